"""The command line's layout: one module per command, options mapped onto the library entries."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sonar_raster.cli import app
from sonar_raster.cli.render import _model

#: Positional arguments and required options of each command.
_REQUIRED = {
    "render": ["s.toml", "-o", "o.png"],
    "invert": ["i.exr", "-o", "d"],
    "dataset": ["c.toml", "-o", "d"],
    "track": ["f.xtf"],
    "insert": ["r.xtf", "-o", "o"],
}


def test_every_command_is_a_module_with_its_parser_and_run():
    assert list(app.COMMANDS) == [
        "render", "invert", "dataset", "insert", "track", "scenes", "sensors", "doctor"
    ]  # fmt: skip
    for name, module in app.COMMANDS.items():
        assert module.__name__ == f"sonar_raster.cli.{name}"
        assert callable(module.add_parser) and callable(module.run)
        args = app._parser().parse_args([name, *_REQUIRED.get(name, [])])
        assert args.command == name


@pytest.mark.parametrize(
    ("options", "model"),
    [
        ([], "raster"),
        (["--renderer", "gl"], "raster"),
        (["--renderer", "reference"], "reference"),
        (["--model", "coherent"], "coherent"),
        (["--model", "coherent", "--renderer", "reference"], "coherent"),
    ],
)
def test_render_options_pick_one_model(options, model):
    args = app._parser().parse_args(["render", "s.toml", "-o", "o.png", *options])
    assert _model(args) == model


class _Stop(Exception):
    pass


@pytest.mark.parametrize("model", ["raster", "coherent"])
def test_render_calls_the_library_entry(monkeypatch, tmp_path, model):
    from sonar_raster.rendering import entry

    seen = {}

    def fake(scene, sonar, trajectory, **kwargs):
        seen.update(kwargs)
        raise _Stop

    monkeypatch.setattr(entry, "render", fake)
    args = ["render", "flat_calibration", "-o", str(tmp_path / "o.exr"), "--pings", "3", "-q"]
    args += ["--model", model, "--scatterer-spacing", "4", "--seed", "7", "--oversample", "3"]
    with pytest.raises(_Stop):
        app.main(args)
    assert seen["model"] == model and seen["progress"] is False
    assert seen["coherent"]["spacing_wavelengths"] == 4.0 and seen["coherent"]["seed"] == 7
    if model == "raster":
        assert seen["settings"].oversample == 3.0
    else:
        assert seen["settings"] is None
    assert not list(tmp_path.iterdir())


def test_track_csv_and_summary_live_in_the_library(tmp_path):
    from sonar_raster.inversion.bottom import BottomTrack
    from sonar_raster.inversion.track_io import TRACK_CSV_HEADER, summary_lines, write_track_csv

    track = BottomTrack(
        altitude=np.array([5.0, 5.25, 5.5]),
        valid=np.array([True, False, True]),
        raw=np.array([5.0, math.nan, 5.5]),
        contrast_db=np.array([12.0, math.nan, 11.0]),
    )
    recorded = np.array([4.9, math.nan, 5.4])
    path = tmp_path / "t.csv"
    write_track_csv(path, track, recorded)
    rows = path.read_text().splitlines()
    assert rows[0] == TRACK_CSV_HEADER
    assert rows[2] == "1,5.2500,0,,,"
    assert rows[3] == "2,5.5000,1,5.5000,11.0000,5.4000"
    with pytest.raises(FileExistsError):  # a writer for io.commit: never over a file
        write_track_csv(path, track, recorded)
    lines = summary_lines(track, recorded, 0.05)
    assert lines[0].startswith("3 pings, 2 with a clear bottom return (66.7 %)")
    assert "on 2 pings: tracked - file median +0.10 m" in lines[2]
    none = summary_lines(track, np.full(3, math.nan), 0.05)
    assert none[2] == "the file records no altitude (0 on every ping)"
