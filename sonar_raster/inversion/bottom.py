"""Bottom tracking: the sonar's altitude per ping from the first bottom return.

Per side and ping the first return is found in two steps: a robust edge in log intensity gives
its bin, and a model of the nadir return gives its place inside the bin.

1. On ``L = ln(I + ε)`` averaged over 5 neighbouring pings (speckle is multiplicative, so its log
   has a fixed spread), leading bins brighter than twice the image's typical level in every
   ping's median (a transmit pulse or saturated blanking) are skipped. The step score of bin k
   is the mean of L over the ``window`` bins from k on minus the mean over every bin before k:
   the water column before the first return gives the largest score, and an isolated bright
   speck moves the mean of a window only a little. The first local maximum of the score above
   half the ping's largest is the edge, or a distinct step more than a window before it whose
   score reaches ``min_contrast_db`` and the mean over ``SUSTAIN_WINDOWS`` windows after it
   too (a weak first return before bright debris, not a layer of fish); the ping's own
   contrast there, in dB, must reach ``min_contrast_db`` or the ping has no clear return.
   Where L crosses halfway between the water column and the seabed just after the edge (plus
   half a bin) is the coarse position, off by up to half a bin depending on where the edge
   lies in its bin.
2. Over a flat seabed each bin holds ``∫ G(x) dx`` over the ground ranges ``x = √(r² − h²)`` its
   slant ranges cover, ``G`` the smooth return per metre of ground (beam, reflectivity, grazing
   angle). For trial altitudes h within 1.5 bins of the coarse position, ``ln G`` is fitted by
   a quadratic in x to the ``FIT_BINS`` full bins after h and integrated from nadir to the
   first of them, and compared with the intensity received before that bin (the partial bin
   holding h and the water column, the water level subtracted): too early an h predicts more
   than was received, too late an h less. The altitude is where the difference rises through
   0 (the last time before it clearly exceeds the water column's noise). This runs on linear
   intensity averaged over enough pings to reach about 32 looks (at most 9, the brightest of
   them left out: a fish in the water column); on a clean render it finds the edge to about
   0.01 bin wherever it lies in its bin, where the coarse position (and a half-rise crossing
   on linear intensity) are off by up to 0.45 bin.
3. On a speckled image the fine position is noisy (about ``1/√L`` bin for L looks after
   averaging) while the coarse one is steady but off by a uniform fraction of a bin (variance
   1/12): the two are combined with inverse-variance weights, so a clean image keeps the fine
   position and single-look speckle leans on the coarse one.
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

from .._checks import positive
from ..errors import SonarRasterError
from .ground import check_slant
from .priors import estimate_looks

__all__ = ["BottomTrack", "blanking_bins", "track_bottom", "track_side"]

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
#: A step weaker than half the ping's largest is the edge when it reaches the minimum contrast
#: and the mean over this many windows after it does too (a seabed, not a fish).
SUSTAIN_WINDOWS = 4
#: An image with this share of samples exactly 0, and at least ``CLEAN_LOOKS`` looks, is
#: taken as noise-free (:func:`_log_image`): a speckled seabed over an exactly dark water
#: column is not.
CLEAN_ZEROS = 0.01
CLEAN_LOOKS = 100.0
#: Pings averaged (in log intensity) before detection.
AVERAGE_PINGS = 5
#: Gaussian smoothing along range before detection, bins (symmetric: a step stays in place).
RANGE_SIGMA_BINS = 1.0
#: Full bins after a trial altitude to which ln G is fitted (quadratic in ground range).
FIT_BINS = 5
#: Trial altitudes reach this many bins either side of the coarse position, in steps of
#: ``SEARCH_STEP`` bins.
SEARCH_BINS = 1.5
SEARCH_STEP = 0.05
#: Looks that the pings averaged for the fine position should reach on a speckled image, and
#: the most pings averaged (linear intensity, the brightest left out).
AVERAGE_LOOKS = 32.0
MAX_AVERAGE_PINGS = 9
#: Pings fitted at once (bounds the memory of the trial-altitude arrays).
_CHUNK = 256
_GL_X, _GL_W = np.polynomial.legendre.leggauss(8)
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


def blanking_bins(image: np.ndarray) -> int:
    """Number of leading bins brighter than twice the typical column median (transmit pulse).

    ``image`` is (pings, bins), linear; at most a twentieth of the bins count as blanking.
    """
    column = np.median(image, axis=0)
    typical = float(np.median(column))
    limit = max(1, image.shape[1] // 20)
    bright = column[:limit] > 2.0 * typical if typical > 0 else np.zeros(limit, bool)
    return int(limit if bright.all() else np.argmin(bright))


def _log_image(image: np.ndarray, looks: float = 1.0) -> np.ndarray:
    """ln(I + ε), smoothed along range.

    ε is 1e-3 of the median positive intensity, below any noise floor and the deep fades of
    speckle; in a noise-free image (at least :data:`CLEAN_ZEROS` of its samples exactly 0 —
    water column, shadows — and ``looks`` of at least :data:`CLEAN_LOOKS`) it is 1e-3 of the
    1st percentile instead, since there the faintest returns are signal (a render's nadir seen
    through the beam's sidelobes lies near 1e-3 of the median: it was taken for water, and the
    tracked altitude came out 0.4-1.6 m long).
    """
    positive = image[image > 0]
    clean = looks >= CLEAN_LOOKS and positive.size <= (1.0 - CLEAN_ZEROS) * image.size
    if not positive.size:
        eps = 1.0
    elif clean:
        eps = 1e-3 * float(np.percentile(positive, 1.0))
    else:
        eps = 1e-3 * float(np.median(positive))
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


def _edges(
    logs: np.ndarray, lo: int, window: int, floor: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Edge bin, step score (nepers) and water-column level (mean log) per ping.

    The edge climbs from the first bin whose score reaches half the ping's largest, or from
    an earlier one more than a window before it (a distinct step, not the same step's rising
    score) whose score reaches ``floor`` (nepers) with the mean after it staying that much
    above the water for ``SUSTAIN_WINDOWS`` windows: a weak first return followed by a far
    brighter object or patch (a wreck's debris) is the seabed's, where half the largest step
    alone passed it over.
    """
    pings, bins = logs.shape
    c = np.concatenate([np.zeros((pings, 1)), np.cumsum(logs[:, lo:], axis=1)], axis=1)
    # edge after k >= window bins of water (relative to lo): fewer make a noisy water mean
    k = np.arange(window, bins - lo - window + 1)
    if len(k) == 0:
        raise SonarRasterError("too few range bins after the transmit pulse to find the bottom")
    after = (c[:, k + window] - c[:, k]) / window
    before = c[:, k] / k
    score = after - before
    end = np.minimum(k + SUSTAIN_WINDOWS * window, bins - lo)
    sustained = (c[:, end] - c[:, k]) / (end - k) - before
    top = score.max(axis=1)
    first = np.argmax(score >= 0.5 * top[:, None], axis=1)
    weak = (score >= floor) & (sustained >= floor)
    early = np.where(weak.any(axis=1), np.argmax(weak, axis=1), len(k))
    # a distinct step before it, not the same step's rising score (a window long)
    first = np.where(early < first - window, early, first)
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
        raise SonarRasterError(
            "no bottom return found in any ping (the image is blank, saturated or shows no "
            "seabed); give the altitude where the command takes one (--altitude)"
        )
    med = _running_median(clean, size)
    good = np.isfinite(med)
    filled = np.interp(np.arange(len(clean)), np.flatnonzero(good), med[good])
    return ndimage.gaussian_filter1d(filled, 1.0, mode="nearest")


