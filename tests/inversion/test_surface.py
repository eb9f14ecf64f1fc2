"""The surface fit: exact gradients, bases, and a speckled round trip that beats a flat seabed."""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
from scipy import sparse

from sonar_raster.errors import SonarRasterError
from sonar_raster.inversion import surface
from sonar_raster.inversion.law import scattering_law
from sonar_raster.inversion.solver import BeamProfile
from sonar_raster.inversion.surface import layout, solve
from sonar_raster.inversion.surface import problem as problem_module
from sonar_raster.inversion.surface.problem import soft_shadow


def _problem(seed: int = 0, shadows: bool = True, lines: int = 1, law=None):
    """Random images on one line (or several overlapping ones) and parameters near the start."""
    rng = np.random.default_rng(seed)
    pings, bins, rb = 10, 110, 0.1
    made = []
    for k in range(lines):
        images = {
            side: rng.gamma(1.0, 1.0, (pings, bins)) * (np.arange(bins) * rb > 5.0)
            for side in ("port", "starboard")
        }
        position = np.stack([np.full(pings, 6.0 * k), np.arange(pings) * 0.2], axis=1)
        heading = np.full(pings, 0.0 if k % 2 == 0 else math.pi)
        if k % 2:
            position = position[::-1].copy()
        looks = 1.0 + k
        made.append(layout.Line(images, rb, position, heading, np.full(pings, 5.0), law=law))
    problem = solve.problem_at(made, looks=looks, z_knot=0.4, r_knot=0.4)
    p = solve._start(problem) + rng.normal(0.0, 0.05, problem.size)
    if shadows:  # two ridges across track cast shadows behind them
        zc = p[: problem.nz].reshape(problem.kz)
        centre = int(np.argmin(np.abs(problem.grid.knots("z")[1])))
        zc[:, centre + 12] += 1.0
        zc[:, centre - 12] += 1.0
    return problem, p, rng


#: Medium sand's APL-UW law at 400 kHz (``Line.law``).
SAND = scattering_law("sand", 400e3)


@pytest.mark.parametrize(("lines", "law"), [(1, None), (2, None), (1, SAND)])
def test_gradient_matches_central_differences(lines, law):
    problem, p, rng = _problem(lines=lines, law=law)
    assert all(view.geom.law is law for view in problem.views)
    view = problem.views[1]
    z = problem.fields(p, view)[0]
    shade = soft_shadow(z, view.geom.x, view.tau)[0]
    assert (shade < 0.5).mean() > 0.02  # the check covers shadowed cells
    _, grad = problem(p)
    picks = rng.choice(problem.size, 60, replace=False)
    for i in picks:
        step = 1e-6
        q = p.copy()
        q[i] += step
        up = problem(q)[0]
        q[i] -= 2 * step
        down = problem(q)[0]
        numeric = (up - down) / (2 * step)
        assert grad[i] == pytest.approx(numeric, rel=2e-3, abs=1e-3 * (1 + abs(numeric)))


@pytest.mark.parametrize(("lines", "deposit"), [(1, "tent"), (2, "tent"), (1, "segment")])
def test_the_held_z_objective_equals_the_problems(monkeypatch, lines, deposit):
    """The Gauss-Newton steps' inner objective (Z held, the model image linear in R Φ) against
    the full objective at R and Φ moved away from where it was made: the same value and
    gradient wrt log R and log Φ, none wrt Z; every prior on R and Φ acting, shadows cast."""
    monkeypatch.setattr(solve, "DEPOSIT", deposit)
    problem, p, rng = _problem(4, lines=lines)
    held = np.zeros(problem.grid.nodes)
    held[1:-2] = 1.0
    problem.beam_reference = {"port": (rng.normal(0.0, 0.3, held.size) * held, held)}
    p[problem.nz : problem.nz + problem.nr] += 0.5  # the gauge acts
    objective = problem.held_z(p)
    q = p.copy()
    q[problem.nz :] += rng.normal(0.0, 0.2, problem.size - problem.nz)
    value, grad = objective(q)
    expected, expected_grad = problem(q)
    assert value == pytest.approx(expected, rel=1e-11)
    assert not grad[: problem.nz].any()
    free = slice(problem.nz, None)
    np.testing.assert_allclose(
        grad[free], expected_grad[free], rtol=1e-8, atol=1e-10 * abs(grad).max()
    )


def _ridged(offsets, seed: int = 5):
    """:func:`_problem`'s line at its start with ridges along track at ``offsets`` (metres
    across track, port positive), each 0.3–0.5 m high and varying from ping to ping."""
    problem, _, rng = _problem(seed, shadows=False)
    p = solve._start(problem)
    zc = p[: problem.nz].reshape(problem.kz)
    knots_y, knots_x = problem.grid.knots("z")
    for offset in offsets:
        zc[:, np.argmin(np.abs(knots_x - offset))] += rng.uniform(0.3, 0.5, len(knots_y))
    return problem, p, zc


def test_the_anchor_offset_is_the_crests_the_data_confirm():
    """The first return reads a rough seabed's crests: the tracker on the model's own image
    reads above its level, and that gap comes off the tracked altitude as far as the data's
    first returns rise and fall with the model's from ping to ping (all of it when they do,
    none when the data's stay level)."""
    problem, p, zc = _ridged((-0.8, 0.8))  # ridges along track 0.8 m to either side
    seen, depth = solve.model_first_return(problem, p, 0)
    gap = float(np.median(seen - depth))
    assert gap < -0.5 * problem.views[0].geom.range_bin  # crests read above the level
    lead = problem.views[problem.anchored[0]]
    lead.altitude[:] = seen  # the data's first returns are the model's
    solve._track_model(problem, p)
    assert problem.anchor_offset[0] == pytest.approx(gap)
    # the anchor holds the nadir at the tracked altitude less the offset: level there, its
    # gradient sums to zero (each nadir row of the basis sums to one)
    nadir = np.asarray(lead.nadir @ zc.ravel()) - lead.height
    level = zc - np.mean(nadir + lead.altitude - gap)
    assert abs(np.sum(problem._anchor(level)[1])) < 1e-6 * abs(np.sum(problem._anchor(zc)[1]))
    lead.altitude[:] = float(np.mean(seen))  # the data's stay level
    solve._track_model(problem, p)
    assert problem.anchor_offset[0] == 0.0


def test_shifted_moves_the_nadir_across_track():
    """Cell ``j`` lies at ``(j + ½) dx`` from the nadir on its side; moved ``k`` cells to
    port, port cell ``j`` holds port cell ``j + k`` and starboard cell ``j`` what lies at
    ``(k − j − ½) dx`` across the old nadir."""
    port = np.arange(10.0)[None, :] + 100.0
    starboard = -np.arange(10.0)[None, :] - 1.0  # cell j: -(j + 1)
    p0, s0 = solve._shifted(port, starboard, 0)
    assert np.array_equal(p0, port) and np.array_equal(s0, starboard)
    p2, s2 = solve._shifted(port, starboard, 2)
    assert p2[0, :3].tolist() == [102.0, 103.0, 104.0]
    assert p2[0, -1] == 109.0  # beyond the end: the end repeats
    assert s2[0, :4].tolist() == [101.0, 100.0, -1.0, -2.0]
    p3, s3 = solve._shifted(port, starboard, -2)  # to starboard: the mirror image
    assert p3[0, :4].tolist() == [-2.0, -1.0, 100.0, 101.0]
    assert s3[0, :3].tolist() == [-3.0, -4.0, -5.0]


