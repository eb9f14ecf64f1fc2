"""Streaming a track to disk in blocks: same files as rendering it whole, nothing half-written."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import box_from_bounds, rect_seabed

from sonar_raster.cli.app import main
from sonar_raster.errors import SonarRasterError
from sonar_raster.io.images import Display, read_exr, read_pixels, write_image
from sonar_raster.rendering.gl.raster import render_raster
from sonar_raster.rendering.survey import render_survey
from sonar_raster.scene import build_scene
from sonar_raster.sonar import Sonar
from sonar_raster.trajectory import Trajectory


@pytest.fixture()
def setup():
    scene = build_scene(
        [rect_seabed(-60.0, 60.0, -60.0, 60.0), box_from_bounds([[10, -1, 0], [11, 1, 1.2]])]
    )
    sonar = Sonar(max_range=25.0, range_bin=0.1)
    traj = Trajectory.straight((0.0, -8.0, 6.0), 0.0, 0.25, 70)
    return scene, sonar, traj


def test_streamed_files_match_the_whole_image(tmp_path, setup):
    scene, sonar, traj = setup
    written, summary = render_survey(
        scene, sonar, traj, [tmp_path / "s.exr", tmp_path / "s.png"], chunk_pings=16
    )
    assert summary["blocks"] == 5 and summary["draws"] == 10
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.exr", "s.json", "s.png"]
    whole = render_raster(scene, sonar, traj)
    sides, attrs = read_exr(tmp_path / "s.exr")
    for side in sonar.sides:
        err = np.abs(sides[side] - whole.sides[side]).max()
        assert err <= 1e-5 * whole.sides[side].max()
    assert attrs["sonar:range_bin_m"] == pytest.approx(0.1)
    # The PNG of the whole image with the mapping the survey chose (every ping was sampled).
    doc = json.loads((tmp_path / "s.json").read_text())
    assert doc["shape"] == [70, 250] and doc["metadata"]["survey"]["chunk_pings"] == 16
    write_image(
        whole, tmp_path / "w.png", dynamic_range_db=doc["display_mapping"]["dynamic_range_db"]
    )
    streamed, _ = read_pixels(tmp_path / "s.png")
    direct, _ = read_pixels(tmp_path / "w.png")
    assert streamed.shape == direct.shape == (70, 500, 1)
    assert np.mean(np.abs(streamed - direct) > 1.5 / 255) < 1e-3


@pytest.mark.parametrize(
    "display",
    [
        Display(palette="copper"),
        Display(ground_range=True, altitude_m=6.0),
        Display(square_pixels=True, ping_spacing_m=0.25),
        Display(
            level="median",
            palette="copper",
            ground_range=True,
            square_pixels=True,
            altitude_m=6.0,
            ping_spacing_m=0.25,
        ),  # fmt: skip
    ],
)
def test_a_streamed_png_is_shown_as_asked(tmp_path, setup, display):
    """Level, palette, ground range and square pixels reach a streamed PNG: its pixels are the
    whole image's PNG with the same display (rows of square pixels read across blocks)."""
    scene, sonar, traj = setup
    written, _ = render_survey(
        scene, sonar, traj, [tmp_path / "s.png"], chunk_pings=16, display=display
    )
    doc = json.loads((tmp_path / "s.json").read_text())["display_mapping"]
    whole = render_raster(scene, sonar, traj)
    write_image(whole, tmp_path / "w.png", dynamic_range_db=doc["dynamic_range_db"],
                display=display)  # fmt: skip
    streamed, _ = read_pixels(tmp_path / "s.png")
    direct, _ = read_pixels(tmp_path / "w.png")
    assert streamed.shape == direct.shape
    assert streamed.shape[2] == (3 if display.palette == "copper" else 1)
    assert streamed.shape[0] == (175 if display.square_pixels else 70)  # 70 x 0.25 m / 0.1 m
    assert np.mean(np.abs(streamed - direct) > 1.5 / 255) < 1e-3
    shown = json.loads((tmp_path / "w.json").read_text())["display_mapping"]
    assert doc["geometry"] == shown["geometry"] and doc["palette"] == display.palette


def test_a_failed_survey_leaves_nothing(tmp_path, setup, monkeypatch):
    scene, sonar, traj = setup
    (tmp_path / "s.exr").write_bytes(b"user's old file")

    def broken(self, block):
        if block.metadata["first_ping"] > 0:
            raise SonarRasterError("disk full (simulated)")
        return original(self, block)

    from sonar_raster.rendering import survey

    original = survey.ExrStreamWriter.write
    monkeypatch.setattr(survey.ExrStreamWriter, "write", broken)
    with pytest.raises(SonarRasterError, match="disk full"):
        render_survey(scene, sonar, traj, [tmp_path / "s.exr", tmp_path / "s.png"], chunk_pings=16)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.exr"]
    assert (tmp_path / "s.exr").read_bytes() == b"user's old file"


