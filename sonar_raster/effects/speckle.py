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

import functools
import math

import numpy as np
from scipy import fft as sp_fft
from scipy import ndimage, special

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
    return speckle * gamma_texture(shape, rng, amp_along, amp_range, k_shape)


def gamma_texture(
    shape: tuple[int, int],
    rng: np.random.Generator,
    amp_along: np.ndarray,
    amp_range: float,
    k_shape: float,
) -> np.ndarray:
    """Unit-mean gamma(ν) texture, shape ``shape``.

    A Gaussian field filtered by the amplitude kernels (σ in pings per column, and in bins),
    mapped through the gamma quantile function: its one-point law is exactly gamma(ν)/ν.
    """
    g, g_gain = _correlated(rng.standard_normal(shape), amp_along, amp_range)
    u = special.ndtr(g / np.sqrt(g_gain))
    u = np.clip(u, 1e-15, 1.0 - 1e-15)
    return special.gammaincinv(k_shape, u) / k_shape


#: How a recorder turns the sub-samples of one recorded bin into its value (XTF's
#: ``DownsampleMethod``: 2 = MAX, 4 = RMS, the mean of the intensity).
DOWNSAMPLE_KINDS = ("off", "max", "mean")
_BLOCK_BINS = 128  # recorded bins per block of the sub-sampled field (bounds the memory)
#: Most sub-samples drawn at once by the recorder's speckle: about 100 MB at the peak (the
#: noise, its filtered copy and the intensity; 2**24 took 0.8 GB).
_FINE_BUDGET = 1 << 21
#: Sub-samples of the Monte Carlo that sets the recorded speckle's mean (~0.2 %), drawn in
#: blocks of ``_FINE_BUDGET``.
_MEAN_SAMPLES = 1 << 24


def _range_taps(sigma: float) -> np.ndarray:
    """Gaussian FIR taps of standard deviation ``sigma`` (samples) with ``Σ h² = 1``."""
    if sigma <= 0:
        return np.ones(1)
    half = int(math.ceil(4.0 * sigma))
    x = np.arange(-half, half + 1, dtype=np.float64)
    taps = np.exp(-0.5 * (x / sigma) ** 2)
    return taps / math.sqrt(float(np.sum(taps * taps)))


def _column_noise(
    entropy: np.random.SeedSequence, first: int, last: int, rows: int, n: int, fields: int = 2
) -> np.ndarray:
    """White Gaussian noise (fields, rows, (last - first) * n) for recorded columns first..last-1.

    Each column (also those outside the image, negative or past its end) has its own stream,
    keyed by its index, so overlapping blocks draw identical noise for the columns they share.
    """
    parts = []
    for col in range(first, last):
        key = (*entropy.spawn_key, col + 2**31)  # non-negative for the halo left of column 0
        child = np.random.SeedSequence(entropy.entropy, spawn_key=key)
        parts.append(np.random.default_rng(child).standard_normal((fields, rows, n)))
    return np.concatenate(parts, axis=2)


def _reduce(intensity: np.ndarray, n: int, how: str) -> np.ndarray:
    """Combine each run of n sub-samples (last axis) into one recorded value."""
    blocks = intensity.reshape(intensity.shape[0], -1, n)
    return blocks.max(axis=2) if how == "max" else blocks.mean(axis=2)


