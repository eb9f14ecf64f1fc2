"""Rendering a track in blocks of pings: same image, bounded work per block, skipped pings."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import box_from_bounds, rect_seabed

from sonar_raster.errors import SonarRasterError
from sonar_raster.scene import MeshPart, build_scene
from sonar_raster.sonar import Sonar
from sonar_raster.trajectory import Trajectory


def _grid_seabed(x0: float, x1: float, y0: float, y1: float, step: float = 1.0) -> MeshPart:
    """A flat seabed of a regular grid of squares ``step`` metres wide, two triangles each."""
    xs, ys = np.arange(x0, x1 + step / 2, step), np.arange(y0, y1 + step / 2, step)
    gx, gy = np.meshgrid(xs, ys)
    vertices = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    nx = len(xs)
    i = (np.arange(len(ys) - 1)[:, None] * nx + np.arange(nx - 1)).ravel()
    faces = np.concatenate(
        [np.stack([i, i + 1, i + nx + 1], 1), np.stack([i, i + nx + 1, i + nx], 1)]
    )
    return MeshPart(vertices, faces, 0.5, "seabed", is_seabed=True)


def _dogleg(n1: int, n2: int, spacing: float = 0.3) -> Trajectory:
    leg1 = Trajectory.straight((0.0, -10.0, 7.0), 0.0, spacing, n1)
    end = leg1.positions[-1]
    leg2 = Trajectory.straight((end[0] + 0.2, end[1] + 0.2, 7.0), 45.0, spacing, n2)
    return Trajectory(
        np.concatenate([leg1.positions, leg2.positions]),
        np.concatenate([leg1.headings, leg2.headings]),
        np.zeros(n1 + n2),
    )


@pytest.mark.parametrize("chunk", [1, 7, 64])
def test_blocks_put_together_equal_the_whole_track(gl, chunk):
    scene = build_scene(
        [
            rect_seabed(-80.0, 80.0, -80.0, 80.0),
            box_from_bounds([[12.0, -2.0, 0.0], [13.0, 2.0, 1.5]]),
            box_from_bounds([[-9.0, 5.0, 0.0], [-8.0, 7.0, 1.0]], name="port box"),
        ]
    )
    sonar = Sonar(max_range=30.0, range_bin=0.1)
    traj = _dogleg(30, 25)
    whole = gl.render(scene, sonar, traj, labels=True)
    blocks = list(gl.render_chunks(scene, sonar, traj, chunk, labels=True))
    assert [b.metadata["first_ping"] for b in blocks] == list(range(0, traj.n_pings, chunk))
    for side in sonar.sides:
        joined = np.concatenate([b.sides[side] for b in blocks])
        assert joined.shape == whole.sides[side].shape
        # The same samples, cut at block edges: equal up to float32 rounding of the shifted
        # segment origins (a few units in the last place of the largest value).
        tol = 1e-5 * float(whole.sides[side].max())
        assert np.abs(joined - whole.sides[side]).max() <= tol
        labels = np.concatenate([b.labels[side] for b in blocks])
        agree = np.mean(labels == whole.labels[side])
        assert agree > 0.999, f"{side}: labels agree on {agree:.4%} of cells"


def test_a_render_between_two_blocks_does_not_change_the_generator_scene(gl):
    """Blocks of a survey interleaved with renders of another scene on the same renderer still
    show the survey's scene (the other render replaced the uploaded geometry)."""
    seabed = rect_seabed(-60.0, 60.0, -60.0, 60.0)
    survey = build_scene([seabed, box_from_bounds([[12.0, -2.0, 0.0], [13.0, 2.0, 1.5]])])
    other = build_scene([seabed, box_from_bounds([[6.0, -9.0, 0.0], [8.0, 9.0, 3.0]])])
    sonar = Sonar(max_range=25.0, range_bin=0.1)
    traj = Trajectory.straight((0.0, -6.0, 7.0), 0.0, 0.3, 40)
    whole = gl.render(survey, sonar, traj)
    blocks = []
    for block in gl.render_chunks(survey, sonar, traj, 10):
        blocks.append(block)
        gl.render(other, sonar, traj.subset(slice(0, 5)))
    joined = np.concatenate([b.sides["starboard"] for b in blocks])
    tol = 1e-5 * float(whole.sides["starboard"].max())
    assert np.abs(joined - whole.sides["starboard"]).max() <= tol


def test_triangles_drawn_per_block_stay_flat_as_the_seabed_grows(gl):
    """The tile index culls to each block's swath: work per block does not follow scene size."""
    sonar = Sonar(max_range=25.0, range_bin=0.1, sides=("starboard",))
    spacing, chunk = 0.5, 40
    per_block, totals = {}, {}
    for length in (200.0, 400.0, 800.0):
        scene = build_scene([_grid_seabed(-5.0, 40.0, -10.0, length + 10.0)])
        traj = Trajectory.straight((0.0, 0.0, 6.0), 0.0, spacing, int(length / spacing))
        drawn = [
            b.metadata["counters"]["triangles_drawn"]
            for b in gl.render_chunks(scene, sonar, traj, chunk)
        ]
        per_block[length] = np.median(drawn)
        totals[length] = scene.n_triangles
    assert totals[800.0] > 3.5 * totals[200.0]
    ratio = max(per_block.values()) / min(per_block.values())
    assert ratio < 1.1, f"median triangles per block {per_block}"
    assert per_block[800.0] < 0.05 * totals[800.0]


def test_pings_with_nothing_in_reach_cost_no_draw(gl):
    """A track that runs off the end of the seabed: the blocks beyond it draw nothing."""
    sonar = Sonar(max_range=20.0, range_bin=0.1, sides=("starboard",))
    scene = build_scene([_grid_seabed(-5.0, 30.0, -10.0, 60.0)])
    traj = Trajectory.straight((0.0, 0.0, 6.0), 0.0, 0.5, 400)  # 200 m, seabed ends at 60 m
    blocks = list(gl.render_chunks(scene, sonar, traj, 50))
    counters = [b.metadata["counters"] for b in blocks]
    reach = 60.0 + sonar.max_range  # pings beyond this y see nothing
    for block, count in zip(blocks, counters, strict=True):
        first_y = block.metadata["first_ping"] * 0.5
        if first_y > reach:
            assert count["draws"] == 0 and count["draws_skipped_empty"] == 1
            assert not np.any(block.sides["starboard"])
        if first_y + 25.0 < 60.0:
            assert count["draws"] == 1
    assert sum(c["draws_skipped_empty"] for c in counters) >= 4


def test_bad_block_size_is_refused(gl, flat_scene):
    traj = Trajectory.straight((0.0, 0.0, 5.0), 0.0, 0.2, 4)
    with pytest.raises(SonarRasterError, match="chunk_pings"):
        next(gl.render_chunks(flat_scene, Sonar(max_range=10.0), traj, 0))
