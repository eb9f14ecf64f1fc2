"""Bottom tracking: the sonar's altitude per ping from the first bottom return.

Per side and ping the first return is a step in log intensity from the water column to the
seabed. The detector works on ``L = ln(I + ε)`` averaged over 3 neighbouring pings (speckle is
multiplicative, so its log has a fixed spread, π/√6 nepers for fully developed speckle):

1. Leading bins brighter than twice the image's typical level in every ping's median (a
   transmit pulse or saturated blanking, as in real recorders) are skipped.
2. The step score of bin k is the mean of L over the ``window`` bins from k on minus the mean
   over every bin before k (back to the blanking): the water column before the first return
   gives the largest score, later rises (the end of a shadow) are compared with seabed as well
   and score less, and an isolated bright speck in the water column moves the mean of a
   window only a little. The first local maximum of the score above half the ping's largest
   is the edge; the ping's own contrast there (the same step on its own samples, not
   averaged with its neighbours), in dB, must reach ``min_contrast_db`` or the ping has no
   clear return.
3. The sub-bin range is where L crosses the mid level between the two means, the crossing
   nearest the edge, interpolated between bin centres; then again where it crosses halfway
   between the water column and the mean of the 3 bins after that first crossing (the seabed
   often brightens away from nadir, which moves the first crossing out); plus half a bin: a
   sharp edge anywhere inside a bin crosses at about that bin's start, so this centres the
   error (at most half a bin on a clean, sharp edge).
4. Along track, detections further than ``max(3 bins, 5 %)`` from the running median of
   ``smooth_pings`` pings are rejected; the altitude is the running median of the accepted
   detections, interpolated over rejected pings and smoothed by a Gaussian of one ping.

Two sides: over a plane the first return on the up-slope side is the perpendicular distance
``h cos(slope)`` and on the down-slope side the vertical altitude ``h``, while an object only
shortens a side's first return, so :func:`track_bottom` takes the larger of the two sides'
detections per ping where they differ by more than 2 bins, and their mean otherwise.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy import ndimage

from ..errors import SonarRasterError
from .ground import check_slant

__all__ = ["BottomTrack", "first_return", "track_bottom", "track_side"]

#: Bins averaged after a candidate edge.
WINDOW_BINS = 8
#: Contrast between the water column and the seabed a return must reach, dB.
MIN_CONTRAST_DB = 6.0
#: Running-median window along track, pings (odd).
SMOOTH_PINGS = 9
#: Bins just after the first crossing that give the seabed level for the second crossing.
NEAR_BINS = 3
#: Two sides' detections within this many bins are averaged; further apart, the larger wins.
AGREE_BINS = 2.0
#: Pings averaged (in log intensity) before detection.
AVERAGE_PINGS = 5
#: Gaussian smoothing along range before detection, bins (symmetric: a step stays in place).
RANGE_SIGMA_BINS = 1.0
_DB_PER_NEPER = 10.0 / math.log(10.0)


@dataclass(frozen=True)
class BottomTrack:
    """Altitude per ping from the first bottom return.

    Attributes
    ----------
    altitude : ndarray, shape (pings,), float64
        Smoothed altitude in metres, finite for every ping (interpolated where not ``valid``).
    valid : ndarray, shape (pings,), bool
        Pings with a clear return consistent with their neighbours.
    raw : ndarray, shape (pings,), float64
        The per-ping detection in metres before smoothing; NaN where no clear return.
    contrast_db : ndarray, shape (pings,), float64
        Seabed over water-column level at the detected edge, dB.
    """

    altitude: np.ndarray
    valid: np.ndarray
    raw: np.ndarray
    contrast_db: np.ndarray


def _blanking(image: np.ndarray) -> int:
    """Leading bins brighter than twice the typical column median (transmit pulse)."""
    column = np.median(image, axis=0)
    typical = float(np.median(column))
    limit = max(1, image.shape[1] // 20)
    bright = column[:limit] > 2.0 * typical if typical > 0 else np.zeros(limit, bool)
    return int(limit if bright.all() else np.argmin(bright))


def _log_image(image: np.ndarray) -> np.ndarray:
    """ln(I + ε), smoothed along range; ε = 1e-3 of the median positive intensity."""
    positive = image[image > 0]
    eps = 1e-3 * float(np.median(positive)) if positive.size else 1.0
    return ndimage.gaussian_filter1d(np.log(image + eps), RANGE_SIGMA_BINS, axis=1)


def _own_contrast(logs: np.ndarray, lo: int, edge: np.ndarray, window: int) -> np.ndarray:
    """Each ping's own step at ``edge`` (nepers): window mean after minus mean before."""
    pings, bins = logs.shape
    c = np.concatenate([np.zeros((pings, 1)), np.cumsum(logs, axis=1)], axis=1)
    rows = np.arange(pings)
    end = np.minimum(edge + window, bins)
    after = (c[rows, end] - c[rows, edge]) / np.maximum(end - edge, 1)
    before = (c[rows, edge] - c[rows, lo]) / np.maximum(edge - lo, 1)
    return after - before


