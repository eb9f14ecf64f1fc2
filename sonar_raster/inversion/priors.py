"""Regularisation of the inversion: beam profile per depression angle and shadow filling.

Φ is parametrised by a profile over depression-angle bins, so every cell of equal angle has
the same Φ (the constraint of seed Eq. 21). Angles are the nominal ``atan2(h, x)`` of each
ping's altitude ``h``; bin edges are those of the ground cells at the median altitude, so for
a level track bin b is ground column b. The profile starts from the median (Eq. 21) of the
image over each bin.

On a speckled image two Gaussian priors on Z join the fit: on the relief ``Z − Z_flat`` and on
the slopes (:func:`slope_roughness`). Their weights are the image noise variance, from the
speckle looks (:func:`estimate_looks`), over the assumed variances of relief and slopes, so they
fade away as the image gets clean (see ``invert``'s ``looks``).

Reflectivity in shadow is tied to the nearest lit cell (Euclidean distance transform): the
limit of the seed's hexadecagonal dilation, which grows lit regions by an almost round disc
until every shadow cell is reached, and exact where 16 directions are only approximate.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage, sparse

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


def _difference(n: int, step: float) -> sparse.csr_matrix:
    """Forward differences ``(v[j+1] − v[j]) / step`` of a length-``n`` axis, (n − 1) × n."""
    return sparse.diags([-np.ones(n - 1), np.ones(n - 1)], [0, 1], (max(n - 1, 0), n)) / step


def slope_roughness(z: np.ndarray, dx: float, dy: float) -> tuple[float, np.ndarray]:
    """``Σ (∂Z/∂x)² + Σ (∂Z/∂y)²`` over forward differences and its gradient (shape of ``z``).

    The prior of a seabed whose slopes have a standard deviation ``s`` is this sum over
    ``2 s²``. Unlike the image, it ties each ping's Z to its neighbours' (the model image does
    not depend on ``∂Z/∂y``, so the data fit every ping alone). Its Hessian is constant: see
    :func:`slope_hessian`.
    """
    ax, ay = np.diff(z, axis=1) / dx, np.diff(z, axis=0) / dy
    value = float(np.sum(ax * ax) + np.sum(ay * ay))
    grad = np.zeros_like(z)
    grad[:, 1:] += 2.0 * ax / dx
    grad[:, :-1] -= 2.0 * ax / dx
    grad[1:] += 2.0 * ay / dy
    grad[:-1] -= 2.0 * ay / dy
    return value, grad


def slope_hessian(
    shape: tuple[int, int], dx: float, dy: float
) -> tuple[sparse.csr_matrix, np.ndarray]:
    """The Hessian of :func:`slope_roughness` in two parts, for Z of ``shape`` (pings, cells).

    The across-track part, a sparse (pings·cells)² matrix that couples cells of one ping only
    (a 1-D Laplacian per ping, free ends), and the diagonal of the along-track part (shape
    ``shape``). Keeping the pings apart keeps the Gauss-Newton matrix block diagonal, one
    banded block per ping, so its solve stays as cheap as without the prior.
    """
    pings, cells = shape
    d_x = sparse.kron(sparse.identity(pings), _difference(cells, dx))
    along = np.zeros(shape)
    along[1:] += 2.0 / dy**2
    along[:-1] += 2.0 / dy**2
    return (2.0 * (d_x.T @ d_x)).tocsr(), along


def estimate_looks(slant: np.ndarray, weight: np.ndarray) -> float:
    """Equivalent number of looks L of the speckle, from neighbouring pings.

    For independent L-look speckle on a mean ``μ`` that changes little from ping to ping,
    ``E[I₁ I₂] = μ²`` and ``E[(I₁ − I₂)²] = 2 μ² / L``, so
    ``L = 2 Σ I₁ I₂ / Σ (I₁ − I₂)²`` over the bins both pings cover (``weight > 0``). Relief
    that changes between pings lowers the estimate; speckle correlated between pings raises
    it. ``inf`` for identical pings.
    """
    keep = (weight[:-1] > 0) & (weight[1:] > 0)
    return looks_between(slant[:-1][keep], slant[1:][keep])


def looks_between(a: np.ndarray, b: np.ndarray, spread: float = 2.0) -> float:
    """Looks L of independent L-look speckle on paired samples ``a``, ``b`` of one mean.

    ``E[a b] = μ²`` and ``E[(a − b)²] = spread μ² / L`` (2 for two samples, 1.5 for one
    against the mean of two), so ``L = spread Σ a b / Σ (a − b)²``; ``inf`` where they agree.
    """
    diff = float(np.sum((a - b) ** 2))
    if diff <= 0.0:
        return math.inf
    return spread * float(np.sum(a * b)) / diff
