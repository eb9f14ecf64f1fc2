"""Options a new user reaches for: placement of bare models, sonar options, -q, --version,
invert on a display PNG, a recorded track, and warnings for settings that image little."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from conftest import SHARED_DATA

from sonar_raster import __version__
from sonar_raster.cli import app
from sonar_raster.cli.app import main
from sonar_raster.cli.invert import load_side
from sonar_raster.io.images import read_exr

XTF = SHARED_DATA / "xtf" / "scotsman-iver2.xtf"
#: A 0.5 x 0.5 x 2 m post authored z-up, in VRML (y-up by its specification).
POST_VRML = "#VRML V2.0 utf8\nShape { geometry Box { size 0.5 0.5 2 } }\n"


def test_version(capsys):
    with pytest.raises(SystemExit) as info:
        main(["--version"])
    assert info.value.code == 0
    assert capsys.readouterr().out.strip() == f"sonar-raster {__version__}"
    assert __version__ != "0+unknown"  # installed (editable): the package metadata's version


def test_scenes_lists_default_first(capsys):
    assert main(["scenes"]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert first.startswith("default ") and "= cylinder_on_flat" in first
    assert main(["scenes", "-q"]) == 0
    names = capsys.readouterr().out.split()
    assert names[0] == "default" and "cylinder_on_flat" in names


def test_every_command_takes_q_and_quiet():
    parser = app._parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    for name, command in sub.choices.items():
        flags = [a.option_strings for a in command._actions if a.dest == "quiet"]
        assert flags and set(flags[0]) == {"-q", "--quiet"}, name


def test_quiet_silences_a_command_without_its_own_summary(capsys):
    assert main(["doctor", "-q"]) in (0, 1)
    assert capsys.readouterr().out == ""


def test_spacing_is_a_deprecated_alias_that_warns_and_still_works(monkeypatch, tmp_path, capsys):
    from sonar_raster.rendering import entry

    seen = {}

    class Stop(Exception):
        pass

    def fake(scene, sonar, trajectory, **kwargs):
        seen.update(kwargs)
        raise Stop

    monkeypatch.setattr(entry, "render", fake)
    args = ["render", "flat_calibration", "-o", str(tmp_path / "o.exr"), "--pings", "2", "-q"]
    with pytest.raises(Stop):
        main([*args, "--model", "coherent", "--spacing", "3"])
    assert seen["coherent"]["spacing_wavelengths"] == 3.0
    err = capsys.readouterr().err.strip()
    assert err == (
        "sonar-raster: warning: --spacing is deprecated (it reads like ping spacing); "
        "use --scatterer-spacing"
    )


def test_settings_that_image_nothing_or_little(tmp_path, capsys):
    out = tmp_path / "o.png"
    base = ["render", "flat_calibration", "-o", str(out), "--pings", "3", "-q", "--no-effects"]
    assert main([*base, "--altitude", "100", "--range", "40"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "altitude 100 m is above the maximum range 40 m" in err
    assert not out.exists()
    assert main([*base, "--range-bin", "10", "--range", "40"]) == 0
    err = capsys.readouterr().err
    assert err == (
        "sonar-raster: warning: range bin 10 m over the 40 m range leaves 4 range bins per "
        "side: the image is 4 pixels wide; lower --range-bin (e.g. 0.05) or raise --range\n"
    )
    assert json.loads(out.with_suffix(".json").read_text())["sonar"]["n_bins"] == 4


def test_sonar_options_reach_the_image_metadata(tmp_path):
    out = tmp_path / "o.exr"
    args = ["render", "flat_calibration", "-o", str(out), "--pings", "3", "-q", "--no-effects"]
    args += ["--frequency", "900", "--tilt", "15", "--beamwidth", "20", "--sound-speed", "1490"]
    assert main([*args, "--heading", "90", "--speed", "1.5"]) == 0
    sonar = json.loads(out.with_suffix(".json").read_text())["sonar"]
    assert sonar["frequency_hz"] == 900e3 and sonar["sound_speed_m_s"] == 1490.0
    assert sonar["tilt_deg"] == pytest.approx(15.0) and sonar["beam"] == "gaussian"


def _shadow_bins(exr, rows) -> int:
    """Zero bins behind the object in the pings through its middle (beyond the water column)."""
    star = read_exr(exr)[0]["starboard"][rows]
    first = np.argmax(star > 0, axis=1).max()  # first seabed return
    return int(np.median(np.sum(star[:, first:] == 0, axis=1)))


def test_up_z_stands_a_z_up_post_and_its_shadow_shows_its_height(tmp_path, capsys):
    model = tmp_path / "post.wrl"
    model.write_text(POST_VRML)
    common = ["render", str(model), "--pings", "21", "--ping-spacing", "0.1", "--no-effects"]
    common += ["--range-bin", "0.02"]
    heights = {}
    for up, height in ((None, 0.5), ("z", 2.0)):
        out = tmp_path / f"{up}.exr"
        assert main([*common, "-o", str(out), *(["--up", up] if up else [])]) == 0
        line = capsys.readouterr().out.splitlines()[0]
        assert line.startswith("placed post.wrl: ") and f"x {height:.3g} m (up {up or 'y'}" in line
        placed = json.loads(out.with_suffix(".json").read_text())["metadata"]["placement"]
        x, h = placed["track"]["passing_m"], placed["track"]["altitude_m"]
        # Nothing returns beyond both the foot of the post's near face and the far edge of its
        # top, up to the ground where the top's shadow ends (ground range x_far h / (h - H)).
        start = max(math.hypot(x - 0.25, h), math.hypot(x + 0.25, h - height))
        end = math.hypot((x + 0.25) * h / (h - height), h)
        expected = (end - start) / 0.02
        heights[up] = (_shadow_bins(out, slice(9, 12)), expected)
    for shadow, expected in heights.values():
        assert abs(shadow - expected) <= 3, heights
    assert heights["z"][0] > 3 * heights[None][0]


def test_invert_reads_the_renderers_display_png(tmp_path, capsys):
    png, exr = tmp_path / "r.png", tmp_path / "r.exr"
    args = ["render", "default", "-o", str(png), "-o", str(exr), "--pings", "6", "-q"]
    assert main([*args, "--no-effects", "--bits", "16"]) == 0
    sides, attrs = read_exr(exr)
    meta = json.loads(png.with_suffix(".json").read_text())["display_mapping"]
    step_db = meta["dynamic_range_db"] / 65535  # one 16-bit code
    for side in ("port", "starboard"):
        image, name, range_bin = load_side(png, side, None)
        assert name == side and range_bin == pytest.approx(attrs["sonar:range_bin_m"])
        truth = sides[side].astype(np.float64)
        assert image.shape == truth.shape
        shown = (image > 0) & (truth < meta["ref_level_m2"])  # not clipped at either end
        ratio_db = 10 * np.log10(image[shown] / truth[shown])
        assert shown.mean() > 0.5 and np.abs(ratio_db).max() <= 0.5 * step_db + 1e-6
        assert np.all(image[truth == 0] == 0)
    out = tmp_path / "inv"
    assert main(["invert", str(png), "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err
    assert err == (
        "sonar-raster: error: r.png is a two-sided display image (port on the left, starboard "
        "on the right); pass --side port or --side starboard\n"
    )
    assert not out.exists()


@pytest.mark.parametrize("extra", [["--no-effects"], []])
def test_invert_takes_the_ping_spacing_the_render_wrote(tmp_path, capsys, extra):
    """A render's header says its pings' spacing (with or without effects); ``invert`` takes
    it for the along-track geometry instead of the ground cell (it took 0.04 m for the default
    render's 0.05 m); ``--ping-spacing`` still wins; an image that does not say is noted."""
    model = tmp_path / "post.wrl"
    model.write_text(POST_VRML)
    exr = tmp_path / "r.exr"
    args = ["render", str(model), "--pings", "12", "--ping-spacing", "0.13", "--range-bin"]
    assert main([*args, "0.05", "-o", str(exr), "-q", *extra]) == 0
    assert float(read_exr(exr)[1]["sonar_raster:ping_spacing_m"]) == pytest.approx(0.13)
    for given, expected in (([], 0.13), (["--ping-spacing", "0.2"], 0.2)):
        out = tmp_path / f"inv{len(given)}"
        base = ["invert", str(exr), "-o", str(out), "--no-mesh", "--no-previews"]
        assert main([*base, "--method", "profiles", *given]) == 0
        doc = json.loads((out / "inversion.json").read_text())
        assert doc["ping_spacing_m"] == pytest.approx(expected)
    assert "ping spacing" not in capsys.readouterr().out
    np.save(tmp_path / "img.npy", read_exr(exr)[0]["starboard"])
    args = ["invert", str(tmp_path / "img.npy"), "--range-bin", "0.05", "--method", "profiles"]
    assert main([*args, "-o", str(tmp_path / "npy"), "--no-mesh", "--no-previews"]) == 0
    said = [line for line in capsys.readouterr().out.splitlines() if "ping spacing" in line]
    assert said == [
        "note: img.npy does not say its ping spacing; the along-track geometry takes the "
        "ground cell (give --ping-spacing METRES)"
    ]


def test_invert_help_states_the_default_side(capsys):
    with pytest.raises(SystemExit):
        main(["invert", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "EXR (default starboard)" in text and "required there" in text


@pytest.mark.skipif(not XTF.is_file(), reason=f"{XTF} not available")
def test_render_reuses_a_recorded_track(tmp_path, capsys):
    from sonar_raster.io.xtf import read_xtf, read_xtf_track

    model = tmp_path / "post.wrl"
    model.write_text(POST_VRML)
    out = tmp_path / "o.exr"
    args = ["render", str(model), "--up", "z", "-o", str(out), "--track", str(XTF)]
    assert main([*args, "--range", "30", "--no-effects"]) == 0
    line = capsys.readouterr().out.splitlines()[0]
    assert f"track ({XTF}): 461 pings" in line
    sides, _ = read_exr(out)
    assert sides["starboard"].shape[0] == 461
    track, altitude, _ = read_xtf_track(XTF)
    _, nav = read_xtf(XTF)
    east, north = nav.projected()
    np.testing.assert_allclose(track.positions[:, 0], east - east[0], atol=1e-6)
    np.testing.assert_allclose(track.positions[:, 1], north - north[0], atol=1e-6)
    np.testing.assert_allclose(track.headings, nav.filled_heading())
    assert np.array_equal(np.isfinite(altitude), np.isfinite(nav.altitude))


def test_invert_chooses_the_surface_fit_for_a_speckled_image(tmp_path, capsys):
    """``--method auto`` (the default) fits one surface to a speckled image, profiles to a
    clean one, and says which; ``--method profiles`` on speckle points to the surface."""
    rng = np.random.default_rng(0)
    k = np.arange(256)
    clean = np.where(k >= 60, 40.0 / np.maximum(k - 20.0, 1.0), 0.0) * np.ones((40, 1))
    speckled = clean * rng.exponential(size=clean.shape)
    runs = {}
    for name, image, extra in (
        ("clean", clean, []),
        ("speckled", speckled, []),
        ("profiles", speckled, ["--method", "profiles"]),
        ("none", speckled, ["--looks", "none"]),
    ):
        np.save(tmp_path / f"{name}.npy", image)
        args = ["invert", str(tmp_path / f"{name}.npy"), "--range-bin", "0.05", *extra]
        assert main([*args, "-o", str(tmp_path / name), "--no-mesh", "--no-previews"]) == 0
        out = capsys.readouterr().out.splitlines()
        settings = json.loads((tmp_path / name / "inversion.json").read_text())["settings"]
        assert settings["method"] in ("profiles", "surface")
        runs[name] = (out, settings["method"] == "surface")
    chosen = {name: [line for line in out if line.startswith("method:")] for name, (out, _) in
              runs.items()}  # fmt: skip
    assert chosen["clean"][0].startswith("method: profiles") and not runs["clean"][1]
    assert chosen["speckled"][0].startswith("method: surface") and runs["speckled"][1]
    assert "about 1" in chosen["speckled"][0]  # one look, estimated
    assert chosen["profiles"] == [] and not runs["profiles"][1]
    assert any("--method surface" in line for line in runs["profiles"][0] if "note:" in line)
    assert chosen["none"][0].startswith("method: profiles") and not runs["none"][1]


def _speckled_npy_invert(tmp_path, seed: int) -> list[str]:
    """``invert`` arguments for a small single-look ``.npy`` side (24 pings × 128 bins)."""
    rng = np.random.default_rng(seed)
    k = np.arange(128)
    image = np.where(k >= 30, 20.0 / np.maximum(k - 10.0, 1.0), 0.0) * rng.exponential(
        size=(24, 128)
    )
    np.save(tmp_path / "img.npy", image)
    base = ["invert", str(tmp_path / "img.npy"), "--range-bin", "0.05", "--no-mesh"]
    return base


def test_the_profiles_priors_are_refused_by_the_surface_fit_and_choose_the_profiles(
    tmp_path, capsys
):
    base = _speckled_npy_invert(tmp_path, 1)
    for option in (["--relief-std", "0.05"], ["--slope-std", "0.3"], ["--flat-prior", "0.5"]):
        out = tmp_path / option[0].strip("-")
        assert main([*base, "--method", "surface", *option, "-o", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and option[0] in err[0] and "--method profiles" in err[0]
        assert not out.exists()
        # without --method they pick the profiles on this speckled image
        assert main([*base, "--no-previews", "--max-iter", "2", *option, "-o", str(out)]) == 0
        assert capsys.readouterr().out.startswith(f"method: profiles ({option[0]}")


def test_a_scattering_law_picks_the_surface_fit_and_its_mistakes_are_one_line(tmp_path, capsys):
    base = _speckled_npy_invert(tmp_path, 2)
    mistakes = (
        (["--law", "granite"], "--law: unknown material 'granite'"),
        (["--frequency", "400"], "--frequency is for --law"),
        (["--law", "sand"], "give it with --frequency"),  # a .npy records no frequency
        (["--law", "sand", "--frequency", "400", "--method", "profiles"], "--method surface"),
    )
    for k, (option, message) in enumerate(mistakes):
        out = tmp_path / f"bad{k}"
        assert main([*base, *option, "-o", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], err
        assert not out.exists()
    out = tmp_path / "sand"
    law = ["--law", "fine sand", "--frequency", "400"]
    assert main([*base, *law, "--no-previews", "--max-iter", "2", "-o", str(out)]) == 0
    assert capsys.readouterr().out.startswith("method: surface (--law")
    doc = json.loads(next(out.rglob("inversion.json")).read_text())
    assert doc["settings"]["law"] == "fine sand at 400 kHz"
