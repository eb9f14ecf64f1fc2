"""The heightfield sweep (``RasterSettings.heightfield``) against rasterising the same grid.

Both sample the same rays (rows × warped columns) and share each ray's weight among range bins by
the same rule; the sweep finds each ray's first hit by walking the grid's cells along the fan's
trace, the raster by drawing the triangles. They differ only where a ray meets the surface near a
triangle edge (the raster's projected edges are straight, the true ones slightly curved), so the
images agree to a fraction of a percent, with objects, labels, per-material laws, both sides, any
heading and more columns than one dispatch resolves.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from conftest import box_from_bounds

from sonar_raster.rendering.gl.heightfield import find_grid
from sonar_raster.rendering.gl.raster import RasterSettings
from sonar_raster.scene import build_scene
from sonar_raster.scenes.seabed import heightfield_mesh, make_seabed
from sonar_raster.sonar import BeamPattern, Sonar
from sonar_raster.trajectory import Trajectory

#: Largest relative L1 between the sweep and the raster of the same grid.
TOL = 3e-3


def _rough(size=(40.0, 40.0), resolution=0.1, seed=3, rms=0.08, law=0):
    field = make_seabed(
        "rough", size=size, center=(0.0, 0.0), resolution=resolution, seed=seed, rms_height=rms
    )
    part = field.mesh(0.3, "seabed")
    if law:
        part = replace(part, law=law)
    return part


def _track(n=12, heading=0.0, spacing=0.1, altitude=6.0, x=0.0, y=0.0, pitch=0.0):
    h = math.radians(heading)
    along = np.array([math.sin(h), math.cos(h), 0.0])
    pos = np.array([x, y, altitude]) + (np.arange(n) - n / 2)[:, None] * spacing * along
    return Trajectory(pos, np.full(n, h), 0.0, math.radians(pitch))


def _both(gl, scene, sonar, traj, labels=False, **settings):
    saved = gl.settings
    try:
        gl.settings = RasterSettings(heightfield=True, **settings)
        swept = gl.render(scene, sonar, traj, labels=labels)
        gl.settings = RasterSettings(heightfield=False, **settings)
        drawn = gl.render(scene, sonar, traj, labels=labels)
    finally:
        gl.settings = saved
    return swept, drawn


def _rel(a, b) -> float:
    num = sum(float(np.abs(a.sides[s].astype(np.float64) - b.sides[s]).sum()) for s in b.sides)
    return num / sum(float(b.sides[s].astype(np.float64).sum()) for s in b.sides)


@pytest.mark.parametrize("heading", [0.0, 90.0, 33.0, 225.0])
@pytest.mark.parametrize("split", ["footprint", "nearest"])
def test_sweep_matches_the_raster_on_a_rough_grid(gl, heading, split):
    scene = build_scene([_rough()])
    sonar = Sonar(max_range=15.0, range_bin=0.02, beam=BeamPattern.gaussian(50.0))
    swept, drawn = _both(gl, scene, sonar, _track(heading=heading), split=split)
    assert swept.metadata["grid_sweeps"] == swept.metadata["draws"] > 0
    assert drawn.metadata["grid_sweeps"] == 0
    assert _rel(swept, drawn) < TOL


def test_sweep_matches_with_crab_along_samples_and_a_law(gl):
    """Crab (fans off the course, still level), 3 rays per ping, an APL-UW sediment law."""
    scene = build_scene([_rough(law=2)])
    sonar = Sonar(frequency_hz=300e3, max_range=12.0, range_bin=0.03)
    n = 10
    pos = np.column_stack([np.zeros(n), 0.15 * np.arange(n) - 0.7, np.full(n, 5.0)])
    traj = Trajectory(pos, np.full(n, math.radians(15.0)), 0.0)
    swept, drawn = _both(gl, scene, sonar, traj, along_samples=3, oversample=3.0)
    assert swept.metadata["grid_sweeps"] > 0
    assert _rel(swept, drawn) < TOL


def test_sweep_resumes_over_several_dispatches(gl):
    """Over 12 000 columns: a row is resolved in several dispatches (llvmpipe's loop budget),
    each resuming the walk where the last stopped; a resume one cell late or early shows."""
    scene = build_scene([_rough(size=(70.0, 8.0), resolution=0.1)])
    sonar = Sonar(max_range=32.0, range_bin=0.005, sides=("starboard",))
    traj = _track(n=4, x=-33.0, altitude=3.0)
    swept, drawn = _both(gl, scene, sonar, traj)
    assert swept.metadata["grid_sweeps"] == 1
    columns = swept.metadata["settings"]["oversample"] * sonar.n_bins
    assert columns > 12000
    assert _rel(swept, drawn) < TOL
    far = slice(sonar.n_bins // 2, None)  # the columns of the later dispatches
    a = swept.sides["starboard"][:, far].astype(np.float64)
    b = drawn.sides["starboard"][:, far].astype(np.float64)
    assert np.abs(a - b).sum() < TOL * b.sum()


def test_objects_on_the_grid_are_merged_by_range(gl):
    """A box on the swept seabed: its echo, its shadow and its labels as when all is drawn."""
    seabed = _rough(size=(30.0, 30.0), rms=0.03)
    box = box_from_bounds([[6.0, -1.0, -0.2], [7.0, 1.0, 1.0]], name="box")
    scene = build_scene([seabed, box])
    sonar = Sonar(max_range=14.0, range_bin=0.02, sides=("starboard",))
    traj = _track(n=16, spacing=0.125, altitude=5.0)
    swept, drawn = _both(gl, scene, sonar, traj, labels=True)
    assert swept.metadata["grid_sweeps"] > 0
    assert _rel(swept, drawn) < TOL
    a, b = swept.labels["starboard"], drawn.labels["starboard"]
    assert np.any(b == 2)  # the box is labelled
    assert np.mean(a != b) < 0.01
    # the shadow behind the box: bins where the raster has nothing have nothing swept either
    img = swept.sides["starboard"]
    dark = drawn.sides["starboard"] == 0
    assert float(img[dark].sum()) < 1e-3 * float(img.sum())


@pytest.mark.parametrize("mirror", [False, True])
def test_a_turned_or_mirrored_grid_gives_the_same_image(gl, mirror):
    """Scene and track turned by 37 degrees (and mirrored, faces re-wound): the grid is still
    swept, and the image is the same as the axis-aligned one's (sides swapped by the mirror)."""
    part = _rough(size=(30.0, 30.0))
    sonar = Sonar(max_range=12.0, range_bin=0.03)
    traj = _track(n=8, heading=0.0)
    c, s = math.cos(math.radians(37.0)), math.sin(math.radians(37.0))
    m = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # compass turn by 37 degrees
    heading = 37.0
    if mirror:
        m = np.diag([-1.0, 1.0, 1.0]) @ m
        heading = -37.0
    faces = part.faces[:, ::-1] if mirror else part.faces
    turned = build_scene([replace(part, vertices=part.vertices @ m.T, faces=faces)])
    moved = Trajectory(traj.positions @ m.T, np.full(traj.n_pings, math.radians(heading)), 0.0)
    base = gl.render(build_scene([part]), sonar, traj)
    other = gl.render(turned, sonar, moved)
    assert base.metadata["grid_sweeps"] > 0 and other.metadata["grid_sweeps"] > 0
    for side in sonar.sides:
        mate = {"port": "starboard", "starboard": "port"}[side] if mirror else side
        a, b = other.sides[mate].astype(np.float64), base.sides[side].astype(np.float64)
        assert np.abs(a - b).sum() <= 5e-4 * b.sum()


def test_pitched_fans_are_rasterised(gl):
    """Tilted fans do not trace straight lines on the grid: the draw falls back, bit for bit."""
    scene = build_scene([_rough(size=(30.0, 30.0))])
    sonar = Sonar(max_range=12.0, range_bin=0.03)
    swept, drawn = _both(gl, scene, sonar, _track(pitch=-5.0))
    assert swept.metadata["grid_sweeps"] == 0
    for side in sonar.sides:
        assert np.array_equal(swept.sides[side], drawn.sides[side])


def test_find_grid_reads_the_heightfield_layout():
    z = np.random.default_rng(0).normal(size=(12, 15))
    part = heightfield_mesh(z, -3.0, 2.0, 0.5, 0.25)
    box = box_from_bounds([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    grid = find_grid(build_scene([box, part]))
    assert grid is not None
    assert (grid.nx, grid.ny, grid.u, grid.v) == (15, 12, (0.5, 0.0), (0.0, 0.25))
    assert (grid.x0, grid.y0, grid.object_id, grid.winding) == (-3.0, 2.0, 1, 1)
    assert grid.first_face == 12 and grid.z_max == z.max()
    # turned 30 degrees and mirrored (faces re-wound): still a grid, its steps turned too
    c, s = math.cos(math.radians(30.0)), math.sin(math.radians(30.0))
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    mirror = np.diag([-1.0, 1.0, 1.0])
    moved = part.vertices @ (mirror @ turn).T
    other = find_grid(build_scene([part.__class__(moved, part.faces[:, ::-1], 0.5)]))
    assert other is not None and other.winding == -1
    assert np.allclose(other.u, (mirror @ turn)[:2, 0] * 0.5)
    assert np.allclose(other.grid_coordinates(moved[[16, 40], :2]), [[1, 1], [10, 2]])
    # faces in another order, or nodes off the regular spacing, are not a grid
    shuffled = part.faces[np.random.default_rng(1).permutation(len(part.faces))]
    assert find_grid(build_scene([part.__class__(part.vertices, shuffled, 0.5)])) is None
    moved = part.vertices.copy()
    moved[20, 0] += 0.01
    assert find_grid(build_scene([part.__class__(moved, part.faces, 0.5)])) is None


def test_egl_and_osmesa_sweep_alike(gl, osmesa_renderer):
    """The sweep (a compute pass reading the vertex buffer as storage) on both backends."""
    seabed = _rough(size=(30.0, 30.0))
    box = box_from_bounds([[6.0, -1.0, -0.2], [7.0, 1.0, 1.0]])
    scene = build_scene([seabed, box])
    sonar = Sonar(max_range=12.0, range_bin=0.03)
    a = gl.render(scene, sonar, _track(), labels=True)
    b = osmesa_renderer.render(scene, sonar, _track(), labels=True)
    assert a.metadata["grid_sweeps"] == b.metadata["grid_sweeps"] > 0
    for side in sonar.sides:
        assert np.array_equal(a.sides[side], b.sides[side])
        assert np.array_equal(a.labels[side], b.labels[side])
