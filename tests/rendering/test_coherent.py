"""The coherent (Eq. 10) model: point targets, resolution, exactness of the fast method, chunking,
speckle, and agreement of its mean intensity with the patch reference on a rough seabed."""

import math

import numpy as np
import pytest
from conftest import box_from_bounds as box
from conftest import rect_seabed as seabed

from sonar_raster.errors import SonarRasterError
from sonar_raster.rendering.coherent.model import (
    HorizontalBeam,
    PointScatterers,
    Pulse,
    ping_echo,
    render_coherent,
    to_raster_units,
)
from sonar_raster.rendering.reference import render_reference
from sonar_raster.scene import MeshPart, build_scene
from sonar_raster.sonar import BeamPattern, Sonar
from sonar_raster.trajectory import Trajectory

C = 1500.0


pytestmark = pytest.mark.usefixtures("strict_float")


def facing(points, sonar_position=(0.0, 0.0, 0.0)):
    """Unit normals from each point towards the sonar."""
    d = np.asarray(sonar_position, dtype=float) - np.asarray(points, dtype=float)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def point_echo(ranges, sonar, pulse=None, samples_per_bin=None, method="fast", phases_equal=False):
    """Echo of unit-area, unit-reflectivity points at slant ``ranges`` abeam to starboard."""
    r = np.asarray(ranges, dtype=float)
    if phases_equal:  # move each by < λ/4 so every two-way phase is a whole number of cycles
        r = np.round(r / (0.5 * sonar.wavelength)) * 0.5 * sonar.wavelength
    pos = np.stack([r * math.cos(0.3), np.zeros_like(r), -r * math.sin(0.3)], axis=1)
    pts = PointScatterers(pos, facing(pos), 1e-4, 1.0)
    return ping_echo(
        pts, sonar, np.zeros(3), 0.0, pulse=pulse, samples_per_bin=samples_per_bin, method=method
    )


def half_power_width(x, power):
    """Width of the main lobe at half its peak, by linear interpolation between samples."""
    p = power / power.max()
    i = int(np.argmax(p))
    lo, hi = i, i
    while p[lo] >= 0.5:
        lo -= 1
    while p[hi] >= 0.5:
        hi += 1
    x_lo = np.interp(0.5, [p[lo], p[lo + 1]], [x[lo], x[lo + 1]])
    x_hi = np.interp(0.5, [p[hi], p[hi - 1]], [x[hi], x[hi - 1]])
    return x_hi - x_lo


SONAR = Sonar(frequency_hz=100e3, max_range=30.0, range_bin=0.05, sides=("starboard",))


# -- the pulse ------------------------------------------------------------------------------------
def test_default_pulse_resolution_is_one_bin_and_spectrum_has_the_pulse_energy():
    pulse = Pulse.for_range_bin(0.05, C)
    assert pulse.kind == "lfm" and pulse.window == "taylor"
    assert pulse.resolution(C) == pytest.approx(0.05)
    nu = np.linspace(-4 * pulse.bandwidth_hz, 4 * pulse.bandwidth_hz, 400001)
    energy = np.sum(np.abs(pulse.spectrum(nu)) ** 2) * (nu[1] - nu[0])  # Parseval: ∫|s|² = T
    assert energy == pytest.approx(pulse.duration_s, rel=2e-3)
    cw = Pulse.cw(1e-3)
    cw_energy = np.sum(np.abs(cw.spectrum(nu)) ** 2) * (nu[1] - nu[0])
    assert cw.bandwidth_hz == pytest.approx(1e3) and cw_energy == pytest.approx(1e-3, rel=1e-2)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"kind": "fm", "bandwidth_hz": 1e3, "duration_s": 1.0},
        {"kind": "lfm", "bandwidth_hz": 1e3, "duration_s": 1e-4},  # B T < 1
        {"kind": "cw", "bandwidth_hz": 5e3, "duration_s": 1e-3},  # B != 1/T
        {"kind": "lfm", "bandwidth_hz": -1.0, "duration_s": 1.0},
        {"kind": "lfm", "bandwidth_hz": 1e3, "duration_s": 1.0, "window": "kaiser"},
    ],
)
def test_bad_pulses_raise(kwargs):
    with pytest.raises(SonarRasterError):
        Pulse(**kwargs)


