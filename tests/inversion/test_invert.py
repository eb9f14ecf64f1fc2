"""Inversion: exact gradient, slant/ground conversion, round trips and numerical stability."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sonar_raster.errors import SonarRasterError
from sonar_raster.inversion.bottom import track_side
from sonar_raster.inversion.em import Problem, Steps, _search_direction
from sonar_raster.inversion.ground import ground_to_slant, slant_to_ground
from sonar_raster.inversion.model import (
    Geometry,
    energy,
    evaluate,
    forward,
    jacobian_z,
    slope,
    slope_adjoint,
)
from sonar_raster.inversion.priors import estimate_looks, slope_hessian, slope_roughness
from sonar_raster.inversion.solver import BeamProfile, invert
from sonar_raster.scene import build_scene
from sonar_raster.scenes.seabed import from_grid, make_seabed
from sonar_raster.sonar import BeamPattern, Sonar
from sonar_raster.trajectory import Trajectory

ALT = 10.0
PINGS = 32
SPACING = 0.1
SONAR = Sonar(
    max_range=20.0,
    range_bin=0.05,
    beam=BeamPattern.gaussian(50.0),
    tilt=math.radians(20.0),
    sides=("starboard",),
)
TRACK = Trajectory.straight((0.0, -1.6, ALT), 0.0, SPACING, PINGS)


def _render(renderer, heightfield, reflectivity=0.5) -> np.ndarray:
    scene = build_scene([heightfield.mesh(reflectivity)])
    return renderer.render(scene, SONAR, TRACK).sides["starboard"].astype(np.float64)


def _truth(heightfield, x: np.ndarray) -> np.ndarray:
    y = TRACK.positions[:, 1]
    xx, yy = np.meshgrid(x, y)
    return heightfield.height_at(xx, yy) - ALT


def _true_profile() -> BeamProfile:
    dep = np.linspace(0.05, math.pi / 2, 400)
    return BeamProfile(dep, SPACING * SONAR.gain(dep))


def _z_rmse(inv, truth) -> float:
    ok = np.isfinite(inv.elevation)
    return float(np.sqrt(np.mean((inv.elevation - truth)[ok] ** 2)))


def _monotone(inv) -> None:
    for e in inv.energies:
        assert np.all(np.diff(e) <= 1e-12 * e[0])


@pytest.fixture(scope="module")
def ripples():
    return make_seabed(
        "ripples",
        size=(30.0, 8.0),
        center=(12.0, 0.0),
        resolution=0.05,
        wavelength=1.0,
        amplitude=0.05,
        direction_deg=90.0,
        seed=1,
    )


@pytest.fixture(scope="module")
def ripple_image(gl_renderer, ripples):
    return _render(gl_renderer, ripples)


@pytest.mark.parametrize(
    ("smooth", "edge", "subsamples"), [(0.0, 0.0, 1), (3.0, 0.0, 1), (3.0, 0.05, 1), (0.0, 0.0, 3)]
)
def test_gradient_matches_central_differences(smooth, edge, subsamples):
    # subsamples > 1: each cell's return spread over points of its tangent plane, whose ranges
    # move with the cell's slope too.
    rng = np.random.default_rng(3)
    shape = (5, 7)
    geom = Geometry((np.arange(7) + 0.5) * 0.5 + 1.0, 0.5, 0.4, 0.2, 60, subsamples)
    args = {
        "r": rng.uniform(0.3, 1.0, shape),
        "phi": rng.uniform(0.5, 2.0, shape),
        "z": -10.0 + 0.2 * rng.standard_normal(shape),
    }
    image = rng.uniform(0.0, 1.0, (5, 60))
    weight = (rng.uniform(size=(5, 60)) > 0.1) * 1.0
    ev = evaluate(image, weight, geom=geom, smooth=smooth, edge=edge, **args)
    for name, grad in (("r", ev.grad_r), ("phi", ev.grad_phi), ("z", ev.grad_z)):
        num = np.zeros(shape)
        for idx in np.ndindex(shape):
            h = 1e-6 * max(1.0, abs(args[name][idx]))
            e = []
            for sign in (1.0, -1.0):
                moved = dict(args)
                moved[name] = args[name].copy()
                moved[name][idx] += sign * h
                e.append(energy(image, weight, geom=geom, smooth=smooth, edge=edge, **moved))
            num[idx] = (e[0] - e[1]) / (2 * h)
        assert np.max(np.abs(grad - num)) <= 1e-4 * np.max(np.abs(num))
    # The sparse Jacobian of the Levenberg-Marquardt step carries the same data terms.
    jac = jacobian_z(weight, geom=geom, **args)
    res = np.sqrt(weight) * (forward(geom=geom, **args) - image)
    data_grad = ev.grad_z if smooth == 0.0 else evaluate(image, weight, geom=geom, **args).grad_z
    assert np.allclose(2.0 * jac.T @ res.ravel(), data_grad.ravel(), rtol=1e-8, atol=1e-10)


def test_beam_curvature_gradient_matches_central_differences():
    rng = np.random.default_rng(5)
    shape = (4, 6)
    geom = Geometry((np.arange(6) + 0.5) * 0.5 + 1.0, 0.5, 0.4, 0.2, 60)
    bins = np.repeat(np.arange(6)[None, :], 4, axis=0)
    prob = Problem(
        rng.uniform(0.0, 1.0, (4, 60)),
        np.ones((4, 60)),
        geom,
        bins,
        np.arange(24),
        smooth=0.5,
        smooth_phi=7.0,
    )
    r, phi = rng.uniform(0.3, 1.0, 24), rng.uniform(0.5, 2.0, 6)
    z = -10.0 + 0.2 * rng.standard_normal(shape)
    dirs, slope_ = _search_direction(prob, r, phi, z, Steps(0.0, 1.0, 0.0))
    h = 1e-6
    num = (prob.energy(r, phi + h * dirs[1], z) - prob.energy(r, phi - h * dirs[1], z)) / (2 * h)
    assert slope_ == pytest.approx(num, rel=1e-5)


@pytest.mark.parametrize("steps", [Steps(1.0, 0.0, 0.0), Steps(0.0, 0.0, 1.0)])
def test_prior_gradients_match_central_differences(steps):
    # Edge-preserving R roughness, the flat-seabed prior on Z (low-pass of Z − Z_ref, zero
    # padded, σ of 1.5 pings and 2 cells) and the slope prior: the slope of E along the search
    # direction (gradient · direction) must match a central difference of E.
    rng = np.random.default_rng(9)
    geom = Geometry((np.arange(6) + 0.5) * 0.5 + 1.0, 0.5, 0.4, 0.2, 60)
    bins = np.repeat(np.arange(6)[None, :], 4, axis=0)
    z0 = np.full((4, 6), -10.0)
    prob = Problem(
        rng.uniform(0.0, 1.0, (4, 60)),
        np.ones((4, 60)),
        geom,
        bins,
        np.arange(24),
        smooth=0.5,
        edge=0.05,
        flat=2.0,
        flat_sigma=(1.5, 2.0),
        z_ref=z0 + 0.1,
        slopes=0.3,
    )
    r, phi = rng.uniform(0.3, 1.0, 24), rng.uniform(0.5, 2.0, 6)
    z = z0 + 0.2 * rng.standard_normal((4, 6))
    dirs, slope_ = _search_direction(prob, r, phi, z, steps)
    h = 1e-6
    up = prob.energy(r + h * dirs[0], phi, z + h * dirs[2])
    down = prob.energy(r - h * dirs[0], phi, z - h * dirs[2])
    assert slope_ < 0
    assert slope_ == pytest.approx((up - down) / (2 * h), rel=1e-5)


def test_slope_roughness_gradient_and_hessian():
    # Σ (∂Z/∂x)² + (∂Z/∂y)² is quadratic: value and gradient by finite differences; the full
    # Hessian (gradient differences along unit vectors, exact) must equal the across-track part
    # of slope_hessian within each ping, and its diagonal the across part's plus ``along``.
    rng = np.random.default_rng(12)
    shape = (5, 7)
    z, v = rng.standard_normal(shape), rng.standard_normal(shape)
    value, grad = slope_roughness(z, 0.3, 0.7)
    across, along = slope_hessian(shape, 0.3, 0.7)
    ax, ay = np.diff(z, axis=1) / 0.3, np.diff(z, axis=0) / 0.7
    assert value == pytest.approx(np.sum(ax**2) + np.sum(ay**2), rel=1e-12)
    h = 1e-6
    up, down = slope_roughness(z + h * v, 0.3, 0.7)[0], slope_roughness(z - h * v, 0.3, 0.7)[0]
    assert np.sum(grad * v) == pytest.approx((up - down) / (2 * h), rel=1e-7)
    full = np.stack(
        [(slope_roughness(z + e.reshape(shape), 0.3, 0.7)[1] - grad).ravel() for e in np.eye(35)]
    )
    same_ping = np.equal.outer(np.arange(35) // 7, np.arange(35) // 7)
    within = np.where(same_ping, full, 0.0) - np.diag(along.ravel())
    np.testing.assert_allclose(across.toarray(), within, atol=1e-9)
    np.testing.assert_allclose(np.diag(full), across.diagonal() + along.ravel(), rtol=1e-12)
    assert np.allclose(full @ np.ones(35), 0.0, atol=1e-9)  # a level shift costs nothing


@pytest.mark.parametrize("axis", [0, 1])
def test_slope_adjoint_is_the_transpose(axis):
    rng = np.random.default_rng(4)
    a, b = rng.standard_normal((6, 5)), rng.standard_normal((6, 5))
    lhs = np.sum(slope(a, axis, 0.3) * b)
    assert lhs == pytest.approx(np.sum(a * slope_adjoint(b, axis, 0.3)), rel=1e-12)


def test_slant_ground_round_trip():
    alt = np.array([5.0, 5.5, 6.0, 6.5])
    x = (np.arange(300) + 0.5) * 0.05
    ground = 1.0 + 0.3 * np.sin(x / 0.4 + np.arange(4)[:, None])
    slant = ground_to_slant(ground, x, alt, 0.05, 400)
    back, valid = slant_to_ground(slant, 0.05, alt, x)
    inner = valid & (x > 2.0) & (x < 14.0)
    assert np.all(slant[:, :99] == 0)
    assert np.max(np.abs(back - ground)[inner]) < 0.02


@pytest.mark.parametrize("looks", [None, 1.0])
def test_first_return_robust_to_noisy_water_column(looks):
    rng = np.random.default_rng(6)
    r = (np.arange(400) + 0.5) * 0.05
    alt = 6.0 + 0.2 * np.sin(np.arange(40) / 15.0)
    slant = np.where(r[None, :] > alt[:, None], 1.0, 0.0) + 0.01 * rng.random((40, 400))
    slant[7, 20] = 5.0  # a fish in one ping (the trimmed mean over 9 pings drops it)
    found = track_side(slant, 0.05, looks=looks).altitude  # looks=1: 9 pings averaged
    assert np.max(np.abs(found - alt)) < 0.1


@pytest.mark.xfail(
    strict=True,
    reason="bars of the former half-rise detector, which sat exactly on an edge at a bin's start "
    "(and up to 0.45 bin early elsewhere); the merged tracker measures mean +17 mm, std 6.8 mm, "
    "rms 18.5 mm pooled against 22.6 mm alone (unbiased over the bin, see test_bottom.py)",
)
def test_first_return_on_speckle_averages_pings():
    # A flat seabed's step (fading with range) under single-look speckle: alone, each ping's
    # edge comes late where the first seabed bins draw dark values; the trimmed mean over 9
    # pings steadies it.
    rng = np.random.default_rng(13)
    r = (np.arange(400) + 0.5) * 0.05
    mean = np.where(r > 6.0, np.exp(-(r - 6.0) / 8.0), 0.0)
    slant = mean[None, :] * rng.exponential(1.0, (200, 400)) + 1e-4 * rng.random((200, 400))
    alone = track_side(slant, 0.05, looks=math.inf).altitude - 6.0
    pooled = track_side(slant, 0.05).altitude - 6.0
    # Measured with the former detector: alone 8.8 ± 14.3 mm, pooled 3.6 ± 7.0 mm.
    assert abs(np.mean(pooled)) < 0.1 * 0.05 and np.std(pooled) < 0.2 * 0.05
    assert np.sqrt(np.mean(pooled**2)) < 0.6 * np.sqrt(np.mean(alone**2))


@pytest.mark.xfail(
    strict=True,
    reason="a step of constant height in slant range is no nadir return (over a seabed each bin "
    "holds the ground between its ranges, a caustic at the edge): the merged tracker's nadir "
    "model places it 0.28, 0.24, 0.19 and 0.11 bin late at 0, 0.2, 0.5 and 0.8 "
    "(test_first_return_finds_a_nadir_edge_inside_its_bin is the seabed's case)",
)
@pytest.mark.parametrize("fraction", [0.0, 0.2, 0.5, 0.8])
def test_first_return_finds_a_sharp_edge_inside_its_bin(fraction):
    # A step of constant height starting a fraction of the way into a bin: the detector must
    # place it there (the Gaussian-smoothed low-threshold crossing alone was a bin early).
    rng = np.random.default_rng(8)
    edges = np.arange(401) * 0.05
    alt = 6.0 + fraction * 0.05
    step = np.clip((edges[1:] - alt) / 0.05, 0.0, 1.0)
    slant = step[None, :] * np.ones((12, 1)) + 0.002 * rng.random((12, 400))
    assert np.max(np.abs(track_side(slant, 0.05).altitude - alt)) < 0.1 * 0.05


@pytest.mark.parametrize("fraction", [0.0, 0.2, 0.5, 0.8])
def test_first_return_finds_a_nadir_edge_inside_its_bin(fraction):
    # A flat seabed starting a fraction of the way into a bin: bin k holds the ground between
    # its ranges, ∫ G dx over x = √(r² − h²), here with G = exp(0.3 x) (x in metres, a beam
    # brightening away from nadir), plus the same noise as above.
    rng = np.random.default_rng(8)
    alt = 6.0 + fraction * 0.05
    x = np.sqrt(np.maximum((np.arange(401) * 0.05) ** 2 - alt**2, 0.0))
    slant = np.diff(np.exp(0.3 * x) / 0.3)[None, :] * np.ones((12, 1))
    slant += 0.002 * rng.random((12, 400))
    assert np.max(np.abs(track_side(slant, 0.05).altitude - alt)) < 0.1 * 0.05


def test_flat_seabed_stays_flat_and_recovers_the_beam(gl_renderer):
    flat = make_seabed("flat", size=(40.0, 8.0), center=(12.0, 0.0))
    inv = invert(_render(gl_renderer, flat), SONAR.range_bin, ping_spacing=SPACING, max_iter=40)
    assert _z_rmse(inv, -ALT) < 0.01 * ALT
    # The absolute level comes from the first return: within 1 cm (it was 3 cm early when the
    # smoothed low-threshold crossing was taken as the edge).
    assert abs(np.nanmean(inv.elevation) + ALT) < 0.01
    dep = inv.profile.depression
    keep = (dep > math.radians(30)) & (dep < math.radians(80))
    corr = np.corrcoef(inv.profile.gain[keep], SONAR.gain(dep[keep]))[0, 1]
    assert corr > 0.99
    _monotone(inv)


@pytest.mark.xfail(
    strict=True,
    reason="bars of the former half-rise detector, exact at 10 m because the edge lies at a bin's "
    "start; the merged tracker measures 11.2 mm rms (6.3 mm without averaging) with this draw "
    "(11-22 mm over four draws: single-look speckle leaves the place in the bin uncertain)",
)
def test_speckled_image_finds_the_altitude_on_averaged_pings(gl_renderer):
    # Single-look speckle over a flat seabed: per ping the first return comes late by up to
    # 3.7 cm with this draw, 1.4 cm rms (2.8 ± 1.7 cm on tools/bench_inversion.py's flat
    # render); invert's estimated looks (about 1) make it average 9 pings: 0.34 cm rms.
    flat = make_seabed("flat", size=(40.0, 8.0), center=(12.0, 0.0))
    clean = _render(gl_renderer, flat)
    image = clean * np.random.default_rng(17).exponential(1.0, clean.shape)
    inv = invert(image, SONAR.range_bin, ping_spacing=SPACING, max_iter=2, levels=1)
    assert inv.settings["looks"] == pytest.approx(1.0, rel=0.15)
    alone = track_side(image, SONAR.range_bin, looks=math.inf).altitude - ALT
    assert np.sqrt(np.mean((inv.altitude - ALT) ** 2)) < 0.005
    assert np.sqrt(np.mean((inv.altitude - ALT) ** 2)) < 0.5 * np.sqrt(np.mean(alone**2))


@pytest.mark.parametrize("water", [0.0, 0.1])
def test_invert_altitude_anywhere_in_the_bin(gl_renderer, water):
    # 10.03 m puts the first return 0.6 of the way into its bin. Clean: within a twentieth of
    # a bin (measured 0.006; the former half-rise detector was 0.39 bin early, the log-step
    # one 0.19). With water-column noise at 10 % of the seabed level and bright specks (no
    # speckle): within half a bin, mean within 0.15 (measured +0.00, largest 0.13; the
    # half-rise detector lost pings by 22 bins).
    height = ALT + 0.03
    track = Trajectory.straight((0.0, -1.6, height), 0.0, SPACING, PINGS)
    flat = make_seabed("flat", size=(40.0, 8.0), center=(12.0, 0.0))
    image = gl_renderer.render(build_scene([flat.mesh(0.5)]), SONAR, track).sides["starboard"]
    image = image.astype(np.float64)
    rng = np.random.default_rng(5)
    level = float(image[:, 200:210].mean())
    image += water * level * rng.exponential(size=image.shape)
    specks = rng.random(image.shape) < 0.002 * (water > 0)
    image[specks] += 3.0 * level * rng.exponential(size=int(specks.sum()))
    inv = invert(image, SONAR.range_bin, ping_spacing=SPACING, max_iter=1, levels=1)
    err = (inv.altitude - height) / SONAR.range_bin
    assert np.max(np.abs(err)) <= (0.5 if water else 0.05)
    assert abs(np.mean(err)) <= 0.15


def test_ripple_round_trip(ripple_image, ripples):
    inv = invert(ripple_image, SONAR.range_bin, ping_spacing=SPACING, max_iter=100)
    truth = _truth(ripples, inv.x)
    # Reached today: 0.53 of the relief's std (0.50 without the constant offset: the first
    # return comes from the crests near nadir, 3.8 cm above the trough under the track, so the
    # first-return altitude is not the mean level; see the strict xfail below for the target).
    assert _z_rmse(inv, truth) < 0.7 * np.std(truth)
    _monotone(inv)


def test_ripple_round_trip_with_altitude_and_flat_prior(ripple_image, ripples):
    # The best measured free setting: the true altitude (an altimeter's, instead of the first
    # return, which sits in the trough under the track, 3 cm below the mean level) and the
    # flat-seabed prior, with the default looks="auto" (1933 looks estimated on this render:
    # weak relief and slope priors, whose along-track slope term ties the pings together).
    # Reached: 0.300 of the relief's std over all cells and 0.230 beyond 4 m of ground range
    # (0.40 and 0.30 without the noise priors); nearer, the 0.29 stoss slopes fold range
    # (layover for x < h x 0.29 = 2.9 m) and the error there is about the relief's std.
    inv = invert(ripple_image, SONAR.range_bin, altitude=ALT, ping_spacing=SPACING, flat_prior=0.25)
    truth = _truth(ripples, inv.x)
    ok = np.isfinite(inv.elevation)
    err = np.where(ok, inv.elevation - truth, 0.0)
    far = ok & (inv.x >= 4.0)[None, :]
    assert np.sqrt(np.mean(err[ok] ** 2)) < 0.33 * np.std(truth[ok])
    assert np.sqrt(np.mean(err[far] ** 2)) < 0.26 * np.std(truth[far])
    _monotone(inv)


@pytest.mark.xfail(
    strict=True,
    reason="issue 4 target (Z RMSE < 30% of relief std) not reached on the default path: "
    "0.53 with the first return; reached with the true altitude, the flat prior and the "
    "calibrated beam (0.267, test_calibrated_ripples_with_altitude_and_flat_prior), 0.300 free",
)
def test_ripple_round_trip_target(ripple_image, ripples):
    inv = invert(ripple_image, SONAR.range_bin, ping_spacing=SPACING, max_iter=100)
    assert _z_rmse(inv, _truth(ripples, inv.x)) < 0.3 * np.std(_truth(ripples, inv.x))


def test_calibrated_ripples_with_altitude_and_flat_prior(ripple_image, ripples):
    # Issue 4's target (below 0.3 of the relief's std) in its best setting. With Φ fixed and
    # the altitude known, nothing in the image holds the bending of Z across the swath:
    # `python tools/bench_inversion.py --known-altitude` gives 2.66 x without the flat prior
    # (the far range sinks 16 cm), 0.37 x with --flat-prior 0.25 and no noise priors
    # (--looks none), 0.267 x with the default looks="auto" (measured here too).
    inv = invert(
        ripple_image,
        SONAR.range_bin,
        altitude=ALT,
        ping_spacing=SPACING,
        max_iter=100,
        beam=_true_profile(),
        flat_prior=0.25,
    )
    truth = _truth(ripples, inv.x)
    assert _z_rmse(inv, truth) < 0.3 * np.std(truth)
    _monotone(inv)


@pytest.mark.parametrize("looks", [1.0, 4.0, 16.0])
def test_looks_are_estimated_from_neighbouring_pings(looks):
    # Gamma(L, 1/L) speckle on a mean that varies across range but not along track.
    rng = np.random.default_rng(3)
    mean = (1.0 + 0.5 * np.sin(np.arange(300) / 20.0))[None, :] * np.ones((40, 1))
    weight = np.ones_like(mean)
    weight[:, :30] = 0.0  # a water column left out
    image = mean * rng.gamma(looks, 1.0 / looks, mean.shape)
    image[:, :30] = 0.0
    assert estimate_looks(image, weight) == pytest.approx(looks, rel=0.1)
    assert estimate_looks(mean, weight) == math.inf


def test_priors_keep_speckle_out_of_the_relief(ripple_image, ripples):
    # 8-look speckle on the ripples, the true altitude: without the priors the fit turns
    # speckle into relief (1.65 x the relief's std with this draw, 2.8 x with the benchmark's);
    # with the looks estimated from the image (8.5) the relief and slope priors hold it at
    # 0.70 x.
    rng = np.random.default_rng(21)
    image = ripple_image * rng.gamma(8.0, 1.0 / 8.0, ripple_image.shape)
    kwargs = {"altitude": ALT, "ping_spacing": SPACING, "max_iter": 100}
    bare = invert(image, SONAR.range_bin, looks=None, **kwargs)
    held = invert(image, SONAR.range_bin, **kwargs)
    truth = _truth(ripples, held.x)
    assert held.settings["looks"] == pytest.approx(8.0, rel=0.15)
    assert bare.settings["looks"] is None
    assert _z_rmse(held, truth) < 0.8 * np.std(truth)
    assert _z_rmse(held, truth) < 0.6 * _z_rmse(bare, truth)
    _monotone(held)


def test_calibrated_beam_beats_three_unknowns(gl_renderer):
    # A mound (0.4 m, σ 1.5 m) spanning most of the 3.1 m of track: with Φ free, the beam
    # profile (shared by equal depression angles) takes up most of it; with the true Φ the
    # relief has to explain it. On the ripples calibrated mode is unstable (see docs/inversion.md).
    x = np.linspace(-3.0, 27.0, 601)
    y = np.linspace(-4.0, 4.0, 161)
    xx, yy = np.meshgrid(x, y)
    mound = from_grid(
        0.4 * np.exp(-((xx - 12.0) ** 2 + yy**2) / (2 * 1.5**2)), 0.05, x0=-3.0, y0=-4.0
    )
    image = _render(gl_renderer, mound)
    free = invert(image, SONAR.range_bin, ping_spacing=SPACING, max_iter=60)
    fixed = invert(image, SONAR.range_bin, ping_spacing=SPACING, max_iter=60, beam=_true_profile())
    truth = _truth(mound, free.x)
    assert _z_rmse(fixed, truth) < 0.5 * np.std(truth)
    assert _z_rmse(fixed, truth) < 0.5 * _z_rmse(free, truth)


def test_beam_profile_file_round_trip(tmp_path):
    prof = _true_profile()
    prof.save(tmp_path / "beam.json")
    back = BeamProfile.load(tmp_path / "beam.json")
    assert np.array_equal(back.gain, prof.gain)
    (tmp_path / "bad.json").write_text("{}")
    with pytest.raises(SonarRasterError):
        BeamProfile.load(tmp_path / "bad.json")


def _stability_cases(base: np.ndarray) -> dict[str, tuple[np.ndarray, float | None]]:
    saturated = np.minimum(base, np.percentile(base, 80))
    dark_far = base.copy()
    dark_far[:, 300:] = 0.0
    black_water = base.copy()
    black_water[:, :150] = 0.0
    return {
        "zeros": (np.zeros_like(base), ALT),
        "saturated": (saturated, None),
        "dark far range (R, Φ driven to 0)": (dark_far, None),
        "black water column": (black_water, None),
    }


@pytest.mark.parametrize("flat_prior", [0.0, 1.0])
def test_stability_on_hostile_images(ripple_image, flat_prior):
    # errstate restores numpy's error settings afterwards (a global seterr leaked into later
    # tests and turned harmless underflows into errors there).
    with np.errstate(all="raise"):
        for name, (img, alt) in _stability_cases(ripple_image).items():
            inv = invert(
                img,
                SONAR.range_bin,
                altitude=alt,
                ping_spacing=SPACING,
                max_iter=20,
                flat_prior=flat_prior,
            )
            ok = np.isfinite(inv.elevation)
            assert ok.any(), name
            for arr in (inv.elevation, inv.reflectivity, inv.beam):
                assert np.all(np.isfinite(arr[ok])), name
            _monotone(inv)


@pytest.mark.parametrize("altitude", [0.3, 19.5])
def test_stability_at_grazing_and_near_nadir(altitude):
    rng = np.random.default_rng(7)
    x = (np.arange(400) + 0.5) * 0.05
    alt = np.full(16, altitude)
    ground = rng.uniform(0.5, 1.5, (16, 400)) * altitude / np.sqrt(x**2 + altitude**2)
    slant = ground_to_slant(ground, x, alt, 0.05, 400)
    with np.errstate(all="raise"):
        inv = invert(slant, 0.05, altitude=altitude, max_iter=20)
    ok = np.isfinite(inv.elevation)
    assert ok.any()
    assert np.all(np.isfinite(inv.reflectivity[ok])) and np.all(np.isfinite(inv.beam[ok]))
    _monotone(inv)


def test_no_estimate_where_the_data_end():
    # The last cells' returns and their slope neighbours' fall partly beyond the image: they
    # get NaN (EDGE_BINS = 6 bins of slant range), the cells before them an estimate.
    from sonar_raster.inversion.solver import EDGE_BINS

    h, rb, bins = 5.0, 0.05, 300
    x = (np.arange(400) + 0.5) * rb
    slant = ground_to_slant(np.ones((4, x.size)), x, np.full(4, h), rb, bins)
    inv = invert(slant, rb, altitude=h, max_iter=5)
    known = np.all(np.isfinite(inv.elevation), axis=0)
    last = np.flatnonzero(known)[-1]
    assert known[: last + 1].all() and not known[last + 1 :].any()
    image_end = bins * rb
    assert np.hypot(inv.x[last], h) <= image_end - EDGE_BINS * rb
    assert np.hypot(inv.x[last], h) > image_end - (EDGE_BINS + 4) * rb


@pytest.mark.parametrize(
    "image",
    [np.zeros((1, 10)), np.full((4, 10), np.nan), -np.ones((4, 10)), np.zeros((4, 10, 2))],
)
def test_bad_input_is_one_error(image):
    with pytest.raises(SonarRasterError):
        invert(image, 0.05, altitude=1.0)


def test_ground_cells_longer_than_a_bin_alias_and_are_refused():
    # Flat seabed, Φ = R = 1: the exact slant density is h (acosh(r_hi/h) − acosh(r_lo/h)) / Δr.
    # The model puts each cell's return at one range (split between two bins): fine for cells
    # no longer than a bin, a comb of bright and dark bins for longer ones.
    h, rb, bins = 10.0, 0.05, 400
    edges = np.arange(bins + 1) * rb
    exact = h * np.diff(np.arccosh(np.maximum(edges, h) / h)) / rb
    far = slice(240, 380)  # away from nadir and the end of the ground axis

    def residual(dx: float, subsamples: int = 1) -> float:
        x = (np.arange(int(19.5 / dx)) + 0.5) * dx
        geom = Geometry(x, dx, 1.0, rb, bins, subsamples)
        model = forward(np.ones((1, x.size)), np.ones((1, x.size)), np.full((1, x.size), -h), geom)
        return float(np.linalg.norm(model[0, far] - exact[far]) / np.linalg.norm(exact[far]))

    assert residual(rb) < 0.1
    assert residual(2 * rb) > 0.2
    assert residual(2 * rb, subsamples=4) < 0.1  # spread over the cell's range extent
    assert residual(rb, subsamples=2) < 0.5 * residual(rb)
    with pytest.raises(SonarRasterError, match="ground bin"):
        invert(np.ones((4, 100)), rb, altitude=1.0, ground_bin=2 * rb)


def test_cli_invert_renderer_exr(gl_renderer, ripples, tmp_path, capsys):
    import json

    from sonar_raster.cli.app import main
    from sonar_raster.io.images import write_image

    image = gl_renderer.render(build_scene([ripples.mesh(0.5)]), SONAR, TRACK)
    write_image(image, tmp_path / "in.exr", sidecar=False)
    out = tmp_path / "out"
    assert main(["invert", str(tmp_path / "in.exr"), "-o", str(out), "--quiet"]) == 0
    doc = json.loads((out / "inversion.json").read_text())
    assert doc["ground_axis"]["spacing_m"] == pytest.approx(SONAR.range_bin)
    assert len(doc["altitude_m"]) == PINGS
    assert {"elevation.exr", "reflectivity.exr", "beam.exr", "inversion.json"} <= {
        p.name for p in out.iterdir()
    }
    quick = tmp_path / "quick"
    argv = ["invert", str(tmp_path / "in.exr"), "-o", str(quick), "--quiet", "--max-iter", "2"]
    assert main([*argv, "--ping-spacing", "0.1", "--flat-prior", "0.5", "--altitude", "10"]) == 0
    short = json.loads((quick / "inversion.json").read_text())
    quiet = tmp_path / "no_priors"
    argv[3] = str(quiet)
    assert main([*argv, "--looks", "none"]) == 0
    assert json.loads((quiet / "inversion.json").read_text())["settings"]["looks"] is None
    assert main([*argv, "--looks", "4", "--relief-std", "0.05", "--slope-std", "0.3"]) == 0
    given = json.loads((quiet / "inversion.json").read_text())["settings"]
    assert (given["looks"], given["relief_std"], given["slope_std"]) == (4.0, 0.05, 0.3)
    assert doc["settings"]["looks"] > 1000  # auto on a noise-free render: priors negligible
    assert all(len(level) <= 3 for level in short["energy_per_iteration"])
    assert doc["settings"]["flat_prior"] == 0 and doc["settings"]["altitude"] == "first return"
    assert short["settings"]["flat_prior"] == 0.5 and short["settings"]["altitude"] == "given"
    assert short["settings"]["max_iter"] == 2 and not short["settings"]["calibrated"]


@pytest.mark.parametrize(
    "argv",
    [
        ["invert", "missing.npy", "-o", "out", "--range-bin", "0.05"],
        ["invert", "bad.txt", "-o", "out", "--range-bin", "0.05"],
        ["invert", "neg.npy", "-o", "out", "--range-bin", "0.05"],
        ["invert", "neg.npy", "-o", "out"],
        ["invert", "ok.npy", "-o", "out", "--range-bin", "0.05", "--looks", "0"],
        ["invert", "ok.npy", "-o", "out", "--range-bin", "0.05", "--looks", "many"],
        ["invert", "ok.npy", "-o", "out", "--range-bin", "0.05", "--relief-std", "-1"],
    ],
)
def test_cli_invert_bad_input_writes_nothing(argv, tmp_path, monkeypatch, capsys):
    from sonar_raster.cli.app import main

    monkeypatch.chdir(tmp_path)
    np.save("neg.npy", -np.ones((4, 20)))
    np.save("ok.npy", np.ones((4, 20)))
    (tmp_path / "bad.txt").write_text("x")
    try:
        code = main(argv)
    except SystemExit as exc:  # option errors exit from argparse
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("sonar-raster: error:") and "\n" not in err
    assert not (tmp_path / "out").exists()


def _exr(path, pixels, names, **attributes):
    import OpenImageIO as oiio

    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], oiio.FLOAT)
    spec.channelnames = names
    for key, value in attributes.items():
        spec.attribute(key, value)
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), spec)
    out.write_image(np.ascontiguousarray(pixels, dtype=np.float32))
    out.close()


def test_another_tools_exr_or_tiff_is_one_side(tmp_path):
    from sonar_raster.inversion.write import read_side

    values = np.random.default_rng(0).exponential(size=(5, 7)).astype(np.float32)
    _exr(tmp_path / "y.exr", values[:, :, None], ["Y"], **{"sonar:range_bin_m": 0.05})
    _exr(tmp_path / "grey.exr", np.stack([values] * 3 + [np.ones_like(values)], -1), list("RGBA"))
    for name, side in (("y.exr", None), ("grey.exr", "port")):
        image, got, attrs = read_side(tmp_path / name, side)
        assert got == (side or "starboard")
        np.testing.assert_array_equal(image, values)
    assert "sonar:range_bin_m" not in attrs
    assert read_side(tmp_path / "y.exr", None)[2]["sonar:range_bin_m"] == pytest.approx(0.05)
    from sonar_raster.inversion.write import exr_sides

    assert exr_sides(tmp_path / "y.exr") == []  # so --method surface fits one side, not two
    _exr(tmp_path / "sides.exr", np.stack([values, values], -1), ["port", "starboard"])
    assert exr_sides(tmp_path / "sides.exr") == ["port", "starboard"]
    _exr(tmp_path / "t.tif", values[:, :, None], ["Y"])  # a float TIFF of another tool
    np.testing.assert_array_equal(read_side(tmp_path / "t.tif", None)[0], values)
    _exr(tmp_path / "colour.exr", np.stack([values, 2 * values, values], -1), list("RGB"))
    _exr(tmp_path / "two.exr", np.stack([values, values], -1), ["intensity", "mask"])
    for name in ("colour.exr", "two.exr"):
        with pytest.raises(SonarRasterError, match=r"are not one side: give the renderer's"):
            read_side(tmp_path / name, None)


def test_png_input_is_read_as_linear_grey_levels(tmp_path):
    import OpenImageIO as oiio

    from sonar_raster.inversion.write import read_side

    levels = (np.arange(6 * 9).reshape(6, 9) * 4).astype(np.uint8)
    out = oiio.ImageOutput.create(str(tmp_path / "in.png"))
    out.open(str(tmp_path / "in.png"), oiio.ImageSpec(9, 6, 1, oiio.UINT8))
    out.write_image(levels[:, :, None])
    out.close()
    image, side, _ = read_side(tmp_path / "in.png", None)
    assert image.shape == (6, 9) and side == "starboard"
    np.testing.assert_allclose(image, levels / 255.0, atol=1e-6)


def test_the_profiles_progress_bar_runs_over_the_budget_and_says_what_ran(capsys):
    """Each level's bar covers its starts' iteration budget; a start that converges early
    gives back the rest, so the bar ends at 100 % and says the iterations run (it used to
    start at the budget, e.g. 0/900, and jump to 16/16)."""
    rng = np.random.default_rng(0)
    image = rng.exponential(1.0, (60, 400))
    image[:, :150] *= 1e-3  # the water column before the first return
    invert(image, 0.05, ping_spacing=0.1, progress=True)
    lines = capsys.readouterr().err.replace("\r", "\n").splitlines()
    finals = [line for line in lines if line.startswith("level 3/3") and "100%" in line]
    assert finals, lines
    ran = finals[-1].split(", ")[-1]
    assert ran.endswith("iterations]") and int(ran.split()[0]) > 0
    assert not any("/900" in line or "it/s" in line for line in lines)
