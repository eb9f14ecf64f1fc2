"""The coherent model's fine delay grid: deposit, pulse compression, envelope and binning.

Everything is in slant-range units: a delay ``τ`` is the range ``ρ = c τ / 2`` and a baseband
frequency ``ν`` is the range frequency ``κ = 2 ν / c`` (cycles per metre). One ping and side is a
row of ``N`` complex samples ``ρ_n = ρ_0 + n δ`` with ``δ = range_bin / M``; the image part of the
row holds ``M`` samples at the midpoints of each range bin's ``M`` equal parts.

Matched-filter output of scatterers with complex amplitudes ``c_k`` at ranges ``R_k``:
``y(ρ) = Σ_k c_k g(ρ − R_k)``, ``g`` the compressed pulse (inverse transform of
``G(κ) = |S|² W``). Two evaluations of the same sum on the same periodic grid:

- direct (Eq. 10 in the frequency domain): ``Y_m = G_m Σ_k c_k exp(−2πi ξ_m x_k)`` at every
  in-band DFT frequency ``ξ_m`` (cycles per sample) with ``x_k = (R_k − ρ_0) / δ``, then one
  inverse FFT. O(scatterers × frequencies).
- fast (non-uniform FFT gridding): spread each ``c_k`` over the ``W`` grid samples nearest
  ``x_k`` with a Kaiser-Bessel kernel ``φ`` (the fractional-delay interpolation), one FFT,
  multiply by ``G_m / Φ̂(ξ_m)`` (compression and kernel deconvolution in one product), one
  inverse FFT. O(W × scatterers + N log N). The grid samples the signal band at least
  ``_OVERSAMPLING`` times above its Nyquist rate, where ``W = 6`` taps keep the difference to the
  direct sum near 1e-7 of the peak.

``G`` is scaled so that ``Σ_n |g_n|² = M``: a unit point target puts exactly unit energy into the
bin-averaged image, wherever it lies between samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Kernel taps per deposit.
KERNEL_TAPS = 6
#: Least ratio of the grid's Nyquist frequency to the highest signal frequency.
_OVERSAMPLING = 4.0
#: Table steps per grid sample of the kernel's weights.
_TABLE = 8192
_TABLES: dict[tuple[int, float], np.ndarray] = {}
#: Complex frequency-domain terms per batch of the direct sum (bounds its memory to ~64 MB).
_DIRECT_BATCH = 1 << 22


@dataclass(frozen=True)
class KaiserBessel:
    """Kaiser-Bessel gridding kernel ``φ(z) = I0(β sqrt(1 − (2z/W)²)) / I0(β)``, ``|z| < W/2``.

    Attributes
    ----------
    taps : int
        Width W in grid samples (even).
    beta : float
        Shape parameter, from the oversampling σ by Beatty et al. (2005):
        ``β = π sqrt(W² (σ − 1/2)² / σ² − 0.8)``.
    """

    taps: int
    beta: float

    @classmethod
    def for_oversampling(cls, sigma: float, taps: int = KERNEL_TAPS) -> KaiserBessel:
        """Kernel for a grid whose Nyquist frequency is ``sigma`` times the signal's highest."""
        beta = math.pi * math.sqrt(taps**2 * (sigma - 0.5) ** 2 / sigma**2 - 0.8)
        return cls(taps, beta)

    def weights(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """First grid index and the ``W`` tap weights for positions ``x`` (grid units).

        Returns ``first`` (shape (p,), int64) and ``w`` (shape (W, p)): tap ``q`` goes to grid
        index ``first + q``, at ``z = first + q − x`` in ``(−W/2, W/2]``. Weights are linearly
        interpolated in a table of ``_TABLE`` steps per sample (relative error < 1e-7).
        """
        base = np.floor(x)
        pos = x - base
        pos *= _TABLE  # fractional part in table steps, [0, _TABLE)
        cell = pos.astype(np.int64)
        np.minimum(cell, _TABLE - 1, out=cell)
        pos -= cell
        rows = np.take(self.table(), cell, axis=1)
        w = rows[self.taps :] * pos
        w += rows[: self.taps]
        first = base.astype(np.int64)
        first -= self.taps // 2 - 1
        return first, w

    def table(self) -> np.ndarray:
        """``φ_q(f_i)`` (rows q < W) and ``φ_q(f_{i+1}) − φ_q(f_i)`` (rows W + q), shape (2W, T).

        ``φ_q(f) = φ(q − W/2 + 1 − f)`` is tap q's weight at fraction ``f_i = i / _TABLE``.
        """
        key = (self.taps, self.beta)
        if key not in _TABLES:
            f = np.arange(_TABLE + 1) / _TABLE
            q = np.arange(self.taps, dtype=np.float64)
            phi = self.kernel(q[:, None] - self.taps // 2 + 1.0 - f)
            _TABLES[key] = np.ascontiguousarray(np.concatenate([phi[:, :-1], np.diff(phi)]))
        return _TABLES[key]

    def kernel(self, z: np.ndarray) -> np.ndarray:
        """φ(z), zero outside ``|z| < W/2``."""
        from scipy.special import i0

        s = 1.0 - (2.0 * np.asarray(z, dtype=np.float64) / self.taps) ** 2
        return np.where(s > 0, i0(self.beta * np.sqrt(np.maximum(s, 0.0))) / i0(self.beta), 0.0)

    def transform(self, xi: np.ndarray) -> np.ndarray:
        """Fourier transform ``Φ̂(ξ) = ∫ φ(z) exp(−2πiξz) dz`` (real), ξ in cycles per sample.

        ``W sinh(sqrt(β² − (πWξ)²)) / (sqrt(β² − (πWξ)²) I0(β))``; only used in the signal band,
        where ``πWξ < β``.
        """
        from scipy.special import i0

        arg = np.sqrt(np.maximum(self.beta**2 - (math.pi * self.taps * xi) ** 2, 1e-300))
        return self.taps * np.sinh(arg) / (arg * i0(self.beta))


@dataclass(frozen=True)
class EchoGrid:
    """The periodic fine grid shared by every ping of one render.

    Attributes
    ----------
    n : int
        Samples per row (a fast FFT length).
    samples_per_bin : int
        M, fine samples per image range bin.
    step : float
        δ, metres of slant range per sample.
    origin : float
        ρ_0, slant range of sample 0, metres (negative: the grid has a margin before range 0).
    first_image : int
        Index of the first image sample (the midpoint of bin 0's first part).
    n_bins : int
        Image range bins.
    band : ndarray, shape (f,), int64
        DFT indices where the compressed spectrum is non-zero.
    xi : ndarray, shape (f,)
        Their signed frequencies, cycles per sample.
    compressed : ndarray, shape (f,), complex128
        ``G_m`` there, scaled so that ``Σ_n |g_n|² = M``.
    kernel : KaiserBessel
        Gridding kernel of the fast method.
    """

    n: int
    samples_per_bin: int
    step: float
    origin: float
    first_image: int
    n_bins: int
    band: np.ndarray
    xi: np.ndarray
    compressed: np.ndarray
    kernel: KaiserBessel

    @classmethod
    def make(
        cls,
        range_bin: float,
        n_bins: int,
        sound_speed: float,
        compressed_spectrum,
        band_hz: float,
        support_m: float,
        samples_per_bin: int | None = None,
    ) -> EchoGrid:
        """Lay out the grid.

        Parameters
        ----------
        range_bin : float
            Image bin size, metres.
        n_bins : int
            Image bins.
        sound_speed : float
            c, m/s.
        compressed_spectrum : callable
            ``G(ν)`` for baseband frequencies ν in Hz (array in, complex array out), zero
            outside ``|ν| <= band_hz / 2``.
        band_hz : float
            Width of the band where G is non-zero, Hz.
        support_m : float
            Half-length of the compressed pulse in slant range (``c T / 2``), metres: the margin
            each side of the image that keeps the circular convolution from wrapping into it.
        samples_per_bin : int, optional
            M; default the least that samples the band ``_OVERSAMPLING`` times above Nyquist
            (and at least 4).
        """
        from scipy.fft import next_fast_len

        need = 2.0 * _OVERSAMPLING * band_hz * range_bin / sound_speed
        m = samples_per_bin or max(4, int(math.ceil(need - 1e-9)))
        step = range_bin / m
        pad = int(math.ceil(support_m / step)) + 2 * KERNEL_TAPS + 8
        n = int(next_fast_len(n_bins * m + 2 * pad))
        xi_all = np.fft.fftfreq(n)
        nu = xi_all / step * (0.5 * sound_speed)
        g = np.asarray(compressed_spectrum(nu), dtype=np.complex128)
        band = np.flatnonzero(g != 0)
        if len(band) == 0:
            raise ValueError("the pulse's compressed spectrum is zero on the grid")
        g = g * math.sqrt(m * n / float(np.sum(np.abs(g[band]) ** 2)))
        xi = xi_all[band]
        sigma = 0.5 / max(float(np.abs(xi).max()), 1e-12)
        kernel = KaiserBessel.for_oversampling(max(sigma, 1.5))
        return cls(n, m, step, -pad * step + 0.5 * step, pad, n_bins, band, xi, g[band], kernel)

    # -- positions --------------------------------------------------------------------------
    def position(self, slant_range: np.ndarray) -> np.ndarray:
        """Fractional grid index of slant ranges (metres)."""
        return (slant_range - self.origin) / self.step

    @property
    def image_ranges(self) -> np.ndarray:
        """Slant range of each image sample, metres, shape (n_bins * M,)."""
        k = np.arange(self.n_bins * self.samples_per_bin)
        return self.origin + (self.first_image + k) * self.step

    # -- accumulation -----------------------------------------------------------------------
    def accumulator(self, rows: int, method: str) -> np.ndarray:
        """Zeroed accumulator for ``rows`` rows.

        "fast": float64 (2, N, rows), real and imaginary deposits, sample-major (a chunk of
        scatterers spans a few metres of range, so its deposit touches a short stretch);
        "direct": complex (rows, f), the in-band spectrum.
        """
        if method == "fast":
            return np.zeros((2, self.n, rows))
        return np.zeros((rows, len(self.band)), dtype=np.complex128)

    def add(self, acc: np.ndarray, row: np.ndarray, x: np.ndarray, c: np.ndarray) -> None:
        """Add amplitudes ``c`` (complex, shape (p,)) at grid positions ``x`` of rows ``row``."""
        self.add_parts(acc, row, x, np.ascontiguousarray(c.real), np.ascontiguousarray(c.imag))

    def add_parts(
        self, acc: np.ndarray, row: np.ndarray, x: np.ndarray, re: np.ndarray, im: np.ndarray
    ) -> None:
        """:meth:`add` with the amplitudes' real and imaginary parts (shape (p,) each)."""
        if len(row) == 0:
            return
        if acc.dtype == np.complex128:
            self._add_direct(acc, row, x, re + 1j * im)
        else:
            self._deposit(acc, row, x, re, im)

    def _deposit(
        self, acc: np.ndarray, row: np.ndarray, x: np.ndarray, re: np.ndarray, im: np.ndarray
    ) -> None:
        first, w = self.kernel.weights(x)
        if first.min() < 0 or first.max() + self.kernel.taps > self.n:
            raise ValueError("a scatterer lies outside the echo grid")
        # One bincount per tap on the first taps' indices (sample-major), added at the tap's
        # shift: no (taps, p) index array (1.5x faster than one bincount of every tap).
        rows = acc.shape[2]
        idx = first * rows
        idx += row
        lo = int(idx.min())
        idx -= lo
        size = int(idx.max()) + 1
        acc_re, acc_im = acc[0].reshape(-1), acc[1].reshape(-1)
        for q in range(self.kernel.taps):
            at = slice(lo + q * rows, lo + q * rows + size)
            acc_re[at] += np.bincount(idx, weights=w[q] * re, minlength=size)
            acc_im[at] += np.bincount(idx, weights=w[q] * im, minlength=size)

    def _add_direct(self, acc: np.ndarray, row: np.ndarray, x: np.ndarray, c: np.ndarray) -> None:
        order = np.argsort(row, kind="stable")
        row, x, c = row[order], x[order], c[order]
        cuts = np.flatnonzero(np.diff(row)) + 1
        starts = np.concatenate([[0], cuts])
        ends = np.concatenate([cuts, [len(row)]])
        batch = max(1, _DIRECT_BATCH // len(self.xi))
        for s, e in zip(starts, ends, strict=True):
            for lo in range(s, e, batch):
                hi = min(e, lo + batch)
                phase = np.exp(-2j * math.pi * np.outer(x[lo:hi], self.xi))
                acc[row[s]] += c[lo:hi] @ phase

    # -- output -----------------------------------------------------------------------------
    def signal(self, acc: np.ndarray) -> np.ndarray:
        """Compressed complex baseband signal at the image samples, shape (rows, n_bins * M)."""
        from scipy import fft

        rows = acc.shape[2] if acc.dtype != np.complex128 else acc.shape[0]
        spectrum = np.zeros((rows, self.n), dtype=np.complex128)
        if acc.dtype == np.complex128:
            spectrum[:, self.band] = acc * self.compressed
        else:
            u = fft.fft((acc[0] + 1j * acc[1]).T, axis=1)
            spectrum[:, self.band] = u[:, self.band] * (
                self.compressed / self.kernel.transform(self.xi)
            )
        y = fft.ifft(spectrum, axis=1)
        return y[:, self.first_image : self.first_image + self.n_bins * self.samples_per_bin]

    def intensity(self, acc: np.ndarray) -> np.ndarray:
        """Envelope power averaged over each range bin's samples, shape (rows, n_bins)."""
        y = self.signal(acc)
        power = y.real**2 + y.imag**2
        return power.reshape(len(power), self.n_bins, self.samples_per_bin).mean(axis=2)

    def nbytes(self, rows: int) -> int:
        """Bytes held while finishing ``rows`` rows (accumulator, spectrum, FFT temporaries)."""
        return rows * self.n * 16 * 4