# -- point targets --------------------------------------------------------------------------------
@pytest.mark.parametrize("r", [7.53, 12.34, 21.99])
def test_point_target_peaks_in_its_bin_with_the_nominal_width(r):
    echo = point_echo([r], SONAR, samples_per_bin=32)
    assert int(np.argmax(echo.intensity["starboard"])) == int(r / SONAR.range_bin)
    power = np.abs(echo.signal["starboard"]) ** 2
    assert echo.ranges[np.argmax(power)] == pytest.approx(r, abs=SONAR.range_bin / 32)
    resolution = Pulse.for_range_bin(SONAR.range_bin).resolution(C)
    width = half_power_width(echo.ranges, power)
    assert width == pytest.approx(resolution, rel=0.10)  # Taylor -25 dB: 1.08 c/(2B)


def test_unweighted_chirp_compresses_to_a_sinc():
    pulse = Pulse.lfm(C / (2 * SONAR.range_bin), window="none")
    echo = point_echo([12.34], SONAR, pulse=pulse, samples_per_bin=32)
    width = half_power_width(echo.ranges, np.abs(echo.signal["starboard"]) ** 2)
    # |sinc(B t)|² is 0.886 / B wide at half power; the finite chirp's Fresnel ripple adds ~3 %
    assert width / pulse.resolution(C) == pytest.approx(0.886, rel=0.05)


def test_point_target_intensity_falls_as_r_to_the_fourth():
    # both at the middle of a bin, so the bin-averaged peaks compare as well as the energies
    r1, r2 = 8.025, 16.025
    e1, e2 = (point_echo([r], SONAR).intensity["starboard"] for r in (r1, r2))
    assert e1.sum() / e2.sum() == pytest.approx((r2 / r1) ** 4, rel=1e-4)
    assert e1.max() / e2.max() == pytest.approx((r2 / r1) ** 4, rel=1e-3)
    # unit energy per unit amplitude²: |a²/λ · 1/r²|² summed over all bins
    assert e1.sum() == pytest.approx((1e-4 / SONAR.wavelength / r1**2) ** 2, rel=1e-4)


def count_peaks(power, floor_db=-10.0):
    p = power / power.max()
    inner = p[1:-1]
    return int(np.sum((inner > p[:-2]) & (inner >= p[2:]) & (inner > 10 ** (floor_db / 10))))


def test_two_scatterers_merge_within_and_resolve_beyond_the_resolution():
    res = Pulse.for_range_bin(SONAR.range_bin).resolution(C)
    close = point_echo([15.0, 15.0 + 0.5 * res], SONAR, samples_per_bin=32, phases_equal=True)
    assert count_peaks(np.abs(close.signal["starboard"]) ** 2) == 1
    far = point_echo([15.0, 15.0 + 2.2 * res], SONAR, samples_per_bin=32, phases_equal=True)
    power = np.abs(far.signal["starboard"]) ** 2
    assert count_peaks(power) == 2
    between = (far.ranges > 15.0) & (far.ranges < 15.0 + 2.2 * res)
    assert power[between].min() < 0.5 * power.max()  # a dip deeper than 3 dB


