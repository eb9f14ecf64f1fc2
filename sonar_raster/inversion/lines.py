"""Several survey lines: split at turns, inverted one by one, gridded together on the ground.

The pipeline has three stages, each on plain data, so any one can be replaced:

1. :func:`read_lines`: XTF files into :class:`Line` objects (intensity per side, the track in
   projected metres, heading, pitch, sensor depth, the first-return altitude). Each file is one
   line, or, with ``split``, the runs between turns of :func:`split_lines`; lines recorded
   with different sonar settings, or without navigation, are refused.
2. :func:`invert_lines`: side -> :class:`~.solver.Inversion` per line: with
   ``method="surface"`` every line in one surface fit (:func:`.surface.invert_lines`), with
   ``"profiles"`` each side of each line on its own.
3. :func:`line_samples` places each line's cells on the ground (:func:`.xtf.ground_positions`)
   in one vertical datum (:func:`vertical_datum`), and :func:`grid_lines` grids each line by
   footprints (:func:`.xtf.grid`) on one shared frame and combines the lines pixel by pixel
   (:func:`combine`): the elevation by inverse-variance weighting where it has a standard
   deviation (the combined one is ``1 / sqrt(Σ 1/σ²)``), every other layer by the plain mean
   of the lines that cover the pixel.

Turns (:func:`split_lines`): a ping is in a turn when the heading, median-filtered over
:data:`HEADING_FILTER` pings, changes by more than :data:`TURN_DEG` degrees over the
:data:`TURN_WINDOW_M` metres of track centred on it; the lines are the runs of pings between
turns, and runs shorter than :data:`MIN_LINE_PINGS` pings are dropped with the turns.
"""

from __future__ import annotations

import logging
import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import SonarRasterError
from .bottom import BottomTrack
from .xtf import Raster

if TYPE_CHECKING:
    from .solver import Inversion

log = logging.getLogger(__name__)

#: Heading change (degrees) over :data:`TURN_WINDOW_M` metres of track that marks a turn:
#: turns tighter than a radius of about 29 m. The OpenSidescan sample's course corrections reach
#: 12.7° (one line); 10° split it in two.
TURN_DEG = 20.0
#: Length of track (metres) over which the heading change is measured, centred on the ping.
TURN_WINDOW_M = 10.0
#: Pings of the running median taken of the heading first (yaw jitter is not a turn).
HEADING_FILTER = 9
#: Shortest line kept, pings; shorter runs between turns are dropped with the turns.
MIN_LINE_PINGS = 20
#: Relative difference of range bin or frequency below which two lines count as one setting.
SETTING_TOLERANCE = 1e-3

#: Sample = (east, north, layers): positions (pings, cells) and layer name -> (pings, cells).
Samples = tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]

#: Vertical datums of :func:`vertical_datum`: what the gridded elevation is relative to.
DATUMS = {
    "sea surface": "metres relative to the sea surface (the XTF sensor depth plus the "
    "inverted elevation below the sensor), negative down",
    "first line": "metres relative to the first line's mean transducer level (no sensor depth "
    "in the files: each later line shifted by its median difference to the lines before it "
    "where they overlap), negative down",
}


