"""Inversion of XTF files and georeferenced products (GeoTIFF) from their navigation.

Both sides are inverted separately (:func:`.solver.invert`) with the altitude of
:func:`.bottom.track_bottom`, on intensity = sample² (XTF side-scan samples are
envelope amplitudes) with the leading transmit-pulse bins set to 0; each side's products
go to ``DIR/port`` and ``DIR/starboard`` (:func:`sonar_raster.inversion.write.write_products`).
With navigation, the maps of both sides are placed on the ground and gridded into one raster
each:

- The side-scan fan is perpendicular to the vehicle's axis, so a pitch p (nose up > 0)
  tilts it: the inversion's Z (negative below the transducer) runs along the fan's "down",
  ``sin p`` along track and ``−cos p`` vertical, and its altitude (the first return) is
  ``h / cos p``. Ground cell j of ping i on side s (s = +1 starboard, −1 port) lies at
  ``p_i + s x_j u_i − Z_ij sin(p_i) a_i`` and at height ``Z_ij cos(p_i)`` below the
  transducer: ``p_i`` the ping's position (easting, northing), ``u_i = (cos h, −sin h)``
  the starboard unit vector and ``a_i = (sin h, cos h)`` the along-track one for compass
  heading h, ``x_j`` the ground range. With the nose down the seabed seen lies behind. (On
  the OpenSidescan sample, pitched −22° for half the file, the tracked first return times
  cos p is 0.60 m above the file's altitude in the median, against 0.73 m without.)
- The samples are splatted by footprints (:func:`grid`): port and starboard joined into one
  swath, each quadrilateral between two neighbouring pings and cells spread over the pixels it
  covers with bilinear values and area weights, so the raster has no gaps inside the swath
  (the earlier point gridding, ``method="points"``, left 0.97 % of the sample file's swath
  empty). The raster's extent is that of the track after :func:`sonar_raster.io.xtf.track_jumps`
  (positions that jump off the track are interpolated), so one bad fix cannot stretch it; a
  raster above :data:`MAX_GRID_CELLS` pixels, or more than :data:`MAX_GRID_SAMPLES` samples,
  is refused; the splats go a chunk at a time, so memory follows the raster.
- CRS: files in degrees are projected to the UTM zone of their first fix (WGS 84, EPSG
  326xx/327xx, via rasterio/PROJ); files in metres keep their coordinates with no CRS (XTF
  does not say which projection).
- ``elevation.tif`` is the seabed elevation relative to the sea surface, ``Z cos p −
  depth`` (metres, negative down), when the file records the sensor depth, else ``Z cos p``
  relative to the transducer; ``reflectivity.tif`` is R; ``mosaic.tif`` the evenly
  illuminated ground-range image (:func:`mosaic_values`).
- PNG quick-looks of the products, with colour and scale bars: :func:`quicklook_jobs`.
- ``method="surface"`` fits both sides as one surface (:func:`.surface.invert_lines`); its
  ``elevation_std`` is gridded as a variance and written as ``elevation_std.tif``. Several
  files or lines are gridded together by :mod:`.lines`.
"""

from __future__ import annotations

import logging
import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from .._checks import positive
from ..errors import SonarRasterError
from ..image import SonarImage
from ..io.xtf import XtfNavigation, read_xtf, track_jumps
from .bottom import BottomTrack, track_bottom

log = logging.getLogger(__name__)

#: Most pixels :func:`grid` makes (16 bytes per layer each while gridding, 4 per layer after).
MAX_GRID_CELLS = 100_000_000
#: Most samples gridded after the along-track interpolation (about 60 bytes each).
MAX_GRID_SAMPLES = 30_000_000

GEOTIFFS = {
    "elevation.tif": "seabed elevation, metres (relative to the sea surface when the file "
    "records the sensor depth, else to the transducer), negative down",
    "reflectivity.tif": "recovered reflectivity R",
    "mosaic.tif": "evenly illuminated ground-range image of both sides (seed Eq. 22: the "
    "ground image over the recovered beam and incidence cosine; R-like)",
    "elevation_std.tif": "standard deviation of the elevation, metres (--method surface only)",
}