def test_point_target_through_the_mesh_renderer_lands_in_its_bin():
    # a 1 mm triangle is a single scatterer (spacing λ/4 = 3.75 mm) at its centroid
    centre = np.array([15.0, 0.0, -5.0])
    n = facing([centre], (0.0, 0.0, 0.0))[0]
    e1 = np.cross(n, [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    v = centre + 1e-3 * np.array([-e1 - e2, e1 - e2, e2]) / 2
    scene = build_scene([MeshPart(v, np.array([[0, 1, 2]]), 1.0, "point")])
    traj = Trajectory.straight((0.0, -0.05, 0.0), 0.0, 0.05, 3)
    image = render_coherent(scene, SONAR, traj, jitter_wavelengths=0.0)
    assert image.metadata["n_visible"] == 1 and image.metadata["renderer"] == "coherent"
    rows = image.sides["starboard"]
    assert rows.shape == (3, SONAR.n_bins) and rows.dtype == np.float32
    r = float(np.linalg.norm(v.mean(axis=0)))
    assert int(np.argmax(rows[1])) == int(r / SONAR.range_bin)
    assert rows[1].max() > rows[0].max()  # the middle ping is abeam: its beam is centred


# -- exactness, chunking, visibility -----------------------------------------------------------
LOW = Sonar(
    frequency_hz=20e3,
    max_range=12.0,
    range_bin=0.1,
    beam=BeamPattern.gaussian(50.0),
    tilt=math.radians(25.0),
)


@pytest.fixture(scope="module")
def small_scene():
    return build_scene([seabed(-6, 6, -1, 3), box([[5.0, 0.5, 0.0], [5.6, 1.5, 0.6]])])


@pytest.fixture(scope="module")
def small_track():
    return Trajectory.straight((0.0, 0.6, 4.0), 0.0, 0.2, 5)


def test_fast_method_matches_the_direct_sum(small_scene, small_track):
    kw = {"spacing_wavelengths": 1.0, "seed": 3}
    fast = render_coherent(small_scene, LOW, small_track, method="fast", **kw)
    direct = render_coherent(small_scene, LOW, small_track, method="direct", **kw)
    assert fast.metadata["n_pairs"] == direct.metadata["n_pairs"] > 1000
    for side in ("port", "starboard"):
        a, b = fast.sides[side].astype(float), direct.sides[side].astype(float)
        assert np.abs(a - b).max() <= 2e-6 * b.max()


def test_result_does_not_depend_on_chunk_size(small_scene, small_track):
    kw = {"spacing_wavelengths": 0.5, "seed": 1}
    big = render_coherent(small_scene, LOW, small_track, chunk=1 << 16, **kw)
    small = render_coherent(small_scene, LOW, small_track, chunk=97, **kw)
    assert big.metadata["n_scatterers"] == small.metadata["n_scatterers"]
    for side in big.sides:
        a, b = big.sides[side].astype(float), small.sides[side].astype(float)
        assert np.abs(a - b).max() <= 1e-6 * a.max()


def test_seed_changes_the_speckle_only(small_scene, small_track):
    a = render_coherent(small_scene, LOW, small_track, spacing_wavelengths=1.0, seed=1)
    b = render_coherent(small_scene, LOW, small_track, spacing_wavelengths=1.0, seed=2)
    assert not np.array_equal(a.sides["starboard"], b.sides["starboard"])
    assert a.metadata["n_visible"] == b.metadata["n_visible"]


def test_box_shadow_matches_the_reference():
    # the box is longer than the horizontal beam's footprint, so every ping sees its shadow
    scene = build_scene([seabed(-1, 13, -3, 5), box([[5.0, -1.5, 0.0], [5.6, 3.5, 0.6]])])
    track = Trajectory.straight((0.0, 0.6, 4.0), 0.0, 0.2, 5)
    sonar = Sonar(frequency_hz=20e3, max_range=12.0, range_bin=0.1, sides=("starboard",))
    coh = to_raster_units(render_coherent(scene, sonar, track)).sides["starboard"].mean(axis=0)
    ref = render_reference(scene, sonar, track).sides["starboard"]
    dark = np.flatnonzero(np.all(ref == 0, axis=0) & (np.arange(sonar.n_bins) > 60))
    assert len(dark) >= 8 and np.all(np.diff(dark) == 1)  # one shadow, 66..75
    lit = slice(dark[-1] + 2, sonar.n_bins)
    # inside the shadow, away from the box's bright face (its range sidelobes reach a few bins
    # in) and off the far edge by 2 bins (the compressed pulse), only weak sidelobes remain
    assert coh[dark[len(dark) // 2] : dark[-2]].mean() < 0.03 * coh[lit].mean()
    assert coh[dark[-1] + 2 : dark[-1] + 12].mean() > 0.3 * coh[lit].mean()


# -- rough seabed: speckle and mean level -----------------------------------------------------
def test_fine_samples_of_a_rough_surface_have_unit_speckle_contrast():
    # fully developed speckle: exponential intensity, std / mean = 1 (pooled over 8 pings)
    rng = np.random.default_rng(5)
    pooled = []
    for _ in range(8):
        r = rng.uniform(4.0, 29.0, 50000)
        pos = np.stack([r, rng.uniform(-0.05, 0.05, len(r)), np.zeros_like(r)], axis=1)
        echo = ping_echo(PointScatterers(pos, facing(pos), 1e-4, 1.0), SONAR, np.zeros(3))
        inside = (echo.ranges > 5.0) & (echo.ranges < 28.0)
        pooled.append(np.abs(echo.signal["starboard"][inside]) ** 2 * echo.ranges[inside] ** 4)
    power = np.concatenate(pooled)
    assert power.std() / power.mean() == pytest.approx(1.0, abs=0.08)


def test_rough_flat_seabed_speckle_and_mean_profile_match_the_reference():
    sonar = Sonar(
        frequency_hz=20e3,
        max_range=12.0,
        range_bin=0.1,
        beam=BeamPattern.gaussian(50.0),
        tilt=math.radians(25.0),
        sides=("starboard",),
    )
    scene = build_scene([seabed(-1, 14, -3, 18)])
    traj = Trajectory.straight((0.0, 0.0, 4.0), 0.0, 0.1, 150)
    coherent = render_coherent(scene, sonar, traj, seed=11)  # λ/4 spacing: 580 k scatterers
    coh = to_raster_units(coherent).sides["starboard"].astype(float)
    ref = render_reference(scene, sonar, traj, patch_size=0.05).sides["starboard"].astype(float)
    k0, k1 = 50, 110  # 5 m to 11 m: past nadir's strong slope, clear of the far edge
    profile_c, profile_r = coh.mean(axis=0)[k0:k1], ref.mean(axis=0)[k0:k1]
    # speckle: each bin integrates about 1.3 looks of the compressed pulse, so the contrast of
    # bin-averaged intensity is ~0.87 (1 for single samples, test above)
    contrast = (coh[:, k0:k1] / profile_c).std()
    assert 0.75 < contrast < 1.05
    # the along-track-averaged profile in 1 m blocks (statistical noise ~3.5 % rms; the
    # systematic difference, pooled over 6 seeds, is under 3 %), after one global scale
    a, b = profile_c.reshape(-1, 10).mean(axis=1), profile_r.reshape(-1, 10).mean(axis=1)
    scale = float(a @ b / (a @ a))
    rms = float(np.sqrt(np.mean((scale * a / b - 1.0) ** 2)))
    assert rms < 0.10
    assert scale == pytest.approx(1.0, abs=0.15)  # to_raster_units gets the absolute level too


# -- settings -----------------------------------------------------------------------------------
def test_horizontal_beam_half_power_and_footprint():
    for kind in ("gaussian", "sinc"):
        beam = HorizontalBeam(0.01, kind)
        assert beam(0.005) == pytest.approx(0.5, rel=1e-3)
        y = np.linspace(-0.5, 0.5, 200001)
        r = 10.0
        numeric = np.sum(beam(y / np.hypot(r, y))) * (y[1] - y[0])
        assert numeric == pytest.approx(float(beam.footprint(r)), rel=2e-3)
    traj = Trajectory.straight((0.0, 0.0, 5.0), 0.0, 0.2, 10)
    default = HorizontalBeam.for_track(SONAR, traj)
    assert default.width * 0.5 * SONAR.max_range == pytest.approx(0.2)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"method": "nufft"},
        {"scattering": "phong"},
        {"chunk": 0},
        {"spacing_wavelengths": 0.0},
        {"jitter_wavelengths": -1.0},
        {"pulse": Pulse.lfm(250e3)},  # band above twice the 100 kHz carrier
    ],
)
def test_bad_settings_raise(kwargs):
    scene = build_scene([seabed(0, 5, 0, 5, z=-5.0)])
    traj = Trajectory.straight((0.0, 0.0, 0.0), 0.0, 0.1, 2)
    with pytest.raises(SonarRasterError):
        render_coherent(scene, SONAR, traj, **kwargs)


def test_wrong_types_raise():
    traj = Trajectory.straight((0.0, 0.0, 0.0), 0.0, 0.1, 2)
    with pytest.raises(TypeError):
        render_coherent("scene", SONAR, traj)
    with pytest.raises(TypeError):
        ping_echo([[1.0, 0.0, 0.0]], SONAR, np.zeros(3))