def _coarse(
    logs: np.ndarray, edge: np.ndarray, score: np.ndarray, water: np.ndarray, window: int
) -> np.ndarray:
    """Where L crosses halfway from the water column to the seabed just after the edge, bins."""
    pos = _crossing(logs, edge, water + 0.5 * score, window)
    # again, halfway to the seabed just after the crossing rather than to the window's mean
    # (near nadir the seabed often brightens with range, which would move the crossing out)
    bins = logs.shape[1]
    first = np.clip(np.floor(pos).astype(np.int64), 0, bins - NEAR_BINS)
    near = logs[np.arange(len(pos))[:, None], first[:, None] + np.arange(NEAR_BINS)].mean(axis=1)
    return _crossing(logs, first, 0.5 * (water + np.maximum(near, water)), window)


def _averaging(looks: float) -> tuple[int, float]:
    """Pings to average for the fine position and the looks they give (inf: noise-free)."""
    if not math.isfinite(looks):
        return 1, math.inf
    pings = int(min(MAX_AVERAGE_PINGS, math.ceil(AVERAGE_LOOKS / looks)))
    return pings, looks * max(pings - 1, 1)


def _along_track_mean(slant: np.ndarray, pings: int) -> np.ndarray:
    """Mean of each bin over up to ``pings`` neighbouring pings without the brightest one.

    Fewer pings at the ends of the image; ``pings < 2`` returns ``slant``. Leaving out the
    brightest value keeps a single bright ping (a fish in the water column) from spreading.
    """
    n = slant.shape[0]
    if pings < 2 or n < 3:
        return slant
    half = pings // 2
    c = np.concatenate([np.zeros((1, slant.shape[1])), np.cumsum(slant, axis=0)])
    i = np.arange(n)
    lo, hi = np.maximum(i - half, 0), np.minimum(i + half + 1, n)
    brightest = ndimage.maximum_filter1d(slant, 2 * half + 1, axis=0, mode="nearest")
    return np.maximum(c[hi] - c[lo] - brightest, 0.0) / (hi - lo - 1)[:, None]


