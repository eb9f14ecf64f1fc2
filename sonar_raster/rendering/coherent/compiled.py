"""The coherent model's per-scatterer work as compiled loops over small buffers (numba).

:func:`render_runs` takes runs of facets (:class:`~sonar_raster.rendering.patches.Runs`, not
yet expanded) and does for each facet what :mod:`.model` does with numpy arrays, without
materialising any of them: the facet centroid, the cull (side, range reach, facing the track,
inside some ping's horizontal beam), the visibility test on the GL range maps (the rule of
:mod:`.visibility`), the jitter (the counter-based hash of :mod:`.scatter`), every
scatterer-ping term of Eq. 10 and its Kaiser-Bessel deposit on the fine delay grid
(:class:`.echo.EchoGrid`). The numpy path does ~25 passes over arrays of terms; this works on
small buffers that stay in cache, in three kinds of loop: the facet tests, one facet at a time;
the visibility, the jitter and the terms of a buffer, each one loop without branches, so that
the compiler runs it in SIMD lanes (the polynomial cosine, sine, arctangent, logarithm and
power of two below exist for that: library calls do not vectorise); the deposit, one term at a
time (docs/performance.md).

The same numbers as the numpy path up to float rounding: the cosine and sine of the phase come
from a polynomial on a quarter cycle (error < 1e-12) instead of numpy's float32 SIMD cosine
corrected to first order (~1e-7), so the images agree to ~1e-6 relative
(``tests/rendering/test_coherent_compiled.py``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, types
from numba.extending import intrinsic

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
#: e^z / Taylor, highest power first (|z| <= ln 2 / 2), and the float64 mantissa's bits.
_EXP = tuple(1.0 / math.factorial(k) for k in range(12, -1, -1))
_MANTISSA = np.uint64((1 << 52) - 1)
_ONE_BITS = np.uint64(1023 << 52)
#: Buffer sizes of :func:`render_runs`: scatterers, scatterer-ping pairs (fit in L1/L2 cache).
_SCATTERERS = 512
_PAIRS = 2048


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
    """``math.atan2`` to < 1e-10 rad by a series on [0, tan(π/8)]; no branches (loops vectorise).

    A zero ``y`` counts as positive (``atan2(-0.0, -1.0)`` is π, not −π).
    """
    ax = abs(x)
    ay = abs(y)
    z = min(ax, ay) / max(ax, ay, 1e-300)  # 0 at the origin, as math.atan2(±0, +0)
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
def _first_at_least(tp, x, t0, inv):  # pragma: no cover - compiled
    """``np.searchsorted(tp, x, "left")``, guessed for even spacing, then walked to the index."""
    n = len(tp)
    g = (x - t0) * inv
    i = 0 if not g > -1.0 else (n if g >= n else int(math.ceil(g)))  # tp[i] >= x when even
    while i > 0 and tp[i - 1] >= x:
        i -= 1
    while i < n and tp[i] < x:
        i += 1
    return i


@_jit
def _first_above(tp, x, t0, inv):  # pragma: no cover - compiled
    """``np.searchsorted(tp, x, "right")``, guessed for even spacing, then walked to the index."""
    n = len(tp)
    g = (x - t0) * inv
    i = 0 if not g >= 0.0 else (n if g >= n else int(g) + 1)  # tp[i] > x when even
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
def _visible(n, t, x, v, ranges, m, sign, range_bin, rel_tol, bin_tol, cells, reach, out):
    # pragma: no cover - compiled
    """visibility._test for scatterers ``[0, n)`` of one side on its map (``out``: 1 or 0).

    Two loops: the warp to map cells without branches (SIMD lanes), then the four map values
    per scatterer (gathers, which keep the first loop from vectorising). ``cells`` (3, n) and
    ``reach`` (n) are scratch: row, column and the column step; the range (−1 off the map).
    """
    rows, cols = ranges.shape
    h = m[M_H]
    ch = m[M_C] * m[M_H]
    alpha0 = m[M_ALPHA0]
    rho0 = m[M_RHO0]
    slope0 = m[M_SLOPE0]
    rho_lo = m[M_RHO_LO]
    scale = m[M_COLUMNS] / (m[M_RHO_HI] - m[M_RHO_LO])
    t0 = m[M_T0]
    inv_dt = 1.0 / m[M_DT]
    c_i, c_j, c_step = cells[0], cells[1], cells[2]
    for k in range(n):
        a = x[k]
        b = v[k]
        r = math.sqrt(a * a + b * b)
        alpha = atan2(-b, sign * a)
        near = h * r / -b + ch * (0.5 * math.pi - alpha)  # sin(alpha) = -v / r
        rho = near if alpha >= alpha0 else rho0 + (alpha0 - alpha) * slope0
        col = (rho - rho_lo) * scale - 0.5
        row = (t[k] - t0) * inv_dt
        inside = (row >= 0) & (row < rows - 1) & (col > -1.0) & (col < cols)
        inside = inside & (alpha <= 0.5 * math.pi)
        row = row if inside else 0.0
        col = col if inside else 0.0
        j0 = int(math.floor(col))
        j = max(j0, 0)
        c_i[k] = min(int(math.floor(row)), rows - 2)
        c_j[k] = j
        c_step[k] = min(j0 + 1, cols - 1) - j
        reach[k] = r if inside else -1.0  # off the map: visible
    tol = bin_tol * range_bin
    for k in range(n):
        i = c_i[k]
        j = c_j[k]
        j1 = j + c_step[k]
        far = max(max(ranges[i, j], ranges[i, j1]), max(ranges[i + 1, j], ranges[i + 1, j1]))
        out[k] = 1 if reach[k] <= far * (1.0 + rel_tol) + tol else 0


def _bit_cast(source, target):  # pragma: no cover - compiled
    """A compiled function giving the ``target`` value with the bits of a ``source`` value."""

    @intrinsic
    def cast(typingctx, x):
        def codegen(context, builder, signature, args):
            return builder.bitcast(args[0], context.get_value_type(target))

        return target(source), codegen

    return cast


#: IEEE-754 bits of a float64 as uint64, and back.
_float_bits = _bit_cast(types.float64, types.uint64)
_bits_float = _bit_cast(types.uint64, types.float64)


@_jit
def exp2(y):  # pragma: no cover - compiled
    """``2 ** y`` for -1022 <= y <= 1023 (a series on [-1/2, 1/2]; error < 1e-13 relative).

    Without branches or library calls, so that loops over it vectorise.
    """
    k = math.floor(y + 0.5)
    z = (y - k) * 0.6931471805599453
    e = 0.0
    for coefficient in _EXP:
        e = e * z + coefficient
    return e * _bits_float(np.uint64(int(k) + 1023) << np.uint64(52))


@_jit
def log(u):  # pragma: no cover - compiled
    """``math.log`` of a normal u > 0 to ~1e-15 relative (an atanh series on the mantissa).

    The mantissa and exponent come from the bits, without branches or library calls, so that
    loops over it vectorise.
    """
    bits = _float_bits(u)
    e = float(np.int64(bits >> np.uint64(52)) - 1023)
    m = _bits_float((bits & _MANTISSA) | _ONE_BITS)  # in [1, 2)
    big = m > 1.4142135623730951
    m = 0.5 * m if big else m
    e = e + 1.0 if big else e
    s = (m - 1.0) / (m + 1.0)
    s2 = s * s
    series = 0.0
    for coefficient in _ATANH:
        series = series * s2 + coefficient
    return e * 0.6931471805599453 + 2.0 * s * series


@_jit
def _jitter(n, t, x, v, face_key, cell, axes):  # pragma: no cover - compiled
    """Move scatterers ``[0, n)`` by their hashed Gaussian jitter (scatter._gaussian3 · axes)."""
    for i in range(n):
        key = _splitmix(face_key[i] ^ cell[i])
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
        t[i] += g0 * axes[0, 0] + g1 * axes[0, 1] + g2 * axes[0, 2]
        x[i] += g0 * axes[1, 0] + g1 * axes[1, 1] + g2 * axes[1, 2]
        v[i] += g0 * axes[2, 0] + g1 * axes[2, 1] + g2 * axes[2, 2]


@_jit
def _terms(n, geometry, out, params, flags, n_table, half):  # pragma: no cover - compiled
    """Every term of pairs ``[0, n)``: amplitude, phasor and kernel position, no branches.

    ``geometry``: rows fore, dx, dv (scatterer minus ping), the facet normal (nx, nv, nt) and
    the amplitude factor; ``out``: amplitude (0 where a test fails), real and imaginary part of
    the amplitude times ``exp(−4πi r/λ)``, the kernel's table position and fraction, the first
    tap's grid index (as float). One loop over plain arrays, so that it runs in SIMD lanes.
    """
    fore, dx, dv, nx, nv, nt, fac = (
        geometry[0],
        geometry[1],
        geometry[2],
        geometry[3],
        geometry[4],
        geometry[5],
        geometry[6],
    )
    o_amp, o_re, o_im, o_cell, o_pos, o_first = out[0], out[1], out[2], out[3], out[4], out[5]
    r_limit = params[P_R_LIMIT]
    u_cut = params[P_U_CUT]
    two_over_lambda = 2.0 / params[P_WAVELENGTH]
    width = params[P_BEAM_WIDTH]
    beam_cut = params[P_BEAM_CUT]
    g_origin = params[P_ORIGIN]
    inv_step = 1.0 / params[P_STEP]
    beam_kind = flags[F_BEAM_H]
    lambert = flags[F_LAMBERT] != 0
    cut = min(u_cut, beam_cut) if beam_kind != BEAM_NONE else u_cut
    sinc_scale = 0.5 * _SINC4_HALF * 2.0 / width if width > 0 else 0.0
    for k in range(n):
        a = dx[k]
        b = dv[k]
        f = fore[k]
        r = math.sqrt(a * a + b * b + f * f)
        inv = 1.0 / max(r, 1e-9)
        u = f * inv
        cos_inc = -(nx[k] * a + nv[k] * b + nt[k] * f) * inv
        ok = (r < r_limit) & (r > 1e-9) & (abs(u) <= cut) & (cos_inc > 0.0)
        c = max(cos_inc, 0.0)
        amp = (math.sqrt(c) if lambert else c) * inv * inv * fac[k]
        if beam_kind == BEAM_GAUSSIAN:
            w = u / width
            amp *= exp2(-2.0 * min(w * w, 16.0))
        elif beam_kind == BEAM_SINC:
            h = u * sinc_scale  # y / 2π
            _c, sn = cos_sin_cycles(h - math.floor(h + 0.5))
            y = _TWO_PI * h
            sinc = sn / y if y != 0.0 else 1.0
            amp *= sinc * sinc
        amp = amp if ok else 0.0
        cycles = r * two_over_lambda
        cycles -= math.floor(cycles + 0.5)
        re, im = cos_sin_cycles(cycles)
        o_amp[k] = amp
        o_re[k] = re * amp
        o_im[k] = -im * amp  # exp(−4πi r / λ)
        xg = (r - g_origin) * inv_step
        base = math.floor(xg)
        pos = (xg - base) * n_table
        cell = min(math.floor(pos), n_table - 1.0)
        o_cell[k] = cell
        o_pos[k] = pos - cell
        o_first[k] = base - half


@_jit
def _deposit(n, out, rows, gain, per_pair, table, taps, acc, stats):  # pragma: no cover
    """Add terms ``[0, n)`` (see :func:`_terms`) to the accumulator, ``taps`` taps each.

    ``gain``: each term's vertical-beam amplitude, used where it changes from ping to ping
    (``per_pair``).
    """
    o_amp, o_re, o_im, o_cell, o_pos, o_first = out[0], out[1], out[2], out[3], out[4], out[5]
    n_rows = acc.shape[0]
    n_grid = acc.shape[1]
    for k in range(n):
        re = o_re[k]
        im = o_im[k]
        amp = o_amp[k]
        if per_pair:
            amp *= gain[k]
            re *= gain[k]
            im *= gain[k]
        if amp == 0.0:
            continue
        row = rows[k]
        first = int(o_first[k])
        if first < 0 or first + taps > n_grid or row >= n_rows:
            stats[S_OUTSIDE] += 1.0
            continue
        stats[S_PAIRS] += 1.0
        cell_t = int(o_cell[k])
        pos = o_pos[k]
        for q in range(taps):
            w = table[cell_t, q] + pos * table[cell_t, taps + q]
            acc[row, first + q, 0] += w * re
            acc[row, first + q, 1] += w * im


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

    Three stages over buffers: the facet tests, one scatterer at a time (branches); the jitter
    of a buffer of scatterers and then every term of a buffer of scatterer-ping pairs, each one
    loop without branches (SIMD lanes); the deposit, one term at a time.
    """
    r_limit = params[P_R_LIMIT]
    slack = params[P_SLACK]
    u_cut = params[P_U_CUT]
    den = params[P_DEN]
    n_pings = len(tp)
    t0 = tp[0]
    inv_dt = (n_pings - 1) / (tp[n_pings - 1] - tp[0]) if tp[n_pings - 1] > tp[0] else 0.0
    # one buffer of facets per side (0 port, 1 starboard): position, hash keys, face
    s_t = np.empty((2, _SCATTERERS))
    s_x = np.empty((2, _SCATTERERS))
    s_v = np.empty((2, _SCATTERERS))
    s_key = np.empty((2, _SCATTERERS), dtype=np.uint64)
    s_cell = np.empty((2, _SCATTERERS), dtype=np.uint64)
    s_face = np.empty((2, _SCATTERERS), dtype=np.int64)
    # pair buffer: geometry in, terms out, accumulator row, vertical-beam gain
    capacity = max(_PAIRS, 2 * n_pings)
    pairs = (
        np.empty((7, capacity)),
        np.empty((6, capacity)),
        np.empty(capacity, dtype=np.int64),
        np.empty(capacity),
        np.empty(_SCATTERERS, dtype=np.uint8),
        np.empty((3, _SCATTERERS), dtype=np.int64),
        np.empty(_SCATTERERS),
    )
    # the pings in travel order (tp): position, accumulator row, roll
    sorted_pings = (
        tp,
        pings[order, 1].copy(),
        pings[order, 2].copy(),
        order * (2 if flags[F_TWO_SIDES] != 0 else 1),
        roll[order].copy(),
    )
    maps = (map_port, map_starboard)
    fill = np.zeros(2, dtype=np.int64)
    in_reach = 0.0  # facets in range reach (a register, not a store per facet)
    for q in range(len(run_face)):
        face = run_face[q]
        nx = normal[face, 1]
        nv = normal[face, 2]
        key = _splitmix(np.uint64(face) ^ seed_key)
        cell0 = run_i[q] * n_sub[face]
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
            in_reach += 1.0
            if not x * nx + v * nv < 0:
                continue
            reach = (rho + slack) * u_cut / den + slack + 1e-9
            lo = _first_at_least(tp, t - reach, t0, inv_dt)
            if not (lo < n_pings and tp[lo] <= t + reach):
                continue
            side = 1 if x > 0 else 0
            n_s = fill[side]
            s_t[side, n_s] = t
            s_x[side, n_s] = x
            s_v[side, n_s] = v
            s_key[side, n_s] = key
            s_cell[side, n_s] = np.uint64(cell0 + j)
            s_face[side, n_s] = face
            fill[side] = n_s + 1
            if n_s + 1 == _SCATTERERS:
                _flush(
                    side, n_s + 1, s_t[side], s_x[side], s_v[side], s_key[side], s_cell[side],
                    s_face[side], maps[side], maps_params[side], pairs, sorted_pings,
                    normal, factor, facet_area, tp, travel, params, flags,
                    beam_angles, beam_values, range_bin, jitter_axes, table, taps, acc, stats,
                )  # fmt: skip
                fill[side] = 0
    stats[S_SCATTERERS] += in_reach
    for side in range(2):
        if fill[side] > 0:
            _flush(
                side, fill[side], s_t[side], s_x[side], s_v[side], s_key[side], s_cell[side],
                s_face[side], maps[side], maps_params[side], pairs, sorted_pings,
                normal, factor, facet_area, tp, travel, params, flags,
                beam_angles, beam_values, range_bin, jitter_axes, table, taps, acc, stats,
            )  # fmt: skip


