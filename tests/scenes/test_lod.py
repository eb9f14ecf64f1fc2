"""Level of detail: seabed grids finer than the image resolves are drawn from a coarser grid."""

from __future__ import annotations

import numpy as np
import pytest

from sonar_raster.errors import SonarRasterError
from sonar_raster.scenes.description import load_scene_file
from sonar_raster.scenes.seabed import Heightfield, level_of_detail


def _field(dx: float, f) -> Heightfield:
    x = np.arange(0.0, 4.0 + dx / 2, dx)
    y = np.arange(0.0, 3.0 + dx / 2, dx)
    return Heightfield(f(x[None, :], y[:, None]), 0.0, 0.0, dx, dx)


def test_a_plane_is_coarsened_without_error():
    fine = _field(0.01, lambda x, y: 0.1 * x - 0.05 * y + 2.0)
    coarse, report = level_of_detail(fine, 0.05)
    assert (coarse.dx, coarse.dy) == pytest.approx((0.05, 0.05))
    assert coarse.extent == pytest.approx(fine.extent)
    assert report["triangles_to"] * 25 == pytest.approx(report["triangles_from"], rel=0.02)
    assert report["rms_m"] < 1e-12 and report["max_m"] < 1e-12


def test_reported_error_is_the_height_difference_at_the_fine_nodes():
    wave = lambda x, y: 0.01 * np.sin(2 * np.pi * x / 0.3) + 0 * y  # noqa: E731
    fine = _field(0.01, wave)
    coarse, report = level_of_detail(fine, 0.1)
    xx, yy = np.meshgrid(fine.x, fine.y)
    diff = coarse.height_at(xx, yy) - fine.z
    assert report["rms_m"] == pytest.approx(np.sqrt(np.mean(diff**2)))
    assert report["max_m"] == pytest.approx(np.abs(diff).max())
    assert 0.001 < report["rms_m"] < 0.01  # a 0.3 m wave on 0.1 m cells: visibly smoothed


def test_coarse_enough_grids_and_coarse_axes_are_kept():
    fine = _field(0.2, lambda x, y: x * y)
    same, report = level_of_detail(fine, 0.05)
    assert same is fine and report == {}
    mixed = Heightfield(np.zeros((301, 5)), 0.0, 0.0, 1.0, 0.01)  # only y is fine
    coarse, _ = level_of_detail(mixed, 0.05)
    assert coarse.dx == 1.0 and coarse.dy == pytest.approx(0.05)
    with pytest.raises(SonarRasterError):
        level_of_detail(fine, 0.0)


def _scene_file(tmp_path, lod_line: str):
    path = tmp_path / "fine.toml"
    path.write_text(
        "[sonar]\nmax_range = 20.0\nrange_bin = 0.05\n"
        '[seabed]\nkind = "rough"\nsize = [10.0, 10.0]\nresolution = 0.01\n'
        f"{lod_line}\n[trajectory]\npings = 3\n"
    )
    return load_scene_file(path)


def test_scene_files_coarsen_by_default_and_say_so(tmp_path):
    auto = _scene_file(tmp_path, "")
    off = _scene_file(tmp_path, "lod = false")
    wider = _scene_file(tmp_path, "lod = 2.0")
    assert off.scene.n_triangles == 2 * 1000 * 1000 and off.notes == {}
    report = auto.notes["seabed_lod"]
    assert report["to_m"] == pytest.approx([0.025, 0.025])
    assert auto.scene.n_triangles == report["triangles_to"] == 2 * 400 * 400
    assert wider.notes["seabed_lod"]["to_m"] == pytest.approx([0.1, 0.1])
    with pytest.raises(SonarRasterError, match="lod must be"):
        _scene_file(tmp_path, 'lod = "yes"')