def test_the_crests_are_measured_where_the_shading_shows_them():
    """With ``CREST_SHIFTS`` the gap is the tracker's on the model moved so that ground 30–50 %
    of the altitude out lies under the nadir: a seabed rough everywhere reads crests there as
    under the nadir (measured −4.7 and −3.7 cm), and a ridge under the track only, where the
    fit's relief is least seen, reads nothing (+0.9 against −21.7 cm)."""
    bins = 0.1  # _problem's range bin
    problem, p, zc = _ridged(())
    zc += np.random.default_rng(6).uniform(0.0, 0.8, zc.shape)  # rough everywhere
    seen, depth = solve.model_first_return(problem, p, 0)
    under = float(np.median(seen - depth))
    shifted = solve._shifted_gap(problem, p, 0, 5.0, np.nan, solve.CREST_SHIFTS)
    print("rough everywhere: under the nadir", under, "moved", shifted)
    assert under < -0.3 * bins and shifted < -0.3 * bins
    problem, p, _ = _ridged((0.0,))  # a ridge under the track only
    seen, depth = solve.model_first_return(problem, p, 0)
    shifted = solve._shifted_gap(problem, p, 0, 5.0, np.nan, solve.CREST_SHIFTS)
    print("under the track only: under", float(np.median(seen - depth)), "moved", shifted)
    assert float(np.median(seen - depth)) < -1.0 * bins
    assert abs(shifted) < 0.1 * bins


def test_bspline_basis_reproduces_linear_functions():
    x = np.linspace(-3.0, 7.0, 101)
    basis = layout.bspline_basis(x, -3.0, 7.0, 0.5)
    centres = layout.knot_centres(-3.0, 7.0, 0.5)
    assert basis.shape == (101, centres.size)
    assert np.allclose(basis.sum(axis=1), 1.0)
    assert np.allclose(basis @ (2.0 * centres - 1.0), 2.0 * x - 1.0)


@pytest.mark.parametrize(("start", "stop", "spacing"), [(-3.0, 7.0, 0.5), (0.3, 41.7, 0.23)])
def test_bspline_basis_equals_scipys_design_matrix(start, stop, spacing):
    """The closed-form uniform cubic rows against scipy's de Boor evaluation, at random points,
    on every knot, at both ends and beyond them (clipped)."""
    from scipy.interpolate import BSpline

    spans = math.ceil((stop - start) / spacing - 1e-9)
    knots = start + spacing * np.arange(-3, spans + 4)
    rng = np.random.default_rng(1)
    points = np.concatenate(
        [rng.uniform(start, stop, 500), knots[3 : spans + 4], [start - 1.0, stop + 1.0]]
    )
    expected = BSpline.design_matrix(np.clip(points, knots[3], knots[spans + 3]), knots, 3)
    got = layout.bspline_basis(points, start, stop, spacing)
    got.check_format(full_check=True)  # no column past the last basis function
    np.testing.assert_allclose(got.toarray(), expected.toarray(), rtol=0, atol=1e-12)


def test_soft_shadow_follows_the_line_of_sight():
    x = np.arange(1, 201) * 0.05
    z = np.full((1, x.size), -5.0)
    z[0, 99] = -4.0  # a post at 5 m, 1 m high: shadow to 5 * 5 / 4 = 6.25 m
    shade, occluder, _ = soft_shadow(z, x, np.full(x.size, 1e-4))
    dark = x[shade[0] < 0.5]
    assert dark.min() == pytest.approx(5.05, abs=1e-9)
    assert dark.max() == pytest.approx(6.25, abs=0.05)
    assert np.all(occluder[0, shade[0] < 0.5] == 99)


def test_the_shades_jacobian_is_the_transpose_of_the_shadow_adjoint():
    """``shade_jacobian`` (the Gauss-Newton steps' ``∂S/∂Z``) and ``shadow_adjoint`` (the
    gradient's) are one derivative, formed and applied: ``Jᵀ g`` equals the adjoint of ``g``."""
    from sonar_raster.inversion.surface.problem import shade_jacobian, shadow_adjoint

    rng = np.random.default_rng(3)
    x = np.arange(1, 601) * 0.05
    z = -5.0 + 0.3 * np.sin(x[None, :] * 2.0 + rng.uniform(0, 6, (4, 1)))  # ridges per ping
    _, occluder, slope = soft_shadow(z, x, np.full(x.size, 2e-3))
    assert (slope > 0).sum() > 20
    g = rng.normal(size=z.shape)
    formed = shade_jacobian(occluder, slope, x).T @ g.ravel()
    np.testing.assert_allclose(formed, shadow_adjoint(g, occluder, slope, x).ravel(), atol=1e-12)


def test_refuses_bad_input():
    with pytest.raises(SonarRasterError, match="port"):
        surface.fit_surface({"left": np.ones((4, 50))}, 0.1, ping_spacing=0.1)
    with pytest.raises(SonarRasterError, match="ping spacing"):
        surface.fit_surface({"port": np.ones((4, 50))}, 0.1, ping_spacing=0.0)
    for bad in (0, 1.5):
        with pytest.raises(SonarRasterError, match="finest"):
            surface.fit_surface({"port": np.ones((4, 50))}, 0.1, ping_spacing=0.1, finest=bad)


@pytest.mark.parametrize("lines", [1, 2])
def test_the_line_profile_prior_equals_its_ping_by_ping_definition(lines):
    """Its precomputed line averages (made once per set of objects) against the definition;
    setting new objects, or a side's own weight and low-pass, must remake them."""
    problem, p, rng = _problem(3, lines=lines)
    dev = p[: problem.nz] - problem.flat.ravel() + rng.normal(0.0, 0.05, problem.nz)
    for fraction in (0.0, 0.2, 0.5):
        problem.objects = (rng.uniform(size=problem.kz) < fraction).astype(float)
        value, grad = problem_module.line_profile(problem, dev)
        expected, expected_grad = problem_module.line_profile_reference(problem, dev)
        assert value > 0 and value == pytest.approx(expected, rel=1e-10)
        np.testing.assert_allclose(grad, expected_grad, rtol=1e-9, atol=1e-12 * abs(grad).max())
    before = value
    problem.line_prior = {"port": (0.5, 1.0)}  # a calibrated side: its own weight and low-pass
    value, grad = problem_module.line_profile(problem, dev)
    expected, expected_grad = problem_module.line_profile_reference(problem, dev)
    assert value != pytest.approx(before, rel=1e-3)
    assert value == pytest.approx(expected, rel=1e-10)
    np.testing.assert_allclose(grad, expected_grad, rtol=1e-9, atol=1e-12 * abs(grad).max())


