"""The image model's "segment" deposit: boxes as the renderer bins them, against a fine
numerical integration, its adjoint and Jacobian against central differences, and its energy
against the tent deposit's."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from sonar_raster.inversion import model
from sonar_raster.inversion.ground import ground_axis
from sonar_raster.inversion.law import ScatteringLaw, scattering_law
from sonar_raster.inversion.model import Geometry, adjoint, energy, evaluate, forward, jacobian_z

ALT, BIN, BINS = 12.0, 0.05, 400


#: Medium sand's APL-UW law at 400 kHz.
SAND = scattering_law("sand", 400e3)


def _boxes(r, phi, z, geom: Geometry, points: int) -> np.ndarray:
    """Each cell's energy shared by ``points`` points of its tangent plane, each into the box
    ``⌊ρ / range_bin⌋`` (the renderer's binning), (pings, bins)."""
    pings, cells = z.shape
    zx = model.slope(z, 1, geom.dx)
    x = np.asarray(geom.x)
    q = np.maximum(x * zx - z, 0.0) / np.hypot(x, z)
    e = phi * r * q * geom.dx / points
    o = ((np.arange(points) + 0.5) / points - 0.5) * geom.dx
    out = np.zeros((pings, geom.bins))
    for p in range(pings):
        rho = np.hypot(x[:, None] + o, z[p, :, None] + o * zx[p, :, None])
        k = np.floor(rho / geom.range_bin).astype(np.int64)
        inside = (k >= 0) & (k < geom.bins)
        share = np.broadcast_to(e[p, :, None], k.shape)
        out[p] = np.bincount(k[inside], share[inside], geom.bins)
    return out / geom.range_bin


def _flat(subsamples: int, deposit: str) -> tuple[Geometry, np.ndarray]:
    x = ground_axis(np.array([ALT]), BIN, BINS, BIN)
    return Geometry(x, BIN, 0.1, BIN, BINS, subsamples, deposit), np.full((1, x.size), -ALT)


@pytest.mark.parametrize("subsamples", [1, 2])
def test_flat_seabed_matches_boxes(subsamples):
    """Flat seabed at 12 m, 5 cm cells and bins: the first return lands in bin 240 (12 m /
    5 cm), not in 239 as the tent puts it, and every bin agrees with 20 000 points per cell
    binned as boxes."""
    geom, z = _flat(subsamples, "segment")
    tent_geom, _ = _flat(subsamples, "tent")
    one = np.ones_like(z)
    seg = forward(one, one, z, geom)[0]
    tent = forward(one, one, z, tent_geom)[0]
    fine = _boxes(one, one, z, geom, 20_000)[0]
    assert np.flatnonzero(seg)[0] == 240
    assert np.flatnonzero(tent)[0] == 239
    assert np.flatnonzero(fine)[0] == 240
    lit = fine > 0
    assert np.all(seg[~lit] == 0.0)
    assert np.max(np.abs(seg[lit] - fine[lit]) / fine[lit]) < 1e-3


def _wavy(subsamples: int, seed: int = 1, law: ScatteringLaw | None = None):
    """3 pings × 12 cells of a wavy lit seabed; 0.6 m cells over 0.25 m bins, so that one
    cell's interval covers up to three bins."""
    rng = np.random.default_rng(seed)
    x = 0.4 + 0.6 * np.arange(12)
    geom = Geometry(x, 0.6, 0.4, 0.25, 40, subsamples, "segment", law)
    waves = 0.3 * np.sin(x / 1.3 + np.arange(3)[:, None])
    z = -5.0 + waves + 0.05 * rng.standard_normal((3, 12))
    r, phi = rng.uniform(0.4, 1.2, z.shape), rng.uniform(0.5, 2.0, z.shape)
    return geom, r, phi, z, rng


def _away_from_kinks(z: np.ndarray, geom: Geometry) -> None:
    """Every interval end is 1e-4 bin (25 steps of the differences) or more from a bin edge,
    and the seabed is lit."""
    x = np.asarray(geom.x)
    zx = model.slope(z, 1, geom.dx)
    assert np.all(x * zx - z > 0.5)
    n = geom.subsamples
    for s in range(n + 1):
        o = (s / n - 0.5) * geom.dx
        u = np.hypot(x + o, z + o * zx) / geom.range_bin
        assert np.min(np.abs(u - np.round(u))) > 1e-4


def _central(f, v: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central differences of the scalar or array ``f`` wrt every entry of ``v``, stacked."""
    out = []
    for i in np.ndindex(v.shape):
        up, down = v.copy(), v.copy()
        up[i] += h
        down[i] -= h
        out.append((np.asarray(f(up)) - np.asarray(f(down))) / (2 * h))
    return np.array(out)


@pytest.mark.parametrize("law", [None, SAND], ids=["lambert", "sand"])
@pytest.mark.parametrize("subsamples", [1, 2, 3])
def test_adjoint_matches_central_differences(subsamples, law):
    geom, r, phi, z, rng = _wavy(subsamples, law=law)
    _away_from_kinks(z, geom)
    assert int(model._segment_cells(z, geom).reach[0]) >= (3 if subsamples == 1 else 2)
    g = rng.standard_normal((3, geom.bins))
    grad_r, grad_phi, grad_z = adjoint(g, r, phi, z, geom)
    cases = (
        (grad_z, z, lambda v: np.sum(g * forward(r, phi, v, geom))),
        (grad_r, r, lambda v: np.sum(g * forward(v, phi, z, geom))),
        (grad_phi, phi, lambda v: np.sum(g * forward(r, v, z, geom))),
    )
    for exact, v, f in cases:
        numeric = _central(f, v).reshape(v.shape)
        np.testing.assert_allclose(exact, numeric, rtol=0, atol=1e-6 * np.abs(numeric).max())


@pytest.mark.parametrize("law", [None, SAND], ids=["lambert", "sand"])
@pytest.mark.parametrize("subsamples", [1, 2])
def test_jacobian_matches_central_differences(subsamples, law):
    geom, r, phi, z, rng = _wavy(subsamples, seed=2, law=law)
    _away_from_kinks(z, geom)
    w = rng.uniform(0.5, 2.0, (3, geom.bins))
    w[:, :5] = 0.0
    jac = jacobian_z(w, r, phi, z, geom).toarray()
    numeric = _central(lambda v: (np.sqrt(w) * forward(r, phi, v, geom)).ravel(), z).T
    np.testing.assert_allclose(jac, numeric, rtol=0, atol=1e-6 * np.abs(numeric).max())


def test_evaluate_gradient_is_the_energys():
    geom, r, phi, z, rng = _wavy(2, seed=3)
    image, w = rng.uniform(0.0, 2.0, (3, geom.bins)), rng.uniform(0.5, 2.0, (3, geom.bins))
    ev = evaluate(image, w, r, phi, z, geom, smooth=0.3)
    assert ev.energy == pytest.approx(energy(image, w, r, phi, z, geom, smooth=0.3), rel=1e-12)
    for exact, v, f in (
        (ev.grad_z, z, lambda v: energy(image, w, r, phi, v, geom, 0.3)),
        (ev.grad_r, r, lambda v: energy(image, w, v, phi, z, geom, 0.3)),
    ):
        numeric = _central(f, v).reshape(v.shape)
        np.testing.assert_allclose(exact, numeric, rtol=0, atol=1e-6 * np.abs(numeric).max())
    jac = jacobian_z(w, r, phi, z, geom)
    np.testing.assert_allclose(ev.diag_z, 2.0 * (jac.multiply(jac)).sum(axis=0).A1.reshape(3, 12))
    assert np.all(ev.diag_r > 0) and np.all(ev.diag_phi > 0)


@pytest.mark.parametrize("deposit", ["tent", "segment"])
def test_evaluate_gradient_is_the_energys_with_a_law(deposit):
    """With a law each cell's q depends on its neighbouring pings (the along-track slope):
    evaluate's Z gradient carries it for both deposits."""
    geom, r, phi, z, rng = _wavy(2, seed=5, law=SAND)
    geom = replace(geom, deposit=deposit)
    image, w = rng.uniform(0.0, 2.0, (3, geom.bins)), rng.uniform(0.5, 2.0, (3, geom.bins))
    ev = evaluate(image, w, r, phi, z, geom)
    numeric = _central(lambda v: energy(image, w, r, phi, v, geom), z).reshape(z.shape)
    np.testing.assert_allclose(ev.grad_z, numeric, rtol=0, atol=1e-6 * np.abs(numeric).max())
    assert np.all(ev.diag_z > 0)


@pytest.mark.parametrize("subsamples", [1, 2])
def test_energy_equals_the_tents(subsamples):
    """Both deposits keep each cell's energy when its points fall inside the bins."""
    geom, r, phi, z, _ = _wavy(subsamples, seed=4)
    tent = Geometry(geom.x, geom.dx, geom.dy, geom.range_bin, geom.bins, subsamples)
    seg = forward(r, phi, z, geom).sum(axis=1)
    ref = forward(r, phi, z, tent).sum(axis=1)
    np.testing.assert_allclose(seg, ref, rtol=1e-13)
    cell = phi * r * model._segment_cells(z, geom).q * geom.dx / geom.range_bin
    np.testing.assert_allclose(seg, cell.sum(axis=1), rtol=1e-13)


def test_zero_length_interval_is_a_point():
    """A cell centred at nadir on a flat seabed (its two ends at one range) and a point
    exactly on a bin edge: no division by zero, the energy goes to the box of its range."""
    x = np.array([0.0, 0.5, 1.0])
    geom = Geometry(x, 0.5, 0.4, 0.25, 60, 1, "segment")
    z = np.full((1, 3), -12.0)
    r = np.array([[1.0, 0.0, 0.0]])
    with np.errstate(all="raise"):
        out = forward(r, np.ones_like(z), z, geom)
        grads = adjoint(np.ones((1, 60)), r, np.ones_like(z), z, geom)
        jac = jacobian_z(np.ones((1, 60)), r, np.ones_like(z), z, geom)
    assert np.flatnonzero(out[0]).tolist() == [48]  # 12 m / 0.25 m
    assert out[0, 48] * 0.25 == pytest.approx(0.5)  # q = 1, dx = 0.5
    assert all(np.all(np.isfinite(g)) for g in grads)
    assert np.all(np.isfinite(jac.data))


def test_unknown_deposit_is_refused():
    with pytest.raises(ValueError, match="deposit"):
        Geometry(np.ones(2), 1.0, 1.0, 1.0, 4, 1, "box")


@pytest.mark.parametrize("deposit", ["tent", "segment"])
def test_deposit_matrix_reproduces_forward(deposit):
    """The deposit matrix times each cell's return is the model image, for either deposit (the
    surface fit builds its Jacobians wrt per-cell Φ and R from it)."""
    from sonar_raster.inversion.model import deposit_matrix

    rng = np.random.default_rng(4)
    x = (np.arange(300) + 0.5) * 0.05
    geom = Geometry(x, 0.05, 0.1, 0.05, 400, 2, deposit)
    z = -6.0 + 0.2 * np.sin(np.arange(300) / 7.0)[None, :] + 0.05 * rng.normal(size=(4, 300))
    r, phi = rng.uniform(0.5, 1.0, z.shape), rng.uniform(0.5, 1.0, z.shape)
    matrix, q = deposit_matrix(z, geom)
    image = forward(r, phi, z, geom)
    rebuilt = (matrix @ (phi * r * q).ravel()).reshape(image.shape) * geom.dx / geom.range_bin
    assert np.abs(rebuilt - image).max() < 1e-12 * np.abs(image).max()
