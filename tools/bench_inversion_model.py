"""Speed of the surface fit's image model: the numpy path before the speed work against today's.

A benchmark, not a test: it prints a table and asserts nothing. The baseline is
``sonar_raster/inversion/model.py`` as it was at commit dafe83f (copied verbatim below, its
public functions renamed ``old_*``); the package may not keep a copy. Both run on the same
inputs in one process, interleaved, and each row gives the best of ``--repeats`` timings, their
ratio and the largest difference relative to the baseline's largest value (``max |new − old| /
max |old|`` over every output of the call).

Inputs are built as the surface fit (``sonar_raster.inversion.surface``) builds one side: 12 m
altitude, 5 cm slant bins and ground cells (``ground_axis``), pings 0.1 m apart,
``SUBSAMPLES`` points per cell, a wavy seabed (oblique sand waves, 0.1 m, plus a 2 m mound that
casts layover), random R and Φ, and a likelihood weight that is zero over the water column.
Z and R are Fortran-ordered, as the fit's products of its B-spline bases give them.
Each repeat uses a new Z, as the fit does, so the model's cache of prepared cells only helps
where the fit itself reuses Z (its adjoint and Jacobian follow a forward at the same Z).
The ``context`` rows time the fit's other per-evaluation work on the same side (shadow,
B-spline products) for the breakdown; they have no baseline.

Times are this process's CPU time (``time.process_time``), which waiting for a shared core
does not inflate, though other processes' use of the caches and memory still does: compare
ratios, not absolute times.

``--fit PINGSxBINS`` also runs one :func:`~sonar_raster.inversion.surface.fit_surface` on a
synthetic speckled line (both sides, images from the model itself) in which every call of
``forward``, ``adjoint`` and ``jacobian_z`` runs both paths on the same inputs (the fit
follows the baseline's answers): it prints each path's CPU time over the fit's calls, the
largest difference, and the rest of the fit's time. (Two separate fits would not compare:
the fit is chaotic under rounding, a 1e-15 relative change in the model moves its Z by
decimetres.)

The ``deposit`` rows time ``Geometry(deposit="segment")`` (each point's return spread over
its slant-range interval, boxes as the renderer bins) against the default tent deposit on the
same inputs; the ratio is segment / tent (no baseline: the two models differ by design).

Usage: ``python tools/bench_inversion_model.py [--sizes 200x600,1000x2000] [--repeats 5]
[--fit 200x600]``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from _common import parser
from scipy import sparse

from sonar_raster.inversion import model
from sonar_raster.inversion.ground import ground_axis
from sonar_raster.inversion.model import Evaluation, Geometry, roughness
from sonar_raster.inversion.surface.layout import bspline_basis
from sonar_raster.inversion.surface.problem import shadow_adjoint, soft_shadow
from sonar_raster.inversion.surface.solve import SUBSAMPLES

ALT, BIN, SPACING = 12.0, 0.05, 0.1

# --- baseline: sonar_raster/inversion/model.py at dafe83f, verbatim (public names old_*) ---


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


@dataclass(frozen=True)
class _Cells:
    """Per-cell terms of the model, all shape (pings, ground cells)."""

    q: np.ndarray  # max(0, x Zx − Z) / ρ
    lit: np.ndarray  # x Zx − Z > 0
    rho: np.ndarray
    subs: list[_Sub]  # the points the cell's return is spread over


@dataclass(frozen=True)
class _Sub:
    """One point of every cell's tangent plane, all shape (pings, ground cells)."""

    k0: np.ndarray  # lower slant bin (may be −1 or >= bins)
    t: np.ndarray  # weight of bin k0 + 1
    zr: np.ndarray  # Z_s / ρ_s = ∂ρ_s/∂Z
    offset: float  # o dx: ∂ρ_s/∂Zx = zr · offset


def _cells(z: np.ndarray, geom: Geometry) -> _Cells:
    x = geom.x[None, :]
    rho = np.sqrt(x * x + z * z)
    zx = slope(z, 1, geom.dx)
    num = x * zx - z
    n = geom.subsamples
    subs = []
    for s in range(n):
        offset = ((s + 0.5) / n - 0.5) * geom.dx
        zs = z + offset * zx
        rs = np.sqrt((x + offset) ** 2 + zs * zs)
        u = rs / geom.range_bin - 0.5
        k0 = np.floor(u)
        subs.append(_Sub(k0.astype(np.int64), u - k0, zs / rs, offset))
    return _Cells(np.maximum(num, 0.0) / rho, num > 0.0, rho, subs)