@pytest.mark.parametrize("lines", [1, 2])
def test_prior_gradients_match_central_differences_everywhere(lines):
    problem, p, rng = _problem(2, lines=lines)
    # every prior acts: the line profile and relief differ from the flat seabed, log R has a mean
    problem.flat = p[: problem.nz].reshape(problem.kz) + rng.normal(0.0, 0.05, problem.kz)
    problem.views[0].altitude[3] = np.nan  # a ping without a first return
    p[problem.nz : problem.nz + problem.nr] += 0.5
    # objects found by their shadows (off the line profile and the relief prior) and the
    # ground in their shadows (held at the flat seabed)
    problem.objects = (rng.uniform(size=problem.kz) < 0.2).astype(float)
    problem.shadowed = ((rng.uniform(size=problem.kz) < 0.2) & (problem.objects == 0)) * 1.0
    # a calibrated beam's shape held on port's inner nodes
    held = np.zeros(problem.grid.nodes)
    held[1:-2] = 1.0
    problem.beam_reference = {"port": (rng.normal(0.0, 0.3, held.size) * held, held)}

    def priors(q):
        grad = np.zeros_like(q)
        zc, rc, lphi = problem.split(q)
        value = problem.z_priors(zc, grad) + problem.reflectivity_beam_priors(rc, lphi, grad)
        return value, grad

    _, grad = priors(p)
    numeric = np.empty_like(p)
    for i in range(p.size):
        q = p.copy()
        q[i] += 1e-6
        up = priors(q)[0]
        q[i] -= 2e-6
        numeric[i] = (up - priors(q)[0]) / 2e-6
    blocks = (slice(0, problem.nz), slice(problem.nz, problem.nz + problem.nr))
    blocks += (slice(problem.nz + problem.nr, None),)
    for block in blocks:  # Z, log R, log Φ: each to its own scale
        scale = np.abs(numeric[block]).max()
        assert np.allclose(grad[block], numeric[block], rtol=1e-4, atol=1e-5 * scale)


@functools.cache
def _sand_render(material: str | None = None):
    """Both sides of 60 pings over sand waves at 30° to the track, noise-free (``material``:
    that sediment's APL-UW law on the seabed's faces, else Lambert's)."""
    from sonar_raster.rendering.gl.raster import RasterRenderer
    from sonar_raster.scene import build_scene
    from sonar_raster.scenes.seabed import from_grid
    from sonar_raster.sonar import BeamPattern, Sonar
    from sonar_raster.trajectory import Trajectory

    alt, pings, spacing, rb = 6.0, 60, 0.1, 0.05
    sonar = Sonar(
        max_range=14.0,
        range_bin=rb,
        beam=BeamPattern.gaussian(60.0),
        tilt=math.radians(20.0),
        sides=("port", "starboard"),
    )
    track = Trajectory.straight((0.0, 0.0, alt), 0.0, spacing, pings)
    x, y = np.arange(-16, 16.01, 0.05), np.arange(-2, pings * spacing + 2.01, 0.05)
    xx, yy = np.meshgrid(x, y)
    crest = xx * math.cos(math.radians(30)) + yy * math.sin(math.radians(30))
    field = from_grid(0.08 * np.sin(2 * np.pi * crest / 1.5), 0.05, 0.05, x0=-16, y0=-2)
    mesh = field.mesh(0.5)
    if material is not None:
        from dataclasses import replace

        from sonar_raster.scenes.sediments import material_index

        mesh = replace(mesh, law=material_index(material))
    image = RasterRenderer().render(build_scene([mesh]), sonar, track)
    return field, track, image.sides, alt, rb, spacing


def _sand_line(seed: int):
    """:func:`_sand_render` times single-look speckle drawn from ``seed``."""
    field, track, clean, alt, rb, spacing = _sand_render()
    rng = np.random.default_rng(seed)
    sides = {k: v.astype(float) * rng.gamma(1.0, 1.0, v.shape) for k, v in clean.items()}
    return field, track, sides, alt, rb, spacing


def _errors(fit, field, track, alt, baseline):
    keep = (fit.x > 1.0) & (fit.x < fit.x[-1] - 1.5)
    fits, flats, truths = [], [], []
    for side, sign in (("port", -1.0), ("starboard", 1.0)):
        xx, yy = np.meshgrid(sign * fit.x[keep], track.positions[:, 1])
        truth = field.height_at(xx, yy) - alt
        truths.append(truth)
        fits.append(fit.elevation[side][:, keep] - truth)
        flats.append(-baseline[:, None] - truth)
    std = float(np.std(np.concatenate(truths, axis=1)))
    rms = [float(np.sqrt(np.mean(np.concatenate(e, axis=1) ** 2))) / std for e in (fits, flats)]
    return rms[0], rms[1]


@pytest.mark.slow
def test_a_seabeds_law_in_the_model_recovers_more_of_its_relief():
    """Sand waves rendered with medium sand's APL-UW law, noise-free: the fit that models that
    law comes closer than Lambert's model (0.69 against 0.77 of the relief's std, measured);
    with the law dropped from the model the two are one fit."""
    from sonar_raster.inversion.bottom import track_bottom

    field, track, sides, alt, rb, spacing = _sand_render("sand")
    sides = {k: v.astype(float) for k, v in sides.items()}
    baseline = track_bottom(sides, rb).altitude
    errors = []
    for law in (None, SAND):  # the render's frequency: the sonar's default, 400 kHz
        line = layout.Line.straight(sides, rb, spacing, law=law)
        fit = solve.fit_lines([line], uncertainty=False)[0]
        errors.append(_errors(fit, field, track, alt, baseline)[0])
    lambert, with_law = errors
    assert with_law < 0.95 * lambert


@pytest.mark.slow
def test_speckled_sand_waves_beat_a_flat_seabed_because_pings_share_the_surface(monkeypatch):
    from sonar_raster.inversion.bottom import track_bottom

    # three speckle draws: one fit's outcome moves with small changes of the image (measured
    # 0.95 and 1.17 on one draw rendered by two raster paths 3.5e-5 apart), their mean less so
    shared, apart, flat = [], [], []
    for seed in (1, 2, 3):
        field, track, sides, alt, rb, spacing = _sand_line(seed)
        baseline = track_bottom(sides, rb).altitude
        fit = surface.fit_surface(sides, rb, ping_spacing=spacing, uncertainty=False)
        error, flat_error = _errors(fit, field, track, alt, baseline)
        shared.append(error)
        flat.append(flat_error)
        # without the prior that ties neighbouring pings' heights, each ping is fitted from its
        # own speckle
        with monkeypatch.context() as patch:
            patch.setattr(problem_module, "CURVATURE_STD_ALONG", 1e6)
            alone = surface.fit_surface(sides, rb, ping_spacing=spacing, uncertainty=False)
        apart.append(_errors(alone, field, track, alt, baseline)[0])
    print("shared", shared, "apart", apart, "flat", flat)
    assert np.mean(shared) < 0.8 * np.mean(flat)
    assert np.mean(apart) > np.mean(shared) + 0.15