def test_cli_streams_with_chunk_pings(tmp_path, capsys):
    out = tmp_path / "flat.exr"
    code = main(["render", "flat_calibration", "-o", str(out), "--chunk-pings", "7", "-q"])
    assert code == 0
    sides, _ = read_exr(out)
    assert all(np.isfinite(a).all() and a.max() > 0 for a in sides.values())
    code = main(
        ["render", "default", "-o", str(out), "--chunk-pings", "7", "--renderer", "reference"]
    )
    assert code == 2
    assert "--chunk-pings needs the GL raster renderer" in capsys.readouterr().err
    png = tmp_path / "copper.png"
    argv = ["render", "default", "--pings", "20", "--palette", "copper", "--ground-range"]
    assert main([*argv, "-o", str(png), "--chunk-pings", "8", "-q"]) == 0
    pixels, _ = read_pixels(png)
    assert pixels.shape[2] == 3 and pixels.shape[1] < 2000  # copper, ground range (no water)


def test_streamed_and_whole_xtf_read_back_the_same(tmp_path):
    from sonar_raster.io.xtf import read_xtf

    assert main(["render", "default", "-o", str(tmp_path / "whole.xtf"), "-q", "--ideal"]) == 0
    streamed = ["render", "default", "-o", str(tmp_path / "s.xtf"), "--chunk-pings", "64"]
    assert main([*streamed, "-q", "--ideal"]) == 0
    whole, nav_whole = read_xtf(tmp_path / "whole.xtf")
    streamed, nav = read_xtf(tmp_path / "s.xtf")
    assert whole.shape == streamed.shape == (400, 1000)
    for side in whole.sides:
        err = np.abs(streamed.sides[side] - whole.sides[side]).max()
        assert err <= 1e-5 * whole.sides[side].max()
    np.testing.assert_allclose(nav.x, nav_whole.x)
    np.testing.assert_allclose(nav.altitude, nav_whole.altitude)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.xtf", "whole.xtf"]


def test_a_streamed_render_has_the_whole_renders_effects(tmp_path):
    """By default a streamed survey gets the default sensor's effects too: the same level per
    range band as the whole render (random fields differ: drawn per block), no exact zeros."""
    whole, streamed = tmp_path / "whole.exr", tmp_path / "s.exr"
    common = ["render", "default", "-q", "--seed", "4", "--no-micro-relief"]
    assert main([*common, "-o", str(whole), "-o", str(tmp_path / "wp.png")]) == 0
    streamed_png = ["-o", str(tmp_path / "sp.png"), "--chunk-pings", "64"]
    assert main([*common, "-o", str(streamed), *streamed_png]) == 0
    # the PNG is levelled as the whole render's: median at mid-grey over 45 dB
    shown = json.loads((tmp_path / "wp.json").read_text())["display_mapping"]
    streamed_shown = json.loads((tmp_path / "sp.json").read_text())["display_mapping"]
    assert streamed_shown["level"] == shown["level"] == "median"
    assert streamed_shown["dynamic_range_db"] == shown["dynamic_range_db"]
    assert streamed_shown["ref_level_m2"] == pytest.approx(shown["ref_level_m2"], rel=0.03)
    a, b = read_exr(whole)[0], read_exr(streamed)[0]
    fx = json.loads(whole.with_suffix(".json").read_text())["metadata"]["effects"]
    sfx = json.loads(streamed.with_suffix(".json").read_text())["metadata"]["effects"]
    assert sfx["stages"] == fx["stages"] and "speckle" in sfx["stages"]
    for side in a:
        assert (b[side] > 0).all()  # the noise floor, never zeros
        for lo in range(300, 1000, 175):  # 7 m bands of the seabed
            ratio = b[side][:, lo : lo + 175].mean() / a[side][:, lo : lo + 175].mean()
            assert ratio == pytest.approx(1.0, abs=0.03), (side, lo)


def test_a_streamed_render_writes_every_name_it_is_given(tmp_path):
    """Two EXR and two XTF names on a streamed render: each written whole (a copy)."""
    names = ["a.exr", "b.exr", "a.xtf", "b.xtf"]
    outputs = [arg for name in names for arg in ("-o", str(tmp_path / name))]
    argv = ["render", "default", "--pings", "20", "--chunk-pings", "8", "-q", "--ideal"]
    assert main([*argv, *outputs]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([*names, "a.json", "b.json"])
    for kind in ("exr", "xtf"):
        a, b = (tmp_path / f"{n}.{kind}" for n in "ab")
        assert a.stat().st_size > 1000 and a.read_bytes() == b.read_bytes()
