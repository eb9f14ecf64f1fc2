"""Writers and readers: linear EXR, display PNG and a JSON sidecar, all written atomically.

Every output of one ``write_image`` call is first written to a hidden temporary file in the
target directory (``.<name>.<token><suffix>``) and only renamed into place with ``os.replace``
once all of them are complete, so a failure never leaves a half-written file behind and never
replaces an existing file with a broken one.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, replace
from datetime import datetime, timezone
from importlib import metadata as importlib_metadata
from pathlib import Path
from typing import Any

import numpy as np
import OpenImageIO as oiio

from ..errors import SonarRasterError
from ..image import SonarImage
from ..sonar import SIDES
from .commit import check_directory, commit, write_json, write_oiio

UNITS = "m^2 (beam-weighted backscattering area, K=1)"
LAYOUT = "rows=pings, columns=slant-range bins near->far"
DISPLAY_LAYOUT = (
    "rows=pings; columns=port bins far->near, then starboard bins near->far (missing side left out)"
)
MAPPING_FORMULA = (
    "code = round(max_code * clip((10*log10(I/ref) + DR) / DR, 0, 1)), I == 0 -> 0; "
    "inverse for code > 0: I = ref * 10**(DR/10 * (code/max_code - 1))"
)
SUPPORTED = (".exr", ".png")
_MAX_KEY = 79  # PNG text keywords are truncated beyond 79 characters
_MAX_VALUE = 1024  # longer metadata entries go to the JSON sidecar only


def display_mapping(
    intensity: np.ndarray, dynamic_range_db: float, ref: float | None = None
) -> tuple[np.ndarray, float]:
    """Map linear intensity to display codes in [0, 1] on a decibel scale.

    ``code = clip((10 log10(I / ref) + DR) / DR, 0, 1)``, so ``I = ref`` maps to 1,
    ``I = ref * 10**(-DR / 10)`` and anything weaker maps to 0, and exact zeros (shadow, water
    column) map to 0.

    Parameters
    ----------
    intensity : ndarray, any shape
        Linear intensity, m², finite and >= 0.
    dynamic_range_db : float
        DR, the decibel span shown, > 0.
    ref : float, optional
        Reference level (m²) shown at full scale. Default: the 99.5th percentile of the
        nonzero intensities (linear interpolation), or 1.0 when every value is zero.

    Returns
    -------
    codes : ndarray, same shape as ``intensity``, float64
        Display values in [0, 1]; multiply by the largest code value and round to quantise.
    ref : float
        The reference level used.
    """
    values: np.ndarray = np.asarray(intensity, dtype=np.float64)
    dr_ok = isinstance(dynamic_range_db, (int, float)) and math.isfinite(dynamic_range_db)
    if not (dr_ok and dynamic_range_db > 0):
        raise SonarRasterError(
            f"dynamic range must be a positive number of dB, got {dynamic_range_db!r}"
        )
    if not np.all(np.isfinite(values)):
        raise SonarRasterError("intensity has NaN or infinite values; cannot map it for display")
    if np.any(values < 0):
        raise SonarRasterError("intensity has negative values; display mapping needs I >= 0")
    positive = values > 0
    if ref is None:
        ref = peak_reference(values)
    if not (math.isfinite(ref) and ref > 0):
        raise SonarRasterError(f"display reference level must be a positive number, got {ref!r}")
    codes = np.zeros_like(values)
    decibels = 10.0 * np.log10(values[positive] / ref)
    codes[positive] = np.clip((decibels + dynamic_range_db) / dynamic_range_db, 0.0, 1.0)
    return codes, float(ref)


def peak_reference(values: np.ndarray) -> float:
    """The raw display's reference (full white): the 99.5th percentile of the non-zero values.

    Linear interpolation between order statistics; 1 when nothing is positive.
    """
    positive = np.asarray(values, np.float64)
    positive = positive[positive > 0]
    return float(np.percentile(positive, 99.5)) if positive.size else 1.0


#: Bounds of the automatic display range, dB.
AUTO_RANGE_DB = (6.0, 60.0)
#: Display range of a levelled image (one with sensor effects), dB: what side-scan viewers show.
LEVELLED_RANGE_DB = 45.0
PALETTES = ("grey", "copper")
LEVELS = ("peak", "median")
#: matplotlib's "copper": (R, G, B) = (min(1, 1.25 c), 0.7812 c, 0.4975 c) for a code c in [0, 1].
COPPER = (1.25, 0.7812, 0.4975)
COPPER_FORMULA = (
    "copper palette: (R, G, B) = round(max_code * (min(1, 1.25 c), 0.7812 c, 0.4975 c)) of the "
    "grey code c in [0, 1]; inverse: c = G / (0.7812 * max_code)"
)


@dataclass(frozen=True)
class Display:
    """How a PNG shows an image: level, palette and pixel geometry.

    Attributes
    ----------
    level : {"peak", "median"}, optional
        ``"peak"``: the reference level (full white) is the 99.5th percentile of the non-zero
        intensities; ``"median"``: the median non-zero intensity sits at mid-grey, so the
        reference is ``median · 10^(DR / 20)`` — the levelled look of a side-scan viewer for an
        image whose TVG levelled it. None: ``"median"`` for an image with sensor effects (its
        metadata lists effect stages), ``"peak"`` for a raw one.
    palette : {"grey", "copper"}
        Grey levels (one channel) or matplotlib's copper (RGB, :data:`COPPER_FORMULA`).
    ground_range : bool
        Resample each ping from slant range r to ground range ``x = √(r² − h²)`` over a flat
        seabed at the altitude h (bins of the same size; the water column is dropped).
    square_pixels : bool
        Resample along track (linear between pings) so a row is one range bin long.
    altitude_m : float, optional
        h for ``ground_range``; default: the image metadata's ``altitude_m``.
    ping_spacing_m : float, optional
        Along-track distance between pings for ``square_pixels``; default: the metadata's
        ``ping_spacing_m``, or the one its effects record.
    """

    level: str | None = None
    palette: str = "grey"
    ground_range: bool = False
    square_pixels: bool = False
    altitude_m: float | None = None
    ping_spacing_m: float | None = None

    def __post_init__(self) -> None:
        if self.level is not None and self.level not in LEVELS:
            raise SonarRasterError(f"display level must be one of {', '.join(LEVELS)}")
        if self.palette not in PALETTES:
            raise SonarRasterError(
                f"unknown palette {self.palette!r}; use one of {', '.join(PALETTES)}"
            )
        for name in ("altitude_m", "ping_spacing_m"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise SonarRasterError(f"display {name} must be a positive number, got {value!r}")


def _has_effects(image: SonarImage) -> bool:
    record = image.metadata.get("effects")
    return isinstance(record, dict) and bool(record.get("stages"))


def _metadata_number(image: SonarImage, *keys: str) -> float | None:
    node: Any = image.metadata
    for key in keys:
        node = node.get(key) if isinstance(node, dict) else None
    ok = isinstance(node, (int, float)) and not isinstance(node, bool)
    return float(node) if ok and math.isfinite(node) and node > 0 else None


def ground_range_sides(
    sides: dict[str, np.ndarray], range_bin: float, altitude: float
) -> dict[str, np.ndarray]:
    """Slant-range rows resampled to ground range over a flat seabed at ``altitude`` (metres).

    Parameters
    ----------
    sides : dict of str to ndarray, (pings, bins)
        Intensities per side, bin k centred at slant range ``(k + 0.5) · range_bin``.
    range_bin : float
        Slant-range bin, metres; the ground-range bins have the same size.
    altitude : float
        Height of the sonar above the flat seabed, metres.

    Returns
    -------
    dict of str to ndarray, (pings, ground bins), float64
        Column j holds the intensity at ground range ``(j + 0.5) · range_bin``, linearly
        interpolated between slant-range bins; beyond the last bin, 0.
    """
    n_bins = next(iter(sides.values())).shape[1]
    far = n_bins * range_bin
    if altitude >= far:
        raise SonarRasterError(
            f"ground-range display: altitude {altitude:g} m is beyond the range {far:g} m"
        )
    n_ground = max(1, int(math.ceil(math.sqrt(far**2 - altitude**2) / range_bin)))
    x = (np.arange(n_ground) + 0.5) * range_bin
    position = np.sqrt(x**2 + altitude**2) / range_bin - 0.5  # fractional slant bin
    k = np.arange(n_bins)
    return {
        name: np.stack(
            [np.interp(position, k, row, right=0.0) for row in np.asarray(a, np.float64)]
        )
        for name, a in sides.items()
    }


def square_pixel_sides(
    sides: dict[str, np.ndarray], ping_spacing: float, column_size: float
) -> dict[str, np.ndarray]:
    """Rows resampled along track so that each row is ``column_size`` long (square pixels).

    Parameters
    ----------
    sides : dict of str to ndarray, (pings, columns)
        Intensities per side.
    ping_spacing : float
        Along-track distance between pings, metres.
    column_size : float
        Across-track size of a column, metres.

    Returns
    -------
    dict of str to ndarray, (rows, columns), float64
        ``rows = round(pings · ping_spacing / column_size)`` (at least 1); row i is centred at
        ``(i + 0.5) · column_size`` along track, linearly interpolated between pings.
    """
    pings = next(iter(sides.values())).shape[0]
    lo, hi, w = square_pixel_rows(pings, ping_spacing, column_size)
    w = w[:, None]
    return {
        name: (1.0 - w) * np.asarray(a, np.float64)[lo] + w * np.asarray(a, np.float64)[hi]
        for name, a in sides.items()
    }


def square_pixel_rows(
    pings: int, ping_spacing: float, column_size: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each row of :func:`square_pixel_sides`, its two pings and the second one's weight.

    Row i is ``(1 − w_i) · ping[lo_i] + w_i · ping[hi_i]``; a long image can be resampled in
    blocks of rows, reading only the pings ``lo`` to ``hi`` of each block.
    """
    rows = max(1, int(round(pings * ping_spacing / column_size)))
    position = (np.arange(rows) + 0.5) * column_size / ping_spacing - 0.5
    position = np.clip(position, 0.0, pings - 1.0)
    lo = np.floor(position).astype(np.int64)
    hi = np.minimum(lo + 1, pings - 1)
    return lo, hi, position - lo