@dataclass(frozen=True)
class Line:
    """One survey line: a run of pings of one XTF file, ready to invert and to place.

    Attributes
    ----------
    source : str
        The XTF file.
    pings : ndarray of int, shape (pings,)
        The file's ping indices of the line's rows (``read_xtf``'s ``ping_indices``).
    sides : dict of str to ndarray, each (pings, bins) float64
        Linear intensity per side (the samples squared for amplitude files), bins from range
        0, the transmit pulse's bins set to 0.
    range_bin, frequency_hz : float
        Slant-range bin (metres) and sonar frequency (Hz).
    east, north, heading, pitch, depth, recorded_altitude : ndarray, shape (pings,)
        Projected position (metres, jumps off the track interpolated), compass heading and
        pitch (radians, nose up), sensor depth (metres, positive down; 0 when the file has
        none) and the file's altitude (NaN: none).
    crs : str or None
        CRS of ``east``/``north`` ("EPSG:nnnn", None for files in projected metres).
    track : BottomTrack
        The first bottom return per ping (:func:`.bottom.track_bottom`).
    ping_spacing : float
        Mean distance between pings, metres.
    """

    source: str
    pings: np.ndarray
    sides: dict[str, np.ndarray]
    range_bin: float
    frequency_hz: float
    east: np.ndarray
    north: np.ndarray
    heading: np.ndarray
    pitch: np.ndarray
    depth: np.ndarray
    recorded_altitude: np.ndarray
    crs: str | None
    track: BottomTrack
    ping_spacing: float

    @property
    def label(self) -> str:
        """``FILE pings A:B`` (file ping indices, stop excluded)."""
        return f"{Path(self.source).name} pings {self.pings[0]}:{self.pings[-1] + 1}"

    @property
    def has_depth(self) -> bool:
        """Whether the file records the sensor depth (some ping deeper than 0)."""
        return bool(np.any(self.depth > 0))


