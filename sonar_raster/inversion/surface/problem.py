"""The surface fit's objective: the speckle likelihood of every view plus the priors.

The image model is :mod:`..model`'s (each ground cell's Lambertian return at its own slant
range, so foreshortening and layover are modelled) with Φ at each cell's own depression angle
``atan2(−Z, x)``, times a soft cast-shadow factor ``S = exp(min(0, (Z/x − M) / τ))`` (``M`` the
largest ``Z/x`` of the nearer cells of the ping, ``τ`` one cell's angle on the flat seabed),
plus the noise floor. Its fit to the data is the L-look Gamma likelihood of speckle,
``L Σ (I/μ + log μ)``; the gradient is exact (tests/inversion/test_surface.py).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import TypeVar

import numpy as np
from scipy import ndimage, sparse

from ..._budget import usable_cores
from ..model import adjoint, deposit_matrix, forward
from .layout import View, bspline_basis, knot_centres

#: Threads the fit works on (the views of :class:`HeldZ` side by side, the uncertainty's
#: blocks): numpy's arithmetic and scipy's sparse products and triangular solves release the
#: GIL. (The full objective's views are not: its model's ``np.add.at`` holds the GIL, and two
#: threads measured no faster there.)
THREADS = min(usable_cores(), 4)

#: SuperLU settings for the fit's symmetric positive definite matrices (the Gauss-Newton matrix,
#: the flat start's normal equations, the uncertainty's blocks; minimum degree on A + Aᵀ,
#: diagonal pivots): 3.5x faster factorisation than the defaults at 29k knots.
SYMMETRIC_LU = {
    "permc_spec": "MMD_AT_PLUS_A",
    "diag_pivot_thresh": 0.0,
    "options": {"SymmetricMode": True},
}
#: Ridge of the flat start's least squares, per knot (what holds knots no nadir sees).
FLAT_START_DAMP = 1e-3

_T = TypeVar("_T")
_U = TypeVar("_U")


@functools.cache
def _pool(threads: int) -> ThreadPoolExecutor:
    return ThreadPoolExecutor(threads, thread_name_prefix="surface")


def each(func: Callable[[_T], _U], items: Iterable[_T]) -> list[_U]:
    """``[func(item) for item in items]`` on up to :data:`THREADS` threads, in order.

    ``func`` must not call :func:`each` itself (the threads would wait on one another).
    """
    items = list(items)
    if THREADS <= 1 or len(items) <= 1:
        return [func(item) for item in items]
    return list(_pool(THREADS).map(func, items))


#: Standard deviations of the seabed's curvature across and along track assumed by the prior
#: on Z, 1/m (in data units: that curvature costs one nat per knot and look).
CURVATURE_STD = 30.0
CURVATURE_STD_ALONG = 3.0
#: Weight of the reflectivity's edge-preserving roughness, in nats of data per R knot (per
#: unit look) for a jump of one in log R, and its ε (log R differences below ε cost
#: quadratically).
REFLECTIVITY_WEIGHT = 0.5
REFLECTIVITY_EDGE = 0.05
#: Weight of the curvature of log Φ against angle, in the same units, per node.
BEAM_WEIGHT = 10.0
#: Standard deviation of log Φ about a calibrated beam profile's shape, per node (0.02: about
#: 0.1 dB, a calibration's own spread; its level stays free per side).
CALIBRATED_BEAM_STD = 0.02
#: Standard deviation of the first-return altitude per ping, in range bins (the images' own at
#: the finest level fitted, pooled above it) on a single look: the bottom tracker's own error
#: there (a phase bias of up to a third of a bin); its reading of a rough seabed's crests is
#: taken off first (``solve.CREST_OFFSET``). With L looks it is this over √L (capped at
#: ``solve.MAX_LOOKS``), as the data's weight grows with L: on clean images held at a quarter
#: bin the data near the nadir outweighed it and kept sand waves 6.7 cm high (clean sand 0.733;
#: 0.350 with σ 0.05 bin, docs/notes/2026-11-29-anchor-looks.md).
ANCHOR_BINS = 0.25
#: Standard deviation of the relief about the flat seabed at the first return, metres (None:
#: no such prior). The image hardly fixes a broad bending of Z that the beam can absorb.
RELIEF_STD: float | None = 0.3
#: Standard deviation of the ground's height about the flat seabed inside the shadows of
#: objects the fit found by their shadows, in range bins (in data units, like the curvature):
#: the data say nothing there, and a hollow behind a lower object casts the same shadow.
SHADOW_GROUND_BINS = 1.0
#: Weight of the prior holding each view's line-averaged across-track profile of Z at the flat
#: seabed: a mean deviation of one range bin costs this many nats per knot and look (0: none).
LINE_PROFILE_WEIGHT = 1.0
#: Across-track scale of that prior's low-pass, as a fraction of the altitude.
LINE_PROFILE_SCALE = 0.25
#: The line-profile prior's directions the Gauss-Newton steps solve exactly
#: (:meth:`Problem.line_subspace`): those whose low-pass gain² is above this fraction of the
#: largest, at most ``LINE_SUBSPACE_MAX`` per view (they number about 4.4 × the swath's width
#: over the altitude: 37 at 100 m range and 12 m altitude).
LINE_SUBSPACE_GAIN = 1e-5
LINE_SUBSPACE_MAX = 100


@dataclass(frozen=True)
class Grid:
    """The knot grids of Z and log R and the beam's angle nodes, shared by every view."""

    extent: tuple[float, float, float, float]  # y0, y1, X0, X1 in the frame
    z_spacing: float
    r_spacing: float
    angles: tuple[float, float]  # depression angles of the first and last Φ node
    nodes: int
    sides: tuple[str, ...]  # one Φ profile per side, shared by every line

    def knots(self, which: str) -> tuple[np.ndarray, np.ndarray]:
        """Centres (y, X) of the Z (``"z"``) or log R (``"r"``) basis functions."""
        y0, y1, x0, x1 = self.extent
        s = self.z_spacing if which == "z" else self.r_spacing
        return knot_centres(y0, y1, s), knot_centres(x0, x1, s)

    def sample(self, coefs: np.ndarray, points: tuple[np.ndarray, np.ndarray], which: str):
        """The Z or log R spline with coefficients ``coefs`` (ky, kx) on the grid ``points``."""
        y0, y1, x0, x1 = self.extent
        s = self.z_spacing if which == "z" else self.r_spacing
        by = bspline_basis(points[0], y0, y1, s)
        bx = bspline_basis(points[1], x0, x1, s)
        return np.asarray((bx @ (by @ coefs).T).T)


