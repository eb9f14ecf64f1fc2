"""Dataset samples on real seabeds (``[background] recordings``): seeded, resumable, failures."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import SHARED_DATA

from sonar_raster.dataset.generate import generate_dataset, load_dataset_config
from sonar_raster.errors import SonarRasterError

SAMPLE = SHARED_DATA / "xtf" / "scotsman-iver2.xtf"

CONFIG = """
[dataset]
name = "real"
count = 3
seed = 7
pings = 96
sides = ["port", "starboard"]

[background]
recordings = ["{recording}"]

[[objects]]
primitive = "box"
count = {{ integers = [1, 2] }}
size = [{size}, {{ uniform = [0.5, 1.0] }}, {{ uniform = [0.4, 0.9] }}]

[[objects]]
primitive = "cylinder"
count = 1

[output]
formats = ["png"]
"""


def _config(tmp_path: Path, size: str = "{ uniform = [0.8, 1.5] }") -> Path:
    if not SAMPLE.is_file():
        pytest.skip(f"{SAMPLE} not present")
    path = tmp_path / "real.toml"
    path.write_text(CONFIG.format(recording=SAMPLE, size=size))
    return path


def _files(root: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(root)): p.read_bytes()
        for p in sorted(root.rglob("*"))
        if p.is_file() and p.suffix in (".png", ".txt") or p.parent.name == "meta"
    }


def test_background_samples_are_seeded_and_resume(tmp_path):
    config = _config(tmp_path)
    whole = generate_dataset(config, tmp_path / "a", count=3)
    assert whole.failed == []
    generate_dataset(config, tmp_path / "b", count=1)
    resumed = generate_dataset(config, tmp_path / "b", count=3)
    assert resumed.done_before == 1 and resumed.made == 2
    assert _files(tmp_path / "a") == _files(tmp_path / "b")
    meta = json.loads((tmp_path / "a" / "meta" / "000000.json").read_text())
    assert meta["background"]["recording"] == SAMPLE.name and meta["background"]["pings"] == 96
    coco = json.loads((tmp_path / "a" / "coco.json").read_text())
    assert {c["name"] for c in coco["categories"]} == {"box", "cylinder"}
    per_image = {img["id"]: 0 for img in coco["images"]}
    for a in coco["annotations"]:
        per_image[a["image_id"]] += 1
    assert all(n >= 2 for n in per_image.values())  # a box or two and a cylinder each
    other = generate_dataset(config, tmp_path / "c", count=3, seed=8)
    assert other.failed == []
    assert _files(tmp_path / "a") != _files(tmp_path / "c")


def test_a_sample_that_cannot_be_made_fails_and_the_batch_goes_on(tmp_path):
    config = _config(tmp_path, size="60.0")  # a 60 m box stands outside any swath
    summary = generate_dataset(config, tmp_path / "out", count=2)
    assert [i for i, _ in summary.failed] == [0, 1]
    assert all("no free place" in why for _, why in summary.failed)
    lines = (tmp_path / "out" / "index.jsonl").read_text().splitlines()
    records = [json.loads(line) for line in lines]
    assert {r["status"] for r in records} == {"failed"} and not any(r["retry"] for r in records)


def test_bad_background_tables(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text('[dataset]\ncount = 1\n[background]\nrecordings = ["missing.xtf"]\n')
    with pytest.raises(SonarRasterError, match="missing.xtf"):
        load_dataset_config(path)
    path.write_text("[dataset]\ncount = 1\n[background]\nrecordings = []\n")
    with pytest.raises(SonarRasterError, match="recordings"):
        load_dataset_config(path)


DUAL = """
[dataset]
name = "dual"
count = 1
seed = 3
pings = 40
sides = ["starboard"]

[background]
recordings = ["dual.xtf"]
{frequency}

[[objects]]
primitive = "box"
count = 1
size = [1.0, 0.6, 0.5]

[output]
formats = ["png"]
"""


def test_a_dual_frequency_background_reads_the_pair_asked_for(tmp_path, capsys):
    """``[background] frequency``: the window comes from that pair (its own bins); a pair the
    file lacks is one error when the config is read, naming the file's."""
    from sonar_raster.cli.app import main
    from sonar_raster.io.images import read_pixels

    argv = ["render", "default", "--pings", "60", "--seed", "1", "-q"]
    sensor = ["--sensor", "klein-3900-445,klein-3900-900", "-o", str(tmp_path / "dual.xtf")]
    assert main([*argv, *sensor]) == 0
    widths = {}
    for choice, bins in (('"high"', 5333), ("445", 4000)):
        config = tmp_path / "dual.toml"
        config.write_text(DUAL.format(frequency=f"frequency = {choice}"))
        out = tmp_path / f"out{bins}"
        assert generate_dataset(load_dataset_config(config), out, count=1).failed == []
        (image,) = sorted((out / "images").glob("*.png"))
        widths[choice] = read_pixels(image)[0].shape[1]
        assert widths[choice] == bins  # one side, the pair's own bins
    config.write_text(DUAL.format(frequency="frequency = 600"))
    with pytest.raises(SonarRasterError, match="445 kHz, 900 kHz"):
        load_dataset_config(config)
    config.write_text(DUAL.format(frequency='frequency = "middle"'))
    with pytest.raises(SonarRasterError, match="'frequency' must be"):
        load_dataset_config(config)
