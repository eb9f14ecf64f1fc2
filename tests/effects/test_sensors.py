"""Sensor presets wired in: --sensor, [sonar] preset, the realistic default, --ideal, the floor."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from sonar_raster.cli.app import main
from sonar_raster.effects.chain import Effects, apply_effects, tvg_db
from sonar_raster.effects.presets import DEFAULT_SENSOR, PRESETS, list_presets, preset
from sonar_raster.errors import SonarRasterError
from sonar_raster.image import SonarImage
from sonar_raster.io.images import read_exr, read_pixels, write_image
from sonar_raster.rendering.entry import render
from sonar_raster.scenes.description import Overrides, load_scene
from sonar_raster.sonar import BeamPattern, Sonar

FWHM = 2.0 * math.sqrt(2.0 * math.log(2.0))
EVERY_STAGE = {
    "along_track",
    "water_column",
    "speckle",
    "spreading",
    "absorption",
    "noise",
    "tvg",
    "saturate",
    "quantise",
}


def _sidecar(path) -> dict:
    return json.loads(path.with_suffix(".json").read_text())


# -- the command line --------------------------------------------------------------------------
def test_ideal_is_the_raw_render_bit_for_bit(tmp_path):
    exr, png = tmp_path / "ideal.exr", tmp_path / "ideal.png"
    args = ["render", "default", "--pings", "24", "-q", "--ideal"]
    assert main([*args, "-o", str(exr), "-o", str(png)]) == 0
    sides, _ = read_exr(exr)
    setup = load_scene("default", Overrides(pings=24, micro_relief=False))  # no seabed texture
    raw = render(setup.scene, setup.sonar, setup.trajectory)
    for side in raw.sides:
        assert np.array_equal(sides[side], raw.sides[side])  # bit for bit
    assert (raw.sides["starboard"] == 0).any()  # raw: the water column is exactly zero
    assert "sensor_preset" not in _sidecar(exr)["metadata"]
    # the PNG is today's raw display image too (peak level, auto range), code for code
    write_image(raw, tmp_path / "api.png", sidecar=False)
    assert np.array_equal(read_pixels(png)[0], read_pixels(tmp_path / "api.png")[0])
    assert "level" not in _sidecar(png)["display_mapping"]


def test_ideal_with_a_sensor_is_its_sonar_without_effects(tmp_path, capsys):
    exr = tmp_path / "ideal.exr"
    args = ["render", "default", "--pings", "8", "-q", "--ideal", "-o", str(exr)]
    assert main([*args, "--sensor", "klein-3900-900"]) == 0
    sidecar = _sidecar(exr)
    assert sidecar["metadata"]["sensor_sonar"] == "klein-3900-900"
    assert "effects" not in sidecar["metadata"]  # ideal: the raw image of that sonar
    assert main([*args, "--sensor", "nonsense"]) == 2  # not silently dropped
    assert "unknown sensor preset 'nonsense'" in capsys.readouterr().err


def test_default_render_has_every_effect_of_the_default_sensor_and_no_zeros(tmp_path):
    exr = tmp_path / "real.exr"
    assert main(["render", "default", "--pings", "24", "-q", "--seed", "3", "-o", str(exr)]) == 0
    meta = _sidecar(exr)["metadata"]
    assert meta["sensor_preset"] == DEFAULT_SENSOR
    assert set(meta["effects"]["stages"]) == EVERY_STAGE
    sides, _ = read_exr(exr)
    setup = load_scene("default", Overrides(pings=24))
    raw = render(setup.scene, setup.sonar, setup.trajectory)
    for side in sides:
        zero = raw.sides[side] == 0  # water column and shadows in the raw image
        assert zero.sum() > 1000
        assert np.all(sides[side][zero] > 0)  # they hold the noise floor in the recording


def test_sensor_option_sets_the_sonar_and_the_effects(tmp_path):
    exr = tmp_path / "k.exr"
    name = "klein-3900-900"
    args = ["render", "default", "--pings", "6", "-q", "--sensor", name, "-o", str(exr)]
    assert main(args) == 0
    doc = _sidecar(exr)
    p = PRESETS[name]
    assert doc["sonar"]["frequency_hz"] == p.frequency_hz
    assert doc["sonar"]["max_range_m"] == p.max_ranges_m[0]
    assert doc["sonar"]["range_bin_m"] == pytest.approx(p.range_resolution_m / 2)
    assert doc["sonar"]["tilt_deg"] == pytest.approx(p.tilt_deg)
    assert doc["metadata"]["sensor_preset"] == name
    assert doc["metadata"]["sensor_sonar"] == name
    assert doc["metadata"]["effects"]["settings"]["along_beam_deg"] == p.horizontal_beamwidth_deg
    # --range keeps the preset's sample count where it has one (the real file's 1024)
    exr2 = tmp_path / "m.exr"
    args = ["render", "default", "--pings", "4", "-q", "--sensor", "marine-sonic-600"]
    assert main([*args, "--range", "20", "-o", str(exr2)]) == 0
    assert _sidecar(exr2)["sonar"]["n_bins"] == 1024


def test_unknown_sensor_is_one_line(tmp_path, capsys):
    out = tmp_path / "x.png"
    assert main(["render", "default", "--pings", "4", "--sensor", "nope", "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "marine-sonic-600" in err
    assert not out.exists()


def test_sensors_command_lists_every_preset(capsys):
    assert main(["sensors"]) == 0
    text = capsys.readouterr().out
    for name in list_presets():
        assert name in text
    assert "(default)" in text
    assert main(["sensors", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["default"] == DEFAULT_SENSOR and set(doc["presets"]) == set(PRESETS)


# -- scene files and tables --------------------------------------------------------------------
SCENE = """
[sonar]
preset = "garmin-sidevu-1200"
max_range = 20.0
sides = ["starboard"]
[seabed]
kind = "flat"
size = [60.0, 30.0]
reflectivity = 0.3
[trajectory]
altitude = 5.0
spacing = 0.1
pings = 10
"""


def test_scene_preset_fills_the_sonar_and_the_effects(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(SCENE + "[effects]\nnoise_db = -150.0\n")
    setup = load_scene(path)
    p = PRESETS["garmin-sidevu-1200"]
    assert setup.sonar.frequency_hz == p.frequency_hz
    assert setup.sonar.max_range == 20.0  # the file's key wins over the preset
    assert setup.sonar.range_bin == pytest.approx(p.range_resolution_m / 2)
    assert setup.sonar.tilt == pytest.approx(math.radians(p.tilt_deg))
    half = math.radians(p.vertical_beamwidth_deg) / (2 * math.sqrt(2))
    assert float(setup.sonar.beam(half)) == pytest.approx(0.5, rel=1e-3)
    assert setup.effects.sensor == p.name
    assert setup.effects.along_beam_deg == p.horizontal_beamwidth_deg
    assert setup.effects.noise_db == -150.0  # the file's [effects] key wins
    path.write_text(SCENE.replace("garmin-sidevu-1200", "nope"))
    with pytest.raises(SonarRasterError, match=r"s\.toml \[sonar\].*unknown sensor preset"):
        load_scene(path)


def test_table_sensor_key():
    assert Effects.from_table({"sensor": "ideal"}).stages == ()
    fx = Effects.from_table({"sensor": "klein-3900-445", "noise_db": -100.0})
    assert fx == replace(preset("klein-3900-445").effects(), noise_db=-100.0)
    with pytest.raises(SonarRasterError, match=r"^here: unknown sensor preset"):
        Effects.from_table({"sensor": "nope"}, where="here")


def test_dataset_default_effects_are_the_default_sensors():
    from sonar_raster.dataset.sample import effects_of

    config = SimpleNamespace(effects=None, source="x.toml", base=".")
    assert effects_of(config) == preset(DEFAULT_SENSOR).effects()
    config.effects = {"sensor": "ideal"}
    assert effects_of(config).stages == ()


# -- the parameters reach the image ------------------------------------------------------------
@pytest.mark.parametrize("name", [n for n in PRESETS if PRESETS[n].kind == "side-scan"])
def test_along_track_width_follows_the_presets_beam_width(name):
    p = PRESETS[name]
    fx = replace(
        p.effects(),
        speckle="off",
        noise_db=None,
        volume_db=None,
        bits=None,
        headroom_db=None,
        ping_spacing_m=0.02,
    )
    sonar = p.sonar()
    n_bins = sonar.n_bins
    data = np.zeros((401, n_bins))
    data[200] = 1.0  # one ping line: its along-track spread is the footprint
    out = apply_effects(SonarImage({"starboard": data}, sonar), fx).sides["starboard"]
    k = int(0.8 * n_bins)
    column = out[:, k].astype(np.float64)
    n = np.arange(len(column))
    w = column / column.sum()
    sigma = math.sqrt((w * (n - (w * n).sum()) ** 2).sum())
    r = (k + 0.5) * sonar.range_bin
    expected = math.radians(p.horizontal_beamwidth_deg) * r / math.sqrt(2) / FWHM / 0.02
    assert sigma == pytest.approx(expected, rel=0.03)


@pytest.mark.parametrize("effects", [True, False], ids=["effects", "ideal"])
@pytest.mark.parametrize("name", [n for n in PRESETS if PRESETS[n].kind == "side-scan"])
def test_each_presets_render_shows_the_first_bottom_return(name, effects):
    """Over a flat plane at 8 m the preset's own sonar (its range and bins), with its effects
    or none, gives a first return at the nadir that the bottom tracker finds within a bin.
    Without the beam's sidelobe floor 7 of these 14 fail; without the tracker's floor under a
    noise-free image's faintest returns (``bottom._log_image``) 4 of the 7 without effects."""
    from conftest import plane

    from sonar_raster import Trajectory, build_scene
    from sonar_raster.inversion.bottom import track_bottom
    from sonar_raster.rendering.gl.raster import render_raster

    p = PRESETS[name]
    sonar = p.sonar()  # its own range and bins
    track = Trajectory.straight((0.0, 0.0, 8.0), 0.0, 0.1, 60)
    raw = render_raster(build_scene([plane(200.0, reflectivity=0.1)]), sonar, track)
    if effects:
        fx = replace(p.effects(), ping_spacing_m=0.1)
        raw = apply_effects(raw, fx, seed=3, trajectory=track)
    sides = {s: v.astype(np.float64) for s, v in raw.sides.items()}
    altitude = track_bottom(sides, sonar.range_bin).altitude
    assert abs(float(np.median(altitude)) - 8.0) <= sonar.range_bin


