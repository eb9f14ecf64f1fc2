"""Transmit pulses for the coherent model: spectra, weighting windows and matched filters."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...errors import SonarRasterError

#: Time-bandwidth product of the default linear FM pulse.
DEFAULT_TIME_BANDWIDTH = 100.0
#: Weighting windows of the matched filter (amplitude taper over the processed band).
WINDOWS = ("taylor", "none", "hann", "hamming")
KINDS = ("lfm", "cw")
#: Taylor window of the default matched filter: peak range sidelobe -25 dB, nbar = 4. Its -3 dB
#: compressed width is 1.056 c / (2B) (unweighted: 0.886; Taylor -30 dB: 1.124; Hann: 1.44).
TAYLOR_SLL_DB = 25.0
TAYLOR_NBAR = 4


@dataclass(frozen=True)
class Pulse:
    """A transmit pulse at the sonar's centre frequency, described in baseband.

    Attributes
    ----------
    kind : {"lfm", "cw"}
        Linear FM up-chirp ``s(t) = exp(iπ (B/T) t²)`` or a constant tone ``s(t) = 1``, both of
        unit amplitude for ``|t| <= T/2``.
    bandwidth_hz : float
        B, Hz: the swept band of the chirp; for CW it must be ``1 / duration_s`` (the nominal
        bandwidth, so ``c / (2B) = c T / 2`` is its range resolution).
    duration_s : float
        T, seconds.
    window : {"taylor", "none", "hann", "hamming"}
        Amplitude weighting of the matched filter over the processed band (``B`` for a chirp,
        the main lobe ``2 / T`` of a tone's spectrum); the filter is zero outside that band.
        "taylor" is -25 dB, nbar = 4.
    """

    kind: str
    bandwidth_hz: float
    duration_s: float
    window: str = "taylor"

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise SonarRasterError(f"pulse kind must be one of {KINDS}, got {self.kind!r}")
        if self.window not in WINDOWS:
            raise SonarRasterError(f"pulse window must be one of {WINDOWS}, got {self.window!r}")
        for name in ("bandwidth_hz", "duration_s"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise SonarRasterError(f"pulse {name} must be a positive number, got {value!r}")
        tb = self.bandwidth_hz * self.duration_s
        if self.kind == "cw" and abs(tb - 1.0) > 1e-9:
            raise SonarRasterError("a CW pulse's bandwidth is 1 / duration; use Pulse.cw(duration)")
        if self.kind == "lfm" and tb < 1.0:
            raise SonarRasterError(
                f"a chirp needs bandwidth x duration >= 1, got {tb:.3g}; lengthen it or use CW"
            )

    @classmethod
    def lfm(
        cls, bandwidth_hz: float, duration_s: float | None = None, window: str = "taylor"
    ) -> Pulse:
        """Linear FM chirp; duration defaults to ``DEFAULT_TIME_BANDWIDTH / bandwidth``."""
        if duration_s is None and isinstance(bandwidth_hz, (int, float)) and bandwidth_hz > 0:
            duration_s = DEFAULT_TIME_BANDWIDTH / bandwidth_hz
        return cls("lfm", bandwidth_hz, duration_s, window)  # type: ignore[arg-type]

    @classmethod
    def cw(cls, duration_s: float, window: str = "none") -> Pulse:
        """Constant-frequency pulse of ``duration_s`` seconds (range resolution ``c T / 2``)."""
        if not (isinstance(duration_s, (int, float)) and duration_s > 0):
            raise SonarRasterError(f"pulse duration_s must be > 0, got {duration_s!r}")
        return cls("cw", 1.0 / duration_s, duration_s, window)

    @classmethod
    def for_range_bin(cls, range_bin: float, sound_speed: float = 1500.0) -> Pulse:
        """Default pulse: a Taylor-weighted chirp with ``c / (2B)`` equal to ``range_bin``."""
        return cls.lfm(sound_speed / (2.0 * range_bin))

    def resolution(self, sound_speed: float = 1500.0) -> float:
        """Nominal range resolution ``c / (2B)``, metres."""
        return sound_speed / (2.0 * self.bandwidth_hz)

    @property
    def band_hz(self) -> float:
        """Width of the band the matched filter passes, Hz."""
        return self.bandwidth_hz if self.kind == "lfm" else 2.0 / self.duration_s

    def spectrum(self, nu: np.ndarray) -> np.ndarray:
        """Baseband spectrum ``S(ν) = ∫ s(t) exp(−2πiνt) dt`` (seconds) at ν in Hz, complex."""
        nu = np.asarray(nu, dtype=np.float64)
        t = self.duration_s
        if self.kind == "cw":
            return t * np.sinc(nu * t) + 0j
        from scipy.special import fresnel

        k = self.bandwidth_hz / t  # sweep rate, Hz/s
        scale = math.sqrt(2.0 * k)
        s2, c2 = fresnel(scale * (0.5 * t - nu / k))
        s1, c1 = fresnel(scale * (-0.5 * t - nu / k))
        return np.exp(-1j * math.pi * nu**2 / k) * ((c2 - c1) + 1j * (s2 - s1)) / scale

    def weighting(self, nu: np.ndarray) -> np.ndarray:
        """Matched-filter amplitude weighting ``W(ν)``: the window over the band, 0 outside."""
        x = np.asarray(nu, dtype=np.float64) / self.band_hz
        inside = np.abs(x) <= 0.5
        if self.window == "none":
            w = np.ones_like(x)
        elif self.window == "hann":
            w = np.cos(math.pi * x) ** 2
        elif self.window == "hamming":
            w = 0.54 + 0.46 * np.cos(2.0 * math.pi * x)
        else:
            w = _taylor(x, TAYLOR_NBAR, TAYLOR_SLL_DB)
        return np.where(inside, w, 0.0)

    def matched_filter(self, nu: np.ndarray) -> np.ndarray:
        """Receive filter ``H(ν) = W(ν) S*(ν)``."""
        return self.weighting(nu) * np.conj(self.spectrum(nu))

    def compressed(self, nu: np.ndarray) -> np.ndarray:
        """Spectrum of the compressed pulse ``G(ν) = W(ν) |S(ν)|²`` (unnormalised)."""
        s = self.spectrum(nu)
        return self.weighting(nu) * (s.real**2 + s.imag**2) + 0j

    def to_dict(self) -> dict:
        """Plain description for metadata."""
        return {
            "kind": self.kind,
            "bandwidth_hz": self.bandwidth_hz,
            "duration_s": self.duration_s,
            "window": self.window,
        }


def _taylor(x: np.ndarray, nbar: int, sll_db: float) -> np.ndarray:
    """Taylor window ``1 + 2 Σ F_m cos(2π m x)`` on ``x`` in [-1/2, 1/2], peak (x = 0) = 1."""
    a = math.acosh(10.0 ** (sll_db / 20.0)) / math.pi
    s2 = nbar**2 / (a**2 + (nbar - 0.5) ** 2)
    ms = np.arange(1, nbar)
    coef = [
        (-1) ** (m + 1)
        * np.prod(1.0 - m**2 / s2 / (a**2 + (ms - 0.5) ** 2))
        / (2.0 * np.prod(1.0 - m**2 / ms[ms != m] ** 2))
        for m in ms
    ]
    out = np.ones_like(x)
    for m, f in zip(ms, coef, strict=True):
        out = out + 2.0 * f * np.cos(2.0 * math.pi * m * x)
    return out / (1.0 + 2.0 * sum(coef))
