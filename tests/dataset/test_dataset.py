"""Dataset generation: reproducibility, resume, failures, labels against geometry, COCO/YOLO."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sonar_raster.dataset.generate import generate_dataset, load_dataset_config
from sonar_raster.dataset.labels import rle_decode, rle_encode, shadow_owners
from sonar_raster.dataset.scene import draw_sample
from sonar_raster.errors import SonarRasterError
from sonar_raster.scenes.objects import build_primitive

ROOT = Path(__file__).resolve().parents[2]

SMALL = """
[dataset]
pings = 128
bins = 256
seed = 5
[sonar]
max_range = { uniform = [10.0, 14.0] }
frequency_hz = { choice = [300e3, 900e3] }
tilt_deg = 15.0
beamwidth_deg = 50.0
[track]
altitude = { uniform = [3.0, 5.0] }
heading_deg = { uniform = [0.0, 360.0] }
spacing = 0.08
[[seabed]]
kind = "rough"
resolution = 0.2
rms_height = 0.02
[[seabed]]
kind = "flat"
[[objects]]
primitive = "cylinder"
count = { integers = [0, 2] }
radius = 0.25
length = 1.2
[[objects]]
class = "rock"
primitive = "rock"
count = { integers = [0, 1] }
[placement]
along_track = { uniform = [0.2, 0.8] }
ground_range = { uniform = [0.3, 0.9] }
"""

# One box, heading 0 (track frame = world frame), placed anywhere in and around the swath.
SWATH = """
[dataset]
pings = 128
bins = 256
[sonar]
max_range = 12.0
tilt_deg = 15.0
beamwidth_deg = 60.0
[track]
altitude = 4.0
heading_deg = 0.0
spacing = 0.08
[[seabed]]
kind = "flat"
reflectivity = 0.3
[[objects]]
primitive = "box"
size = [0.8, 0.8, 0.6]
yaw_deg = { uniform = [0.0, 90.0] }
[placement]
along_track = { uniform = [-0.4, 1.4] }
ground_range = { uniform = [0.1, 1.5] }
"""


def _config(tmp_path: Path, text: str, name: str = "ds.toml"):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return load_dataset_config(path)


def _files(root: Path) -> dict[str, bytes]:
    """Every dataset file but the index (which holds timings) and the lock."""
    skip = {"index.jsonl", ".lock"}
    return {
        str(p.relative_to(root)): p.read_bytes()
        for p in sorted(root.rglob("*"))
        if p.is_file() and p.name not in skip
    }


def _codes(path: Path) -> np.ndarray:
    """A label PNG's integer codes, (h, w)."""
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    try:
        return inp.read_image(inp.spec().format)[:, :, 0].astype(np.int64)
    finally:
        inp.close()