def display_sides(
    image: SonarImage, sides: dict[str, np.ndarray], display: Display
) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """The sides as the PNG shows them (ground range, square pixels) and that geometry.

    Parameters
    ----------
    image : SonarImage
        The image (its sonar and metadata give the bin size, altitude and ping spacing).
    sides : dict of str to ndarray
        Its checked sides (:func:`checked_sides`).
    display : Display
        The geometry asked for.

    Returns
    -------
    sides : dict of str to ndarray
        The resampled sides (the input when no resampling is asked for).
    geometry : dict
        ``columns`` ("slant range" or "ground range"), ``column_m`` (metres per column),
        ``row_m`` (metres per row, or None when unknown), ``altitude_m`` (ground range only):
        what a reader needs to map pixels back to pings and bins.
    """
    column = float(image.sonar.range_bin)
    spacing = display_ping_spacing(image, display)
    geometry: dict[str, Any] = {"columns": "slant range", "column_m": column, "row_m": spacing}
    if display.ground_range:
        altitude = display.altitude_m or _metadata_number(image, "altitude_m")
        if altitude is None:
            raise SonarRasterError(
                "the ground-range display needs the altitude: give it (Display.altitude_m) or "
                "write an image whose metadata has altitude_m"
            )
        sides = ground_range_sides(sides, column, altitude)
        geometry.update(columns="ground range", altitude_m=altitude)
    if display.square_pixels:
        if spacing is None:
            raise SonarRasterError(
                "square pixels need the ping spacing: give it (Display.ping_spacing_m) or "
                "write an image whose metadata has ping_spacing_m"
            )
        sides = square_pixel_sides(sides, spacing, column)
        geometry["row_m"] = column
    return sides, geometry


