"""First bottom return and the slant-range ↔ ground-range conversion of one side.

Slant bin k covers ``[k, k + 1) * range_bin``; ground cell j has centre
``x_j = (j + 1/2) * ground_bin``. Slant intensities are areas per bin (as the renderer's);
ground intensities are densities per metre of ground range, so the conversion carries the
flat-seabed Jacobian ``dr/dx = x / r``: ``G(x) = I(r) / range_bin * x / r``. Over a flat
seabed rendered by the GL raster, ``G = w Φ R cos θ`` with ``w`` the ping width.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from ..errors import SonarRasterError


def check_slant(slant: np.ndarray, range_bin: float, min_pings: int = 1) -> np.ndarray:
    """A slant-range image (pings x bins, linear, finite, >= 0) as float64, or one clear error."""
    a = np.asarray(slant)
    if a.ndim != 2 or a.shape[0] < min_pings or a.shape[1] < 4:
        raise SonarRasterError(
            f"image must be 2-D with >= {min_pings} ping(s) and >= 4 range bins, got {a.shape}"
        )
    if not np.issubdtype(a.dtype, np.number) or not np.all(np.isfinite(a)):
        raise SonarRasterError("image must hold finite numbers")
    if np.any(a < 0):
        raise SonarRasterError("image intensities must be >= 0 (linear, not dB)")
    if not (math.isfinite(range_bin) and range_bin > 0):
        raise SonarRasterError(f"range bin must be > 0 metres, got {range_bin!r}")
    return a.astype(np.float64)


#: Fraction of the way from the water-column floor to the bright seabed that marks the return.
FIRST_RETURN_FRACTION = 0.05
#: Water-column noise deviations (robust sigma) the return must also exceed.
FIRST_RETURN_SIGMAS = 8.0
#: Along-track median window (pings) applied to the detected altitudes.
ALTITUDE_MEDIAN_PINGS = 9


def first_return(slant: np.ndarray, range_bin: float, pings: int = 1) -> np.ndarray:
    """Altitude of the sonar over the seabed per ping from the first bottom return.

    Each ping is smoothed (Gaussian, 0.75 bins) and the return detected where it first rises
    above ``floor + max(0.05 (p99 − floor), 8 σ)``, ``floor`` and ``σ`` the median and robust
    deviation (1.4826 MAD) of the image's nearest 2 % of bins (the water column) and ``p99`` the
    ping's 99th percentile. The altitude is then where the unsmoothed ping crosses half the
    height of its leading edge (see :func:`_half_rise`), interpolated linearly between bin
    centres: the smoothed crossing of a low
    threshold lies most of a bin before a sharp edge (3 cm early at 5 cm bins), the half-height
    crossing of a step at the step. The altitudes are then
    median filtered over 9 pings, so a ping with a noisy water column or no return takes its
    neighbours' value.

    With ``pings > 1`` each ping is first replaced by the mean of its ``pings`` neighbours
    without the brightest of them per bin (see :func:`_along_track_mean`): on speckled images
    a single ping's leading edge is itself speckled.

    Parameters
    ----------
    slant : ndarray, shape (pings, bins)
        Linear intensity, bins from range 0 outward.
    range_bin : float
        Slant-range bin size, metres.
    pings : int
        Pings averaged around each ping before detection (1: none).

    Returns
    -------
    ndarray, shape (pings,), float64
        Altitude, metres, > 0.

    Raises
    ------
    SonarRasterError
        If no ping shows a bottom return.
    """
    raw = _along_track_mean(np.asarray(slant, dtype=np.float64), pings)
    smooth = ndimage.gaussian_filter1d(raw, 0.75, axis=1)
    water = smooth[:, : max(1, smooth.shape[1] // 50)]
    floor = float(np.median(water))
    sigma = 1.4826 * float(np.median(np.abs(water - floor)))
    top = np.percentile(smooth, 99.0, axis=1)
    rise = np.maximum(FIRST_RETURN_FRACTION * (top - floor), FIRST_RETURN_SIGMAS * sigma)
    threshold = floor + rise
    above = (smooth > threshold[:, None]) & (top > floor)[:, None]
    found = above.any(axis=1)
    if not found.any():
        raise SonarRasterError("no bottom return found in any ping; give --altitude")
    k = np.argmax(above, axis=1)
    alt = (_half_rise(raw, k, floor, threshold) + 0.5) * range_bin
    alt = np.where(found, np.maximum(alt, 0.5 * range_bin), np.nan)
    alt = np.where(found, alt, np.nanmedian(alt))
    return ndimage.median_filter(alt, size=ALTITUDE_MEDIAN_PINGS, mode="nearest")


def _along_track_mean(slant: np.ndarray, pings: int) -> np.ndarray:
    """Mean of each bin over ``pings`` neighbouring pings without the brightest one.

    Averaging independent speckle looks steadies the leading edge; leaving out the brightest
    value keeps a single bright ping (a fish in the water column) from spreading to its
    neighbours. Edge pings repeat at the ends; ``pings < 2`` returns ``slant``.
    """
    if pings < 2 or slant.shape[0] < 2:
        return slant
    total = pings * ndimage.uniform_filter1d(slant, pings, axis=0, mode="nearest")
    brightest = ndimage.maximum_filter1d(slant, pings, axis=0, mode="nearest")
    return np.maximum(total - brightest, 0.0) / (pings - 1)


def _half_rise(raw: np.ndarray, k: np.ndarray, floor: float, threshold: np.ndarray) -> np.ndarray:
    """Sub-bin position (in bin-centre units) of each ping's leading edge.

    The edge starts at the first raw bin from ``k − 2`` to ``k + 2`` (``k`` the smoothed
    detection) above the threshold, else ``k``; its height is the larger of that bin and the
    next; the position is where the raw ping first crosses half that height above the floor,
    interpolated linearly between bin centres. A step of constant height found at a fraction
    ``f`` of a bin is placed at ``f`` for ``f`` = 0 and within a tenth of a bin elsewhere.
    """
    pings, bins = raw.shape
    rows = np.arange(pings)
    cols = np.clip(k[:, None] + np.arange(-2, 3)[None, :], 0, bins - 1)
    window = raw[rows[:, None], cols]
    above = window > threshold[:, None]
    above[:, 0] = False  # the crossing needs a bin before it
    j = np.where(above.any(axis=1), np.argmax(above, axis=1), 2)
    top = np.maximum(window[rows, j], window[rows, np.minimum(j + 1, 4)])
    half = floor + 0.5 * (top - floor)
    j = np.where(window[rows, j] >= half, j, np.minimum(j + 1, 4))
    hi, lo = window[rows, j], window[rows, j - 1]
    step = hi - lo
    frac = np.where(step > 0, (half - lo) / np.where(step > 0, step, 1.0), 1.0)
    return cols[rows, j - 1] + np.clip(frac, 0.0, 1.0)


def ground_axis(altitude: np.ndarray, range_bin: float, bins: int, ground_bin: float) -> np.ndarray:
    """Ground cell centres reaching the farthest ground range any ping sees, shape (cells,)."""
    reach = np.sqrt(max((bins * range_bin) ** 2 - float(np.min(altitude)) ** 2, 0.0))
    cells = int(reach // ground_bin)
    if cells < 2:
        raise SonarRasterError(
            f"altitude {np.min(altitude):g} m leaves fewer than 2 ground cells in "
            f"{bins * range_bin:g} m of range"
        )
    return (np.arange(cells) + 0.5) * ground_bin


def slant_to_ground(
    slant: np.ndarray, range_bin: float, altitude: np.ndarray, x: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Resample a slant-range image onto ground cells over a flat seabed at the altitude.

    Parameters
    ----------
    slant : ndarray, shape (pings, bins)
        Intensity per slant bin.
    range_bin : float
        Slant bin size, metres.
    altitude : ndarray, shape (pings,)
        Sonar altitude per ping, metres.
    x : ndarray, shape (cells,)
        Ground cell centres, evenly spaced, metres.

    Returns
    -------
    ground : ndarray, shape (pings, cells), float64
        Intensity per metre of ground range (0 where invalid).
    valid : ndarray, shape (pings, cells), bool
        Cells whose slant range lies inside the image.
    """
    return sample_ground(
        slant, range_bin, np.broadcast_to(altitude[:, None], (len(altitude), len(x))), x
    )