QUICKLOOKS = {
    "waterfall.png": "the recorded image in dB, port on the left (intensity = sample² for "
    "amplitude samples)",
    "mosaic.png": "mosaic.tif in dB, north up",
    "elevation.png": "elevation.tif hillshaded (light from the north-west), coloured by height",
    "reflectivity.png": "reflectivity.tif",
    "elevation_std.png": "elevation_std.tif (--method surface)",
}


@dataclass(frozen=True)
class XtfInversion:
    """An XTF file's image, navigation, bottom track and per-side inversions."""

    image: SonarImage
    navigation: XtfNavigation
    track: BottomTrack
    sides: dict  # side name -> sonar_raster.inversion.solver.Inversion
    blanking: int
    amplitude: bool = True  # the samples were squared into intensity


@dataclass(frozen=True)
class Raster:
    """Gridded maps, north up: ``layers`` name -> (rows, cols) float32, NaN = no data.

    ``west``/``north`` are the outer corner of pixel (0, 0), ``pixel`` the pixel size in
    metres, ``crs`` an "EPSG:nnnn" string or None.
    """

    layers: dict[str, np.ndarray]
    west: float
    north: float
    pixel: float
    crs: str | None

    @property
    def transform(self):
        """The rasterio affine transform (built directly: ``from_origin`` warns in affine 3)."""
        from affine import Affine

        return Affine(self.pixel, 0.0, self.west, 0.0, -self.pixel, self.north)


def invert_xtf(
    path: str | Path,
    *,
    pings: slice | None = None,
    sides: tuple[str, ...] | None = None,
    altitude: float | None = None,
    ping_spacing: float | None = None,
    amplitude: bool = True,
    progress: bool = False,
    method: str = "profiles",
    recording: tuple | None = None,
    frequency: float | str | None = None,
    **options,
) -> XtfInversion:
    """Read an XTF file, track the bottom and invert each side.

    Parameters
    ----------
    path : str or Path
        The XTF file.
    pings : slice, optional
        Ping range to invert.
    sides : tuple of str, optional
        Sides to invert (default: every side in the file).
    altitude : float, optional
        Fixed altitude in metres instead of the bottom track.
    ping_spacing : float, optional
        Along-track spacing, metres (default: the mean spacing of the navigation).
    amplitude : bool
        The samples are envelope amplitudes, so the intensity inverted is their square (true
        of the OpenSidescan sample: its samples have the speckle contrast of a Rayleigh
        amplitude, 0.48, and their squares that of an intensity, 1.1). False inverts the
        samples as they are.
    progress : bool
        Progress bars.
    method : {"profiles", "surface"}
        ``"profiles"``: :func:`.solver.invert` per side; ``"surface"``: one surface for both
        sides (:func:`.surface.invert_lines`, with ``elevation_std``).
    recording : tuple, optional
        ``read_xtf(path, pings)`` already done (image, navigation): the file is not read again.
    frequency : float or {"low", "high"}, optional
        Dual-frequency files: the channels to read (``read_xtf``'s ``frequency``).
    **options
        Passed to :func:`.solver.invert` (``max_iter``, ``levels``, ``tol``,
        ``beam``); for ``"surface"`` only ``max_iter``, ``looks``, ``beam``, ``finest`` and
        ``law`` (a :class:`.law.ScatteringLaw`, or a sediment's name taken at the file's
        recorded frequency).

    Returns
    -------
    XtfInversion
    """
    from .bottom import blanking_bins
    from .solver import invert

    image, nav = read_xtf(path, pings, frequency) if recording is None else recording
    dr = image.sonar.range_bin
    track = track_bottom(image.sides, dr)
    if altitude is not None:  # 0 is an error, not "track it"
        positive("altitude (metres)", altitude)
    given = None if altitude is None else np.full(image.shape[0], float(altitude))
    alt = track.altitude if given is None else given
    if ping_spacing is None and nav.valid.sum() >= 2:
        spacing = nav.along_track_spacing()
        ping_spacing = spacing if math.isfinite(spacing) else None
    chosen = sides or tuple(image.sides)
    missing = [s for s in chosen if s not in image.sides]
    if missing:
        raise SonarRasterError(f"{path} has no {', '.join(missing)} channel")
    slants, blank = {}, 0
    for side in chosen:
        slant = image.sides[side].astype(np.float64)
        if amplitude:
            slant *= slant
        blank = max(blank, blanking_bins(slant))
        slants[side] = slant
    for slant in slants.values():
        slant[:, :blank] = 0.0  # the transmit pulse is not seabed
    if method == "surface":
        from .law import resolve_law
        from .lines import surface_options
        from .surface import Line, invert_lines

        line = Line.straight(
            slants, dr, ping_spacing or dr,
            altitude=given, law=resolve_law(options.get("law"), image.sonar.frequency_hz),
        )  # fmt: skip
        results = invert_lines(
            [line], progress=print if progress else None, **surface_options(options)
        )[0]
    elif method == "profiles":
        results = {
            side: invert(
                slant, dr, altitude=alt, ping_spacing=ping_spacing, progress=progress, **options
            )
            for side, slant in slants.items()
        }
    else:
        raise SonarRasterError(f"unknown method {method!r}; use profiles or surface")
    return XtfInversion(image, nav, track, results, blank, amplitude)


