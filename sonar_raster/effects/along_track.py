"""Along-track beam: per-range-column Gaussian blur along pings, by FFT.

A side-scan array of length L has a horizontal (along-track) beam of one-way -3 dB width
``β ≈ 0.886 λ / L`` (uniform line aperture, one-way intensity ``sinc²(L sin φ / λ)``), so at
slant range r it ensonifies an along-track footprint ``β r`` wide: targets are smeared over
more pings the further out they are. A synthetic aperture (SAS) instead focuses every range
to one along-track resolution δ. Both are modelled by a Gaussian two-way intensity kernel
along pings whose full width at half maximum is ``β r / √2`` (the square of a one-way Gaussian
of width β) or δ, one kernel per range column.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import fft as sp_fft

#: Full width at half maximum of a Gaussian over its standard deviation, 2 sqrt(2 ln 2).
FWHM_PER_SIGMA = 2.0 * math.sqrt(2.0 * math.log(2.0))
#: One-way -3 dB beam width of a uniform line aperture, in units of λ / L.
LINE_APERTURE_WIDTH = 0.886


def kernel_sigma_pings(
    n_bins: int,
    range_bin: float,
    ping_spacing: float,
    beamwidth_rad: float | None,
    sas_resolution: float | None,
) -> np.ndarray:
    """Standard deviation (pings) of the two-way along-track intensity kernel per range bin.

    Parameters
    ----------
    n_bins : int
        Range bins; bin k is centred at slant range ``(k + 0.5) * range_bin``.
    range_bin : float
        Range bin size, metres.
    ping_spacing : float
        Along-track distance between pings, metres.
    beamwidth_rad : float or None
        One-way -3 dB horizontal beam width (side-scan mode), radians.
    sas_resolution : float or None
        Along-track resolution of a synthetic aperture, metres (used when beamwidth is None).

    Returns
    -------
    ndarray, shape (n_bins,), float64
        σ in pings: ``β r / (√2 · 2.3548 · Δy)`` (side-scan) or ``δ / (2.3548 · Δy)`` (SAS).
    """
    if beamwidth_rad is not None:
        r = (np.arange(n_bins) + 0.5) * range_bin
        fwhm = beamwidth_rad * r / math.sqrt(2.0)
    else:
        assert sas_resolution is not None
        fwhm = np.full(n_bins, float(sas_resolution))
    return fwhm / (FWHM_PER_SIGMA * ping_spacing)


def gaussian_transfer(n: int, sigma: np.ndarray) -> np.ndarray:
    """Unit-sum Gaussian transfer ``exp(-2 π² σ² f²)`` on the rfft grid, (n // 2 + 1, len(σ))."""
    f = sp_fft.rfftfreq(n)
    return np.exp(-2.0 * math.pi**2 * np.outer(f * f, np.asarray(sigma, dtype=np.float64) ** 2))


def filter_columns(data: np.ndarray, sigma: np.ndarray, circular: bool = False) -> np.ndarray:
    """Convolve each column of ``data`` along axis 0 with a unit-sum Gaussian of its own σ.

    Parameters
    ----------
    data : ndarray, shape (pings, bins), real
    sigma : ndarray, shape (bins,)
        Standard deviation per column, in rows (pings); 0 leaves a column unchanged.
    circular : bool
        Wrap around the ends (right for stationary noise fields); otherwise the image is
        extended by mirror reflection so the ends keep their level.

    Returns
    -------
    ndarray, shape (pings, bins), float64
    """
    n = data.shape[0]
    pad = 0 if circular else int(math.ceil(6.0 * float(np.max(sigma, initial=0.0)))) + 1
    pad = min(pad, 3 * n)  # a kernel wider than the image: its mirror images repeat anyway
    work = np.pad(data, ((pad, pad), (0, 0)), mode="symmetric") if pad else data
    m = work.shape[0] if circular else sp_fft.next_fast_len(work.shape[0], real=True)
    spectrum = sp_fft.rfft(work, n=m, axis=0)
    spectrum *= gaussian_transfer(m, sigma)
    out = sp_fft.irfft(spectrum, n=m, axis=0)
    return out[pad : pad + n]


def peak_gain(sigma: np.ndarray) -> np.ndarray:
    """``Σ_n exp(-n² / (2 σ²))`` per column: the sum of a unit-peak kernel sampled at pings.

    Turns a unit-sum blur into the unit-peak beam weighting: a point target keeps its level at
    the beam's centre, and a seabed returns the sum over the footprint (``√(2π) σ`` pings when
    σ >> 1, one ping when σ -> 0).
    """
    sigma = np.asarray(sigma, dtype=np.float64)
    out = np.ones_like(sigma)
    small = (sigma > 0) & (sigma <= 1.5)
    n = np.arange(1, 16)[:, None]
    out[small] = 1.0 + 2.0 * np.exp(-(n**2) / (2.0 * sigma[small] ** 2)).sum(axis=0)
    big = sigma > 1.5  # Poisson summation; the next term is below 1e-19
    out[big] = (
        math.sqrt(2.0 * math.pi)
        * sigma[big]
        * (1.0 + 2.0 * np.exp(-2.0 * math.pi**2 * sigma[big] ** 2))
    )
    return out


def blur_along_track(side: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """Apply the unit-peak along-track beam to one side image.

    Parameters
    ----------
    side : ndarray, shape (pings, bins)
        Intensity per ping strip (each row covers one ping spacing along track).
    sigma : ndarray, shape (bins,)
        Kernel σ in pings per range column (:func:`kernel_sigma_pings`).

    Returns
    -------
    ndarray, shape (pings, bins), float64, >= 0
        ``Σ_m I[m, k] exp(-(n - m)² / (2 σ_k²))`` per ping n and bin k.
    """
    out = filter_columns(side.astype(np.float64), sigma) * peak_gain(sigma)
    np.maximum(out, 0.0, out=out)  # FFT round-off around exact zeros
    return out
