"""Multiplicative speckle correlated at the resolution cell: exponential or K-distributed.

A resolution cell holds many random scatterers; their echoes add as a complex Gaussian sum, so
intensity is exponentially distributed (contrast std/mean = 1, fully developed speckle). The
field is made that way: white complex Gaussian noise filtered by the cell's amplitude point
spread (the square root of the two-way intensity kernel, a Gaussian √2 times wider), then
``|z|²``, normalised so its mean is exactly 1 in expectation. Neighbouring pixels inside one
cell are then correlated like real speckle: the intensity correlation at lag Δ is
``exp(-Δ² / (4 σ²))`` for an intensity kernel of standard deviation σ.

K-distributed intensity (patchy seabeds, Jakeman & Pusey 1976; Abraham & Lyons 2002) is that
speckle times an independent gamma texture of shape ν and mean 1, so ``contrast² = 1 + 2 / ν``;
the texture is a Gaussian field with the same correlation mapped through the gamma quantile
function, so its one-point law is exactly gamma.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import fft as sp_fft
from scipy import special

from .along_track import filter_columns, gaussian_transfer


def _filter_gain(n: int, sigma: np.ndarray) -> np.ndarray:
    """``Σ h²`` of the circular unit-sum Gaussian kernels of :func:`filter_columns`, per column."""
    kernels = sp_fft.irfft(gaussian_transfer(n, sigma), n=n, axis=0)
    return np.einsum("ij,ij->j", kernels, kernels)


def _correlated(
    noise: np.ndarray, sigma_along: np.ndarray, sigma_range: float
) -> tuple[np.ndarray, np.ndarray]:
    """Filter a white field along range (one σ) then along pings (σ per column), circularly.

    Returns the filtered field and the variance gain per column (pixel variance of the output
    for unit-variance white input), shape (bins,).
    """
    pings, bins = noise.shape
    gain = np.ones(bins)
    out = noise
    if sigma_range > 0:
        out = filter_columns(out.T, np.full(pings, sigma_range), circular=True).T
        gain = gain * _filter_gain(bins, np.array([sigma_range]))[0]
    if np.any(sigma_along > 0):
        out = filter_columns(out, sigma_along, circular=True)
        gain = gain * _filter_gain(pings, sigma_along)
    return out, gain


def speckle_field(
    shape: tuple[int, int],
    rng: np.random.Generator,
    sigma_along: np.ndarray,
    sigma_range: float,
    k_shape: float | None = None,
    looks: float = 1.0,
) -> np.ndarray:
    """Unit-mean multiplicative speckle for one side image.

    Parameters
    ----------
    shape : (pings, bins)
    rng : numpy.random.Generator
        Source of randomness (seed it for reproducible images).
    sigma_along : ndarray, shape (bins,)
        Standard deviation of the two-way intensity resolution kernel along track, pings, per
        range column (0: every ping independent).
    sigma_range : float
        Same across range, bins (0: every bin independent).
    k_shape : float, optional
        Shape ν > 0 of the K-distribution; None gives exponential (fully developed) speckle.
    looks : float
        Looks L ≥ 1: the exponential speckle is mapped through the gamma(L) quantile function
        (one-point law of L-look speckle, mean 1, contrast 1/√L; correlation kept in rank).

    Returns
    -------
    ndarray, shape ``shape``, float64
        Intensity factors >= 0 with expectation 1.
    """
    pings, bins = shape
    amp_along = math.sqrt(2.0) * np.asarray(sigma_along, dtype=np.float64)
    amp_range = math.sqrt(2.0) * float(sigma_range)
    white = rng.standard_normal((2, pings, bins))
    re, gain = _correlated(white[0], amp_along, amp_range)
    im, _ = _correlated(white[1], amp_along, amp_range)
    speckle = (re * re + im * im) / (2.0 * gain)
    if looks != 1.0:  # exponential -> uniform -> gamma(L) / L, pixel by pixel
        u = np.clip(-np.expm1(-speckle), 1e-15, 1.0 - 1e-15)
        speckle = special.gammaincinv(looks, u) / looks
    if k_shape is None:
        return speckle
    g, g_gain = _correlated(rng.standard_normal((pings, bins)), amp_along, amp_range)
    u = special.ndtr(g / np.sqrt(g_gain))
    u = np.clip(u, 1e-15, 1.0 - 1e-15)
    texture = special.gammaincinv(k_shape, u) / k_shape
    return speckle * texture