def _splat(values: np.ndarray, c: _Sub, bins: int) -> np.ndarray:
    """``Σ_j values_j w_jk``, shape (pings, bins); bins outside ``[0, bins)`` are dropped."""
    pings, width = values.shape[0], bins + 2
    rows = np.broadcast_to(np.arange(pings)[:, None] * width, values.shape)
    lo = (rows + np.clip(c.k0 + 1, 0, bins + 1)).ravel()
    hi = (rows + np.clip(c.k0 + 2, 0, bins + 1)).ravel()
    out = np.bincount(lo, (values * (1.0 - c.t)).ravel(), pings * width)
    out += np.bincount(hi, (values * c.t).ravel(), pings * width)
    out = out.reshape(pings, width)
    return out[:, 1:-1]


def _gather(field: np.ndarray, c: _Sub) -> tuple[np.ndarray, np.ndarray]:
    """``field`` (pings, bins) at each cell's bins k0 and k0 + 1 (0 outside)."""
    pad = np.pad(field, ((0, 0), (1, 1)))
    rows = np.arange(field.shape[0])[:, None]
    last = field.shape[1] + 1
    return pad[rows, np.clip(c.k0 + 1, 0, last)], pad[rows, np.clip(c.k0 + 2, 0, last)]


def old_forward(r: np.ndarray, phi: np.ndarray, z: np.ndarray, geom: Geometry) -> np.ndarray:
    """Model intensity per metre of slant range, shape (pings, bins)."""
    c = _cells(z, geom)
    return _splat_all(phi * r * c.q * geom.dx, c, geom.bins) / geom.range_bin


def _splat_all(e: np.ndarray, c: _Cells, bins: int) -> np.ndarray:
    """Each cell's energy ``e`` shared equally by its points, splatted, (pings, bins)."""
    out = np.zeros((e.shape[0], bins))
    for sub in c.subs:
        out += _splat(e / len(c.subs), sub, bins)
    return out