def _row_median(values: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Median of each row over its ``mask`` entries (rows with at least one)."""
    count = mask.sum(axis=1)
    ordered = np.sort(np.where(mask, values, np.inf), axis=1)
    rows = np.arange(len(values))
    lower = ordered[rows, np.maximum(count - 1, 0) // 2]
    return 0.5 * (lower + ordered[rows, count // 2])


def _water_level(lin: np.ndarray, lo: int, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean level and robust deviation of the water column per ping (0 where it has no bins).

    The water column runs from ``lo`` to 3 bins before ``centre``; values above 5 times the
    ping's median (specks) count as 5 times the median in the mean.
    """
    cols = np.arange(lin.shape[1])[None, :]
    water = (cols >= lo) & (cols < np.floor(centre)[:, None] - 3)
    ok = water.any(axis=1)
    level, spread = np.zeros(len(lin)), np.zeros(len(lin))
    if ok.any():
        values, water = lin[ok], water[ok]
        med = _row_median(values, water)
        clipped = np.where(water, np.minimum(values, 5.0 * med[:, None]), 0.0)
        level[ok] = clipped.sum(axis=1) / water.sum(axis=1)
        spread[ok] = 1.4826 * _row_median(np.abs(values - med[:, None]), water)
    return level, spread


def _nadir_residual(
    seg: np.ndarray, base: np.ndarray, h: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Received minus predicted intensity before the first full bin, per trial altitude.

    ``seg`` (pings, L): water-subtracted intensity of bins ``base .. base + L - 1``; ``h``
    (pings, trials): trial altitudes in bins. Returns the residual and the number of bins
    summed into the received intensity.
    """
    pings = np.arange(len(seg))[:, None, None]
    m = np.floor(h).astype(np.int64) + 1  # first full bin
    rel = m - base[:, None]
    q = np.arange(FIT_BINS + 1)
    r = (m[..., None] + q).astype(np.float64)
    x = np.sqrt(r**2 - h[..., None] ** 2)  # ground range of the bin boundaries, bins
    values = seg[pings, rel[..., None] + q[:-1]]
    scale = np.maximum(values.mean(axis=2), 1e-300)
    g = np.maximum(values, 1e-3 * scale[..., None]) / np.diff(x, axis=2)
    xm = 0.5 * (x[..., 1:] + x[..., :-1])
    centre = xm.mean(axis=2, keepdims=True)
    basis = np.stack([np.ones_like(xm), xm - centre, (xm - centre) ** 2], axis=-1)
    gram = np.einsum("...nd,...ne->...de", basis, basis)
    coef = np.linalg.solve(gram, np.einsum("...nd,...n->...d", basis, np.log(g))[..., None])
    c0, c1, c2 = (coef[..., k, 0][..., None] for k in range(3))
    x0 = x[..., :1]
    z = 0.5 * x0 * (_GL_X + 1.0) - centre
    density = np.exp(np.clip(c0 + c1 * z + c2 * z**2, -700.0, 700.0))
    predicted = 0.5 * x0[..., 0] * np.sum(_GL_W * density, axis=2)
    cum = np.concatenate([np.zeros((len(seg), 1)), np.cumsum(seg, axis=1)], axis=1)
    return cum[pings[..., 0], rel] - predicted, rel


def _trials() -> np.ndarray:
    """Trial altitudes relative to the start of the coarse position's bin, in bins.

    Every ``SEARCH_STEP`` from ``SEARCH_BINS`` before that bin to as many after it, plus a point
    just before each bin boundary: the residual jumps there, so a crossing that falls on a
    boundary is found on it rather than interpolated across it.
    """
    lo, hi = math.floor(-SEARCH_BINS), math.ceil(1 + SEARCH_BINS)
    n = round(1 / SEARCH_STEP)
    grid = np.arange(lo * n, hi * n + 1) / n
    grid = grid[(grid >= -SEARCH_BINS) & (grid <= 1 + SEARCH_BINS)]
    edges = np.arange(lo, hi + 1) - 1e-6
    return np.sort(np.concatenate([grid, edges[(edges > grid[0]) & (edges < grid[-1])]]))


def _fine(lin: np.ndarray, lo: int, coarse: np.ndarray) -> np.ndarray:
    """Edge position per ping (bins from range 0) from the nadir model; NaN where not found.

    Trial altitudes (:func:`_trials`) run from ``SEARCH_BINS`` before ``coarse`` to as many
    after its bin. The residual
    of :func:`_nadir_residual` is negative before the edge and grows past the edge's bin after
    it, while noise in the water column only lifts it a little at bin boundaries: the edge is
    where it last rises through 0 before it first exceeds 3 deviations of the water column's
    noise summed over the same bins, interpolated between trials.
    """
    pings, bins = lin.shape
    reach = math.ceil(SEARCH_BINS)
    width = 2 * reach + 3 + FIT_BINS
    t = _trials()
    out = np.full(pings, np.nan)
    if bins < width + 1:
        return out
    level, spread = _water_level(lin, lo, coarse)
    start = np.floor(coarse)
    base = np.clip(start.astype(np.int64) - reach - 1, 0, bins - width)
    lowest, highest = base + 1.0, base + float(width - FIT_BINS - 1)
    for s in range(0, pings, _CHUNK):
        rows = slice(s, s + _CHUNK)
        b = base[rows]
        seg = lin[np.arange(s, s + len(b))[:, None], b[:, None] + np.arange(width)]
        seg = seg - level[rows, None]
        h = np.clip(start[rows, None] + t, lowest[rows, None], highest[rows, None])
        res, summed = _nadir_residual(seg, b, h)
        clear = res >= 3.0 * spread[rows, None] * np.sqrt(summed)
        first = np.where(clear.any(axis=1), np.argmax(clear, axis=1), len(t))
        negative = (res < 0) & (np.arange(len(t)) < first[:, None])
        i = np.where(negative.any(axis=1), len(t) - np.argmax(negative[:, ::-1], axis=1), 0)
        k = np.arange(len(b))
        j = np.clip(i, 1, len(t) - 1)
        lo_r, hi_r = res[k, j - 1], res[k, j]
        frac = np.where(hi_r > lo_r, -lo_r / np.where(hi_r > lo_r, hi_r - lo_r, 1.0), 0.5)
        pos = h[k, j - 1] + np.clip(frac, 0.0, 1.0) * (h[k, j] - h[k, j - 1])
        out[rows] = np.where((i > 0) & (first < len(t)), pos, np.nan)
    return out


def _detect(
    slant: np.ndarray,
    range_bin: float,
    window: int,
    min_contrast_db: float,
    looks: float | None,
) -> tuple[np.ndarray, np.ndarray]:
    image = check_slant(slant, range_bin)
    if not (isinstance(window, (int, np.integer)) and window >= 2):
        raise SonarRasterError(f"window must be an integer >= 2 bins, got {window!r}")
    positive("min_contrast_db (the return's rise over the water column, dB)", min_contrast_db)
    if looks is None:  # fully developed speckle has at least one look
        looks = max(estimate_looks(image, np.ones_like(image)), 1.0) if len(image) > 1 else math.inf
    elif not (isinstance(looks, (int, float)) and looks > 0):
        raise SonarRasterError(f"looks must be a number > 0 or None, got {looks!r}")
    own = _log_image(image, float(looks))
    logs = ndimage.uniform_filter1d(own, AVERAGE_PINGS, axis=0, mode="nearest")
    lo = blanking_bins(image)
    edge, score, water = _edges(logs, lo, window, min_contrast_db / _DB_PER_NEPER)
    # validity from the ping's own samples: averaging lends a lost ping its neighbours' edge
    contrast = _own_contrast(own, lo, edge, window) * _DB_PER_NEPER
    coarse = _coarse(logs, edge, score, water, window)
    pings, eff_looks = _averaging(float(looks))
    lin = _along_track_mean(image, pings)
    fine = _fine(lin, lo, coarse)
    # inverse-variance weights: the coarse error is uniform over a bin, the fine one ~ 1/√looks
    weight = 1.0 / (1.0 + 12.0 / eff_looks)
    pos = np.where(np.isfinite(fine), coarse + weight * (fine - coarse), coarse)
    raw = np.where(contrast >= min_contrast_db, pos * range_bin, np.nan)
    return raw, contrast


def track_side(
    slant: np.ndarray,
    range_bin: float,
    *,
    window: int = WINDOW_BINS,
    min_contrast_db: float = MIN_CONTRAST_DB,
    smooth_pings: int = SMOOTH_PINGS,
    looks: float | None = None,
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
    looks : float or None
        Speckle looks of the image (inf: noise-free); None estimates them from neighbouring
        pings (:func:`sonar_raster.inversion.priors.estimate_looks`). They set how many pings
        are averaged for the sub-bin position and how far it is trusted.

    Returns
    -------
    BottomTrack

    Raises
    ------
    SonarRasterError
        For a bad image, or when no ping has a clear return.
    """
    raw, contrast = _detect(slant, range_bin, window, min_contrast_db, looks)
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
    looks: float | None = None,
) -> BottomTrack:
    """Track the bottom using every side (the larger detection where the sides disagree).

    Parameters
    ----------
    sides : mapping of str to ndarray, each shape (pings, bins)
        E.g. ``SonarImage.sides``; linear intensity, range bins from range 0 outward.
    range_bin : float
        Slant-range bin size, metres.
    window, min_contrast_db, smooth_pings, looks
        As for :func:`track_side` (looks None: estimated per side).

    Returns
    -------
    BottomTrack
        ``raw`` and ``contrast_db`` are the larger over the sides.
    """
    if not isinstance(sides, Mapping):
        raise SonarRasterError(
            f"track_bottom takes the image's sides (a dict such as image.sides), got "
            f"{type(sides).__name__}; for one side's array use track_side"
        )
    if not sides:
        raise SonarRasterError("no image sides to track")
    shapes = {np.shape(v)[:1] for v in sides.values()}
    if len(shapes) > 1:
        raise SonarRasterError("the sides have different ping counts; give sides of one image")
    size = _odd(smooth_pings)
    raws, cleans, contrasts = [], [], []
    for values in sides.values():
        raw, contrast = _detect(values, range_bin, window, min_contrast_db, looks)
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


def _odd(size: int) -> int:
    if not (isinstance(size, (int, np.integer)) and size >= 1):
        raise SonarRasterError(f"smooth_pings must be a positive integer, got {size!r}")
    return int(size) | 1