def test_the_sidelobe_floor_holds_the_gaussian_off_its_axis():
    plain, floored = BeamPattern.gaussian(35.0), BeamPattern.gaussian(35.0, sidelobe_db=-40.0)
    off = np.radians(np.arange(0.0, 90.0, 0.5))
    assert floored(off).min() == pytest.approx(1e-4) and plain(np.radians(80.0)) < 1e-6
    main_lobe = plain(off) > 1e-4
    np.testing.assert_array_equal(floored(off)[main_lobe], plain(off)[main_lobe])
    with pytest.raises(SonarRasterError, match="sidelobe level must be < 0 dB"):
        BeamPattern.gaussian(35.0, sidelobe_db=3.0)


def test_noise_floor_in_shadows_is_the_sensors_level():
    p = preset(DEFAULT_SENSOR)
    sonar = p.sonar()
    data = np.full((300, sonar.n_bins), 1e-6)  # sand: R sin g · Δy · δr, m²
    data[:, :200] = 0.0  # water column
    data[100:200, 600:800] = 0.0  # a shadow
    fx = replace(p.effects(), speckle="off", along_beam_deg=None, ping_spacing_m=0.05)
    out = apply_effects(SonarImage({"starboard": data}, sonar), fx, seed=2).sides["starboard"]
    shadow = out[100:200, 600:800].astype(np.float64)
    assert shadow.min() > 0  # quantised, yet never exactly zero
    r = (np.arange(600, 800) + 0.5) * sonar.range_bin
    alpha = fx.alpha_db_m(sonar.frequency_hz)
    expected = 10 ** (p.noise_db / 10) * 10 ** (tvg_db(fx, r, alpha) / 10)
    assert shadow.mean(axis=0).mean() == pytest.approx(expected.mean(), rel=0.03)
    assert np.all(out[:, :200] > 0)  # the water column holds reverberation and noise


