"""``sonar-raster insert`` on bad input: one line, exit 2, nothing written; and a good run."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import SHARED_DATA

from sonar_raster.cli.app import main
from sonar_raster.image import SonarImage
from sonar_raster.io.xtf import write_xtf
from sonar_raster.sonar import Sonar
from sonar_raster.trajectory import Trajectory

SAMPLE = SHARED_DATA / "xtf" / "scotsman-iver2.xtf"


def _bad(capsys, tmp_path, argv: list[str], words: str) -> None:
    out = tmp_path / "out"
    out.mkdir(exist_ok=True)
    assert main(["insert", *argv, "-o", str(out / "line.xtf")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err
    assert words in err, err
    assert list(out.iterdir()) == []


@pytest.fixture()
def sample():
    if not SAMPLE.is_file():
        pytest.skip(f"{SAMPLE} not present")
    return str(SAMPLE)


def test_object_outside_the_swath(capsys, tmp_path, sample):
    _bad(capsys, tmp_path, [sample, "--object", "box", "--at", "100,40"], "outside the swath")


def test_object_across_the_track(capsys, tmp_path, sample):
    _bad(capsys, tmp_path, [sample, "--object", "box:size=3,1,1", "--at", "100,0.5"], "crosses")


def test_unreadable_model(capsys, tmp_path, sample):
    bad = tmp_path / "broken.glb"
    bad.write_bytes(b"not a model")
    _bad(capsys, tmp_path, [sample, "--object", str(bad), "--at", "100,10"], "broken.glb")
    _bad(capsys, tmp_path, [sample, "--object", "teapot", "--at", "100,10"], "neither")


def test_misspelt_primitive_key_names_the_keys(capsys, tmp_path, sample):
    _bad(
        capsys,
        tmp_path,
        [sample, "--object", "box:sise=1,1,1", "--at", "100,10"],
        "unknown key(s) 'sise' for a box; its keys are size (sise: did you mean size?)",
    )


def test_an_output_named_like_an_image_is_refused_before_reading(capsys, tmp_path, sample):
    out = tmp_path / "out"
    out.mkdir()
    assert main(["insert", sample, "--object", "box", "-o", str(out / "ins.png")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "give a stem or OUT.xtf (e.g. -o " in err, err
    assert list(out.iterdir()) == []


def test_recording_without_bottom_track(capsys, tmp_path):
    rng = np.random.default_rng(0)
    pings, bins = 40, 400
    water = {"starboard": rng.exponential(1e-6, (pings, bins)).astype(np.float32)}
    image = SonarImage(water, Sonar(max_range=20.0, range_bin=0.05, sides=("starboard",)))
    path = tmp_path / "water.xtf"
    write_xtf(path, image, Trajectory.straight((0.0, 0.0, -5.0), 0.0, 0.1, pings))
    _bad(capsys, tmp_path, [str(path), "--object", "box", "--at", "20,8"], "no bottom track")


def test_good_run_writes_every_file(capsys, tmp_path, sample):
    out = tmp_path / "line"
    argv = ["insert", sample, "-o", str(out), "--object", "box", "--object", "cylinder",
            "--object", "barrel", "--at", "100,-10", "--seed", "5"]  # fmt: skip
    assert main(argv) == 0
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == sorted(
        f"line{s}" for s in (".xtf", ".png", ".json", ".instances.png", ".classes.png", ".txt",
                             ".coco.json", ".objects.json")
    )  # fmt: skip
    coco = json.loads((tmp_path / "line.coco.json").read_text())
    assert len(coco["annotations"]) == 3
    assert {a["category_id"] for a in coco["annotations"]} == {1, 2, 3}
    assert len((tmp_path / "line.txt").read_text().splitlines()) == 3
    # same seed, same bytes
    again = tmp_path / "again"
    again.mkdir()
    assert main([*argv[:3], str(again / "line"), *argv[4:]]) == 0
    for name in ("line.xtf", "line.instances.png", "line.coco.json"):
        assert (again / name).read_bytes() == (tmp_path / name).read_bytes()
