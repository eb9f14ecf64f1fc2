"""Faces scatter from the side the sound meets, whichever way the model file wound them.

An open sheet (a plate, a fin, a hull exported as a surface) or a body whose faces are wound
both ways is seen from either side; a closed body wound outward, and the seabed, from the
front (their backs are never in sight). The GL raster, the numpy reference and the coherent
model agree on it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import box, plane

from sonar_raster.rendering.coherent.model import render_coherent
from sonar_raster.rendering.reference import render_reference
from sonar_raster.scene import MeshPart, build_scene
from sonar_raster.sonar import Sonar
from sonar_raster.trajectory import Trajectory

SONAR = Sonar(max_range=25.0, range_bin=0.05, sides=("starboard",))
TRACK = Trajectory.straight((0.0, -1.0, 10.0), 0.0, 0.2, 10)


def _plate(flip: bool, name: str = "plate") -> MeshPart:
    """A 2 x 2 m plate leaning back 30 degrees, 20 m to starboard: its front faces the sonar
    (``flip``: the same plate wound the other way, its front facing away)."""
    c, s = math.cos(math.radians(30.0)), math.sin(math.radians(30.0))
    v = np.array(
        [[20 - s, -1, 0.5], [20 - s, 1, 0.5], [20 + s, 1, 0.5 + 2 * c], [20 + s, -1, 0.5 + 2 * c]]
    )
    f = np.array([[0, 2, 1], [0, 3, 2]])
    return MeshPart(v, f[:, ::-1].copy() if flip else f, 0.5, name)


#: The plate's echo, bins (slant ranges 21.5-22.2 m).
PLATE_BINS = slice(430, 444)


def test_build_scene_says_which_faces_are_seen_from_both_sides():
    closed = box((20.0, 0.0, 1.0), (2.0, 1.0, 0.8))
    inside_out = MeshPart(closed.vertices, closed.faces[:, ::-1].copy(), 0.9, "inverted")
    mixed_faces = closed.faces.copy()
    mixed_faces[::3] = mixed_faces[::3, ::-1]
    mixed = MeshPart(closed.vertices, mixed_faces, 0.9, "mixed")
    sheet = _plate(False)
    twice = MeshPart(
        sheet.vertices,
        np.concatenate([sheet.faces, sheet.faces[:, ::-1]]),
        np.array([0.2, 0.3, 0.2, 0.3]),
        "written twice",
    )
    down = plane(60.0)
    down = MeshPart(down.vertices, down.faces[:, ::-1].copy(), 0.5, "seabed", is_seabed=True)
    scene = build_scene([down, closed, inside_out, mixed, sheet, twice])
    both = scene.two_sided_faces()
    by_part = [both[scene.object_id == k] for k in range(6)]
    assert [bool(b.all()) for b in by_part] == [False, False, False, True, True, True]
    assert not any(b.any() for b in by_part[:3])
    normals, _ = scene.face_normals_areas()
    assert np.all(normals[scene.object_id == 0, 2] > 0)  # the seabed turned up
    inverted = scene.object_id == 2
    centre = scene.vertices[scene.faces[inverted]].mean(axis=1) - [20.0, 0.0, 1.0]
    assert np.all(np.einsum("ij,ij->i", normals[inverted], centre) > 0)  # turned outward
    kept = scene.object_id == 5
    assert kept.sum() == 2  # the sheet written twice is kept once, with its own R
    np.testing.assert_array_equal(scene.reflectivity[kept], [0.2, 0.3])


def test_with_back_faces_appends_a_reversed_copy_of_the_two_sided_faces_only():
    scene = build_scene([plane(60.0), box((20.0, 0.0, 1.0), (2.0, 1.0, 0.8)), _plate(False)])
    doubled = scene.with_back_faces()
    both = np.flatnonzero(scene.two_sided_faces())
    assert len(both) == 2
    assert doubled.n_triangles == scene.n_triangles + 2
    np.testing.assert_array_equal(doubled.faces[-2:], scene.faces[both][:, ::-1])
    np.testing.assert_array_equal(doubled.object_id[-2:], scene.object_id[both])
    assert not doubled.two_sided_faces().any()
    assert doubled.with_back_faces() is doubled


def test_a_sheet_renders_the_same_from_either_side_in_gl_and_the_reference(gl):
    images = {}
    for flip in (False, True):
        scene = build_scene([plane(60.0), _plate(flip)])
        images["gl", flip] = gl.render(scene, SONAR, TRACK).sides["starboard"]
        images["ref", flip] = render_reference(scene, SONAR, TRACK).sides["starboard"]
    plate = images["gl", False][:, PLATE_BINS].sum()
    assert plate > 2.0 * images["gl", False][:, 400:430].sum()  # the plate's echo is there
    # float32 sums in another order: equal to 1e-4
    np.testing.assert_allclose(images["gl", True], images["gl", False], rtol=1e-4, atol=1e-9)
    np.testing.assert_allclose(images["ref", True], images["ref", False], rtol=1e-6, atol=1e-12)
    ref = images["ref", False][:, PLATE_BINS].sum()
    assert abs(plate / ref - 1.0) < 0.01


@pytest.mark.parametrize(("engine", "visibility"), [("numpy", "rays"), ("compiled", "depth")])
def test_a_sheet_renders_alike_from_either_side_in_the_coherent_model(engine, visibility):
    """The plate's echo, about 6 times the seabed's in its bins (as in GL), keeps its energy
    wound either way; the scatterers' draws differ (they are keyed by face), so the two
    sums agree to within their speckle (140 pixels)."""
    echo = {}
    for name, parts in (
        ("front", [plane(60.0), _plate(False)]),
        ("back", [plane(60.0), _plate(True)]),
        ("no plate", [plane(60.0)]),
    ):
        image = render_coherent(
            build_scene(parts), SONAR, TRACK, visibility=visibility, engine=engine
        ).sides["starboard"]
        echo[name] = float(image[:, PLATE_BINS].sum())
    assert echo["front"] > 4.0 * echo["no plate"]
    assert 0.8 < echo["back"] / echo["front"] < 1.25, echo


def test_a_body_wound_both_ways_renders_as_the_body_wound_outward(gl):
    closed = box((20.0, 0.0, 1.0), (2.0, 1.5, 1.2))
    mixed_faces = closed.faces.copy()
    mixed_faces[::3] = mixed_faces[::3, ::-1]  # one triangle of the faces the sonar sees
    mixed = MeshPart(closed.vertices, mixed_faces, 0.9, "box")
    out = {}
    for name, part in (("outward", closed), ("mixed", mixed)):
        scene = build_scene([plane(60.0), part])
        out["gl", name] = gl.render(scene, SONAR, TRACK).sides["starboard"]
        out["ref", name] = render_reference(scene, SONAR, TRACK).sides["starboard"]
    np.testing.assert_allclose(out["gl", "mixed"], out["gl", "outward"], rtol=1e-4, atol=1e-9)
    echo = out["ref", "outward"].sum()
    assert np.abs(out["ref", "mixed"] - out["ref", "outward"]).sum() < 1e-3 * echo