def test_volume_reverberation_level_closed_form():
    sonar = Sonar(max_range=20.0, range_bin=0.05, beam=BeamPattern.uniform())
    data = np.zeros((5, sonar.n_bins))
    data[:, 200:] = 1.0
    image = SonarImage({"starboard": data}, sonar)
    r = (np.arange(200) + 0.5) * 0.05
    out = apply_effects(image, Effects(volume_db=-60.0, ping_spacing_m=0.1)).sides["starboard"]
    # uniform beam: Ψ = π over depression angles (-90°, 90°); no along-track beam: width = Δy
    np.testing.assert_allclose(out[0, :200], 1e-6 * 0.05 * r * math.pi * 0.1, rtol=2e-6)
    assert np.all(out[:, 200:] == 1.0)
    beam = apply_effects(image, Effects(volume_db=-60.0, ping_spacing_m=0.1, along_beam_deg=1.0))
    width = math.sqrt(2 * math.pi) * math.radians(1.0) * r / math.sqrt(2) / FWHM
    got = beam.sides["starboard"][0, :200].astype(np.float64)
    np.testing.assert_allclose(got[40:], (1e-6 * 0.05 * r * math.pi * width)[40:], rtol=0.02)


def test_quantisation_keeps_positive_values_off_code_zero():
    data = np.array([[0.0, 1e-9, 0.4 / 255, 0.6 / 255, 1.0]])
    out = apply_effects(SonarImage({"port": data}, Sonar()), Effects(bits=8)).sides["port"]
    codes = np.round(out[0].astype(np.float64) * 255).astype(int)
    assert codes.tolist() == [0, 1, 1, 1, 255]


