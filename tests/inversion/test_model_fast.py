"""The vectorised image model against a loop-by-loop reference, its adjoint and Jacobian
against the reference's derivatives, and its cache of prepared cells."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sonar_raster.inversion import model
from sonar_raster.inversion.law import ScatteringLaw, scattering_law
from sonar_raster.inversion.model import Geometry, adjoint, forward, jacobian_z

BINS = 27


def _reference(r, phi, z, geom: Geometry) -> np.ndarray:
    """The module notes' model written as plain loops, (pings, bins)."""
    pings, cells = z.shape
    n, h = geom.subsamples, geom.dx
    out = np.zeros((pings, geom.bins))
    for p in range(pings):
        for j in range(cells):
            if cells < 2:
                zx = 0.0
            elif j == 0:
                zx = (z[p, 1] - z[p, 0]) / h
            elif j == cells - 1:
                zx = (z[p, j] - z[p, j - 1]) / h
            else:
                zx = (z[p, j + 1] - z[p, j - 1]) / (2 * h)
            x = geom.x[j]
            q = max(0.0, x * zx - z[p, j]) / math.hypot(x, z[p, j])
            if geom.law is not None and q > 0:
                # cos θ between the facet's normal (−Zx, −Zy, 1), Zy from the neighbouring
                # pings, and the way to the sonar (−x, 0, −Z)
                zy = 0.0
                if pings > 1:
                    lo, hi = max(p - 1, 0), min(p + 1, pings - 1)
                    zy = (z[hi, j] - z[lo, j]) / ((hi - lo) * geom.dy)
                normal = np.array([-zx, -zy, 1.0]) / math.sqrt(zx * zx + zy * zy + 1.0)
                cos = float(normal @ np.array([-x, 0.0, -z[p, j]])) / math.hypot(x, z[p, j])
                q *= math.exp(float(geom.law.log_factor_at(np.array([cos]))[0][0]))
            e = phi[p, j] * r[p, j] * q * h / n
            for s in range(n):
                o = ((s + 0.5) / n - 0.5) * h
                rho = math.hypot(x + o, z[p, j] + o * zx)
                u = rho / geom.range_bin - 0.5
                k0 = math.floor(u)
                t = u - k0
                for k, w in ((k0, 1.0 - t), (k0 + 1, t)):
                    if 0 <= k < geom.bins:
                        out[p, k] += e * w
    return out / geom.range_bin


#: Medium sand's APL-UW law at 400 kHz: the model's cells times its factor of cos θ.
SAND = scattering_law("sand", 400e3)


def _case(subsamples: int, seed: int = 4, law: ScatteringLaw | None = None):
    """3 pings × 12 cells: layover, a shadowed cell, points beyond both ends of the bins."""
    rng = np.random.default_rng(seed)
    x = 0.05 + 0.6 * np.arange(12)
    geom = Geometry(x, 0.6, 0.4, 0.25, BINS, subsamples, law=law)
    z = -2.5 + 0.3 * rng.standard_normal((3, 12))
    z[0, 3] += 2.0  # a spike: its near face folds over (layover), its far side is unlit
    z[1, :2] = (-0.05, -0.3)  # the nearest cell lit above the first bin's centre (k0 = -1)
    r = rng.uniform(0.4, 1.2, z.shape)
    phi = rng.uniform(0.5, 2.0, z.shape)
    return geom, r, phi, z


def x_zx_minus_z(z: np.ndarray, geom: Geometry) -> np.ndarray:
    """``x Zx − Z`` per cell: where it crosses 0 the model has a kink (a cell turns away)."""
    return geom.x[None, :] * model.slope(z, 1, geom.dx) - z


@pytest.mark.parametrize("law", [None, SAND], ids=["lambert", "sand"])
@pytest.mark.parametrize("subsamples", [1, 2, 3])
def test_forward_matches_the_loop_reference(subsamples, law):
    geom, r, phi, z = _case(subsamples, law=law)
    unlit = x_zx_minus_z(z, geom) <= 0
    assert unlit.any() and (~unlit).sum() > 20  # shadowed and lit cells are both covered
    ref = _reference(r, phi, z, geom)
    assert ref[:, -1].sum() > 0 and ref[1, 0] > 0  # energy reaches both ends of the bins
    k0 = np.floor(np.hypot(geom.x, z) / geom.range_bin - 0.5)
    assert k0.min() == -1 and k0.max() >= BINS  # and falls off both ends
    got = forward(r, phi, z, geom)
    assert np.max(np.abs(got - ref)) <= 1e-13 * np.max(ref)