def sample_ground(
    slant: np.ndarray, range_bin: float, depth: np.ndarray, x: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Resample a slant-range image onto ground cells that lie ``depth`` below the sonar.

    Cell (i, j) takes the slant image at range ``r = sqrt(x_j² + depth_ij²)`` (linear
    interpolation between bin centres) per metre of ground range with the flat-seabed Jacobian
    ``x / r``; :func:`slant_to_ground` is the case of one depth per ping.

    Parameters
    ----------
    slant : ndarray, shape (pings, bins)
        Intensity per slant bin.
    range_bin : float
        Slant bin size, metres.
    depth : ndarray, shape (pings, cells)
        Depth of each ground cell below the transducer, metres (finite).
    x : ndarray, shape (cells,)
        Ground cell centres, metres.

    Returns
    -------
    ground : ndarray, shape (pings, cells), float64
        Intensity per metre of ground range (0 where invalid).
    valid : ndarray, shape (pings, cells), bool
        Cells whose slant range lies inside the image.
    """
    r = np.sqrt(x[None, :] ** 2 + depth**2)
    pos = r / range_bin - 0.5
    bins = slant.shape[1]
    valid = r < bins * range_bin
    k0 = np.clip(np.floor(pos).astype(np.int64), 0, bins - 1)
    k1 = np.minimum(k0 + 1, bins - 1)
    t = np.clip(pos - k0, 0.0, 1.0)
    rows = np.arange(slant.shape[0])[:, None]
    values = (1.0 - t) * slant[rows, k0] + t * slant[rows, k1]
    ground = values / range_bin * (x[None, :] / r)
    return np.where(valid, ground, 0.0), valid


def ground_to_slant(
    ground: np.ndarray, x: np.ndarray, altitude: np.ndarray, range_bin: float, bins: int
) -> np.ndarray:
    """Inverse of :func:`slant_to_ground`: intensity per slant bin, shape (pings, bins).

    Bins nearer than the altitude (water column) and beyond the ground axis are 0. The
    Jacobian ``r / x`` is evaluated at ``x >= dx / 2`` so nadir stays finite.
    """
    dx = float(x[1] - x[0])
    r = (np.arange(bins) + 0.5) * range_bin
    xs = np.sqrt(np.maximum(r[None, :] ** 2 - altitude[:, None] ** 2, 0.0))
    out = np.empty((ground.shape[0], bins))
    for i, row in enumerate(ground):
        out[i] = np.interp(xs[i], x, row, left=row[0], right=0.0)
    xs_safe = np.maximum(xs, 0.5 * dx)
    out *= range_bin * (r[None, :] / xs_safe)
    inside = (r[None, :] >= altitude[:, None]) & (xs <= x[-1] + 0.5 * dx)
    return np.where(inside, out, 0.0)