def _index(root: Path) -> list[dict]:
    return [json.loads(line) for line in (root / "index.jsonl").read_text().splitlines()]


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The uninterrupted six-sample dataset, made in this process (one worker)."""
    tmp = tmp_path_factory.mktemp("reference")
    config = _config(tmp, SMALL)
    out = tmp / "out"
    summary = generate_dataset(config, out, count=6)
    assert summary.made == 6 and not summary.failed
    return config, out


# -- reproducibility -----------------------------------------------------------------------------
def test_two_workers_give_the_same_files(reference, tmp_path):
    config, ref = reference
    out = tmp_path / "two"
    generate_dataset(config, out, count=6, workers=2)
    a, b = _files(ref), _files(out)
    assert sorted(a) == sorted(b)
    assert len([k for k in a if k.startswith("images/") and k.endswith(".png")]) == 6
    assert all(a[k] == b[k] for k in a), [k for k in a if a[k] != b[k]]
    # Both worker processes took part (records carry the process id).
    assert len({r["pid"] for r in _index(out)}) == 2


def test_one_index_reproduces_its_sample(reference, tmp_path):
    config, ref = reference
    out = tmp_path / "again"
    generate_dataset(config, out, count=6)  # same again in a fresh folder, same process
    assert _files(out) == _files(ref)


def test_a_different_seed_gives_different_samples(reference, tmp_path):
    config, ref = reference
    out = tmp_path / "seed"
    generate_dataset(config, out, count=6, seed=6)
    a, b = _files(ref), _files(out)
    for i in range(6):
        assert a[f"images/{i:06d}.exr"] != b[f"images/{i:06d}.exr"]
        assert json.loads(a[f"meta/{i:06d}.json"]) != json.loads(b[f"meta/{i:06d}.json"])


@pytest.mark.slow
def test_dask_local_cluster_gives_the_same_files(reference, tmp_path):
    pytest.importorskip("distributed")
    config, ref = reference
    out = tmp_path / "dask"
    generate_dataset(config, out, count=6, workers=2, scheduler="local")
    assert _files(out) == _files(ref)


# -- resume --------------------------------------------------------------------------------------
def test_a_stopped_run_resumes_to_the_uninterrupted_dataset(reference, tmp_path):
    config, ref = reference
    out = tmp_path / "resumed"
    generate_dataset(config, out, count=3)
    first = {p: (out / p).stat().st_mtime_ns for p in ("images/000000.png", "meta/000001.json")}
    # Simulate a crash: sample 2's files are in place but its index line was never written
    # (a torn half line instead), and a temporary file was left behind mid-write.
    lines = (out / "index.jsonl").read_text().splitlines()
    (out / "index.jsonl").write_text("\n".join(lines[:2]) + "\n" + lines[2][:40])
    (out / "images" / ".000003.png.0123456789ab.tmp").write_bytes(b"half a png")
    summary = generate_dataset(config, out, count=6)
    assert summary.done_before == 2 and summary.made == 4
    assert _files(out) == _files(ref)
    records = _index(out)
    assert sorted(r["index"] for r in records) == list(range(6))
    # Finished samples were not made again.
    assert all((out / p).stat().st_mtime_ns == t for p, t in first.items())
    # A third run with nothing to do changes nothing.
    again = generate_dataset(config, out, count=6)
    assert again.made == 0 and _files(out) == _files(ref)


@pytest.mark.slow
def test_a_killed_command_resumes_to_the_uninterrupted_dataset(reference, tmp_path):
    """SIGKILL the command line part-way (no clean-up runs), then run it again."""
    import time

    config, ref = reference
    out = tmp_path / "killed"
    cmd = [sys.executable, "-m", "sonar_raster", "dataset", config.source, "-o", str(out)]
    proc = subprocess.Popen([*cmd, "-n", "6", "-q"])
    index = out / "index.jsonl"
    deadline = time.monotonic() + 120
    while proc.poll() is None and time.monotonic() < deadline:
        if index.exists() and index.read_text().count("\n") >= 1:
            proc.kill()
            break
        time.sleep(0.01)
    assert proc.wait() == -9, "the run finished before it could be killed"
    assert len(index.read_text().splitlines()) < 6
    subprocess.run([*cmd, "-n", "6", "-q"], check=True)
    assert _files(out) == _files(ref)
    assert sorted(r["index"] for r in _index(out)) == list(range(6))


def test_a_record_whose_files_vanished_is_made_again(reference, tmp_path):
    config, ref = reference
    out = tmp_path / "vanished"
    generate_dataset(config, out, count=6)
    (out / "classes" / "000004.png").unlink()
    summary = generate_dataset(config, out, count=6)
    assert summary.made == 1 and _files(out) == _files(ref)


def test_another_config_or_seed_or_a_foreign_folder_is_refused(reference, tmp_path):
    config, ref = reference
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(SonarRasterError, match="not empty"):
        generate_dataset(config, tmp_path, count=1)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]
    with pytest.raises(SonarRasterError, match="another config or seed"):
        generate_dataset(config, ref, count=6, seed=99)
    other = _config(tmp_path, SMALL.replace("radius = 0.25", "radius = 0.3"))
    with pytest.raises(SonarRasterError, match="another config or seed"):
        generate_dataset(other, ref, count=6)


# -- failures ------------------------------------------------------------------------------------
def test_a_failing_sample_is_recorded_and_the_others_complete(tmp_path):
    (tmp_path / "broken.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\nend_header\n1 2\n"
    )
    text = SMALL + '\n[[objects]]\nfile = "broken.ply"\ncount = { integers = [0, 1] }\n'
    config = _config(tmp_path, text)
    out = tmp_path / "out"
    summary = generate_dataset(config, out, count=6, seed=0)
    failed = {i for i, _ in summary.failed}
    assert 0 < len(failed) < 6
    records = {r["index"]: r for r in _index(out)}
    assert set(records) == set(range(6))
    for i, rec in records.items():
        assert (rec["status"] == "failed") == (i in failed)
        assert (out / f"images/{i:06d}.png").exists() == (i not in failed)
    assert all("broken.ply" in records[i]["error"] for i in failed)
    coco = json.loads((out / "coco.json").read_text())
    assert sorted(im["id"] - 1 for im in coco["images"]) == sorted(set(range(6)) - failed)
    # Failed samples are deterministic: a resumed run does not retry them.
    assert generate_dataset(config, out, count=6, seed=0).made == 0


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (("radius = 0.25", "radius = 0.25\nwidth = 1.0"), "unknown parameter.*width"),
        (("count = { integers = [0, 2] }", "count = 1.5"), "'count' must be an integer"),
        (('kind = "flat"', 'kind = "flat"\nsize = 10.0'), "set per sample"),
        (("spacing = 0.08", "spacing = { uniform = [0.1] }"), "list of two numbers"),
        (("spacing = 0.08", "spacing = { uniform = [1, 2], normal = [0, 1] }"), "exactly one"),
        (('primitive = "cylinder"', 'primitive = "pyramid"'), "unknown primitive"),
        (("[placement]", "[render]\noversample = 0.0\n[placement]"), "oversample"),
        (('kind = "flat"', 'kind = "flat"\nmicro_relief = "cheese"'), "unknown material"),
        (('kind = "flat"', 'kind = "flat"\nmicro_relief = 0.1'), "sediment name"),
        (('kind = "flat"', 'kind = "flat"\nmaterial = "cheese"'), "unknown material"),
        (('kind = "flat"', 'kind = "flat"\nmaterial = "sand"\nreflectivity = 0.3'), "not both"),
        (('kind = "flat"', 'kind = "flat"\nscattering = "lambert"'), "needs a 'material'"),
        (('kind = "flat"', 'kind = "flat"\nmaterial = "sand"\nscattering = "x"'), "one of"),
        (('kind = "flat"', 'kind = "flat"\nmicro_relief = true'), "takes the seabed's"),
        (("seed = 5", 'seed = 5\nsides = ["starboard", "starboard"]'), "each once"),
    ],
)
def test_config_errors_name_the_key(tmp_path, change, message):
    with pytest.raises(SonarRasterError, match=message):
        _config(tmp_path, SMALL.replace(*change))


def test_an_unexpected_failure_is_retried_by_the_next_run(reference, tmp_path, monkeypatch):
    from sonar_raster.dataset import sample as _dataset_sample

    config, ref = reference
    real = _dataset_sample.make_sample

    def flaky(config, seed, index, renderer):
        if index == 1:
            raise RuntimeError("GL context lost")
        return real(config, seed, index, renderer)

    out = tmp_path / "flaky"
    monkeypatch.setattr(_dataset_sample, "make_sample", flaky)
    summary = generate_dataset(config, out, count=6)
    assert [i for i, _ in summary.failed] == [1] and "GL context lost" in summary.failed[0][1]
    monkeypatch.setattr(_dataset_sample, "make_sample", real)
    again = generate_dataset(config, out, count=6)
    assert again.made == 1 and not again.failed
    assert _files(out) == _files(ref)


def test_a_user_mesh_is_turned_up_scaled_and_given_the_drawn_reflectivity(tmp_path):
    """barrel.wrl is y-up (VRML): its 0.88 m y extent becomes the object's height."""
    import shutil

    from sonar_raster.meshio.load import load_model

    shutil.copy(ROOT / "sonar_raster/scenes/data" / "barrel.wrl", tmp_path / "barrel.wrl")
    text = SMALL.replace('primitive = "cylinder"', 'file = "barrel.wrl"')
    text = text.replace("radius = 0.25\nlength = 1.2", "scale = 1.5\nreflectivity = 0.6")
    config = _config(tmp_path, text.replace("{ integers = [0, 2] }", "1"))
    parts = load_model(tmp_path / "barrel.wrl")
    model = np.concatenate([p.vertices for p in parts])
    drawn = draw_sample(config, 0, 0)
    scene = drawn.scene
    mine = scene.object_id == 1
    v = scene.vertices[np.unique(scene.faces[mine])]
    assert np.ptp(v[:, 2]) == pytest.approx(1.5 * np.ptp(model[:, 1]), rel=1e-9)
    assert scene.reflectivity[mine].mean() == pytest.approx(0.6, rel=1e-9)
    assert drawn.instances[0]["class"] == "barrel"