def display_ping_spacing(image: SonarImage, display: Display) -> float | None:
    """The along-track distance between pings a display uses, metres; None when unknown.

    The display's own, else the image metadata's ``ping_spacing_m``, else its effects'.
    """
    spacing = display.ping_spacing_m or _metadata_number(image, "ping_spacing_m")
    return spacing or _metadata_number(image, "effects", "ping_spacing_m")


def palette_codes(codes: np.ndarray, palette: str) -> np.ndarray:
    """Grey codes in [0, 1], (h, w), as (h, w, channels) in the palette: 1 (grey) or 3 (RGB).

    Parameters
    ----------
    codes : ndarray, (h, w)
        Display codes in [0, 1].
    palette : {"grey", "copper"}
        The palette (:data:`COPPER_FORMULA`).
    """
    if palette == "grey":
        return codes[:, :, np.newaxis]
    r, g, b = COPPER
    return np.stack([np.minimum(1.0, r * codes), g * codes, b * codes], axis=-1)


def auto_dynamic_range(intensity: np.ndarray, ref: float | None = None) -> float:
    """Display range that spans the image: from its 1st percentile of nonzero values to ``ref``.

    Raw images carry no spreading loss or gain, so their span is often only 10–20 dB; a fixed
    60 dB window would show them washed out. The result is rounded to 0.1 dB and bounded by
    :data:`AUTO_RANGE_DB`; ``ref`` defaults as in :func:`display_mapping`.
    """
    values = np.asarray(intensity, dtype=np.float64)
    positive = values[values > 0]
    if positive.size == 0:
        return AUTO_RANGE_DB[1]
    top = float(np.percentile(positive, 99.5)) if ref is None else ref
    low = float(np.percentile(positive, 1.0))
    span = 10.0 * math.log10(top / low) if low > 0 and top > low else AUTO_RANGE_DB[0]
    return round(min(max(span, AUTO_RANGE_DB[0]), AUTO_RANGE_DB[1]), 1)