def test_clean_sand_waves_come_out_at_their_level(monkeypatch):
    """On a clean image the first-return anchor holds the level against the data (its σ over
    √L, L the looks): the tracker reads the crests 4 cm above the waves' mean, the crest offset
    takes them off, and the fit keeps that. Measured: level +2.1 cm, score 0.68; with the
    single-look σ +4.8 cm, 1.05."""
    field, track, clean, alt, rb, spacing = _sand_render()
    sides = {k: v.astype(float) for k, v in clean.items()}

    def level_and_score():
        fit = surface.fit_surface(sides, rb, ping_spacing=spacing, uncertainty=False)
        keep = (fit.x > 1.0) & (fit.x < fit.x[-1] - 1.5)
        errors, truths = [], []
        for side, sign in (("port", -1.0), ("starboard", 1.0)):
            xx, yy = np.meshgrid(sign * fit.x[keep], track.positions[:, 1])
            truth = field.height_at(xx, yy) - alt
            errors.append(fit.elevation[side][:, keep] - truth)
            truths.append(truth)
        e, t = np.concatenate(errors, axis=1), np.concatenate(truths, axis=1)
        return float(np.mean(e)), float(np.sqrt(np.mean(e**2)) / np.std(t))

    level, score = level_and_score()
    assert abs(level) < 0.03 and score < 0.8
    single_look = problem_module.ANCHOR_BINS  # the σ a single look gets, at any looks
    monkeypatch.setattr(
        problem_module.Problem, "anchor_std", lambda self, view: single_look * view.anchor_bin
    )
    held_weakly = level_and_score()
    assert held_weakly[0] > level + 0.02 and held_weakly[1] > score + 0.2


@functools.cache
def _grid_render(alt: float, box: tuple[float, float, float] | None = None, trench: float = 0.0):
    """Both sides of 60 pings, 0.1 m apart at altitude ``alt``, over a flat, clean seabed with
    an optional box to starboard (centre and half-width across track, height; 3 m along) and
    two trenches along the track ``trench`` deep (σ 0.5 m, 5 m to starboard and 4 m to port);
    the track and the heightfield."""
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
    track = Trajectory.straight((0.0, 0.0, alt), 0.0, 0.1, 60)
    xx, yy = np.meshgrid(np.arange(641) * 0.05 - 16.0, np.arange(141) * 0.05 - 0.5)
    heights = np.zeros(xx.shape)
    if box is not None:
        cx, half, height = box
        heights[(np.abs(xx - cx) < half) & (np.abs(yy - 3.0) < 1.5)] = height
    heights -= trench * sum(np.exp(-((xx - c) ** 2) / (2 * 0.5**2)) for c in (5.0, -4.0))
    field = from_grid(heights, 0.05, 0.05, x0=-16, y0=-0.5)
    image = RasterRenderer().render(build_scene([field.mesh(0.5)]), sonar, track)
    return {k: v.astype(float) for k, v in image.sides.items()}, track, field


def _flat_render(alt: float):
    """Both sides of 60 pings over a flat, clean seabed at altitude ``alt``."""
    return _grid_render(alt)[0]


@pytest.mark.parametrize(
    ("alt", "mean_bound", "rms_bound"), [(6.0, 0.025, 0.03), (6.0125, 0.005, 0.008)]
)
def test_a_flat_seabed_comes_out_level(alt, mean_bound, rms_bound):
    """The model shares each return between the two nearest bin centres (a tent) where the
    renderer bins by boxes; compared with the image blurred by the same one-bin box, a flat
    seabed comes out at its level. Measured: first return on a bin edge -2.0 cm (-3.0 cm
    without the blur), a quarter bin in -0.1 cm, rms 0.45 cm (1.15 cm without)."""
    sides = _flat_render(alt)
    fit = surface.fit_surface(sides, 0.05, ping_spacing=0.1, uncertainty=False)
    keep = (fit.x > 0.5) & (fit.x < fit.x[-1] - 1.5)
    error = np.concatenate([fit.elevation[s][:, keep] + alt for s in fit.elevation])
    assert abs(float(np.mean(error))) < mean_bound
    assert float(np.sqrt(np.mean(error**2))) < rms_bound


def test_multigrid_preconditions_the_gauss_newton_matrix(monkeypatch):
    """Above ``AMG_KNOTS`` the steps' conjugate gradients use a multigrid V-cycle: a valid
    (symmetric) preconditioner that cuts the iterations (28 against 184 with the diagonal,
    printed with ``pytest -s``) and reaches the exact solution."""
    from scipy import sparse
    from scipy.sparse.linalg import LinearOperator, cg, spsolve

    problem, p, rng = _problem(0)
    h = solve._fisher_z(problem, p)
    lhs = (h + sparse.diags(1e-3 * h.diagonal())).tocsc()
    b = rng.normal(size=problem.nz)
    exact = spsolve(lhs, b)
    monkeypatch.setattr(solve, "AMG_KNOTS", 0)
    multigrid = solve._preconditioner(lhs)
    u, v = rng.normal(size=(2, problem.nz))
    assert u @ multigrid(v) == pytest.approx(v @ multigrid(u), rel=1e-8)  # symmetric
    assert u @ multigrid(u) > 0  # and positive
    counts = {}
    for name, apply in (("multigrid", multigrid), ("diagonal", None)):
        apply = apply or (lambda v: v / lhs.diagonal())
        steps = []
        x, info = cg(
            lhs, b, M=LinearOperator(lhs.shape, matvec=apply), rtol=1e-9, maxiter=5000,
            callback=steps.append,
        )  # fmt: skip
        assert info == 0
        np.testing.assert_allclose(x, exact, rtol=0, atol=1e-7 * np.abs(exact).max())
        counts[name] = len(steps)
    print("CG iterations to 1e-9:", counts)  # pytest -s shows them
    assert counts["multigrid"] * 3 < counts["diagonal"], counts


def test_the_line_prior_deflation_solves_its_directions_exactly():
    """The steps' preconditioner with the line-profile prior's strongest directions ``Q``
    solved exactly: on them it inverts the whole Gauss-Newton matrix ``A`` (``M⁻¹ A Q c = Q c``,
    which fails with a wrong ``Qᵀ H Q``), it is symmetric and positive, and CG with it reaches
    ``A``'s exact solution in fewer iterations than with the plain preconditioner (two
    overlapping lines: 9 against 20 to 1e-9, printed with ``pytest -s``)."""
    from scipy import sparse
    from scipy.sparse.linalg import LinearOperator, cg

    problem, p, rng = _problem(0, lines=2)
    problem.flat = p[: problem.nz].reshape(problem.kz)
    h = solve._fisher_z(problem, p)
    lhs = (h + sparse.diags(1e-3 * h.diagonal())).tocsc()
    nz = problem.nz
    matvec = functools.partial(solve._gn_matvec, problem, lhs)
    plain = solve._preconditioner(lhs)
    deflated = solve._deflated(problem, lhs, plain)
    q = problem.line_subspace()[0]
    assert 0 < q.shape[1] < nz
    c = rng.normal(size=q.shape[1])
    np.testing.assert_allclose(deflated(matvec(q @ c)), q @ c, rtol=0, atol=1e-8 * abs(q @ c).max())
    u, v = rng.normal(size=(2, nz))
    assert u @ deflated(v) == pytest.approx(v @ deflated(u), rel=1e-8)
    assert u @ deflated(u) > 0
    a = np.column_stack([matvec(e) for e in np.eye(nz)])
    b = rng.normal(size=nz)
    exact = np.linalg.solve(a, b)
    counts = {}
    for name, apply in (("deflated", deflated), ("plain", plain)):
        steps = []
        x, info = cg(
            LinearOperator((nz, nz), matvec=matvec), b, M=LinearOperator((nz, nz), matvec=apply),
            rtol=1e-9, maxiter=500, callback=steps.append,
        )  # fmt: skip
        assert info == 0
        np.testing.assert_allclose(x, exact, rtol=0, atol=1e-7 * np.abs(exact).max())
        counts[name] = len(steps)
    print("CG iterations to 1e-9:", counts)
    assert counts["deflated"] * 1.5 < counts["plain"], counts


