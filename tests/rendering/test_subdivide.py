"""Clipping huge triangles to what the track sees before subdividing them."""

from __future__ import annotations

import logging
import re

import numpy as np
import pytest
from conftest import rect_seabed

from sonar_raster.rendering.analytic import flat_seabed_profile
from sonar_raster.rendering.gl.subdivide import subdivide_within
from sonar_raster.scene import build_scene
from sonar_raster.sonar import Sonar
from sonar_raster.trajectory import Trajectory


def _areas(tri: np.ndarray) -> np.ndarray:
    """Vector area (half the cross product) of each triangle, shape (m, 3)."""
    return 0.5 * np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])


def test_pieces_near_the_box_cover_it_with_the_triangles_shape():
    rng = np.random.default_rng(3)
    box = (-1.0, 2.0, -0.5, 1.5, -np.inf, np.inf)
    tri = rng.uniform(-400.0, 400.0, (30, 3, 3))
    pieces, parent = subdivide_within(tri, 0.5, box)
    edges = np.linalg.norm(pieces - np.roll(pieces, 1, axis=1), axis=2)
    assert edges.max() <= 0.5 + 1e-9
    # each piece faces the way its triangle does, and lies in its plane
    normal = _areas(tri)
    assert np.all(np.einsum("ij,ij->i", _areas(pieces), normal[parent]) > 0)
    offsets = np.einsum("ikj,ij->ik", pieces - tri[parent][:, :1], normal[parent])
    assert np.max(np.abs(offsets)) < 1e-6 * np.linalg.norm(normal, axis=1).max()
    # every point of a triangle inside the box lies in one of its kept pieces (by area: the
    # kept pieces of a triangle cover at least its area inside the box, and not more than the
    # box's neighbourhood holds)
    x0, x1, y0, y1 = box[:4]
    u, v = rng.uniform(size=(2, 40000))
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    for k in range(len(tri)):
        p = tri[k, 0] + u[:, None] * (tri[k, 1] - tri[k, 0]) + v[:, None] * (tri[k, 2] - tri[k, 0])
        inside = (p[:, 0] >= x0) & (p[:, 0] <= x1) & (p[:, 1] >= y0) & (p[:, 1] <= y1)
        area = np.linalg.norm(normal[k])
        kept = np.linalg.norm(_areas(pieces[parent == k]), axis=1).sum()
        assert kept >= inside.mean() * area - 3 * area * np.sqrt(inside.mean() / len(u))
        # the box grown all round by a piece (< 0.5 m)
        margin = (x1 - x0 + 1.0) * (y1 - y0 + 1.0)
        assert kept <= margin / max(abs(normal[k][2]) / area, 1e-3) + 1e-9


def test_a_wall_kilometres_tall_is_cut_only_where_the_track_sees():
    wall = np.array([[[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 0.0, 3000.0]]])  # a mast in mm
    pieces, _ = subdivide_within(wall, 0.05, (-30.0, 30.0, -30.0, 30.0, -20.0, 40.0))
    assert len(pieces) < 1_000_000  # 3.6e9 pieces of 5 cm without the height bound
    assert pieces[..., 2].min() == 0.0 and 40.0 <= pieces[..., 2].max() < 40.05
    area = 0.5 * np.linalg.norm(
        np.cross(pieces[:, 1] - pieces[:, 0], pieces[:, 2] - pieces[:, 0]), axis=1
    )
    assert area.sum() == pytest.approx(2.0 * 40.0 * (1 - 40.0 / 6000.0), rel=1e-3)  # up to 40 m


def test_a_plane_kilometres_wide_renders_as_one_the_swath_wide(gl, caplog):
    sonar = Sonar(max_range=12.0, range_bin=0.1, tilt=0.0)  # triangles cut to 2 m
    traj = Trajectory.straight((0.0, 0.0, 4.0), 0.0, 0.2, 10)
    images = []
    caplog.set_level(logging.INFO, logger="sonar_raster.rendering.gl.raster")
    for half in (30.0, 3000.0):  # 30 edge pieces (not clipped) and 3000 (clipped)
        scene = build_scene([rect_seabed(-half, half, -half, half, 0.0, 0.5)])
        image = gl.render(scene, sonar, traj)
        images.append(np.concatenate([image.sides[s].astype(np.float64) for s in image.sides]))
    pieces = [int(n) for n in re.findall(r"into (\d+)", caplog.text)]
    assert pieces[-1] < 20_000  # 2 × 3000² without the clip
    np.testing.assert_allclose(images[1], images[0], rtol=1e-4, atol=1e-9)
    exact = flat_seabed_profile(sonar, 4.0, 0.5, 0.2).sum()  # both sides alike
    np.testing.assert_allclose(images[1].sum(axis=1), exact, rtol=1e-3)


def test_relief_too_steep_to_cut_up_is_one_line_before_any_work(gl):
    from sonar_raster.errors import SonarRasterError
    from sonar_raster.scenes.seabed import from_grid

    z = 200.0 * (np.indices((21, 41)).sum(axis=0) % 2)  # 200 m ripples at 1 m: 64 M pieces
    scene = build_scene([from_grid(z, 1.0, 1.0, x0=-20.0, y0=-10.0).mesh(0.5)])
    sonar = Sonar(max_range=12.0, range_bin=0.05, tilt=0.0)
    traj = Trajectory.straight((0.0, 0.0, 4.0), 0.0, 0.2, 4)
    with pytest.raises(SonarRasterError, match=r"would be cut into over [\d,]+ pieces of at most"):
        gl.render(scene, sonar, traj)


def test_uniform_and_clipped_cuts_share_one_piece_budget(gl, monkeypatch):
    """A scene whose small triangles (cut uniformly: 3 698 pieces) and huge one (cut within the
    track's reach: 1 680) each fit the budget, but not together, is refused."""
    from sonar_raster.errors import SonarRasterError
    from sonar_raster.rendering.gl import raster

    monkeypatch.setattr(raster, "MAX_PIECES", 4000)
    sonar = Sonar(max_range=12.0, range_bin=0.1, tilt=0.0)
    traj = Trajectory.straight((0.0, 0.0, 4.0), 0.0, 0.2, 10)
    small = rect_seabed(-30.0, 30.0, -30.0, 30.0, 0.0, 0.5)
    huge = rect_seabed(-3000.0, 3000.0, -3000.0, 3000.0, -1.0, 0.5)
    for parts in ([small], [huge]):
        gl.render(build_scene(parts), sonar, traj)
    with pytest.raises(SonarRasterError, match=r"would be cut into over [\d,]+ pieces"):
        gl.render(build_scene([small, huge]), sonar, traj)
