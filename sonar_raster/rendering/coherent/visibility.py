"""Visibility of scatterers from the GL raster's range maps (no ray caster needed).

The raster's pass 1 already knows the nearest surface along every ray of a fan. For a block of
pings, :class:`RangeMaps` sweeps the fan along the segment at a fine travel step (rows) and the
raster's warped look angles (columns), keeping the slant range of the first hit of each ray
(:meth:`~sonar_raster.rendering.gl.raster.RasterRenderer.fan_ranges`). A scatterer at travel t,
look angle α and slant range r (its facet centroid, seen from the track point abeam of it, as
the ray test of :mod:`..fan` does) is visible when the largest first-hit range of the four rays
around it is not nearer than r:

``r <= max(R[i, j], R[i+1, j], R[i, j+1], R[i+1, j+1]) (1 + 1e-4) + range_bin / 4``.

On a surface that is convex or planar between the rays (a planar seabed's range is convex in
angle and linear in travel) the largest corner bounds the range inside the cell, so lit points
never shadow themselves; the tolerance covers float32 ranges and mild concavity. A point is
hidden only when all four rays stop short of it, so shadow edges are placed to within one ray
(one column is half a range bin, one row ``dt`` along track): the test is permissive at edges.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Relative slack of the range comparison (float32 ranges, curvature between rays).
REL_TOL = 1e-4
#: Slack in range bins.
BIN_TOL = 0.25
#: Most rows of one map (the GL target's limit is 16384).
MAX_ROWS = 8192


@dataclass(frozen=True)
class _Map:
    ranges: np.ndarray  # (rows, columns) float32, inf where a ray meets nothing
    sign: float  # +1 starboard, -1 port
    t0: float
    dt: float
    h: float
    c: float
    alpha0: float
    rho0: float
    slope0: float
    rho_lo: float
    rho_hi: float
    columns: int


class RangeMaps:
    """First-hit range maps of one block of pings (one per side) and the visibility test.

    Parameters
    ----------
    renderer : RasterRenderer
        The GL renderer that draws the maps (its context and scene upload are reused).
    scene, sonar : Scene, Sonar
        What is drawn and the range sampling.
    segment : Segment
        The block's straight track segment (its frame is the scatterers' frame).
    sides : tuple of str
        Sides imaged.
    t_lo, t_hi : float
        Travel interval to cover, metres from the segment's first ping.
    dt : float
        Travel between rows, metres (raised when the interval would need more than
        ``MAX_ROWS`` rows).
    origin : ndarray, shape (3,)
        The scene's local origin, world metres.
    """

    def __init__(self, renderer, scene, sonar, segment, sides, t_lo, t_hi, dt, origin) -> None:
        dt = max(float(dt), (t_hi - t_lo) / (MAX_ROWS - 2))
        rows = int(math.ceil((t_hi - t_lo) / dt)) + 2
        self.range_bin = sonar.range_bin
        self.maps = {}
        self.rays = 0
        for side in sides:
            ranges, warp, columns = renderer.fan_ranges(
                scene, sonar, segment, side, t_lo - dt, dt, rows, origin
            )
            rho_lo, rho_hi = warp.rho_range
            self.rays += ranges.size
            self.maps[side] = _Map(
                ranges,
                1.0 if side == "starboard" else -1.0,
                t_lo - dt,
                dt,
                warp.h,
                warp.c,
                warp.alpha0,
                warp.rho0,
                warp.slope0,
                rho_lo,
                rho_hi,
                columns,
            )

    def visible(self, nominal: np.ndarray) -> np.ndarray:
        """Whether each facet centroid (frame coordinates (t, x, v), shape (k, 3)) is visible.

        Parameters
        ----------
        nominal : ndarray, shape (k, 3)
            Travel, starboard and up coordinates in the segment's frame, metres.
        """
        t, x, v = nominal.T
        out = np.ones(len(t), dtype=bool)
        for side, m in self.maps.items():
            on = np.flatnonzero((x > 0) if side == "starboard" else (x < 0))
            if len(on) == 0:
                continue
            out[on] = _test(m, t[on], x[on], v[on], self.range_bin)
        return out


def _test(m: _Map, t: np.ndarray, x: np.ndarray, v: np.ndarray, range_bin: float) -> np.ndarray:
    r = np.hypot(x, v)
    alpha = np.arctan2(-v, m.sign * x)
    # the warp of gl/ping_samples.glsl (columns cover depressions up to nadir)
    above = m.h / np.sin(np.maximum(alpha, m.alpha0)) + m.c * m.h * (0.5 * math.pi - alpha)
    rho = np.where(alpha >= m.alpha0, above, m.rho0 + (m.alpha0 - alpha) * m.slope0)
    col = (rho - m.rho_lo) / (m.rho_hi - m.rho_lo) * m.columns - 0.5
    row = (t - m.t0) / m.dt
    rows, cols = m.ranges.shape
    inside = (row >= 0) & (row < rows - 1) & (col > -1.0) & (col < cols) & (alpha <= 0.5 * math.pi)
    i = np.clip(np.floor(row).astype(np.int64), 0, rows - 2)
    j0 = np.floor(col).astype(np.int64)
    j = np.clip(j0, 0, cols - 1)
    j1 = np.clip(j0 + 1, 0, cols - 1)
    flat = m.ranges.reshape(-1)
    a = i * cols
    b = a + cols
    nearest_far = np.maximum(
        np.maximum(flat[a + j], flat[a + j1]), np.maximum(flat[b + j], flat[b + j1])
    )
    ok = r <= nearest_far * (1.0 + REL_TOL) + BIN_TOL * range_bin
    return ok | ~inside