def test_bad_config_is_one_line_and_no_output(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(SMALL.replace("[placement]", "[placement]\nground_rnage = 0.5"))
    out = tmp_path / "out"
    proc = subprocess.run(
        [sys.executable, "-m", "sonar_raster", "dataset", str(path), "-o", str(out)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "ground_rnage" in proc.stderr
    assert not out.exists()


# -- labels against geometry ---------------------------------------------------------------------
def _object_vertices(config, seed: int, index: int) -> np.ndarray:
    scene = draw_sample(config, seed, index).scene
    return scene.vertices[np.unique(scene.faces[scene.object_id == 1])]


def _raw_cells(config, seed: int, index: int, renderer):
    """Raw full-scene and seabed-only images of one sample, rendered here without labels."""
    d = draw_sample(config, seed, index)
    full = renderer.render(d.scene, d.sonar, d.trajectory).sides["starboard"]
    alone = renderer.render(d.seabed, d.sonar, d.trajectory).sides["starboard"]
    return full.astype(np.float64), alone.astype(np.float64)


def test_a_box_is_labelled_exactly_when_inside_the_swath(tmp_path, gl):
    config = _config(tmp_path, SWATH)
    out = tmp_path / "out"
    n = 14
    generate_dataset(config, out, count=n, seed=2)
    coco = json.loads((out / "coco.json").read_text())
    boxes = {a["image_id"] - 1: a for a in coco["annotations"]}
    h, r_max = 4.0, 12.0
    bin_m, spacing = r_max / 256, 0.08
    half = 0.5 * (128 - 1) * spacing
    inside = outside = 0
    for i in range(n):
        v = _object_vertices(config, 2, i)
        slant = np.hypot(v[:, 0], v[:, 2] - h)
        along_in = (v[:, 1] > -half + 2 * spacing) & (v[:, 1] < half - 2 * spacing)
        if np.any(along_in & (slant < r_max - 3 * bin_m) & (v[:, 0] > 0)):
            inside += 1
            assert i in boxes, f"sample {i}: object in the swath but not labelled"
            x, y, w, hh = boxes[i]["bbox"]
            # The box spans the object's slant ranges and along-track extent (± 2 cells).
            assert x >= slant.min() / bin_m - 2 and x + w <= slant.max() / bin_m + 2
            rows = (v[:, 1] + half) / spacing
            assert y >= rows.min() - 2 and y + hh <= rows.max() + 3
            # Every cell the object clearly brightens (it carries more than half the cell's
            # echo) lies inside the box: an oracle independent of the label pass.
            full, alone = _raw_cells(config, 2, i, gl)
            bright = np.argwhere(full > 2.0 * alone + 1e-12 * full.max())
            assert len(bright) > 0
            assert bright[:, 0].min() >= y and bright[:, 0].max() < y + hh
            assert bright[:, 1].min() >= x and bright[:, 1].max() < x + w
        elif np.all(slant > r_max + 3 * bin_m) or np.all(np.abs(v[:, 1]) > half + 3 * spacing):
            outside += 1
            assert i not in boxes, f"sample {i}: object outside the swath but labelled"
            meta = json.loads((out / f"meta/{i:06d}.json").read_text())
            assert meta["objects"][0]["visible"] is False
    assert inside >= 3 and outside >= 3, (inside, outside)


def test_both_sides_share_one_display_image(tmp_path):
    """Port is flipped on the left, starboard on the right: each box lies in its side's half."""
    text = SMALL.replace("seed = 5", 'seed = 5\nsides = ["port", "starboard"]')
    config = _config(tmp_path, text)
    out = tmp_path / "out"
    generate_dataset(config, out, count=4)
    coco = json.loads((out / "coco.json").read_text())
    sides = set()
    for a in coco["annotations"]:
        im = a["image_id"] - 1
        meta = json.loads((out / f"meta/{im:06d}.json").read_text())
        side = meta["objects"][a["instance"] - 1]["side"]
        x, _, w, _ = a["bbox"]
        assert (x + w <= 256) if side == "port" else (x >= 256), (im, a["instance"], side)
        sides.add(side)
    assert sides == {"port", "starboard"}
    assert all(im["width"] == 512 for im in coco["images"])


SHADOW = """
[dataset]
pings = 128
bins = 256
[sonar]
max_range = 14.0
tilt_deg = 10.0
beamwidth_deg = 80.0
[track]
altitude = 5.0
heading_deg = 0.0
spacing = 0.05
[[seabed]]
kind = "flat"
reflectivity = 0.3
[[objects]]
primitive = "box"
size = [0.6, 1.2, 1.0]
yaw_deg = 0.0
[placement]
along_track = 0.5
ground_range = { choice = [0.45, 0.6, 0.75] }
"""


def test_shadow_lies_beyond_the_highlight_with_the_analytic_length(tmp_path):
    """Box of height H, far top edge at ground range x_f, altitude h: the shadow ends at ground
    range x_f h / (h - H), i.e. slant range sqrt(x_end² + h²)."""
    config = _config(tmp_path, SHADOW)
    out = tmp_path / "out"
    generate_dataset(config, out, count=3, seed=1)
    h, big_h, bin_m = 5.0, 1.0, 14.0 / 256
    for i in range(3):
        inst, cls = _codes(out / f"instances/{i:06d}.png"), _codes(out / f"classes/{i:06d}.png")
        highlight, shadow = (inst == 1) & (cls == 1), (inst == 1) & (cls == 2)
        assert highlight.any() and shadow.any()
        rows = np.flatnonzero(shadow.any(axis=1))
        for r in rows:  # in every ping, the shadow starts beyond the highlight's near edge
            assert np.flatnonzero(shadow[r]).min() > np.flatnonzero(highlight[r]).min()
        x_far = _object_vertices(config, 1, i)[:, 0].max()
        x_end = x_far * h / (h - big_h)
        mid = 64
        end_bin = np.flatnonzero(shadow[mid]).max() + 1  # far edge of the last shadow cell
        assert abs(end_bin - math.hypot(x_end, h) / bin_m) <= 1.5
        meta = json.loads((out / f"meta/{i:06d}.json").read_text())
        assert meta["objects"][0]["shadow_area"] == int(shadow.sum())


def test_shadow_owner_is_the_nearest_highlight_at_shorter_range():
    seabed = np.ones((2, 10))
    full = seabed.copy()
    inst = np.zeros((2, 10), dtype=np.uint16)
    inst[0, 2], inst[0, 5] = 1, 2
    full[0, 3:5] = 0.1  # behind object 1
    full[0, 6:9] = 0.4  # behind object 2
    full[0, 9] = 0.6  # not dark enough
    full[1, 1:4] = 0.0  # no highlight at shorter range in this ping
    got = shadow_owners(full, seabed, inst, 0.5)
    want = np.zeros((2, 10), dtype=np.uint16)
    want[0, 3:5], want[0, 6:9] = 1, 2
    np.testing.assert_array_equal(got, want)


# -- formats -------------------------------------------------------------------------------------
def test_coco_document_is_valid_and_matches_the_label_images(reference):
    _, out = reference
    coco = json.loads((out / "coco.json").read_text())
    images = {im["id"]: im for im in coco["images"]}
    cats = {c["id"] for c in coco["categories"]}
    ids = [a["id"] for a in coco["annotations"]]
    assert len(ids) == len(set(ids)) > 0 and len(images) == 6
    assert [c["name"] for c in coco["categories"]] == ["cylinder", "rock"]
    for a in coco["annotations"]:
        im = images[a["image_id"]]
        x, y, w, h = a["bbox"]
        assert a["category_id"] in cats and a["iscrowd"] == 0
        assert x >= 0 and y >= 0 and w > 0 and h > 0
        assert x + w <= im["width"] and y + h <= im["height"]
        mask = rle_decode(a["segmentation"])
        assert a["area"] == int(mask.sum()) > 0
        inst = _codes(out / im["file_name"].replace("images/", "instances/"))
        cls = _codes(out / im["file_name"].replace("images/", "classes/"))
        own = (inst == a["instance"]) & (cls == 1)
        np.testing.assert_array_equal(mask, own)
        rows, cols = np.nonzero(own)
        assert [cols.min(), rows.min(), np.ptp(cols) + 1, np.ptp(rows) + 1] == a["bbox"]


@pytest.mark.filterwarnings("ignore:__array__ implementation:DeprecationWarning")
def test_pycocotools_reads_the_masks_back(reference):
    coco_api = pytest.importorskip("pycocotools.coco")
    _, out = reference
    api = coco_api.COCO(str(out / "coco.json"))
    for ann in api.loadAnns(api.getAnnIds()):
        np.testing.assert_array_equal(
            api.annToMask(ann).astype(bool), rle_decode(ann["segmentation"])
        )
        assert float(api.annToRLE(ann)["size"][0]) == api.imgs[ann["image_id"]]["height"]


def test_yolo_boxes_are_the_coco_boxes_normalised(reference):
    _, out = reference
    coco = json.loads((out / "coco.json").read_text())
    for im in coco["images"]:
        lines = (out / f"labels/{im['id'] - 1:06d}.txt").read_text().splitlines()
        anns = [a for a in coco["annotations"] if a["image_id"] == im["id"]]
        assert len(lines) == len(anns)
        for line, a in zip(lines, anns, strict=True):
            c, cx, cy, w, h = line.split()
            x, y, bw, bh = a["bbox"]
            assert int(c) == a["category_id"] - 1
            got = np.array([float(cx), float(cy), float(w), float(h)])
            want = np.array([x + bw / 2, y + bh / 2, bw, bh]) / np.tile(
                [im["width"], im["height"]], 2
            )
            np.testing.assert_allclose(got, want, atol=1e-6)


def test_rle_round_trip():
    rng = np.random.default_rng(0)
    for shape in [(5, 7), (1, 1), (4, 3)]:
        for start in (False, True):
            mask = rng.random(shape) < 0.4
            mask.flat[0] = start
            rle = rle_encode(mask)
            assert sum(rle["counts"]) == mask.size
            np.testing.assert_array_equal(rle_decode(rle), mask)


def test_effects_change_the_image_but_not_the_labels(reference, tmp_path):
    pytest.importorskip("sonar_raster.effects.chain")
    config, ref = reference
    text = Path(config.source).read_text() + '\n[effects]\nspeckle = "exponential"\n'
    noisy = _config(tmp_path, text, "noisy.toml")
    out = tmp_path / "noisy"
    generate_dataset(noisy, out, count=2)
    a, b = _files(ref), _files(out)
    for i in range(2):
        assert a[f"images/{i:06d}.exr"] != b[f"images/{i:06d}.exr"]
        for kind in ("instances", "classes"):
            assert a[f"{kind}/{i:06d}.png"] == b[f"{kind}/{i:06d}.png"]


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ("bogus = 1", r"noisy\.toml \[effects\]: unknown key\(s\) bogus"),
        ('spreading = "yes"', "'spreading' must be true or false"),
        ('speckle = "gauss"', "unknown speckle 'gauss'"),
        ('tvg = "curve"\ntvg_curve = "missing.csv"', "cannot read TVG curve"),
    ],
)
def test_a_bad_effects_table_fails_before_any_output(tmp_path, table, message):
    config = _config(tmp_path, SMALL + f"\n[effects]\n{table}\n", "noisy.toml")
    out = tmp_path / "out"
    with pytest.raises(SonarRasterError, match=message):
        generate_dataset(config, out, count=1)
    assert not out.exists()


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (
            ("altitude = { uniform = [3.0, 5.0] }", "altitude = 0.0"),
            r"\[track\] 'altitude': must be > 0, got 0$",
        ),
        (("radius = 0.25", "radius = 0.0"), r"object 1 \(cylinder\) fails in all 3 draws"),
        (
            ("max_range = { uniform = [10.0, 14.0] }", "max_range = [10, 14]"),
            r"\[sonar\] 'max_range': must be a number, got \[10, 14\]$",
        ),
    ],
    ids=["altitude 0", "radius 0 (drawn or not)", "a list for a number"],
)
def test_a_bad_fixed_value_fails_once_before_any_output(tmp_path, change, message):
    """Not once per sample (each of thousands recorded as failed) but before the folder is made
    (a value that can never be right: when the config loads)."""
    out = tmp_path / "out"
    with pytest.raises(SonarRasterError, match=message):
        generate_dataset(_config(tmp_path, SMALL.replace(*change)), out, count=50)
    assert not out.exists()


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (
            ("altitude = { uniform = [3.0, 5.0] }", "altitude = { uniform = [-5.0, -1.0] }"),
            r"'altitude': must be > 0; uniform \[-5, -1\] never is",
        ),
        (
            ("max_range = { uniform = [10.0, 14.0] }", "max_range = { choice = [10.0, -1.0] }"),
            r"'max_range': must be > 0, got -1",
        ),
        (
            ("max_range = { uniform = [10.0, 14.0] }", "max_range = 3.0"),
            r"max_range \(at most 3 m\) never reaches past \[track\] altitude \(at least 3 m\)",
        ),
        (("spacing = 0.08", "spacing = true"), r"'spacing': must be a number, got True"),
        (
            ("max_range = { uniform = [10.0, 14.0] }", "max_range = [{ uniform = [10, 14] }]"),
            r"'max_range': must be a number, got a list$",
        ),
    ],
    ids=["a range below zero", "a bad choice", "range within the altitude", "a bool", "a list"],
)
def test_a_value_outside_its_range_fails_when_the_config_loads(tmp_path, change, message):
    """One line naming the table, the key and its rule, before a sample is drawn."""
    assert change[0] in SMALL
    with pytest.raises(SonarRasterError, match=message):
        _config(tmp_path, SMALL.replace(*change))
    # a range that reaches into its valid values is left to the samples' own checks
    reaching = SMALL.replace(
        "altitude = { uniform = [3.0, 5.0] }", "altitude = { uniform = [-1.0, 5.0] }"
    ).replace("tilt_deg = 15.0", "tilt_deg = { uniform = [-1000.0, 100.0] }")
    config = _config(tmp_path, reaching, "ok.toml")
    assert config.track["altitude"].bounds == (-1.0, 5.0)
    assert config.sonar["tilt_deg"].bounds == (-1000.0, 100.0)  # [-90, 90] lies inside it


