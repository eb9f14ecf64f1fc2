"""An installed wheel ships its shaders and scenes and renders what the checkout renders."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sonar_raster.io.images import read_exr

ROOT = Path(__file__).resolve().parents[1]

RENDER = """
import sys, sonar_raster
from sonar_raster.cli.app import main
print(sonar_raster.__file__)
sys.exit(main(["render", "default", "-o", sys.argv[1], "--pings", "12", "-q"]))
"""


@pytest.mark.slow
def test_installed_wheel_renders_like_the_checkout(tmp_path):
    wheels = tmp_path / "wheels"
    build = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "-q",
            "-w",
            str(wheels),
            str(ROOT),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert build.returncode == 0, build.stderr
    wheel = next(wheels.glob("sonar_raster-*.whl"))
    target = tmp_path / "site"
    install = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "--no-deps",
            "-q",
            "--target",
            str(target),
            str(wheel),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert install.returncode == 0, install.stderr
    env = {**os.environ, "PYTHONPATH": str(target)}
    out_wheel, out_tree = tmp_path / "wheel.exr", tmp_path / "tree.exr"
    ran = subprocess.run(
        [sys.executable, "-c", RENDER, str(out_wheel)],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert ran.returncode == 0, ran.stderr
    assert ran.stdout.strip().startswith(str(target)), "the wheel's package was not the one used"
    ran = subprocess.run(
        [sys.executable, "-c", RENDER, str(out_tree)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert ran.returncode == 0, ran.stderr
    a, _ = read_exr(out_wheel)
    b, _ = read_exr(out_tree)
    for side in b:
        assert np.array_equal(a[side], b[side])