def test_a_flat_seabed_comes_out_level_with_the_multigrid_steps(monkeypatch):
    """The whole fit with every Gauss-Newton step on the multigrid path: as level as with the
    LU (the quarter-bin case's bounds of the test above). It guards the path end to end; the
    preconditioner's quality is the test above's (backtracking and L-BFGS would carry the fit
    even with none)."""
    monkeypatch.setattr(solve, "AMG_KNOTS", 0)
    sides = _flat_render(6.0125)
    fit = surface.fit_surface(sides, 0.05, ping_spacing=0.1, uncertainty=False)
    keep = (fit.x > 0.5) & (fit.x < fit.x[-1] - 1.5)
    error = np.concatenate([fit.elevation[s][:, keep] + 6.0125 for s in fit.elevation])
    assert abs(float(np.mean(error))) < 0.005
    assert float(np.sqrt(np.mean(error**2))) < 0.008


def test_cli_surface_method_writes_both_sides_with_their_std(tmp_path):
    """... and takes an earlier run's beam profile (calibrated mode: its folder or a file)."""
    import json

    from sonar_raster.cli.app import main
    from sonar_raster.io.images import read_pixels

    image = tmp_path / "line.exr"
    assert main(["render", "default", "--pings", "12", "--ideal", "-q", "-o", str(image)]) == 0
    out = tmp_path / "seabed"
    args = ["invert", str(image), "--method", "surface", "--no-mesh", "--no-previews", "-q"]
    assert main([*args, "-o", str(out)]) == 0
    for side in ("port", "starboard"):
        names = {p.name for p in (out / side).iterdir()}
        assert {"elevation.exr", "elevation_std.exr", "reflectivity.exr"} <= names
    for beam in (out, out / "port" / "beam_profile.json"):
        again = tmp_path / f"again_{beam.suffix}"
        assert main([*args, "--beam", str(beam), "-o", str(again)]) == 0
        doc = json.loads((again / "starboard" / "inversion.json").read_text())
        assert doc["settings"]["calibrated"] is True
    for beam in (image, tmp_path):  # not a profile; a folder without one
        assert main([*args, "--beam", str(beam), "-o", str(tmp_path / "other")]) == 2
        assert not (tmp_path / "other").exists()
    # a coarser fit writes the same products at every ping and bin
    coarse = tmp_path / "coarse"
    assert main([*args, "--coarsen", "2", "-o", str(coarse)]) == 0
    doc = json.loads((coarse / "port" / "inversion.json").read_text())
    assert doc["settings"]["finest"] == 2
    shapes = [read_pixels(d / "port" / "elevation.exr")[0].shape for d in (out, coarse)]
    assert shapes[0] == shapes[1]
    profiles = ["invert", str(image), "--method", "profiles", "--coarsen", "2", "-q", "-o"]
    profiles.append(str(tmp_path / "other"))
    assert main(profiles) == 2  # the profile method's pyramid is --levels
    assert not (tmp_path / "other").exists()


def test_a_coarser_fit_comes_out_level_at_every_ping_and_bin():
    """``finest=2`` fits the images pooled 2 × 2 and returns Z and its std at every ping and
    ground cell of the images. At the finest level fitted the first-return anchor's σ is in the
    images' own bins: measured +1.4 cm (rms 1.6 cm) on a flat seabed a quarter bin in; with σ
    in that level's pooled bins it settles +3.8 cm high."""
    alt = 6.0125
    fit = surface.fit_surface(_flat_render(alt), 0.05, ping_spacing=0.1, finest=2)
    assert fit.altitude.shape == (60,)
    assert np.diff(fit.x) == pytest.approx(0.05)  # the images' ground cells, not pooled ones
    for side in ("port", "starboard"):
        assert fit.elevation[side].shape == fit.elevation_std[side].shape == (60, fit.x.size)
    keep = (fit.x > 0.5) & (fit.x < fit.x[-1] - 1.5)
    error = np.concatenate([fit.elevation[s][:, keep] + alt for s in fit.elevation])
    assert abs(float(np.mean(error))) < 0.025
    assert float(np.sqrt(np.mean(error**2))) < 0.025


def test_products_leave_out_the_swaths_edge_in_the_finest_levels_bins():
    """``invert`` gives no estimate within ``EDGE_BINS`` bins of the image's end, counted in
    the finest level's bins: 6 at full resolution, 12 with the images pooled 2 × 2."""
    from sonar_raster.inversion.surface import invert_line

    alt = 6.0
    sides = _flat_render(alt)
    bins = sides["port"].shape[1]
    for finest in (1, 2):
        result = invert_line(sides, 0.05, ping_spacing=0.1, finest=finest, uncertainty=False)
        for inv in result.values():
            known = np.isfinite(inv.elevation)
            slant = np.hypot(inv.x[None, :], inv.altitude[:, None])
            edge = (bins - solve.EDGE_BINS * finest) * 0.05
            assert known.any(axis=1).all()
            assert slant[known].max() < edge
            assert slant[~known & (inv.x[None, :] > 1.0)].min() >= edge


@pytest.mark.parametrize(("lines", "shadows"), [(1, False), (2, False), (1, True), (2, True)])
def test_fisher_jacobian_includes_the_beam_and_the_shadows(lines, shadows):
    """The Gauss-Newton Jacobian wrt the Z knots (R and Φ nodes held) equals the model image's
    central differences, the beam's change of depression angle and the cast shadows' change
    included (without the shadows' term: 47 % off on the shadowed case)."""
    from sonar_raster.inversion.model import forward
    from sonar_raster.inversion.surface.problem import soft_shadow

    problem, p, rng = _problem(2, shadows=shadows, lines=lines)
    start = problem.nz + problem.nr
    p[start:] += np.linspace(0.0, 3.0, p.size - start)  # a steep beam: ∂Φ/∂θ matters
    jacobians, _ = solve._jacobians(problem, p)
    assert len(jacobians) == 2 * lines
    shadowed = [
        (soft_shadow(problem.fields(p, v)[0], v.geom.x, v.tau)[2] > 0).any() for v in problem.views
    ]
    assert any(shadowed) == shadows
    for view, jac in zip(problem.views, jacobians, strict=True):

        def image(q, view=view):
            z, r, beam = problem.fields(q, view)
            shade = soft_shadow(z, view.geom.x, view.tau)[0]
            return forward(r * shade, beam.phi, z, view.geom) + view.floor

        mu = image(p)
        weight = np.sqrt(np.where(view.mask, view.looks / (mu * mu), 0.0)).ravel()
        direction = np.zeros(p.size)
        direction[: problem.nz] = rng.normal(0.0, 1.0, problem.nz)
        step = 1e-6
        numeric = (image(p + step * direction) - image(p - step * direction)) / (2 * step)
        analytic = jac @ direction[: problem.nz]
        expected = weight * numeric.ravel()
        assert np.abs(analytic - expected).max() < 2e-3 * np.abs(expected).max()


