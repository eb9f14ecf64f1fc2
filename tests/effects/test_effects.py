"""Sensor effects against closed forms, published figures and their own statistics."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import box_from_bounds, plane
from scipy import special, stats

from sonar_raster.effects import chain as fx_module
from sonar_raster.effects.absorption import francois_garrison
from sonar_raster.effects.chain import Effects, apply_effects, load_tvg_curve
from sonar_raster.effects.presets import DEFAULT_SENSOR
from sonar_raster.errors import SonarRasterError
from sonar_raster.image import SonarImage
from sonar_raster.rendering.analytic import flat_seabed_profile
from sonar_raster.scene import build_scene
from sonar_raster.scenes.sediments import SEDIMENTS, material_reflectivity, sediment
from sonar_raster.sonar import BeamPattern, Sonar
from sonar_raster.trajectory import Trajectory

FWHM = 2.0 * math.sqrt(2.0 * math.log(2.0))


def image_of(data: np.ndarray, sonar: Sonar | None = None, **meta) -> SonarImage:
    sonar = sonar or Sonar(max_range=data.shape[1] * 0.05, range_bin=0.05)
    sides = {"port": data.astype(np.float32), "starboard": data[::-1].astype(np.float32)}
    return SonarImage(sides, sonar, dict(meta))


def flat_image(sonar: Sonar, altitude: float, pings: int = 4) -> SonarImage:
    row = flat_seabed_profile(sonar, altitude, 0.3, 0.1)
    data = np.tile(row, (pings, 1)).astype(np.float32)
    return SonarImage({"port": data, "starboard": data.copy()}, sonar, {})


def along_sigma(column: np.ndarray) -> float:
    """Standard deviation along pings of a nonnegative column, pings."""
    n = np.arange(len(column))
    w = column / column.sum()
    mean = (w * n).sum()
    return float(math.sqrt((w * (n - mean) ** 2).sum()))


# -- off means off -----------------------------------------------------------------------------
def test_every_effect_off_returns_the_input_untouched(monkeypatch):
    def boom(*args):
        raise AssertionError("a disabled stage ran")

    for name in fx_module.STAGES:
        monkeypatch.setitem(fx_module._FUNCTIONS, name, boom)
    data = np.random.default_rng(1).random((20, 30))
    image = image_of(data)
    for effects in (None, Effects(), Effects(gain_db=0.0, speckle="off", tvg="off")):
        out = apply_effects(image, effects, seed=3)
        assert out.metadata["effects"]["stages"] == []
        for side in image.sides:
            assert out.sides[side] is image.sides[side]
            assert np.array_equal(out.sides[side], image.sides[side])


def test_only_enabled_stages_run(monkeypatch):
    calls: dict[str, int] = {}
    for name, fn in list(fx_module._FUNCTIONS.items()):

        def counted(data, fx, ctx, _name=name, _fn=fn):
            calls[_name] = calls.get(_name, 0) + 1
            return _fn(data, fx, ctx)

        monkeypatch.setitem(fx_module._FUNCTIONS, name, counted)
    image = image_of(np.ones((6, 40)))
    out = apply_effects(image, Effects(spreading=True, gain_db=6.0))
    assert calls == {"spreading": 2, "gain": 2}  # once per side, nothing else
    assert out.metadata["effects"]["stages"] == ["spreading", "gain"]
    assert all(a.dtype == np.float32 for a in out.sides.values())


# -- propagation and gain ----------------------------------------------------------------------
def test_flat_seabed_with_spreading_absorption_and_tvg_follows_closed_form():
    sonar = Sonar(frequency_hz=600e3, max_range=40.0, range_bin=0.05, tilt=math.radians(15))
    altitude = 6.0
    raw = flat_image(sonar, altitude)
    r = (np.arange(sonar.n_bins) + 0.5) * 0.05
    i0 = flat_seabed_profile(sonar, altitude, 0.3, 0.1)
    # α at 600 kHz, 12 °C, 35 PSU, 20 m, pH 8 from the formula written out independently.
    t, s, z, f = 12.0, 35.0, 20.0, 600.0
    c = 1412 + 3.21 * t + 1.19 * s + 0.0167 * z
    boric = 8.86 / c * 10 ** (0.78 * 8 - 5) * 2.8 * math.sqrt(s / 35) * 10 ** (4 - 1245 / 285)
    f1 = 2.8 * math.sqrt(s / 35) * 10 ** (4 - 1245 / 285)
    f2 = 8.17 * 10 ** (8 - 1990 / 285)
    mg = 21.44 * s / c * (1 + 0.025 * t) * (1 - 1.37e-4 * z + 6.2e-9 * z * z) * f2
    water = (4.937e-4 - 2.59e-5 * t + 9.11e-7 * t * t - 1.5e-8 * t**3) * (1 - 3.83e-5 * z)
    alpha = (
        boric * f * f / (f1 * f1 + f * f) + mg * f * f / (f2 * f2 + f * f) + water * f * f
    ) / 1e3
    water_props = dict(temperature_c=t, salinity_psu=s, depth_m=z, ph=8.0)
    lossy = apply_effects(raw, Effects(spreading=True, absorption=True, **water_props))
    assert lossy.metadata["effects"]["alpha_db_m"] == pytest.approx(alpha, rel=1e-6)
    expected = i0 * r**-4.0 * 10 ** (-2 * alpha * r / 10)
    hit = i0 > 0
    got = lossy.sides["starboard"][1].astype(np.float64)
    np.testing.assert_allclose(got[hit], expected[hit], rtol=2e-6)
    assert np.all(got[~hit] == 0)
    for n_log in (20.0, 30.0, 40.0):  # N log r + 2 α r leaves I0 r^(N/10 - 4)
        fx = Effects(spreading=True, absorption=True, tvg="log", tvg_log_coefficient=n_log)
        out = apply_effects(raw, fx.__class__(**{**fx.changed(), **water_props}))
        got = out.sides["port"][2].astype(np.float64)
        np.testing.assert_allclose(got[hit], i0[hit] * r[hit] ** (n_log / 10 - 4), rtol=2e-5)


def test_user_tvg_curve_and_gain(tmp_path):
    path = tmp_path / "tvg.csv"
    path.write_text("range_m,gain_db\n0,0\n10,30\n100,30\n")
    curve = load_tvg_curve(str(path))
    assert curve == ((0.0, 0.0), (10.0, 30.0), (100.0, 30.0))
    image = image_of(np.ones((3, 400)))  # bins of 0.05 m up to 20 m
    out = apply_effects(image, Effects(tvg="curve", tvg_curve=curve, gain_db=-10.0))
    r = (np.arange(400) + 0.5) * 0.05
    expected_db = np.where(r < 10, 3.0 * r, 30.0) - 10.0
    got_db = 10 * np.log10(out.sides["port"][0].astype(np.float64))
    np.testing.assert_allclose(got_db, expected_db, atol=1e-4)


def test_saturation_and_quantisation_levels():
    ramp = np.linspace(0.0, 1.0, 400_000).reshape(400, 1000)
    image = image_of(ramp)
    for bits in (8, 12, 16):
        out = apply_effects(image, Effects(saturation=0.5, bits=bits)).sides["port"]
        values = np.unique(out.astype(np.float64))
        assert len(values) == 2**bits  # every code from 0 to 2**bits - 1 is used
        codes = values / (0.5 / (2**bits - 1))
        np.testing.assert_allclose(codes, np.arange(2**bits), atol=2e-3)
        assert out.max() == np.float32(0.5)
        assert np.mean(out == np.float32(0.5)) == pytest.approx(0.5, abs=0.01)
    clipped = apply_effects(image, Effects(saturation=0.25)).sides["port"]
    assert clipped.max() == np.float32(0.25) and np.mean(clipped == np.float32(0.25)) > 0.74
    unbounded = apply_effects(image, Effects(bits=8)).sides["port"]  # full scale = image max
    assert unbounded.max() == np.float32(1.0) and len(np.unique(unbounded)) == 256


def test_nadir_gap_and_water_column():
    sonar = Sonar(max_range=30.0, range_bin=0.05)
    altitude = 5.0
    raw = flat_image(sonar, altitude)
    first = int(altitude / 0.05)  # flat seabed: the first bin with a return starts at h
    gap_edge = math.ceil(altitude / math.cos(math.radians(40.0)) / 0.05)
    out = apply_effects(raw, Effects(nadir_gap_deg=40.0, water_column_db=-30.0))
    got = out.sides["starboard"][0].astype(np.float64)
    row = raw.sides["starboard"][0].astype(np.float64)
    np.testing.assert_allclose(got[:first], 1e-3, rtol=1e-6)
    assert np.all(got[first:gap_edge] == 0.0)
    assert np.array_equal(got[gap_edge:], row[gap_edge:])


def test_receiver_noise_level():
    image = image_of(np.zeros((200, 500)))
    out = apply_effects(image, Effects(noise_db=-20.0), seed=5).sides["starboard"]
    assert out.mean() == pytest.approx(0.01, rel=0.02)
    assert out.std() / out.mean() == pytest.approx(1.0, abs=0.02)  # exponential intensity


# -- absorption against published figures ------------------------------------------------------
# Check values tabulated with the Francois-Garrison equation (pH 8, surface), dB/km: as listed
# by G. Jimenez Arranz, SEAWATER_PROPERTIES (2017), from Francois & Garrison (1982b).
FG_CHECKS = [
    (0, 30, 1, 6.10e-2),
    (0, 35, 1, 6.40e-2),
    (10, 35, 1, 6.00e-2),
    (0, 30, 10, 1.12),
    (0, 35, 10, 1.29),
    (10, 35, 10, 9.63e-1),
    (0, 30, 100, 21.0),
    (0, 35, 100, 23.4),
    (10, 35, 100, 33.6),
]


@pytest.mark.parametrize(("t", "s", "f_khz", "db_km"), FG_CHECKS)
def test_francois_garrison_matches_published_values(t, s, f_khz, db_km):
    got = francois_garrison(f_khz * 1e3, t, s, 0.0, 8.0) * 1e3
    assert got == pytest.approx(db_km, rel=0.006)  # the table has three digits


def ainslie_mccolm(f_khz: float, t: float, s: float, z_km: float, ph: float) -> float:
    """Ainslie & McColm (1998) JASA 103(3):1671, a separate fit to Francois-Garrison, dB/km."""
    f1 = 0.78 * math.sqrt(s / 35) * math.exp(t / 26)
    f2 = 42 * math.exp(t / 17)
    boric = 0.106 * f1 * f_khz**2 / (f_khz**2 + f1**2) * math.exp((ph - 8) / 0.56)
    mg = 0.52 * (1 + t / 43) * (s / 35) * f2 * f_khz**2 / (f_khz**2 + f2**2) * math.exp(-z_km / 6)
    return boric + mg + 0.00049 * f_khz**2 * math.exp(-(t / 27 + z_km / 17))


@pytest.mark.parametrize("f_khz", [30.0, 100.0, 300.0, 600.0, 900.0])
@pytest.mark.parametrize("t", [4.0, 10.0, 20.0])
def test_francois_garrison_agrees_with_ainslie_mccolm(f_khz, t):
    got = francois_garrison(f_khz * 1e3, t, 35.0, 50.0, 8.0) * 1e3
    assert got == pytest.approx(ainslie_mccolm(f_khz, t, 35.0, 0.05, 8.0), rel=0.10)


def test_absorption_at_600_khz_is_about_0_16_db_per_metre():
    assert 0.14 < francois_garrison(600e3, 10.0, 35.0, 10.0, 8.0) < 0.18


# -- along-track beam --------------------------------------------------------------------------
def delta_image(pings: int, bins: int, range_bin: float) -> SonarImage:
    data = np.zeros((pings, bins))
    data[pings // 2] = 1.0
    return image_of(data, Sonar(frequency_hz=600e3, max_range=bins * range_bin, range_bin=0.1))


def test_side_scan_footprint_grows_linearly_with_range():
    image = delta_image(801, 400, 0.1)
    spacing, beam_deg = 0.05, 1.0
    out = apply_effects(image, Effects(along_beam_deg=beam_deg), ping_spacing=spacing)
    port = out.sides["port"].astype(np.float64)
    r = (np.arange(400) + 0.5) * 0.1
    widths = np.array([along_sigma(port[:, k]) for k in range(400)])
    expected = math.radians(beam_deg) * r / math.sqrt(2) / FWHM / spacing
    far = expected > 2.0  # resolved by the ping grid
    np.testing.assert_allclose(widths[far], expected[far], rtol=5e-3)
    slope, intercept = np.polyfit(r[far], widths[far], 1)
    assert abs(intercept) < 0.05 and slope == pytest.approx(expected[-1] / r[-1], rel=5e-3)
    np.testing.assert_allclose(port[400, far], 1.0, rtol=1e-3)  # unit peak: targets keep level


def test_array_length_sets_the_beam_width():
    image = delta_image(801, 300, 0.1)
    length = 0.5  # 0.886 λ / L at 600 kHz = 0.254 degrees
    a = apply_effects(image, Effects(array_length_m=length), ping_spacing=0.02)
    beam = math.degrees(0.886 * 1500.0 / 600e3 / length)
    b = apply_effects(image, Effects(along_beam_deg=beam), ping_spacing=0.02)
    np.testing.assert_allclose(a.sides["port"], b.sides["port"], rtol=1e-5, atol=1e-7)


def test_sas_resolution_is_constant_with_range():
    image = delta_image(801, 400, 0.1)
    out = apply_effects(image, Effects(sas_resolution_m=0.3), ping_spacing=0.05)
    port = out.sides["port"].astype(np.float64)
    widths = np.array([along_sigma(port[:, k]) for k in range(400)])
    np.testing.assert_allclose(widths, 0.3 / FWHM / 0.05, rtol=2e-3)


def test_rendered_targets_blur_with_range_side_scan_and_not_sas(gl):
    """Three small boxes at increasing range, rendered on the GL path, then blurred."""
    altitude, spacing = 5.0, 0.05
    ranges = (8.0, 16.0, 24.0)
    parts = [plane(120.0, reflectivity=0.0)]
    for x in ranges:
        parts.append(box_from_bounds([[x, -0.05, 0.0], [x + 0.1, 0.05, 0.1]], 1.0, f"b{x}"))
    sonar = Sonar(frequency_hz=600e3, max_range=30.0, range_bin=0.05, tilt=math.radians(20))
    traj = Trajectory.straight((0.0, -6.0, altitude), 0.0, spacing, 241)
    raw = gl.render(build_scene(parts), sonar, traj)

    def widths(image: SonarImage) -> list[float]:
        star = image.sides["starboard"].astype(np.float64)
        out = []
        for x in ranges:
            k = int(math.hypot(x, altitude) / 0.05)
            out.append(along_sigma(star[:, k - 4 : k + 6].sum(axis=1)))
        return out

    w_raw = np.array(widths(raw))
    assert np.all(w_raw < 1.5)  # the boxes are 0.1 m = 2 pings long
    side_scan = apply_effects(raw, Effects(along_beam_deg=2.0), trajectory=traj)
    sas = apply_effects(raw, Effects(sas_resolution_m=0.4), trajectory=traj)
    slant = np.array([math.hypot(x + 0.05, altitude - 0.05) for x in ranges])
    beam = math.radians(2.0) * slant / math.sqrt(2) / FWHM / spacing
    np.testing.assert_allclose(
        np.sqrt(np.array(widths(side_scan)) ** 2 - w_raw**2), beam, rtol=0.05
    )
    sas_w = np.sqrt(np.array(widths(sas)) ** 2 - w_raw**2)
    np.testing.assert_allclose(sas_w, 0.4 / FWHM / spacing, rtol=0.05)


def test_along_track_needs_a_ping_spacing():
    with pytest.raises(SonarRasterError, match="ping spacing"):
        apply_effects(image_of(np.ones((4, 10))), Effects(along_beam_deg=1.0))
    out = apply_effects(image_of(np.ones((4, 10)), ping_spacing_m=0.1), Effects(along_beam_deg=1))
    assert out.metadata["effects"]["ping_spacing_m"] == 0.1


# -- speckle -----------------------------------------------------------------------------------
def test_exponential_speckle_statistics_and_seeds():
    image = image_of(np.full((512, 512), 2.0))
    out = apply_effects(image, Effects(speckle="exponential"), seed=11).sides["port"]
    values = out.astype(np.float64).ravel() / 2.0
    assert values.mean() == pytest.approx(1.0, abs=0.01)
    assert values.std() / values.mean() == pytest.approx(1.0, abs=0.01)
    assert stats.kstest(values, stats.expon.cdf).statistic < 0.005
    again = apply_effects(image, Effects(speckle="exponential"), seed=11)
    other = apply_effects(image, Effects(speckle="exponential"), seed=12)
    assert np.array_equal(again.sides["port"], out)
    assert not np.array_equal(other.sides["port"], out)
    assert not np.array_equal(again.sides["starboard"], again.sides["port"][::-1])


def k_cdf(x: np.ndarray, nu: float) -> np.ndarray:
    """CDF of unit-mean K-distributed intensity: 1 - 2 (ν x)^(ν/2) K_ν(2 sqrt(ν x)) / Γ(ν)."""
    y = np.sqrt(nu * x)
    return 1.0 - 2.0 * y**nu * special.kv(nu, 2.0 * y) / special.gamma(nu)


@pytest.mark.parametrize("nu", [1.0, 3.0])
def test_k_distributed_speckle(nu):
    image = image_of(np.ones((1024, 1024)))
    out = apply_effects(image, Effects(speckle="k", k_shape=nu), seed=2).sides["port"]
    values = out.astype(np.float64).ravel()
    assert values.mean() == pytest.approx(1.0, abs=0.02)
    contrast_sq = values.var() / values.mean() ** 2
    assert contrast_sq == pytest.approx(1.0 + 2.0 / nu, rel=0.05)
    assert stats.kstest(values, lambda x: k_cdf(x, nu)).statistic < 0.005


@pytest.mark.parametrize("looks", [2.0, 2.5])
def test_multi_look_speckle(looks):
    """speckle_looks L: gamma(L) one-point law (contrast 1/sqrt(L)); with K texture ν the
    contrast² is (1 + 1/L)(1 + 1/ν) - 1."""
    image = image_of(np.ones((1024, 1024)))
    out = apply_effects(image, Effects(speckle="exponential", speckle_looks=looks), seed=3)
    values = out.sides["port"].astype(np.float64).ravel()
    assert values.mean() == pytest.approx(1.0, abs=0.02)
    assert values.std() / values.mean() == pytest.approx(1 / math.sqrt(looks), rel=0.03)
    assert stats.kstest(values, stats.gamma(looks, scale=1 / looks).cdf).statistic < 0.005
    fx = Effects(speckle="k", k_shape=2.0, speckle_looks=looks)
    k = apply_effects(image, fx, seed=3).sides["port"].astype(np.float64).ravel()
    want = (1 + 1 / looks) * (1 + 1 / 2.0) - 1
    assert k.var() / k.mean() ** 2 == pytest.approx(want, rel=0.05)
    with pytest.raises(SonarRasterError, match="speckle_looks must be >= 1"):
        Effects(speckle="exponential", speckle_looks=0.5)


def lag_correlation(field: np.ndarray, lags: range, axis: int) -> np.ndarray:
    x = field - field.mean()
    n = field.shape[axis]
    var = (x * x).mean()
    out = []
    for lag in lags:
        a = np.take(x, range(n - lag), axis=axis)
        b = np.take(x, range(lag, n), axis=axis)
        out.append((a * b).mean() / var)
    return np.array(out)


def test_speckle_correlation_matches_the_resolution_cell():
    sigma_pings, sigma_bins = 3.0, 2.0
    spacing, range_bin = 0.05, 0.05
    image = image_of(np.ones((4096, 256)))
    fx = Effects(
        speckle="exponential",
        sas_resolution_m=sigma_pings * FWHM * spacing,
        range_resolution_m=sigma_bins * FWHM * range_bin,
    )
    out = apply_effects(image, fx, seed=4, ping_spacing=spacing).sides["port"]
    field = out.astype(np.float64)
    lags = range(0, 13)
    along = lag_correlation(field, lags, axis=0)
    across = lag_correlation(field, lags, axis=1)
    lag = np.arange(13)
    np.testing.assert_allclose(along, np.exp(-(lag**2) / (4 * sigma_pings**2)), atol=0.03)
    np.testing.assert_allclose(across, np.exp(-(lag**2) / (4 * sigma_bins**2)), atol=0.03)
    assert field.std() / field.mean() == pytest.approx(1.0, abs=0.03)


def test_side_scan_speckle_cells_grow_with_range():
    image = image_of(np.ones((4096, 400)), Sonar(max_range=40.0, range_bin=0.1))
    fx = Effects(speckle="exponential", along_beam_deg=1.5)
    out = apply_effects(image, fx, seed=9, ping_spacing=0.05).sides["port"].astype(np.float64)
    out /= out.mean(axis=0)  # the footprint gain grows with range; speckle is what is left
    r = (np.arange(400) + 0.5) * 0.1
    for lo, hi in ((150, 200), (350, 400)):
        sigma = math.radians(1.5) * r[lo:hi].mean() / math.sqrt(2) / FWHM / 0.05
        got = lag_correlation(out[:, lo:hi], range(4, 5), axis=0)[0]
        assert got == pytest.approx(math.exp(-16 / (4 * sigma**2)), abs=0.04)


# -- bad input ---------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [
        ({"along_beam_deg": -1.0}, "along_beam_deg"),
        ({"along_beam_deg": 1.0, "sas_resolution_m": 0.1}, "only one"),
        ({"speckle": "gauss"}, "speckle"),
        ({"k_shape": 0.0}, "k_shape"),
        ({"bits": 10}, "bits"),
        ({"nadir_gap_deg": 95.0}, "nadir_gap_deg"),
        ({"tvg": "linear"}, "tvg"),
        ({"tvg": "curve", "tvg_curve": ((10.0, 1.0), (5.0, 2.0))}, "increasing"),
        ({"tvg_curve": ((0.0, 1.0), (5.0, 2.0))}, 'not "curve"'),
        ({"absorption": True, "temperature_c": 80.0}, "temperature"),
        ({"saturation": 0.0}, "saturation"),
        ({"noise_db": math.nan}, "noise_db"),
    ],
)
def test_bad_parameters_raise(kwargs, needle):
    with pytest.raises(SonarRasterError, match=needle):
        Effects(**kwargs)


def test_bad_images_and_files_raise(tmp_path):
    with pytest.raises(SonarRasterError, match="negative"):
        apply_effects(image_of(-np.ones((3, 4))), Effects(gain_db=1.0))
    with pytest.raises(SonarRasterError, match="cannot read"):
        load_tvg_curve(str(tmp_path / "missing.csv"))
    with pytest.raises(SonarRasterError, match="frequency"):
        francois_garrison(-5.0)


# -- vertical beam -----------------------------------------------------------------------------
def test_sinc_beam_is_the_aperture_pattern():
    length, freq = 0.04, 400e3
    lam = 1500.0 / freq
    beam = BeamPattern.sinc(length, freq)
    one_way = np.sqrt(beam.values)  # two-way sinc⁴ = (one-way sinc²)²
    main = one_way >= 0.5
    width = np.ptp(beam.angles[main])
    assert width == pytest.approx(0.886 * lam / length, rel=0.01)
    first_null = math.asin(lam / length)
    assert beam(first_null) < 1e-6 and beam(0.5 * first_null) > 0.1


@pytest.mark.parametrize("tilt_deg", [20.0, 35.0])
def test_tilted_beam_moves_the_flat_seabed_peak(gl, tilt_deg):
    altitude = 8.0
    traj = Trajectory.straight((0.0, -0.5, altitude), 0.0, 0.2, 6)
    scene = build_scene([plane(200.0)])
    tilt = math.radians(tilt_deg)
    shaped = Sonar(max_range=45.0, range_bin=0.05, beam=BeamPattern.sinc(0.03, 400e3), tilt=tilt)
    flat = Sonar(max_range=45.0, range_bin=0.05, tilt=tilt)
    a = gl.render(scene, shaped, traj).sides["starboard"].astype(np.float64).mean(axis=0)
    b = gl.render(scene, flat, traj).sides["starboard"].astype(np.float64).mean(axis=0)
    r = (np.arange(shaped.n_bins) + 0.5) * 0.05
    ok = r > altitude + 0.2
    ratio = np.where(ok, a / np.where(b > 0, b, 1.0), 0.0)
    peak = r[np.argmax(ratio)]
    assert peak == pytest.approx(altitude / math.sin(tilt), abs=0.15)
    pattern = shaped.gain(np.arcsin(altitude / r[ok]))
    assert np.corrcoef(ratio[ok], pattern)[0, 1] > 0.995


# -- sediments ---------------------------------------------------------------------------------
def test_sediment_table():
    order = ["rock", "gravel", "sand", "mud", "clay"]
    assert list(SEDIMENTS) == order
    levels = [sediment(n).bs45_db for n in order]
    assert levels == sorted(levels, reverse=True)  # harder, coarser seabeds scatter more
    for name in order:
        s = sediment(name.upper())
        r = material_reflectivity(name)
        assert 10 * math.log10(r * math.cos(math.radians(45))) == pytest.approx(s.bs45_db)
        assert s.lambert_db == pytest.approx(s.bs45_db + 3.0103, abs=1e-3)
        lo, hi = s.phi_range
        assert lo < hi
    with pytest.raises(SonarRasterError, match="unknown material"):
        sediment("cheese")


# -- scene files and the command line ---------------------------------------------------------
SCENE = """
[sonar]
max_range = 20.0
range_bin = 0.05
[seabed]
kind = "flat"
size = [50.0, 20.0]
material = "{material}"
[[objects]]
primitive = "box"
size = [1.0, 1.0, 1.0]
position = [8.0, 1.0]
material = "rock"
[trajectory]
altitude = 5.0
pings = 20
spacing = 0.1
[effects]
along_beam_deg = 1.5
speckle = "k"
k_shape = 2.0
tvg = "curve"
tvg_curve = "tvg.csv"
"""


def test_scene_materials_and_effects_table(tmp_path):
    from sonar_raster.scenes.description import load_scene_file

    (tmp_path / "tvg.csv").write_text("0,0\n20,40\n")
    path = tmp_path / "s.toml"
    path.write_text(SCENE.format(material="mud"))
    setup = load_scene_file(path)
    scene = setup.scene
    seabed = scene.reflectivity[scene.object_id == scene.names.index("seabed")]
    box = scene.reflectivity[scene.object_id != scene.names.index("seabed")]
    np.testing.assert_allclose(seabed, sediment("mud").reflectivity)
    np.testing.assert_allclose(box, sediment("rock").reflectivity)
    # a material brings its APL-UW law (index into MATERIALS, 0 = Lambert) ...
    from sonar_raster.scenes.sediments import material_index

    is_bed = scene.object_id == scene.names.index("seabed")
    assert np.all(scene.law[is_bed] == material_index("mud"))
    assert np.all(scene.law[~is_bed] == material_index("rock"))
    # ... unless scattering = "lambert" asks for Lambert; a plain reflectivity is Lambert
    lam = tmp_path / "lam.toml"
    lam.write_text(SCENE.format(material="mud").replace('"mud"', '"mud"\nscattering = "lambert"'))
    scene2 = load_scene_file(lam).scene
    assert np.all(scene2.law[scene2.object_id == scene2.names.index("seabed")] == 0)
    with pytest.raises(SonarRasterError, match="scattering must be one of lambert, apl"):
        lam.write_text(SCENE.format(material="mud").replace('"mud"', '"mud"\nscattering = "x"'))
        load_scene_file(lam)
    fx = setup.effects
    assert fx.stages == ("along_track", "speckle", "tvg")
    assert fx.k_shape == 2.0 and fx.tvg_curve == ((0.0, 0.0), (20.0, 40.0))
    path.write_text(SCENE.format(material="lava"))
    with pytest.raises(SonarRasterError, match="unknown material 'lava'"):
        load_scene_file(path)
    path.write_text(SCENE.format(material="mud") + "bogus = 1\n")
    with pytest.raises(SonarRasterError, match=r"\[effects\]: unknown key\(s\) bogus"):
        load_scene_file(path)
    both = SCENE.format(material="mud").replace(
        'material = "rock"', 'material = "rock"\nreflectivity = 0.5'
    )
    path.write_text(both)
    with pytest.raises(SonarRasterError, match="not both"):
        load_scene_file(path)


def test_cli_effects_options(tmp_path):
    from sonar_raster.cli.app import main
    from sonar_raster.io.images import read_exr

    plain, fx = tmp_path / "plain.exr", tmp_path / "fx.exr"
    common = ["render", "flat_calibration", "--pings", "30", "-q", "--ideal"]  # raw base
    assert main([*common, "-o", str(plain)]) == 0
    opts = ["--spreading", "--absorption", "--tvg", "log", "--tvg-log", "40", "--seed", "1"]
    assert main([*common, "-o", str(fx), *opts]) == 0
    a, _ = read_exr(plain)
    b, _ = read_exr(fx)
    # 40 log r + 2 α r undoes spreading and absorption exactly (float32 round-off aside).
    np.testing.assert_allclose(b["starboard"], a["starboard"], rtol=1e-4, atol=1e-9)
    speckled = tmp_path / "sp.exr"
    assert main([*common, "-o", str(speckled), "--speckle", "exponential", "--seed", "1"]) == 0
    c, _ = read_exr(speckled)
    assert not np.array_equal(c["starboard"], a["starboard"])
    bad = tmp_path / "bad.exr"
    assert main([*common, "-o", str(bad), "--along-beam-deg", "0"]) == 2
    assert not bad.exists()


def test_cli_options_merge_over_the_scene_effects():
    from sonar_raster.cli.app import _parser
    from sonar_raster.cli.effects_options import effects_from_args

    def parse(*extra):
        return _parser().parse_args(["render", "x.toml", "-o", "o.png", *extra])

    assert effects_from_args(parse("--ideal"), None) is None  # nothing on: the step is skipped
    assert effects_from_args(parse(), None).sensor == DEFAULT_SENSOR  # the default sensor
    scene = Effects(along_beam_deg=1.0, speckle="exponential")
    fx = effects_from_args(parse("--sas-resolution", "0.2", "--k-shape", "3"), scene)
    assert fx.sas_resolution_m == 0.2 and fx.along_beam_deg is None  # the CLI picks the mode
    assert fx.speckle == "k" and fx.k_shape == 3.0
    assert effects_from_args(parse("--no-effects"), scene) is None
    fx = effects_from_args(parse("--ideal", "--tvg-log", "20", "--quantise-bits", "12"), None)
    assert fx.tvg == "log" and fx.tvg_log_coefficient == 20.0 and fx.bits == 12


# -- one [effects] parser: scene files, dataset configs and the command line ------------------
def test_from_table_reads_what_a_scene_file_gave(tmp_path):
    (tmp_path / "tvg.csv").write_text("range_m,gain_db\n0,0\n20,40\n")
    table = {"along_beam_deg": 1.5, "speckle": "k", "k_shape": 2.0, "tvg": "curve"}
    fx = Effects.from_table({**table, "tvg_curve": "tvg.csv"}, base=tmp_path, where="s.toml")
    assert fx == Effects(**table, tvg_curve=((0.0, 0.0), (20.0, 40.0)))
    inline = Effects.from_table({**table, "tvg_curve": [[0, 0], [20.0, 40]]})
    assert inline == fx


def test_from_table_reads_what_a_dataset_config_gave():
    tables = [
        {"speckle": "exponential"},
        {"spreading": True, "absorption": True, "tvg": "log", "tvg_log_coefficient": 40},
        {"sas_resolution_m": 0.1, "noise_db": -60, "gain_db": 3, "saturation": 1, "bits": 12},
        {},
    ]
    for table in tables:
        fx = Effects.from_table(table)
        assert fx == Effects(**table)
        assert fx.changed() == table  # values as given: metadata does not change


def test_from_table_replaces_the_defaults_as_the_command_line_does(tmp_path, monkeypatch):
    scene = Effects(along_beam_deg=1.0, speckle="exponential", gain_db=2.0)
    modes = {"along_beam_deg": None, "array_length_m": None}
    fx = Effects.from_table({"sas_resolution_m": 0.2, **modes}, defaults=scene)
    assert fx == Effects(sas_resolution_m=0.2, speckle="exponential", gain_db=2.0)
    assert Effects.from_table({}, defaults=scene) == scene
    monkeypatch.chdir(tmp_path)  # a curve named on the command line is relative to the cwd
    (tmp_path / "c.csv").write_text("1,0\n9,12\n")
    fx = Effects.from_table({"tvg": "curve", "tvg_curve": "c.csv"}, defaults=scene)
    assert fx.tvg_curve == ((1.0, 0.0), (9.0, 12.0)) and fx.gain_db == 2.0


@pytest.mark.parametrize(
    ("table", "needle"),
    [
        ({"bogus": 1, "speckle": "k"}, r"^s\.toml \[effects\]: unknown key\(s\) bogus$"),
        ({"spreading": "yes"}, r"^s\.toml \[effects\]: 'spreading' must be true or false"),
        ({"absorption": 1}, "'absorption' must be true or false"),
        ({"bits": 10}, "'bits' must be 8, 12 or 16, got 10"),
        ({"bits": 8.0}, "'bits' must be 8, 12 or 16, got 8.0"),
        ({"tvg": "curve", "tvg_curve": [[1, 2], [3]]}, "'tvg_curve' must be a CSV file name"),
        ({"tvg": "curve", "tvg_curve": [["1", "2"], ["3", "4"]]}, "'tvg_curve' must be"),
        ({"tvg": "curve", "tvg_curve": 5}, "'tvg_curve' must be"),
        ({"tvg": "curve", "tvg_curve": "missing.csv"}, "cannot read TVG curve .*missing.csv"),
        ({"tvg": "curve", "tvg_curve": [[0, 1]]}, ">= 2 rows"),
        ({"tvg_curve": [[0, 1], [5, 2]]}, 'tvg is not "curve"'),
        ({"gain_db": "3"}, "gain_db must be a number, got '3'"),
        ({"along_beam_deg": -1.0}, "along_beam_deg must be > 0"),
        ({"nadir_gap_deg": math.nan}, "nadir_gap_deg must be finite"),
        ({"nadir_gap_deg": 95}, "nadir_gap_deg must be in"),
        ({"speckle": "gauss"}, "unknown speckle 'gauss'"),
        ({"along_beam_deg": 1.0, "sas_resolution_m": 0.1}, "only one"),
        ({"absorption_db_m": -0.1}, "absorption_db_m"),
        ({"depth_m": math.inf}, "depth_m must be finite"),
    ],
)
def test_from_table_rejects_bad_values_with_one_clear_message(tmp_path, table, needle):
    with pytest.raises(SonarRasterError, match=needle) as info:
        Effects.from_table(table, base=tmp_path, where="s.toml [effects]")
    message = str(info.value)
    assert "\n" not in message and "__init__" not in message


def test_ragged_curve_given_directly_is_a_clear_error():
    with pytest.raises(SonarRasterError, match="TVG curve"):
        Effects(tvg="curve", tvg_curve=((0.0, 1.0), (2.0,)))  # type: ignore[arg-type]


def test_cli_downsample_options_reach_the_effects(tmp_path, capsys):
    from sonar_raster.cli.app import _parser, main
    from sonar_raster.cli.effects_options import effects_from_args

    def parse(*extra):
        return _parser().parse_args(["render", "x.toml", "-o", "o.png", *extra])

    opts = ("--speckle", "exponential", "--downsample", "max", "--sample-spacing", "0.01")
    fx = effects_from_args(parse("--ideal", *opts), None)
    assert fx.downsample == "max" and fx.sample_spacing_m == 0.01
    sensor = ("--sensor", "marine-sonic-600-max")  # sets max and its spacing
    spacing = effects_from_args(parse(*sensor), None).sample_spacing_m
    fx = effects_from_args(parse(*sensor, "--downsample", "mean"), None)  # the method alone
    assert fx.downsample == "mean" and fx.sample_spacing_m == spacing is not None
    assert effects_from_args(parse(*sensor, "--downsample", "off"), None).downsample == "off"
    fx = effects_from_args(parse(*sensor, "--sample-spacing", "0.005"), None)
    assert fx.downsample == "max" and fx.sample_spacing_m == 0.005

    out = str(tmp_path / "bad.exr")
    base = ["render", "flat_calibration", "--pings", "4", "-q", "-o", out]
    for bad, fix in (
        (["--sample-spacing", "0"], "must be a length > 0 in metres"),
        (["--sample-spacing", "-0.01"], "must be a length > 0 in metres"),
        (["--downsample", "min"], "choose from"),
    ):
        with pytest.raises(SystemExit) as exit_:
            main([*base, *bad])
        err = capsys.readouterr().err
        assert exit_.value.code == 2 and err.count("\n") == 1
        assert bad[0] in err and fix in err
    for bad, fix in (
        (["--ideal", "--speckle", "exponential", "--downsample", "max"], "add --sample-spacing"),
        (["--ideal", "--sample-spacing", "0.01"], "add --downsample max or mean"),
    ):
        assert main([*base, *bad]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and fix in err
    assert not (tmp_path / "bad.exr").exists()


def test_bad_effect_options_fail_before_any_render(tmp_path, capsys, monkeypatch):
    """An effect option that cannot work is refused before the (possibly long) render."""
    from sonar_raster.cli import render as render_cli
    from sonar_raster.cli.app import main

    def no_render(*_args, **_kwargs):
        raise AssertionError("rendered before checking the effect options")

    monkeypatch.setattr(render_cli, "_render_image", no_render)
    out = tmp_path / "bad.exr"
    for model in ("raster", "coherent"):
        code = main(
            ["render", "flat_calibration", "--pings", "4", "-q", "-o", str(out), "--model", model]
            + ["--ideal", "--sample-spacing", "0.01"]
        )
        err = capsys.readouterr().err
        assert code == 2 and err.count("\n") == 1 and "add --downsample" in err, (model, err)
    assert not out.exists()


def test_downsampling_without_a_sample_spacing_is_refused_not_ignored():
    from sonar_raster.effects.chain import Effects

    with pytest.raises(SonarRasterError, match="downsample 'max' needs the recorder's sample"):
        Effects.from_table({"speckle": "exponential", "downsample": "max"}, where="[effects]")
    fx = Effects.from_table({"downsample": "mean", "sample_spacing_m": 0.01}, where="[effects]")
    assert fx.downsample == "mean"
