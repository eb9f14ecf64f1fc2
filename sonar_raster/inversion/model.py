"""The Lambertian model of one side in slant range, its objective and exact discrete gradient.

Conventions
-----------
Per ping the transducer is the origin; ``x > 0`` is the ground distance across track on the
imaged side, ``y`` the along-track distance and ``Z`` the seabed elevation relative to the
transducer (negative below it). Unknowns are (pings, ground cells) arrays: axis 0 is ``y``
(spacing ``dy``), axis 1 is ``x`` (spacing ``dx``, cell centres ``x``). Data and model are
(pings, slant bins) arrays of intensity per metre of slant range, bin k covering
``[k, k + 1) * range_bin``.

Slopes use the stencil of ``numpy.gradient`` with ``edge_order=1``: central differences
``(Z[j+1] − Z[j−1]) / 2h`` inside, one-sided ``(Z[1] − Z[0]) / h`` and
``(Z[n−1] − Z[n−2]) / h`` at the ends.

Model (the renderer's image formation, K absorbed into Φ): with ``n = (−Zx, −Zy, 1)`` the
upward normal, the seabed patch ``dA = s dx dy`` (``s = |n|``) seen from the sonar at range
``ρ = sqrt(x² + Z²)`` has ``cos θ = (x Zx − Z) / (ρ s)``, so ``cos θ dA = q dx dy`` with
``q = (x Zx − Z) / ρ`` (Zy drops out). Ground cell j returns the energy
``e_j = Φ_j R_j max(0, q_j) dx`` at its own slant range ``ρ_j``; it is split between the two
nearest slant-bin centres by linear weights, ``u = ρ / range_bin − 1/2``, ``k0 = ⌊u⌋``,
``t = u − k0``, and the model density is ``Î_k = Σ_j e_j w_jk / range_bin``. With
``Geometry.subsamples = n > 1`` the energy is shared equally by n points of the cell's tangent
plane, at ``x + o dx`` and ``Z + o dx Zx`` for ``o = (s + 1/2)/n − 1/2``, each split the same
way: the cell's return then covers its range extent instead of one range (against the exact
density of a flat seabed, 5 cm cells and bins: 5.6 % off at n = 1, 1.3 % at 2, 0.5 % at 3).
The points' ranges move with the cell's slope too, which the gradients carry.

With ``Geometry.deposit = "segment"`` the renderer's boxes are followed instead (a return at
range r belongs to bin ``⌊r / range_bin⌋``): point s stands for the sub-segment of the tangent
plane between offsets ``(s/n − 1/2) dx`` and ``((s+1)/n − 1/2) dx``, its energy is spread
uniformly over the slant-range interval ``[lo, hi]`` between its two ends' ranges (in bins),
and bin k takes the overlap ``clip(hi − k, 0, 1) − clip(lo − k, 0, 1)`` over ``hi − lo``; an
interval inside one bin (``⌊lo⌋ = ⌊hi⌋``, which includes zero length) puts all its energy
there with weight 1. The shares are piecewise linear in ``lo`` and ``hi`` (kinks where an end
crosses a bin edge), ``∂w_k/∂lo = (w_k − [k = ⌊lo⌋]) / (hi − lo)`` and
``∂w_k/∂hi = ([k = ⌊hi⌋] − w_k) / (hi − lo)``, and the ends move with Z and Zx as the tent's
points do. (Where a segment passes its closest point to the sonar, a facet seen at normal
incidence as at nadir, the interval between its ends' ranges is used and the fold is missed.)
Either deposit carries the foreshortening ``dr/dx = (x + Z Zx) / ρ`` and the misregistration
of relief in slant range, and sums the cells that fold onto one range (layover) as the
renderer does.

A seabed that is not Lambertian (``Geometry.law``, :class:`.law.ScatteringLaw`) returns
``R f(θ) dA = R cos θ L(cos θ) dA``: q becomes ``q̃ = q L(c)`` with ``c = cos θ = q / s``,
``s = sqrt(1 + Zx² + Zy²)``, and its derivatives follow by the chain rule
(:func:`_apply_law`). The along-track slope Zy (the :func:`slope` stencil over the pings,
spacing ``dy``; NaN taken as 0) no longer drops out, so a cell depends on its neighbouring
pings: :func:`adjoint`, :func:`jacobian_z` and :func:`evaluate` carry that through
``∂ ln q̃ / ∂Zy = −c g Zy / s²`` (``g = d ln L / dc``), kept per cell as ``dlnq_dzy``
(None for Lambert's law, whose model stays ping by ping). Left out, Zy made the model's
image of a sand-law render differ by 2.6 % (median) where the along-track slope passed 0.3.

The terms that depend on Z alone (q, its derivatives, every point's bins, weights and
``Z_s/ρ_s``) are prepared once per Z and reused by :func:`forward`, :func:`adjoint`,
:func:`evaluate` and :func:`jacobian_z` while Z is unchanged (a per-thread cache of the last
:data:`CACHE_SIZE`, compared by value; :func:`clear_cache` frees it); the work runs over blocks
of whole pings so that its temporaries stay in the processor's cache.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.sparse.linalg import spsolve

from .law import ScatteringLaw


def slope(z: np.ndarray, axis: int, step: float) -> np.ndarray:
    """Finite-difference derivative of ``z`` along ``axis`` (stencil in the module notes)."""
    zt = np.moveaxis(z, axis, -1)
    out = np.zeros_like(zt)
    if zt.shape[-1] >= 2:
        out[..., 1:-1] = (zt[..., 2:] - zt[..., :-2]) / (2.0 * step)
        out[..., 0] = (zt[..., 1] - zt[..., 0]) / step
        out[..., -1] = (zt[..., -1] - zt[..., -2]) / step
    return np.moveaxis(out, -1, axis)


def slope_adjoint(g: np.ndarray, axis: int, step: float, power: int = 1) -> np.ndarray:
    """Transpose of :func:`slope` applied to ``g``; ``power=2`` squares every stencil weight.

    ``power=2`` gives ``Σ_k D[k, j]² g[k]``, used for the Gauss-Newton diagonal.
    """
    gt = np.moveaxis(g, axis, -1)
    out = np.zeros_like(gt)
    if gt.shape[-1] >= 2:
        sign = -1.0 if power == 1 else 1.0
        inner = gt[..., 1:-1] / (2.0 * step) ** power
        out[..., 2:] += inner
        out[..., :-2] += sign * inner
        first, last = gt[..., 0] / step**power, gt[..., -1] / step**power
        out[..., 1] += first
        out[..., 0] += sign * first
        out[..., -1] += last
        out[..., -2] += sign * last
    return np.moveaxis(out, -1, axis)


def _slope_x(z: np.ndarray, step: float, out: np.ndarray) -> np.ndarray:
    """:func:`slope` of ``z`` (pings, cells) along axis 1, written into ``out``."""
    if z.shape[1] < 2:
        out.fill(0.0)
        return out
    np.subtract(z[:, 2:], z[:, :-2], out=out[:, 1:-1])
    out[:, 1:-1] /= 2.0 * step
    np.subtract(z[:, 1], z[:, 0], out=out[:, 0])
    out[:, 0] /= step
    np.subtract(z[:, -1], z[:, -2], out=out[:, -1])
    out[:, -1] /= step
    return out


def _add_slope_adjoint_x(g: np.ndarray, step: float, out: np.ndarray) -> np.ndarray:
    """``out += slope_adjoint(g, 1, step)`` for (pings, cells) arrays; ``g`` is overwritten."""
    if g.shape[1] < 2:
        return out
    first, last = g[:, 0] / step, g[:, -1] / step
    inner = g[:, 1:-1]
    inner /= 2.0 * step
    out[:, 2:] += inner
    out[:, :-2] -= inner
    out[:, 1] += first
    out[:, 0] -= first
    out[:, -1] += last
    out[:, -2] -= last
    return out


@dataclass(frozen=True)
class Geometry:
    """Ground-range grid of one side and the slant-range bins it is compared in.

    Attributes
    ----------
    x : ndarray, shape (cells,)
        Ground-range cell centres, metres, > 0.
    dx : float
        Ground-range cell size, metres.
    dy : float
        Along-track ping spacing, metres.
    range_bin : float
        Slant-range bin size, metres.
    bins : int
        Number of slant-range bins.
    subsamples : int
        Points each cell's return is spread over along its tangent plane (1: the cell centre
        only); see the module notes.
    deposit : {"tent", "segment"}
        How a point's return is shared among the bins: ``"tent"`` linearly between the two
        nearest bin centres; ``"segment"`` uniformly over the slant-range interval of the
        point's tangent-plane segment, each bin taking its exact overlap with the interval
        (the renderer's boxes; see the module notes).
    law : ScatteringLaw or None
        The seabed's scattering law (None: Lambert's); see the module notes.
    """

    x: np.ndarray
    dx: float
    dy: float
    range_bin: float
    bins: int
    subsamples: int = 1
    deposit: str = "tent"
    law: ScatteringLaw | None = None

    def __post_init__(self) -> None:
        if self.deposit not in DEPOSITS:
            raise ValueError(
                f"deposit {self.deposit!r} is not known: use one of {', '.join(DEPOSITS)}"
            )


#: The ways a point's return is shared among the slant bins (``Geometry.deposit``).
DEPOSITS = ("tent", "segment")


#: Prepared cells kept for reuse per thread (forward and adjoint of one Z share them).
CACHE_SIZE = 2
#: Padding columns on each side of a ping's bins in the flat splat layout (see _Cells).
_PAD = 2


@dataclass(frozen=True, eq=False)
class _Cells:
    """Per-cell terms of the model for one Z; (pings, cells) arrays unless noted.

    The points' bins live in a flat layout of ``pings`` rows of ``width = bins + 4`` columns,
    bin k of ping p at ``p·width + k + 2``; a point whose lower bin ``k0`` lies outside
    ``[−1, bins − 1]`` is moved to a pad column, so that it and its bin ``k0 + 1`` fall on pads.
    """

    q: np.ndarray  # max(0, x Zx − Z) / ρ
    dq_dz: np.ndarray  # ∂q/∂Z = −1/ρ − q Z/ρ² where lit (x Zx − Z > 0), else 0
    dq_dzx: np.ndarray  # ∂q/∂Zx = x/ρ where lit, else 0
    index: np.ndarray  # (points, pings·cells) flat index of each point's bin k0
    t: np.ndarray  # (points, pings·cells) weight of bin k0 + 1
    zr: np.ndarray  # (points, pings·cells) Z_s / ρ_s = ∂ρ_s/∂Z
    offsets: tuple[float, ...]  # o dx per point: ∂ρ_s/∂Zx = zr · offset
    width: int  # bins + 4
    dlnq_dzy: np.ndarray | None = None  # ∂ ln q/∂Zy with a law (module notes), else None

    @property
    def points(self) -> int:
        """Points per cell (``Geometry.subsamples``)."""
        return len(self.offsets)


class _Store(threading.local):
    """Per thread: the last :data:`CACHE_SIZE` prepared cells and a work buffer."""

    def __init__(self) -> None:
        self.entries: list[tuple[tuple, np.ndarray, np.ndarray, _Cells | _Segments]] = []
        self.work = np.empty(0)


_STORE = _Store()


def clear_cache() -> None:
    """Drop the prepared cells and the work buffer the model keeps (this thread's)."""
    _STORE.entries.clear()
    _STORE.work = np.empty(0)


def _work(*sizes: int) -> list[np.ndarray]:
    """Float64 work arrays of the given sizes, views of one buffer reused between calls.

    The views are valid until the next call; the caller must not call anything that uses
    them (``_cells`` does) while it holds them.
    """
    total = sum(sizes)
    if _STORE.work.size < total:
        _STORE.work = np.empty(total)
    starts = np.cumsum((0, *sizes))
    return [_STORE.work[a:b] for a, b in zip(starts[:-1], starts[1:], strict=True)]


def _cells(z: np.ndarray, geom: Geometry) -> _Cells | _Segments:
    """The model's per-cell terms for ``z``, reused while ``z`` and ``geom`` are unchanged.

    An entry is reused only when ``z`` and ``geom.x`` equal (by value) those it was made from,
    so changing ``z`` in place is safe. The oldest entry's arrays are recycled for the new one.
    """
    z = np.ascontiguousarray(z, np.float64)  # the fit's Z is often a transposed product
    key = (
        float(geom.dx),
        float(geom.range_bin),
        int(geom.bins),
        int(geom.subsamples),
        geom.deposit,
        geom.law,  # compared by identity
        z.shape,
    )
    entries = _STORE.entries
    for i, (k, x, zc, cells) in enumerate(entries):
        if k == key and np.array_equal(x, geom.x) and _same(zc, z):
            entries.insert(0, entries.pop(i))
            return cells
    spare = entries.pop() if len(entries) >= CACHE_SIZE else None
    if spare is not None and spare[0] == key:
        zc, cells = spare[2], spare[3]
        zc[...] = z
    else:
        zc = z.copy()
        cells = _empty_cells(z.shape, geom) if geom.deposit == "tent" else _empty_segments(z, geom)
    if isinstance(cells, _Segments):
        _fill_segments_blocks(cells, z, geom)
    else:
        _fill_blocks(cells, z, geom)
    entries.insert(0, (key, np.array(geom.x, np.float64), zc, cells))
    return cells


def _tent_cells(z: np.ndarray, geom: Geometry) -> _Cells:
    c = _cells(z, geom)
    assert isinstance(c, _Cells)
    return c


def _same(cached: np.ndarray, z: np.ndarray) -> bool:
    """``cached == z`` everywhere (same shape); a sparse sample first rejects most misses."""
    sample = slice(None, None, 997)
    if not np.array_equal(cached.ravel()[sample], z.ravel()[sample]):
        return False
    return bool(np.array_equal(cached, z))


def _empty_cells(shape: tuple[int, ...], geom: Geometry) -> _Cells:
    n, size = geom.subsamples, shape[0] * shape[1]
    offsets = tuple(((s + 0.5) / n - 0.5) * geom.dx for s in range(n))
    return _Cells(
        np.empty(shape),
        np.empty(shape),
        np.empty(shape),
        np.empty((n, size), np.intp),
        np.empty((n, size)),
        np.empty((n, size)),
        offsets,
        geom.bins + 2 * _PAD,
        None if geom.law is None else np.empty(shape),
    )


#: Elements (pings × cells) per block of whole pings in which the model works, so that its
#: temporaries stay in the processor's cache.
_BLOCK = 1 << 14


def _blocks(pings: int, cells: int) -> list[tuple[slice, slice]]:
    """Blocks of whole pings: (ping rows, their elements in a flat (pings·cells) array)."""
    step = max(1, _BLOCK // max(cells, 1))
    return [
        (slice(a, min(a + step, pings)), slice(a * cells, min(a + step, pings) * cells))
        for a in range(0, pings, step)
    ]


def _fill_blocks(c: _Cells, z: np.ndarray, geom: Geometry) -> None:
    """:func:`_fill_cells` over blocks of whole pings."""
    zy = None if c.dlnq_dzy is None else _along_slope(z, geom)
    for rows, flat in _blocks(*z.shape):
        part = _Cells(
            c.q[rows],
            c.dq_dz[rows],
            c.dq_dzx[rows],
            c.index[:, flat],
            c.t[:, flat],
            c.zr[:, flat],
            c.offsets,
            c.width,
            None if c.dlnq_dzy is None else c.dlnq_dzy[rows],
        )
        _fill_cells(part, z[rows], geom, rows.start, None if zy is None else zy[rows])


def _along_slope(z: np.ndarray, geom: Geometry) -> np.ndarray:
    """Zy: :func:`slope` over the pings (spacing ``dy``), 0 where it is not finite."""
    with np.errstate(invalid="ignore"):
        return np.nan_to_num(slope(z, 0, geom.dy), nan=0.0, posinf=0.0, neginf=0.0)


def _fill_cells(
    c: _Cells, z: np.ndarray, geom: Geometry, first: int = 0, zy: np.ndarray | None = None
) -> None:
    """Compute every term of ``c`` for ``z`` in place (formulas of the module notes).

    ``zy``: the block's along-track slope, needed where ``c`` has ``dlnq_dzy`` (a law).
    """
    pings, cells = z.shape
    x = np.asarray(geom.x, np.float64)
    rho, zx, a, b = (v.reshape(pings, cells) for v in _work(*[z.size] * 4))
    _fill_lit((c.q, c.dq_dz, c.dq_dzx), z, geom, (rho, zx, a, b), (zy, c.dlnq_dzy))
    rows = np.arange(first, first + pings, dtype=np.intp)[:, None] * c.width + _PAD
    for s, offset in enumerate(c.offsets):
        zs, rs = a, b
        np.multiply(zx, offset, out=zs)
        zs += z  # Z_s = Z + o dx Zx
        np.multiply(zs, zs, out=rs)
        rs += (x + offset) ** 2
        np.sqrt(rs, out=rs)  # ρ_s
        np.divide(zs, rs, out=c.zr[s].reshape(pings, cells))
        rs /= geom.range_bin
        rs -= 0.5  # u
        np.floor(rs, out=zs)  # k0
        np.subtract(rs, zs, out=c.t[s].reshape(pings, cells))
        index = c.index[s].reshape(pings, cells)
        np.copyto(index, zs, casting="unsafe")  # NaN: a huge negative number, clipped below
        np.clip(index, -_PAD, geom.bins, out=index)
        index += rows


def _fill_lit(
    out: tuple[np.ndarray, np.ndarray, np.ndarray],
    z: np.ndarray,
    geom: Geometry,
    work: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    along: tuple[np.ndarray | None, np.ndarray | None] = (None, None),
) -> None:
    """q, ∂q/∂Z and ∂q/∂Zx of ``z`` into ``out``; leaves ρ and Zx in ``work[0]``, ``work[1]``.

    ``work`` holds four arrays shaped as ``z``; the last two are scratch. With a law,
    ``along`` is ``(Zy, out for ∂ ln q/∂Zy)``.
    """
    q, dq_dz, dq_dzx = out
    rho, zx, a, b = work
    x = np.asarray(geom.x, np.float64)
    np.multiply(z, z, out=rho)
    rho += x * x
    np.sqrt(rho, out=rho)
    _slope_x(z, geom.dx, zx)
    num = q
    np.multiply(x, zx, out=num)
    num -= z
    lit = num > 0.0
    np.maximum(num, 0.0, out=q)
    q /= rho
    np.divide(x, rho, out=dq_dzx)
    dq_dzx *= lit
    np.multiply(rho, rho, out=a)
    np.multiply(q, z, out=b)
    b /= a
    np.divide(-1.0, rho, out=dq_dz)
    dq_dz -= b
    dq_dz *= lit
    if geom.law is not None:
        zy, dlnq_dzy = along
        if zy is None or dlnq_dzy is None:
            raise ValueError("a scattering law needs the along-track slope")
        _apply_law(geom.law, (q, dq_dz, dq_dzx, dlnq_dzy), zx, zy)


def _apply_law(
    law: ScatteringLaw,
    out: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    zx: np.ndarray,
    zy: np.ndarray,
) -> None:
    """Lambert's q and its derivatives times the law's factor ``L(c)``, in place.

    ``q̃ = q L(c)`` with ``c = q / s``, ``s² = 1 + Zx² + Zy²`` (see the module notes):
    ``∂q̃/∂Z = ∂q/∂Z · L (1 + c g)``,
    ``∂q̃/∂Zx = ∂q/∂Zx · L (1 + c g) − q̃ c g Zx / s²`` and ``∂ ln q̃/∂Zy = −c g Zy / s²``,
    ``g = d ln L / dc``; ``out`` is ``(q, ∂q/∂Z, ∂q/∂Zx, ∂ ln q/∂Zy)``.
    """
    q, dq_dz, dq_dzx, dlnq_dzy = out
    s2 = 1.0 + zx * zx + zy * zy
    c = q / np.sqrt(s2)
    log_l, g = law.log_factor_at(c)
    factor = np.exp(log_l)
    q *= factor
    cg = c * g
    chain = factor * (1.0 + cg)
    dq_dz *= chain
    dq_dzx *= chain
    dq_dzx -= q * cg * zx / s2
    np.multiply(cg, zy, out=dlnq_dzy)
    dlnq_dzy /= s2
    np.negative(dlnq_dzy, out=dlnq_dzy)


def _splat_block(
    e: np.ndarray, c: _Cells, block: tuple[slice, slice], work: tuple[np.ndarray, ...]
) -> np.ndarray:
    """Splat one block's energies ``e`` (its pings × cells, flat) in the layout of ``c``.

    Each of the cells' points takes ``e`` (the same share for every point), split over its
    two bins. ``work`` is ``(low, high, upper, lower)``: two full flat layouts and two arrays
    shaped as ``e``. Returns the block's rows of ``low``, (block pings, width): every bin's sum.
    """
    rows, flat = block
    low, high, upper, lower = work
    span = slice(rows.start * c.width, rows.stop * c.width)
    low[span] = 0.0
    high[span] = 0.0
    for s in range(c.points):
        index = c.index[s, flat]
        np.multiply(c.t[s, flat], e, out=upper)
        np.subtract(e, upper, out=lower)
        np.add.at(low, index, lower)
        np.add.at(high, index, upper)
    low[span][1:] += high[span][:-1]
    return low[span].reshape(-1, c.width)


def _padded(field: np.ndarray, c: _Cells | _Segments, out: np.ndarray | None = None) -> np.ndarray:
    """``field`` (pings, bins) in the flat layout of :class:`_Cells`, zero on the pads."""
    pings = field.shape[0]
    out = np.empty(pings * c.width) if out is None else out
    grid = out.reshape(pings, c.width)
    grid[:, :_PAD] = 0.0
    grid[:, c.width - _PAD :] = 0.0
    grid[:, _PAD : c.width - _PAD] = field
    return out


def _gather_point(
    flat: np.ndarray, c: _Cells, s: int, out: tuple[np.ndarray, np.ndarray] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """A padded field at point ``s``'s bins k0 and k0 + 1, each flat (pings·cells,)."""
    low, high = out if out is not None else (None, None)
    low = np.take(flat, c.index[s], mode="clip", out=low)
    high = np.take(flat[1:], c.index[s], mode="clip", out=high)
    return low, high


def roughness(r: np.ndarray, edge: float = 0.0) -> tuple[float, np.ndarray, np.ndarray]:
    """Roughness of R over neighbouring cells along both axes, its gradient and a diagonal.

    With ``edge = 0``: ``Σ (ΔR)²`` and the JᵀJ diagonal. With ``edge = ε > 0`` the
    edge-preserving Charbonnier form ``Σ 2ε (sqrt(ΔR² + ε²) − ε)``, equal to ``(ΔR)²`` for
    ``|ΔR| ≪ ε`` but growing only as ``2ε |ΔR|`` across a jump (a patch of other material), and
    the diagonal of its reweighted quadratic (weights ``ε / sqrt(ΔR² + ε²)``).
    """
    dx, dy = np.diff(r, axis=1), np.diff(r, axis=0)
    if edge > 0:
        sx, sy = np.sqrt(dx * dx + edge * edge), np.sqrt(dy * dy + edge * edge)
        value = 2.0 * edge * (float(np.sum(sx - edge)) + float(np.sum(sy - edge)))
        wx, wy = edge / sx, edge / sy
    else:
        value = float(np.sum(dx * dx) + np.sum(dy * dy))
        wx, wy = np.ones_like(dx), np.ones_like(dy)
    grad = np.zeros_like(r)
    grad[:, 1:] += 2.0 * wx * dx
    grad[:, :-1] -= 2.0 * wx * dx
    grad[1:] += 2.0 * wy * dy
    grad[:-1] -= 2.0 * wy * dy
    count = np.zeros_like(r)
    count[:, 1:] += wx
    count[:, :-1] += wx
    count[1:] += wy
    count[:-1] += wy
    return value, grad, 2.0 * count


def forward(r: np.ndarray, phi: np.ndarray, z: np.ndarray, geom: Geometry) -> np.ndarray:
    """Model intensity per metre of slant range, shape (pings, bins)."""
    if geom.deposit == "segment":
        return _segment_forward(r, phi, z, geom)
    c = _tent_cells(z, geom)
    shape = c.q.shape
    r, phi = np.broadcast_to(r, shape), np.broadcast_to(phi, shape)
    out = np.empty((shape[0], geom.bins))
    blocks = _blocks(*shape)
    most = max((flat.stop - flat.start for _, flat in blocks), default=0)
    size = shape[0] * c.width
    low, high, energy_, upper, lower = _work(size, size, most, most, most)
    for rows, flat in blocks:
        k = flat.stop - flat.start
        e = energy_[:k].reshape(-1, shape[1])
        np.multiply(c.q[rows], phi[rows], out=e)
        e *= r[rows]
        e *= geom.dx / c.points
        sums = _splat_block(e.ravel(), c, (rows, flat), (low, high, upper[:k], lower[:k]))
        np.divide(sums[:, _PAD : _PAD + geom.bins], geom.range_bin, out=out[rows])
    return out


@dataclass(frozen=True)
class Evaluation:
    """Objective, gradients and Gauss-Newton diagonals wrt per-cell R, Φ and Z."""

    energy: float
    grad_r: np.ndarray
    grad_phi: np.ndarray
    grad_z: np.ndarray
    diag_r: np.ndarray
    diag_phi: np.ndarray
    diag_z: np.ndarray


def energy(
    image: np.ndarray,
    weight: np.ndarray,
    r: np.ndarray,
    phi: np.ndarray,
    z: np.ndarray,
    geom: Geometry,
    smooth: float = 0.0,
    edge: float = 0.0,
) -> float:
    """``E = Σ w (I − Î)² + smooth · roughness(R, edge)``, a float.

    ``image`` and ``weight`` are (pings, bins). The second term ties each cell's reflectivity
    to its neighbours' (along and across track), so R cannot take up the relief's shading
    (see :func:`roughness`).
    """
    res = forward(r, phi, z, geom) - image
    return float(np.sum(weight * res * res)) + smooth * roughness(r, edge)[0]


def evaluate(
    image: np.ndarray,
    weight: np.ndarray,
    r: np.ndarray,
    phi: np.ndarray,
    z: np.ndarray,
    geom: Geometry,
    smooth: float = 0.0,
    edge: float = 0.0,
) -> Evaluation:
    """Exact gradient of :func:`energy` wrt every ground cell of R, Φ and Z.

    With ``G = 2 w (Î − I) / range_bin`` back-projected as ``b = (1 − t) G[k0] + t G[k0+1]``
    and ``b' = (G[k0+1] − G[k0]) / range_bin``: ``∂E/∂e = b``, ``∂E/∂ρ = e b'``, and
    ``∂E/∂Z`` collects ``b Φ R dx ∂q/∂Z + e b' Z/ρ`` and, through the transposed stencil,
    ``b Φ R dx x/ρ`` of the neighbours whose slope the cell enters. Where ``q = 0`` (shadow)
    its derivative is taken as 0. The diagonals are those of JᵀJ for each cell alone. With
    several points per cell (``geom.subsamples``) ``b`` is the mean over the points and each
    point s adds ``(e/n) b'_s Z_s/ρ_s`` directly and ``(e/n) b'_s (Z_s/ρ_s) o_s dx`` through
    the transposed stencil (its range moves with the slope); the diagonals are then
    approximate (they only scale the steps). With ``geom.deposit == "segment"`` the gradients
    are :func:`adjoint`'s, the Z diagonal that of 2 JᵀJ from :func:`jacobian_z`, and the R and
    Φ diagonals sum each point's squared bin shares (approximate).
    """
    if geom.deposit == "segment":
        return _segment_evaluate(image, weight, r, phi, z, geom, smooth, edge)
    c = _tent_cells(z, geom)
    rb, dx, n = geom.range_bin, geom.dx, c.points
    e = c.q * phi * r * dx
    res = forward(r, phi, z, geom) - image
    grad = 2.0 * weight * res / rb
    curv = np.broadcast_to(2.0 * weight / rb**2, res.shape)
    flat_g, flat_w = _padded(grad, c), _padded(curv, c)
    b, a = np.zeros(e.size), np.zeros(e.size)
    shift_z, shift_zx, shift_diag = np.zeros(e.size), np.zeros(e.size), np.zeros(e.size)
    for s in range(n):
        g0, g1 = _gather_point(flat_g, c, s)
        w0, w1 = _gather_point(flat_w, c, s)
        t, zr = c.t[s], c.zr[s]
        b += (1.0 - t) * g0 + t * g1
        a += (1.0 - t) ** 2 * w0 + t**2 * w1
        moved = (g1 - g0) * zr  # ∂E/∂ρ_s · ∂ρ_s/∂Z, over e / (n rb)
        shift_z += moved
        shift_zx += moved * c.offsets[s]
        shift_diag += (w0 + w1) * zr * zr
    scale = e.ravel() / (n * rb)
    shape = e.shape
    b, a = (b / n).reshape(shape), (a / n).reshape(shape)
    shift_z, shift_zx = (shift_z * scale).reshape(shape), (shift_zx * scale).reshape(shape)
    shift_diag = (shift_diag * scale * scale).reshape(shape)
    amp = phi * r * dx
    gz = b * amp * c.dq_dz + shift_z + slope_adjoint(b * amp * c.dq_dzx + shift_zx, 1, dx)
    dz = a * (amp * c.dq_dz) ** 2 + shift_diag
    dz += slope_adjoint(a * (amp * c.dq_dzx) ** 2, 1, dx, power=2)
    if c.dlnq_dzy is not None:  # the along-track slope, through ln q
        via_y = np.nan_to_num(amp * c.q * c.dlnq_dzy)
        gz += slope_adjoint(b * via_y, 0, geom.dy)
        dz += slope_adjoint(a * via_y**2, 0, geom.dy, power=2)
    rough, grad_rough, diag_rough = roughness(r, edge)
    return Evaluation(
        energy=float(np.sum(weight * res * res)) + smooth * rough,
        grad_r=b * phi * c.q * dx + smooth * grad_rough,
        grad_phi=b * r * c.q * dx,
        grad_z=gz,
        diag_r=a * (phi * c.q * dx) ** 2 + smooth * diag_rough,
        diag_phi=a * (r * c.q * dx) ** 2,
        diag_z=dz,
    )


def _slope_columns(n: int, step: float) -> tuple[np.ndarray, np.ndarray]:
    """The :func:`slope` stencil ``D`` (n × n) by columns, ``(wl, wr)``, each shape (n,).

    Column c of ``D`` holds ``wl[c] = D[c − 1, c]`` and ``wr[c] = D[c + 1, c]`` inside; at
    the ends the neighbour row is replaced by the end's own (``wl[0] = D[0, 0]``,
    ``wr[n − 1] = D[n − 1, n − 1]``). Zero for ``n < 2`` (no slope).
    """
    if n < 2:
        return np.zeros(n), np.zeros(n)
    wl, wr = np.full(n, 0.5 / step), np.full(n, -0.5 / step)
    wl[0], wl[1] = -1.0 / step, 1.0 / step  # D[0, 0], D[0, 1]
    wr[-1], wr[-2] = 1.0 / step, -1.0 / step  # D[n−1, n−1], D[n−1, n−2]
    return wl, wr


def jacobian_z(
    weight: np.ndarray, r: np.ndarray, phi: np.ndarray, z: np.ndarray, geom: Geometry
) -> sparse.csr_matrix:
    """``sqrt(w) ∂Î/∂Z`` as a sparse (pings·bins) × (pings·cells) matrix.

    Exact, with the same terms as :func:`evaluate`; explicit zeros (shadowed cells, rows of
    zero weight) are dropped.
    """
    if geom.deposit == "segment":
        jac = _segment_jacobian(weight, r, phi, z, geom)
    else:
        jac = _tent_jacobian(weight, r, phi, z, geom)
    if geom.law is None:  # Lambert's: each ping alone (no lookup of the cells again)
        return jac
    c = _cells(z, geom)
    assert c.dlnq_dzy is not None
    # the along-track slope: sqrt(w) D diag(Φ R q dx/rb ∂ln q/∂Zy) Dy, D the deposit
    deposit, q = deposit_matrix(z, geom)
    pings, cells = q.shape
    root = np.sqrt(np.broadcast_to(weight, (pings, geom.bins))).ravel()
    scale = np.broadcast_to(phi, q.shape) * np.broadcast_to(r, q.shape) * q * c.dlnq_dzy
    scale = np.nan_to_num(scale).ravel() * (geom.dx / geom.range_bin)
    along = sparse.kron(_slope_matrix(pings, geom.dy), sparse.identity(cells), format="csr")
    jac = (jac + sparse.diags(root) @ deposit @ sparse.diags(scale) @ along).tocsr()
    jac.sum_duplicates()
    jac.eliminate_zeros()
    return jac


def _slope_matrix(n: int, step: float) -> sparse.csr_matrix:
    """The :func:`slope` stencil as a sparse n × n matrix (zero for ``n < 2``)."""
    if n < 2:
        return sparse.csr_matrix((n, n))
    inner = np.arange(1, n - 1)
    rows = np.concatenate([[0, 0, n - 1, n - 1], inner, inner])
    cols = np.concatenate([[0, 1, n - 2, n - 1], inner - 1, inner + 1])
    half = 0.5 / step
    vals = np.concatenate(
        [
            [-1.0 / step, 1.0 / step, -1.0 / step, 1.0 / step],
            np.full(n - 2, -half),
            np.full(n - 2, half),
        ]
    )
    return sparse.csr_matrix((vals, (rows, cols)), shape=(n, n))


def _tent_jacobian(
    weight: np.ndarray, r: np.ndarray, phi: np.ndarray, z: np.ndarray, geom: Geometry
) -> sparse.csr_matrix:
    """:func:`jacobian_z` with ``geom.deposit == "tent"``, each ping's own terms."""
    c = _tent_cells(z, geom)
    n, bins = c.points, geom.bins
    pings, cells = shape = c.q.shape
    r, phi = np.broadcast_to(r, shape), np.broadcast_to(phi, shape)
    root = np.sqrt(np.broadcast_to(weight, (pings, bins)))
    small = max(6 * n * z.size, pings * bins) < 2**31 - 1
    index_type = np.int32 if small else np.int64
    # column (p, c) holds, for each point's two bins (2n slots each): the slope values of the
    # cell whose stencil row reaches it from the left, its own values, and those of the cell
    # reaching it from the right (see _slope_columns)
    data = np.empty((pings, cells, 3, 2 * n))
    rows = np.empty((pings, cells, 3, 2 * n), index_type)
    for block in _blocks(pings, cells):
        b = block[0]
        _jacobian_block(c, geom, block, (r[b], phi[b], root), (data[b], rows[b]))
    return _columns_to_csr(data, rows, 6 * n, (pings * bins, pings * cells))


def _columns_to_csr(
    data: np.ndarray, rows: np.ndarray, per_column: int, shape: tuple[int, int]
) -> sparse.csr_matrix:
    """A Jacobian as CSR from ``per_column`` fixed slots per cell column.

    ``rows`` and ``data`` hold each slot's row index and value, column-major; duplicates are
    summed and zeros dropped.
    """
    indptr = np.arange(shape[1] + 1, dtype=rows.dtype) * per_column
    jac = sparse.csc_matrix((data.ravel(), rows.ravel(), indptr), shape=shape).tocsr()
    jac.sum_duplicates()
    jac.eliminate_zeros()
    return jac


def _jacobian_block(
    c: _Cells,
    geom: Geometry,
    block: tuple[slice, slice],
    fields: tuple[np.ndarray, np.ndarray, np.ndarray],
    out: tuple[np.ndarray, np.ndarray],
) -> None:
    """Columns of :func:`jacobian_z` for one block of pings, into ``out = (data, rows)``.

    ``fields`` are the block's R and Φ and the full ``sqrt(w)`` (pings, bins); ``data`` and
    ``rows`` are the block's (block pings, cells, 3, 2n) slots.
    """
    rows_b, flat = block
    r, phi, root = fields
    data, rows = out
    rb, dx, n, bins = geom.range_bin, geom.dx, c.points, geom.bins
    shape = r.shape
    amp = phi * r
    amp *= dx / rb / n
    direct = amp * c.dq_dz[rows_b]  # ∂e/∂Z through q, per bin weight
    via = amp * c.dq_dzx[rows_b]  # ∂e/∂Zx through q
    energy_ = c.q[rows_b] * phi
    energy_ *= r
    energy_ *= dx / n / rb**2  # × zr: ∂/∂ρ of the bin weights
    root = root.ravel()
    own, rows_own = data[:, :, 1], rows[:, :, 1]
    via_slope = np.empty(own.shape)
    ping_row = (np.arange(rows_b.start, rows_b.stop, dtype=np.intp) * bins)[:, None]
    first = (np.arange(rows_b.start, rows_b.stop, dtype=np.intp) * c.width + _PAD)[:, None]
    for s in range(n):
        k0 = c.index[s, flat].reshape(shape) - first  # clipped to [−2, bins]
        t, shift = c.t[s, flat].reshape(shape), energy_ * c.zr[s, flat].reshape(shape)
        for corner, wgt, dw in ((0, 1.0 - t, -1.0), (1, t, 1.0)):
            k = k0 + corner
            row = ping_row + np.clip(k, 0, bins - 1)
            w_row = root[row] * ((k >= 0) & (k < bins))
            slot = 2 * s + corner
            rows_own[:, :, slot] = row
            value = direct * wgt
            value += shift * dw
            np.multiply(value, w_row, out=own[:, :, slot])
            np.multiply(via, wgt, out=value)
            value += shift * (c.offsets[s] * dw)
            np.multiply(value, w_row, out=via_slope[:, :, slot])
    # D[left[c], c] and D[right[c], c] with left = c − 1, right = c + 1 but at the ends
    wl, wr = _slope_columns(shape[1], dx)
    np.multiply(via_slope[:, :-1], wl[1:, None], out=data[:, 1:, 0])
    np.multiply(via_slope[:, :1], wl[:1, None], out=data[:, :1, 0])
    np.multiply(via_slope[:, 1:], wr[:-1, None], out=data[:, :-1, 2])
    np.multiply(via_slope[:, -1:], wr[-1:, None], out=data[:, -1:, 2])
    rows[:, 1:, 0], rows[:, :1, 0] = rows_own[:, :-1], rows_own[:, :1]
    rows[:, :-1, 2], rows[:, -1:, 2] = rows_own[:, 1:], rows_own[:, -1:]


def deposit_matrix(z: np.ndarray, geom: Geometry) -> tuple[sparse.csr_matrix, np.ndarray]:
    """How each ground cell's return is shared among the slant bins, and the cells' ``q``.

    Returns ``(D, q)``: ``D`` a (pings·bins) × (pings·cells) matrix whose column j holds the
    shares of cell j's return in its ping's bins (by ``geom.deposit``; shares falling outside
    the image are dropped), and ``q = max(0, x Zx − Z) / ρ`` (pings, cells), so that
    ``forward(r, phi, z, geom) == (D @ (phi r q).ravel()).reshape(pings, bins) · dx / rb``.
    The Jacobian of the image wrt per-cell Φ (or R) is ``D`` times a diagonal.
    """
    z = np.ascontiguousarray(z, dtype=np.float64)
    c = _cells(z, geom)
    pings, cells = z.shape
    rows, cols, vals = [], [], []
    column = np.arange(pings * cells)

    def add(index: np.ndarray, share: np.ndarray) -> None:
        ping, k = np.divmod(index, c.width)
        k = k - _PAD
        keep = (k >= 0) & (k < geom.bins) & (share != 0.0)
        rows.append((ping * geom.bins + k)[keep])
        cols.append(column[keep])
        vals.append(share[keep] / c.points)

    everything = slice(0, pings * cells)
    for point in range(c.points):
        if isinstance(c, _Segments):
            for j in range(int(c.reach[0])):
                index = _segment_index(c, point, everything, j, geom.bins)
                add(index, _segment_weight(c, point, everything, j).copy())
        else:
            t = c.t[point]
            add(c.index[point], 1.0 - t)
            add(c.index[point] + 1, t.copy())
    matrix = sparse.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
        shape=(pings * geom.bins, pings * cells),
    )
    return matrix, c.q.copy()


def gauss_newton_z(
    grad_z: np.ndarray,
    weight: np.ndarray,
    r: np.ndarray,
    phi: np.ndarray,
    z: np.ndarray,
    geom: Geometry,
    damping: float,
    prior: float | np.ndarray = 0.0,
    prior_matrix: sparse.spmatrix | None = None,
) -> np.ndarray:
    """Levenberg-Marquardt step of Z: ``−(2 JᵀJ + P + μ I)⁻¹ ∂E/∂Z``, shape of ``z``.

    ``μ = damping × mean diagonal of 2 JᵀJ``; with ``μ > 0`` the step is a descent direction.
    ``P`` is the Hessian of the quadratic priors on Z included in ``grad_z``: ``prior`` (a
    number or an array shaped like ``z``) on the diagonal plus ``prior_matrix`` (sparse,
    (pings·cells)², positive semi-definite) where a prior couples cells.
    """
    j = jacobian_z(weight, r, phi, z, geom)
    h = 2.0 * (j.T @ j).tocsc()
    diag = h.diagonal()
    mu = damping * float(diag.mean()) if diag.size and diag.mean() > 0 else 1.0
    extra = np.broadcast_to(np.asarray(prior, np.float64), z.shape).ravel() + mu
    h = h + sparse.diags(extra, format="csc")
    if prior_matrix is not None:
        h = h + prior_matrix.tocsc()
    return -spsolve(h, grad_z.ravel()).reshape(z.shape)


def adjoint(
    grad_model: np.ndarray, r: np.ndarray, phi: np.ndarray, z: np.ndarray, geom: Geometry
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gradients wrt every ground cell's R, Φ and Z of any objective of the model image.

    Parameters
    ----------
    grad_model : ndarray, shape (pings, bins)
        ``∂E/∂Î`` at ``Î = forward(r, phi, z, geom)``.
    r, phi, z : ndarray, shape (pings, cells)
        Reflectivity, beam gain and elevation per ground cell.
    geom : Geometry
        The grid and bins.

    Returns
    -------
    tuple of ndarray, each shape (pings, cells)
        ``∂E/∂R``, ``∂E/∂Φ``, ``∂E/∂Z``: the chain rule of :func:`evaluate` (shadowed cells,
        ``q = 0``, have a zero derivative wrt Z through ``q``).
    """
    if geom.deposit == "segment":
        out = _segment_adjoint(grad_model, r, phi, z, geom)
    else:
        out = _tent_adjoint(grad_model, r, phi, z, geom)
    if geom.law is not None:  # the along-track slope, through ln q
        c = _cells(z, geom)
        assert c.dlnq_dzy is not None
        moved = out[1] * np.broadcast_to(phi, c.q.shape) * c.dlnq_dzy  # ∂E/∂ln q · ∂ln q/∂Zy
        grad_z = out[2]
        grad_z += slope_adjoint(np.nan_to_num(moved), 0, geom.dy)
    return out


def _tent_adjoint(
    grad_model: np.ndarray, r: np.ndarray, phi: np.ndarray, z: np.ndarray, geom: Geometry
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`adjoint` with ``geom.deposit == "tent"``, each ping's own terms."""
    c = _tent_cells(z, geom)
    shape = c.q.shape
    r, phi = np.broadcast_to(r, shape), np.broadcast_to(phi, shape)
    grad_r, grad_phi, grad_z = np.empty(shape), np.empty(shape), np.empty(shape)
    blocks = _blocks(*shape)
    most = max((flat.stop - flat.start for _, flat in blocks), default=0)
    padded, *work = _work(shape[0] * c.width, *[most] * 5)
    for rows, flat in blocks:
        k = flat.stop - flat.start
        span = slice(rows.start * c.width, rows.stop * c.width)
        _padded(grad_model[rows], c, padded[span])
        parts = [v[:k].reshape(-1, shape[1]) for v in work]
        _adjoint_block(padded, c, geom, (rows, flat), (r[rows], phi[rows]), parts)
        de, gz = parts[2], parts[3]
        np.multiply(de, phi[rows], out=grad_r[rows])
        np.multiply(de, r[rows], out=grad_phi[rows])
        grad_z[rows] = gz
    return grad_r, grad_phi, grad_z


def _adjoint_block(
    padded: np.ndarray,
    c: _Cells,
    geom: Geometry,
    block: tuple[slice, slice],
    fields: tuple[np.ndarray, np.ndarray],
    work: list[np.ndarray],
) -> None:
    """:func:`adjoint` on one block of pings, (block pings, cells) arrays in ``work``.

    ``padded`` is ``∂E/∂Î`` in the flat layout of ``c`` (at least this block's rows);
    ``fields`` the block's R and Φ. Leaves ``∂E/∂e · q dx`` in ``work[2]`` (times Φ and R it
    gives the gradients wrt R and Φ) and ``∂E/∂Z`` in ``work[3]``.
    """
    rows, flat = block
    r, phi = fields
    rb, dx, n = geom.range_bin, geom.dx, c.points
    g0, g1, b, shift_z, shift_zx = work
    shape = g0.shape
    for array in (b, shift_z, shift_zx):
        array.fill(0.0)
    for s in range(n):
        index = c.index[s, flat]
        np.take(padded, index, mode="clip", out=g0.ravel())
        np.take(padded[1:], index, mode="clip", out=g1.ravel())
        g1 -= g0
        b += g0
        np.multiply(c.t[s, flat].reshape(shape), g1, out=g0)
        b += g0
        g1 *= c.zr[s, flat].reshape(shape)  # ∂E/∂ρ_s · ∂ρ_s/∂Z, over e / (n rb²)
        shift_z += g1
        g1 *= c.offsets[s]
        shift_zx += g1
    q = c.q[rows]
    e, amp = g0, g1
    np.multiply(q, phi, out=e)
    e *= r
    e *= dx / (n * rb * rb)
    shift_z *= e
    shift_zx *= e
    np.multiply(b, phi, out=amp)
    amp *= r
    amp *= dx / (n * rb)  # ∂E/∂q
    de = b
    de *= q
    de *= dx / (n * rb)  # ∂E/∂e · q dx
    via = e
    np.multiply(amp, c.dq_dzx[rows], out=via)
    via += shift_zx
    gz = shift_z
    amp *= c.dq_dz[rows]
    gz += amp
    _add_slope_adjoint_x(via, dx, gz)


# --- the "segment" deposit: each point's return spread over its slant-range interval --------


@dataclass(frozen=True, eq=False)
class _Segments:
    """Per-cell terms of the segment model for one Z; (pings, cells) arrays unless noted.

    Point s covers the tangent-plane segment between ground offsets ``ends[s]`` (metres from
    the cell centre); its ends' slant ranges in bins are ``lo ≤ hi``, its first bin
    ``k_lo = ⌊lo⌋`` and last ``k_lo + span``. Each (points, pings·cells) array is one row per
    point. A point whose interval lies in one bin (``span = 0``) is stored as the whole box
    (``w0 = 1``, ``top = 1``, ``inv = 1``) with ``glo = ghi = 0``: its weight is 1 and fixed.
    """

    q: np.ndarray  # max(0, x Zx − Z) / ρ
    dq_dz: np.ndarray  # ∂q/∂Z where lit, else 0
    dq_dzx: np.ndarray  # ∂q/∂Zx where lit, else 0
    base: np.ndarray  # (pings·cells,) flat index of bin 0 of the cell's ping (layout of _Cells)
    k_lo: np.ndarray  # (points, pings·cells) first bin, clipped to [−1, bins]
    span: np.ndarray  # (points, pings·cells) last bin − first bin, ≥ 0
    w0: np.ndarray  # (points, pings·cells) share of bin k_lo: (min(hi, k_lo + 1) − lo) inv
    top: np.ndarray  # (points, pings·cells) hi − k_lo
    inv: np.ndarray  # (points, pings·cells) 1 / (hi − lo)
    glo: np.ndarray  # (points, pings·cells) inv ∂lo/∂Z (∂lo/∂Z_end = Z_end / (ρ_end rb))
    ghi: np.ndarray  # (points, pings·cells) inv ∂hi/∂Z
    xlo: np.ndarray  # (points, pings·cells) inv ∂lo/∂Zx = glo × the lo end's ground offset
    xhi: np.ndarray  # (points, pings·cells) inv ∂hi/∂Zx
    ends: tuple[tuple[float, float], ...]  # ground offsets (o_a, o_b) of each point's ends
    reach: np.ndarray  # (1,) int: 1 + the largest span (bins any point touches)
    width: int  # bins + 4
    dlnq_dzy: np.ndarray | None = None  # ∂ ln q/∂Zy with a law (module notes), else None

    @property
    def points(self) -> int:
        """Points per cell (``Geometry.subsamples``)."""
        return len(self.ends)


def _empty_segments(z: np.ndarray, geom: Geometry) -> _Segments:
    n, (pings, cells) = geom.subsamples, z.shape
    size, width = pings * cells, geom.bins + 2 * _PAD
    ends = tuple(((s / n - 0.5) * geom.dx, ((s + 1) / n - 0.5) * geom.dx) for s in range(n))
    base = np.repeat(np.arange(pings, dtype=np.intp) * width + _PAD, cells)

    def shaped() -> np.ndarray:
        return np.empty(z.shape)

    def per_point(dtype: type = np.float64) -> np.ndarray:
        return np.empty((n, size), dtype)

    return _Segments(
        q=shaped(),
        dq_dz=shaped(),
        dq_dzx=shaped(),
        base=base,
        k_lo=per_point(np.intp),
        span=per_point(np.intp),
        w0=per_point(),
        top=per_point(),
        inv=per_point(),
        glo=per_point(),
        ghi=per_point(),
        xlo=per_point(),
        xhi=per_point(),
        ends=ends,
        reach=np.ones(1, np.intp),
        width=width,
        dlnq_dzy=None if geom.law is None else shaped(),
    )


def _segment_cells(z: np.ndarray, geom: Geometry) -> _Segments:
    c = _cells(z, geom)
    assert isinstance(c, _Segments)
    return c


def _fill_segments_blocks(c: _Segments, z: np.ndarray, geom: Geometry) -> None:
    """Compute every term of ``c`` for ``z`` in place, over blocks of whole pings."""
    c.reach[0] = 1
    x = np.asarray(geom.x, np.float64)
    zy = None if c.dlnq_dzy is None else _along_slope(z, geom)
    for rows, flat in _blocks(*z.shape):
        zb = z[rows]
        work = _work(*[zb.size] * 10)
        rho, zx, a, b = (v.reshape(zb.shape) for v in work[:4])
        along = (None, None) if zy is None or c.dlnq_dzy is None else (zy[rows], c.dlnq_dzy[rows])
        _fill_lit((c.q[rows], c.dq_dz[rows], c.dq_dzx[rows]), zb, geom, (rho, zx, a, b), along)
        xf = np.broadcast_to(x, zb.shape).ravel()
        ends = (work[4], work[5]), (work[6], work[7])
        for s, (oa, ob) in enumerate(c.ends):
            for (u, zr), offset in zip(ends, (oa, ob), strict=True):
                _end_range(zb.ravel(), zx.ravel(), xf, offset, geom.range_bin, (u, zr, a.ravel()))
            (ua, za), (ub, zb_) = ends
            _fill_point(c, (s, flat, oa, ob), (ua, za, ub, zb_), work[8:10], geom.bins)


def _fill_point(
    c: _Segments,
    at: tuple[int, slice, float, float],
    ends: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    work: list[np.ndarray],
    bins: int,
) -> None:
    """Point ``at = (s, flat, o_a, o_b)``'s terms of ``c`` from its ends' ranges and slopes.

    ``ends`` is ``(ua, za, ub, zb)``: each end's slant range in bins and ``∂u/∂Z_end``; ``ua``
    and ``ub`` are overwritten, ``work`` holds two more scratch arrays.
    """
    s, flat, oa, ob = at
    ua, za, ub, zb = ends
    lo, hi = work
    glo, ghi, xlo, xhi = c.glo[s, flat], c.ghi[s, flat], c.xlo[s, flat], c.xhi[s, flat]
    swap = np.less(ub, ua)  # the segment's far end is the nearer
    np.minimum(ua, ub, out=lo)
    np.maximum(ua, ub, out=hi)
    np.subtract(zb, za, out=ghi)  # (np.copyto with where= is ten times slower)
    np.multiply(swap, ghi, out=glo)
    ghi -= glo
    ghi += za  # zb, or za where swapped
    glo += za  # za, or zb where swapped
    np.multiply(swap, ob - oa, out=xlo)
    xlo += oa  # the lo end's ground offset
    np.multiply(swap, oa - ob, out=xhi)
    xhi += ob
    k_lo, spanf = ua, ub
    np.floor(lo, out=k_lo)
    np.floor(hi, out=spanf)
    spanf -= k_lo
    span, first = c.span[s, flat], c.k_lo[s, flat]
    np.copyto(span, spanf, casting="unsafe")  # NaN: a huge negative number, clipped below
    np.clip(span, 0, bins + 1, out=span)
    np.copyto(first, k_lo, casting="unsafe")
    np.clip(first, -1, bins, out=first)
    w0, top, inv = c.w0[s, flat], c.top[s, flat], c.inv[s, flat]
    np.subtract(hi, k_lo, out=top)
    np.minimum(top, 1.0, out=w0)
    w0 -= lo
    w0 += k_lo
    np.subtract(hi, lo, out=inv)
    # the interval lies in one bin: the whole box (top = 1, inv = 1), weight 1, fixed; where
    # it does, top, hi − lo and w0 are below 1, so raising them to 1 sets them
    point = spanf == 0.0
    np.maximum(top, point, out=top)
    np.maximum(inv, point, out=inv)
    np.divide(1.0, inv, out=inv)
    w0 *= inv
    np.maximum(w0, point, out=w0)
    np.logical_not(point, out=point)
    glo *= inv
    glo *= point
    ghi *= inv
    ghi *= point
    xlo *= glo
    xhi *= ghi
    if span.size:
        c.reach[0] = max(int(c.reach[0]), int(span.max()) + 1)


def _end_range(
    z: np.ndarray,
    zx: np.ndarray,
    x: np.ndarray,
    offset: float,
    range_bin: float,
    out: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> None:
    """Slant range in bins of the tangent-plane point ``offset`` from each cell centre.

    Writes it and its derivative wrt that point's elevation, ``Z_e / (ρ_e range_bin)``, into
    ``out[0]`` and ``out[1]`` (flat arrays); ``out[2]`` is scratch.
    """
    u, zr, ze = out
    np.multiply(zx, offset, out=ze)
    ze += z
    np.add(x, offset, out=u)
    u *= u
    np.multiply(ze, ze, out=zr)
    u += zr
    np.sqrt(u, out=u)
    np.divide(ze, u, out=zr)
    zr /= range_bin
    u /= range_bin


def _segment_weight(c: _Segments, s: int, flat: slice, j: int) -> np.ndarray:
    """Share of point s's return in its bin ``k_lo + j``, flat over the block ``flat``."""
    if j == 0:
        return c.w0[s, flat]
    w = np.subtract(c.top[s, flat], j)
    np.clip(w, 0.0, 1.0, out=w)
    w *= c.inv[s, flat]
    return w


def _segment_index(c: _Segments, s: int, flat: slice, j: int, bins: int) -> np.ndarray:
    """Flat layout index of point s's bin ``k_lo + j`` (a pad outside ``[0, bins)``)."""
    k = c.k_lo[s, flat] + j
    np.clip(k, -1, bins, out=k)
    k += c.base[flat]
    return k


def _segment_forward(r: np.ndarray, phi: np.ndarray, z: np.ndarray, geom: Geometry) -> np.ndarray:
    """:func:`forward` with ``geom.deposit == "segment"``."""
    c = _segment_cells(z, geom)
    shape = c.q.shape
    r, phi = np.broadcast_to(r, shape), np.broadcast_to(phi, shape)
    out = np.empty((shape[0], geom.bins))
    for rows, flat in _blocks(*shape):
        e = (c.q[rows] * phi[rows] * r[rows]).ravel()
        e *= geom.dx / c.points
        start = rows.start * c.width
        sums = np.zeros((rows.stop - rows.start) * c.width)
        for s in range(c.points):
            for j in range(int(c.reach[0])):
                index = _segment_index(c, s, flat, j, geom.bins) - start
                sums += np.bincount(index, _segment_weight(c, s, flat, j) * e, sums.size)
        grid = sums.reshape(-1, c.width)
        np.divide(grid[:, _PAD : _PAD + geom.bins], geom.range_bin, out=out[rows])
    return out


def _segment_back(
    padded: np.ndarray, c: _Segments, geom: Geometry, flat: slice
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Back-projection of a padded field over one block's cells, flat arrays.

    Returns ``b`` (Σ over points and bins of weight × field), and ``∂/∂Z`` and ``∂/∂Zx`` of
    Σ_s Σ_j field[k] ∂w/∂(ends) (per unit of each point's energy), through the interval ends.
    """
    size = flat.stop - flat.start
    b, dz, dzx = np.zeros(size), np.zeros(size), np.zeros(size)
    g_lo, g, d_lo, d_hi = np.empty(size), np.empty(size), np.empty(size), np.empty(size)
    for s in range(c.points):
        bs = np.take(padded, _segment_index(c, s, flat, 0, geom.bins), out=g_lo)
        bs = bs * c.w0[s, flat]
        for j in range(1, int(c.reach[0])):
            np.take(padded, _segment_index(c, s, flat, j, geom.bins), out=g)
            g *= _segment_weight(c, s, flat, j)
            bs += g
        last = c.k_lo[s, flat] + c.span[s, flat]
        np.clip(last, -1, geom.bins, out=last)
        last += c.base[flat]
        g_hi = np.take(padded, last, out=g)
        np.subtract(bs, g_lo, out=d_lo)  # ∂/∂lo × (hi − lo), per unit energy
        np.subtract(g_hi, bs, out=d_hi)
        dz += d_lo * c.glo[s, flat]
        dz += d_hi * c.ghi[s, flat]
        d_lo *= c.xlo[s, flat]
        dzx += d_lo
        d_hi *= c.xhi[s, flat]
        dzx += d_hi
        b += bs
    return b, dz, dzx


def _segment_adjoint(
    grad_model: np.ndarray, r: np.ndarray, phi: np.ndarray, z: np.ndarray, geom: Geometry
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`adjoint` with ``geom.deposit == "segment"``."""
    c = _segment_cells(z, geom)
    shape = c.q.shape
    r, phi = np.broadcast_to(r, shape), np.broadcast_to(phi, shape)
    rb, dx, n = geom.range_bin, geom.dx, c.points
    padded = _padded(np.asarray(grad_model, np.float64) / rb, c)
    grad_r, grad_phi = np.empty(shape), np.empty(shape)
    direct, via = np.empty(shape), np.empty(shape)
    for rows, flat in _blocks(*shape):
        b, dz, dzx = (v.reshape(-1, shape[1]) for v in _segment_back(padded, c, geom, flat))
        b *= dx / n  # ∂E/∂(Φ R q)
        grad_r[rows] = b * phi[rows] * c.q[rows]
        grad_phi[rows] = b * r[rows] * c.q[rows]
        amp = b * phi[rows] * r[rows]  # ∂E/∂q
        e = c.q[rows] * phi[rows] * r[rows] * (dx / n)
        direct[rows] = amp * c.dq_dz[rows] + e * dz
        via[rows] = amp * c.dq_dzx[rows] + e * dzx
    return grad_r, grad_phi, _add_slope_adjoint_x(via, dx, direct)


def _segment_jacobian(
    weight: np.ndarray, r: np.ndarray, phi: np.ndarray, z: np.ndarray, geom: Geometry
) -> sparse.csr_matrix:
    """:func:`jacobian_z` with ``geom.deposit == "segment"``."""
    c = _segment_cells(z, geom)
    bins, rb, dx, n = geom.bins, geom.range_bin, geom.dx, c.points
    pings, cells = shape = c.q.shape
    r, phi = np.broadcast_to(r, shape), np.broadcast_to(phi, shape)
    root = np.sqrt(np.broadcast_to(weight, (pings, bins))).ravel()
    slots = n * int(c.reach[0])
    data = np.empty((pings, cells, 3, slots))
    rows = np.empty((pings, cells, 3, slots), np.int64)
    wl, wr = _slope_columns(cells, dx)
    ping_row = np.repeat(np.arange(pings, dtype=np.int64) * bins, cells)
    for rows_b, flat in _blocks(pings, cells):
        amp = (phi[rows_b] * r[rows_b]).ravel() * (dx / (n * rb))
        e = amp * c.q[rows_b].ravel()
        direct_q, via_q = amp * c.dq_dz[rows_b].ravel(), amp * c.dq_dzx[rows_b].ravel()
        size = flat.stop - flat.start
        own, via = np.empty((size, slots)), np.empty((size, slots))
        own_rows = np.empty((size, slots), np.int64)
        for s in range(c.points):
            span = c.span[s, flat]
            dlo, dhi, xlo, xhi = c.glo[s, flat], c.ghi[s, flat], c.xlo[s, flat], c.xhi[s, flat]
            for j in range(int(c.reach[0])):
                slot = s * int(c.reach[0]) + j
                w = _segment_weight(c, s, flat, j)
                k = c.k_lo[s, flat] + j
                inside = (k >= 0) & (k < bins)
                row = ping_row[flat] + np.clip(k, 0, bins - 1)
                w_row = root[row] * inside
                at_lo = w - (1.0 if j == 0 else 0.0)  # ∂w/∂lo · (hi − lo)
                at_hi = (span == j) - w  # ∂w/∂hi · (hi − lo)
                own_rows[:, slot] = row
                own[:, slot] = (direct_q * w + e * (at_lo * dlo + at_hi * dhi)) * w_row
                via[:, slot] = (via_q * w + e * (at_lo * xlo + at_hi * xhi)) * w_row
        via = via.reshape(-1, cells, slots)
        block_data, block_rows = data[rows_b], rows[rows_b]
        block_data[:, :, 1] = own.reshape(-1, cells, slots)
        block_rows[:, :, 1] = own_rows.reshape(-1, cells, slots)
        block_data[:, 1:, 0] = via[:, :-1] * wl[1:, None]
        block_data[:, :1, 0] = via[:, :1] * wl[:1, None]
        block_data[:, :-1, 2] = via[:, 1:] * wr[:-1, None]
        block_data[:, -1:, 2] = via[:, -1:] * wr[-1:, None]
        block_rows[:, 1:, 0], block_rows[:, :1, 0] = block_rows[:, :-1, 1], block_rows[:, :1, 1]
        block_rows[:, :-1, 2], block_rows[:, -1:, 2] = block_rows[:, 1:, 1], block_rows[:, -1:, 1]
    return _columns_to_csr(data, rows, 3 * slots, (pings * bins, pings * cells))


def _segment_evaluate(
    image: np.ndarray,
    weight: np.ndarray,
    r: np.ndarray,
    phi: np.ndarray,
    z: np.ndarray,
    geom: Geometry,
    smooth: float,
    edge: float,
) -> Evaluation:
    """:func:`evaluate` with ``geom.deposit == "segment"``."""
    res = forward(r, phi, z, geom) - image
    grad_r, grad_phi, grad_z = adjoint(2.0 * weight * res, r, phi, z, geom)
    jac = jacobian_z(weight, r, phi, z, geom)
    diag_z = 2.0 * np.asarray(jac.multiply(jac).sum(axis=0)).reshape(z.shape)
    c = _segment_cells(z, geom)
    curv = _padded(np.broadcast_to(2.0 * weight / geom.range_bin**2, res.shape), c)
    a = np.zeros(z.size)
    for s in range(c.points):
        for j in range(int(c.reach[0])):
            share = _segment_weight(c, s, slice(0, z.size), j)
            a += share * share * curv[_segment_index(c, s, slice(0, z.size), j, geom.bins)]
    a = a.reshape(z.shape) * (geom.dx / c.points) ** 2
    rough, grad_rough, diag_rough = roughness(r, edge)
    return Evaluation(
        energy=float(np.sum(weight * res * res)) + smooth * rough,
        grad_r=grad_r + smooth * grad_rough,
        grad_phi=grad_phi,
        grad_z=grad_z,
        diag_r=a * (phi * c.q) ** 2 + smooth * diag_rough,
        diag_phi=a * (r * c.q) ** 2,
        diag_z=diag_z,
    )
