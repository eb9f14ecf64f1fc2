"""The public API as the README shows it: its example runs from any folder."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import sonar_raster as sr

README = Path(__file__).resolve().parents[1] / "README.md"


def test_readme_python_example_runs_from_another_folder(tmp_path):
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), re.S)
    assert blocks, "the README has a Python example"
    done = subprocess.run(
        [sys.executable, "-c", blocks[0]], cwd=tmp_path, capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr
    for name in (
        "raw.exr",
        "raw.json",
        "recorded.png",
        "seabed/elevation.exr",
        "seabed/inversion.json",
        "seabed/seabed.glb",
    ):
        assert (tmp_path / name).is_file(), name


def test_load_scene_takes_a_bundled_name_or_a_path():
    by_name = sr.load_scene("flat_calibration")
    assert "flat_calibration" in dict(sr.list_bundled()) and by_name.scene.n_triangles > 0
    by_path = sr.load_scene(by_name.source)
    assert by_path.scene.n_triangles == by_name.scene.n_triangles


def test_render_models_agree_on_the_flat_calibration_scene():
    setup = sr.load_scene("flat_calibration")
    raster = sr.render(setup.scene, setup.sonar, setup.trajectory)
    reference = sr.render(setup.scene, setup.sonar, setup.trajectory, model="reference")
    for side in raster.sides:
        a, b = raster.sides[side].astype(np.float64), reference.sides[side]
        assert np.abs(a - b).sum() / b.sum() < 0.01


def test_render_returns_labels_from_the_raster_model():
    setup = sr.load_scene("cylinder_on_flat")
    image = sr.render(setup.scene, setup.sonar, setup.trajectory, labels=True)
    assert image.labels is not None and set(image.labels) == set(image.sides)
    try:
        sr.render(setup.scene, setup.sonar, setup.trajectory, model="reference", labels=True)
    except sr.SonarRasterError as exc:
        assert "raster" in str(exc)
    else:
        raise AssertionError("labels from the reference model should be refused")


def test_bundled_dataset_config_by_name():
    assert sr.load_dataset_config("dataset_default").name


@pytest.mark.parametrize("sides", [("starboard", "starboard"), ("port", "starboard", "port"), ()])
def test_a_sonar_with_a_side_twice_or_none_is_refused(sides):
    from sonar_raster.errors import SonarRasterError
    from sonar_raster.sonar import Sonar

    with pytest.raises(SonarRasterError, match="port, starboard or both, each once"):
        Sonar(sides=sides)
    assert Sonar(sides=("starboard", "port")).sides == ("starboard", "port")