def ground_positions(
    east: np.ndarray,
    north: np.ndarray,
    heading: np.ndarray,
    pitch: np.ndarray,
    x: np.ndarray,
    elevation: np.ndarray,
    side: str,
) -> tuple[np.ndarray, np.ndarray]:
    """Easting and northing of each ground cell, each shape (pings, cells), metres.

    ``east``, ``north``, ``heading`` (compass, radians), ``pitch`` (nose up, radians) have
    shape (pings,); ``x`` (cells,) is the ground range; ``elevation`` (pings, cells) the
    recovered Z relative to the transducer along the fan's "down" (NaN is taken as the
    ping's median).
    """
    s = 1.0 if side == "starboard" else -1.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # an all-NaN ping gives NaN, then 0
        median = np.nanmedian(elevation, axis=1)[:, None]
    z = np.nan_to_num(np.where(np.isfinite(elevation), elevation, median), nan=0.0)
    along = -z * np.sin(pitch)[:, None]
    h = heading[:, None]
    e = east[:, None] + s * x[None, :] * np.cos(h) + along * np.sin(h)
    n = north[:, None] - s * x[None, :] * np.sin(h) + along * np.cos(h)
    return e, n


def _densify(a: np.ndarray, factor: int) -> np.ndarray:
    """Linear interpolation between consecutive rows, ``factor`` rows per interval."""
    if factor <= 1 or len(a) < 2:
        return a
    t = (np.arange(factor) / factor)[None, :, None]
    mid = a[:-1, None, :] * (1.0 - t) + a[1:, None, :] * t
    return np.concatenate([mid.reshape(-1, a.shape[1]), a[-1:]], axis=0)


#: Gridding methods of :func:`grid`.
GRID_METHODS = ("footprint", "points")
#: Most sub-samples per footprint side (a footprint longer than this many half pixels, at a
#: sharp turn or a navigation jump, is sampled more sparsely and may leave holes).
MAX_SPLIT = 256
#: Sub-samples handled at once while splatting (bounds the working memory, ~100 bytes each).
_CHUNK = 1 << 20