def test_cells_land_where_the_sonar_looked():
    """A line heading east: starboard cells lie south of the track, port cells north, in the
    lines' own frame, whatever the fit's frame (set by the first line, heading north-east)."""
    first = layout.Line({"port": np.ones((3, 10))}, 0.1, np.zeros((3, 2)), np.full(3, math.pi / 4))
    frame = layout.Frame.of([first])
    position = np.array([[10.0, 20.0], [11.0, 20.0]])
    heading = np.full(2, math.pi / 2)
    for side, north in (("starboard", 15.0), ("port", 25.0)):
        y, x = layout.cell_points(frame, position, heading, side, np.array([5.0]))
        world = frame.to_world(y, x)
        assert np.allclose(world[:, 0, 0], [10.0, 11.0])
        assert np.allclose(world[:, 0, 1], north)


def test_tensor_basis_is_the_kronecker_product_on_a_grid():
    extent = (0.0, 2.0, -3.0, 3.0)
    y, x = np.meshgrid(np.linspace(0.1, 1.9, 7), np.linspace(-2.9, 2.9, 9), indexing="ij")
    basis = layout.tensor_basis(y.ravel(), x.ravel(), extent, 0.5)
    by = layout.bspline_basis(y[:, 0], 0.0, 2.0, 0.5)
    bx = layout.bspline_basis(x[0], -3.0, 3.0, 0.5)
    assert np.allclose(basis.toarray(), np.kron(by.toarray(), bx.toarray()))


def test_freeing_the_reflectivity_widens_the_elevation_uncertainty():
    """With log R in the Laplace approximation (shading can be either), Z's marginal spread is
    at least its spread with R held: the marginal variance of a Gaussian is never below a
    conditional one."""
    problem, p, _ = _problem(3, shadows=False)
    free = solve.elevation_std(problem, p, samples=64, reflectivity=True)
    held = solve.elevation_std(problem, p, samples=64, reflectivity=False)
    ratio = [np.median(free[k] / held[k]) for k in free]
    assert min(ratio) > 1.05, ratio


def test_the_uncertainty_solves_every_sample_to_its_tolerance():
    """The Laplace draws (all samples solved together by block conjugate gradients on Z and
    log R) equal the direct solve of the precision to the solver's tolerance, column by column,
    and their spread is the one the precision implies."""
    problem, p, _ = _problem(3, shadows=False)
    h, rhs = solve.laplace_draws(problem, p, 400)
    x = solve._symmetric_solver(h, problem.nz)(rhs)
    exact = np.linalg.solve(h.toarray(), rhs)
    error = np.linalg.norm(x - exact, axis=0) / np.linalg.norm(exact, axis=0)
    assert error.max() < 0.05, error.max()
    residual = np.linalg.norm(h @ x - rhs, axis=0) / np.linalg.norm(rhs, axis=0)
    assert residual.max() < 1e-3, residual.max()
    # the draws' covariance is H⁻¹: their Z variances to the 400 samples' accuracy (~7 %)
    covariance = np.linalg.inv(h.toarray())
    ratio = np.var(exact[: problem.nz], axis=1) / np.diag(covariance)[: problem.nz]
    assert abs(np.median(ratio) - 1.0) < 0.05, np.median(ratio)


def test_nearest_ping_within_a_gap():
    found = np.array([0, 1, 0, 0, 1, 0, 0, 0, 0, 1, 0], bool)
    assert solve._nearest_within(found, 3).tolist() == [-1, 1, 1, 4, 4, -1, -1, -1, -1, 9, -1]
    assert solve._nearest_within(np.zeros(4, bool), 3).tolist() == [-1] * 4


#: Centre and half-width across track, and height of the box, metres.
BOX = (8.0, 1.0, 1.2)


def _box_render(looks: float):
    """Both sides of 60 pings at 6 m over a flat seabed with ``BOX`` to starboard, with
    ``looks``-look speckle (0: none), and the track."""
    clean, track, _ = _grid_render(6.0, BOX)
    if not looks:
        return clean, track
    rng = np.random.default_rng(7)
    return {k: v * rng.gamma(looks, 1.0 / looks, v.shape) for k, v in clean.items()}, track


@pytest.mark.parametrize("looks", [0.0, 1.0])
def test_an_object_grows_to_its_shadow_height(monkeypatch, looks):
    """From a flat start the shadow behind an object is cheaper to explain by a dark R or a
    hollow than by growing the object (no shadow, so no gradient towards one, until it is tall
    enough to cast it); starting the object at its shadow's height lets the fit keep it."""
    sides, track = _box_render(looks)

    def height(fit):
        xx, yy = np.meshgrid(fit.x, track.positions[:, 1])
        cx, half, _ = BOX
        on = (np.abs(xx - cx) < half - 0.2) & (np.abs(yy - 3.0) < 1.2)
        off = (xx > 2.0) & (xx < cx - half - 1.0)
        z = fit.elevation["starboard"]
        return float(np.mean(z[on]) - np.mean(z[off]))

    fit = surface.fit_surface(sides, 0.05, ping_spacing=0.1, uncertainty=False)
    with monkeypatch.context() as patch:
        patch.setattr(solve, "SHADOW_START_BINS", None)
        flat = surface.fit_surface(sides, 0.05, ping_spacing=0.1, uncertainty=False)
    print("with the shadow start", height(fit), "flat start", height(flat))
    assert height(fit) > 0.8 * BOX[2]
    assert height(flat) < height(fit) - 0.1


def test_a_lines_law_is_modelled_at_the_finest_level_only(monkeypatch):
    problem, _, _ = _problem(shadows=False, law=SAND)
    line = layout.Line(
        {v.side: v.image for v in problem.views}, 0.1, np.zeros((10, 2)), np.zeros(10), law=SAND
    )
    assert all(view.geom.law is SAND for view in solve.problem_at([line]).views)
    coarse = solve.problem_at([line], level=2).views
    assert all(view.geom.law is None for view in coarse)
    monkeypatch.setattr(solve, "LAW_AT_FINEST_ONLY", False)
    assert all(view.geom.law is SAND for view in solve.problem_at([line], level=2).views)


def test_shadow_start_skips_pings_without_a_first_return():
    sides, _ = _box_render(0.0)
    line = layout.Line.straight(sides, 0.05, 0.1, None)
    problem = solve.problem_at([line], level=2)
    whole = solve._shadow_start(problem)[0]
    for view in problem.views:
        view.altitude[5] = np.nan  # a glitch: find_shadows refuses NaN altitudes
    raised = solve._shadow_start(problem)[0]
    assert whole.max() == pytest.approx(BOX[2], abs=0.1)
    assert raised.max() == pytest.approx(whole.max(), abs=0.05)


def test_the_fit_reports_every_gauss_newton_step():
    """A long fit says where it is: one line per Gauss-Newton step of each level, then the
    uncertainty's size, then the total time."""
    rng = np.random.default_rng(0)
    pings, bins, rb = 12, 120, 0.05
    image = rng.gamma(1.0, 1.0, (pings, bins)) * (np.arange(bins) * rb > 3.0)
    lines: list[str] = []
    surface.fit_surface(
        {"port": image},
        rb,
        ping_spacing=0.1,
        altitude=np.full(pings, 3.0),
        levels=2,
        progress=lines.append,
    )
    steps = solve.GAUSS_NEWTON_STEPS
    for level in ("level 1/2 (1/2 res.)", "level 2/2 (1/1 res.)"):
        found = [x for x in lines if x.startswith(f"{level}: Gauss-Newton step")]
        assert [x.split("step ")[1].split(",")[0] for x in found] == [
            f"{k}/{steps}" for k in range(1, steps + 1)
        ]
    assert any(x.startswith("uncertainty of Z") for x in lines)
    assert lines[-1].startswith("done in")


