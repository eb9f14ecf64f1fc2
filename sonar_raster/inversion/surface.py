"""One seabed surface fitted to every ping of a line: both sides, shadows, a speckle likelihood.

The per-ping solver (:mod:`.em`) gives each ping its own elevation profile, so each profile is
fitted from its own speckle (one datum per cell for two unknowns). Here the unknowns are shared
by many pings and bins instead:

* ``Z`` is one smooth surface, a tensor cubic B-spline over (across-track X, along-track y) with
  knots a few resolution cells apart, X signed (starboard positive), so both sides and the
  nadir share it;
* ``log R`` is a tensor B-spline too, with an edge-preserving (Charbonnier) roughness: a jump
  between two sediments costs in proportion to its size, so it stays in R, while a ripple's
  repeated shading costs R far more than it costs Z;
* ``log Φ`` is a profile over nominal depression angle per side, shared along the line;
* the first bottom return anchors Z at nadir (a Gaussian of the tracker's error).

The image model is :mod:`.model`'s (each ground cell's Lambertian return at its own slant
range, so foreshortening and layover are modelled) times a soft cast-shadow factor
``S = exp(min(0, (Z/x − M) / τ))``, with ``M`` the largest ``Z/x`` of the nearer cells of
the ping (the horizon) and ``τ`` one cell's angle on the flat seabed, plus the noise floor of
the image. Its fit to the data is the L-look Gamma likelihood of speckle,
``L Σ (I/μ + log μ)``; its gradient is exact (checked against central differences in
``tests/inversion/test_surface.py``). Gauss-Newton steps on the Z knots alternate with L-BFGS
on R and Φ, coarse to fine (:func:`_gauss_newton`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING

import numpy as np
from scipy import ndimage, optimize, sparse
from scipy.interpolate import BSpline

from ..errors import SonarRasterError
from .model import Geometry, adjoint, forward

if TYPE_CHECKING:
    from .solver import Inversion

#: Knot spacing of Z and of log R in resolution cells (range bins) when not given.
Z_KNOT_BINS = 4.0
R_KNOT_BINS = 4.0
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
#: Standard deviation of the first-return altitude, in range bins.
ANCHOR_BINS = 4.0
#: Standard deviation of the relief about the flat seabed at the first return assumed on the
#: scale of the swath, metres (None: no such prior). The image hardly fixes a broad bending
#: of Z that the beam profile can absorb.
RELIEF_STD: float | None = 0.3
#: Weight of the prior holding the line-averaged across-track profile of Z at the first
#: return's flat seabed: a mean deviation of one range bin costs this many nats per knot
#: and look (0: no such prior).
LINE_PROFILE_WEIGHT = 1.0
#: Across-track scale of that prior's low-pass, as a fraction of the altitude.
LINE_PROFILE_SCALE = 0.25
#: Points per ground cell in the model (sonar_raster.inversion.model).
SUBSAMPLES = 2
#: Largest number of looks the likelihood trusts (the model's own error on clean images).
MAX_LOOKS = 30.0
#: Gauss-Newton steps on the Z knots per level (each followed by L-BFGS on R and Φ); 0: plain
#: L-BFGS on everything.
GAUSS_NEWTON_STEPS = 8
#: A restart of L-BFGS after its line search failed must lower E by this much (E is divided by
#: looks × bins, so per bin) for another restart.
RESTART_GAIN = 1e-6
#: Ground cells whose slant range at the altitude lies within this many bins of the image's
#: end get no estimate (NaN) in the per-side results.
EDGE_BINS = 6
#: Depression-angle nodes of log Φ, per degree.
BEAM_NODES_PER_DEGREE = 1.0


def bspline_basis(
    points: np.ndarray, start: float, stop: float, spacing: float
) -> sparse.csr_matrix:
    """Cubic B-spline basis with uniform knots ``spacing`` apart covering ``[start, stop]``.

    Parameters
    ----------
    points : ndarray, shape (n,)
        Where the basis is evaluated (clipped to the covered interval).
    start, stop : float
        Interval the basis must cover.
    spacing : float
        Knot spacing, > 0.

    Returns
    -------
    scipy.sparse.csr_matrix, shape (n, knots)
        Row i holds the weights of the coefficients at ``points[i]`` (they sum to 1).
    """
    degree = 3
    spans = max(1, int(math.ceil((stop - start) / spacing - 1e-9)))
    t = start + spacing * np.arange(-degree, spans + degree + 1, dtype=np.float64)
    pts = np.clip(np.asarray(points, np.float64), t[degree], t[spans + degree])
    return BSpline.design_matrix(pts, t, degree).tocsr()


def knot_centres(start: float, stop: float, spacing: float) -> np.ndarray:
    """Where each basis function of :func:`bspline_basis` peaks (its Greville abscissa).

    Parameters
    ----------
    start, stop, spacing : float
        As for :func:`bspline_basis`.

    Returns
    -------
    ndarray, shape (knots,)
    """
    spans = max(1, int(math.ceil((stop - start) / spacing - 1e-9)))
    return start + spacing * (np.arange(spans + 3) - 1.0)


@dataclass(frozen=True)
class SideData:
    """One side of a line, resampled for the fit.

    Attributes
    ----------
    image : ndarray, shape (pings, bins)
        Intensity per metre of slant range.
    mask : ndarray, shape (pings, bins), bool
        Bins the likelihood uses.
    floor : float
        Noise floor added to the model, same units as ``image``.
    """

    image: np.ndarray
    mask: np.ndarray
    floor: float


@dataclass
class _Layout:
    """Bases of the unknowns on the fine grid of one level."""

    geom: Geometry
    by: sparse.csr_matrix  # (pings, ky) Z along track
    bx: dict[str, sparse.csr_matrix]  # side -> (cells, kx) Z across track
    bry: sparse.csr_matrix
    brx: dict[str, sparse.csr_matrix]
    nadir: sparse.csr_matrix  # (1, kx) Z at X = 0
    phi_index: np.ndarray  # (pings, cells) lower Φ node
    phi_weight: np.ndarray  # (pings, cells) weight of the upper node
    phi_nodes: int
    tau: np.ndarray  # (cells,) shadow softness
    altitude: np.ndarray  # (pings,)
    z_spacing: tuple[float, float]  # (along, across) knot spacing, m
    r_spacing: tuple[float, float]
    extent: tuple[float, float, float, float]  # y0, y1, X0, X1 covered by the bases


@dataclass
class SurfaceFit:
    """Result of :func:`fit_surface`; maps are (pings, ground cells) per side.

    Attributes
    ----------
    x : ndarray, shape (cells,)
        Ground-range cell centres, metres (on each side).
    elevation, reflectivity, beam : dict of str to ndarray
        Z (metres relative to the transducer), R and Φ per side.
    elevation_std : dict of str to ndarray
        Standard deviation of Z per cell, metres (Laplace approximation; see
        :func:`elevation_std`); empty without ``uncertainty``.
    profile : dict of str to (ndarray, ndarray)
        Per side, depression angles (radians) and Φ there.
    looks : dict of str to float
        Looks used by the likelihood per side.
    altitude : ndarray, shape (pings,)
        First-return (or given) altitude per ping, metres.
    energies : list of float
        Objective after each level.
    evaluations : list of int
        Objective evaluations per level.
    """

    x: np.ndarray
    elevation: dict[str, np.ndarray]
    reflectivity: dict[str, np.ndarray]
    beam: dict[str, np.ndarray]
    elevation_std: dict[str, np.ndarray]
    profile: dict[str, tuple[np.ndarray, np.ndarray]]
    looks: dict[str, float]
    altitude: np.ndarray = field(default_factory=lambda: np.zeros(0))
    energies: list[float] = field(default_factory=list)
    evaluations: list[int] = field(default_factory=list)


class Problem:
    """The objective of one level: likelihood of every side plus the priors, and its gradient.

    Parameters
    ----------
    sides : mapping of str to SideData
        The data per side.
    layout : _Layout
        The bases.
    looks : mapping of str to float
        Looks per side.
    anchor : ndarray, shape (pings,)
        First-return altitude per ping (NaN: none).
    anchor_std : float
        Its standard deviation, metres.
    """

    def __init__(
        self,
        sides: Mapping[str, SideData],
        layout: _Layout,
        looks: Mapping[str, float],
        anchor: np.ndarray,
        anchor_std: float,
    ) -> None:
        self.sides = dict(sides)
        self.layout = layout
        self.looks = dict(looks)
        self.anchor = anchor
        self.anchor_std = anchor_std
        #: Z knots of the flat seabed at the first return (set by the start).
        self.flat: np.ndarray | None = None
        lay = layout
        self.kz = (lay.by.shape[1], lay.nadir.shape[1])
        self.kr = (lay.bry.shape[1], next(iter(lay.brx.values())).shape[1])
        self.nz = self.kz[0] * self.kz[1]
        self.nr = self.kr[0] * self.kr[1]
        self.size = self.nz + self.nr + lay.phi_nodes * len(self.sides)
        pixels = sum(float(np.sum(s.mask)) for s in self.sides.values())
        mean_looks = float(np.mean(list(self.looks.values())))
        per_knot = mean_looks * pixels / max(self.nz, 1)
        # in data units: a curvature of CURVATURE_STD costs one nat per knot and look
        self.w_z = per_knot / (2.0 * CURVATURE_STD**2)
        self.w_z_along = per_knot / (2.0 * CURVATURE_STD_ALONG**2)
        self.w_r = REFLECTIVITY_WEIGHT * mean_looks * pixels / max(self.nr, 1)
        self.w_phi = BEAM_WEIGHT * mean_looks * pixels / max(lay.phi_nodes * len(self.sides), 1)
        self.w_gauge = mean_looks * pixels * 1e-3
        self.w_line = LINE_PROFILE_WEIGHT * per_knot / layout.geom.range_bin**2
        #: The objective's natural size (L per used bin), by which the minimiser divides it.
        self.norm = max(mean_looks * pixels, 1.0)

    # -- the minimiser's variables: Z knots as steps outward from the nadir knot -----------
    # The shading fixes slopes, so knots as the differences of neighbours outward from nadir
    # (and the nadir knot itself, which the first return fixes) are far better conditioned
    # than heights: one variable per slope instead of a height that integrates all of them.
    def _nadir_knot(self) -> int:
        return int(np.argmax(self.layout.nadir.toarray().ravel()))

    def to_steps(self, p: np.ndarray) -> np.ndarray:
        """Parameters with Z knots replaced by their steps outward from the nadir knot."""
        out = p.copy()
        z = p[: self.nz].reshape(self.kz)
        u = out[: self.nz].reshape(self.kz)
        c = self._nadir_knot()
        u[:, c + 1 :] = np.diff(z[:, c:], axis=1)
        u[:, :c] = -np.diff(z[:, : c + 1], axis=1)
        return out

    def from_steps(self, q: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`to_steps`."""
        out = q.copy()
        u = q[: self.nz].reshape(self.kz)
        z = out[: self.nz].reshape(self.kz)
        c = self._nadir_knot()
        z[:, c:] = np.cumsum(u[:, c:], axis=1)
        z[:, :c] = u[:, c : c + 1] + np.cumsum(u[:, :c][:, ::-1], axis=1)[:, ::-1]
        return out

    def steps_gradient(self, g: np.ndarray) -> np.ndarray:
        """Gradient wrt the variables of :meth:`to_steps` from the gradient wrt parameters."""
        out = g.copy()
        gz = g[: self.nz].reshape(self.kz)
        gu = out[: self.nz].reshape(self.kz)
        c = self._nadir_knot()
        right = np.cumsum(gz[:, c:][:, ::-1], axis=1)[:, ::-1]  # Σ_{k >= j}
        left = np.cumsum(gz[:, :c], axis=1)  # Σ_{k <= j}
        gu[:, c:] = right
        gu[:, :c] = left
        gu[:, c] += left[:, -1] if c > 0 else 0.0
        return out

    def scales(self) -> np.ndarray:
        """Typical step of each parameter: a range bin for Z, 0.1 in log R and log Φ."""
        out = np.full(self.size, 0.1)
        out[: self.nz] = self.layout.geom.range_bin
        return out

    # -- parameters -------------------------------------------------------------------------
    def split(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Z knots (ky, kx), log R knots and log Φ nodes per side from the parameter vector."""
        zc = p[: self.nz].reshape(self.kz)
        rc = p[self.nz : self.nz + self.nr].reshape(self.kr)
        start, n = self.nz + self.nr, self.layout.phi_nodes
        lphi = {s: p[start + i * n : start + (i + 1) * n] for i, s in enumerate(self.sides)}
        return zc, rc, lphi

    def fields(self, p: np.ndarray, side: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Z, R and Φ of one side on the fine grid, (pings, cells) each."""
        zc, rc, lphi = self.split(p)
        lay = self.layout
        z = np.asarray((lay.bx[side] @ (lay.by @ zc).T).T)
        r = np.exp(np.asarray((lay.brx[side] @ (lay.bry @ rc).T).T))
        return z, r, self._phi(lphi[side])

    def knot_grid(self, which: str) -> tuple[np.ndarray, np.ndarray]:
        """Centres (y, X) of the Z (``"z"``) or log R (``"r"``) basis functions."""
        lay = self.layout
        y0, y1, x0, x1 = lay.extent
        spacing = lay.z_spacing if which == "z" else lay.r_spacing
        return knot_centres(y0, y1, spacing[0]), knot_centres(x0, x1, spacing[1])

    def surface_at(
        self, coefs: np.ndarray, points: tuple[np.ndarray, np.ndarray], which: str
    ) -> np.ndarray:
        """The Z or log R spline with coefficients ``coefs`` on the grid ``points`` (y, X)."""
        lay = self.layout
        y0, y1, x0, x1 = lay.extent
        spacing = lay.z_spacing if which == "z" else lay.r_spacing
        by = bspline_basis(points[0], y0, y1, spacing[0])
        bx = bspline_basis(points[1], x0, x1, spacing[1])
        return np.asarray((bx @ (by @ coefs).T).T)

    def _phi(self, lphi: np.ndarray) -> np.ndarray:
        lay = self.layout
        w = lay.phi_weight
        return np.exp((1.0 - w) * lphi[lay.phi_index] + w * lphi[lay.phi_index + 1])

    # -- objective --------------------------------------------------------------------------
    def __call__(self, p: np.ndarray) -> tuple[float, np.ndarray]:
        """Objective and its gradient."""
        zc, rc, lphi = self.split(p)
        lay = self.layout
        grad = np.zeros_like(p)
        g_zc = grad[: self.nz].reshape(self.kz)
        g_rc = grad[self.nz : self.nz + self.nr].reshape(self.kr)
        total = 0.0
        by_z = lay.by @ zc
        by_r = lay.bry @ rc
        for i, (name, data) in enumerate(self.sides.items()):
            z = np.asarray((lay.bx[name] @ by_z.T).T)
            r = np.exp(np.asarray((lay.brx[name] @ by_r.T).T))
            phi = self._phi(lphi[name])
            value, g_z, g_r, g_phi = side_objective(data, self.looks[name], r, phi, z, lay)
            total += value
            g_zc += lay.by.T @ np.asarray((lay.bx[name].T @ g_z.T).T)
            g_rc += lay.bry.T @ np.asarray((lay.brx[name].T @ (g_r * r).T).T)
            g_lphi = g_phi * phi
            w = lay.phi_weight
            n = lay.phi_nodes
            start = self.nz + self.nr + i * n
            grad[start : start + n] += np.bincount(
                lay.phi_index.ravel(), ((1.0 - w) * g_lphi).ravel(), n
            ) + np.bincount(lay.phi_index.ravel() + 1, (w * g_lphi).ravel(), n)
        total += self._priors(zc, rc, lphi, grad)
        return total, grad

    def _priors(
        self, zc: np.ndarray, rc: np.ndarray, lphi: Mapping[str, np.ndarray], grad: np.ndarray
    ) -> float:
        lay = self.layout
        g_zc = grad[: self.nz].reshape(self.kz)
        g_rc = grad[self.nz : self.nz + self.nr].reshape(self.kr)
        total = 0.0
        # curvature of Z along and across track
        for axis, step, w in (
            (0, lay.z_spacing[0], self.w_z_along),
            (1, lay.z_spacing[1], self.w_z),
        ):
            value, g = _second_difference(zc, axis, step, w)
            total += value
            g_zc += g
        # broad relief about the flat seabed at the first return
        if RELIEF_STD is not None and self.flat is not None:
            w = self.layout.z_spacing[0] * self.layout.z_spacing[1] / (2.0 * RELIEF_STD**2)
            d = zc - self.flat
            total += w * float(np.sum(d * d))
            g_zc += 2.0 * w * d
        # the line-averaged across-track profile is held at the flat seabed (_line_profile)
        if self.flat is not None and self.w_line > 0:
            value, g = _line_profile(self, zc - self.flat)
            total += value
            g_zc += g
        # first-return anchor at nadir
        known = np.isfinite(self.anchor)
        if known.any():
            zn = np.asarray(lay.by @ (zc @ lay.nadir.T.toarray())).ravel()
            res = np.where(known, zn + np.nan_to_num(self.anchor), 0.0)
            w = 1.0 / (2.0 * self.anchor_std**2)
            total += w * float(np.sum(res * res))
            g_zc += np.outer(lay.by.T @ (2.0 * w * res), lay.nadir.toarray().ravel())
        # edge-preserving roughness of log R, and its gauge (mean log R = 0)
        for axis in (0, 1):
            value, g = _charbonnier(rc, axis, REFLECTIVITY_EDGE, self.w_r)
            total += value
            g_rc += g
        mean = float(np.mean(rc))
        total += self.w_gauge * mean * mean
        g_rc += 2.0 * self.w_gauge * mean / rc.size
        # curvature of log Φ against angle
        n = lay.phi_nodes
        for i, name in enumerate(self.sides):
            value, g = _second_difference(lphi[name], 0, 1.0, self.w_phi)
            total += value
            start = self.nz + self.nr + i * n
            grad[start : start + n] += g
        return total


def side_objective(
    data: SideData, looks: float, r: np.ndarray, phi: np.ndarray, z: np.ndarray, lay: _Layout
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """Gamma negative log-likelihood of one side and its gradients wrt per-cell Z, R and Φ.

    Parameters
    ----------
    data : SideData
        Image, mask and noise floor.
    looks : float
        Speckle looks L.
    r, phi, z : ndarray, shape (pings, cells)
        Reflectivity, beam gain and elevation per ground cell.
    lay : _Layout
        Grid (its ``geom`` and shadow softness ``tau``).

    Returns
    -------
    tuple
        ``(value, ∂/∂Z, ∂/∂R, ∂/∂Φ)``; ``value = L Σ_mask (I/μ + log μ)``, μ the model plus
        the noise floor.
    """
    geom = lay.geom
    shade, occluder, slope_ = soft_shadow(z, geom.x, lay.tau)
    mu = forward(r * shade, phi, z, geom) + data.floor
    ratio = data.image / mu
    value = looks * float(np.sum(np.where(data.mask, ratio + np.log(mu), 0.0)))
    g_mu = np.where(data.mask, looks * (1.0 - ratio) / mu, 0.0)
    g_reff, g_phi, g_z = adjoint(g_mu, r * shade, phi, z, geom)
    g_shade = g_reff * r
    g_z = g_z + shadow_adjoint(g_shade, occluder, slope_, geom.x)
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

    Parameters
    ----------
    g_shade : ndarray, shape (pings, cells)
        ``∂E/∂S``.
    occluder, slope_ : ndarray, shape (pings, cells)
        From :func:`soft_shadow`.
    x : ndarray, shape (cells,)
        Ground ranges.

    Returns
    -------
    ndarray, shape (pings, cells)
        Each shadowed cell's term ``g slope / x_j`` on itself and ``−g slope / x_m`` on its
        occluder m.
    """
    g = g_shade * slope_
    pings, cells = g.shape
    flat = (np.arange(pings)[:, None] * cells + occluder).ravel()
    back = np.bincount(flat, g.ravel(), pings * cells).reshape(pings, cells)
    return (g - back) / x[None, :]


def _second_difference(
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


def _charbonnier(
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


Progress = Callable[[str], None]


def fit_surface(
    sides: Mapping[str, np.ndarray],
    range_bin: float,
    *,
    ping_spacing: float,
    altitude: np.ndarray | None = None,
    looks: float | str = "auto",
    z_knot: float | None = None,
    r_knot: float | None = None,
    levels: int = 2,
    max_iter: int = 150,
    uncertainty: bool = True,
    progress: Progress | None = None,
) -> SurfaceFit:
    """Fit one seabed surface, its reflectivity and each side's beam profile to a line.

    Parameters
    ----------
    sides : mapping of str to ndarray, each shape (pings, bins)
        ``"port"`` and/or ``"starboard"`` images, linear intensity >= 0, bins from range 0.
    range_bin : float
        Slant-range bin, metres.
    ping_spacing : float
        Along-track distance between pings, metres.
    altitude : ndarray, shape (pings,), optional
        Altitude per ping (default: the first bottom return of the sides).
    looks : float or "auto"
        Speckle looks of the images; "auto" estimates them per side from neighbouring pings.
    z_knot, r_knot : float, optional
        Knot spacing of Z and of log R, metres (default 4 range bins, at least the ping spacing).
    levels : int
        Resolution levels (each halves pings and bins), coarse to fine.
    max_iter : int
        Most L-BFGS iterations per level where the fit is plain L-BFGS
        (``GAUSS_NEWTON_STEPS = 0``; by default Gauss-Newton steps on Z, see the module).
    uncertainty : bool
        Estimate the standard deviation of Z per cell (:func:`elevation_std`).
    progress : callable, optional
        Called with a line of text after each level.

    Returns
    -------
    SurfaceFit
    """
    from .bottom import track_bottom
    from .ground import check_slant, ground_axis
    from .priors import estimate_looks

    images = {name: check_slant(v, range_bin) for name, v in sides.items()}
    if not (math.isfinite(ping_spacing) and ping_spacing > 0):
        raise SonarRasterError(f"ping spacing must be > 0 metres, got {ping_spacing!r}")
    if not images or any(n not in ("port", "starboard") for n in images):
        raise SonarRasterError("sides must be 'port' and/or 'starboard'")
    pings = {v.shape[0] for v in images.values()}
    if len(pings) != 1:
        raise SonarRasterError("both sides must have the same number of pings")
    if altitude is None:
        alt = track_bottom(images, range_bin).altitude
    else:
        alt = np.broadcast_to(np.asarray(altitude, np.float64), (pings.pop(),)).copy()
    look = {}
    for name, image in images.items():
        if looks == "auto":
            est = estimate_looks(image, image > 0)
        else:
            est = float(looks)
        look[name] = float(min(max(est, 1.0), MAX_LOOKS))
    zs = float(z_knot or Z_KNOT_BINS * range_bin)
    rs = float(r_knot or R_KNOT_BINS * range_bin)
    params: np.ndarray | None = None
    fit_energies, evaluations = [], []
    factors = [2**k for k in range(levels - 1, -1, -1)]
    n_pings, bins = next(iter(images.values())).shape
    reach = float(ground_axis(alt, range_bin, bins, range_bin)[-1]) + range_bin
    extent = (
        0.0,
        max((n_pings - 1) * ping_spacing, ping_spacing),
        -reach if "port" in images else 0.0,
        reach,
    )
    lo = math.atan2(float(np.min(alt)), reach)
    hi = math.atan2(float(np.max(alt)), 0.5 * range_bin)
    angles = (lo, hi, max(4, int(math.degrees(hi - lo) * BEAM_NODES_PER_DEGREE) + 2))
    previous: Problem | None = None
    for f in factors:
        knots = (max(zs * f, ping_spacing * f), max(rs * f, ping_spacing * f))
        problem, data_x = _level(
            images, range_bin, ping_spacing, alt, look, f, knots, extent, angles
        )
        if params is None or previous is None:
            params = _start(problem)
        else:
            params = _transfer(previous, params, problem)
        previous = problem
        if GAUSS_NEWTON_STEPS:
            params, value, count = _gauss_newton(problem, params, GAUSS_NEWTON_STEPS, 20)
        else:
            params, value, count = _minimise(problem, params, max_iter)
        fit_energies.append(value)
        evaluations.append(count)
        if progress is not None:
            progress(f"level 1/{f}: E {value:.6g} after {count} evaluations")
    assert params is not None
    fit = _result(problem, params, data_x, look, fit_energies, evaluations)
    fit.altitude = alt
    if uncertainty:
        fit.elevation_std = elevation_std(problem, params)
    return fit


def _pool(image: np.ndarray, f: int) -> np.ndarray:
    if f == 1:
        return image
    p, b = image.shape[0] // f, image.shape[1] // f
    return image[: p * f, : b * f].reshape(p, f, b, f).mean(axis=(1, 3))


def _level(
    images: Mapping[str, np.ndarray],
    range_bin: float,
    spacing: float,
    alt: np.ndarray,
    looks: Mapping[str, float],
    f: int,
    knots: tuple[float, float],
    extent: tuple[float, float, float, float],
    angles: tuple[float, float, int],
) -> tuple[Problem, np.ndarray]:
    from .ground import ground_axis

    zs, rs = knots
    y0, y1, x0, xmax = extent
    rb, dy = range_bin * f, spacing * f
    pooled = {n: _pool(v, f) / rb for n, v in images.items()}  # per metre of slant range
    p = next(iter(pooled.values())).shape[0]
    h = alt[: p * f].reshape(p, f).mean(axis=1)
    bins = next(iter(pooled.values())).shape[1]
    x = ground_axis(h, rb, bins, rb)
    geom = Geometry(x, rb, dy, rb, bins, SUBSAMPLES)
    y = (np.arange(p) * f + 0.5 * (f - 1)) * spacing  # pooled ping positions, ping i at i·spacing
    by = bspline_basis(y, y0, y1, zs)
    bry = bspline_basis(y, y0, y1, rs)
    bx = {n: bspline_basis((1.0 if n == "starboard" else -1.0) * x, x0, xmax, zs) for n in pooled}
    brx = {n: bspline_basis((1.0 if n == "starboard" else -1.0) * x, x0, xmax, rs) for n in pooled}
    nadir = bspline_basis(np.zeros(1), x0, xmax, zs)
    hm = float(np.median(h))
    theta = np.arctan2(h[:, None], x[None, :])
    lo, hi, nodes = angles
    pos = np.clip((theta - lo) / (hi - lo), 0.0, 1.0) * (nodes - 1)
    index = np.clip(np.floor(pos).astype(np.int64), 0, nodes - 2)
    tau = hm * rb / np.maximum(x, rb) ** 2
    layout = _Layout(
        geom,
        by,
        bx,
        bry,
        brx,
        nadir,
        index,
        pos - index,
        nodes,
        tau,
        h,
        (zs, zs),
        (rs, rs),
        extent,
    )
    sides = {}
    scaled_looks = {}
    for name, image in pooled.items():
        centres = (np.arange(bins) + 0.5) * rb
        first = centres[None, :] >= 0.9 * h[:, None]
        mask = first & (centres[None, :] < (bins - 3) * rb)
        water = (~first) & (centres[None, :] > 0.3 * h[:, None])
        lit = image[mask]
        level = float(np.mean(lit)) if lit.size else 1.0
        floor = float(np.mean(image[water])) if water.any() else 0.0
        floor = max(floor, 1e-3 * level)
        sides[name] = SideData(image, mask, floor)
        scaled_looks[name] = min(looks[name] * f * f, MAX_LOOKS)
    return Problem(sides, layout, scaled_looks, h, ANCHOR_BINS * range_bin), x


def _start(problem: Problem) -> np.ndarray:
    """Flat seabed at the first return, R = 1, Φ fitted with Z and R held."""
    from scipy.sparse.linalg import lsqr

    lay = problem.layout
    p = np.zeros(problem.size)
    level = float(np.median(lay.altitude))
    col = lsqr(lay.by, level - lay.altitude, damp=1e-3, atol=1e-10, btol=1e-10)[0] - level
    p[: problem.nz] = np.repeat(col, problem.kz[1])
    problem.flat = p[: problem.nz].reshape(problem.kz).copy()
    start = problem.nz + problem.nr
    for i, data in enumerate(problem.sides.values()):
        level = float(np.mean(data.image[data.mask])) if data.mask.any() else 1.0
        p[start + i * lay.phi_nodes : start + (i + 1) * lay.phi_nodes] = math.log(max(level, 1e-30))
    free = np.zeros(problem.size, bool)
    free[problem.nz + problem.nr :] = True  # Φ only: R left to the joint fit, which shares
    # the shading between R and Z by their priors (fitted first, R would keep it all)
    p[:], _, _ = _minimise(problem, p, 60, free)
    return p


def _transfer(old: Problem, p: np.ndarray, new: Problem) -> np.ndarray:
    """Parameters of ``new`` (finer knots) from those of ``old``.

    Each new coefficient takes the old surface at its knot centre; the flat-seabed knots
    likewise; the Φ nodes are the same.
    """
    out = np.zeros(new.size)
    zc, rc, lphi = old.split(p)
    out[: new.nz] = old.surface_at(zc, new.knot_grid("z"), "z").ravel()
    out[new.nz : new.nz + new.nr] = old.surface_at(rc, new.knot_grid("r"), "r").ravel()
    assert old.flat is not None
    new.flat = old.surface_at(old.flat, new.knot_grid("z"), "z")
    start = new.nz + new.nr
    for i, name in enumerate(new.sides):
        out[start + i * new.layout.phi_nodes : start + (i + 1) * new.layout.phi_nodes] = lphi[name]
    return out


def _minimise(
    problem: Problem, p: np.ndarray, max_iter: int, free: np.ndarray | None = None
) -> tuple[np.ndarray, float, int]:
    base = problem.to_steps(p)
    keep = np.ones(p.size, bool) if free is None else free
    scale = problem.scales()[keep]
    norm = problem.norm

    def fun(q: np.ndarray) -> tuple[float, np.ndarray]:
        full = base.copy()
        full[keep] = q * scale
        value, grad = problem(problem.from_steps(full))
        if not np.isfinite(value):
            return math.inf, np.zeros_like(q)
        return value / norm, problem.steps_gradient(grad)[keep] * scale / norm

    x0 = base[keep] / scale
    # L-BFGS stops early where its line search fails on a kink of the model (a shadow's edge,
    # a facet turning away); it restarts from there with a fresh memory while that still
    # lowers E by a useful amount and iterations are left
    left, count, best = max_iter, 0, math.inf
    while left > 0:
        res = optimize.minimize(
            fun,
            x0,
            jac=True,
            method="L-BFGS-B",
            options={"maxiter": left, "maxcor": 20, "ftol": 1e-12, "gtol": 1e-12},
        )
        count += int(res.nfev)
        left -= max(int(res.nit), 1)
        gain = best - float(res.fun)
        x0, best = res.x, min(best, float(res.fun))
        if res.status != 2 or gain < RESTART_GAIN:  # 2: line search failed
            break
    out = base.copy()
    out[keep] = x0 * scale
    return problem.from_steps(out), best * norm, count


def _result(
    problem: Problem,
    p: np.ndarray,
    x: np.ndarray,
    looks: Mapping[str, float],
    energies: list[float],
    evaluations: list[int],
) -> SurfaceFit:
    lay = problem.layout
    elevation, refl, beam, profile = {}, {}, {}, {}
    std: dict[str, np.ndarray] = {}  # filled by fit_surface
    _, _, lphi = problem.split(p)
    for name in problem.sides:
        z, r, phi = problem.fields(p, name)
        elevation[name], refl[name], beam[name] = z, r, phi
        theta = np.linspace(
            float(np.arctan2(lay.altitude.max(), x[-1])),
            float(np.arctan2(lay.altitude.min(), x[0])),
            lay.phi_nodes,
        )
        profile[name] = (theta, np.exp(lphi[name]))
    return SurfaceFit(
        x,
        elevation,
        refl,
        beam,
        std,
        profile,
        dict(looks),
        energies=energies,
        evaluations=evaluations,
    )


def invert_line(
    sides: Mapping[str, np.ndarray],
    range_bin: float,
    *,
    ping_spacing: float,
    altitude: np.ndarray | None = None,
    looks: float | str = "auto",
    levels: int = 2,
    max_iter: int = 150,
    uncertainty: bool = True,
    progress: Progress | None = None,
) -> dict[str, Inversion]:
    """One surface fitted to both sides of a line, returned per side as :class:`Inversion`.

    The per-side results carry the same products as :func:`sonar_raster.invert`'s (ground-range,
    reprojected and evenly lit images), so :func:`sonar_raster.write_products` writes them.

    Parameters
    ----------
    sides : mapping of str to ndarray, each shape (pings, bins)
        ``"port"`` and/or ``"starboard"`` linear intensity, bins from range 0.
    range_bin : float
        Slant-range bin, metres.
    ping_spacing : float
        Along-track distance between pings, metres.
    altitude, looks, levels, max_iter, uncertainty, progress
        As for :func:`fit_surface`.

    Returns
    -------
    dict of str to Inversion
    """
    from dataclasses import replace

    from .ground import slant_to_ground
    from .products import even_illumination, reproject
    from .solver import BeamProfile, Inversion

    fit = fit_surface(
        sides,
        range_bin,
        ping_spacing=ping_spacing,
        altitude=altitude,
        looks=looks,
        levels=levels,
        max_iter=max_iter,
        uncertainty=uncertainty,
        progress=progress,
    )
    out = {}
    for name, image in sides.items():
        slant = np.asarray(image, np.float64)
        alt = fit.altitude
        ground, _ = slant_to_ground(slant, range_bin, alt, fit.x)
        reach = (slant.shape[1] - EDGE_BINS) * range_bin
        known = np.sqrt(fit.x[None, :] ** 2 + alt[:, None] ** 2) < reach
        refl, beam, elev = (
            np.where(known, v[name], np.nan) for v in (fit.reflectivity, fit.beam, fit.elevation)
        )
        depression, gain = fit.profile[name]
        settings = {
            "method": "surface",
            "levels": levels,
            "max_iter": max_iter,
            "looks": fit.looks[name],
            "altitude": "first return" if altitude is None else "given",
            "calibrated": False,
        }
        inv = Inversion(
            fit.x,
            alt,
            ground,
            refl,
            beam,
            elev,
            BeamProfile(depression, gain),
            energies=[[e] for e in fit.energies],
            ping_spacing=ping_spacing,
            runs=[
                {"evaluations": n, "energy": float(e)}
                for n, e in zip(fit.evaluations, fit.energies, strict=True)
            ],
            settings=settings,
        )
        reprojected = reproject(slant, range_bin, fit.x, inv.elevation)
        even = even_illumination(reprojected, inv.beam, fit.x, inv.elevation)
        std = fit.elevation_std.get(name)
        if std is not None:
            std = np.where(known, std, np.nan)
        out[name] = replace(inv, reprojected=reprojected, even=even, elevation_std=std)
    return out


def elevation_std(problem: Problem, p: np.ndarray, samples: int = 32, seed: int = 0) -> dict:
    """Standard deviation of Z per cell and side, from the Laplace approximation.

    The posterior of the Z knots, R and Φ held at the fit, is approximated by a Gaussian with
    the Gauss-Newton (Fisher) precision ``H = Jᵀ W J + P``: ``J`` the exact Jacobian of the
    model image wrt the knots (shadows held), ``W = L / μ²`` the Gamma likelihood's Fisher
    weight per bin and ``P`` the Hessian of the quadratic priors on Z (curvature, relief,
    anchor). Samples ``H⁻¹ (Jᵀ ε₁ + Σ Dᵀ ε₂)`` with ``ε`` standard normal have exactly that
    covariance; each costs one solve with the sparse LU factors of ``H``. The cell's standard
    deviation is that of its interpolated Z over the samples.

    Parameters
    ----------
    problem : Problem
        The finest level's problem.
    p : ndarray
        Its parameters at the fit.
    samples : int
        Number of posterior samples.
    seed : int
        Seed of the normal draws.

    Returns
    -------
    dict of str to ndarray, each shape (pings, cells)
    """
    from scipy.sparse.linalg import splu

    lay = problem.layout
    rng = np.random.default_rng(seed)
    h, parts = _fisher_z(problem, p)
    jac = sparse.vstack([j for j, _ in parts.values()], format="csr")
    roots = _prior_roots(problem)
    lu = splu(h)
    draws = []
    for _ in range(samples):
        rhs = jac.T @ rng.standard_normal(jac.shape[0])
        for root in roots:
            rhs = rhs + root.T @ rng.standard_normal(root.shape[0])
        draws.append(lu.solve(rhs))
    knots = np.stack(draws, axis=1)  # (nz, samples)
    shape = (lay.by.shape[0], lay.geom.x.size)
    return {
        name: np.std(np.asarray(basis @ knots), axis=1, ddof=1).reshape(shape)
        for name, (_, basis) in parts.items()
    }


def _prior_roots(problem: Problem) -> list[sparse.csr_matrix]:
    """Square roots ``D`` (``P = Σ DᵀD``) of the Hessians of the quadratic priors on Z knots."""
    lay = problem.layout
    ky, kx = problem.kz
    roots = []
    for axis, step, w in (
        (0, lay.z_spacing[0], problem.w_z_along),
        (1, lay.z_spacing[1], problem.w_z),
    ):
        n = (ky, kx)[axis]
        if n < 3:
            continue
        d2 = sparse.diags([1.0, -2.0, 1.0], [0, 1, 2], shape=(n - 2, n)) / step**2
        eye = sparse.identity((kx, ky)[axis])
        d = sparse.kron(d2, eye) if axis == 0 else sparse.kron(eye, d2)
        roots.append((math.sqrt(2.0 * w) * d).tocsr())
    if RELIEF_STD is not None:
        w = lay.z_spacing[0] * lay.z_spacing[1] / (2.0 * RELIEF_STD**2)
        roots.append(math.sqrt(2.0 * w) * sparse.identity(problem.nz, format="csr"))
    w = 1.0 / (2.0 * problem.anchor_std**2)
    known = sparse.diags(np.isfinite(problem.anchor).astype(np.float64))
    roots.append(math.sqrt(2.0 * w) * (known @ sparse.kron(lay.by, lay.nadir)).tocsr())
    return roots


def _fisher_z(problem: Problem, p: np.ndarray) -> tuple[sparse.csc_matrix, dict]:
    """Gauss-Newton (Fisher) matrix of the objective wrt the Z knots, R, Φ and shadows held.

    ``Σ_sides (J B)ᵀ (J B)`` with ``J`` the model's Jacobian wrt per-cell Z weighted by
    ``sqrt(L / μ²)`` and ``B`` the Z basis, plus the Hessians of the quadratic priors on Z
    (curvature, relief, anchor); the line-profile prior is applied separately
    (:func:`_line_profile`). Also returns the per-side weighted Jacobians and bases.
    """
    from .model import jacobian_z

    lay = problem.layout
    parts = {}
    h = None
    for name, data in problem.sides.items():
        z, r, phi = problem.fields(p, name)
        shade = soft_shadow(z, lay.geom.x, lay.tau)[0]
        mu = forward(r * shade, phi, z, lay.geom) + data.floor
        weight = np.where(data.mask, problem.looks[name] / (mu * mu), 0.0)
        basis = sparse.kron(lay.by, lay.bx[name], format="csr")
        jac = (jacobian_z(weight, r * shade, phi, z, lay.geom) @ basis).tocsr()
        parts[name] = (jac, basis)
        block = (jac.T @ jac).tocsc()
        h = block if h is None else h + block
    assert h is not None
    for root in _prior_roots(problem):
        h = h + (root.T @ root).tocsc()
    return h.tocsc(), parts


def _line_profile(problem: Problem, dev: np.ndarray) -> tuple[float, np.ndarray]:
    """The line-profile prior on the Z knots' deviation ``dev`` from the flat seabed.

    Φ, shared along the line, absorbs any bend of Z that every ping shares, so the image
    cannot fix it: the across-track profile of ``dev`` averaged along the line, taken relative
    to its value at nadir (whose level the first return's range fixes) and low-passed (a smooth
    Φ absorbs only a broad bend), is held at zero. Quadratic in ``dev``, so its gradient at
    ``v`` is also its Hessian times ``v``. Returns the value and the gradient, shaped as ``dev``.
    """
    lay = problem.layout
    at = lay.nadir.toarray().ravel()
    m = np.mean(dev, axis=0)
    m = m - float(at @ m)
    sigma = LINE_PROFILE_SCALE * float(np.median(lay.altitude)) / lay.z_spacing[1]
    low = ndimage.gaussian_filter1d(m, sigma, mode="constant")
    g_m = ndimage.gaussian_filter1d(2.0 * problem.w_line * low, sigma, mode="constant")
    value = problem.w_line * dev.shape[0] * float(np.sum(low * low))
    grad = np.broadcast_to((g_m - at * float(np.sum(g_m)))[None, :], dev.shape)
    return value, np.ascontiguousarray(grad)


def _gn_matvec(problem: Problem, lhs: sparse.csc_matrix, v: np.ndarray) -> np.ndarray:
    out = np.asarray(lhs @ v)
    if problem.flat is not None and problem.w_line > 0:
        out = out + _line_profile(problem, v.reshape(problem.kz))[1].ravel()
    return out


def _gauss_newton(problem: Problem, p: np.ndarray, steps: int, inner: int) -> tuple:
    """Alternate Gauss-Newton steps on the Z knots with L-BFGS on R and Φ.

    Each Z step solves ``(H + H_line + μ D) δ = −g`` by conjugate gradients preconditioned with
    the sparse LU factors of ``H + μ D`` (D its diagonal; μ shrinks after a good step and grows
    after a bad one), then backtracks on the full objective, which never rises.
    """
    from scipy.sparse.linalg import LinearOperator, cg, splu

    nz = problem.nz
    free = np.zeros(problem.size, bool)
    free[nz:] = True
    value, grad = problem(p)
    count, damping = 1, 1e-3
    for _ in range(int(steps)):
        h, _ = _fisher_z(problem, p)
        diag = h.diagonal()
        lhs = (h + sparse.diags(damping * diag + 1e-12 * diag.mean())).tocsc()
        lu = splu(lhs)
        op = LinearOperator((nz, nz), matvec=partial(_gn_matvec, problem, lhs))
        pre = LinearOperator((nz, nz), matvec=lu.solve)
        step, _ = cg(op, -grad[:nz], M=pre, maxiter=30)
        accepted = False
        for t in (1.0, 0.5, 0.25, 0.125):
            q = p.copy()
            q[:nz] += t * step
            trial, g_trial = problem(q)
            count += 1
            if trial < value:
                p, value, grad, accepted = q, trial, g_trial, True
                break
        damping = damping * 0.3 if accepted else damping * 10.0
        p, value, n = _minimise(problem, p, inner, free)
        count += n
        grad = problem(p)[1]
    return p, value, count