def grid(
    samples: list[tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]],
    pixel: float,
    crs: str | None,
    along_factor: int = 1,
    method: str = "footprint",
    frame: tuple[float, float, int, int] | None = None,
) -> Raster:
    """Grid samples on a north-up raster: each pixel the area-weighted mean of what covers it.

    ``"footprint"`` (default) splats the samples over the ground between them: the
    quadrilaterals between each two neighbouring pings and each two neighbouring ground cells
    tile the swath without gaps, whatever the ping spacing, heading changes or pixel size.
    Each is sampled on a k_a × k_x grid in its bilinear coordinates, fine enough that the
    sub-samples lie at most half a pixel apart (a pixel inside the swath then always holds
    one), each weighted by the quadrilateral's area / (k_a k_x) and carrying the bilinear
    interpolation of its four corner samples (a NaN corner is left out and the others'
    weights renormalised), so each sample spreads over its ping spacing × ground cell with
    tent weights and a linear field is gridded exactly (to the pixel's centroid). ``"points"``
    is the earlier point gridding (kept as the baseline of ``tools/bench_mosaic.py``): samples
    interpolated linearly along track, ``along_factor`` per ping interval, then the plain mean
    of the points inside each pixel; it leaves holes where the samples are sparser than the
    pixels.

    Parameters
    ----------
    samples : list of (east, north, layers)
        Per side: positions, each (pings, cells) with cells in ground-range order, and
        layer name -> values (pings, cells). Samples at non-finite positions are left out; a
        non-finite value is left out of its layer only.
    pixel : float
        Pixel size, metres.
    crs : str or None
        CRS of the positions.
    along_factor : int
        ``"points"`` only: samples per ping interval after linear interpolation along track;
        lowered (with a logged note) to keep the samples within :data:`MAX_GRID_SAMPLES`.
    method : {"footprint", "points"}
        How samples are spread over pixels.
    frame : (west, north, rows, cols), optional
        The raster's outer west and north edges (metres) and size (default: spanning the
        samples, :func:`raster_frame`), e.g. one frame shared by several lines.

    Returns
    -------
    Raster
        Spanning the sample positions (or ``frame``); a pixel nothing covers is NaN.

    Raises
    ------
    SonarRasterError
        When the raster would have more than :data:`MAX_GRID_CELLS` pixels, there are more
        than :data:`MAX_GRID_SAMPLES` samples, or no sample has a finite position.
    """
    if not (math.isfinite(pixel) and pixel > 0):
        raise SonarRasterError(f"the pixel size must be a positive number of metres, got {pixel}")
    if method not in GRID_METHODS:
        raise SonarRasterError(f"unknown gridding {method!r}; use one of {', '.join(GRID_METHODS)}")
    west, top, rows, cols = frame or raster_frame(samples, pixel)
    if method == "points":
        return _grid_points(samples, pixel, crs, along_factor, (west, top, rows, cols))
    _affordable_factor(samples, 1)  # the same refusal of too many samples
    names = list(samples[0][2])
    total = {k: np.zeros(rows * cols) for k in names}
    weight = {k: np.zeros(rows * cols) for k in names}
    for side in samples:
        east, north, layers = _two_by_two(side)
        cells = east.shape[1]
        for flat, w, corner, bilinear in _splats(east, north, pixel, (west, top, rows, cols)):
            for k in names:
                v = layers[k].ravel()
                num = np.zeros(len(flat))
                den = np.zeros(len(flat))
                for offset, b in zip((0, cells, 1, cells + 1), bilinear, strict=True):
                    vc = v[corner + offset]
                    ok = np.isfinite(vc)
                    num += b * np.where(ok, vc, 0.0)
                    den += b * ok
                total[k] += np.bincount(flat, weights=w * num, minlength=rows * cols)
                weight[k] += np.bincount(flat, weights=w * den, minlength=rows * cols)
    out = {}
    for k in names:
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(weight[k] > 0, total[k] / weight[k], np.nan)
        out[k] = mean.reshape(rows, cols).astype(np.float32)
        del total[k], weight[k]
    return Raster(out, west, top, pixel, crs)


def _two_by_two(
    side: tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]],
) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """Positions and layers as float64, a single ping or cell repeated (a zero-width strip)."""

    def pad(a: np.ndarray) -> np.ndarray:
        a = np.asarray(a, dtype=np.float64)
        for axis in (0, 1):
            if a.shape[axis] == 1:
                a = np.repeat(a, 2, axis=axis)
        return a

    east, north, layers = side
    return pad(east), pad(north), {k: pad(v) for k, v in layers.items()}