# -- calibrated mode: a beam profile from an earlier fit held in shape --------------------------
def _trench_line(depth: float, seed: int):
    """:func:`_grid_render`'s trenches at 6 m, single-look speckle drawn from ``seed``."""
    clean, track, field = _grid_render(6.0, None, depth)
    rng = np.random.default_rng(seed)
    return {k: v * rng.gamma(1.0, 1.0, v.shape) for k, v in clean.items()}, track, field


@pytest.mark.slow
def test_a_calibrated_beam_lets_single_look_trenches_along_the_track_be_seen():
    """Relief every ping shares (a trench along the track) shades the image as a beam change
    would, so with Φ free the fit keeps it in Φ; with the shape of a profile fitted to a flat
    seabed (the same sonar, its own speckle) it goes into Z. Z RMSE / relief std on the two
    draws: calibrated 0.76 / 0.68, free 0.99 / 0.97 (a third draw with its own calibration,
    a one-off run: 0.85 / 1.00); with the beam ignored both are the free values."""
    options = {"ping_spacing": 0.1, "uncertainty": False}
    flat = surface.fit_surface(_trench_line(0.0, 1)[0], 0.05, **options)
    beam = {side: BeamProfile(*flat.profile[side]) for side in flat.profile}
    level = np.full(60, 6.0)  # _errors' flat baseline, unused here
    free, calibrated = [], []
    for seed in (2, 4):
        sides, track, field = _trench_line(0.25, seed)
        fit = surface.fit_surface(sides, 0.05, **options)
        free.append(_errors(fit, field, track, 6.0, level)[0])
        fit = surface.fit_surface(sides, 0.05, beam=beam, **options)
        calibrated.append(_errors(fit, field, track, 6.0, level)[0])
    print("calibrated", calibrated, "free", free)
    assert np.mean(calibrated) < 0.85
    assert np.mean(calibrated) < np.mean(free) - 0.15