def test_explicit_sonar_options_win_over_the_sensor_preset(tmp_path):
    """--frequency, --tilt, --beamwidth and --sound-speed given with --sensor are kept."""
    name = "klein-3900-900"
    p = PRESETS[name]
    base = ["render", "default", "--pings", "4", "-q", "--sensor", name]
    exr = tmp_path / "o.exr"
    extra = ["--frequency", "123", "--tilt", "33", "--beamwidth", "21", "--sound-speed", "1480"]
    assert main([*base, *extra, "-o", str(exr)]) == 0
    doc = _sidecar(exr)
    assert doc["sonar"]["frequency_hz"] == pytest.approx(123e3)
    assert doc["sonar"]["tilt_deg"] == pytest.approx(33.0)
    assert doc["sonar"]["sound_speed_m_s"] == pytest.approx(1480.0)
    assert doc["metadata"]["sensor_sonar_overrides"] == [
        "--frequency",
        "--tilt",
        "--beamwidth",
        "--sound-speed",
    ]
    # the preset's other settings stay (its range sampling and its effects)
    assert doc["sonar"]["max_range_m"] == p.max_ranges_m[0]
    assert doc["metadata"]["effects"]["settings"]["along_beam_deg"] == p.horizontal_beamwidth_deg
    # the beam is the asked one: a Gaussian two-way beam of 5° full width at half power
    from sonar_raster.cli.app import _parser as build_parser
    from sonar_raster.cli.effects_options import apply_sensor_option
    from sonar_raster.cli.render import load_setup

    args = build_parser().parse_args([*base, "--beamwidth", "5", "--tilt", "33", "-o", "x.exr"])
    setup = apply_sensor_option(args, load_setup(args))
    beam = setup.sonar.beam
    assert float(beam(np.radians([2.5]))[0]) == pytest.approx(0.5, abs=0.01)  # half power at 2.5°
    assert setup.sonar.tilt == pytest.approx(math.radians(33.0))