def _splats(
    east: np.ndarray, north: np.ndarray, pixel: float, frame: tuple[float, float, int, int]
):
    """Footprint sub-samples landing on the raster, a chunk at a time.

    Yields (flat pixel index, weight, flat index of each sub-sample's corner (i, j), bilinear
    weights of its corners (i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)).
    """
    west, top, rows, cols = frame
    p = np.stack([east, north], axis=-1)
    p = np.where(np.isfinite(p), p, np.nan)  # inf - inf would warn; NaN propagates quietly
    c00, c10, c01, c11 = p[:-1, :-1], p[1:, :-1], p[:-1, 1:], p[1:, 1:]
    ok = np.isfinite(p).all(-1)
    ok = ok[:-1, :-1] & ok[1:, :-1] & ok[:-1, 1:] & ok[1:, 1:]
    d1, d2 = c11 - c00, c01 - c10
    area = 0.5 * np.abs(d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0])
    area = np.where(ok, area + 1e-9 * pixel * pixel, 0.0)  # a zero-width strip still counts

    def split(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
        longest = np.maximum(np.linalg.norm(b - a, axis=-1), np.linalg.norm(d - c, axis=-1))
        per_row = np.max(np.where(ok, longest, 0.0), axis=1)
        return np.clip(np.ceil(2.0 * per_row / pixel), 1, MAX_SPLIT).astype(np.int64)

    ka, kx = split(c00, c10, c01, c11), split(c00, c01, c10, c11)
    if np.any(ka == MAX_SPLIT) or np.any(kx == MAX_SPLIT):
        log.warning(
            "georeferencing: some footprints are over %d half pixels long (a sharp turn or a "
            "navigation jump); they are sampled more sparsely and may leave holes",
            MAX_SPLIT,
        )
    quads = c00.shape[1]
    for a_split, x_split in sorted(set(zip(ka.tolist(), kx.tolist(), strict=True))):
        group = np.flatnonzero((ka == a_split) & (kx == x_split))
        step = max(1, _CHUNK // (quads * a_split * x_split))
        s = ((np.arange(a_split) + 0.5) / a_split)[None, None, :, None]
        t = ((np.arange(x_split) + 0.5) / x_split)[None, None, None, :]
        bilinear = ((1 - s) * (1 - t), s * (1 - t), (1 - s) * t, s * t)
        for lo in range(0, len(group), step):
            i = group[lo : lo + step]
            pts = sum(q[i][:, :, None, None, :] * b[..., None]
                      for q, b in zip((c00, c10, c01, c11), bilinear, strict=True))  # fmt: skip
            col = np.floor((pts[..., 0] - west) / pixel)
            row = np.floor((top - pts[..., 1]) / pixel)
            shape = col.shape
            w = np.broadcast_to((area[i] / (a_split * x_split))[:, :, None, None], shape)
            corner = np.broadcast_to(
                (i[:, None] * (quads + 1) + np.arange(quads)[None, :])[:, :, None, None], shape
            )
            inside = (w > 0) & (col >= 0) & (col < cols) & (row >= 0) & (row < rows)
            flat = row[inside].astype(np.int64) * cols + col[inside].astype(np.int64)
            yield (flat, w[inside], corner[inside],
                   [np.broadcast_to(b, shape)[inside] for b in bilinear])  # fmt: skip


def _grid_points(
    samples: list[tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]],
    pixel: float,
    crs: str | None,
    along_factor: int,
    frame: tuple[float, float, int, int],
) -> Raster:
    """The ``"points"`` method of :func:`grid`."""
    west, top, rows, cols = frame
    factor = _affordable_factor(samples, along_factor)
    names = list(samples[0][2])

    def dense(pick) -> np.ndarray:
        return np.concatenate([_densify(pick(s), factor).ravel() for s in samples])

    east, north = dense(lambda s: s[0]), dense(lambda s: s[1])
    placed = np.isfinite(east) & np.isfinite(north)
    flat = ((top - north[placed]) // pixel).astype(np.int64) * cols + (
        (east[placed] - west) // pixel
    ).astype(np.int64)
    del east, north
    layers = {}
    for k in names:
        v = dense(lambda s, k=k: s[2][k])[placed]
        ok = np.isfinite(v)
        total = np.bincount(flat[ok], weights=v[ok], minlength=rows * cols)
        count = np.bincount(flat[ok], minlength=rows * cols)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(count > 0, total / np.maximum(count, 1), np.nan)
        layers[k] = mean.reshape(rows, cols).astype(np.float32)
    return Raster(layers, west, top, pixel, crs)


def raster_frame(
    samples: list[tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]], pixel: float
) -> tuple[float, float, int, int]:
    """West and north edges, rows and columns of the raster spanning ``samples``.

    The edges are whole multiples of ``pixel``, so the frames of any samples share one pixel
    lattice. Refused (:class:`SonarRasterError`) beyond :data:`MAX_GRID_CELLS` pixels.
    """
    lo, hi = np.full(2, np.inf), np.full(2, -np.inf)
    for e, n, _ in samples:
        placed = np.isfinite(e) & np.isfinite(n)
        if placed.any():
            for axis, v in enumerate((e[placed], n[placed])):
                lo[axis], hi[axis] = min(lo[axis], v.min()), max(hi[axis], v.max())
    if not np.all(np.isfinite(np.concatenate([lo, hi]))):
        raise SonarRasterError("no sample has a finite ground position: nothing to grid")
    west, top = math.floor(lo[0] / pixel) * pixel, math.ceil(hi[1] / pixel) * pixel
    cols = int((hi[0] - west) // pixel) + 1
    rows = int((top - lo[1]) // pixel) + 1
    if rows * cols > MAX_GRID_CELLS:
        raise SonarRasterError(
            f"the georeferenced raster would be {rows} x {cols} pixels of {pixel:.3g} m "
            f"({rows * cols * 48 / 2**30:.0f} GiB to grid) over {hi[0] - lo[0]:.0f} x "
            f"{hi[1] - lo[1]:.0f} m; grid fewer pings (--pings A:B) or larger pixels"
        )
    return west, top, rows, cols


def _affordable_factor(
    samples: list[tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]], factor: int
) -> int:
    """``factor``, lowered so the interpolated samples stay within MAX_GRID_SAMPLES."""
    pings, cells = max(len(e) for e, _, _ in samples), sum(e.shape[1] for e, _, _ in samples)
    if pings * cells > MAX_GRID_SAMPLES:
        raise SonarRasterError(
            f"{pings} pings of {cells} ground cells are {pings * cells} samples to grid, more "
            f"than {MAX_GRID_SAMPLES}; grid fewer pings (--pings A:B)"
        )
    intervals = max(pings - 1, 1)
    fit = max(1, (MAX_GRID_SAMPLES // max(cells, 1) - 1) // intervals)
    if factor > fit:
        log.warning(
            "georeferencing: %d samples per ping interval instead of %d (memory); the rasters "
            "may show gaps between pings (grid fewer pings for full coverage)",
            fit,
            factor,
        )
        return fit
    return max(1, factor)


def world_elevation(result: XtfInversion) -> dict[str, np.ndarray]:
    """Each side's elevation in the vertical of the world, metres, shape (pings, cells).

    ``Z cos(pitch)`` (Z is in the pitched fan, relative to the transducer) minus the sensor's
    depth (interpolated over pings without a fix), so relative to the sea surface; relative to
    the transducer when the file has no depth.
    """
    nav = result.navigation
    pitch = nav.filled("pitch")
    depth = nav.filled("depth")
    shift = depth[:, None] if np.any(depth > 0) else 0.0
    return {
        side: inv.elevation * np.cos(pitch)[:, None] - shift for side, inv in result.sides.items()
    }


def georeference(
    result: XtfInversion, pixel: float | None = None, method: str = "footprint"
) -> Raster:
    """Grid the inversion's elevation, reflectivity and mosaic on the ground.

    Parameters
    ----------
    result : XtfInversion
    pixel : float, optional
        Pixel size in metres (default: the larger of the ground cell and half the ping
        spacing).
    method : {"footprint", "points"}
        Gridding of :func:`grid`: each sample's footprint splatted (default), or the earlier
        point gridding (the benchmark's baseline).

    Returns
    -------
    Raster
        Layers ``elevation``, ``reflectivity`` and ``mosaic`` (:func:`mosaic_values`), and
        ``elevation_std`` where every side has one (the surface fit; gridded as a variance).

    Raises
    ------
    SonarRasterError
        When the file has no navigation, or the raster would be too large (see :func:`grid`).
    """
    nav = result.navigation
    if not nav.valid.any():
        raise SonarRasterError("the file has no navigation: no GeoTIFF can be placed")
    east, north = robust_track(nav)
    heading = nav.filled_heading()
    pitch = nav.filled("pitch")
    levels = world_elevation(result)
    spacing = nav.along_track_spacing()
    first = next(iter(result.sides.values()))
    dx = float(first.x[1] - first.x[0])
    px = float(pixel or max(dx, 0.5 * spacing if math.isfinite(spacing) else dx))
    if nav.valid.sum() >= 2:  # points: samples at most half a pixel apart along track
        step = float(np.max(np.hypot(np.diff(east), np.diff(north)), initial=0.0))
        factor = max(1, int(math.ceil(2.0 * step / px)))
    else:
        factor = 1
    by_side = {}
    with_std = all(getattr(i, "elevation_std", None) is not None for i in result.sides.values())
    for side, inv in result.sides.items():
        e, n = ground_positions(east, north, heading, pitch, inv.x, inv.elevation, side)
        layers = {
            "elevation": levels[side],
            "reflectivity": inv.reflectivity,
            "mosaic": mosaic_values(inv),
        }
        if with_std:
            layers["elevation_var"] = (inv.elevation_std * np.cos(pitch)[:, None]) ** 2
        by_side[side] = (e, n, layers)
    samples = join_sides(by_side) if method == "footprint" else list(by_side.values())
    raster = grid(samples, px, nav.crs, factor, method=method)
    var = raster.layers.pop("elevation_var", None)
    if var is not None:  # gridded as a variance, written as a standard deviation
        raster.layers["elevation_std"] = np.sqrt(var)
    return raster


def join_sides(
    by_side: dict[str, tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]],
) -> list[tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]]:
    """Port (cells reversed, far to near) and starboard side by side as one swath.

    Gridded by footprints (:func:`grid`), the quadrilaterals between the two sides' nearest
    cells then cover the ground under the track, which two separate sides would leave as a
    gap of one ground cell at nadir.

    Parameters
    ----------
    by_side : dict of str to (east, north, layers)
        Per side ("port", "starboard"): positions and layers, each (pings, cells) from near
        range outward; sides with the same pings.

    Returns
    -------
    list of (east, north, layers)
        One joined swath when both sides are there, else the one side given.
    """
    if set(by_side) != {"port", "starboard"}:
        return list(by_side.values())
    (pe, pn, pl), (se, sn, sl) = by_side["port"], by_side["starboard"]

    def join(p: np.ndarray, s: np.ndarray) -> np.ndarray:
        return np.concatenate([np.asarray(p)[:, ::-1], np.asarray(s)], axis=1)

    return [(join(pe, se), join(pn, sn), {k: join(pl[k], sl[k]) for k in pl})]


def mosaic_values(inv) -> np.ndarray:
    """The mosaic's values for one side, (pings, cells): the evenly illuminated image.

    ``inv.even``, the ground image divided by the recovered beam and the mean incidence
    cosine (seed Eq. 22; R-like, equal to R on a level seabed), so the near-nadir cells,
    which the tilted vertical beam barely lights (on the OpenSidescan sample the raw return
    1 m out from nadir is 20 dB below that 3-6 m out), do not draw a dark seam down the
    mosaic. Without it (None, or a result that has none), ``inv.ground``: intensity per metre
    of ground range over a flat seabed.

    Parameters
    ----------
    inv : sonar_raster.inversion.solver.Inversion
        One side's inversion.
    """
    even = getattr(inv, "even", None)
    return np.asarray(inv.ground if even is None else even, dtype=np.float64)


def robust_track(nav: XtfNavigation) -> tuple[np.ndarray, np.ndarray]:
    """Projected positions per ping, those that jump off the track interpolated."""
    east, north = nav.projected()
    jumps = track_jumps(east, north, nav.time)
    if jumps.any() and not jumps.all():
        k, good = np.arange(len(east)), np.flatnonzero(~jumps)
        east, north = np.interp(k, good, east[good]), np.interp(k, good, north[good])
    return east, north


def _write_geotiff(tmp: Path, values: np.ndarray, raster: Raster, description: str) -> None:
    import rasterio

    profile = {
        "driver": "GTiff",
        "height": values.shape[0],
        "width": values.shape[1],
        "count": 1,
        "dtype": "float32",
        "transform": raster.transform,
        "nodata": float("nan"),
        "compress": "deflate",
    }
    if raster.crs:
        profile["crs"] = raster.crs
    with rasterio.open(tmp, "w", **profile) as dst:
        dst.write(values, 1)
        dst.update_tags(description=description, pixel_size_m=str(raster.pixel))
        if not raster.crs:
            dst.update_tags(crs="unknown: the XTF file's projected coordinates, metres")


def geotiff_jobs(
    directory: Path, raster: Raster, descriptions: dict[str, str] | None = None
) -> list[tuple[Path, Callable[[Path], None]]]:
    """(path, writer) jobs for :func:`sonar_raster.io.commit.commit`, one GeoTIFF per layer.

    ``descriptions`` maps file names (``"elevation.tif"``) to the text tagged into each
    (default :data:`GEOTIFFS`); a file whose layer the raster lacks is left out.
    """
    jobs: list[tuple[Path, Callable[[Path], None]]] = []
    for name, description in (descriptions or GEOTIFFS).items():
        layer = raster.layers.get(name.removesuffix(".tif"))
        if layer is None:
            continue
        jobs.append((directory / name, partial(_write_geotiff, values=layer, raster=raster,
                                               description=description)))  # fmt: skip
    return jobs


def quicklook_jobs(
    directory: Path, result: XtfInversion, raster: Raster | None
) -> list[tuple[Path, Callable[[Path], None]]]:
    """(path, writer) jobs of the PNG quick-looks (:data:`QUICKLOOKS`) of a file's products.

    ``waterfall.png`` always; with a raster, ``mosaic.png``, ``elevation.png`` (hillshaded)
    and ``reflectivity.png`` of its layers, north up. Each has a colour bar and a scale bar
    (:mod:`sonar_raster.inversion.quicklook`).

    Parameters
    ----------
    directory : Path
        Output folder.
    result : XtfInversion
        The file's inversion (its image makes the waterfall).
    raster : Raster or None
        Its georeferenced layers (:func:`georeference`), None without navigation.
    """
    from . import quicklook as ql

    image = result.image
    sides = {k: np.asarray(v, dtype=np.float64) for k, v in image.sides.items()}
    if result.amplitude:
        sides = {k: v * v for k, v in sides.items()}
    spacing = result.navigation.along_track_spacing() if result.navigation.valid.sum() >= 2 else 0
    waterfall = partial(
        ql.waterfall_png, sides=sides, range_bin=image.sonar.range_bin,
        ping_spacing=spacing if math.isfinite(spacing) and spacing > 0 else None,
    )  # fmt: skip
    jobs: list[tuple[Path, Callable[[Path], None]]] = [(directory / "waterfall.png", waterfall)]
    if raster is None:
        return jobs
    crs = f", {raster.crs}" if raster.crs else ""
    layers, px = raster.layers, raster.pixel
    jobs += [
        (directory / "mosaic.png", partial(ql.mosaic_png, values=layers["mosaic"], pixel=px,
                                           title=f"mosaic{crs}")),
        (directory / "elevation.png", partial(ql.hillshade_png, elevation=layers["elevation"],
                                              cell_m=px, title=f"elevation{crs}")),
        (directory / "reflectivity.png", partial(ql.reflectivity_png,
                                                 values=layers["reflectivity"], cell_m=px,
                                                 title=f"reflectivity{crs}")),
    ]  # fmt: skip
    if "elevation_std" in layers:
        std = std_quicklook(layers["elevation_std"], px, f"elevation std{crs}")
        jobs.append((directory / "elevation_std.png", std))
    return jobs


def std_quicklook(values: np.ndarray, pixel: float, title: str) -> Callable[[Path], None]:
    """Writer of a north-up PNG of the elevation's standard deviation (metres)."""
    from . import quicklook as ql

    return partial(ql.map_png, values=values, cell_m=pixel, cmap="magma",
                   label="std of elevation, m", title=title, north_up=True)  # fmt: skip