@dataclass(frozen=True)
class Beam:
    """Φ per cell, (pings, cells): its value, lower node, weight of the upper node, ∂Φ/∂Z."""

    phi: np.ndarray
    index: np.ndarray
    weight: np.ndarray
    dz: np.ndarray


class Problem:
    """The objective of one level and its gradient.

    Parameters
    ----------
    views : sequence of View
        Every side of every line at this level.
    grid : Grid
        The knots and Φ nodes.
    flat : ndarray, shape (ky, kx)
        Z knots of the flat seabed at the first returns (the start and the priors' reference).

    Attributes
    ----------
    objects : ndarray, shape (ky, kx)
        1 on the Z knots of objects found by their shadows (the fit's shadow start), else 0:
        the line-profile prior leaves them out of its line average, the relief prior off them.
    shadowed : ndarray, shape (ky, kx)
        1 on the Z knots of the ground in those objects' shadows: held near the flat seabed.
    """

    def __init__(self, views: Sequence[View], grid: Grid, flat: np.ndarray) -> None:
        self.views = list(views)
        self.grid = grid
        self.flat = flat
        ky, kx = (len(k) for k in grid.knots("z"))
        self.kz = (ky, kx)
        self._line_operators: list[tuple] | None = None
        self._line_subspace: tuple[np.ndarray, np.ndarray] | None = None
        self._line_prior: dict[str, tuple[float, float]] = {}
        self.objects = np.zeros(self.kz)
        self.shadowed = np.zeros(self.kz)
        ry, rx = (len(k) for k in grid.knots("r"))
        self.kr = (ry, rx)
        self.nz = self.kz[0] * self.kz[1]
        self.nr = self.kr[0] * self.kr[1]
        self.size = self.nz + self.nr + grid.nodes * len(grid.sides)
        pixels = sum(float(np.sum(v.mask)) for v in self.views)
        mean_looks = float(np.mean([v.looks for v in self.views]))
        per_knot = mean_looks * pixels / max(self._seen_knots(), 1)
        self.per_knot = per_knot
        self.w_z = per_knot / (2.0 * CURVATURE_STD**2)
        self.w_z_along = per_knot / (2.0 * CURVATURE_STD_ALONG**2)
        self.w_r = REFLECTIVITY_WEIGHT * mean_looks * pixels / max(self.nr, 1)
        self.w_phi = BEAM_WEIGHT * mean_looks * pixels / max(grid.nodes * len(grid.sides), 1)
        self.w_gauge = mean_looks * pixels * 1e-3
        self.w_line = LINE_PROFILE_WEIGHT * per_knot / self.views[0].geom.range_bin ** 2
        #: The objective's natural size (L per used bin), by which the minimiser divides it.
        self.norm = max(mean_looks * pixels, 1.0)
        #: One view per line carries its first-return anchor.
        self.anchored: dict[int, int] = {}
        for i, v in enumerate(self.views):
            self.anchored.setdefault(v.line, i)
        #: Per line, how far the first return reads above the seabed's level, metres (its
        #: crests, as far as the data confirm them: ``solve._track_model``; 0 until measured),
        #: taken off the tracked altitude by the anchor.
        self.anchor_offset: dict[int, float] = dict.fromkeys(self.anchored, 0.0)
        #: Per side, a calibrated log Φ at each node and where it holds (1) or not (0): the
        #: beam's shape is held there, its level left free (empty: Φ free).
        self.beam_reference: dict[str, tuple[np.ndarray, np.ndarray]] = {}

    @property
    def objects(self) -> np.ndarray:
        """The knots of objects found by their shadows (see the class's attributes)."""
        return self._objects

    @objects.setter
    def objects(self, value: np.ndarray) -> None:
        self._objects = value
        self._line_operators = None  # the line profile's average leaves the objects out
        self._line_subspace = None

    @property
    def line_prior(self) -> dict[str, tuple[float, float]]:
        """Per side, the line-profile prior's weight factor and low-pass where they differ.

        ``(factor, scale)``, the low-pass a fraction of the altitude; ``(1,
        LINE_PROFILE_SCALE)`` where a side is absent (in the fit: the calibrated sides).
        """
        return self._line_prior

    @line_prior.setter
    def line_prior(self, value: dict[str, tuple[float, float]]) -> None:
        self._line_prior = dict(value)
        self._line_operators = None
        self._line_subspace = None

    def line_operators(self) -> list[tuple[sparse.csr_matrix, np.ndarray, float, float]]:
        """Per view, what :func:`line_profile` needs, made once per set of objects.

        ``(A, n, σ, w)``: ``A`` (cells × knots) the line's average over its pings of each
        cell's Z, the objects' cells left out (so the average of the deviation is ``A dev``,
        one small product instead of one the size of the image); ``n`` the pings' mean nadir
        row; ``σ`` the low-pass in cells; ``w`` the weight.
        """
        if self._line_operators is None:
            keep_all = self.objects.ravel()
            spacing = self.grid.z_spacing
            ops = []
            for view in self.views:
                pings, cells = view.shape
                if keep_all.any():
                    inside = np.asarray(view.bz @ keep_all).reshape(pings, cells)
                    keep = 1.0 - np.clip(inside, 0.0, 1.0)
                else:
                    keep = np.ones((pings, cells))
                count = np.maximum(keep.sum(axis=0), 1e-9)
                # row c of the sum over pings: column c of every ping, weighted by keep / count
                total = sparse.kron(np.ones((1, pings)), sparse.identity(cells), format="csr")
                weights = sparse.diags((keep / count[None, :]).ravel())
                average = (total @ weights @ view.bz).tocsr()
                nadir = np.asarray(view.nadir.sum(axis=0)).ravel() / pings
                factor, scale = self.line_prior.get(view.side, (1.0, LINE_PROFILE_SCALE))
                sigma = scale * float(np.nanmedian(view.altitude)) / view.geom.dx
                # per knot along the line and across it, as in data units elsewhere
                w = (
                    factor
                    * self.w_line
                    * (pings * view.geom.dy / spacing)
                    * (view.geom.dx / spacing)
                )
                ops.append((average, nadir, sigma, w))
            self._line_operators = ops
        return self._line_operators

    def line_subspace(self) -> tuple[np.ndarray, np.ndarray]:
        """The Z knots' directions the line-profile prior weighs most, and its Hessian on them.

        Returns ``(Q, H Q)``: ``Q`` (nz, k) orthonormal, ``H`` the prior's Hessian
        ``Σ 2w Bᵀ Gᵀ G B`` (``B`` a view's line average less its nadir, ``G`` the low-pass).
        ``Q`` spans ``Bᵀ v`` for the eigenvectors ``v`` of ``Gᵀ G`` with eigenvalues above
        :data:`LINE_SUBSPACE_GAIN` of the largest: a few per low-pass width across the swath
        (the along-track mean of the relief, per range), where ``H`` dwarfs the image's own
        curvature. ``H Q`` is :func:`line_profile`'s gradient at each column of ``Q``, all
        columns at once. Made once per set of objects, like :meth:`line_operators`.
        """
        if self._line_subspace is None:
            columns = []
            for average, nadir, sigma, _ in self.line_operators():
                cells = average.shape[0]
                low = ndimage.gaussian_filter1d(np.eye(cells), sigma, axis=0, mode="constant")
                gains, vectors = np.linalg.eigh(low.T @ low)
                strong = int(np.sum(gains > LINE_SUBSPACE_GAIN * gains.max()))
                v = vectors[:, cells - min(strong, LINE_SUBSPACE_MAX) :]  # gains ascending
                columns.append(np.asarray(average.T @ v) - np.outer(nadir, v.sum(axis=0)))
            q = np.linalg.qr(np.hstack(columns))[0] if columns else np.zeros((self.nz, 0))
            hq = np.zeros_like(q)
            for average, nadir, sigma, w in self.line_operators():
                bq = np.asarray(average @ q) - (nadir @ q)[None, :]
                gbq = ndimage.gaussian_filter1d(bq, sigma, axis=0, mode="constant")
                g = ndimage.gaussian_filter1d(2.0 * w * gbq, sigma, axis=0, mode="constant")
                hq += np.asarray(average.T @ g) - np.outer(nadir, g.sum(axis=0))
            self._line_subspace = (q, hq)
        return self._line_subspace

    def relief_weights(self) -> np.ndarray | None:
        """Per Z knot, the weight of ``(Z − flat)²`` in the priors, (ky, kx); None if none.

        ``RELIEF_STD`` everywhere but on objects found by their shadows; on the ground in
        their shadows (where the data say nothing of Z) ``SHADOW_GROUND_BINS``, as the shadow's
        height assumes a flat seabed there.
        """
        w = np.zeros(self.kz)
        if RELIEF_STD is not None:
            w += self.grid.z_spacing**2 / (2.0 * RELIEF_STD**2) * (1.0 - self.objects)
        if self.shadowed.any():
            std = SHADOW_GROUND_BINS * self.views[0].geom.range_bin
            w += self.per_knot / (2.0 * std**2) * self.shadowed
        return w if w.any() else None

    def _seen_knots(self) -> int:
        seen = np.zeros(self.nz, bool)
        for v in self.views:
            seen |= np.asarray(abs(v.bz).sum(axis=0)).ravel() > 0
        return int(seen.sum())

    def scales(self) -> np.ndarray:
        """Typical step of each parameter: a range bin for Z, 0.1 in log R and log Φ."""
        out = np.full(self.size, 0.1)
        out[: self.nz] = self.views[0].geom.range_bin
        return out

    # -- parameters -------------------------------------------------------------------------
    def split(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Z knots (ky, kx), log R knots and log Φ nodes per side from the parameter vector."""
        zc = p[: self.nz].reshape(self.kz)
        rc = p[self.nz : self.nz + self.nr].reshape(self.kr)
        start, n = self.nz + self.nr, self.grid.nodes
        lphi = {s: p[start + i * n : start + (i + 1) * n] for i, s in enumerate(self.grid.sides)}
        return zc, rc, lphi

    def phi_slice(self, side: str) -> slice:
        """Where the log Φ nodes of ``side`` sit in the parameter vector."""
        i, n = self.grid.sides.index(side), self.grid.nodes
        start = self.nz + self.nr + i * n
        return slice(start, start + n)

    def fields(self, p: np.ndarray, view: View) -> tuple[np.ndarray, np.ndarray, Beam]:
        """Z (relative to the transducer), R and the beam of one view, (pings, cells) each."""
        zc, rc, lphi = self.split(p)
        z = self.z_of(view, zc)
        r = np.exp(np.asarray(view.br @ rc.ravel()).reshape(view.shape))
        return z, r, self.beam(view, lphi[view.side], z)

    def z_of(self, view: View, zc: np.ndarray) -> np.ndarray:
        """The view's Z relative to its transducer from Z knots."""
        return np.asarray(view.bz @ zc.ravel()).reshape(view.shape) - view.height[:, None]

    def beam(self, view: View, lphi: np.ndarray, z: np.ndarray) -> Beam:
        """Φ per cell at its depression angle ``atan2(−Z, x)`` (linear in log Φ between nodes)."""
        lo, hi = self.grid.angles
        n = self.grid.nodes
        x = view.geom.x[None, :]
        theta = np.arctan2(-z, x)
        pos = (theta - lo) * ((n - 1) / (hi - lo))
        inside = (pos >= 0.0) & (pos <= n - 1)
        pos = np.clip(pos, 0.0, n - 1)
        index = np.minimum(pos.astype(np.int64), n - 2)
        w = pos - index
        low, high = lphi[index], lphi[index + 1]
        phi = np.exp(low + w * (high - low))
        # ∂Φ/∂Z = Φ ∂logΦ/∂θ ∂θ/∂Z, ∂θ/∂Z = −x / (x² + Z²); flat beyond the end nodes
        dtheta = np.where(inside, (high - low) * ((n - 1) / (hi - lo)), 0.0)
        return Beam(phi, index, w, phi * dtheta * (-x / (x * x + z * z)))

    def beam_gradient(self, beam: Beam, g_phi: np.ndarray) -> np.ndarray:
        """Gradient wrt the log Φ nodes from ``∂E/∂Φ`` per cell."""
        return _node_gradient(beam.index, beam.weight, g_phi * beam.phi, self.grid.nodes)

    # -- objective --------------------------------------------------------------------------
    def __call__(self, p: np.ndarray) -> tuple[float, np.ndarray]:
        """Objective and its gradient."""
        zc, rc, lphi = self.split(p)
        grad = np.zeros_like(p)
        g_z = grad[: self.nz]
        g_r = grad[self.nz : self.nz + self.nr]
        total = 0.0
        for view in self.views:
            z, r, beam = self.fields(p, view)
            value, gz, gr, gphi = view_objective(view, r, beam.phi, z)
            total += value
            g_z += view.bz.T @ (gz + gphi * beam.dz).ravel()
            g_r += view.br.T @ (gr * r).ravel()
            grad[self.phi_slice(view.side)] += self.beam_gradient(beam, gphi)
        total += self.z_priors(zc, grad) + self.reflectivity_beam_priors(rc, lphi, grad)
        return total, grad

    def held_z(self, p: np.ndarray) -> HeldZ:
        """The objective as a function of log R and log Φ alone, Z held at ``p``'s knots."""
        return HeldZ(self, p)

    def z_priors(self, zc: np.ndarray, grad: np.ndarray) -> float:
        """The priors on the Z knots; their gradient added to ``grad``'s Z part."""
        grid = self.grid
        g_zc = grad[: self.nz].reshape(self.kz)
        total = 0.0
        for axis, w in ((0, self.w_z_along), (1, self.w_z)):
            value, g = second_difference(zc, axis, grid.z_spacing, w)
            total += value
            g_zc += g
        relief = self.relief_weights()
        if relief is not None:
            d = zc - self.flat
            total += float(np.sum(relief * d * d))
            g_zc += 2.0 * relief * d
        if self.w_line > 0:
            value, g = line_profile(self, (zc - self.flat).ravel())
            total += value
            g_zc += g.reshape(self.kz)
        value, g = self._anchor(zc)
        total += value
        g_zc += g.reshape(self.kz)
        return total

    def reflectivity_beam_priors(
        self, rc: np.ndarray, lphi: Mapping[str, np.ndarray], grad: np.ndarray
    ) -> float:
        """The priors on log R and log Φ; their gradient added to ``grad``'s parts."""
        g_rc = grad[self.nz : self.nz + self.nr].reshape(self.kr)
        total = 0.0
        for axis in (0, 1):
            value, g = charbonnier(rc, axis, REFLECTIVITY_EDGE, self.w_r)
            total += value
            g_rc += g
        mean = float(np.mean(rc))
        total += self.w_gauge * mean * mean
        g_rc += 2.0 * self.w_gauge * mean / rc.size
        for side in self.grid.sides:
            value, g = second_difference(lphi[side], 0, 1.0, self.w_phi)
            total += value
            grad[self.phi_slice(side)] += g
        w = 1.0 / (2.0 * CALIBRATED_BEAM_STD**2)
        for side, (target, held) in self.beam_reference.items():
            d = lphi[side] - target
            res = held * (d - float(np.sum(held * d)) / max(float(np.sum(held)), 1.0))
            total += w * float(np.sum(res * res))
            grad[self.phi_slice(side)] += 2.0 * w * res
        return total

    def beam_prior_hessian(self) -> np.ndarray:
        """Hessian of the priors on the log Φ nodes (all sides), dense."""
        n = self.grid.nodes
        out = np.zeros((n * len(self.grid.sides),) * 2)
        d2 = np.diff(np.eye(n), 2, axis=0)
        for i, side in enumerate(self.grid.sides):
            block = 2.0 * self.w_phi * d2.T @ d2
            if side in self.beam_reference:
                held = self.beam_reference[side][1]
                centre = np.diag(held) @ (
                    np.eye(n) - np.outer(np.ones(n), held) / max(held.sum(), 1.0)
                )
                block += (1.0 / CALIBRATED_BEAM_STD**2) * centre.T @ centre
            out[i * n : (i + 1) * n, i * n : (i + 1) * n] = block
        return out

    def anchor_std(self, view: View) -> float:
        """Standard deviation of the first-return altitude per ping, metres."""
        return ANCHOR_BINS * view.anchor_bin / math.sqrt(max(view.anchor_looks, 1.0))

    def _anchor(self, zc: np.ndarray) -> tuple[float, np.ndarray]:
        """Each line's nadir at its first-return altitude (less its crests) below the transducer."""
        total, grad = 0.0, np.zeros(self.nz)
        for line, i in self.anchored.items():
            view = self.views[i]
            known = np.isfinite(view.altitude)
            zn = np.asarray(view.nadir @ zc.ravel()) - view.height
            target = np.nan_to_num(view.altitude) - self.anchor_offset[line]
            res = np.where(known, zn + target, 0.0)
            w = 1.0 / (2.0 * self.anchor_std(view) ** 2)
            total += w * float(np.sum(res * res))
            grad += view.nadir.T @ (2.0 * w * res)
        return total, grad


class HeldZ:
    """A problem's objective over log R and log Φ with its Z knots held: the same numbers.

    It serves the Gauss-Newton steps' inner minimisation, and is faster than the problem's.
    With Z held, each view's model image is linear in ``a = R Φ`` per cell: ``μ = A a +
    floor`` with ``A`` the deposit (:func:`..model.deposit_matrix`) times each cell's ``q``
    and cast-shadow factor, made once; Φ's nodes and weights per cell are fixed too. An
    evaluation is then two sparse products per view, without the geometry, the shadows or
    the priors on Z (a constant, added to the value). Called with a full parameter vector
    whose Z part equals the held one; the gradient's Z part is zero.
    """

    def __init__(self, problem: Problem, p: np.ndarray) -> None:
        self.problem = problem
        zc, _, lphi = problem.split(p)

        def one(view: View) -> tuple:
            z = problem.z_of(view, zc)
            beam = problem.beam(view, lphi[view.side], z)
            shade = soft_shadow(z, view.geom.x, view.tau)[0]
            deposit, q = deposit_matrix(z, view.geom)
            scale = (q * shade).ravel() * (view.geom.dx / view.geom.range_bin)
            a = (deposit @ sparse.diags(scale)).tocsr()
            return view, a, a.T.tocsr(), beam.index, beam.weight

        self.parts = each(one, problem.views)
        self.constant = problem.z_priors(zc, np.zeros(problem.size))

    def __call__(self, p: np.ndarray) -> tuple[float, np.ndarray]:
        """Objective and its gradient (zero wrt Z) at ``p``, whose Z must be the held Z."""
        problem = self.problem
        _, rc, lphi = problem.split(p)
        n = problem.grid.nodes

        def one(part: tuple) -> tuple[float, np.ndarray, np.ndarray]:
            view, a, a_t, index, w = part
            side = lphi[view.side]
            low = side[index]
            energy = np.exp(low + w * (side[index + 1] - low))  # Φ, as Problem.beam
            energy *= np.exp(np.asarray(view.br @ rc.ravel()).reshape(view.shape))  # R Φ
            mu = np.asarray(a @ energy.ravel()).reshape(view.image.shape) + view.floor
            ratio = view.image / mu
            value = view.looks * float(np.sum(np.where(view.mask, ratio + np.log(mu), 0.0)))
            g_mu = np.where(view.mask, view.looks * (1.0 - ratio) / mu, 0.0)
            # ∂E/∂log R = ∂E/∂log Φ = ∂E/∂a · a per cell
            g = np.asarray(a_t @ g_mu.ravel()).reshape(view.shape) * energy
            return value, view.br.T @ g.ravel(), _node_gradient(index, w, g, n)

        grad = np.zeros_like(p)
        total = self.constant
        for part, (value, g_r, g_phi) in zip(self.parts, each(one, self.parts), strict=True):
            total += value
            grad[problem.nz : problem.nz + problem.nr] += g_r
            grad[problem.phi_slice(part[0].side)] += g_phi
        total += problem.reflectivity_beam_priors(rc, lphi, grad)
        return total, grad


def _node_gradient(index: np.ndarray, weight: np.ndarray, g: np.ndarray, nodes: int) -> np.ndarray:
    """Gradient wrt the log Φ nodes from ``∂E/∂log Φ`` per cell (linear between nodes)."""
    flat = index.ravel()
    return np.bincount(flat, ((1.0 - weight) * g).ravel(), nodes) + np.bincount(
        flat + 1, (weight * g).ravel(), nodes
    )


def view_objective(
    view: View, r: np.ndarray, phi: np.ndarray, z: np.ndarray
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """Gamma negative log-likelihood of one view and its gradients wrt per-cell Z, R and Φ.

    Returns ``(value, ∂/∂Z, ∂/∂R, ∂/∂Φ)`` (Φ held for ∂/∂Z), each (pings, cells);
    ``value = L Σ_mask (I/μ + log μ)``, μ the model plus the noise floor.
    """
    geom = view.geom
    shade, occluder, slope_ = soft_shadow(z, geom.x, view.tau)
    mu = forward(r * shade, phi, z, geom) + view.floor
    ratio = view.image / mu
    value = view.looks * float(np.sum(np.where(view.mask, ratio + np.log(mu), 0.0)))
    g_mu = np.where(view.mask, view.looks * (1.0 - ratio) / mu, 0.0)
    g_reff, g_phi, g_z = adjoint(g_mu, r * shade, phi, z, geom)
    g_z = g_z + shadow_adjoint(g_reff * r, occluder, slope_, geom.x)
    return value, g_z, g_reff * shade, g_phi


def soft_shadow(
    z: np.ndarray, x: np.ndarray, tau: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cast-shadow factor per cell, the occluding cell and ``∂S/∂(Z/x)``.

    ``S = exp(min(0, (Z/x − M)/τ))`` with ``M`` the largest ``Z/x`` among the nearer cells of
    the ping (the cell that sets it is the occluder). 1 where nothing nearer rises above the
    line of sight.

    Parameters
    ----------
    z : ndarray, shape (pings, cells)
        Elevation relative to the transducer.
    x : ndarray, shape (cells,)
        Ground ranges, increasing.
    tau : ndarray, shape (cells,)
        Softness in ``Z/x`` units.

    Returns
    -------
    shade : ndarray, shape (pings, cells)
    occluder : ndarray, shape (pings, cells), int64
        Column of the occluding cell (0 where unshadowed).
    slope : ndarray, shape (pings, cells)
        ``∂S/∂(Z_j/x_j)`` (0 where unshadowed); ``∂S/∂(Z_m/x_m) = −slope`` for the occluder.
    """
    v = z / x[None, :]
    top = np.maximum.accumulate(v, axis=1)
    cols = np.broadcast_to(np.arange(v.shape[1]), v.shape)
    where = np.maximum.accumulate(np.where(v >= top, cols, 0), axis=1)
    horizon = np.full_like(v, -np.inf)
    horizon[:, 1:] = top[:, :-1]
    occluder = np.zeros(v.shape, np.int64)
    occluder[:, 1:] = where[:, :-1]
    u = np.minimum((v - horizon) / tau[None, :], 0.0)
    shade = np.exp(u)
    slope_ = np.where(u < 0.0, shade / tau[None, :], 0.0)
    return shade, occluder, slope_


def shadow_adjoint(
    g_shade: np.ndarray, occluder: np.ndarray, slope_: np.ndarray, x: np.ndarray
) -> np.ndarray:
    """``∂E/∂Z`` through the shadow factor, given ``∂E/∂S`` and :func:`soft_shadow`'s terms.

    Each shadowed cell's term ``g slope / x_j`` on itself and ``−g slope / x_m`` on its
    occluder m, shape (pings, cells).
    """
    g = g_shade * slope_
    pings, cells = g.shape
    flat = (np.arange(pings)[:, None] * cells + occluder).ravel()
    back = np.bincount(flat, g.ravel(), pings * cells).reshape(pings, cells)
    return (g - back) / x[None, :]


def shade_jacobian(occluder: np.ndarray, slope: np.ndarray, x: np.ndarray) -> sparse.csr_matrix:
    """``∂S/∂Z`` per cell, (pings·cells) × (pings·cells), from :func:`soft_shadow`'s terms.

    A shadowed cell j (``slope`` > 0) of occluder m: ``slope / x_j`` on its own Z and
    ``−slope / x_m`` on the occluder's; :func:`shadow_adjoint` is its transpose applied to
    ``∂E/∂S``, without forming it.
    """
    pings, cells = slope.shape
    j = np.flatnonzero(slope)
    m = (j // cells) * cells + occluder.ravel()[j]
    s = slope.ravel()[j]
    vals = np.concatenate([s / x[j % cells], -s / x[m % cells]])
    shape = (pings * cells, pings * cells)
    return sparse.csr_matrix((vals, (np.concatenate([j, j]), np.concatenate([j, m]))), shape)


def second_difference(
    values: np.ndarray, axis: int, step: float, weight: float
) -> tuple[float, np.ndarray]:
    """``weight Σ (Δ² v / step²)²`` along ``axis`` and its gradient."""
    v = np.moveaxis(values, axis, 0)
    grad = np.zeros_like(v)
    if v.shape[0] < 3:
        return 0.0, np.moveaxis(grad, 0, axis)
    d = (v[2:] - 2.0 * v[1:-1] + v[:-2]) / step**2
    g = 2.0 * weight * d / step**2
    grad[2:] += g
    grad[1:-1] -= 2.0 * g
    grad[:-2] += g
    return weight * float(np.sum(d * d)), np.moveaxis(grad, 0, axis)


def charbonnier(
    values: np.ndarray, axis: int, edge: float, weight: float
) -> tuple[float, np.ndarray]:
    """``weight Σ 2ε (sqrt(Δv² + ε²) − ε)`` along ``axis`` and its gradient."""
    v = np.moveaxis(values, axis, 0)
    grad = np.zeros_like(v)
    if v.shape[0] < 2:
        return 0.0, np.moveaxis(grad, 0, axis)
    d = v[1:] - v[:-1]
    s = np.sqrt(d * d + edge * edge)
    g = weight * 2.0 * edge * d / s
    grad[1:] += g
    grad[:-1] -= g
    return weight * 2.0 * edge * float(np.sum(s - edge)), np.moveaxis(grad, 0, axis)


def line_profile(problem: Problem, dev: np.ndarray) -> tuple[float, np.ndarray]:
    """The line-profile prior on the Z knots' deviation ``dev`` (nz,) from the flat seabed.

    Φ, shared along a line, absorbs any bend of Z that every ping of the line shares, so the
    image cannot fix it: per view, the across-track profile of the deviation averaged over the
    line's pings, taken relative to the line's nadir (whose level the first return fixes) and
    low-passed (a smooth Φ absorbs only a broad bend), is held at zero. Cells on
    ``problem.objects`` are left out of the average (an object raises its own pings, not the
    line's bend; averaged in, it pulls every other ping at its range down, most where nothing
    else holds them: in its shadow). Quadratic in ``dev``, so its gradient at ``v`` is also its
    Hessian times ``v``. Returns the value and the gradient (nz,).
    """
    value, grad = 0.0, np.zeros(problem.nz)
    for average, nadir, sigma, w in problem.line_operators():
        m = np.asarray(average @ dev) - float(nadir @ dev)
        low = ndimage.gaussian_filter1d(m, sigma, mode="constant")
        value += w * float(np.sum(low * low))
        g_m = ndimage.gaussian_filter1d(2.0 * w * low, sigma, mode="constant")
        grad += average.T @ g_m
        grad -= nadir * float(np.sum(g_m))
    return value, grad


def line_profile_reference(problem: Problem, dev: np.ndarray) -> tuple[float, np.ndarray]:
    """:func:`line_profile` from its definition: each view's Z deviation, ping by ping.

    The same numbers (to rounding) at the cost of three products the size of the image per
    view and call; kept as the fit's check (tests) and its speed baseline
    (``tools/bench_surface_solver.py``).
    """
    value, grad = 0.0, np.zeros(problem.nz)
    objects = problem.objects.ravel()
    spacing = problem.grid.z_spacing
    for view in problem.views:
        pings, cells = view.shape
        d = np.asarray(view.bz @ dev).reshape(pings, cells)
        keep = 1.0 - np.clip(np.asarray(view.bz @ objects).reshape(pings, cells), 0.0, 1.0)
        count = np.maximum(keep.sum(axis=0), 1e-9)
        m = (keep * d).sum(axis=0) / count - float(np.mean(view.nadir @ dev))
        factor, scale = problem.line_prior.get(view.side, (1.0, LINE_PROFILE_SCALE))
        sigma = scale * float(np.nanmedian(view.altitude)) / view.geom.dx
        low = ndimage.gaussian_filter1d(m, sigma, mode="constant")
        w = factor * problem.w_line * (pings * view.geom.dy / spacing) * (view.geom.dx / spacing)
        value += w * float(np.sum(low * low))
        g_m = ndimage.gaussian_filter1d(2.0 * w * low, sigma, mode="constant")
        grad += view.bz.T @ (keep * (g_m / count)[None, :]).ravel()
        grad -= view.nadir.T @ np.full(pings, float(np.sum(g_m)) / pings)
    return value, grad


def flat_start_knots(views: Sequence[View], grid: Grid, kz: tuple[int, int]) -> np.ndarray:
    """Z knots of a seabed flat across the lines at each line's first-return level.

    Least squares of the knots to the nadir levels (transducer height minus altitude) with a
    strong first-difference penalty across track, a weak second difference along it and a
    small ridge (:data:`FLAT_START_DAMP`), solved directly by its normal equations' sparse
    factors (an iterative lsqr needed 1 000-2 000 iterations for the same knots).
    """
    from scipy.sparse import diags, identity, kron, vstack
    from scipy.sparse.linalg import splu

    ky, kx = kz
    rows, rhs = [], []
    for v in views:
        known = np.isfinite(v.altitude)
        rows.append(v.nadir[known])
        rhs.append((v.height - v.altitude)[known])
    a = vstack(rows)
    b = np.concatenate(rhs)
    level = float(np.median(b))
    scale = math.sqrt(max(a.shape[0], 1) / max(ky * kx, 1))
    blocks = [a]
    if kx >= 2:
        d1 = diags([-1.0, 1.0], [0, 1], shape=(kx - 1, kx))
        blocks.append(10.0 * scale * kron(identity(ky), d1))
    if ky >= 3:
        d2 = diags([1.0, -2.0, 1.0], [0, 1, 2], shape=(ky - 2, ky))
        blocks.append(0.1 * scale * kron(d2, identity(kx)))
    system = vstack(blocks).tocsr()
    normal = (system.T @ system + FLAT_START_DAMP**2 * identity(ky * kx)).tocsc()
    coef = splu(normal, **SYMMETRIC_LU).solve(np.asarray(a.T @ (b - level)).ravel()) + level
    return coef.reshape(kz)