def split_lines(
    east: np.ndarray,
    north: np.ndarray,
    heading: np.ndarray,
    *,
    turn_deg: float = TURN_DEG,
    window_m: float = TURN_WINDOW_M,
    min_pings: int = MIN_LINE_PINGS,
) -> list[tuple[int, int]]:
    """Runs of pings between turns, as (start, stop) row ranges, stop excluded.

    Parameters
    ----------
    east, north : ndarray, shape (pings,)
        Positions, metres.
    heading : ndarray, shape (pings,)
        Compass heading, radians (no NaN).
    turn_deg, window_m, min_pings : float, float, int
        The rule of the module's notes: a ping whose median-filtered heading changes by more
        than ``turn_deg`` degrees over the ``window_m`` metres of track centred on it is in a
        turn; runs shorter than ``min_pings`` are dropped.

    Returns
    -------
    list of (int, int)
        In ping order; empty when no run is long enough.
    """
    from scipy.ndimage import median_filter

    n = len(heading)
    if n == 0:
        return []
    h = median_filter(
        np.unwrap(np.asarray(heading, dtype=np.float64)), HEADING_FILTER, mode="nearest"
    )
    step = np.hypot(np.diff(east), np.diff(north))
    s = np.concatenate([[0.0], np.cumsum(np.nan_to_num(step))])
    lo = np.searchsorted(s, s - window_m / 2.0, side="left")
    hi = np.searchsorted(s, s + window_m / 2.0, side="right") - 1
    steady = np.abs(h[hi] - h[lo]) <= math.radians(turn_deg)
    edges = np.diff(np.concatenate([[0], steady.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return [(int(a), int(b)) for a, b in zip(starts, stops, strict=True) if b - a >= min_pings]


def describe_lines(lines: Sequence[Line]) -> str:
    """One line of text: ``3 lines: A.xtf pings 0:812, 840:1650, ...``."""
    parts, last = [], None
    for line in lines:
        name = Path(line.source).name
        span = f"{line.pings[0]}:{line.pings[-1] + 1}"
        parts.append(span if name == last else f"{name} pings {span}")
        last = name
    return f"{len(lines)} line{'s' if len(lines) != 1 else ''}: {', '.join(parts)}"


def read_lines(
    paths: Sequence[str | Path],
    *,
    split: bool | list[tuple[int, int]] = False,
    pings: slice | None = None,
    amplitude: bool = True,
    frequency: float | str | None = None,
) -> tuple[list[Line], list[str]]:
    """Read XTF files as survey lines.

    Parameters
    ----------
    paths : sequence of str or Path
        XTF files, each with navigation, all recorded with one range bin, range and frequency.
    split : bool or list of (int, int)
        False: each file is one line. True: each file is split at turns (:func:`split_lines`).
        A list: these ping ranges (file ping indices, stop excluded) of the one file given.
    pings : slice, optional
        Ping range read from each file (as ``read_xtf``'s), before any split.
    amplitude : bool
        The samples are envelope amplitudes: the intensity is their square (as
        :func:`.xtf.invert_xtf`).
    frequency : float or {"low", "high"}, optional
        Dual-frequency files: the channels to read (``read_xtf``'s ``frequency``).

    Returns
    -------
    lines : list of Line
    notes : list of str
        What was found per file (lines and dropped turn pings), for printing.

    Raises
    ------
    SonarRasterError
        A file without navigation or heading to split with, lines recorded with different
        range bins, ranges, sides or frequencies, a split that finds no line, or ping ranges
        given for several files.
    """
    from ..io.xtf import read_xtf

    if isinstance(split, list) and len(paths) != 1:
        raise SonarRasterError(
            "ping ranges of lines (--line-pings A:B,C:D) apply to one XTF file; "
            "give one file, or --lines to split each at its turns"
        )
    lines: list[Line] = []
    notes: list[str] = []
    for path in paths:
        image, nav = read_xtf(path, pings, frequency)
        if not nav.valid.any():
            raise SonarRasterError(
                f"{path} has no navigation: lines can only be combined on "
                "the ground; invert it on its own"
            )
        track = _file_track(nav, lines[0].crs if lines else nav.crs, path)
        rows = _line_rows(image, nav, split, path, track)
        indices = np.asarray(image.metadata.get("ping_indices", range(image.shape[0])))
        file_lines = [
            _make_line(path, image, track, nav.altitude, a, b, indices, amplitude) for a, b in rows
        ]
        dropped = image.shape[0] - sum(b - a for a, b in rows)
        what = "turn pings" if split is True else "pings outside the lines"
        if split is not False:
            notes.append(
                describe_lines(file_lines) + (f" ({dropped} {what} dropped)" * (dropped > 0))
            )
        lines += file_lines
    _check_compatible(lines)
    return lines, notes


def _file_track(nav: Any, crs: str | None, path: Any) -> dict[str, Any]:
    """A file's east, north (in ``crs``), heading, pitch and depth per ping, and ``crs``.

    Files in degrees are projected to the UTM zone of their first fix; a file in another zone
    than ``crs`` (the first file's) is transformed into it. Files in projected metres keep
    their coordinates (no CRS) and cannot join files in degrees.
    """
    from .xtf import robust_track

    east, north = robust_track(nav)
    if (crs is None) != (nav.crs is None):
        units = "degrees" if nav.crs else "projected metres"
        raise SonarRasterError(
            f"{path} has its positions in {units}, unlike the first file; lines in degrees and "
            "in metres cannot be placed together"
        )
    if crs != nav.crs:
        from rasterio.warp import transform

        e, n = transform(nav.crs, crs, east.tolist(), north.tolist())
        east, north = np.asarray(e), np.asarray(n)
    return {
        "east": east, "north": north, "heading": nav.filled_heading(),
        "pitch": nav.filled("pitch"), "depth": np.maximum(nav.filled("depth"), 0.0), "crs": crs,
    }  # fmt: skip


def _line_rows(
    image: Any, nav: Any, split: bool | list[tuple[int, int]], path: Any, track: dict[str, Any]
) -> list:
    """Row ranges (start, stop) of the lines of one file."""
    n = image.shape[0]
    if split is False:
        return [(0, n)]
    if isinstance(split, list):
        indices = np.asarray(image.metadata.get("ping_indices", range(n)))
        rows = []
        for a, b in split:
            inside = np.flatnonzero((indices >= a) & (indices < b))
            if len(inside) < 2:
                raise SonarRasterError(
                    f"{path}: the line {a}:{b} has fewer than 2 pings "
                    f"(the file's pings run {indices[0]}:{indices[-1] + 1})"
                )
            rows.append((int(inside[0]), int(inside[-1]) + 1))
        return rows
    if not np.isfinite(nav.heading).any():
        raise SonarRasterError(
            f"{path} has no heading: cannot find its turns; give the lines' "
            "ping ranges (--line-pings A:B,C:D)"
        )
    rows = split_lines(track["east"], track["north"], track["heading"])
    if not rows:
        raise SonarRasterError(
            f"{path}: no straight run of {MIN_LINE_PINGS} pings or more "
            "between turns; invert it as one line (leave out --lines)"
        )
    return rows


def _make_line(path, image, track, altitude, a: int, b: int, indices, amplitude: bool) -> Line:
    """One :class:`Line` from rows a:b of a file's image and track (:func:`_file_track`)."""
    from .bottom import blanking_bins, track_bottom

    sides = {}
    for side, values in image.sides.items():
        slant = np.asarray(values[a:b], dtype=np.float64)
        sides[side] = slant * slant if amplitude else slant.copy()
    blank = max(blanking_bins(s) for s in sides.values())
    for slant in sides.values():
        slant[:, :blank] = 0.0  # the transmit pulse is not seabed
    e, n = track["east"][a:b], track["north"][a:b]
    spacing = float(np.sum(np.hypot(np.diff(e), np.diff(n))) / max(b - a - 1, 1))
    return Line(
        source=str(path),
        pings=indices[a:b],
        sides=sides,
        range_bin=float(image.sonar.range_bin),
        frequency_hz=float(image.sonar.frequency_hz),
        east=e,
        north=n,
        heading=track["heading"][a:b],
        pitch=track["pitch"][a:b],
        depth=track["depth"][a:b],
        recorded_altitude=np.asarray(altitude[a:b], dtype=np.float64),
        crs=track["crs"],
        track=track_bottom(sides, float(image.sonar.range_bin)),
        ping_spacing=spacing if spacing > 0 else float(image.sonar.range_bin),
    )


def _check_compatible(lines: Sequence[Line]) -> None:
    """Refuse lines recorded with different sonar settings."""
    first = lines[0]
    bins = {s: v.shape[1] for s, v in first.sides.items()}

    def differs(a: float, b: float) -> bool:
        return abs(a - b) > SETTING_TOLERANCE * max(abs(a), abs(b))

    for line in lines[1:]:
        here = {s: v.shape[1] for s, v in line.sides.items()}
        what = None
        if differs(line.range_bin, first.range_bin):
            what = f"range bin {line.range_bin:.4g} m, not {first.range_bin:.4g} m"
        elif here != bins:
            what = f"range {_range(here, line.range_bin)}, not {_range(bins, first.range_bin)}"
        elif differs(line.frequency_hz, first.frequency_hz):
            khz = (line.frequency_hz / 1e3, first.frequency_hz / 1e3)
            what = f"frequency {khz[0]:.4g} kHz, not {khz[1]:.4g} kHz"
        if what:
            raise SonarRasterError(
                f"{line.label} has {what} as {first.label}: invert lines recorded with one "
                "sonar setting together"
            )


def _range(bins: dict[str, int], range_bin: float) -> str:
    return ", ".join(f"{s} {n * range_bin:.4g} m" for s, n in bins.items())


def invert_lines(
    lines: Sequence[Line],
    *,
    method: str = "profiles",
    altitude: float | None = None,
    progress: bool = False,
    **options: Any,
) -> list[dict[str, Inversion]]:
    """Invert every line, both sides.

    The gridding (:func:`line_samples`, :func:`grid_lines`) takes any side -> Inversion per
    line, whichever method made it.

    Parameters
    ----------
    lines : sequence of Line
    method : {"profiles", "surface"}
        ``"profiles"``: :func:`.solver.invert` per side with the line's first-return altitude;
        ``"surface"``: :func:`.surface.invert_lines`, one surface for both sides of every
        line (they share it where they overlap; one beam profile per side for all).
    altitude : float, optional
        A fixed altitude, metres, instead of the first return.
    progress : bool
        Progress bars (profiles) or per-step lines (surface).
    **options
        ``"profiles"``: :func:`.solver.invert`'s options; ``"surface"``: ``looks``,
        ``max_iter``, ``beam`` (a calibrated profile, one or per side), ``finest`` (the
        finest level's pooling) and ``law`` (a :class:`.law.ScatteringLaw`, or a sediment's
        name taken at each line's recorded frequency); others are refused.

    Returns
    -------
    list of dict of str to Inversion
        Per line, side -> its inversion, maps (line pings, ground cells).
    """
    if method not in ("profiles", "surface"):
        raise SonarRasterError(f"unknown method {method!r}; use profiles or surface")
    if method == "surface":
        return _surface(lines, altitude, progress, options)
    results = []
    for line in lines:
        n = len(line.pings)
        alt = np.full(n, float(altitude)) if altitude else None
        from .solver import invert

        results.append(
            {
                side: invert(
                    slant,
                    line.range_bin,
                    altitude=line.track.altitude if alt is None else alt,
                    ping_spacing=line.ping_spacing,
                    progress=progress,
                    **options,
                )
                for side, slant in line.sides.items()
            }
        )
    return results


def surface_options(options: dict[str, Any]) -> dict[str, Any]:
    """The surface fit's options (``looks``, ``max_iter``, ``beam``, ``finest``); others refused.

    ``law`` (a line's, :func:`.law.resolve_law`) is taken too and left out of the result.
    """
    unused = sorted(set(options) - {"looks", "max_iter", "beam", "finest", "law"})
    if unused:
        raise SonarRasterError(f"{', '.join(unused)} not used by the surface fit; leave it out")
    looks = options.get("looks", "auto")
    return {
        "looks": "auto" if looks in ("auto", None) else looks,
        "max_iter": options.get("max_iter", 150),
        "beam": options.get("beam"),
        "finest": options.get("finest", 1),
    }


def _surface(
    lines: Sequence[Line], altitude: float | None, progress: bool, options: dict
) -> list[dict[str, Inversion]]:
    """Every line in one surface fit (:func:`.surface.invert_lines`).

    Where lines overlap they share the seabed, and Φ is shared by all; the transducer heights
    come from the sensor depth when every line records it.
    """
    from .law import resolve_law
    from .surface import Line as SurfaceLine
    from .surface import invert_lines as fit_together

    depth = all(line.has_depth for line in lines)
    together = [
        SurfaceLine(
            line.sides,
            line.range_bin,
            np.stack([line.east, line.north], axis=1),
            line.heading,
            altitude=np.full(len(line.pings), float(altitude)) if altitude else None,
            height=-line.depth if depth else None,
            law=resolve_law(options.get("law"), line.frequency_hz),
        )
        for line in lines
    ]
    return fit_together(together, progress=print if progress else None, **surface_options(options))


def vertical_datum(lines: Sequence[Line]) -> str:
    """``"sea surface"`` when every line records the sensor depth, else ``"first line"``."""
    return "sea surface" if all(line.has_depth for line in lines) else "first line"


def line_samples(line: Line, sides: dict[str, Inversion], datum: str) -> dict[str, Samples]:
    """A line's cells on the ground, per side: (east, north, layers), each (pings, cells).

    Layers: ``elevation`` (``Z cos p`` below the transducer, minus the sensor depth for the
    ``"sea surface"`` datum), ``elevation_var`` (``(σ_Z cos p)²``, where the inversion has a
    standard deviation), ``reflectivity`` and ``mosaic`` (:func:`.xtf.mosaic_values`).
    """
    from .xtf import ground_positions, mosaic_values

    if datum not in DATUMS:
        raise SonarRasterError(f"unknown datum {datum!r}; use one of {', '.join(DATUMS)}")
    cos_p = np.cos(line.pitch)[:, None]
    out = {}
    for side, inv in sides.items():
        e, n = ground_positions(
            line.east, line.north, line.heading, line.pitch, inv.x, inv.elevation, side
        )
        z = inv.elevation * cos_p
        if datum == "sea surface":
            z = z - line.depth[:, None]
        layers = {"elevation": z, "reflectivity": inv.reflectivity, "mosaic": mosaic_values(inv)}
        if getattr(inv, "elevation_std", None) is not None:
            layers["elevation_var"] = (inv.elevation_std * cos_p) ** 2
        out[side] = (e, n, layers)
    return out


@dataclass(frozen=True)
class LinesRaster:
    """Gridded lines: the combined raster, each line's raster on the same frame, offsets.

    ``combined`` and each of ``lines`` hold ``elevation``, ``reflectivity``, ``mosaic`` and,
    when every line has one, ``elevation_std``; ``offsets`` (metres, one per line) were added
    to each line's elevation to align it with the lines before it (all 0 without alignment).
    """

    combined: Raster
    lines: list[Raster]
    offsets: list[float]


def grid_lines(
    samples: Sequence[dict[str, Samples]],
    pixel: float,
    crs: str | None,
    *,
    align: bool = False,
) -> LinesRaster:
    """Grid several lines on one north-up frame and combine them (:func:`combine`).

    Parameters
    ----------
    samples : sequence of dict of str to (east, north, layers)
        Per line, per side (``"port"``, ``"starboard"``): ground positions (pings, cells) in
        ground-range order from near to far, and layers of the same shape: ``elevation``,
        ``reflectivity``, ``mosaic`` and optionally ``elevation_var`` (σ², m²). Plain arrays:
        how they were fitted does not matter.
    pixel : float
        Pixel size, metres.
    crs : str or None
        CRS of the positions.
    align : bool
        Shift each line's elevation by the median difference to the lines before it where
        they overlap (for elevations relative to each line's own transducer).

    Returns
    -------
    LinesRaster

    Raises
    ------
    SonarRasterError
        When the lines' rasters together would hold more than :data:`.xtf.MAX_GRID_CELLS`
        pixels (each line is held on the shared frame until they are combined).
    """
    from .xtf import MAX_GRID_CELLS, grid, join_sides, raster_frame

    if not samples:
        raise SonarRasterError("no line to grid")
    swaths = [join_sides(dict(line)) for line in samples]
    frame = raster_frame([s for swath in swaths for s in swath], pixel)
    if len(swaths) * frame[2] * frame[3] > MAX_GRID_CELLS:
        raise SonarRasterError(
            f"{len(swaths)} lines on a raster of {frame[2]} x {frame[3]} pixels of {pixel:.3g} m "
            f"are more than {MAX_GRID_CELLS} line pixels to hold; grid fewer lines at a time"
        )
    rasters = []
    for swath in swaths:
        raster = grid(swath, pixel, crs, frame=frame)
        layers = dict(raster.layers)
        var = layers.pop("elevation_var", None)
        if var is not None:
            layers["elevation_std"] = np.sqrt(var)
        rasters.append(Raster(layers, raster.west, raster.north, pixel, crs))
    offsets = _align(rasters) if align else [0.0] * len(rasters)
    return LinesRaster(combine(rasters), rasters, offsets)


def _align(rasters: list[Raster]) -> list[float]:
    """Shift each line's elevation (in place) onto the lines before it; the offsets."""
    offsets = [0.0]
    done = rasters[0].layers["elevation"].astype(np.float64)
    for raster in rasters[1:]:
        z = raster.layers["elevation"]
        both = np.isfinite(z) & np.isfinite(done)
        shift = float(np.median(done[both] - z[both])) if both.any() else 0.0
        z += np.float32(shift)
        offsets.append(shift)
        done = np.where(np.isfinite(done), done, z)
    return offsets


def combine(rasters: Sequence[Raster]) -> Raster:
    """Combine rasters on one frame pixel by pixel.

    ``elevation`` with ``elevation_std`` in every raster: the inverse-variance mean
    ``Σ (z_k / σ_k²) / Σ (1 / σ_k²)`` over the rasters covering the pixel, with
    ``elevation_std`` = ``1 / sqrt(Σ 1 / σ_k²)`` (pixels with σ = 0 or a non-finite σ count as
    not covered); without, and for every other layer, the plain mean of the covering rasters.

    Parameters
    ----------
    rasters : sequence of Raster
        Same frame (west, north, pixel, shape) and layer names.

    Returns
    -------
    Raster
        Float32 layers, NaN where no raster covers the pixel.
    """
    first = rasters[0]
    for r in rasters[1:]:
        same = (r.west, r.north, r.pixel) == (first.west, first.north, first.pixel)
        if not same or r.layers["elevation"].shape != first.layers["elevation"].shape:
            raise SonarRasterError("rasters to combine must share one frame")
    names = [k for k in first.layers if all(k in r.layers for r in rasters)]
    weighted = "elevation_std" in names
    out: dict[str, np.ndarray] = {}
    with warnings.catch_warnings(), np.errstate(invalid="ignore", divide="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN pixels: NaN, as meant
        for k in names:
            if weighted and k in ("elevation", "elevation_std"):
                continue
            stack = np.stack([r.layers[k].astype(np.float64) for r in rasters])
            out[k] = np.nanmean(stack, axis=0).astype(np.float32)
        if weighted:
            z = np.stack([r.layers["elevation"].astype(np.float64) for r in rasters])
            s = np.stack([r.layers["elevation_std"].astype(np.float64) for r in rasters])
            w = np.where(np.isfinite(z) & np.isfinite(s) & (s > 0), 1.0 / (s * s), 0.0)
            total = w.sum(axis=0)
            mean = np.where(total > 0, (w * np.nan_to_num(z)).sum(axis=0) / total, np.nan)
            out["elevation"] = mean.astype(np.float32)
            out["elevation_std"] = np.where(total > 0, 1.0 / np.sqrt(total), np.nan).astype(
                np.float32
            )
    ordered = {k: out[k] for k in names if k in out}
    return Raster(ordered, first.west, first.north, first.pixel, first.crs)


def default_pixel(lines: Sequence[Line], results: Sequence[dict[str, Any]]) -> float:
    """The larger of the ground cell and half the largest ping spacing, metres."""
    cell = max(float(inv.x[1] - inv.x[0]) for res in results for inv in res.values())
    return max(cell, 0.5 * max(line.ping_spacing for line in lines))


def geotiff_descriptions(datum: str) -> dict[str, str]:
    """File name -> description of the GeoTIFFs of several lines."""
    return {
        "elevation.tif": f"seabed elevation, {DATUMS[datum]}; overlapping lines combined by "
        "inverse-variance weighting where elevation_std.tif exists, else their mean",
        "elevation_std.tif": "standard deviation of the elevation, metres (per line from the "
        "surface fit; combined: 1 / sqrt(sum of 1 / std^2))",
        "reflectivity.tif": "recovered reflectivity R, mean of the lines covering a pixel",
        "mosaic.tif": "evenly illuminated ground-range image (seed Eq. 22), mean of the lines "
        "covering a pixel",
    }


def quicklook_jobs(directory: Path, raster: Raster) -> list[tuple[Path, Callable[[Path], None]]]:
    """(path, writer) jobs of the PNG quick-looks of gridded lines, north up.

    ``elevation.png`` (hillshaded), ``elevation_std.png`` (where the raster has it),
    ``reflectivity.png`` and ``mosaic.png``, each with a colour bar and a scale bar.
    """
    from functools import partial

    from . import quicklook as ql
    from .xtf import std_quicklook

    crs = f", {raster.crs}" if raster.crs else ""
    layers, px = raster.layers, raster.pixel
    jobs: list[tuple[Path, Callable[[Path], None]]] = [
        (
            directory / "elevation.png",
            partial(
                ql.hillshade_png, elevation=layers["elevation"], cell_m=px, title=f"elevation{crs}"
            ),
        ),
        (
            directory / "reflectivity.png",
            partial(
                ql.reflectivity_png,
                values=layers["reflectivity"],
                cell_m=px,
                title=f"reflectivity{crs}",
            ),
        ),
        (
            directory / "mosaic.png",
            partial(ql.mosaic_png, values=layers["mosaic"], pixel=px, title=f"mosaic{crs}"),
        ),
    ]
    if "elevation_std" in layers:
        std = std_quicklook(layers["elevation_std"], px, f"elevation std{crs}")
        jobs.append((directory / "elevation_std.png", std))
    return jobs
