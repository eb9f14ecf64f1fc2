"""Failures the stress tests (tests/test_stress.py) found, each written out as a plain test.

Each test is the shrunk example hypothesis reported, with the truth it violated computed
independently (closed form or the numpy reference). Tests of bugs not yet fixed are marked
``xfail(strict=True)`` with the diagnosis, so they start failing (XPASS) once the fix lands and
the mark must then be removed.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import box_from_bounds, rect_seabed

from sonar_raster.rendering.analytic import flat_seabed_profile
from sonar_raster.rendering.gl.raster import RasterSettings
from sonar_raster.rendering.reference import render_reference
from sonar_raster.scene import build_scene
from sonar_raster.sonar import BeamPattern, Sonar
from sonar_raster.trajectory import Trajectory


def test_low_altitude_flat_seabed_keeps_its_nadir_energy(gl):
    """Altitude 2 m over 0.33 m bins (6 bins): the ping's energy matches the closed form.

    Fixed: triangles straddling the track under the sonar span more than pi/2 of look angle
    and were culled as if they wrapped over the top (now only a span beyond pi is).

    Found by test_flat_seabed_energy_matches_the_closed_form_integral: the GL image summed to
    4.469 m² per ping where R w h acosh(r_max / h) = 6.267 m² (bins 6-8, slant range
    1.97-2.96 m, were 0, 0 and 0.11 instead of 1.08, 0.46 and 0.34).
    """
    sonar = Sonar(max_range=23.0, range_bin=23.0 / 70, tilt=0.0, sides=("port",))
    traj = Trajectory.straight((0.0, 0.0, 2.0), 0.0, 1.0, 8)
    scene = build_scene([rect_seabed(-26.3, 26.3, -26.3, 33.3, 0.0, 1.0)])
    gl.settings = RasterSettings()
    image = gl.render(scene, sonar, traj).sides["port"].astype(np.float64)
    expected = flat_seabed_profile(sonar, 2.0, 1.0, 1.0, side="port")
    assert expected.sum() == pytest.approx(2.0 * np.arccosh(23.0 / 2.0), rel=1e-12)
    np.testing.assert_allclose(image.sum(axis=1), expected.sum(), rtol=1e-3)
    np.testing.assert_allclose(image[:, 6:9], np.tile(expected[6:9], (8, 1)), rtol=0.02)


def test_box_top_passing_under_the_sonar_is_not_culled(gl):
    """A 2 m x 1 m box top 1 m below the sonar (heading 127°): GL matches the patch reference.

    Found by test_gl_agrees_with_the_reference: relative L1 0.40 between the GL image and the
    reference (0.004 with triangles subdivided to 0.5 m, and 0.007 at heading 0, where the
    top's diagonal does not straddle the track at a wide angle).
    """
    scene = build_scene(
        [
            rect_seabed(-12.0, 12.0, -12.0, 12.0, 0.0, 1.0),
            box_from_bounds([[-1.0, -0.5, -0.5], [1.0, 0.5, 1.0]], 1.0),
        ]
    )
    sonar = Sonar(max_range=10.0, range_bin=0.125, tilt=0.0, sides=("port",))
    traj = Trajectory.straight((0.0, 0.0, 2.0), 127.0, 0.1, 3)
    ref = render_reference(scene, sonar, traj).sides["port"].astype(np.float64)
    gl.settings = RasterSettings()
    image = gl.render(scene, sonar, traj).sides["port"].astype(np.float64)
    assert ref[:, 8:10].sum() > 0 and ref[:, 16:18].sum() == 0  # top seen, seabed hidden
    assert np.abs(image - ref).sum() / ref.sum() < 0.02


def test_low_altitude_flat_seabed_with_short_edges_is_right(gl):
    """The same survey with triangles no longer than 2 m: nothing is culled (control)."""
    sonar = Sonar(max_range=23.0, range_bin=23.0 / 70, tilt=0.0, sides=("port",))
    traj = Trajectory.straight((0.0, 0.0, 2.0), 0.0, 1.0, 8)
    scene = build_scene([rect_seabed(-26.3, 26.3, -26.3, 33.3, 0.0, 1.0)])
    gl.settings = RasterSettings(max_edge=2.0)
    try:
        image = gl.render(scene, sonar, traj).sides["port"].astype(np.float64)
    finally:
        gl.settings = RasterSettings()
    expected = flat_seabed_profile(sonar, 2.0, 1.0, 1.0, side="port")
    np.testing.assert_allclose(image.sum(axis=1), expected.sum(), rtol=1e-3)


def _sidelobe_survey():
    """A sinc⁴ beam (0.125 m at 400 kHz: lobes 1.7° apart) pointing at the horizon, so the
    seabed 4 m below (depression 24° to 90°) is lit by sidelobes only."""
    sonar = Sonar(
        max_range=10.0,
        range_bin=0.25,
        beam=BeamPattern.sinc(0.125, 400e3),
        tilt=0.0,
        sides=("port",),
    )
    traj = Trajectory.straight((0.0, 0.0, 4.0), 0.0, 1.0, 2)
    scene = build_scene([rect_seabed(-12.0, 12.0, -12.0, 13.0, 0.0, 1.0)])
    return scene, sonar, traj, flat_seabed_profile(sonar, 4.0, 1.0, 1.0, side="port").sum()


@pytest.mark.xfail(
    strict=True,
    reason=(
        "accuracy, not stability: the column table holds Φ at each column's centre times its "
        "width (rendering/gl/raster.py, _column_tables: phi = sonar.beam(alpha - beam_axis)), "
        "a midpoint rule; near nadir a column is ~1.8° wide here, as wide as the beam's "
        "lobes, so the ping's energy is off by 0.39 % (3.6 %, 0.39 %, 0.097 %, 0.031 %, "
        "0.003 % at 1, 2, 4, 8, 16 columns per bin). Averaging Φ over each column (8 points) "
        "was tried and made it worse (0.58 %, 0.15 %, 0.04 % at 2, 4, 8): Φ and the range r "
        "vary together across such a wide column, so the fix is more columns near nadir "
        "(the warp's near-nadir floor), not a better Φ alone"
    ),
)
def test_sidelobe_lit_flat_seabed_energy(gl):
    """Energy per ping of a flat seabed lit by a sinc⁴ beam's sidelobes, default settings.

    Found by test_flat_seabed_energy_matches_the_closed_form_integral (GL 1.5296e-7 m², closed
    form 1.5356e-7 m²); the energy property now draws smooth beams only.
    """
    scene, sonar, traj, expected = _sidelobe_survey()
    gl.settings = RasterSettings()
    image = gl.render(scene, sonar, traj).sides["port"].astype(np.float64)
    np.testing.assert_allclose(image.sum(axis=1), expected, rtol=3e-4)


def test_sidelobe_lit_flat_seabed_energy_converges(gl):
    """The same survey with 16 columns per bin: the energy is right (it is sampling, only)."""
    scene, sonar, traj, expected = _sidelobe_survey()
    gl.settings = RasterSettings(oversample=16.0)
    try:
        image = gl.render(scene, sonar, traj).sides["port"].astype(np.float64)
    finally:
        gl.settings = RasterSettings()
    np.testing.assert_allclose(image.sum(axis=1), expected, rtol=1e-4)


def _speckled_flat_image(pings: int, bins: int, range_bin: float, alt: float) -> np.ndarray:
    """R w h / sqrt(r² − h²) per bin (capped at the first lit bin) times exponential speckle."""
    rng = np.random.default_rng(1)
    r = (np.arange(bins) + 0.5) * range_bin
    g = np.where(r > alt, alt / np.sqrt(np.maximum(r * r - alt * alt, 1e-12)), 0.0)
    g = np.minimum(g, g[r > alt][0]) * range_bin
    return g * rng.exponential(1.0, (pings, bins))


def test_inversion_of_huge_sparse_spikes_is_finite():
    """Five isolated spikes of 1e77 (a valid float64 image) give finite energies.

    Fixed: invert fits a copy scaled to order one by a power of two and gives Φ the scale back.

    Found by probing test_inversion_is_finite_and_monotone with amplitudes beyond float32
    (the property now draws 1e-38..1e38, which every float32 image file satisfies).
    """
    from sonar_raster.inversion.solver import invert

    rng = np.random.default_rng(1)
    image = np.zeros((11, 188))
    image[rng.integers(0, 11, 5), rng.integers(0, 188, 5)] = 1e77
    with np.errstate(over="raise", invalid="raise", divide="raise"):
        inv = invert(image, 0.05, altitude=3.0, levels=2, max_iter=15)
    assert all(np.all(np.isfinite(e)) for e in inv.energies)


def test_inversion_of_a_tiny_image_is_finite():
    """A speckled flat seabed at 1e-160 of its level inverts like the same image at 1."""
    import warnings

    from sonar_raster.inversion.solver import invert

    image = _speckled_flat_image(11, 188, 0.05, 3.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        tiny = invert(image * 1e-160, 0.05, altitude=3.0, levels=2, max_iter=15)
    ok = np.isfinite(tiny.elevation)
    assert ok.any() and all(np.all(np.isfinite(e)) for e in tiny.energies)


def test_inversion_is_scale_equivariant():
    """Scaling the image by 1e30 scales Φ (and the ground image, E by its square) and leaves
    R and Z as they were: the fit runs on a copy scaled by a power of two."""
    from sonar_raster.inversion.solver import invert

    image = _speckled_flat_image(16, 240, 0.05, 4.0)
    a = invert(image, 0.05, max_iter=10)
    b = invert(image * 1e30, 0.05, max_iter=10)
    np.testing.assert_allclose(b.reflectivity, a.reflectivity, rtol=1e-9, equal_nan=True)
    np.testing.assert_allclose(b.elevation, a.elevation, rtol=1e-9, equal_nan=True)
    np.testing.assert_allclose(b.beam, a.beam * 1e30, rtol=1e-9, equal_nan=True)
    np.testing.assert_allclose(b.energies[-1], np.multiply(a.energies[-1], 1e60), rtol=1e-9)


def _port_gl_against_reference(gl, scene, sonar, traj) -> float:
    """Relative L1 of the GL port image (test_stress.py's settings) against the reference."""
    ref = render_reference(scene, sonar, traj)
    gl.settings = RasterSettings(oversample=4.0, along_samples=16)
    try:
        image = gl.render(scene, sonar, traj)
    finally:
        gl.settings = RasterSettings()
    return float(np.abs(image.sides["port"] - ref.sides["port"]).sum() / ref.sides["port"].sum())


def test_box_top_three_bins_under_a_single_ping(gl):
    """Accuracy at nadir: a box top exactly 3 range bins (1.5 m at 0.5 m bins) under a single
    port ping, the clearance test_stress.py's GL-vs-reference test allowed (NADIR_CLEARANCE_BINS
    = 3, now 4). Hypothesis drew it in full-suite runs. Relative L1 5.26 % (a strict xfail)
    until the raster shaded the faces its rays meet from behind (2026-12-02): 3.87 %, the box
    top's bin 1.059 against the reference's 1.056 (0.935 before: fragments of the top in columns
    near nadir met it from behind in the shader's frame and returned nothing)."""
    seabed = rect_seabed(-12.0, 12.0, -12.0, 12.0, z=0.0, reflectivity=1.0)
    box = box_from_bounds([[-1.0, -3.0, -0.5], [1.0, 3.0, 1.5]], reflectivity=1.0)
    scene = build_scene([seabed, box])
    sonar = Sonar(max_range=10.0, range_bin=0.5, beam=BeamPattern.uniform(), sides=("port",))
    traj = Trajectory(
        np.array([[0.0, 0.0, 3.0]]),
        np.array([0.54105207]),
        np.array([0.00478086]),
        np.array([0.0]),
    )
    err = _port_gl_against_reference(gl, scene, sonar, traj)
    assert err <= 0.05, f"relative L1 {err:.4f}"


@pytest.mark.xfail(
    strict=True,
    reason=(
        "a bright box (R 1 on a 0.125 seabed) straight under a two-ping track with a uniform "
        "beam: relative L1 5.09 % against RENDERERS_TOL = 5 %, and 5.1-5.3 % with its top 4 to 7 "
        "range bins below the sonar, so not a nadir-clearance effect; drawn by test_stress.py in "
        "a full CI run, which now keeps objects off the track's nadir until this is understood"
    ),
)
def test_bright_box_under_the_track(gl):
    seabed = rect_seabed(-12.37460659, 12.0, -12.92718385, 12.0, z=0.0, reflectivity=0.125)
    box = box_from_bounds([[-2.0, -1.0, -0.5], [2.0, 1.0, 2.0]], reflectivity=1.0)
    scene = build_scene([seabed, box])
    sonar = Sonar(max_range=10.0, range_bin=0.5, beam=BeamPattern.uniform(), sides=("port",))
    traj = Trajectory(
        np.array([[0.0, 0.0, 4.0], [-0.37460659, -0.92718385, 4.0]]),
        np.array([3.52556509, 3.52556509]),
        np.array([0.00478086, -0.00803596]),
        np.zeros(2),
    )
    err = _port_gl_against_reference(gl, scene, sonar, traj)
    assert err <= 0.05, f"relative L1 {err:.4f}"
