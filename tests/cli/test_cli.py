"""The command line: renders, and bad input ends in one line, exit 2, and no files."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sonar_raster.cli.app import main
from sonar_raster.io.images import read_exr

CUBE_OBJ = """v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1
f 1 3 2\nf 1 4 3\nf 5 6 7\nf 5 7 8\nf 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8\nf 3 8 7
f 4 1 5\nf 4 5 8
"""


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "sonar_raster", *args],
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_render_bundled_default_to_png_and_exr(tmp_path):
    png, exr = tmp_path / "out.png", tmp_path / "out.exr"
    result = run_cli("render", "default", "-o", str(png), "-o", str(exr), "--pings", "20")
    assert result.returncode == 0, result.stderr
    assert png.is_file() and exr.is_file() and (tmp_path / "out.json").is_file()
    sides, attrs = read_exr(exr)
    assert set(sides) == {"port", "starboard"} and sides["port"].shape == (20, 1000)
    assert sides["starboard"].max() > 0
    meta = json.loads((tmp_path / "out.json").read_text())
    assert meta["sonar"]["n_bins"] == 1000


def test_bare_model_renders_on_a_default_seabed(tmp_path):
    model = tmp_path / "cube.obj"
    model.write_text(CUBE_OBJ)
    out = tmp_path / "cube.exr"
    assert main(["render", str(model), "-o", str(out), "--pings", "40", "-q", "--ideal"]) == 0
    sides, _ = read_exr(out)
    star = sides["starboard"]
    # The cube stands mid-swath to starboard: its echo and shadow break the seabed's profile.
    profile = np.median(star, axis=0)
    middle = star[17:23]
    assert np.any(middle > 2 * profile + 1e-6)  # bright face towards the sonar
    assert np.any((middle == 0) & (profile > 0))  # its shadow
    assert np.all(star[:5] <= 1.0001 * profile)  # pings far from it see only seabed


def test_osmesa_backend_option(tmp_path):
    out = tmp_path / "o.exr"
    assert main(["render", "flat_calibration", "-o", str(out), "--gl", "osmesa", "-q"]) == 0
    _, attrs = read_exr(out)
    assert "osmesa" in json.dumps(attrs)


def test_help_is_instant_and_lists_commands():
    result = run_cli("--help")
    assert result.returncode == 0
    for word in ("render", "scenes", "doctor"):
        assert word in result.stdout
    # --help must not import the heavy modules.
    probe = subprocess.run(
        [
            sys.executable,
            "-c",
            "import sys, sonar_raster.cli.app as c\n"
            "try:\n    c.main(['--help'])\nexcept SystemExit:\n    pass\n"
            "print(sorted(m for m in ('moderngl', 'trimesh', 'OpenImageIO', 'scipy', 'skimage')"
            " if m in sys.modules))",
        ],
        capture_output=True,
        text=True,
    )
    assert probe.stdout.strip().endswith("[]")


def test_doctor_reports_both_backends():
    result = run_cli("doctor")
    assert result.returncode == 0
    assert "egl     ok" in result.stdout and "osmesa  ok" in result.stdout


def _write_bad_files(tmp: Path) -> None:
    (tmp / "broken.wrl").write_text("#VRML V2.0 utf8\nTransform { children [ Shape { \n")
    (tmp / "broken.gltf").write_text('{"asset": {"version": "2.0"}, "meshes": [ {')
    (tmp / "nan.obj").write_text("v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n")
    (tmp / "inf.obj").write_text("v 0 0 0\nv 1 0 inf\nv 0 1 0\nf 1 2 3\n")
    (tmp / "empty.toml").write_text("[sonar]\nmax_range = 30.0\n")
    (tmp / "typo.toml").write_text("[sonar]\nmax_rnage = 30.0\n[seabed]\nkind = 'flat'\n")
    (tmp / "model.xyz").write_text("1 2 3\n")


def _bad_inputs(tmp: Path) -> dict[str, list[str]]:
    out = str(tmp / "out.png")
    return {
        "missing file": ["render", str(tmp / "nope.toml"), "-o", out],
        "unknown extension": ["render", str(tmp / "model.xyz"), "-o", out],
        "malformed vrml": ["render", str(tmp / "broken.wrl"), "-o", out],
        "malformed gltf": ["render", str(tmp / "broken.gltf"), "-o", out],
        "nan vertices": ["render", str(tmp / "nan.obj"), "-o", out],
        "inf vertices": ["render", str(tmp / "inf.obj"), "-o", out],
        "empty scene": ["render", str(tmp / "empty.toml"), "-o", out],
        "unknown key": ["render", str(tmp / "typo.toml"), "-o", out],
        "negative range": ["render", "default", "-o", out, "--range", "-5"],
        "zero bins": ["render", "default", "-o", out, "--range", "10", "--range-bin", "20"],
        "zero bin size": ["render", "default", "-o", out, "--range-bin", "0"],
        "unknown side": ["render", "default", "-o", out, "--side", "up"],
        "unknown gl": ["render", "default", "-o", out, "--gl", "wgl"],
        "unknown output": ["render", "default", "-o", str(tmp / "out.jpg")],
        "missing output dir": ["render", "default", "-o", str(tmp / "no" / "out.png")],
        "unknown scene name": ["render", "atlantis", "-o", out],
        "unknown command": ["paint"],
    }


@pytest.mark.parametrize("case", list(_bad_inputs(Path("/nonexistent"))))
def test_bad_input_is_one_line_exit_2_no_output(tmp_path, capsys, case):
    _write_bad_files(tmp_path)
    args = _bad_inputs(tmp_path)[case]
    before = set(tmp_path.rglob("*"))
    with pytest.raises(SystemExit) as stop:
        sys.exit(main(args))
    assert stop.value.code == 2
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("sonar-raster: error:"), err
    assert "Traceback" not in err
    assert set(tmp_path.rglob("*")) == before, "an output file was left behind"


def test_bad_input_in_a_real_process_has_no_traceback(tmp_path):
    result = run_cli("render", str(tmp_path / "missing.wrl"), "-o", str(tmp_path / "o.png"))
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr
    assert not (tmp_path / "o.png").exists()


def test_existing_output_survives_a_failed_render(tmp_path):
    out = tmp_path / "keep.png"
    out.write_bytes(b"precious")
    code = main(["render", str(tmp_path / "missing.toml"), "-o", str(out)])
    assert code == 2 and out.read_bytes() == b"precious"


def test_reference_renderer_option_agrees_with_gl(tmp_path):
    gl, ref = tmp_path / "gl.exr", tmp_path / "ref.exr"
    common = ["flat_calibration", "--pings", "4", "--side", "starboard", "-q", "--ideal"]
    assert main(["render", *common, "-o", str(gl)]) == 0
    assert main(["render", *common, "-o", str(ref), "--renderer", "reference"]) == 0
    a = read_exr(gl)[0]["starboard"].astype(np.float64)
    b = read_exr(ref)[0]["starboard"].astype(np.float64)
    assert np.abs(a - b).sum() / b.sum() < 0.005


def test_coherent_model(tmp_path):
    out = tmp_path / "c.exr"
    args = ["render", "flat_calibration", "-o", str(out), "--model", "coherent", "--pings", "4"]
    assert (
        main([*args, "--scatterer-spacing", "8", "--seed", "2", "--side", "starboard", "-q"]) == 0
    )
    sides, _ = read_exr(out)
    meta = json.loads((tmp_path / "c.json").read_text())
    assert meta["metadata"]["renderer"] == "coherent" and meta["metadata"]["seed"] == 2
    assert sides["starboard"].shape == (4, 600) and sides["starboard"].max() > 0


def test_bare_model_with_offset_origin_is_centred(tmp_path):
    """A model whose geometry sits far from its file origin still lands mid-swath, mid-track."""
    model = tmp_path / "far.obj"
    lines = [line for line in CUBE_OBJ.splitlines() if line.startswith("f")]
    verts = [
        f"v {x + 40} {y - 25} {z}"
        for x, y, z in [
            (0, 0, 0),
            (1, 0, 0),
            (1, 1, 0),
            (0, 1, 0),
            (0, 0, 1),
            (1, 0, 1),
            (1, 1, 1),
            (0, 1, 1),
        ]
    ]
    model.write_text("\n".join(verts + lines) + "\n")
    from sonar_raster.scenes.description import load_scene_file

    setup = load_scene_file(model)
    cube = setup.scene.vertices[np.unique(setup.scene.faces[setup.scene.object_id == 1])]
    middle = setup.trajectory.positions[setup.trajectory.n_pings // 2]
    assert abs(cube[:, 1].mean() - middle[1]) < 0.2
    assert 0.2 * setup.sonar.max_range < cube[:, 0].mean() < 0.6 * setup.sonar.max_range
    assert cube[:, 2].min() == pytest.approx(0.0)
