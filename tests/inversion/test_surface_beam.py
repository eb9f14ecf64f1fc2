"""The surface fit's calibrated mode: a beam profile from an earlier fit held in shape."""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from sonar_raster.errors import SonarRasterError
from sonar_raster.inversion import surface
from sonar_raster.inversion.solver import BeamProfile
from sonar_raster.inversion.surface import layout, solve


@functools.cache
def _render(depth: float):
    """Both sides of 60 pings 0.1 m apart at 6 m altitude over two trenches along the track
    (``depth`` deep, σ 0.5 m, 5 m to starboard and 4 m to port), noise-free; the heightfield."""
    from sonar_raster.rendering.gl.raster import RasterRenderer
    from sonar_raster.scene import build_scene
    from sonar_raster.scenes.seabed import from_grid
    from sonar_raster.sonar import BeamPattern, Sonar
    from sonar_raster.trajectory import Trajectory

    sonar = Sonar(
        max_range=14.0,
        range_bin=0.05,
        beam=BeamPattern.gaussian(60.0),
        tilt=math.radians(20.0),
        sides=("port", "starboard"),
    )
    track = Trajectory.straight((0.0, 0.0, 6.0), 0.0, 0.1, 60)
    xx, _ = np.meshgrid(np.arange(641) * 0.05 - 16.0, np.arange(141) * 0.05 - 0.5)
    heights = -depth * sum(np.exp(-((xx - c) ** 2) / (2 * 0.5**2)) for c in (5.0, -4.0))
    field = from_grid(heights, 0.05, 0.05, x0=-16, y0=-0.5)
    image = RasterRenderer().render(build_scene([field.mesh(0.5)]), sonar, track)
    return field, track, {k: v.astype(float) for k, v in image.sides.items()}


def _speckled(depth: float, seed: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {k: v * rng.gamma(1.0, 1.0, v.shape) for k, v in _render(depth)[2].items()}


def _error(fit, field, track) -> float:
    keep = (fit.x > 1.0) & (fit.x < fit.x[-1] - 1.5)
    errors, truths = [], []
    for side, sign in (("port", -1.0), ("starboard", 1.0)):
        xx, yy = np.meshgrid(sign * fit.x[keep], track.positions[:, 1])
        truth = field.height_at(xx, yy) - 6.0
        truths.append(truth)
        errors.append(fit.elevation[side][:, keep] - truth)
    return float(np.sqrt(np.mean(np.concatenate(errors) ** 2)) / np.std(np.concatenate(truths)))


@pytest.mark.slow
def test_a_calibrated_beam_lets_single_look_trenches_along_the_track_be_seen():
    """Relief every ping shares (a trench along the track) shades the image as a beam change
    would, so with Φ free the fit keeps it in Φ; with the shape of a profile fitted to a flat
    seabed (the same sonar, its own speckle) it goes into Z. Two speckle draws (one fit's
    outcome moves with the draw: calibrated 0.76 / 0.66 / 0.85, free 0.99 / 0.97 / 1.00 on
    three), Z RMSE / relief std."""
    flat = surface.fit_surface(_speckled(0.0, 1), 0.05, ping_spacing=0.1, uncertainty=False)
    beam = {side: BeamProfile(*flat.profile[side]) for side in flat.profile}
    field, track, _ = _render(0.25)
    options = {"ping_spacing": 0.1, "uncertainty": False}
    free, calibrated = [], []
    for seed in (2, 4):
        sides = _speckled(0.25, seed)
        free.append(_error(surface.fit_surface(sides, 0.05, **options), field, track))
        fit = surface.fit_surface(sides, 0.05, beam=beam, **options)
        calibrated.append(_error(fit, field, track))
    print("calibrated", calibrated, "free", free)
    assert np.mean(calibrated) < 0.85
    assert np.mean(calibrated) < np.mean(free) - 0.15


def test_beam_reference_holds_a_profile_where_its_angles_reach():
    problem = solve.problem_at(
        [layout.Line.straight({"port": _render(0.0)[2]["port"][:8]}, 0.05, 0.1)], looks=1.0
    )
    theta = np.linspace(*problem.grid.angles, problem.grid.nodes)
    half = BeamProfile(theta[: theta.size // 2], np.exp(np.sin(theta[: theta.size // 2])))
    target, held = solve.beam_reference(problem.grid, half)["port"]
    assert held[: theta.size // 2].all() and not held[theta.size // 2 + 1 :].any()
    np.testing.assert_allclose(target[held > 0], np.sin(theta[held > 0]), atol=1e-12)
    assert solve.beam_reference(problem.grid, {"starboard": half}) == {}
    with pytest.raises(SonarRasterError, match="calibrate on a line of similar altitude"):
        solve.beam_reference(problem.grid, BeamProfile(np.array([1.6, 1.7]), np.ones(2)))


def test_beam_of_an_earlier_runs_folder(tmp_path):
    """``--beam`` takes a profile file (every side) or the folder of an earlier single-image,
    XTF or survey-lines run (one per side)."""
    from sonar_raster.cli.invert import surface_beam

    profile = BeamProfile(np.array([0.3, 1.2]), np.array([1.0, 2.0]))
    for folder in ("single/port", "single/starboard", "survey/line_1/port", "one_side"):
        (tmp_path / folder).mkdir(parents=True)
        profile.save(tmp_path / folder / "beam_profile.json")
    assert set(surface_beam(str(tmp_path / "single"))) == {"port", "starboard"}
    assert set(surface_beam(str(tmp_path / "survey"))) == {"port"}
    assert isinstance(surface_beam(str(tmp_path / "one_side")), BeamProfile)
    assert isinstance(surface_beam(str(tmp_path / "one_side" / "beam_profile.json")), BeamProfile)
    with pytest.raises(SonarRasterError, match="holds no beam_profile.json"):
        surface_beam(str(tmp_path))