def test_an_effects_curve_file_is_read_beside_the_config(tmp_path):
    from sonar_raster.dataset.sample import effects_of

    (tmp_path / "tvg.csv").write_text("0,0\n20,30\n")
    text = SMALL + '\n[effects]\ntvg = "curve"\ntvg_curve = "tvg.csv"\n'
    config = _config(tmp_path, text, "curve.toml")
    assert effects_of(config).tvg_curve == ((0.0, 0.0), (20.0, 30.0))


# -- the object library and the bundled config ---------------------------------------------------
@pytest.mark.parametrize(
    ("kind", "params", "volume"),
    [
        ("cylinder", {"radius": 0.3, "length": 2.0, "sections": 256}, math.pi * 0.09 * 2.0),
        ("box", {"size": [1.0, 0.5, 0.4]}, 0.2),
        (
            "truncated_cone",
            {"bottom_radius": 0.5, "top_radius": 0.2, "height": 0.6, "sections": 256},
            math.pi * 0.6 / 3 * (0.25 + 0.1 + 0.04),
        ),
        (
            "tyre",
            {"major_radius": 0.5, "minor_radius": 0.1, "sections": 128},
            2 * math.pi**2 * 0.5 * 0.01,
        ),
    ],
)
def test_primitives_are_closed_outward_with_the_analytic_volume(kind, params, volume):
    v, f = build_primitive(kind, params)
    tri = v[f]
    signed = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0
    assert signed == pytest.approx(volume, rel=5e-3)  # positive: normals point out
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)  # every edge shared by two faces: closed


