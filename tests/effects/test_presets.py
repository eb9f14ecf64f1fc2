"""Sensor presets: valid sonars and effects, physical consistency, the real file's header."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import SHARED_DATA, plane

import sonar_raster
from sonar_raster.effects.along_track import LINE_APERTURE_WIDTH
from sonar_raster.effects.chain import Effects, apply_effects
from sonar_raster.effects.presets import PRESETS, SensorPreset, list_presets, preset
from sonar_raster.errors import SonarRasterError
from sonar_raster.scene import build_scene
from sonar_raster.sonar import Sonar
from sonar_raster.trajectory import Trajectory

XTF = SHARED_DATA / "xtf" / "scotsman-iver2.xtf"
NAMES = list_presets()


def test_table_covers_the_brief():
    side_scans = [p for p in PRESETS.values() if p.kind == "side-scan"]
    in_band = {p.name for p in side_scans if 100e3 <= p.frequency_hz <= 1e6}
    assert len(in_band) >= 5
    assert min(p.frequency_hz for p in side_scans) == 100e3
    assert "marine-sonic-600" in in_band
    assert [p.name for p in PRESETS.values() if p.kind == "sas"] == ["kongsberg-hisas-1030"]
    assert NAMES == sorted(NAMES, key=lambda n: PRESETS[n].frequency_hz)


@pytest.mark.parametrize("name", NAMES)
def test_every_preset_is_cited_and_says_what_it_chose(name):
    p = preset(name)
    assert p.sources and all(s.startswith("https://") or "xtf" in s for s in p.sources)
    assert p.notes
    for field in p.assumed:  # every chosen figure is named in the notes' "Chosen" part
        assert field in SensorPreset.__dataclass_fields__
    assert "hosen" in p.notes or not p.assumed


@pytest.mark.parametrize("name", NAMES)
def test_preset_builds_a_valid_sonar_and_effects(name):
    p = preset(name)
    sonar = p.sonar()
    assert isinstance(sonar, Sonar)
    assert sonar.frequency_hz == p.frequency_hz
    assert sonar.max_range == p.max_ranges_m[0]
    assert sonar.tilt == pytest.approx(math.radians(p.tilt_deg))
    assert sonar.sound_speed == p.sound_speed_m_s
    # Two-way Gaussian beam: half power at ± one-way width / (2 √2) off the axis.
    half = math.radians(p.vertical_beamwidth_deg) / (2 * math.sqrt(2))
    assert float(sonar.beam(half)) == pytest.approx(0.5, rel=1e-3)
    assert p.sonar(sides=("port",)).sides == ("port",)
    fx = p.effects()
    assert isinstance(fx, Effects)
    expected = {"along_track", "water_column", "speckle", "spreading", "absorption", "noise"}
    expected |= {"tvg", "saturate", "quantise"}
    assert set(fx.stages) == expected
    assert fx.range_resolution_m == pytest.approx(p.range_resolution_m)
    assert fx.bits == p.bits
    if p.kind == "sas":
        assert fx.sas_resolution_m == p.sas_resolution_m and fx.along_beam_deg is None
    else:
        assert fx.along_beam_deg == p.horizontal_beamwidth_deg


@pytest.mark.parametrize("name", NAMES)
def test_preset_renders_a_tiny_flat_scene(name):
    p = preset(name)
    sonar = p.sonar(max_range=12.0, range_bin=0.1)
    scene = build_scene([plane(60.0, z=-5.0)])
    traj = Trajectory.straight((0.0, -0.6, 0.0), 90.0, 0.2, 6)
    raw = sonar_raster.render(scene, sonar, traj)
    out = apply_effects(raw, p.effects(), seed=1, trajectory=traj)
    for side in sonar.sides:
        a = out.sides[side]
        assert a.shape == (6, sonar.n_bins) and a.dtype == np.float32
        assert np.all(np.isfinite(a)) and np.all(a >= 0) and a.max() > 0
        levels = np.sqrt(np.unique(a).astype(np.float64) / out.metadata["effects"]["full_scale"])
        steps = levels * (2**p.bits - 1)  # the amplitude is quantised to p.bits
        assert np.allclose(steps, np.round(steps), atol=0.02 * np.maximum(1.0, steps / 100))
        assert a.min() > 0  # a positive value never rounds to code 0


# -- physics -------------------------------------------------------------------------------
@pytest.mark.parametrize("name", NAMES)
def test_range_resolution_follows_bandwidth_or_pulse_length(name):
    p = preset(name)
    c = p.sound_speed_m_s
    if p.bandwidth_hz is not None:
        assert p.range_resolution_m == pytest.approx(c / (2 * p.bandwidth_hz))
    else:
        assert p.range_resolution_m == pytest.approx(c * p.pulse_length_s / 2)
    if p.pulse == "cw" and p.bandwidth_hz is not None and p.pulse_length_s is not None:
        assert p.bandwidth_hz * p.pulse_length_s == pytest.approx(1.0, rel=0.2)
    if p.pulse == "chirp" and p.pulse_length_s is not None:
        assert p.bandwidth_hz * p.pulse_length_s > 10  # a chirp compresses its pulse
    # A resolution cell spans many wavelengths' worth of bandwidth only if B < f.
    assert p.bandwidth_hz is None or p.bandwidth_hz < p.frequency_hz


@pytest.mark.parametrize("name", [n for n in NAMES if PRESETS[n].kind == "side-scan"])
def test_horizontal_beam_matches_a_plausible_line_array(name):
    """β ≈ 0.886 λ / L: the implied array fits a towfish or AUV (5 cm to 3 m)."""
    p = preset(name)
    beam = math.radians(p.horizontal_beamwidth_deg)
    length = LINE_APERTURE_WIDTH * p.wavelength_m / beam
    if p.array_length_m is not None:
        assert length == pytest.approx(p.array_length_m, rel=0.15)
    assert 0.05 < length < 3.0


def test_published_beam_widths_are_kept_exactly():
    assert preset("datasonics-sis1500").horizontal_beamwidth_deg == 1.0
    assert preset("datasonics-sis1500").bandwidth_hz == 20e3  # 190-210 kHz sweep
    assert preset("datasonics-sis1500").range_resolution_m == pytest.approx(0.0375)
    g = preset("garmin-sidevu-1200")
    assert (g.horizontal_beamwidth_deg, g.vertical_beamwidth_deg) == (0.44, 55.0)
    assert g.max_ranges_m[0] == pytest.approx(125 * 0.3048)


def test_sas_resolution_is_range_independent_and_matches_its_bandwidth():
    p = preset("kongsberg-hisas-1030")
    assert p.sas_resolution_m == pytest.approx(p.range_resolution_m)  # 3 cm × 3 cm
    # At its full range a real aperture would need an absurd array for the same 3 cm.
    needed = LINE_APERTURE_WIDTH * p.wavelength_m * p.max_ranges_m[0] / p.sas_resolution_m
    assert needed > 50.0


def test_default_bins_sample_the_resolution_cell_twice():
    p = preset("klein-3900-445")
    assert p.sonar().range_bin == pytest.approx(p.range_resolution_m / 2)


# -- the real file --------------------------------------------------------------------------
@pytest.fixture(scope="module")
def xtf_header():
    if not XTF.is_file():
        pytest.skip(f"{XTF} is missing")
    pyxtf = pytest.importorskip("pyxtf")
    fh, packets = pyxtf.xtf_read(str(XTF))
    pings = next(iter(packets.values()))
    return fh, pings


def test_marine_sonic_preset_matches_the_real_files_header(xtf_header):
    fh, pings = xtf_header
    p = preset("marine-sonic-600")
    chans = [c for ping in pings for c in ping.ping_chan_headers]
    assert {int(c.Frequency) for c in chans} == {600}
    assert {float(c.Frequency) for c in fh.sonar_info} == {600.0}
    assert p.frequency_hz == 600e3
    assert {float(c.SlantRange) for c in chans} == {p.max_ranges_m[0]}
    assert {int(c.NumSamples) for c in chans} == {p.range_bins}
    sonar = p.sonar()
    assert sonar.n_bins == p.range_bins
    assert sonar.range_bin == pytest.approx(chans[0].SlantRange / chans[0].NumSamples)
    # SoundVelocity holds half the sound speed; the timing agrees.
    assert {2 * float(ping.SoundVelocity) for ping in pings} == {p.sound_speed_m_s}
    c = chans[0]
    assert 2 * c.SlantRange / c.TimeDuration == pytest.approx(p.sound_speed_m_s, rel=1e-3)
    assert {int(ci.BytesPerSample) for ci in fh.sonar_info} == {p.bits // 8}
    assert max(int(np.max(d)) for ping in pings for d in ping.data) < 2**p.bits
    # Each recorded sample is the largest of several finer ones (XTF DownsampleMethod 2 = MAX):
    # the -max variant's recorder does the same, with a pulse shorter than a recorded sample.
    assert {int(c.DownsampleMethod) for c in chans} == {2}
    m = preset("marine-sonic-600-max")
    assert m.downsample == "max" and m.effects().downsample == "max"
    assert m.range_resolution_m < sonar.range_bin
    assert p.downsample == "off" and p.range_resolution_m == pytest.approx(sonar.range_bin)
    # What the file does not record is listed as chosen.
    assert {float(ci.BeamWidth) for ci in fh.sonar_info} == {0.0}
    assert {"horizontal_beamwidth_deg", "tilt_deg"} <= set(p.assumed)


# -- errors ---------------------------------------------------------------------------------
@pytest.mark.parametrize("bad", ["klein-3000", "", "MARINE-SONIC-600", None, 600])
def test_unknown_name_gives_one_clear_error(bad):
    with pytest.raises(SonarRasterError) as err:
        preset(bad)
    message = str(err.value)
    assert "unknown sensor preset" in message
    assert all(name in message for name in NAMES)
    assert "\n" not in message


def test_a_side_scan_without_a_beam_is_refused():
    p = preset("klein-3900-445")
    fields = {f: getattr(p, f) for f in SensorPreset.__dataclass_fields__}
    with pytest.raises(SonarRasterError, match="horizontal beam"):
        SensorPreset(**{**fields, "horizontal_beamwidth_deg": None})
    with pytest.raises(SonarRasterError, match="unknown fields"):
        SensorPreset(**{**fields, "assumed": ("colour",)})
