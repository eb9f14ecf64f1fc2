"""The look-angle warp: framebuffer columns spread evenly in slant range over flat ground.

A column's position is a pseudo slant range ``ρ_w(α) = h / sin α + c h (π/2 − α)`` for depression
angles α ≥ α0 = asin(h / r_max) (flat ground at the nominal altitude h, with a floor on the slope
near nadir), continued linearly below α0 so objects standing above the far-range horizon are
sampled too. The geometry shader evaluates the same function (gl/ping_samples.glsl).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

HALF_PI = 0.5 * math.pi


@dataclass(frozen=True)
class Warp:
    """Parameters of the warp for one segment and side (angles in radians, lengths in metres)."""

    h: float
    c: float
    alpha0: float
    alpha_min: float
    alpha_max: float = HALF_PI

    @classmethod
    def make(cls, altitude: float, max_range: float, alpha_top: float, c: float = 1.0) -> Warp:
        """Warp for a sonar ``altitude`` above the nominal seabed.

        ``alpha_top`` is the smallest depression angle at which scene geometry may appear within
        reach of the image (from the top of the scene); columns start just above it (0.05°, for
        rounding), so no column looks where nothing can be imaged.
        """
        h = min(max(altitude, 0.02 * max_range), 0.95 * max_range)
        alpha0 = math.asin(h / max_range)
        alpha_min = max(min(alpha0, alpha_top) - math.radians(0.05), -HALF_PI + 0.05)
        return cls(h=h, c=c, alpha0=alpha0, alpha_min=alpha_min)

    @property
    def rho0(self) -> float:
        """Warp value at ``alpha0``."""
        return self.h / math.sin(self.alpha0) + self.c * self.h * (HALF_PI - self.alpha0)

    @property
    def slope0(self) -> float:
        """``-dρ_w/dα`` at ``alpha0`` (the slope of the linear extension)."""
        s = math.sin(self.alpha0)
        return self.h * math.cos(self.alpha0) / (s * s) + self.c * self.h

    def rho(self, alpha: np.ndarray | float) -> np.ndarray:
        """ρ_w(α), vectorised, float64."""
        a = np.asarray(alpha, dtype=np.float64)
        above = self.h / np.sin(np.maximum(a, self.alpha0)) + self.c * self.h * (HALF_PI - a)
        below = self.rho0 + (self.alpha0 - a) * self.slope0
        return np.where(a >= self.alpha0, above, below)

    @property
    def rho_range(self) -> tuple[float, float]:
        """Warp values at the first (nadir) and last column edges."""
        return float(self.rho(self.alpha_max)), float(self.rho(self.alpha_min))

    def alpha(self, rho: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`rho` by bisection (ρ_w decreases with α), float64."""
        target = np.asarray(rho, dtype=np.float64)
        lo = np.full(target.shape, self.alpha_min)
        hi = np.full(target.shape, self.alpha_max)
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            above = self.rho(mid) > target
            lo = np.where(above, mid, lo)
            hi = np.where(above, hi, mid)
        return 0.5 * (lo + hi)

    def columns(self, first: int, count: int, total: int) -> tuple[np.ndarray, np.ndarray]:
        """Centre angle and angular width of columns ``first .. first+count-1`` of ``total``."""
        rho_lo, rho_hi = self.rho_range
        edges = rho_lo + (rho_hi - rho_lo) * np.arange(first, first + count + 1) / total
        a_edges = self.alpha(edges)
        centres = self.alpha(
            rho_lo + (rho_hi - rho_lo) * (np.arange(first, first + count) + 0.5) / total
        )
        return centres, np.abs(np.diff(a_edges))