def test_cylinder_lies_along_x():
    v, _ = build_primitive("cylinder", {"radius": 0.2, "length": 1.5})
    np.testing.assert_allclose(np.ptp(v, axis=0), [1.5, 0.4, 0.4], atol=1e-3)


def test_bundled_config_loads_and_draws_a_sample_in_its_swath():
    config = load_dataset_config(ROOT / "sonar_raster/scenes/data" / "dataset_default.toml")
    assert config.pings == 512 and config.bins == 1024
    drawn = draw_sample(config, 0, 3)
    assert drawn.sonar.n_bins == 1024 and drawn.trajectory.n_pings == 512
    assert len(drawn.scene.names) == len(drawn.instances) + 1


def test_a_seabed_takes_its_drawn_sediments_micro_relief(tmp_path):
    """``micro_relief`` draws a sediment per sample and adds its roughness to the seabed."""
    text = SWATH.replace(
        'kind = "flat"', 'kind = "flat"\nmicro_relief = { choice = ["rock", "mud"] }'
    )
    config = _config(tmp_path, text)
    seen = {}
    for index in range(6):
        drawn = draw_sample(config, 3, index)
        record = drawn.params["seabed"]["micro_relief"]
        scene = drawn.scene
        z = scene.vertices[np.unique(scene.faces[scene.object_id == 0]), 2]
        seen.setdefault(record["sediment"], []).append(float(np.std(z)))
        assert record["cell_m"] == pytest.approx(1.5 * 12.0 / 256)
    assert set(seen) == {"rock", "mud"}
    assert min(seen["rock"]) > 2.0 * max(seen["mud"]) > 0.0  # rock is rougher (TR 9407 w2)
    # without the key, or with it false, the flat seabed stays flat
    for name, text in (
        ("plain.toml", SWATH),
        ("off.toml", SWATH.replace('kind = "flat"', 'kind = "flat"\nmicro_relief = false')),
    ):
        plain = draw_sample(_config(tmp_path, text, name), 3, 0).scene
        assert np.ptp(plain.vertices[np.unique(plain.faces[plain.object_id == 0]), 2]) == 0.0