def _dense_jacobians(r, phi, z, geom):
    """∂Î/∂R and ∂Î/∂Φ exactly (Î is linear in each), ∂Î/∂Z by central differences."""
    size = z.size
    jr, jphi, jz = (np.zeros((z.shape[0] * geom.bins, size)) for _ in range(3))
    for i in range(size):
        unit = np.zeros(size)
        unit[i] = 1.0
        unit = unit.reshape(z.shape)
        jr[:, i] = _reference(unit, phi, z, geom).ravel()
        jphi[:, i] = _reference(r, unit, z, geom).ravel()
        h = 1e-6
        up = _reference(r, phi, z + h * unit, geom)
        down = _reference(r, phi, z - h * unit, geom)
        jz[:, i] = ((up - down) / (2 * h)).ravel()
    return jr, jphi, jz


def _away_from_kinks(z: np.ndarray, geom: Geometry, margin: float) -> bool:
    """True when no point lies within ``margin`` of a bin centre and no cell near turning."""
    zx = model.slope(z, 1, geom.dx)
    n = geom.subsamples
    for s in range(n):
        o = ((s + 0.5) / n - 0.5) * geom.dx
        u = np.hypot(geom.x + o, z + o * zx) / geom.range_bin - 0.5
        t = u - np.floor(u)
        if np.any(np.minimum(t, 1 - t) < margin):
            return False
    return bool(np.all(np.abs(x_zx_minus_z(z, geom)) > margin))


@pytest.mark.parametrize("law", [None, SAND], ids=["lambert", "sand"])
@pytest.mark.parametrize("subsamples", [1, 2, 3])
def test_adjoint_and_jacobian_match_the_reference_derivatives(subsamples, law):
    geom, r, phi, z = _case(subsamples, law=law)
    assert _away_from_kinks(z, geom, 1e-4)  # central differences are exact to O(h²) here
    jr, jphi, jz = _dense_jacobians(r, phi, z, geom)
    rng = np.random.default_rng(7)
    g = rng.standard_normal((z.shape[0], BINS))
    g_r, g_phi, g_z = adjoint(g, r, phi, z, geom)
    for got, dense in ((g_r, jr), (g_phi, jphi), (g_z, jz)):
        want = (dense.T @ g.ravel()).reshape(z.shape)
        assert np.max(np.abs(got - want)) <= 1e-6 * np.max(np.abs(want))
    weight = rng.uniform(0.0, 2.0, g.shape) * (rng.uniform(size=g.shape) > 0.2)
    jac = jacobian_z(weight, r, phi, z, geom)
    want = np.sqrt(weight).ravel()[:, None] * jz
    assert jac.shape == want.shape
    assert np.max(np.abs(jac.toarray() - want)) <= 1e-6 * np.max(np.abs(want))
    # the sparse structure is canonical: sorted, no duplicates, no stored zeros
    assert jac.has_canonical_format and np.all(jac.data != 0)


@pytest.mark.parametrize("cells", [1, 2, 3])
def test_grids_of_one_to_three_cells_match_the_reference(cells):
    # the slope stencil's ends meet (or vanish) on such grids
    rng = np.random.default_rng(cells)
    geom = Geometry(2.0 + 0.6 * np.arange(cells), 0.6, 0.4, 0.25, 16, 2)
    z = -2.0 + 0.2 * rng.standard_normal((2, cells))
    r, phi = rng.uniform(0.5, 1.0, z.shape), rng.uniform(0.5, 1.0, z.shape)
    assert _away_from_kinks(z, geom, 1e-4)
    ref = _reference(r, phi, z, geom)
    assert np.max(np.abs(forward(r, phi, z, geom) - ref)) <= 1e-13 * np.max(ref)
    jz = _dense_jacobians(r, phi, z, geom)[2]
    jac = jacobian_z(np.ones_like(ref), r, phi, z, geom).toarray()
    assert np.max(np.abs(jac - jz)) <= 1e-6 * np.max(np.abs(jz))