def _edges(logs: np.ndarray, lo: int, window: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Edge bin, step score (nepers) and water-column level (mean log) per ping."""
    pings, bins = logs.shape
    c = np.concatenate([np.zeros((pings, 1)), np.cumsum(logs[:, lo:], axis=1)], axis=1)
    # edge after k >= window bins of water (relative to lo): fewer make a noisy water mean
    k = np.arange(window, bins - lo - window + 1)
    if len(k) == 0:
        raise SonarRasterError("too few range bins after the transmit pulse to find the bottom")
    after = (c[:, k + window] - c[:, k]) / window
    before = c[:, k] / k
    score = after - before
    top = score.max(axis=1)
    strong = score >= 0.5 * top[:, None]
    first = np.argmax(strong, axis=1)
    rows = np.arange(pings)
    # climb to the local maximum of the first strong run
    peak = first.copy()
    for _ in range(window):
        nxt = np.minimum(peak + 1, len(k) - 1)
        up = score[rows, nxt] > score[rows, peak]
        if not up.any():
            break
        peak = np.where(up, nxt, peak)
    edge = k[peak] + lo
    return edge, score[rows, peak], before[rows, peak]


def _crossing(logs: np.ndarray, edge: np.ndarray, mid: np.ndarray, window: int) -> np.ndarray:
    """Sub-bin position (in bins from range 0) of the rise through ``mid`` nearest the edge."""
    pings, bins = logs.shape
    offsets = np.arange(-window, window + 1)
    j = np.clip(edge[:, None] + offsets[None, :], 1, bins - 1)
    rows = np.arange(pings)[:, None]
    lo_v, hi_v = logs[rows, j - 1], logs[rows, j]
    rise = (lo_v < mid[:, None]) & (hi_v >= mid[:, None])
    dist = np.where(rise, np.abs(offsets)[None, :], np.iinfo(np.int64).max)
    pick = np.argmin(dist, axis=1)
    found = rise[np.arange(pings), pick]
    jj = j[np.arange(pings), pick]
    a, b = lo_v[np.arange(pings), pick], hi_v[np.arange(pings), pick]
    t = np.where(b > a, (mid - a) / np.where(b > a, b - a, 1.0), 0.5)
    # Bin centres sit at k + 0.5 and the crossing lies between centres jj - 1 and jj: at
    # jj - 0.5 + t. A sharp edge inside bin jj - 1 or jj (anywhere in it: the bin's area is
    # only partly seabed) crosses near jj, so half a bin is added to centre the error.
    pos = jj + np.clip(t, 0.0, 1.0)
    return np.where(found, pos, edge + 0.5)


def _running_median(values: np.ndarray, size: int) -> np.ndarray:
    half = size // 2
    padded = np.pad(values, half, mode="constant", constant_values=np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN windows give NaN
        return np.nanmedian(sliding_window_view(padded, size), axis=1)


def _clean(raw: np.ndarray, range_bin: float, size: int) -> np.ndarray:
    """Drop detections far from their neighbours' running median (NaN)."""
    med = _running_median(raw, size)
    tol = np.maximum(3.0 * range_bin, 0.05 * np.nan_to_num(med, nan=0.0))
    keep = np.isfinite(raw) & np.isfinite(med) & (np.abs(raw - med) <= tol)
    return np.where(keep, raw, np.nan)


def _smooth(clean: np.ndarray, size: int) -> np.ndarray:
    ok = np.isfinite(clean)
    if not ok.any():
        raise SonarRasterError("no bottom return found in any ping; give the altitude")
    med = _running_median(clean, size)
    good = np.isfinite(med)
    filled = np.interp(np.arange(len(clean)), np.flatnonzero(good), med[good])
    return ndimage.gaussian_filter1d(filled, 1.0, mode="nearest")


def _detect(
    slant: np.ndarray, range_bin: float, window: int, min_contrast_db: float
) -> tuple[np.ndarray, np.ndarray]:
    image = check_slant(slant, range_bin)
    if not (isinstance(window, (int, np.integer)) and window >= 2):
        raise SonarRasterError(f"window must be an integer >= 2 bins, got {window!r}")
    own = _log_image(image)
    logs = ndimage.uniform_filter1d(own, AVERAGE_PINGS, axis=0, mode="nearest")
    lo = _blanking(image)
    edge, score, water = _edges(logs, lo, window)
    # validity from the ping's own samples: averaging lends a lost ping its neighbours' edge
    contrast = _own_contrast(own, lo, edge, window) * _DB_PER_NEPER
    pos = _crossing(logs, edge, water + 0.5 * score, window)
    # again, halfway to the seabed just after the crossing rather than to the window's mean
    # (near nadir the seabed often brightens with range, which would move the crossing out)
    bins = logs.shape[1]
    first = np.clip(np.floor(pos).astype(np.int64), 0, bins - NEAR_BINS)
    near = logs[np.arange(len(pos))[:, None], first[:, None] + np.arange(NEAR_BINS)].mean(axis=1)
    pos = _crossing(logs, first, 0.5 * (water + np.maximum(near, water)), window)
    raw = np.where(contrast >= min_contrast_db, pos * range_bin, np.nan)
    return raw, contrast


def track_side(
    slant: np.ndarray,
    range_bin: float,
    *,
    window: int = WINDOW_BINS,
    min_contrast_db: float = MIN_CONTRAST_DB,
    smooth_pings: int = SMOOTH_PINGS,
) -> BottomTrack:
    """Track the bottom in one side of an image.

    Parameters
    ----------
    slant : ndarray, shape (pings, bins)
        Linear intensity >= 0; columns are slant-range bins from range 0 outward.
    range_bin : float
        Slant-range bin size, metres.
    window : int
        Bins averaged after a candidate edge.
    min_contrast_db : float
        Seabed-over-water contrast a return must reach, dB.
    smooth_pings : int
        Running-median window along track, pings.

    Returns
    -------
    BottomTrack

    Raises
    ------
    SonarRasterError
        For a bad image, or when no ping has a clear return.
    """
    raw, contrast = _detect(slant, range_bin, window, min_contrast_db)
    size = _odd(smooth_pings)
    clean = _clean(raw, range_bin, size)
    return BottomTrack(_smooth(clean, size), np.isfinite(clean), raw, contrast)


def track_bottom(
    sides: Mapping[str, np.ndarray],
    range_bin: float,
    *,
    window: int = WINDOW_BINS,
    min_contrast_db: float = MIN_CONTRAST_DB,
    smooth_pings: int = SMOOTH_PINGS,
) -> BottomTrack:
    """Track the bottom using every side (the larger detection where the sides disagree).

    Parameters
    ----------
    sides : mapping of str to ndarray, each shape (pings, bins)
        E.g. ``SonarImage.sides``; linear intensity, range bins from range 0 outward.
    range_bin : float
        Slant-range bin size, metres.
    window, min_contrast_db, smooth_pings
        As for :func:`track_side`.

    Returns
    -------
    BottomTrack
        ``raw`` and ``contrast_db`` are the larger over the sides.
    """
    if not sides:
        raise SonarRasterError("no image sides to track")
    size = _odd(smooth_pings)
    raws, cleans, contrasts = [], [], []
    for values in sides.values():
        raw, contrast = _detect(values, range_bin, window, min_contrast_db)
        raws.append(raw)
        cleans.append(_clean(raw, range_bin, size))
        contrasts.append(contrast)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN pings stay NaN
        stack = np.stack(cleans)
        high, low = np.nanmax(stack, axis=0), np.nanmin(stack, axis=0)
        raw_max = np.nanmax(np.stack(raws), axis=0)
    # sides that agree are averaged; otherwise an object or a slope shortened one of them and
    # the larger is the vertical altitude
    agree = high - low <= AGREE_BINS * range_bin
    clean = _clean(np.where(agree, 0.5 * (high + low), high), range_bin, size)
    return BottomTrack(
        _smooth(clean, size), np.isfinite(clean), raw_max, np.max(np.stack(contrasts), axis=0)
    )


def first_return(slant: np.ndarray, range_bin: float) -> np.ndarray:
    """Altitude per ping from the first bottom return, shape (pings,), metres.

    The same inputs and output as :func:`sonar_raster.inversion.ground.first_return`, through
    :func:`track_side`; pings without a clear return take their neighbours' altitude.
    """
    return track_side(slant, range_bin).altitude


def _odd(size: int) -> int:
    if not (isinstance(size, (int, np.integer)) and size >= 1):
        raise SonarRasterError(f"smooth_pings must be a positive integer, got {size!r}")
    return int(size) | 1