def test_a_seabed_material_sets_its_law_and_reflectivity_in_both_scenes(tmp_path):
    """``material`` draws a sediment per sample: its APL-UW law (or Lambert, when asked) and
    its reflectivity on the seabed's faces, in the full scene and the seabed alone (whose
    render the shadow labels compare with); ``micro_relief = true`` takes its roughness."""
    from sonar_raster.scenes.sediments import material_index, material_reflectivity

    text = SWATH.replace(
        "reflectivity = 0.3",
        'material = { choice = ["rock", "mud"] }\nmicro_relief = true\nscattering = "LAW"',
    )
    seen = set()
    for law in ("apl", "lambert"):
        config = _config(tmp_path, text.replace("LAW", law), f"{law}.toml")
        for index in range(4):
            drawn = draw_sample(config, 3, index)
            record = drawn.params["seabed"]
            material = record["material"]
            seen.add(material)
            assert record["scattering"] == law and record["micro_relief"]["sediment"] == material
            code = material_index(material) if law == "apl" else 0
            for scene in (drawn.scene, drawn.seabed):
                seabed = scene.object_id == 0
                assert scene.law is not None or code == 0
                laws = np.zeros(scene.n_triangles) if scene.law is None else scene.law
                assert np.all(laws[seabed] == code) and np.all(laws[~seabed] == 0)
                assert np.all(scene.reflectivity[seabed] == material_reflectivity(material))
    assert seen == {"rock", "mud"}


