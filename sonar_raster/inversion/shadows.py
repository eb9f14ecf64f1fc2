"""Object heights from acoustic shadows in a slant-range side-scan image.

A straight ray from the transducer, at altitude h above a flat seabed, that grazes an
object's top at slant range R reaches the seabed at slant range R + Ls, where the shadow
ends. Height falls linearly along the ray, so ``(h − H) / h = R / (R + Ls)``:

    H = Ls · h / (R + Ls)

(slant ranges; exact for straight rays over a flat seabed, with h the altitude in the same
plane as the ranges, e.g. the first bottom return).

Detection, per ping: the image is median filtered (3 pings × 7 bins) and divided by the
ping's seabed level (its median beyond the first return). A shadow is a run of bins below
``shadow_level`` of that level, at least ``min_shadow_m`` long and starting at least
``margin_m`` beyond the first return, that directly follows a highlight: a run above
``highlight_level`` (gaps up to ``gap_m`` bridged) ending within ``gap_m`` of the shadow's
start, and whose mean intensity (unfiltered) is at most ``shadow_mean`` of the level (or
twice the water column's mean before the first return, where the seabed is itself within
10 dB of that floor): a cast shadow holds only the noise floor, where a dark seabed still
returns. The longest such run per ping is kept. A shadow that runs to the end of the range
gives only a lower bound (``R + Ls`` is at least the maximum range).

Why the mean (2026-12-02, docs/notes/2026-12-02-law-in-fit.md): a seabed whose backscatter
falls fast towards low grazing (APL-UW sand) turns the back slopes of sand waves at far range
nearly black, and single-look speckle under a median filter reads them as shadows (183 of 200
pings on the bathymetry bench's sand waves); their mean is 20-30 % of the level, a wreck's
shadow in the real file 1-2 %, the bench's box 2-4 %. At 10 %: the sand waves 2 pings, the
box 55 of 62, the real wreck 100 of 100.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ..errors import SonarRasterError

__all__ = ["Shadows", "find_shadows", "object_pings"]


@dataclass(frozen=True)
class Shadows:
    """Per-ping highlights and shadows of one side; bins are -1 and heights NaN where none.

    Attributes
    ----------
    highlight, start, end : ndarray, shape (pings,), int64
        First bin of the highlight, first bin of the shadow, and one past its last bin.
    height : ndarray, shape (pings,), float64
        ``H = Ls h / (R + Ls)``, metres, for shadows that end inside the range.
    bound : ndarray, shape (pings,), float64
        Lower bound of H, metres, for shadows that run to the end of the range.
    ratio : ndarray, shape (pings, bins), float64
        The filtered image over its seabed level.
    """

    highlight: np.ndarray
    start: np.ndarray
    end: np.ndarray
    height: np.ndarray
    bound: np.ndarray
    ratio: np.ndarray


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of each run of True."""
    padded = np.concatenate([[False], mask, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))


def _highlight_before(bright: np.ndarray, a: int, floor: int, gap: int) -> int:
    """First bin of the bright run ending within ``gap`` bins before ``a``; -1 if none."""
    k = a - 1
    while k > floor and not bright[k] and a - k <= gap:
        k -= 1
    if k <= floor or not bright[k]:
        return -1
    while k > floor and bright[k - 1]:
        k -= 1
    return k


def find_shadows(
    slant: np.ndarray,
    range_bin: float,
    altitude: np.ndarray,
    *,
    shadow_level: float = 0.3,
    shadow_mean: float | None = 0.1,
    highlight_level: float = 1.0,
    min_shadow_m: float = 0.3,
    margin_m: float = 0.5,
    gap_m: float = 0.3,
) -> Shadows:
    """Find each ping's object shadow and the height of the object casting it.

    Parameters
    ----------
    slant : ndarray, shape (pings, bins)
        Linear intensity of one side, bins from range 0 outward.
    range_bin : float
        Slant-range bin size, metres.
    altitude : ndarray, shape (pings,)
        Altitude per ping, metres (the first bottom return).
    shadow_level, highlight_level : float
        Shadow and highlight thresholds, as fractions of the ping's seabed level.
    shadow_mean : float or None
        The most a shadow's mean intensity may be, as a fraction of that level, or twice the
        water column's mean if that is more (None: no such test).
    min_shadow_m, margin_m, gap_m : float
        Shortest shadow, clearance after the first return, largest gap, metres.

    Returns
    -------
    Shadows
    """
    image = np.asarray(slant, dtype=np.float64)
    alt = np.broadcast_to(np.asarray(altitude, dtype=np.float64), (image.shape[0],))
    if image.ndim != 2 or not np.all(np.isfinite(image)) or np.any(image < 0):
        raise SonarRasterError("shadows need a 2-D image of finite intensities >= 0")
    if not (range_bin > 0 and np.all(np.isfinite(alt)) and np.all(alt > 0)):
        raise SonarRasterError("range bin and altitudes must be > 0")
    smooth = ndimage.median_filter(image, size=(3, 7))
    pings, bins = smooth.shape
    first = np.minimum(np.ceil(alt / range_bin).astype(np.int64), bins - 1)
    gap = max(1, int(round(gap_m / range_bin)))
    out = {k: np.full(pings, -1, dtype=np.int64) for k in ("highlight", "start", "end")}
    height, bound = np.full(pings, np.nan), np.full(pings, np.nan)
    ratio = np.zeros_like(smooth)
    for i in range(pings):
        level = float(np.median(smooth[i, first[i] :]))
        # the most a shadow may hold: 10 dB under the seabed, or the noise floor's twice where
        # the seabed is itself near the floor (the water column's mean before the first return)
        water = image[i, int(0.3 * first[i]) : int(0.9 * first[i])]
        floor = 2.0 * float(np.mean(water)) if water.size else 0.0
        most = None if shadow_mean is None else max(shadow_mean * level, floor)
        ratio[i] = smooth[i] / level if level > 0 else 0.0
        lo = min(bins, first[i] + int(round(margin_m / range_bin)))
        dark = ratio[i] < shadow_level
        dark[:lo] = False
        bright = ndimage.binary_closing(ratio[i] > highlight_level, np.ones(gap)) | (
            ratio[i] > highlight_level
        )
        best = None
        for a, b in _runs(dark):
            if (b - a) * range_bin < min_shadow_m:
                continue
            if most is not None and np.mean(image[i, a:b]) > most:
                continue
            k = _highlight_before(bright, a, int(first[i]), gap)
            if k >= 0 and (best is None or b - a > best[2] - best[1]):
                best = (k, a, b)
        if best is None:
            continue
        k, a, b = best
        out["highlight"][i], out["start"][i], out["end"][i] = k, a, b
        value = (b - a) * alt[i] / b  # Ls h / (R + Ls), both in bins
        if b == bins:
            bound[i] = value
        else:
            height[i] = value
    return Shadows(out["highlight"], out["start"], out["end"], height, bound, ratio)


def object_pings(height: np.ndarray, bridge: int = 5) -> np.ndarray:
    """The longest run of pings with a height (gaps up to ``bridge`` pings bridged), bool."""
    found = np.isfinite(np.asarray(height))
    closed = ndimage.binary_closing(found, np.ones(bridge)) | found
    runs = _runs(closed)
    keep = np.zeros_like(found)
    if runs:
        a, b = max(runs, key=lambda r: r[1] - r[0])
        keep[a:b] = True
    return keep & found
