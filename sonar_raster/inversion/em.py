"""One pyramid level of the inversion: EM iterations with a monotone line search.

Expectation: render ``Î`` from the current R, Φ, Z. Maximisation: one step along the
gradient of E scaled by the Gauss-Newton diagonal (Levenberg damped) of each unknown, times a
per-unknown weight, with Z moves capped at one ground cell; the step length is found by
backtracking (halving) until the Armijo condition holds on the exact E. A step that lowers E
is the only one ever taken, so E cannot rise between iterations and the iteration cannot blow
up; when no step lowers E the level has converged.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy import ndimage

from .model import Geometry, energy, evaluate, gauss_newton_z
from .priors import slope_hessian, slope_roughness

#: Sufficient-decrease constant of the Armijo test.
ARMIJO = 1e-4
#: Halvings tried before a level is declared converged.
MAX_HALVINGS = 30
#: Levenberg damping, relative to the mean positive Gauss-Newton diagonal of each unknown.
DAMPING = 1e-3


@dataclass(frozen=True)
class Problem:
    """The data and fixed structure of one level.

    Attributes
    ----------
    image, weight : ndarray, shape (pings, slant bins)
        Intensity per metre of slant range and the 0/1 weight of each bin in E.
    geom : Geometry
        Ground cell centres and spacings.
    bins : ndarray, shape (pings, ground cells), int64
        Depression-angle bin of every cell (index into the Φ profile).
    tie : ndarray, shape (pings * cells,), int64
        Flat index of the cell whose reflectivity each cell takes (nearest lit cell).
    smooth : float
        Weight of the reflectivity roughness term of E.
    smooth_phi : float
        Weight of the beam-profile curvature term ``Σ (Δ²Φ)²`` of E.
    edge : float
        ε of the edge-preserving reflectivity roughness (0: quadratic); see
        :func:`sonar_raster.inversion.model.roughness`.
    flat : float
        Weight of the flat-seabed prior ``Σ (G (Z − Z_ref))²`` of E (0: none), ``G`` a Gaussian
        low-pass along and across track (see :meth:`low_pass`).
    flat_sigma : tuple of float
        σ of ``G`` in cells, (along track, across track).
    z_ref : ndarray, shape (pings, cells), optional
        The reference surface of the prior (a flat seabed at each ping's altitude); needed
        when ``flat > 0``.
    relief : float
        Weight of the relief prior ``Σ (Z − Z_ref)²`` of E (0: none).
    slopes : float
        Weight of the slope prior ``Σ (∂Z/∂x)² + (∂Z/∂y)²`` of E (0: none); see
        :func:`sonar_raster.inversion.priors.slope_roughness`.
    """

    image: np.ndarray
    weight: np.ndarray
    geom: Geometry
    bins: np.ndarray
    tie: np.ndarray
    smooth: float = 0.0
    smooth_phi: float = 0.0
    edge: float = 0.0
    flat: float = 0.0
    flat_sigma: tuple[float, float] = (1.0, 1.0)
    z_ref: np.ndarray | None = None
    relief: float = 0.0
    slopes: float = 0.0

    def low_pass(self, values: np.ndarray) -> np.ndarray:
        """``G values``: Gaussian of σ ``flat_sigma`` cells, zero outside the grid.

        Zero padding makes ``G`` a symmetric matrix, its own adjoint in the gradient.
        """
        return ndimage.gaussian_filter(values, self.flat_sigma, mode="constant")

    @cached_property
    def slope_hessian(self) -> tuple:
        """The slope prior's constant Hessian parts (see :func:`slope_hessian`), built once."""
        return slope_hessian(self.bins.shape, self.geom.dx, self.geom.dy)

    def flat_diagonal(self) -> float:
        """``Σ_k G_kj²`` of an inner cell: the diagonal of ``GᵀG`` (G is separable)."""
        out = 1.0
        for sigma in self.flat_sigma:
            delta = np.zeros(2 * int(4 * sigma + 0.5) + 3)
            delta[delta.size // 2] = 1.0
            out *= float(np.sum(ndimage.gaussian_filter1d(delta, sigma, mode="constant") ** 2))
        return out

    def cells(self, r: np.ndarray, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per-cell R and Φ from the parameters (flat R, Φ profile)."""
        return r[self.tie].reshape(self.bins.shape), phi[self.bins]

    def energy(self, r: np.ndarray, phi: np.ndarray, z: np.ndarray) -> float:
        """E of the parameters."""
        rc, pc = self.cells(r, phi)
        data = energy(self.image, self.weight, rc, pc, z, self.geom, self.smooth, self.edge)
        data += self.smooth_phi * float(np.sum(np.diff(phi, 2) ** 2))
        if self.flat > 0 and self.z_ref is not None:
            data += self.flat * float(np.sum(self.low_pass(z - self.z_ref) ** 2))
        if self.relief > 0 and self.z_ref is not None:
            data += self.relief * float(np.sum((z - self.z_ref) ** 2))
        if self.slopes > 0:
            data += self.slopes * slope_roughness(z, self.geom.dx, self.geom.dy)[0]
        return data


@dataclass(frozen=True)
class Steps:
    """Relative step weights of R, Φ and Z (0 freezes an unknown, e.g. Φ when calibrated)."""

    r: float = 1.0
    phi: float = 1.0
    z: float = 1.0


def _direction(grad: np.ndarray, diag: np.ndarray, scale: float) -> np.ndarray:
    positive = diag[diag > 0]
    mu = DAMPING * float(positive.mean()) if positive.size else 1.0
    return -scale * grad / (diag + mu + 1e-300)


def _search_direction(
    prob: Problem, r: np.ndarray, phi: np.ndarray, z: np.ndarray, steps: Steps
) -> tuple[list[np.ndarray], float]:
    """Step directions of R, Φ and Z and the slope of E along them (gradient · direction)."""
    rc, pc = prob.cells(r, phi)
    ev = evaluate(prob.image, prob.weight, rc, pc, z, prob.geom, prob.smooth, prob.edge)
    nb = len(phi)
    grads = [
        np.bincount(prob.tie, ev.grad_r.ravel(), minlength=r.size),
        np.bincount(prob.bins.ravel(), ev.grad_phi.ravel(), minlength=nb),
        ev.grad_z,
    ]
    prior_z = np.zeros_like(z)
    if prob.flat > 0 and prob.z_ref is not None:
        grads[2] = grads[2] + 2.0 * prob.flat * prob.low_pass(prob.low_pass(z - prob.z_ref))
        prior_z += 2.0 * prob.flat * prob.flat_diagonal()
    if prob.relief > 0 and prob.z_ref is not None:
        grads[2] = grads[2] + 2.0 * prob.relief * (z - prob.z_ref)
        prior_z += 2.0 * prob.relief
    coupled = None
    if prob.slopes > 0:
        across, along = prob.slope_hessian
        grads[2] = grads[2] + prob.slopes * slope_roughness(z, prob.geom.dx, prob.geom.dy)[1]
        coupled = prob.slopes * across
        prior_z += prob.slopes * along
    if prob.smooth_phi > 0 and len(phi) > 2:
        d2 = np.diff(phi, 2)
        adj = np.zeros_like(phi)
        adj[:-2] += d2
        adj[1:-1] -= 2.0 * d2
        adj[2:] += d2
        grads[1] = grads[1] + 2.0 * prob.smooth_phi * adj
    diag_r = np.bincount(prob.tie, ev.diag_r.ravel(), minlength=r.size)
    diag_phi = np.bincount(prob.bins.ravel(), ev.diag_phi.ravel(), minlength=nb)
    dirs = [
        _direction(grads[0], diag_r, steps.r),
        _direction(grads[1], diag_phi + 12.0 * prob.smooth_phi, steps.phi),
        np.zeros_like(z),
    ]
    if steps.z > 0 and z.size:
        dirs[2] = steps.z * gauss_newton_z(
            grads[2], prob.weight, rc, pc, z, prob.geom, DAMPING, prior_z, coupled
        )
    biggest = float(np.max(np.abs(dirs[2]))) if dirs[2].size else 0.0
    if biggest > prob.geom.dx:
        dirs[2] *= prob.geom.dx / biggest
    slope = sum(float(np.sum(g * d)) for g, d in zip(grads, dirs, strict=True))
    return dirs, slope


def iterate(
    prob: Problem,
    r: np.ndarray,
    phi: np.ndarray,
    z: np.ndarray,
    *,
    steps: Steps,
    max_iter: int,
    tol: float,
    tick: Callable[[], None] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[float], str]:
    """Run EM iterations until the relative decrease of E is below ``tol``.

    Parameters
    ----------
    prob : Problem
    r : ndarray, shape (pings * cells,)
        Reflectivity parameters (a shadow cell's own entry is unused; see ``prob.tie``).
    phi : ndarray, shape (bins,)
        Beam profile per depression-angle bin.
    z : ndarray, shape (pings, cells)
        Elevation relative to the transducer, metres.
    steps : Steps
    max_iter : int
    tol : float
    tick : callable, optional
        Called once per iteration (progress bar).

    Returns
    -------
    r, phi, z
        The final parameters.
    energies : list of float
        E before the first iteration and after each accepted one; non-increasing.
    stopped : str
        Why it stopped: ``"tol"`` (E changed by less than ``tol * E``), ``"stalled"`` (no
        descent direction or no step lowers E) or ``"max_iter"``.
    """
    energies = [prob.energy(r, phi, z)]
    t = 1.0
    stopped = "max_iter"
    for _ in range(max_iter):
        e0 = energies[-1]
        dirs, slope = _search_direction(prob, r, phi, z, steps)
        if not slope < 0:
            stopped = "stalled"
            break
        t = min(1.0, 2.0 * t)
        for _ in range(MAX_HALVINGS):
            cand = (
                np.maximum(r + t * dirs[0], 0.0),
                np.maximum(phi + t * dirs[1], 0.0),
                z + t * dirs[2],
            )
            e1 = prob.energy(*cand)
            if e1 <= e0 + ARMIJO * t * slope:
                break
            t *= 0.5
        else:
            stopped = "stalled"
            break
        r, phi, z = cand
        energies.append(e1)
        if tick is not None:
            tick()
        if e0 - e1 <= tol * e0:
            stopped = "tol"
            break
    return r, phi, z, energies, stopped
