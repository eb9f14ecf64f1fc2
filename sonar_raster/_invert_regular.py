"""Regularisation of the inversion: beam profile per depression angle and shadow filling.

Φ is parametrised by a profile over depression-angle bins, so every cell of equal angle has
the same Φ (the constraint of seed Eq. 21). Angles are the nominal ``atan2(h, x)`` of each
ping's altitude ``h``; bin edges are those of the ground cells at the median altitude, so for
a level track bin b is ground column b. The profile starts from the median (Eq. 21) of the
image over each bin.

Reflectivity in shadow is tied to the nearest lit cell (Euclidean distance transform): the
limit of the seed's hexadecagonal dilation, which grows lit regions by an almost round disc
until every shadow cell is reached, and exact where 16 directions are only approximate.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

#: A cell is in shadow where its smoothed normalised intensity is below this fraction of
#: the median of the lit seabed.
SHADOW_FRACTION = 0.2


def angle_bins(x: np.ndarray, altitude: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Depression-angle bin of every cell and the bin centres.

    Returns
    -------
    bins : ndarray, shape (pings, cells), int64
    centres : ndarray, shape (cells,), float64
        Depression angle of each bin's centre, radians, decreasing.
    """
    h = float(np.median(altitude))
    dx = float(x[1] - x[0])
    edges = np.arctan2(h, np.append(x - 0.5 * dx, x[-1] + 0.5 * dx))
    alpha = np.arctan2(altitude[:, None], x[None, :])
    bins = np.searchsorted(-edges, -alpha, side="right") - 1
    return np.clip(bins, 0, len(x) - 1), np.arctan2(h, x)


def profile_median(values: np.ndarray, weight: np.ndarray, bins: np.ndarray, n: int) -> np.ndarray:
    """Median of ``values`` over the weighted cells of each bin (Eq. 21), shape (n,).

    Bins without a cell take the value of the nearest bins by linear interpolation.
    """
    out = np.full(n, np.nan)
    keep = weight > 0
    flat_bins, flat_values = bins[keep], values[keep]
    order = np.argsort(flat_bins, kind="stable")
    flat_bins, flat_values = flat_bins[order], flat_values[order]
    starts = np.searchsorted(flat_bins, np.arange(n))
    stops = np.searchsorted(flat_bins, np.arange(n), side="right")
    for b in np.flatnonzero(stops > starts):
        out[b] = np.median(flat_values[starts[b] : stops[b]])
    have = np.isfinite(out)
    if not have.any():
        return np.zeros(n)
    return np.interp(np.arange(n), np.flatnonzero(have), out[have])


def shadows(normalised: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Shadow mask: smoothed ``I / (Φ cos θ)`` below 0.2 of its lit median, shape as input.

    A Gaussian (1 cell) smooths speckle first, so single dark cells are not shadows.
    """
    valid = weight > 0
    smooth = ndimage.gaussian_filter(np.where(valid, normalised, 0.0), 1.0)
    norm = ndimage.gaussian_filter(valid.astype(np.float64), 1.0)
    smooth = np.where(norm > 1e-6, smooth / np.maximum(norm, 1e-6), 0.0)
    level = np.median(smooth[valid]) if valid.any() else 0.0
    return valid & (smooth < SHADOW_FRACTION * level)


def nearest_lit(shadow: np.ndarray) -> np.ndarray:
    """Flat index of the nearest lit cell for every cell (itself when lit), shape (cells,)."""
    if not shadow.any() or shadow.all():
        return np.arange(shadow.size)
    _, (iy, ix) = ndimage.distance_transform_edt(shadow, return_indices=True)
    return np.ravel_multi_index((iy, ix), shadow.shape).ravel()
