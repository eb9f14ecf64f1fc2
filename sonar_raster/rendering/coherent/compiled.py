"""The coherent model's per-scatterer work as one compiled loop (numba).

:func:`render_runs` takes runs of facets (:class:`~sonar_raster.rendering.patches.Runs`, not
yet expanded) and does for each facet what :mod:`.model` does with numpy arrays, without
materialising any of them: the facet centroid, the cull (side, range reach, facing the track,
inside some ping's horizontal beam), the visibility test on the GL range maps (the rule of
:mod:`.visibility`), the jitter (the counter-based hash of :mod:`.scatter`), every
scatterer-ping term of Eq. 10 and its Kaiser-Bessel deposit on the fine delay grid
(:class:`.echo.EchoGrid`). The numpy path does ~25 passes over arrays of terms; this loop keeps
one scatterer in registers, so the cost is the arithmetic (docs/performance.md).

The same numbers as the numpy path up to float rounding: the cosine and sine of the phase come
from a polynomial on a quarter cycle (error < 1e-12) instead of numpy's float32 SIMD cosine
corrected to first order (~1e-7), so the images agree to ~1e-6 relative
(``tests/rendering/test_coherent_compiled.py``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# the jitter's hash: the same constants as scatter._splitmix and scatter._uniforms
from .scatter import GOLDEN, MIX1, MIX2, STEPS

#: Indices of the scalar parameters in the ``params`` vector of :func:`render_runs`.
P_R_LIMIT, P_SLACK, P_U_CUT, P_DEN, P_OFF, P_WAVELENGTH, P_TILT = 0, 1, 2, 3, 4, 5, 6
P_BEAM_WIDTH, P_BEAM_CUT, P_ORIGIN, P_STEP, P_BIN_TOL, P_REL_TOL = 7, 8, 9, 10, 11, 12
N_PARAMS = 13
#: Flags (int64 vector): sides imaged, law, beams, visibility, jitter, pings on one line.
F_PORT, F_STARBOARD, F_TWO_SIDES, F_LAMBERT, F_BEAM_H, F_VERTICAL = 0, 1, 2, 3, 4, 5
F_VISIBILITY, F_JITTER, F_LINE, F_UNIFORM_TABLE, F_ONE_ROLL = 6, 7, 8, 9, 10
N_FLAGS = 11
#: Beam kinds of ``F_BEAM_H``: none, Gaussian, sinc (see model.HorizontalBeam).
BEAM_NONE, BEAM_GAUSSIAN, BEAM_SINC = 0, 1, 2
#: Columns of a range map's row in ``maps_params`` (see visibility._Map).
M_T0, M_DT, M_H, M_C, M_ALPHA0, M_RHO0, M_SLOPE0, M_RHO_LO, M_RHO_HI, M_COLUMNS = range(10)
N_MAP = 10
#: Entries of the ``stats`` vector.
S_SCATTERERS, S_VISIBLE, S_PAIRS, S_AREA, S_AREA2, S_OUTSIDE = range(6)
N_STATS = 6
_SINC4_HALF = 0.31911
#: Compiled without Python's division checks (error_model "numpy") and with the float
#: contractions, reciprocals and reassociation LLVM may use (15 % faster); no assumption that
#: values are finite (the range maps hold inf).
_jit = njit(
    cache=True,
    nogil=True,
    error_model="numpy",
    fastmath={"nsz", "arcp", "contract", "afn", "reassoc"},
)
_TWO_PI = 2.0 * math.pi
#: Taylor coefficients, highest power first (Horner): sin z / z and cos z in z², atan w / w in
#: w² (|w| <= tan π/8), atanh s / s in s² (|s| <= 0.1716).
_SIN = tuple((-1.0) ** k / math.factorial(2 * k + 1) for k in range(6, -1, -1))
_COS = tuple((-1.0) ** k / math.factorial(2 * k) for k in range(6, -1, -1))
_ATAN = tuple((-1.0) ** k / (2 * k + 1) for k in range(10, -1, -1))
_ATANH = tuple(1.0 / (2 * k + 1) for k in range(8, -1, -1))


@_jit
def _splitmix(z):  # pragma: no cover - compiled
    z = z + GOLDEN
    z ^= z >> np.uint64(30)
    z *= MIX1
    z ^= z >> np.uint64(27)
    z *= MIX2
    z ^= z >> np.uint64(31)
    return z


@_jit
def _uniform(key, step):  # pragma: no cover - compiled
    bits = _splitmix(key + step) >> np.uint64(11)
    return np.int64(bits) * (1.0 / 9007199254740992.0) + 0.5 / 9007199254740992.0


@_jit
def cos_sin_cycles(f):  # pragma: no cover - compiled
    """``cos(2π f)`` and ``sin(2π f)`` for f in [-1/2, 1/2] (a polynomial; error < 1e-12)."""
    q = math.floor(4.0 * f + 0.5)
    z = _TWO_PI * (f - 0.25 * q)
    z2 = z * z
    s = 0.0
    for coefficient in _SIN:
        s = s * z2 + coefficient
    s *= z
    c = 0.0
    for coefficient in _COS:
        c = c * z2 + coefficient
    # rotate by q quarter turns without branches (the quadrant is random: branches mispredict)
    k = int(q) & 3
    swap = (k & 1) == 1
    a = s if swap else c
    b = c if swap else s
    return a * (1.0 - 2.0 * (((k + 1) >> 1) & 1)), b * (1.0 - 2.0 * ((k >> 1) & 1))


@_jit
def atan2(y, x):  # pragma: no cover - compiled
    """``math.atan2`` to < 1e-10 rad by a series on [0, tan(π/8)] (libm's is 5x slower here)."""
    ax = abs(x)
    ay = abs(y)
    big = max(ax, ay)
    if big == 0.0:
        return 0.0
    z = min(ax, ay) / big
    far = z > 0.41421356237309503
    w = (z - 1.0) / (z + 1.0) if far else z
    w2 = w * w
    a = 0.0
    for coefficient in _ATAN:
        a = a * w2 + coefficient
    a *= w
    a += 0.25 * math.pi if far else 0.0
    a = 0.5 * math.pi - a if ay > ax else a
    a = math.pi - a if x < 0.0 else a
    return -a if y < 0.0 else a


@_jit
def log(u):  # pragma: no cover - compiled
    """``math.log`` of u > 0 to ~1e-15 relative (an atanh series on the mantissa)."""
    m, e = math.frexp(u)
    if m < 0.7071067811865476:
        m *= 2.0
        e -= 1
    s = (m - 1.0) / (m + 1.0)
    s2 = s * s
    series = 0.0
    for coefficient in _ATANH:
        series = series * s2 + coefficient
    return e * 0.6931471805599453 + 2.0 * s * series


@_jit
def _first_at_least(tp, x, t0, inv):  # pragma: no cover - compiled
    """``np.searchsorted(tp, x, "left")``, started from a guess for near-even spacing."""
    n = len(tp)
    g = (x - t0) * inv
    i = 0 if not g > 0 else (n if g >= n else int(g))
    while i > 0 and tp[i - 1] >= x:
        i -= 1
    while i < n and tp[i] < x:
        i += 1
    return i


@_jit
def _first_above(tp, x, t0, inv):  # pragma: no cover - compiled
    """``np.searchsorted(tp, x, "right")``, started from a guess for near-even spacing."""
    n = len(tp)
    g = (x - t0) * inv
    i = 0 if not g > 0 else (n if g >= n else int(g))
    while i > 0 and tp[i - 1] > x:
        i -= 1
    while i < n and tp[i] <= x:
        i += 1
    return i


@_jit
def _interp(x, xp, fp, uniform):  # pragma: no cover - compiled
    """``np.interp`` for one value (held constant outside the table).

    ``uniform``: the table's angles are evenly spaced (found by index, not by search).
    """
    n = len(xp)
    if x <= xp[0]:
        return fp[0]
    if x >= xp[n - 1]:
        return fp[n - 1]
    if uniform:
        i = min(int((x - xp[0]) / (xp[1] - xp[0])), n - 2)
        if xp[i] > x:
            i -= 1
        elif xp[i + 1] <= x:
            i += 1
    else:
        i = np.searchsorted(xp, x, side="right") - 1
    return fp[i] + (x - xp[i]) * (fp[i + 1] - fp[i]) / (xp[i + 1] - xp[i])


@_jit
def _visible(ranges, m, t, x, v, sign, range_bin, rel_tol, bin_tol):  # pragma: no cover
    """visibility._test for one facet centroid on one side's map."""
    r = math.sqrt(x * x + v * v)
    alpha = atan2(-v, sign * x)
    if alpha >= m[M_ALPHA0]:  # sin(alpha) = -v / r
        rho = m[M_H] * r / -v + m[M_C] * m[M_H] * (0.5 * math.pi - alpha)
    else:
        rho = m[M_RHO0] + (m[M_ALPHA0] - alpha) * m[M_SLOPE0]
    columns = m[M_COLUMNS]
    col = (rho - m[M_RHO_LO]) / (m[M_RHO_HI] - m[M_RHO_LO]) * columns - 0.5
    row = (t - m[M_T0]) / m[M_DT]
    rows, cols = ranges.shape
    if not (row >= 0 and row < rows - 1 and col > -1.0 and col < cols and alpha <= 0.5 * math.pi):
        return True
    i = min(max(int(math.floor(row)), 0), rows - 2)
    j0 = int(math.floor(col))
    j = min(max(j0, 0), cols - 1)
    j1 = min(max(j0 + 1, 0), cols - 1)
    far = max(max(ranges[i, j], ranges[i, j1]), max(ranges[i + 1, j], ranges[i + 1, j1]))
    return r <= far * (1.0 + rel_tol) + bin_tol * range_bin


@_jit
def render_runs(  # noqa: C901  # pragma: no cover - compiled
    run_face,
    run_i,
    run_lo,
    run_len,
    run_base,
    run_slope,
    n_sub,
    normal,
    factor,
    facet_area,
    tp,
    order,
    pings,
    roll,
    travel,
    params,
    flags,
    beam_angles,
    beam_values,
    map_port,
    map_starboard,
    maps_params,
    range_bin,
    jitter_axes,
    seed_key,
    table,
    taps,
    acc,
    stats,
):
    """Cull, test, jitter and deposit every facet of some runs (see the module docstring).

    Parameters are plain arrays (numba): runs (``run_face`` the face index of each run), the
    per-face normal (fan components), amplitude factor and facet area, the block's pings
    (``tp`` their sorted travel, ``order`` the sort, ``pings`` (p, 3), ``roll``), ``travel``
    (model._travel), ``params``/``flags`` (``P_*``/``F_*``), the vertical beam table, the range
    maps of both sides and their ``M_*`` rows, the jitter (rows of ``axes · σ``, the hashed
    seed), the kernel's weight table (T, 2W) and W, the accumulator (rows, N, 2) and ``stats``
    (``S_*``; ``S_OUTSIDE`` counts deposits that missed the grid).
    """
    r_limit = params[P_R_LIMIT]
    slack = params[P_SLACK]
    u_cut = params[P_U_CUT]
    den = params[P_DEN]
    off = params[P_OFF]
    two_over_lambda = 2.0 / params[P_WAVELENGTH]
    tilt = params[P_TILT]
    width = params[P_BEAM_WIDTH]
    beam_cut = params[P_BEAM_CUT]
    g_origin = params[P_ORIGIN]
    inv_step = 1.0 / params[P_STEP]
    rel_tol = params[P_REL_TOL]
    bin_tol = params[P_BIN_TOL]
    beam_kind = flags[F_BEAM_H]
    lambert = flags[F_LAMBERT] != 0
    vertical = flags[F_VERTICAL] != 0
    line = flags[F_LINE] != 0
    uniform = flags[F_UNIFORM_TABLE] != 0
    one_roll = line and flags[F_ONE_ROLL] != 0
    two_sides = flags[F_TWO_SIDES] != 0
    n_rows = acc.shape[0]
    n_grid = acc.shape[1]
    n_table = table.shape[0]
    half = taps // 2 - 1
    n_pings = len(tp)
    t0 = tp[0]
    inv_dt = (n_pings - 1) / (tp[n_pings - 1] - tp[0]) if tp[n_pings - 1] > tp[0] else 0.0
    ln2 = math.log(2.0)
    for q in range(len(run_face)):
        face = run_face[q]
        nt = normal[face, 0]
        nx = normal[face, 1]
        nv = normal[face, 2]
        ns = n_sub[face]
        for jj in range(run_len[q]):
            j = run_lo[q] + jj
            fj = float(j)
            t = run_base[q, 0] + run_slope[q, 0] * fj
            x = run_base[q, 1] + run_slope[q, 1] * fj
            v = run_base[q, 2] + run_slope[q, 2] * fj
            # cull: side, range reach, facing the track, inside some ping's beam
            if x > 0:
                if flags[F_STARBOARD] == 0:
                    continue
            elif x < 0:
                if flags[F_PORT] == 0:
                    continue
            else:
                continue
            rho = math.sqrt(x * x + v * v)
            if not rho < r_limit + slack:
                continue
            stats[S_SCATTERERS] += 1.0
            if not x * nx + v * nv < 0:
                continue
            reach = (rho + slack) * u_cut / den + slack + 1e-9
            lo = _first_at_least(tp, t - reach, t0, inv_dt)
            if not (lo < n_pings and tp[lo] <= t + reach):
                continue
            starboard = x > 0
            if flags[F_VISIBILITY] != 0:
                if starboard:
                    ok = _visible(
                        map_starboard, maps_params[1], t, x, v, 1.0, range_bin, rel_tol, bin_tol
                    )
                else:
                    ok = _visible(
                        map_port, maps_params[0], t, x, v, -1.0, range_bin, rel_tol, bin_tol
                    )
                if not ok:
                    continue
            a = facet_area[face]
            stats[S_VISIBLE] += 1.0
            stats[S_AREA] += a
            stats[S_AREA2] += a * a
            # jitter (scatter._gaussian3, rotated by the frame's axes times σ)
            pt, px, pv = t, x, v
            if flags[F_JITTER] != 0:
                cell = run_i[q] * ns + j
                key = _splitmix(np.uint64(face) ^ seed_key)
                key = _splitmix(key ^ np.uint64(cell))
                u0 = _uniform(key, STEPS[0])
                u1 = _uniform(key, STEPS[1])
                u2 = _uniform(key, STEPS[2])
                u3 = _uniform(key, STEPS[3])
                r1 = math.sqrt(-2.0 * log(u0))
                r2 = math.sqrt(-2.0 * log(u2))
                c1, s1 = cos_sin_cycles(u1 - 0.5)
                c3, _s3 = cos_sin_cycles(u3 - 0.5)
                g0 = min(max(-r1 * c1, -4.0), 4.0)
                g1 = min(max(-r1 * s1, -4.0), 4.0)
                g2 = min(max(-r2 * c3, -4.0), 4.0)
                pt += g0 * jitter_axes[0, 0] + g1 * jitter_axes[0, 1] + g2 * jitter_axes[0, 2]
                px += g0 * jitter_axes[1, 0] + g1 * jitter_axes[1, 1] + g2 * jitter_axes[1, 2]
                pv += g0 * jitter_axes[2, 0] + g1 * jitter_axes[2, 1] + g2 * jitter_axes[2, 2]
            # the pings within the beam's reach of the (jittered) scatterer
            reach = (math.sqrt(px * px + pv * pv) + off) * u_cut / den + off + 1e-9
            lo = _first_at_least(tp, pt - reach, t0, inv_dt)
            hi = _first_above(tp, pt + reach, t0, inv_dt)
            sign = 1.0 if starboard else -1.0
            slot = 1 if (two_sides and starboard) else 0
            fac = factor[face]
            dep0 = 0.0
            gain0 = 1.0
            if vertical and line:
                dep0 = atan2(-(pv - pings[0, 2]), abs(px - pings[0, 1]))
                if one_roll:
                    gain0 = math.sqrt(
                        _interp(dep0 - tilt - sign * roll[0], beam_angles, beam_values, uniform)
                    )
            for s in range(lo, hi):
                p = order[s]
                dt = pt - pings[p, 0]
                dx = px - pings[p, 1] + dt * travel[1]
                dv = pv - pings[p, 2] + dt * travel[2]
                fore = dt * travel[0]
                r = math.sqrt(dx * dx + dv * dv + fore * fore)
                if not (r < r_limit and r > 1e-9):
                    continue
                inv = 1.0 / r
                u = fore * inv
                if abs(u) > u_cut:
                    continue
                cos_inc = -(nx * dx + nv * dv + nt * fore) * inv
                if not cos_inc > 0:
                    continue
                amp = math.sqrt(cos_inc) if lambert else cos_inc
                amp *= inv * inv * fac
                if beam_kind == BEAM_GAUSSIAN:
                    if abs(u) > beam_cut:
                        continue
                    b = u / width
                    amp *= math.exp(-2.0 * ln2 * min(b * b, 16.0))
                elif beam_kind == BEAM_SINC:
                    if abs(u) > beam_cut:
                        continue
                    y = math.pi * _SINC4_HALF * 2.0 * u / width
                    sinc = math.sin(y) / y if y != 0 else 1.0
                    amp *= sinc * sinc
                if one_roll:
                    amp *= gain0
                elif vertical:
                    dep = dep0 if line else atan2(-dv, abs(dx))
                    amp *= math.sqrt(
                        _interp(dep - tilt - sign * roll[p], beam_angles, beam_values, uniform)
                    )
                if amp == 0.0:
                    continue
                cycles = r * two_over_lambda
                cycles -= math.floor(cycles + 0.5)
                re, im = cos_sin_cycles(cycles)
                re *= amp
                im *= -amp  # exp(−4πi r / λ)
                row = p * (2 if two_sides else 1) + slot
                xg = (r - g_origin) * inv_step
                base = math.floor(xg)
                pos = (xg - base) * n_table
                cell_t = min(int(pos), n_table - 1)
                pos -= cell_t
                first = int(base) - half
                if first < 0 or first + taps > n_grid or row >= n_rows:
                    stats[S_OUTSIDE] += 1.0
                    continue
                stats[S_PAIRS] += 1.0
                for k in range(taps):
                    w = table[cell_t, k] + pos * table[cell_t, taps + k]
                    acc[row, first + k, 0] += w * re
                    acc[row, first + k, 1] += w * im