def test_jacobian_is_exactly_the_adjoint_of_the_model():
    # J^T (sqrt(w) g) and the adjoint of w g share every term; they agree to rounding
    geom, r, phi, z = _case(2, seed=9)
    rng = np.random.default_rng(2)
    weight = rng.uniform(0.0, 2.0, (3, BINS))
    g = rng.standard_normal((3, BINS))
    jac = jacobian_z(weight, r, phi, z, geom)
    via_jac = (jac.T @ (np.sqrt(weight) * g).ravel()).reshape(z.shape)
    via_adjoint = adjoint(weight * g, r, phi, z, geom)[2]
    assert np.max(np.abs(via_jac - via_adjoint)) <= 1e-12 * np.max(np.abs(via_adjoint))


def test_the_cache_follows_z_changed_in_place_and_each_geometry():
    geom, r, phi, z = _case(2)
    other = Geometry(geom.x, geom.dx, geom.dy, geom.range_bin * 1.1, BINS, 2)
    z = z.copy()
    first = forward(r, phi, z, geom)
    assert np.array_equal(forward(r, phi, z, geom), first)  # served from the cache
    z[1, 5] += 0.3  # the same array object, changed in place
    moved = forward(r, phi, z, geom)
    assert np.max(np.abs(moved - _reference(r, phi, z, geom))) <= 1e-13 * np.max(first)
    assert np.max(np.abs(moved - first)) > 0.01 * np.max(first)
    # two geometries and three Zs in turn: every answer is the fresh one
    zs = [z, z + 0.01, z - 0.02]
    g = np.random.default_rng(1).standard_normal((3, BINS))
    for _ in range(2):
        for zz in zs:
            for gg in (geom, other):
                cached = adjoint(g, r, phi, zz, gg)
                model.clear_cache()
                fresh = adjoint(g, r, phi, zz, gg)
                for a, b in zip(cached, fresh, strict=True):
                    assert np.array_equal(a, b)
                assert np.allclose(
                    forward(r, phi, zz, gg), _reference(r, phi, zz, gg), rtol=1e-13, atol=0
                )


def test_outputs_are_not_the_cache_or_work_arrays():
    geom, r, phi, z = _case(2)
    image = forward(r, phi, z, geom)
    grads = adjoint(np.ones_like(image), r, phi, z, geom)
    kept = [image.copy()] + [v.copy() for v in grads]
    forward(r, phi, z + 0.1, geom)  # recomputes cells and reuses the work buffer
    adjoint(-np.ones_like(image), r, phi, z + 0.2, geom)
    for a, b in zip([image, *grads], kept, strict=True):
        assert np.array_equal(a, b)


def test_transposed_inputs_give_the_same_answers():
    # the surface fit passes Z and R as transposes of its basis products (Fortran order)
    geom, r, phi, z = _case(2)
    g = np.random.default_rng(5).standard_normal((3, BINS))
    weight = np.abs(g)
    fortran = [np.asfortranarray(v) for v in (r, phi, z)]
    assert not fortran[2].flags.c_contiguous
    for f in (forward, lambda *a: adjoint(g, *a), lambda *a: jacobian_z(weight, *a)):
        model.clear_cache()
        want = f(r, phi, z, geom)
        model.clear_cache()
        got = f(*fortran, geom)
        for a, b in zip(_outputs(got), _outputs(want), strict=True):
            assert np.array_equal(a, b)


def _outputs(value) -> list[np.ndarray]:
    if isinstance(value, tuple):
        return list(value)
    return [value.toarray()] if hasattr(value, "toarray") else [value]


def test_an_undefined_elevation_raises_nothing_and_leaves_other_pings_alone():
    geom, r, phi, z = _case(2)
    bad = z.copy()
    bad[1, 4] = np.nan
    with np.errstate(invalid="ignore"):
        image = forward(r, phi, bad, geom)
        grads = adjoint(np.ones_like(image), r, phi, bad, geom)
        jac = jacobian_z(np.ones_like(image), r, phi, bad, geom)
    good = forward(r, phi, z, geom)
    assert np.array_equal(image[[0, 2]], good[[0, 2]])
    assert all(np.all(np.isfinite(v[[0, 2]])) for v in grads)
    assert jac.shape == (3 * BINS, z.size)
