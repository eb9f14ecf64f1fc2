"""Changing RasterSettings between renders on one renderer gives what a fresh renderer gives."""

from __future__ import annotations

import numpy as np
from conftest import box_from_bounds, plane

from sonar_raster.rendering.gl.raster import RasterRenderer, RasterSettings
from sonar_raster.scene import build_scene
from sonar_raster.sonar import Sonar
from sonar_raster.trajectory import Trajectory


def test_switching_split_and_along_samples_on_one_renderer(gl):
    """The scene's vertex array draws with the pass-1 program it was made with: a program per
    split once left the uniforms of a later split's render unused (half the image at
    along_samples 1 after a render at 2)."""
    scene = build_scene([plane(80.0), box_from_bounds([[8.0, -1.0, 0.0], [9.0, 1.0, 1.0]])])
    sonar = Sonar(max_range=20.0, range_bin=0.05)
    traj = Trajectory.straight((0.0, -1.0, 6.0), 0.0, 0.2, 10)
    want = RasterSettings(split="footprint", along_samples=1, cull=False)  # the cached array
    saved = gl.settings
    try:
        gl.settings = RasterSettings(split="nearest", along_samples=2, cull=False)
        gl.render(scene, sonar, traj)
        gl.settings = want
        got = gl.render(scene, sonar, traj)
    finally:
        gl.settings = saved
    with RasterRenderer(gl.backend, want) as fresh:
        ref = fresh.render(scene, sonar, traj)
    for side in sonar.sides:
        assert np.array_equal(got.sides[side], ref.sides[side])
