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
- Between consecutive pings the cells are interpolated linearly (positions and values) so
  the raster has no along-track gaps; each pixel takes the mean of the samples inside it.
  The raster's extent is that of the track after :func:`sonar_raster.io.xtf.track_jumps`
  (positions that jump off the track are interpolated), so one bad fix cannot stretch it; a
  raster above :data:`MAX_GRID_CELLS` pixels is refused, and the along-track interpolation is
  thinned to stay within :data:`MAX_GRID_SAMPLES` samples.
- CRS: files in degrees are projected to the UTM zone of their first fix (WGS 84, EPSG
  326xx/327xx, via rasterio/PROJ); files in metres keep their coordinates with no CRS (XTF
  does not say which projection).
- ``elevation.tif`` is the seabed elevation relative to the sea surface, ``Z cos p −
  depth`` (metres, negative down), when the file records the sensor depth, else ``Z cos p``
  relative to the transducer; ``reflectivity.tif`` is R; ``mosaic.tif`` the ground-range
  image (intensity per metre of ground range over a flat seabed at the tracked altitude).
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

from ..errors import SonarRasterError
from ..image import SonarImage
from ..io.xtf import XtfNavigation, read_xtf, track_jumps
from .bottom import BottomTrack, track_bottom

log = logging.getLogger(__name__)

#: Most pixels :func:`grid` makes (about 40 bytes each while gridding, 4 per layer after).
MAX_GRID_CELLS = 100_000_000
#: Most samples gridded after the along-track interpolation (about 60 bytes each).
MAX_GRID_SAMPLES = 30_000_000

GEOTIFFS = {
    "elevation.tif": "seabed elevation, metres (relative to the sea surface when the file "
    "records the sensor depth, else to the transducer), negative down",
    "reflectivity.tif": "recovered reflectivity R",
    "mosaic.tif": "ground-range image of both sides (flat seabed at the tracked altitude)",
}


@dataclass(frozen=True)
class XtfInversion:
    """An XTF file's image, navigation, bottom track and per-side inversions."""

    image: SonarImage
    navigation: XtfNavigation
    track: BottomTrack
    sides: dict  # side name -> sonar_raster.inversion.solver.Inversion
    blanking: int


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
    **options
        Passed to :func:`.solver.invert` (``max_iter``, ``levels``, ``tol``,
        ``beam``).

    Returns
    -------
    XtfInversion
    """
    from .bottom import blanking_bins
    from .solver import invert

    image, nav = read_xtf(path, pings)
    dr = image.sonar.range_bin
    track = track_bottom(image.sides, dr)
    alt = np.full(image.shape[0], float(altitude)) if altitude else track.altitude
    if ping_spacing is None and nav.valid.sum() >= 2:
        spacing = nav.along_track_spacing()
        ping_spacing = spacing if math.isfinite(spacing) else None
    chosen = sides or tuple(image.sides)
    missing = [s for s in chosen if s not in image.sides]
    if missing:
        raise SonarRasterError(f"{path} has no {', '.join(missing)} channel")
    results, blank = {}, 0
    for side in chosen:
        slant = image.sides[side].astype(np.float64)
        if amplitude:
            slant *= slant
        blank = max(blank, blanking_bins(slant))
        slant[:, :blank] = 0.0  # the transmit pulse is not seabed
        results[side] = invert(
            slant, dr, altitude=alt, ping_spacing=ping_spacing, progress=progress, **options
        )
    return XtfInversion(image, nav, track, results, blank)


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


def grid(
    samples: list[tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]],
    pixel: float,
    crs: str | None,
    along_factor: int = 1,
) -> Raster:
    """Mean of the samples falling in each pixel of a north-up raster.

    Parameters
    ----------
    samples : list of (east, north, layers)
        Per side: positions, each (pings, cells), and layer name -> values (pings, cells).
        Samples at non-finite positions are left out.
    pixel : float
        Pixel size, metres.
    crs : str or None
        CRS of the positions.
    along_factor : int
        Samples per ping interval after linear interpolation along track; lowered (with a
        logged note) to keep the samples within :data:`MAX_GRID_SAMPLES`.

    Raises
    ------
    SonarRasterError
        When the raster would have more than :data:`MAX_GRID_CELLS` pixels, there are more
        than :data:`MAX_GRID_SAMPLES` samples before interpolation, or no sample has a finite
        position.
    """
    if not (math.isfinite(pixel) and pixel > 0):
        raise SonarRasterError(f"the pixel size must be a positive number of metres, got {pixel}")
    west, top, rows, cols = _extent(samples, pixel)
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


def _extent(
    samples: list[tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]], pixel: float
) -> tuple[float, float, int, int]:
    """West and north edges, rows and columns of the raster; refused beyond MAX_GRID_CELLS."""
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
            f"({rows * cols * 40 / 2**30:.0f} GiB to grid) over {hi[0] - lo[0]:.0f} x "
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


def georeference(result: XtfInversion, pixel: float | None = None) -> Raster:
    """Grid the inversion's elevation, reflectivity and ground-range image on the ground.

    Parameters
    ----------
    result : XtfInversion
    pixel : float, optional
        Pixel size in metres (default: the larger of the ground cell and half the ping
        spacing).

    Raises
    ------
    SonarRasterError
        When the file has no navigation, or the raster would be too large (see :func:`grid`).
    """
    nav = result.navigation
    if not nav.valid.any():
        raise SonarRasterError("the file has no navigation: no GeoTIFF can be placed")
    east, north = _robust_track(nav)
    heading = nav.filled_heading()
    pitch = nav.filled("pitch")
    ok = nav.valid & np.isfinite(nav.depth)
    k = np.arange(len(nav.valid))
    depth = np.interp(k, np.flatnonzero(ok), nav.depth[ok]) if ok.any() else nav.filled("depth")
    has_depth = bool(np.any(depth > 0))
    spacing = nav.along_track_spacing()
    first = next(iter(result.sides.values()))
    dx = float(first.x[1] - first.x[0])
    px = float(pixel or max(dx, 0.5 * spacing if math.isfinite(spacing) else dx))
    if nav.valid.sum() >= 2:  # samples at most half a pixel apart along track
        step = float(np.max(np.hypot(np.diff(east), np.diff(north)), initial=0.0))
        factor = max(1, int(math.ceil(2.0 * step / px)))
    else:
        factor = 1
    samples = []
    for side, inv in result.sides.items():
        e, n = ground_positions(east, north, heading, pitch, inv.x, inv.elevation, side)
        z = inv.elevation * np.cos(pitch)[:, None] - (depth[:, None] if has_depth else 0.0)
        layers = {"elevation": z, "reflectivity": inv.reflectivity, "mosaic": inv.ground}
        samples.append((e, n, layers))
    return grid(samples, px, nav.crs, factor)


def _robust_track(nav: XtfNavigation) -> tuple[np.ndarray, np.ndarray]:
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


def geotiff_jobs(directory: Path, raster: Raster) -> list[tuple[Path, Callable[[Path], None]]]:
    """(path, writer) jobs for :func:`sonar_raster.io.commit.commit`, one GeoTIFF per layer."""
    jobs: list[tuple[Path, Callable[[Path], None]]] = []
    for name, description in GEOTIFFS.items():
        layer = raster.layers[name.removesuffix(".tif")]
        jobs.append((directory / name, partial(_write_geotiff, values=layer, raster=raster,
                                               description=description)))  # fmt: skip
    return jobs
