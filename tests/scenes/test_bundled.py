"""Every bundled scene loads and the GL image matches the numpy reference within 2 %."""

from __future__ import annotations

import numpy as np
import pytest

from sonar_raster.rendering.reference import render_reference
from sonar_raster.scenes.bundled import DEFAULT_SCENE, bundled_scene, list_bundled
from sonar_raster.scenes.description import Overrides, load_scene_file

NAMES = [name for name, _ in list_bundled()]


def test_the_four_scenes_are_bundled():
    assert {"barrel_on_sand", "cylinder_on_flat", "truck_wheel_on_clay", "flat_calibration"} <= set(
        NAMES
    )
    assert DEFAULT_SCENE in NAMES
    assert bundled_scene("default").stem == DEFAULT_SCENE


@pytest.mark.parametrize("name", NAMES)
def test_gl_matches_reference(gl, name):
    """Relative L1 = Σ|I_gl − I_ref| / Σ I_ref <= 2 % on six pings through the scene's middle."""
    setup = load_scene_file(bundled_scene(name))
    traj = setup.trajectory
    mid = slice(traj.n_pings // 2 - 3, traj.n_pings // 2 + 3)
    six = traj.subset(mid)
    got = gl.render(setup.scene, setup.sonar, six)
    ref = render_reference(setup.scene, setup.sonar, six)
    for side in setup.sonar.sides:
        a = got.sides[side].astype(np.float64)
        b = ref.sides[side].astype(np.float64)
        assert b.sum() > 0
        err = np.abs(a - b).sum() / b.sum()
        assert err <= 0.02, f"{name} {side}: relative L1 {err:.4f}"


def test_objects_stand_on_the_seabed():
    setup = load_scene_file(bundled_scene("cylinder_on_flat"), Overrides(micro_relief=False))
    scene = setup.scene
    cylinder = scene.vertices[np.unique(scene.faces[scene.object_id == 1])]
    assert abs(cylinder[:, 2].min() - 0.0) < 1e-9
    assert np.allclose(cylinder[:, 2].max(), 0.5)
    assert setup.trajectory.positions[0, 2] == pytest.approx(8.0)
    # with the sand's micro-relief the cylinder stands on the relief under its centre
    rough = load_scene_file(bundled_scene("cylinder_on_flat")).scene
    on = rough.vertices[np.unique(rough.faces[rough.object_id == 1])]
    assert 0.0 < np.ptp(rough.vertices[rough.faces[rough.object_id == 0].ravel(), 2]) < 0.5
    assert np.ptp(on[:, 2]) == pytest.approx(0.5)
    assert abs(on[:, 2].min()) < 0.1