def test_a_seabed_materials_law_reaches_the_image(tmp_path, gl):
    """The APL-UW sand law over the Lambert one with the same reflectivity, in a sample's raw
    image: the law's factor at each bin's incidence angle and the sample's frequency."""
    from sonar_raster.scenes.sediments import law_factor, material_index

    text = (
        SWATH.replace("count = 1\n", "")
        .replace("reflectivity = 0.3", 'material = "sand"')
        .replace("[[objects]]", "[[objects]]\ncount = 0")
        + '[effects]\nsensor = "ideal"\n'
    )
    profiles = {}
    for law in ("apl", "lambert"):
        config = _config(
            tmp_path,
            text.replace('material = "sand"', f'material = "sand"\nscattering = "{law}"'),
            f"{law}.toml",
        )
        d = draw_sample(config, 0, 0)
        image = gl.render(d.scene, d.sonar, d.trajectory).sides["starboard"]
        profiles[law] = image.astype(np.float64).mean(axis=0)
    sonar = d.sonar
    r = (np.arange(sonar.n_bins) + 0.5) * sonar.range_bin
    first = int(math.ceil(4.0 / sonar.range_bin)) + 40  # 2 m beyond nadir: a smooth law
    cos_t = 4.0 / r[first:]
    law = np.full(len(cos_t), material_index("sand"))
    expected = law_factor(law, cos_t, sonar.frequency_hz, sonar.sound_speed)
    got = profiles["apl"][first:] / profiles["lambert"][first:]
    np.testing.assert_allclose(got, expected, rtol=0.01)
    assert np.ptp(10 * np.log10(expected)) > 1.0  # the law is not Lambert's shape