def test_beam_reference_holds_a_profile_where_its_angles_reach():
    problem, _, _ = _problem(shadows=False)
    theta = np.linspace(*problem.grid.angles, problem.grid.nodes)
    half = BeamProfile(theta[: theta.size // 2], np.exp(np.sin(theta[: theta.size // 2])))
    references = solve.beam_reference(problem.grid, half)
    assert set(references) == {"port", "starboard"}  # one profile for every side
    target, held = references["port"]
    assert held[: theta.size // 2].all() and not held[theta.size // 2 + 1 :].any()
    np.testing.assert_allclose(target[held > 0], np.sin(theta[held > 0]), atol=1e-12)
    assert set(solve.beam_reference(problem.grid, {"starboard": half})) == {"starboard"}
    with pytest.raises(SonarRasterError, match="calibrate on a line of similar altitude"):
        solve.beam_reference(problem.grid, BeamProfile(np.array([1.6, 1.7]), np.ones(2)))


def test_beam_of_an_earlier_runs_folder(tmp_path):
    """``--beam`` takes a profile file (every side) or the folder of an earlier single-image,
    XTF or survey-lines run (one per side)."""
    from sonar_raster.inversion.solver import load_beams

    profile = BeamProfile(np.array([0.3, 1.2]), np.array([1.0, 2.0]))
    for folder in ("single/port", "single/starboard", "survey/line_1/port", "one_side"):
        (tmp_path / folder).mkdir(parents=True)
        profile.save(tmp_path / folder / "beam_profile.json")
    assert set(load_beams(str(tmp_path / "single"))) == {"port", "starboard"}
    assert set(load_beams(str(tmp_path / "survey"))) == {"port"}
    assert isinstance(load_beams(str(tmp_path / "one_side")), BeamProfile)
    assert isinstance(load_beams(str(tmp_path / "one_side" / "beam_profile.json")), BeamProfile)
    with pytest.raises(SonarRasterError, match="holds no beam_profile.json"):
        load_beams(str(tmp_path))


def test_the_flat_start_follows_each_pings_first_return_and_is_level_across():
    """A line whose first return climbs 0.5 m along it (a straight ramp, which the start's
    penalties leave alone): the start's knots reproduce it at every nadir and are flat across
    the track, knots that no nadir sees included. Fails without the across-track penalty."""
    pings, bins, rb = 40, 110, 0.1
    altitude = np.linspace(5.0, 5.5, pings)
    images = {side: np.ones((pings, bins)) for side in ("port", "starboard")}
    position = np.stack([np.zeros(pings), np.arange(pings) * 0.2], axis=1)
    line = layout.Line(images, rb, position, np.zeros(pings), altitude)
    problem = solve.problem_at([line], looks=1.0, z_knot=0.4, r_knot=0.4)
    knots = problem_module.flat_start_knots(problem.views, problem.grid, problem.kz)
    for view in problem.views:
        np.testing.assert_allclose(view.nadir @ knots.ravel(), view.height - altitude, atol=1e-4)
    inner = knots[2:-2]  # the ends' knots carry the spline's extrapolation along the track
    assert np.ptp(inner, axis=1).max() < 1e-4
    assert np.ptp(inner[:, 0]) > 0.4  # the ramp is there


def test_the_cells_spread_is_the_sample_std_of_their_interpolated_draws():
    """:func:`solve.draws_std` (centred draws interpolated in float32) equals each cell's
    sample standard deviation (ddof 1) of its interpolated Z over the draws, to float32's
    rounding, with the draws 12 m deep (their level is taken off before the float32 cast)."""
    problem, _, rng = _problem(3, shadows=False)
    knots = rng.normal(0.0, 0.05, (problem.nz, 9)) + 12.0
    spread = solve.draws_std(problem, knots)
    for view in problem.views:
        expected = np.std(np.asarray(view.bz @ knots), axis=1, ddof=1).reshape(view.shape)
        got = spread[(view.line, view.side)]
        assert got.dtype == np.float64 and got.shape == view.shape
        np.testing.assert_allclose(got, expected, rtol=1e-5)


@pytest.mark.parametrize("lines", [1, 2])
def test_the_beams_fisher_blocks_are_the_images_central_differences(lines):
    """``H_zΦ`` and ``H_ΦΦ`` of the joint Gauss-Newton step: the model image's central
    differences wrt the log Φ nodes, against the Z Jacobian (tested above), plus the priors'
    Hessian on log Φ (their curvature and a calibrated shape: against the priors' gradient's
    central differences)."""
    from sonar_raster.inversion.model import forward

    problem, p, rng = _problem(3, lines=lines)
    start = problem.nz + problem.nr
    p[start:] += np.linspace(0.0, 3.0, p.size - start)
    held = np.zeros(problem.grid.nodes)
    held[2:-3] = 1.0
    problem.beam_reference = {"starboard": (rng.normal(0.0, 0.3, held.size) * held, held)}
    hzz, hzphi, hphi = solve._fisher_z_beam(problem, p)
    assert np.allclose(hzz.toarray(), solve._fisher_z(problem, p).toarray())
    jz, _ = solve._jacobians(problem, p)
    cross, data = np.zeros(hzphi.shape), np.zeros(hphi.shape)
    for view, jac in zip(problem.views, jz, strict=True):

        def image(q, view=view):
            z, r, beam = problem.fields(q, view)
            shade = soft_shadow(z, view.geom.x, view.tau)[0]
            return (forward(r * shade, beam.phi, z, view.geom) + view.floor).ravel()

        mu = image(p)
        weight = np.sqrt(np.where(view.mask.ravel(), view.looks / (mu * mu), 0.0))
        numeric = np.empty((mu.size, p.size - start))
        for k in range(p.size - start):
            q = p.copy()
            q[start + k] += 1e-6
            up = image(q)
            q[start + k] -= 2e-6
            numeric[:, k] = weight * (up - image(q)) / 2e-6
        cross += np.asarray(jac.T @ numeric)
        data += numeric.T @ numeric
    scale = np.abs(data).max()
    assert np.allclose(hzphi.toarray(), cross, atol=1e-6 * np.abs(cross).max())

    def phi_gradient(q):
        grad = np.zeros_like(q)
        zc, rc, lphi = problem.split(q)
        problem.reflectivity_beam_priors(rc, lphi, grad)
        return grad[start:]

    prior = np.empty(hphi.shape)
    for k in range(p.size - start):
        q = p.copy()
        q[start + k] += 1e-4
        up = phi_gradient(q)
        q[start + k] -= 2e-4
        prior[:, k] = (up - phi_gradient(q)) / 2e-4
    assert np.abs(prior).max() > 0.1 * scale  # the priors weigh in the check
    assert np.allclose(hphi, data + prior, atol=1e-6 * np.abs(data + prior).max())


def test_the_joint_step_solves_the_whole_z_and_beam_system():
    """Φ eliminated (:func:`solve._schur`) gives the step of the joint system solved whole,
    and :func:`solve._model_curvature` is that system's quadratic form."""
    problem, p, rng = _problem(4)
    nz, start = problem.nz, problem.nz + problem.nr
    _, grad = problem(p)
    hzz, hzphi, hphi = solve._fisher_z_beam(problem, p)
    lhs = (hzz + sparse.diags(1e-3 * hzz.diagonal())).tocsc()
    line = np.column_stack(
        [problem_module.line_profile(problem, e)[1] for e in np.eye(nz)]
    )  # the line prior is quadratic: its gradient at a unit vector is a column of its Hessian
    whole = np.block([[lhs.toarray() + line, hzphi.toarray()], [hzphi.T.toarray(), hphi]])
    expected = np.linalg.solve(whole, -np.concatenate([grad[:nz], grad[start:]]))
    matvec, rhs, back = solve._schur(problem, lhs, hzphi, hphi, grad[:nz], grad[start:])
    schur = np.column_stack([matvec(e) for e in np.eye(nz)])
    dz = np.linalg.solve(schur, rhs)
    assert np.allclose(dz, expected[:nz], rtol=1e-6, atol=1e-9 * np.abs(expected).max())
    assert np.allclose(back(dz), expected[nz:], rtol=1e-6, atol=1e-9 * np.abs(expected).max())
    # the trust region's predicted decrease uses the same matrix's quadratic form
    s = rng.normal(size=whole.shape[0])
    curve = solve._model_curvature(problem, lhs, hzphi, hphi, s[:nz], s[nz:])
    assert curve == pytest.approx(s @ whole @ s, rel=1e-9)


def test_the_joint_steps_reach_a_lower_objective_than_steps_on_z_alone(monkeypatch):
    """Φ shared by every ping and Z's bends that every ping shares trade off; stepping on Z
    with Φ held crawls along that valley. Measured on this speckled line: E −66 545 joint
    (within its one-bin trust region; −66 554 uncapped) against −66 480 with Z alone (the same
    number of steps)."""
    _, _, sides, _, rb, spacing = _sand_line(0)
    final = {}
    for joint in (False, True):
        monkeypatch.setattr(solve, "JOINT_BEAM", joint)
        fit = surface.fit_surface(sides, rb, ping_spacing=spacing, uncertainty=False)
        final[joint] = fit.energies[-1]
    assert final[True] < final[False] - 30.0


@pytest.mark.parametrize(
    ("rho", "backtracked", "capped", "expected"),
    [
        (0.9, False, True, 2.0),  # the radius bound a well-predicted step: grow
        (0.9, False, False, 1.0),  # it did not bind: keep
        (0.5, False, True, 1.0),  # fair prediction: keep
        (0.1, False, True, 0.5),  # poor prediction: shrink
        (0.9, True, True, 0.5),  # the full step raised E: shrink
        (0.0, True, False, 0.5),  # rejected
    ],
)
def test_the_trust_radius_follows_the_models_prediction(rho, backtracked, capped, expected):
    assert solve._trust_radius(1.0, rho, backtracked, capped) == expected
    assert solve._trust_radius(0.25, 0.0, True, False) == 0.25  # a floor


def test_a_trust_radius_that_grows_reaches_a_lower_objective_than_one_held(monkeypatch):
    """The radius starts at one bin (a clean flat seabed needs it, the tests above), but held
    there the joint steps stop short where the model predicts well. Measured on this speckled
    line: E −68 230 against −68 178 with the radius held at one bin (single-look sand waves on
    the bench: 0.51 against 0.76 × relief std)."""
    _, _, sides, _, rb, spacing = _sand_line(1)
    final = {}
    for held in (False, True):
        if held:
            monkeypatch.setattr(solve, "_trust_radius", lambda radius, *args: radius)
        fit = surface.fit_surface(sides, rb, ping_spacing=spacing, uncertainty=False)
        final[held] = fit.energies[-1]
    print(final)
    assert final[False] < final[True] - 25.0


def test_a_joint_step_falls_back_to_z_alone_where_the_beams_block_is_singular(monkeypatch):
    problem, p, _ = _problem(5, shadows=False)
    before = problem(p)[0]

    def singular(*args):
        raise np.linalg.LinAlgError("not positive definite")

    monkeypatch.setattr(solve, "_schur", singular)
    q, value, _ = solve._gauss_newton(problem, p, 2, joint=True)
    assert value < before
    assert np.any(q[: problem.nz] != p[: problem.nz])


@pytest.mark.parametrize(("finest", "joint"), [(1, True), (2, True), (4, False)])
def test_fits_pooled_more_than_twice_step_on_z_alone(monkeypatch, finest, joint):
    """With Φ following Z the level rests on the first return less its crests, which knots
    four pooled bins apart cannot show (sand waves at --coarsen 4 came out at their crests).
    Fits pooled 4 × 4 measure the crests at the nadir itself (moved, they scored worse)."""
    seen, moved = [], []
    plain = solve._gauss_newton

    def record(*args, joint=False, shifts=None, **kwargs):
        seen.append(joint)
        moved.append(shifts)
        return plain(*args, joint=joint, shifts=shifts, **kwargs)

    monkeypatch.setattr(solve, "_gauss_newton", record)
    monkeypatch.setattr(solve, "GAUSS_NEWTON_STEPS", 1)
    monkeypatch.setattr(solve, "JOINT_BEAM", True)
    line = layout.Line.straight(_flat_render(6.0), 0.05, 0.1)
    solve.fit_lines([line], finest=finest, uncertainty=False)
    assert seen == [joint, joint]
    assert moved == [solve.CREST_SHIFTS if finest <= 2 else None] * 2
