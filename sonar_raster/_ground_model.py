"""The ground-range Lambertian model of one side, its objective and exact discrete gradient.

Conventions
-----------
Per ping the transducer is the origin; ``x > 0`` is the ground distance across track on the
imaged side, ``y`` the along-track distance and ``Z`` the seabed elevation relative to the
transducer (negative below it). Arrays are (pings, ground cells): axis 0 is ``y`` (spacing
``dy``), axis 1 is ``x`` (spacing ``dx``, cell centres ``x``).

Slopes use the stencil of ``numpy.gradient`` with ``edge_order=1``: central differences
``(Z[j+1] − Z[j−1]) / 2h`` inside, one-sided ``(Z[1] − Z[0]) / h`` and
``(Z[n−1] − Z[n−2]) / h`` at the ends, zero along an axis of length 1.

With ``n = (−Zx, −Zy, 1)`` the upward normal and ``−r = −(x, 0, Z)`` the direction from the
seabed to the sonar, ``cos θ = (x Zx − Z) / (ρ s)`` with ``ρ = sqrt(x² + Z²)`` and
``s = sqrt(1 + Zx² + Zy²)`` (seed Eq. 14 with Z measured upward). The model is
``Î = Φ R max(0, cos θ)``; the seed's constant K is absorbed into Φ.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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
class Geometry:
    """Ground-range grid of one side.

    Attributes
    ----------
    x : ndarray, shape (cells,)
        Ground-range cell centres, metres, > 0.
    dx : float
        Ground-range cell size, metres.
    dy : float
        Along-track ping spacing, metres.
    """

    x: np.ndarray
    dx: float
    dy: float


@dataclass(frozen=True)
class Incidence:
    """``cos θ`` and its partial derivatives, all shape (pings, cells)."""

    cos: np.ndarray
    d_z: np.ndarray
    d_zx: np.ndarray
    d_zy: np.ndarray


def incidence(z: np.ndarray, geom: Geometry) -> Incidence:
    """``cos θ`` of every cell and its partials wrt Z, Zx and Zy (Z held at the others)."""
    x = geom.x[None, :]
    zx, zy = slope(z, 1, geom.dx), slope(z, 0, geom.dy)
    rho = np.sqrt(x * x + z * z)
    s2 = 1.0 + zx * zx + zy * zy
    inv = 1.0 / (rho * np.sqrt(s2))
    cos = (x * zx - z) * inv
    return Incidence(cos, -inv - cos * z / (rho * rho), x * inv - cos * zx / s2, -cos * zy / s2)


def forward(r: np.ndarray, phi: np.ndarray, z: np.ndarray, geom: Geometry) -> np.ndarray:
    """Model intensity ``Φ R max(0, cos θ)``, shape (pings, cells)."""
    return phi * r * np.maximum(incidence(z, geom).cos, 0.0)


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
) -> float:
    """``E = Σ w (I − Î)²`` over the cells, a float."""
    res = forward(r, phi, z, geom) - image
    return float(np.sum(weight * res * res))


def evaluate(
    image: np.ndarray,
    weight: np.ndarray,
    r: np.ndarray,
    phi: np.ndarray,
    z: np.ndarray,
    geom: Geometry,
) -> Evaluation:
    """Exact gradient of :func:`energy` wrt every cell of R, Φ and Z.

    ``∂E/∂Z`` collects the direct term and, through the transposed stencils, the terms that
    reach a cell through its neighbours' slopes. Where ``cos θ < 0`` the model is zero and so
    is its derivative (at exactly 0 the one-sided derivative from the lit side is not used).
    """
    inc = incidence(z, geom)
    lit = inc.cos > 0.0
    c = np.where(lit, inc.cos, 0.0)
    res = 2.0 * weight * (phi * r * c - image)
    gc = res * phi * r * lit
    gz = gc * inc.d_z
    gz += slope_adjoint(gc * inc.d_zx, 1, geom.dx)
    gz += slope_adjoint(gc * inc.d_zy, 0, geom.dy)
    amp = 2.0 * weight * (phi * r * lit) ** 2
    dz = amp * inc.d_z**2
    dz += slope_adjoint(amp * inc.d_zx**2, 1, geom.dx, power=2)
    dz += slope_adjoint(amp * inc.d_zy**2, 0, geom.dy, power=2)
    return Evaluation(
        energy=float(np.sum(weight * (phi * r * c - image) ** 2)),
        grad_r=res * phi * c,
        grad_phi=res * r * c,
        grad_z=gz,
        diag_r=2.0 * weight * (phi * c) ** 2,
        diag_phi=2.0 * weight * (r * c) ** 2,
        diag_z=dz,
    )