def old_evaluate(
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
    approximate (they only scale the steps).
    """
    c = _cells(z, geom)
    rb, dx, n = geom.range_bin, geom.dx, len(c.subs)
    e = phi * r * c.q * dx
    res = _splat_all(e, c, geom.bins) / rb - image
    grad = 2.0 * weight * res / rb
    curv = np.broadcast_to(2.0 * weight / rb**2, res.shape)
    b, a = np.zeros_like(e), np.zeros_like(e)
    shift_z, shift_zx, shift_diag = np.zeros_like(e), np.zeros_like(e), np.zeros_like(e)
    for sub in c.subs:
        g0, g1 = _gather(grad, sub)
        w0, w1 = _gather(curv, sub)
        b += ((1.0 - sub.t) * g0 + sub.t * g1) / n
        a += ((1.0 - sub.t) ** 2 * w0 + sub.t**2 * w1) / n
        moved = e / n * (g1 - g0) / rb * sub.zr  # ∂E/∂ρ_s · ∂ρ_s/∂Z
        shift_z += moved
        shift_zx += moved * sub.offset
        shift_diag += (w0 + w1) * (e / n * sub.zr / rb) ** 2
    amp = phi * r * dx * c.lit
    x = geom.x[None, :]
    dq_dz = -1.0 / c.rho - c.q * z / c.rho**2
    dq_dzx = x / c.rho
    gz = b * amp * dq_dz + shift_z + slope_adjoint(b * amp * dq_dzx + shift_zx, 1, dx)
    dz = a * (amp * dq_dz) ** 2 + shift_diag
    dz += slope_adjoint(a * (amp * dq_dzx) ** 2, 1, dx, power=2)
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


def _slope_matrix(n: int, step: float) -> sparse.csr_matrix:
    """The :func:`slope` stencil along one axis of length ``n`` as a sparse matrix."""
    d = sparse.lil_matrix((n, n))
    if n >= 2:
        for j in range(1, n - 1):
            d[j, j - 1], d[j, j + 1] = -0.5 / step, 0.5 / step
        d[0, 0], d[0, 1] = -1.0 / step, 1.0 / step
        d[n - 1, n - 2], d[n - 1, n - 1] = -1.0 / step, 1.0 / step
    return d.tocsr()


def old_jacobian_z(
    weight: np.ndarray, r: np.ndarray, phi: np.ndarray, z: np.ndarray, geom: Geometry
) -> sparse.csr_matrix:
    """``sqrt(w) ∂Î/∂Z`` as a sparse (pings·bins) × (pings·cells) matrix.

    Exact, with the same terms as :func:`evaluate`.
    """
    c = _cells(z, geom)
    rb, dx, n = geom.range_bin, geom.dx, len(c.subs)
    pings, cells = z.shape
    amp = phi * r * dx * c.lit / rb / n
    x = geom.x[None, :]
    direct_q = amp * (-1.0 / c.rho - c.q * z / c.rho**2)
    via_slope = amp * x / c.rho
    width = geom.bins
    rows_base = np.arange(pings)[:, None] * width
    col = np.arange(pings * cells).reshape(pings, cells)
    parts_d, parts_s = [], []
    for sub in c.subs:
        shift = phi * r * c.q * dx / n * sub.zr / rb**2
        for k, wgt, dw in ((sub.k0, 1.0 - sub.t, -1.0), (sub.k0 + 1, sub.t, 1.0)):
            inside = (k >= 0) & (k < width)
            row = (rows_base + np.clip(k, 0, width - 1))[inside]
            parts_d.append((row, col[inside], (direct_q * wgt + shift * dw)[inside]))
            slope_part = via_slope * wgt + shift * sub.offset * dw
            parts_s.append((row, col[inside], slope_part[inside]))
    shape = (pings * width, pings * cells)

    def build(parts):
        rows, cols, vals = (np.concatenate(p) for p in zip(*parts, strict=True))
        return sparse.csr_matrix((vals, (rows, cols)), shape=shape)

    dmat = sparse.kron(sparse.identity(pings), _slope_matrix(cells, geom.dx), format="csr")
    sw = sparse.diags(np.sqrt(weight).ravel())
    return (sw @ (build(parts_d) + build(parts_s) @ dmat)).tocsr()


def old_adjoint(
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
    c = _cells(z, geom)
    rb, dx, n = geom.range_bin, geom.dx, len(c.subs)
    e = phi * r * c.q * dx
    grad = grad_model / rb
    b = np.zeros_like(e)
    shift_z, shift_zx = np.zeros_like(e), np.zeros_like(e)
    for sub in c.subs:
        g0, g1 = _gather(grad, sub)
        b += ((1.0 - sub.t) * g0 + sub.t * g1) / n
        moved = e / n * (g1 - g0) / rb * sub.zr
        shift_z += moved
        shift_zx += moved * sub.offset
    amp = phi * r * dx * c.lit
    x = geom.x[None, :]
    dq_dz = -1.0 / c.rho - c.q * z / c.rho**2
    gz = b * amp * dq_dz + shift_z + slope_adjoint(b * amp * x / c.rho + shift_zx, 1, dx)
    return b * phi * c.q * dx, b * r * c.q * dx, gz


# --- the benchmark -------------------------------------------------------------------------


@dataclass
class Case:
    """One side's inputs; ``zs`` holds one Z per repeat."""

    geom: Geometry
    zs: list[np.ndarray]
    r: np.ndarray
    phi: np.ndarray
    grad: np.ndarray
    image: np.ndarray
    weight: np.ndarray
    tau: np.ndarray


def make_case(pings: int, bins: int, repeats: int, seed: int = 0) -> Case:
    """Inputs of one side with ``pings`` pings and ``bins`` slant bins (see the module notes)."""
    rng = np.random.default_rng(seed)
    x = ground_axis(np.full(pings, ALT), BIN, bins, BIN)
    geom = Geometry(x, BIN, SPACING, BIN, bins, SUBSAMPLES)
    xx, yy = np.meshgrid(x, np.arange(pings) * SPACING)
    mound = 2.0 * np.exp(-((xx - 0.6 * x[-1]) ** 2 + (yy - yy.mean()) ** 2) / (2 * 1.5**2))
    zs = []
    for i in range(repeats):
        waves = 0.1 * np.sin(2 * np.pi * (0.87 * xx + 0.5 * yy) / 3.0 + 0.3 * i)
        zs.append(np.asfortranarray(-ALT + waves + mound))  # as the fit's (bx @ (by @ c).T).T
    centres = (np.arange(bins) + 0.5) * BIN
    weight = np.broadcast_to(centres >= 0.9 * ALT, (pings, bins)) * rng.uniform(
        0.5, 2.0, (pings, bins)
    )
    return Case(
        geom,
        zs,
        np.asfortranarray(rng.uniform(0.3, 1.5, xx.shape)),  # exp of such a product
        rng.uniform(0.5, 2.0, xx.shape),
        rng.standard_normal((pings, bins)),
        rng.gamma(1.0, 1.0, (pings, bins)),
        weight,
        ALT * BIN / np.maximum(x, BIN) ** 2,
    )


def _outputs(value: Any) -> list[np.ndarray]:
    if isinstance(value, Evaluation):
        names = ("grad_r", "grad_phi", "grad_z", "diag_r", "diag_phi", "diag_z")
        return [np.asarray(value.energy)] + [getattr(value, n) for n in names]
    if sparse.issparse(value):
        return [value.toarray()] if value.shape[0] * value.shape[1] < 4e7 else [value]
    if isinstance(value, tuple):
        return [np.asarray(v) for v in value]
    return [np.asarray(value)]


def difference(new: Any, old: Any) -> float:
    """``max |new − old| / max |old|`` over all outputs of a call."""
    worst = 0.0
    for a, b in zip(_outputs(new), _outputs(old), strict=True):
        if sparse.issparse(b):
            scale = float(abs(b).max())
            delta = float(abs(sparse.csr_matrix(a) - b).max())
        else:
            scale, delta = float(np.max(np.abs(b))), float(np.max(np.abs(a - b)))
        worst = max(worst, delta / scale if scale > 0 else delta)
    return worst


Call = Callable[[np.ndarray], Any]


def race(old: Call, new: Call, case: Case, prepare: Call | None = None) -> tuple:
    """Best times of ``old(z)`` and ``new(z)`` over the case's Zs, and the outputs' difference.

    ``prepare(z)`` runs (untimed) before each new call: the fit's forward at that Z. Each
    call gets a Z that differs from the previous ones', so the model's cache (two entries)
    never holds it unless ``prepare`` put it there.
    """
    best_old, best_new, diff = np.inf, np.inf, 0.0
    for i, z in enumerate(case.zs):
        order = (0, 1) if i % 2 == 0 else (1, 0)
        for which in order:
            if which == 0:
                start = time.process_time()
                out_old = old(z)
                best_old = min(best_old, time.process_time() - start)
            else:
                if prepare is not None:
                    prepare(z)
                start = time.process_time()
                out_new = new(z)
                best_new = min(best_new, time.process_time() - start)
        diff = max(diff, difference(out_new, out_old))
    return best_old, best_new, diff


def rows(case: Case) -> list[tuple[str, Call, Call, Call | None]]:
    """(label, baseline call, package call, untimed preparation) per benchmarked call."""
    g, r, phi, grad, image, w = case.geom, case.r, case.phi, case.grad, case.image, case.weight

    def fwd(z):
        return model.forward(r, phi, z, g)

    def objective_new(z):  # one side of the surface fit's objective: forward, then adjoint
        model.forward(r, phi, z, g)
        return model.adjoint(grad, r, phi, z, g)

    def objective_old(z):
        old_forward(r, phi, z, g)
        return old_adjoint(grad, r, phi, z, g)

    return [
        ("forward (new Z)", lambda z: old_forward(r, phi, z, g), fwd, None),
        (
            "adjoint (new Z)",
            lambda z: old_adjoint(grad, r, phi, z, g),
            lambda z: model.adjoint(grad, r, phi, z, g),
            None,
        ),
        (
            "adjoint after forward",
            lambda z: old_adjoint(grad, r, phi, z, g),
            lambda z: model.adjoint(grad, r, phi, z, g),
            fwd,
        ),
        ("forward + adjoint", objective_old, objective_new, None),
        (
            "jacobian_z after forward",
            lambda z: old_jacobian_z(w, r, phi, z, g),
            lambda z: model.jacobian_z(w, r, phi, z, g),
            fwd,
        ),
        (
            "evaluate (em.py)",
            lambda z: old_evaluate(image, w, r, phi, z, g),
            lambda z: model.evaluate(image, w, r, phi, z, g),
            None,
        ),
    ]


def context(case: Case) -> list[tuple[str, float]]:
    """Best times of the fit's other per-side work at this size, seconds (no baseline)."""
    g, z = case.geom, case.zs[0]
    pings = z.shape[0]
    shade, occluder, slope_ = soft_shadow(z, g.x, case.tau)
    y = np.arange(pings) * SPACING
    by = bspline_basis(y, 0.0, y[-1], 4 * BIN)
    bx = bspline_basis(g.x, -g.x[-1], g.x[-1], 4 * BIN)
    knots = np.random.default_rng(1).standard_normal((by.shape[1], bx.shape[1]))
    g_cells = case.grad[:, : g.x.size]
    calls = {
        "soft_shadow": lambda: soft_shadow(z, g.x, case.tau),
        "shadow_adjoint": lambda: shadow_adjoint(g_cells, occluder, slope_, g.x),
        "Z from knots (bx, by)": lambda: np.asarray((bx @ (by @ knots).T).T),
        "knots from dE/dZ (byT, bxT)": lambda: by.T @ np.asarray((bx.T @ g_cells.T).T),
        "exp of log R": lambda: np.exp(z),
    }
    out = []
    for label, call in calls.items():
        best = np.inf
        for _ in range(len(case.zs)):
            start = time.process_time()
            call()
            best = min(best, time.process_time() - start)
        out.append((label, best))
    return out


def deposit_rows(case: Case) -> list[tuple[str, float, float]]:
    """Best times of the tent deposit (the fit's) and the segment deposit, same calls and Zs.

    Returns (label, tent s, segment s) for forward, adjoint after forward and jacobian_z after
    forward; each call gets a new Z, as in :func:`race`. The deposits run one after the other
    (their order alternating by row), not interleaved: interleaved, each would evict the
    other's cache entry and allocate afresh.
    """
    tent = case.geom
    seg = Geometry(tent.x, tent.dx, tent.dy, tent.range_bin, tent.bins, tent.subsamples, "segment")
    r, phi, grad, w = case.r, case.phi, case.grad, case.weight
    calls = {
        "forward (new Z)": (lambda z, g: model.forward(r, phi, z, g), None),
        "adjoint after forward": (
            lambda z, g: model.adjoint(grad, r, phi, z, g),
            lambda z, g: model.forward(r, phi, z, g),
        ),
        "jacobian_z after forward": (
            lambda z, g: model.jacobian_z(w, r, phi, z, g),
            lambda z, g: model.forward(r, phi, z, g),
        ),
    }
    out = []
    for i, (label, (call, prepare)) in enumerate(calls.items()):
        best = [np.inf, np.inf]
        for which in (0, 1) if i % 2 == 0 else (1, 0):
            g = (tent, seg)[which]
            model.clear_cache()  # then each deposit recycles its own evicted entries
            for z in case.zs:
                if prepare is not None:
                    prepare(z, g)
                start = time.process_time()
                call(z, g)
                best[which] = min(best[which], time.process_time() - start)
        out.append((label, best[0], best[1]))
    return out


def fit_race(pings: int, bins: int) -> None:
    """Run ``fit_surface`` once, every model call made by both paths, and total their times.

    The fit follows the baseline's answers; the package's are computed on the same inputs right
    beside them (the order alternating) and compared. The fit's own work is what is left of
    its CPU time.
    """
    from sonar_raster.inversion import surface
    from sonar_raster.inversion.surface import problem, solve

    case = make_case(pings, bins, 1)
    rng = np.random.default_rng(3)
    sides = {}
    for name in ("port", "starboard"):
        z = np.ascontiguousarray(case.zs[0][:, ::-1] if name == "port" else case.zs[0])
        beam = np.exp(-(((np.arctan2(ALT, case.geom.x) - 0.5) / 0.5) ** 2))
        clean = model.forward(np.ones_like(z), np.broadcast_to(beam, z.shape), z, case.geom)
        sides[name] = clean * BIN * rng.gamma(1.0, 1.0, clean.shape) + 1e-6
    pairs: dict[str, tuple[Callable[..., Any], Callable[..., Any]]] = {
        "forward": (old_forward, model.forward),
        "adjoint": (old_adjoint, model.adjoint),
        "jacobian_z": (old_jacobian_z, model.jacobian_z),
    }
    spent = {name: [0.0, 0.0, 0, 0.0] for name in pairs}  # old s, new s, calls, max diff

    def both(name: str) -> Callable[..., Any]:
        old, new = pairs[name]

        def call(*args: Any) -> Any:
            record = spent[name]
            outputs = [None, None]
            for which in (0, 1) if record[2] % 2 == 0 else (1, 0):
                start = time.process_time()
                outputs[which] = (old, new)[which](*args)
                record[which] += time.process_time() - start
            record[2] += 1
            record[3] = max(record[3], difference(outputs[1], outputs[0]))
            return outputs[0]

        return call

    kept = (problem.forward, problem.adjoint, solve.forward, solve.jacobian_z)
    try:
        problem.forward = solve.forward = both("forward")  # type: ignore[assignment]
        problem.adjoint = both("adjoint")  # type: ignore[assignment]
        solve.jacobian_z = both("jacobian_z")  # type: ignore[assignment]
        start = time.process_time()
        surface.fit_surface(sides, BIN, ping_spacing=SPACING)
        total = time.process_time() - start
    finally:
        problem.forward, problem.adjoint, solve.forward, solve.jacobian_z = kept  # type: ignore[assignment]
    rest = total - sum(v[0] + v[1] for v in spent.values())
    print(f"\nfit_surface, {pings} pings x {bins} bins x 2 sides: model calls in the fit")
    print(f"{'call':12s} {'calls':>6s} {'old s':>8s} {'new s':>8s} {'ratio':>6s} {'max diff':>9s}")
    for name, (t_old, t_new, calls, diff) in spent.items():
        print(f"{name:12s} {calls:6d} {t_old:8.2f} {t_new:8.2f} {t_old / t_new:6.2f} {diff:9.1e}")
    old_all = sum(v[0] for v in spent.values())
    new_all = sum(v[1] for v in spent.values())
    print(
        f"rest of the fit {rest:.1f} s; fit with the old model {rest + old_all:.1f} s, "
        f"with the new {rest + new_all:.1f} s (CPU)"
    )


def main() -> None:
    """Print the table for each size."""
    ap = parser(__doc__)
    ap.add_argument("--sizes", default="200x600,1000x2000", help="pings x bins, comma separated")
    ap.add_argument("--repeats", type=int, default=5, help="Zs (timed calls) per row")
    ap.add_argument("--fit", default="", help="also time fit_surface at PINGSxBINS")
    args = ap.parse_args()
    if args.repeats < 3:
        ap.error("--repeats must be at least 3 (each call needs a Z the cache does not hold)")
    for size in filter(None, args.sizes.split(",")):
        pings, bins = (int(v) for v in size.split("x"))
        case = make_case(pings, bins, args.repeats)
        cells = case.geom.x.size
        print(f"\n{pings} pings x {bins} bins ({cells} ground cells, {SUBSAMPLES} points per cell)")
        print(f"{'call':28s} {'old ms':>9s} {'new ms':>9s} {'ratio':>6s} {'max rel diff':>12s}")
        for label, old, new, prepare in rows(case):
            t_old, t_new, diff = race(old, new, case, prepare)
            print(
                f"{label:28s} {t_old * 1e3:9.2f} {t_new * 1e3:9.2f} "
                f"{t_old / t_new:6.2f} {diff:12.1e}"
            )
        for label, seconds in context(case):
            print(f"{'context: ' + label:38s} {seconds * 1e3:9.2f}")
        model.clear_cache()
        print(f"{'deposit':28s} {'tent ms':>9s} {'seg. ms':>9s} {'seg/tent':>8s}")
        for label, t_tent, t_seg in deposit_rows(case):
            print(f"{label:28s} {t_tent * 1e3:9.2f} {t_seg * 1e3:9.2f} {t_seg / t_tent:8.2f}")
        model.clear_cache()
    if args.fit:
        fit_race(*(int(v) for v in args.fit.split("x")))


if __name__ == "__main__":
    main()
