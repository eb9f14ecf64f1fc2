"""The coherent model's vectorised scatterer-ping terms and deposit equal the plain formulas,
and crab and pitch are modelled.

``_terms`` (per-scatterer factors, phase reduced before a float32 cosine, crab and pitch through
the segment's shear map) against ``_amplitudes`` (Eq. 10 term by term in orthonormal
coordinates, the path ``ping_echo`` uses); the table-interpolated gridding weights and the
per-tap deposit against the Kaiser-Bessel kernel evaluated directly; the jitter's Gaussians
against Box-Muller in float64; a crabbed, pitched track's profile against the raster's.
"""

import math

import numpy as np
import pytest
from conftest import rect_seabed

from sonar_raster.rendering.coherent.echo import EchoGrid
from sonar_raster.rendering.coherent.model import (
    HorizontalBeam,
    PointScatterers,
    Pulse,
    _amplitudes,
    _model,
    _pair_index,
    _terms,
    render_coherent,
    to_raster_units,
)
from sonar_raster.rendering.coherent.scatter import (
    JITTER_CLIP,
    FaceTable,
    Scatterers,
    _gaussian3,
    _uniforms,
    cos_sin,
)
from sonar_raster.rendering.entry import render
from sonar_raster.scene import build_scene
from sonar_raster.sonar import BeamPattern, Sonar
from sonar_raster.trajectory import Trajectory

pytestmark = pytest.mark.usefixtures("strict_float")

FLAT = Sonar(frequency_hz=100e3, max_range=20.0, range_bin=0.05)
BEAMED = Sonar(
    frequency_hz=100e3,
    max_range=20.0,
    range_bin=0.05,
    beam=BeamPattern.gaussian(40.0),
    tilt=math.radians(10.0),
)


def _chunk(rng, n=3000, faces=40):
    """Scatterers around a track in frame coordinates, on both sides, some facing away."""
    normal = rng.normal(size=(faces, 3)) + [0.0, 0.0, 2.0]
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    table = FaceTable(normal, rng.uniform(1e-5, 4e-4, faces), rng.uniform(0.05, 1.0, faces))
    nominal = np.stack(
        [rng.uniform(-3, 9, n), rng.uniform(-19, 19, n), rng.uniform(-6, -1, n)], axis=1
    )
    position = nominal + rng.normal(scale=0.004, size=nominal.shape)
    face = rng.integers(0, faces, n)
    return Scatterers(face, np.arange(n), nominal, position, table)


def _pings(rng, on_line):
    p = np.zeros((12, 3))
    p[:, 0] = np.sort(rng.uniform(0.0, 6.0, 12))
    if not on_line:
        p[:, 1:] = rng.normal(scale=0.02, size=(12, 2))
    return p


@pytest.mark.parametrize(
    "sonar, beam_h, law, on_line, roll",
    [
        (FLAT, HorizontalBeam(0.05), "lambert", True, 0.0),
        (FLAT, HorizontalBeam(0.05, "sinc"), "eq10", False, 0.0),
        (BEAMED, HorizontalBeam(0.08), "lambert", True, 0.1),
        (BEAMED, HorizontalBeam(0.3, "sinc"), "eq10", False, -0.2),
    ],
)
def test_terms_equal_eq10_term_by_term(sonar, beam_h, law, on_line, roll):
    rng = np.random.default_rng(4)
    sc = _chunk(rng)
    pings = _pings(rng, on_line)
    rolls = roll * rng.uniform(0.5, 1.5, len(pings))
    model = _model(sonar, beam_h, law)
    model = type(model)(**{**model.__dict__, "area_ref": 2e-4 if law == "lambert" else 0.0})
    off = float(np.max(np.hypot(pings[:, 1], pings[:, 2])))
    sides = ("port", "starboard")
    terms = _terms(sc, pings, rolls, sides, model, off)
    k, j = _pair_index(sc.position, pings, model, off)
    sign = np.where(sc.nominal[:, 1] > 0, 1.0, -1.0)
    r, c, ok = _amplitudes(sc, k, pings[j], rolls[j], sign[k], model)
    assert ok.sum() == terms.count > 2000 and (~ok).sum() > 100  # both kinds are exercised
    np.testing.assert_array_equal(terms.row, j * 2 + (sc.nominal[k, 1] > 0))
    np.testing.assert_allclose(terms.r[ok], r[ok], rtol=1e-13)
    new = terms.re + 1j * terms.im
    scale = np.abs(c[ok]).max()
    assert np.abs(new[ok] - c[ok]).max() <= 2e-7 * scale
    assert np.all(new[~ok] == 0)