def write_image(
    image: SonarImage,
    path: str | os.PathLike,
    *,
    bit_depth: int = 8,
    dynamic_range_db: float | None = None,
    sidecar: bool = True,
    display: Display | None = None,
) -> list[Path]:
    """Write a sonar image as linear EXR or display PNG, plus a JSON sidecar.

    The format follows the extension: ``.exr`` holds float32 channels "port" and "starboard"
    (rows = pings, columns = range bins near to far, zip compression); ``.png`` holds the
    display image of :meth:`SonarImage.display` mapped with :func:`display_mapping`. Both carry
    ``sonar:*`` and ``sonar_raster:*`` header attributes. The sidecar is ``path`` with the
    suffix ``.json``.

    Parameters
    ----------
    image : SonarImage
        Non-empty, finite intensities; every side the same shape (pings, bins).
    path : str or path-like
        Output file, ending in .exr or .png; its directory must exist.
    bit_depth : int
        8 or 16, grey levels of the PNG (ignored for EXR).
    dynamic_range_db : float, optional
        Decibel span of the display mapping (PNG, and recorded in the sidecar); None spans the
        image (:func:`auto_dynamic_range`).
    sidecar : bool
        Also write the JSON sidecar.
    display : Display, optional
        Level, palette and pixel geometry of the PNG. Default: the ``"peak"`` level and the
        image's own span for a raw image, the ``"median"`` level and 45 dB for one with sensor
        effects; grey; slant range; one row per ping.

    Returns
    -------
    list of Path
        The files written: the image, then the sidecar if any.
    """
    return commit(
        image_jobs(
            image,
            path,
            bit_depth=bit_depth,
            dynamic_range_db=dynamic_range_db,
            sidecar=sidecar,
            display=display,
        )
    )