@_jit
def _flush(  # noqa: C901  # pragma: no cover - compiled
    side, n, s_t, s_x, s_v, s_key, s_cell, s_face, ranges, m, pairs, sorted_pings,
    normal, factor, facet_area, tp, travel, params, flags,
    beam_angles, beam_values, range_bin, jitter_axes, table, taps, acc, stats,
):  # fmt: skip
    """Test, jitter and deposit a buffer of ``n`` facets of one side (0 port, 1 starboard)."""
    geometry, out, rows, gain, visible, cells, reach = pairs
    u_cut = params[P_U_CUT]
    den = params[P_DEN]
    off = params[P_OFF]
    tilt = params[P_TILT]
    vertical = flags[F_VERTICAL] != 0
    line = flags[F_LINE] != 0
    uniform = flags[F_UNIFORM_TABLE] != 0
    one_roll = line and flags[F_ONE_ROLL] != 0
    per_pair_gain = vertical and not one_roll
    two_sides = flags[F_TWO_SIDES] != 0
    n_table = table.shape[0]
    half = taps // 2 - 1
    n_pings = len(tp)
    t0 = tp[0]
    inv_dt = (n_pings - 1) / (tp[n_pings - 1] - tp[0]) if tp[n_pings - 1] > tp[0] else 0.0
    sign = 1.0 if side == 1 else -1.0
    slot = 1 if (two_sides and side == 1) else 0
    if flags[F_VISIBILITY] != 0:
        _visible(
            n, s_t, s_x, s_v, ranges, m, sign, range_bin,
            params[P_REL_TOL], params[P_BIN_TOL], cells, reach, visible,
        )  # fmt: skip
    else:
        visible[:n] = 1
    if flags[F_JITTER] != 0:
        _jitter(n, s_t, s_x, s_v, s_key, s_cell, jitter_axes)
    g_fore, g_dx, g_dv = geometry[0], geometry[1], geometry[2]
    g_nx, g_nv, g_nt, g_fac = geometry[3], geometry[4], geometry[5], geometry[6]
    ping_t, ping_x, ping_v, ping_row, ping_roll = sorted_pings
    tr0, tr1, tr2 = travel[0], travel[1], travel[2]
    capacity = len(rows)
    n_p = 0
    count = 0.0
    area = 0.0
    area2 = 0.0
    for i in range(n):
        if visible[i] == 0:
            continue
        face = s_face[i]
        a = facet_area[face]
        count += 1.0
        area += a
        area2 += a * a
        pt = s_t[i]
        px = s_x[i]
        pv = s_v[i]
        # the pings within the beam's reach of the (jittered) scatterer
        reach = (math.sqrt(px * px + pv * pv) + off) * u_cut / den + off + 1e-9
        lo = _first_at_least(tp, pt - reach, t0, inv_dt)
        hi = _first_above(tp, pt + reach, t0, inv_dt)
        if hi <= lo:
            continue
        if n_p + hi - lo > capacity:
            _terms(n_p, geometry, out, params, flags, n_table, half)
            _deposit(n_p, out, rows, gain, per_pair_gain, table, taps, acc, stats)
            n_p = 0
        fac = factor[face]
        nx = normal[face, 1]
        nv = normal[face, 2]
        nt = normal[face, 0]
        dep0 = 0.0
        if vertical and line:
            dep0 = atan2(-(pv - ping_v[0]), abs(px - ping_x[0]))
            if one_roll:
                fac *= math.sqrt(
                    _interp(dep0 - tilt - sign * ping_roll[0], beam_angles, beam_values, uniform)
                )
        for s in range(lo, hi):
            dt = pt - ping_t[s]
            dx = px - ping_x[s] + dt * tr1
            dv = pv - ping_v[s] + dt * tr2
            g_fore[n_p] = dt * tr0
            g_dx[n_p] = dx
            g_dv[n_p] = dv
            g_nx[n_p] = nx
            g_nv[n_p] = nv
            g_nt[n_p] = nt
            g_fac[n_p] = fac
            rows[n_p] = ping_row[s] + slot
            if per_pair_gain:
                dep = dep0 if line else atan2(-dv, abs(dx))
                gain[n_p] = math.sqrt(
                    _interp(dep - tilt - sign * ping_roll[s], beam_angles, beam_values, uniform)
                )
            n_p += 1
    stats[S_VISIBLE] += count
    stats[S_AREA] += area
    stats[S_AREA2] += area2
    _terms(n_p, geometry, out, params, flags, n_table, half)
    _deposit(n_p, out, rows, gain, per_pair_gain, table, taps, acc, stats)