def _fine_field(
    entropy: np.random.SeedSequence,
    pings: int,
    cols: tuple[int, int],
    n: int,
    sigma_along: np.ndarray,
    sigma_fine: float,
    k_shape: float | None = None,
    looks: float = 1.0,
) -> np.ndarray:
    """Unit-mean intensity on the sub-sample grid of recorded columns cols[0]..cols[1]-1.

    ``|z|²`` of complex Gaussian noise filtered by the resolution cell's amplitude kernels
    (mapped to the gamma(L) law of L looks when ``looks`` ≠ 1); with ``k_shape`` ν, times a
    gamma(ν) texture correlated over the same cell (K speckle below the recorded bin).
    """
    amp_fine = math.sqrt(2.0) * sigma_fine
    taps = _range_taps(amp_fine)
    halo = -(-(len(taps) // 2) // n)  # recorded columns of noise either side, ceil
    lo, hi = cols
    fields = 2 if k_shape is None else 3
    white = _column_noise(entropy, lo - halo, hi + halo, pings, n, fields)
    width = (hi - lo) * n
    # Σ h² = 1: unit variance; the halo covers the taps, so the edge mode never matters.
    z = ndimage.correlate1d(white, taps, axis=2)[:, :, halo * n : halo * n + width]
    gain = np.ones(width)
    amp_along = np.repeat(math.sqrt(2.0) * np.asarray(sigma_along[lo:hi], np.float64), n)
    if np.any(amp_along > 0):
        z = np.stack([filter_columns(part, amp_along, circular=True) for part in z])
        gain = _filter_gain(pings, amp_along)
    intensity = (z[0] ** 2 + z[1] ** 2) / (2.0 * gain)
    if looks != 1.0:  # exponential -> uniform -> gamma(L) / L, sample by sample
        u = np.clip(-np.expm1(-intensity), 1e-15, 1.0 - 1e-15)
        intensity = special.gammaincinv(looks, u) / looks
    if k_shape is None:
        return intensity
    u = np.clip(special.ndtr(z[2] / np.sqrt(gain)), 1e-15, 1.0 - 1e-15)
    return intensity * special.gammaincinv(k_shape, u) / k_shape


@functools.lru_cache(maxsize=64)
def downsampled_mean(
    n: int, sigma_fine: float, how: str, k_shape: float | None = None, looks: float = 1.0
) -> float:
    """E[max] or E[mean] of n correlated unit-mean (K, gamma or exponential) sub-samples.

    The recorded speckle's mean before normalisation (Monte Carlo with a fixed seed, ~0.2 %).
    """
    if how == "mean" or n == 1:
        return 1.0
    entropy = np.random.SeedSequence(20261124)
    # 64 x 4096 recorded values; fewer columns when n is large (a coarse bin), so the draw stays
    # near 2**24 sub-samples (the maximum of many sub-samples varies little). Each column has
    # its own stream, so drawing them in blocks gives the same values.
    cols = max(16, min(4096, _MEAN_SAMPLES // (64 * n)))
    block = max(1, _FINE_BUDGET // (64 * n))
    values = np.empty((64, cols))
    for lo in range(0, cols, block):
        hi = min(cols, lo + block)
        sample = _fine_field(entropy, 64, (lo, hi), n, np.zeros(cols), sigma_fine, k_shape, looks)
        values[:, lo:hi] = _reduce(sample, n, how)
    return float(values.mean())


def recorded_speckle_field(
    shape: tuple[int, int],
    entropy: np.random.SeedSequence,
    sigma_along: np.ndarray,
    resolution_samples: float,
    subsamples: int,
    how: str,
    k_shape: float | None = None,
    looks: float = 1.0,
) -> np.ndarray:
    """Unit-mean speckle of a recorder that keeps one value per n sub-samples.

    The complex field is made on the recorder's sub-sample grid (n per recorded bin), with the
    range resolution cell there, and the along-track cell as in :func:`speckle_field`; each
    recorded bin keeps the maximum (XTF DownsampleMethod MAX) or the mean of the intensity of
    its n sub-samples. Several independent resolution cells per bin give a narrower one-point
    law than exponential (the looks of the downsampling) and little correlation between bins.

    Parameters
    ----------
    shape : (pings, bins)
        Recorded image shape.
    entropy : numpy.random.SeedSequence
        Seed; every recorded column draws its own stream from it.
    sigma_along : ndarray, shape (bins,)
        Along-track σ of the two-way intensity kernel, pings, per recorded column.
    resolution_samples : float
        σ of the two-way range intensity kernel in sub-samples (0: independent sub-samples).
    subsamples : int
        Sub-samples per recorded bin, n ≥ 1.
    how : {"max", "mean"}
    k_shape : float, optional
        Shape ν of a gamma texture of the seabed, correlated over the resolution cell and
        applied to the sub-samples before the recorder reduces them (K speckle); None: none.
    looks : float
        Looks L ≥ 1 of each sub-sample (gamma(L) one-point law; 1: exponential).

    Returns
    -------
    ndarray, shape ``shape``, float64
        Intensity factors ≥ 0 with expectation 1.
    """
    pings, bins = shape
    sigma_along = np.broadcast_to(np.asarray(sigma_along, dtype=np.float64), (bins,))
    out = np.empty(shape)
    block = max(1, min(_BLOCK_BINS, _FINE_BUDGET // max(1, pings * subsamples)))
    for lo in range(0, bins, block):
        hi = min(bins, lo + block)
        fine = _fine_field(
            entropy, pings, (lo, hi), subsamples, sigma_along, resolution_samples, k_shape, looks
        )
        out[:, lo:hi] = _reduce(fine, subsamples, how)
    return out / downsampled_mean(subsamples, float(resolution_samples), how, k_shape, looks)