def image_jobs(
    image: SonarImage,
    path: str | os.PathLike,
    *,
    bit_depth: int = 8,
    dynamic_range_db: float | None = None,
    sidecar: bool = True,
    display: Display | None = None,
) -> list[tuple[Path, Callable[[Path], None]]]:
    """The (final path, writer) jobs of :func:`write_image`, for one :func:`.commit` of many.

    Checks the image and the options as :func:`write_image` does and prepares the pixels;
    nothing is written until the jobs are passed to :func:`~sonar_raster.io.commit.commit`.

    Parameters
    ----------
    image, path, bit_depth, dynamic_range_db, sidecar
        As :func:`write_image`.
    display : Display, optional
        Level, palette and geometry of the PNG (default :class:`Display`).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in SUPPORTED:
        raise SonarRasterError(
            f"cannot write {path}: unsupported extension {path.suffix or '(none)'!r}; "
            f"use one of {', '.join(SUPPORTED)}"
        )
    if bit_depth not in (8, 16):
        raise SonarRasterError(f"PNG bit depth must be 8 or 16, got {bit_depth!r}")
    sides = checked_sides(image)
    check_directory(path)
    codes, mapping = _display(image, sides, display or Display(), dynamic_range_db)
    jobs: list[tuple[Path, Callable[[Path], None]]] = []
    if suffix == ".exr":
        exr_attrs = exr_attributes(image)
        jobs.append((path, lambda tmp: _write_exr(tmp, sides, exr_attrs)))
    else:
        png_attrs = png_attributes(image, mapping, bit_depth)
        pixels = palette_codes(codes, mapping.get("palette", "grey"))
        jobs.append((path, lambda tmp: _write_png(tmp, pixels, bit_depth, png_attrs)))
    if sidecar:
        doc = sidecar_document(image, mapping)
        jobs.append((path.with_suffix(".json"), lambda tmp: write_json(tmp, doc)))
    return jobs


def median_reference(values: np.ndarray, dynamic_range_db: float) -> float:
    """The levelled display's reference (full white), ``median · 10^(DR / 20)``.

    The median non-zero value of ``values`` then sits at mid-grey; 1 when nothing is positive.
    """
    positive = values[values > 0]
    if not positive.size:
        return 1.0
    return float(np.median(positive)) * 10.0 ** (dynamic_range_db / 20.0)


def _display(
    image: SonarImage, sides: dict[str, np.ndarray], display: Display, dr: float | None
) -> tuple[np.ndarray, dict[str, Any]]:
    """Display codes in [0, 1] of the PNG and the mapping that made them (for the metadata)."""
    shown, geometry = display_sides(image, sides, display)
    both = SonarImage(shown, image.sonar).display()
    mapping = display_levels(image, both, display, dr, geometry)
    codes, _ = display_mapping(both, mapping["dynamic_range_db"], mapping["ref_level_m2"])
    return codes, mapping


def display_levels(
    image: SonarImage,
    shown: np.ndarray,
    display: Display,
    dynamic_range_db: float | None,
    geometry: dict[str, Any],
) -> dict[str, Any]:
    """The PNG's display mapping (reference level, range, and how it is shown), as metadata.

    A raw image with the default :class:`Display` gets exactly the mapping it always had (the
    same keys too); other settings add ``level``, ``palette`` and ``geometry`` entries.

    Parameters
    ----------
    image : SonarImage
        The image (its metadata says whether sensor effects levelled it).
    shown : ndarray
        Its intensities as displayed (:meth:`SonarImage.display` of :func:`display_sides`), or
        an even subsample of their rows: the levels are taken from them.
    display : Display
        Level, palette and geometry asked for.
    dynamic_range_db : float, optional
        The range shown; None: :data:`LEVELLED_RANGE_DB` when levelled, else
        :func:`auto_dynamic_range`.
    geometry : dict
        The pixel geometry (:func:`display_sides`).
    """
    level = display.level or ("median" if _has_effects(image) else "peak")
    dr = dynamic_range_db
    if dr is None:
        dr = LEVELLED_RANGE_DB if level == "median" else auto_dynamic_range(shown)
    ref = median_reference(shown, dr) if level == "median" else peak_reference(shown)
    mapping: dict[str, Any] = {
        "ref_level_m2": ref,
        "dynamic_range_db": float(dr),
        "formula": MAPPING_FORMULA,
    }
    plain = replace(display, altitude_m=None, ping_spacing_m=None) == Display()
    if not plain or level != "peak":
        mapping.update(level=level, palette=display.palette, geometry=geometry)
        if display.palette == "copper":
            mapping["palette_formula"] = COPPER_FORMULA
    return mapping


def read_spec(path: str | os.PathLike) -> oiio.ImageSpec | None:
    """The header of any image OpenImageIO reads, without its pixels; None if it cannot open it.

    OpenImageIO's own error is taken (not left pending to be printed at exit): the caller's
    reader of the pixels says what is wrong with the file.
    """
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        oiio.geterror()
        return None
    try:
        return inp.spec()
    finally:
        inp.close()


def read_pixels(path: str | os.PathLike) -> tuple[np.ndarray, oiio.ImageSpec]:
    """Pixels of any image OpenImageIO reads, as float32 (height, width, channels), and its spec.

    Raises
    ------
    SonarRasterError
        If the file cannot be opened or its pixels cannot be read.
    """
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise SonarRasterError(f"cannot read {path}: {oiio.geterror() or 'not an image'}")
    try:
        spec = inp.spec()
        pixels = inp.read_image(format=oiio.FLOAT)
        error = inp.geterror()
    finally:
        inp.close()
    if pixels is None:
        raise SonarRasterError(f"cannot read pixels of {path}: {error}")
    shape = (spec.height, spec.width, spec.nchannels)
    return np.asarray(pixels, dtype=np.float32).reshape(shape), spec


def read_exr(path: str | os.PathLike) -> tuple[dict[str, np.ndarray], dict]:
    """Read an EXR written by :func:`write_image`.

    Parameters
    ----------
    path : str or path-like
        The .exr file.

    Returns
    -------
    sides : dict of str to ndarray, shape (pings, bins), float32
        One entry per channel named "port" or "starboard".
    attributes : dict
        Every header attribute by name (``sonar:*``, ``sonar_raster:*``, compression, ...).
    """
    pixels, spec = read_pixels(path)
    names = list(spec.channelnames)
    if not names or any(name not in SIDES for name in names):
        raise SonarRasterError(f"{path}: channels {names} are not port/starboard sonar sides")
    sides = {name: np.ascontiguousarray(pixels[:, :, i]) for i, name in enumerate(names)}
    return sides, {attr.name: attr.value for attr in spec.extra_attribs}


def checked_sides(image: SonarImage) -> dict[str, np.ndarray]:
    """Check the image and return its sides as float32 (pings, bins), port first."""
    if not image.sides:
        raise SonarRasterError("the image has no sides; nothing to write")
    unknown = sorted(set(image.sides) - set(SIDES))
    if unknown:
        raise SonarRasterError(f"unknown image sides {unknown}; expected port and/or starboard")
    raw = {s: np.asarray(image.sides[s]) for s in SIDES if s in image.sides}
    shapes = {a.shape for a in raw.values()}
    if len(shapes) != 1 or len(next(iter(shapes))) != 2:
        raise SonarRasterError(f"image sides must be 2-D arrays of one shape, got {sorted(shapes)}")
    if 0 in next(iter(shapes)):
        raise SonarRasterError(f"the image is empty (shape {next(iter(shapes))}); nothing to write")
    for name, array in raw.items():
        if array.dtype.kind not in "biuf":
            raise SonarRasterError(
                f"the {name} image has dtype {array.dtype}; expected real numbers"
            )
        if not np.all(np.isfinite(array)) or np.abs(array).max() > np.finfo(np.float32).max:
            raise SonarRasterError(
                f"the {name} image has NaN or infinite values (in float32); an image to write "
                "must be finite (set them to 0, or report it if a render made them)"
            )
    return {name: array.astype(np.float32, copy=False) for name, array in raw.items()}


def png_type(bit_depth: int) -> tuple[type, Any]:
    """The numpy integer type and OpenImageIO type of an 8- or 16-bit PNG."""
    return (np.uint8, oiio.UINT8) if bit_depth == 8 else (np.uint16, oiio.UINT16)


def quantised_codes(codes: np.ndarray, bit_depth: int) -> tuple[np.ndarray, Any]:
    """Display codes in [0, 1] as 8- or 16-bit integers, and their OpenImageIO type."""
    dtype, fmt = png_type(bit_depth)
    return np.rint(codes * np.iinfo(dtype).max).astype(dtype), fmt


def _write_exr(tmp: Path, sides: dict[str, np.ndarray], attrs: dict) -> None:
    pixels = np.stack(list(sides.values()), axis=-1)  # (pings, bins, channels), never 2-D
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], oiio.FLOAT)
    spec.channelnames = tuple(sides)
    spec.attribute("compression", "zip")
    for name, value in attrs.items():
        spec.attribute(name, value)
    write_oiio(tmp, pixels, spec)


def _write_png(tmp: Path, pixels: np.ndarray, bit_depth: int, attrs: dict) -> None:
    """Write (h, w, 1) grey or (h, w, 3) RGB codes in [0, 1] as an 8- or 16-bit PNG."""
    quantised, fmt = quantised_codes(pixels, bit_depth)
    channels = quantised.shape[2]
    spec = oiio.ImageSpec(quantised.shape[1], quantised.shape[0], channels, fmt)
    spec.channelnames = ("Y",) if channels == 1 else ("R", "G", "B")
    for name, value in attrs.items():
        spec.attribute(name, value)
    write_oiio(tmp, quantised, spec)


def _header_value(value: object, as_text: bool) -> str | int | float:
    """Convert to what OIIO headers store: str, int (32-bit) or float; lists comma-joined."""
    if isinstance(value, (list, tuple)):
        return ",".join(str(v) for v in value)
    if isinstance(value, (bool, np.bool_)) or value is None:
        return str(value)
    if isinstance(value, (int, np.integer)) and not as_text and abs(int(value)) < 2**31:
        return int(value)
    if isinstance(value, (float, np.floating)) and not as_text:
        return float(value)
    if isinstance(value, (float, np.floating)):
        return repr(float(value))
    return str(value)


def _metadata_attributes(metadata: dict) -> dict[str, str]:
    """Flatten ``metadata`` to ``sonar_raster:<a.b.c>`` → JSON of each leaf, skipping large ones."""
    flat: dict[str, str] = {}

    def walk(key: str, node: object) -> None:
        if isinstance(node, dict) and node:
            for sub, value in node.items():
                walk(f"{key}.{sub}", value)
            return
        name = f"sonar_raster:{key}"
        text = json.dumps(_jsonable(node), allow_nan=False)
        if len(name) <= _MAX_KEY and len(text) <= _MAX_VALUE:
            flat[name] = text

    for key, value in metadata.items():
        walk(str(key), value)
    return flat


def exr_attributes(image: SonarImage) -> dict:
    """EXR header attributes of an image: ``sonar:*`` fields and its metadata."""
    attrs: dict = {f"sonar:{k}": _header_value(v, False) for k, v in image.sonar.to_dict().items()}
    attrs["sonar:units"] = UNITS
    attrs["sonar:layout"] = LAYOUT
    attrs.update(_metadata_attributes(image.metadata))
    return attrs


def png_attributes(image: SonarImage, mapping: dict, bit_depth: int) -> dict[str, str]:
    """PNG text chunks (PNG keeps only strings): sonar, display mapping, metadata."""
    attrs = {f"sonar:{k}": str(_header_value(v, True)) for k, v in image.sonar.to_dict().items()}
    max_code = 2**bit_depth - 1
    attrs.update(
        {
            "sonar:units": f"display code 0..{max_code}, dB re display_ref_level_m2 of {UNITS}",
            "sonar:layout": DISPLAY_LAYOUT,
            "sonar:display_ref_level_m2": repr(mapping["ref_level_m2"]),
            "sonar:display_dynamic_range_db": repr(mapping["dynamic_range_db"]),
            "sonar:display_max_code": str(max_code),
            "sonar:display_mapping": MAPPING_FORMULA,
            **_display_attributes(mapping),
            "ImageDescription": (
                "Side-scan sonar display image. "
                f"Reference level ref = {mapping['ref_level_m2']!r} m^2, "
                f"dynamic range DR = {mapping['dynamic_range_db']!r} dB, max_code = {max_code}. "
                + MAPPING_FORMULA
            ),
        }
    )
    attrs.update(_metadata_attributes(image.metadata))
    return attrs


def _display_attributes(mapping: dict) -> dict[str, str]:
    """PNG text chunks of the mapping's level, palette and geometry (none for the default)."""
    if "level" not in mapping:
        return {}
    attrs = {
        "sonar:display_level": str(mapping["level"]),
        "sonar:display_palette": str(mapping["palette"]),
    }
    if "palette_formula" in mapping:
        attrs["sonar:display_palette_formula"] = str(mapping["palette_formula"])
    for key, value in mapping["geometry"].items():
        attrs[f"sonar:display_{key}"] = repr(value) if isinstance(value, float) else str(value)
    return attrs


def sidecar_document(image: SonarImage, mapping: dict) -> object:
    """The JSON sidecar document of an image written with display ``mapping``."""
    return _jsonable(
        {
            "sonar": image.sonar.to_dict(),
            "metadata": image.metadata,
            "shape": list(image.shape),
            "sides": [s for s in SIDES if s in image.sides],
            "units": UNITS,
            "layout": LAYOUT,
            "display_mapping": mapping,
            "package_version": _package_version(),
            "written_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        }
    )


def _package_version() -> str:
    try:
        return importlib_metadata.version("sonar_raster")
    except importlib_metadata.PackageNotFoundError:
        return "unknown (not installed)"


def _jsonable(value: object) -> object:
    """Convert to plain JSON data: numpy → Python, tuples/sets → lists, non-finite floats → str."""
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, (set, frozenset)):
        return sorted(_jsonable(v) for v in value)  # type: ignore[type-var]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, np.generic):
        return _jsonable(value.item())
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if value is None or isinstance(value, (str, bool, int, float)):
        return value
    raise SonarRasterError(
        f"image metadata holds a {type(value).__name__}, which JSON cannot store; "
        "use numbers, strings, lists and dicts"
    )