def test_a_sensor_preset_draws_its_sonar_and_effects_per_sample(tmp_path):
    """``[sonar] preset`` (a name or a choice): the preset's frequency, range, tilt and beam
    where the config leaves them out, the config's keys where it gives them, and the preset's
    effects as the base of the sample's effects."""
    from sonar_raster.dataset.sample import effects_of
    from sonar_raster.effects.presets import preset

    names = ["klein-3900-900", "edgetech-4200-100"]
    text = SWATH.replace(
        "[sonar]\nmax_range = 12.0\ntilt_deg = 15.0\nbeamwidth_deg = 60.0\n",
        f"[sonar]\npreset = {{ choice = {json.dumps(names)} }}\n",
    )
    config = _config(tmp_path, text)
    seen = set()
    angles = np.radians(np.linspace(0.0, 80.0, 17))
    for index in range(6):
        drawn = draw_sample(config, 1, index)
        name = drawn.params["sonar"]["preset"]
        seen.add(name)
        own = preset(name).sonar()
        sonar = drawn.sonar
        assert sonar.frequency_hz == own.frequency_hz and sonar.max_range == own.max_range
        assert sonar.tilt == pytest.approx(own.tilt) and sonar.range_bin == own.max_range / 256
        np.testing.assert_allclose(sonar.beam(angles), own.beam(angles))
        assert effects_of(config, name) == preset(name).effects()
    assert seen == set(names)
    # a key the config gives wins; an [effects] table's keys replace the preset's
    given = text.replace("[sonar]\n", "[sonar]\nfrequency_hz = 500e3\ntilt_deg = 5.0\n")
    given += "[effects]\nnoise_db = -150.0\n"
    config = _config(tmp_path, given, "given.toml")
    drawn = draw_sample(config, 1, 0)
    name = drawn.params["sonar"]["preset"]
    assert drawn.sonar.frequency_hz == 500e3 and drawn.sonar.tilt == pytest.approx(np.radians(5))
    assert drawn.sonar.max_range == preset(name).sonar().max_range
    fx = effects_of(config, name)
    assert fx.noise_db == -150.0 and fx.along_beam_deg == preset(name).effects().along_beam_deg


def test_an_unknown_sensor_preset_is_one_line(tmp_path):
    text = SWATH.replace("[sonar]\n", '[sonar]\npreset = "klein-9000"\n')
    with pytest.raises(SonarRasterError, match=r"\[sonar\] 'preset'.*klein-9000") as info:
        _config(tmp_path, text)
    assert "\n" not in str(info.value)