@pytest.mark.parametrize("on_line", [True, False])
def test_crabbed_pitched_terms_equal_eq10_in_the_fans_orthonormal_frame(on_line):
    # frame coordinates (t, x, v) of a sheared segment: a point is t·a + (0, x, v) in the fan's
    # orthonormal components, a = the direction of travel there (crab 20°, pitch 6°)
    crab, pitch = math.radians(20.0), math.radians(6.0)
    travel = np.array([math.cos(crab) * math.cos(pitch), math.sin(crab), -math.sin(pitch)])
    travel /= np.linalg.norm(travel)
    rng = np.random.default_rng(7)
    sc = _chunk(rng)
    pings = _pings(rng, on_line)
    rolls = np.full(len(pings), 0.05)
    model = _model(BEAMED, HorizontalBeam(0.05), "lambert")
    off = float(np.max(np.hypot(pings[:, 1], pings[:, 2])))
    terms = _terms(sc, pings, rolls, ("port", "starboard"), model, off, travel)
    k, j = _pair_index(sc.position, pings, model, off, travel)

    def fan(p):
        return p[:, :1] * travel + np.column_stack([np.zeros(len(p)), p[:, 1:]])

    points = PointScatterers(fan(sc.position), sc.normal, sc.facet_area, sc.reflectivity)
    sign = np.where(sc.nominal[:, 1] > 0, 1.0, -1.0)
    r, c, ok = _amplitudes(points, k, fan(pings)[j], rolls[j], sign[k], model)
    assert ok.sum() == terms.count > 2000
    np.testing.assert_allclose(terms.r[ok], r[ok], rtol=1e-12)
    new = terms.re + 1j * terms.im
    assert np.abs(new[ok] - c[ok]).max() <= 2e-7 * np.abs(c[ok]).max()
    # the pairs cover every term inside the beam: a wider search finds no more
    wide = _model(BEAMED, HorizontalBeam(0.05), "lambert")
    k2, j2 = _pair_index(
        sc.position, pings, type(wide)(**{**wide.__dict__, "r_limit": 1e3}), off + 5.0, travel
    )
    r2, _, ok2 = _amplitudes(points, k2, fan(pings)[j2], rolls[j2], sign[k2], model)
    assert ok2.sum() == ok.sum()


def test_crab_and_pitch_profile_matches_the_raster():
    sonar = Sonar(
        frequency_hz=20e3,
        max_range=12.0,
        range_bin=0.1,
        beam=BeamPattern.gaussian(50.0),
        tilt=math.radians(25.0),
        sides=("starboard",),
    )
    scene = build_scene([rect_seabed(-1, 14, -10, 26)])
    n = 150
    pos = np.column_stack([np.zeros(n), 0.1 * np.arange(n), np.full(n, 4.0)])
    # heading 25° right of the course, nose up 8°: the fans are rotated and tilted
    traj = Trajectory(pos, np.full(n, math.radians(25.0)), 0.0, math.radians(8.0))
    coherent = render_coherent(scene, sonar, traj, seed=5)
    coh = to_raster_units(coherent).sides["starboard"].astype(float)
    ras = render(scene, sonar, traj).sides["starboard"].astype(float)
    k0, k1 = 50, 110
    a = coh.mean(axis=0)[k0:k1].reshape(-1, 10).mean(axis=1)
    b = ras.mean(axis=0)[k0:k1].reshape(-1, 10).mean(axis=1)
    scale = float(a @ b / (a @ a))
    rms = float(np.sqrt(np.mean((scale * a / b - 1.0) ** 2)))
    assert rms < 0.10  # the profile's shape, as on a level track (test_coherent.py)
    # and its level: the fan advances cos 25° cos 8° per metre of travel, a 10 % effect
    assert scale == pytest.approx(1.0, abs=0.06)


def test_gridding_weights_and_deposit_equal_the_kernel():
    grid = EchoGrid.make(
        0.05, 300, 1500.0, Pulse.for_range_bin(0.05, 1500.0).compressed, 15e3, 0.5, None
    )
    rng = np.random.default_rng(2)
    x = rng.uniform(20.0, grid.n - 20.0, 5000)
    first, w = grid.kernel.weights(x)
    taps = grid.kernel.taps
    z = first[None, :] + np.arange(taps)[:, None] - x[None, :]
    assert np.all((z > -taps / 2) & (z <= taps / 2))
    np.testing.assert_allclose(w, grid.kernel.kernel(z), rtol=0, atol=1e-7)
    # the per-tap bincount deposit against np.add.at of the directly evaluated kernel
    rows = 3
    row = rng.integers(0, rows, len(x))
    c = rng.normal(size=len(x)) + 1j * rng.normal(size=len(x))
    acc = grid.accumulator(rows, "fast")
    grid.add(acc, row, x, c)
    expect = np.zeros((rows, grid.n), dtype=complex)
    for q in range(taps):
        np.add.at(expect, (row, first + q), grid.kernel.kernel(z[q]) * c)
    got = acc[0].T + 1j * acc[1].T
    assert np.abs(got - expect).max() <= 1e-7 * np.abs(expect).max()


def test_float32_cos_sin_with_correction_is_float64_accurate():
    angle = np.random.default_rng(0).uniform(-math.pi, math.pi, 200_000)
    cos, sin = cos_sin(angle)
    assert np.abs(cos - np.cos(angle)).max() < 1e-7
    assert np.abs(sin - np.sin(angle)).max() < 1e-7


def test_jitter_gaussians_are_box_muller_of_the_hash():
    rng = np.random.default_rng(5)
    face, cell = rng.integers(0, 10**6, 50_000), rng.integers(0, 10**7, 50_000)
    u = _uniforms(face, cell, 11, 4)
    r1, r2 = np.sqrt(-2 * np.log(u[0])), np.sqrt(-2 * np.log(u[2]))
    expect = np.stack(
        [
            r1 * np.cos(2 * np.pi * u[1]),
            r1 * np.sin(2 * np.pi * u[1]),
            r2 * np.cos(2 * np.pi * u[3]),
        ],
        axis=1,
    )
    expect = np.clip(expect, -JITTER_CLIP, JITTER_CLIP)
    assert np.abs(_gaussian3(face, cell, 11) - expect).max() < 1e-6
