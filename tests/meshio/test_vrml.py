"""VRML97 reader: real model files, transforms, primitives, PROTO/Inline/Switch, errors."""

from __future__ import annotations

import gzip
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import SHARED_DATA

from sonar_raster.errors import InputWarning, SonarRasterError
from sonar_raster.meshio.vrml import SEGMENTS, load_vrml, parse_vrml

DATA = SHARED_DATA / "vrml"
HEADER = "#VRML V2.0 utf8\n"


def real_file(name: str) -> Path:
    path = DATA / name
    if not path.is_file():
        pytest.skip(f"{path} not available")
    return path


def parse(body: str, **kwargs) -> list:
    return parse_vrml(HEADER + body, **kwargs)


def normals_areas(part) -> tuple[np.ndarray, np.ndarray]:
    tri = part.vertices[part.faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(cross, axis=1)
    return cross / norm[:, None], 0.5 * norm


def assert_outward(part, centre) -> None:
    normals, _ = normals_areas(part)
    centroids = part.vertices[part.faces].mean(axis=1)
    assert np.all(np.einsum("ij,ij->i", normals, centroids - centre) > 0)


def bounds(parts) -> np.ndarray:
    used = np.concatenate([p.vertices[np.unique(p.faces)] for p in parts])
    return np.stack([used.min(axis=0), used.max(axis=0)])


def shape(geometry: str, extra: str = "") -> str:
    return f"Shape {{ {extra} geometry {geometry} }}"


TRIANGLE = (
    "IndexedFaceSet { coord Coordinate { point [ 1 0 0, 2 1 1, 1 1 0 ] } coordIndex [ 0 1 2 ] }"
)


# -- real files ---------------------------------------------------------------------------------


def test_tire_is_a_tyre_of_radius_0_1_m():
    (part,) = load_vrml(real_file("tire.wrl"))
    assert part.name == "tire_0"
    assert part.faces.shape == (212, 3)  # counted from coordIndex by a separate script
    assert part.vertices.dtype == np.float64 and part.faces.dtype == np.int64
    radial = np.hypot(part.vertices[:, 1], part.vertices[:, 2])
    assert radial.max() == pytest.approx(0.1, abs=1e-6)
    np.testing.assert_allclose(bounds([part]), [[-0.025, -0.1, -0.1], [0.025, 0.1, 0.1]], atol=1e-4)
    assert part.reflectivity == pytest.approx(0.294118)


def test_valve_handle_keeps_def_names_and_inch_scale():
    parts = load_vrml(real_file("valvehandle213.wrl"))
    assert [p.name for p in parts] == [f"ID{k}" for k in (4, 12, 18, 24, 30, 36, 42, 48)]
    assert sum(len(p.faces) for p in parts) == 332
    inch = 0.0254  # Transform scale; the handle is 8.375 in across, 1.1875 in thick
    expected = np.array([[-4.1876, -4.1876, -0.593701], [4.1874, 4.1874, 0.593799]]) * inch
    np.testing.assert_allclose(bounds(parts), expected, atol=1e-6)
    colour = np.mean([0.862745, 0.0784314, 0.235294])  # one Material, USE'd by seven shapes
    assert all(p.reflectivity == pytest.approx(colour) for p in parts)


def test_rack_nested_transforms_give_a_two_metre_rack():
    text = real_file("rack1.wrl").read_text()
    parts = load_vrml(real_file("rack1.wrl"))
    n_box, n_cyl = len(re.findall(r"\bBox\b", text)), len(re.findall(r"\bCylinder\b", text))
    assert (n_box, n_cyl) == (45, 10)
    # the two 1e-6-scaled IndexedFaceSets only have faces like "0 0 0": nothing is kept
    assert len(parts) == n_box + n_cyl
    assert sum(len(p.faces) for p in parts) == 12 * n_box + 4 * SEGMENTS * n_cyl
    size = np.ptp(bounds(parts), axis=0)
    assert 2.0 < size[1] < 2.2 and 0.4 < size[0] < 1.0 and 0.3 < size[2] < 1.0
    # first upright: Box 0.045 x 1.995 x 0.055 at (0.2465, 1.1315, 0.1975), then the rack's
    # rotation of pi about y and translation (0.545, -0.05, 3.485)
    np.testing.assert_allclose(bounds(parts[:1]).mean(axis=0), [0.2985, 1.0815, 3.2875], atol=1e-4)
    np.testing.assert_allclose(np.ptp(bounds(parts[:1]), axis=0), [0.045, 1.995, 0.055], atol=1e-4)
    assert {round(p.reflectivity, 3) for p in parts} == {0.0, 0.397, 0.883, 1.0}


# -- transforms ---------------------------------------------------------------------------------


def test_transform_rotation_scale_center_against_hand_computed_points():
    (part,) = parse(
        "Transform { translation 10 20 30 rotation 0 0 1 1.5707963267948966 scale 2 3 4"
        f" center 1 0 0 children {shape(TRIANGLE)} }}"
    )
    # p -> T + C + Rz(90) diag(2,3,4) (p - C)
    np.testing.assert_allclose(part.vertices, [[11, 20, 30], [8, 22, 34], [8, 20, 30]], atol=1e-12)


def test_scale_orientation_scales_along_the_rotated_axis():
    points = (
        "IndexedFaceSet { coord Coordinate { point [ 1 0 0, 0 1 0, 0 0 1 ] } coordIndex [0 1 2] }"
    )
    (part,) = parse(
        "Transform { scale 2 1 1 scaleOrientation 0 0 1 1.5707963267948966"
        f" children {shape(points)} }}"
    )
    np.testing.assert_allclose(part.vertices, [[1, 0, 0], [0, 2, 0], [0, 0, 1]], atol=1e-12)


def test_nested_transforms_apply_parent_after_child():
    (part,) = parse(
        "Transform { translation 1 0 0 children Transform { scale 2 2 2 children [ "
        f"{shape(TRIANGLE)} ] }} }}"
    )
    np.testing.assert_allclose(part.vertices, [[3, 0, 0], [5, 2, 2], [3, 2, 0]])


def test_mirroring_transform_keeps_faces_outward():
    (part,) = parse(f"Transform {{ scale -1 2 1 translation 5 0 0 children {shape('Box {}')} }}")
    assert_outward(part, [5, 0, 0])


# -- primitives ---------------------------------------------------------------------------------


def test_box_dimensions_area_and_orientation():
    (part,) = parse(shape("Box { size 1 2 3 }"))
    assert part.faces.shape == (12, 3)
    np.testing.assert_allclose(bounds([part]), [[-0.5, -1, -1.5], [0.5, 1, 1.5]])
    assert normals_areas(part)[1].sum() == pytest.approx(2 * (1 * 2 + 2 * 3 + 1 * 3))
    assert_outward(part, [0, 0, 0])


def test_default_box_is_two_metres():
    (part,) = parse(shape("Box {}"))
    np.testing.assert_allclose(bounds([part]), [[-1, -1, -1], [1, 1, 1]])


def test_sphere_area_close_to_four_pi_r_squared():
    (part,) = parse(shape("Sphere { radius 2 }"))
    np.testing.assert_allclose(np.linalg.norm(part.vertices, axis=1), 2.0)
    assert normals_areas(part)[1].sum() == pytest.approx(4 * np.pi * 4, rel=0.01)
    assert_outward(part, [0, 0, 0])


def test_cylinder_area_bounds_and_flags():
    (part,) = parse(shape("Cylinder { radius 0.5 height 3 }"))
    np.testing.assert_allclose(bounds([part]), [[-0.5, -1.5, -0.5], [0.5, 1.5, 0.5]], atol=1e-12)
    area = 2 * np.pi * 0.5 * 3 + 2 * np.pi * 0.25
    assert normals_areas(part)[1].sum() == pytest.approx(area, rel=0.01)
    assert_outward(part, [0, 0, 0])
    (open_top,) = parse(shape("Cylinder { top FALSE }"))
    assert len(open_top.faces) == 3 * SEGMENTS
    (tube,) = parse(shape("Cylinder { top FALSE bottom FALSE }"))
    assert len(tube.faces) == 2 * SEGMENTS
    assert parse(shape("Cylinder { top FALSE bottom FALSE side FALSE }")) == []


def test_cone_apex_base_and_orientation():
    (part,) = parse(shape("Cone { bottomRadius 2 height 4 }"))
    assert len(part.faces) == 2 * SEGMENTS
    np.testing.assert_allclose(bounds([part]), [[-2, -2, -2], [2, 2, 2]], atol=1e-12)
    assert_outward(part, [0, -1, 0])
    area = np.pi * 2 * (2 + np.hypot(2, 4))  # base + lateral surface
    assert normals_areas(part)[1].sum() == pytest.approx(area, rel=0.01)


def test_elevation_grid_faces_up():
    (part,) = parse(
        shape("ElevationGrid { xDimension 3 zDimension 2 xSpacing 2 height [0 0 0 1 1 1] }")
    )
    assert len(part.faces) == 4
    normals, areas = normals_areas(part)
    assert np.all(normals[:, 1] > 0)
    np.testing.assert_allclose(bounds([part]), [[0, 0, 0], [4, 1, 1]])


def signed_volume(part) -> float:
    tri = part.vertices[part.faces]
    return float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum()) / 6.0


def test_default_extrusion_is_a_box_with_outward_faces():
    """VRML97's default Extrusion: a 2 × 2 square swept from y = 0 to 1, both ends capped."""
    (part,) = parse(shape("Extrusion {}"))
    np.testing.assert_allclose(bounds([part]), [[-1, 0, -1], [1, 1, 1]])
    assert normals_areas(part)[1].sum() == pytest.approx(2 * 4 + 4 * 2)
    assert signed_volume(part) == pytest.approx(4.0)
    assert_outward(part, [0, 0.5, 0])


def test_extrusion_places_the_cross_section_across_the_spine():
    """A straight spine along z: +y turned onto it takes the section's z onto -y; the scale
    and the orientation act in the section's plane before it is placed."""
    (part,) = parse(shape("Extrusion { spine [0 0 0, 0 0 3] scale 0.5 2 }"))
    np.testing.assert_allclose(bounds([part]), [[-0.5, -2, 0], [0.5, 2, 3]], atol=1e-12)
    assert signed_volume(part) == pytest.approx(1.0 * 4.0 * 3.0)
    turned = "Extrusion { orientation 0 1 0 1.5707963 crossSection [2 1, 2 -1, -2 -1, -2 1, 2 1] }"
    (part,) = parse(shape(turned))
    np.testing.assert_allclose(bounds([part]), [[-1, 0, -2], [1, 1, 2]], atol=1e-6)


def test_an_extrusion_along_a_closed_spine_is_a_ring_facing_out():
    """A circle swept round a circle (a torus of radii 1 and 0.2): its volume is 2π² R r²
    less the polygons' shortfall, positive (faces outward), every vertex on the tube."""
    t = np.linspace(0.0, 2.0 * np.pi, 33)
    section = ", ".join(f"{0.2 * np.cos(a):.6f} {0.2 * np.sin(a):.6f}" for a in t)
    spine = ", ".join(f"{np.cos(a):.6f} 0 {np.sin(a):.6f}" for a in t)
    (part,) = parse(shape(f"Extrusion {{ crossSection [{section}] spine [{spine}] }}"))
    radius = np.hypot(part.vertices[:, 0], part.vertices[:, 2])
    tube = np.hypot(radius - 1.0, part.vertices[:, 1])
    assert np.abs(tube - 0.2).max() < 0.01
    assert signed_volume(part) == pytest.approx(2 * np.pi**2 * 0.04, rel=0.03)


def test_an_open_extrusion_follows_ccw():
    (part,) = parse(shape("Extrusion { beginCap FALSE endCap FALSE }"))
    assert len(part.faces) == 8
    assert_outward(part, [0, 0.5, 0])
    (inside,) = parse(shape("Extrusion { beginCap FALSE endCap FALSE ccw FALSE }"))
    np.testing.assert_array_equal(inside.faces, part.faces[:, [0, 2, 1]])


# -- IndexedFaceSet -----------------------------------------------------------------------------


@pytest.mark.parametrize("plane", ["xy", "yz"])
def test_concave_polygons_are_cut_into_ears_where_the_file_says_convex_false(plane):
    """An M-shaped pentagon (area 2.5) and a triangle: with ``convex FALSE`` the triangles
    cover the polygon exactly, all turned as it winds; fanned (the default, as VRML97 allows
    for convex polygons) the notch is covered twice over, one triangle turned back."""
    outline = np.array([[0, 0], [2, 0], [2, 2], [1, 0.5], [0, 2], [3, 0], [4, 0], [3, 1]])
    flat = np.zeros((len(outline), 1))
    points = np.hstack([outline, flat]) if plane == "xy" else np.hstack([flat, outline])
    coord = ", ".join(" ".join(f"{v:g}" for v in p) for p in points)
    body = f"coord Coordinate {{ point [{coord}] }} coordIndex [0 1 2 3 4 -1, 5 6 7]"
    (part,) = parse(shape(f"IndexedFaceSet {{ convex FALSE {body} }}"))
    normals, areas = normals_areas(part)
    axis = 2 if plane == "xy" else 0
    assert areas.sum() == pytest.approx(2.5 + 0.5)
    assert np.all(normals[:, axis] > 0.999)
    (fanned,) = parse(shape(f"IndexedFaceSet {{ {body} }}"))
    assert (normals_areas(fanned)[0][:, axis] < 0).sum() == 1


def test_polygons_are_fan_triangulated_and_degenerate_faces_dropped():
    ifs = (
        "IndexedFaceSet { coord Coordinate { point [0 0 0, 1 0 0, 1 1 0, 0 1 0, -1 0.5 0] }"
        " coordIndex [0 1 2 3 -1, 0 1 2 3 4 -1, 0 0 1 -1, 2 2 2 -1 -1, 0 1 2] }"
    )
    (part,) = parse(shape(ifs))
    np.testing.assert_array_equal(
        part.faces, [[0, 1, 2], [0, 2, 3], [0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 1, 2]]
    )
    assert np.all(normals_areas(part)[0][:, 2] > 0)


def test_ccw_false_flips_normals():
    (front,) = parse(shape(TRIANGLE))
    (back,) = parse(shape(TRIANGLE.replace("coordIndex", "ccw FALSE coordIndex")))
    np.testing.assert_allclose(normals_areas(back)[0], -normals_areas(front)[0])


def test_comments_commas_strings_and_hex_are_tokens_as_in_the_spec():
    text = (
        '# header comment\nWorldInfo { title "a } [ tricky \\" title" info ["x", "y"] }\n'
        "Shape { geometry IndexedFaceSet { coord Coordinate { point [ 0 0 0, # one ] { \n"
        " 1,0,0 , 0 1 0 ] } coordIndex [ 0x0 0x1 2 ] } }"
    )
    (part,) = parse(text)
    np.testing.assert_array_equal(part.faces, [[0, 1, 2]])


def test_bom_crlf_shared_geometry_and_empty_proto():
    text = (
        "\ufeff#VRML V2.0 utf8 exported by something\r\n"
        "DEF a Shape {\r\n geometry DEF g Box { } }\r\n"
        "Shape { geometry USE g }\r\nPROTO Empty [] { }\r\nGroup { children [ Empty { } ] }"
    )
    assert [p.name for p in parse_vrml(text)] == ["a", "g"]


def test_unknown_nodes_and_unsupported_geometry_are_skipped():
    text = (
        'NavigationInfo { type [ "EXAMINE" "ANY" ] headlight TRUE }\n'
        "DEF S Script { field SFBool on TRUE eventIn SFTime touch eventOut SFBool out"
        ' url "javascript: function touch() { out = on; }" }\n'
        "Fog { color 1 1 1 } Viewpoint { position 0 0 10 }\n"
        "ROUTE S.out TO S.touch\n"
        + shape("IndexedLineSet { coord Coordinate { point [0 0 0, 1 1 1] } coordIndex [0 1] }")
        + shape("Box {}")
    )
    (part,) = parse(text)
    assert len(part.faces) == 12


# -- names, materials, DEF/USE ------------------------------------------------------------------


def test_reflectivity_from_material_diffuse_colour():
    parts = parse(
        shape("Box {}")
        + shape("Box {}", "appearance Appearance { }")
        + shape("Box {}", "appearance Appearance { material Material { } }")
        + shape(
            "Box {}", "appearance Appearance { material Material { diffuseColor 0.1 0.2 0.3 } }"
        )
    )
    assert [p.reflectivity for p in parts] == pytest.approx([0.5, 0.5, 0.8, 0.2])


def test_names_prefer_shape_then_geometry_then_ancestor_then_stem(tmp_path):
    text = (
        f"DEF top Transform {{ children [ DEF s {shape('DEF g Box {}')} {shape('DEF g2 Box {}')}"
        f" {shape('Box {}')} ] }} {shape('Box {}')}"
    )
    (tmp_path / "thing.wrl").write_text(HEADER + text)
    assert [p.name for p in load_vrml(tmp_path / "thing.wrl")] == ["s", "g2", "top", "thing_3"]
    assert parse(shape("Box {}"))[0].name == "vrml_0"


def test_use_reinstantiates_under_the_current_transform():
    text = (
        f"DEF Part Transform {{ translation 1 0 0 children {shape('Box { size 1 1 1 }')} }}\n"
        "Transform { translation 0 0 10 children [ USE Part ] }\n"
        "Transform { translation 0 0 20 children [ USE Part USE Part ] }"
    )
    parts = parse(text)
    assert [p.name for p in parts] == ["Part"] * 4
    centres = [bounds([p]).mean(axis=0) for p in parts]
    np.testing.assert_allclose(centres, [[1, 0, 0], [1, 0, 10], [1, 0, 20], [1, 0, 20]])


# -- grouping nodes -----------------------------------------------------------------------------


@pytest.mark.parametrize(("which", "sizes"), [(-1, []), (0, [1.0]), (1, [2.0]), (5, [])])
def test_switch_shows_the_chosen_child(which, sizes):
    text = (
        f"Switch {{ whichChoice {which} choice [ {shape('Box { size 1 1 1 }')}"
        f" {shape('Box { size 2 2 2 }')} ] }}"
    )
    assert [np.ptp(p.vertices[:, 0]) for p in parse(text)] == sizes


def test_switch_default_shows_nothing_and_lod_shows_the_first_level():
    assert parse(f"Switch {{ choice [ {shape('Box {}')} ] }}") == []
    text = f"LOD {{ range [10] level [ {shape('Box { size 1 1 1 }')} {shape('Sphere {}')} ] }}"
    (part,) = parse(text)
    assert len(part.faces) == 12


def test_collision_anchor_billboard_group_are_groups():
    text = " ".join(
        f"{kind} {{ children [ {shape('Box {}')} ] }}"
        for kind in ("Group", "Collision", "Anchor", "Billboard")
    )
    assert len(parse(text)) == 4


# -- PROTO / EXTERNPROTO / Inline ---------------------------------------------------------------

BLOCK_PROTO = """
PROTO Block [ field SFVec3f size 1 1 1  field SFColor colour 0.5 0.5 0.5
              field SFVec3f where 0 0 0  eventIn SFFloat set_fraction ]
{
  Transform { translation IS where children [
    Shape { appearance Appearance { material Material { diffuseColor IS colour } }
            geometry Box { size IS size } } ] }
  TimeSensor { }
}
"""


def test_proto_instances_use_is_fields_and_defaults():
    parts = parse(BLOCK_PROTO + "DEF big Block { size 2 4 6 where 10 0 0 colour 1 0 1 } Block { }")
    assert [p.name for p in parts] == ["big", "vrml_1"]
    np.testing.assert_allclose(bounds(parts[:1]), [[9, -2, -3], [11, 2, 3]])
    np.testing.assert_allclose(bounds(parts[1:]), [[-0.5, -0.5, -0.5], [0.5, 0.5, 0.5]])
    assert [p.reflectivity for p in parts] == pytest.approx([2 / 3, 0.5])


def test_nested_proto_passes_is_fields_through_and_keeps_use_inside_body():
    text = BLOCK_PROTO + (
        "PROTO Pair [ field SFVec3f size 1 1 1 ] {"
        " Group { children [ Block { size IS size }"
        " DEF b Block { size IS size where 0 5 0 } USE b ] } }"
        " Pair { size 2 2 2 } Pair { }"
    )
    parts = parse(text)
    assert len(parts) == 6
    np.testing.assert_allclose([np.ptp(p.vertices[:, 0]) for p in parts], [2, 2, 2, 1, 1, 1])


def test_externproto_resolved_from_a_local_file(tmp_path):
    (tmp_path / "protos.wrl").write_text(HEADER + "PROTO Other [] { Group {} }" + BLOCK_PROTO)
    main = tmp_path / "main.wrl"
    main.write_text(
        HEADER
        + 'EXTERNPROTO Blk [ field SFVec3f size ] ["http://x/protos.wrl#Block", "protos.wrl#Block"]'
        " Blk { size 3 3 3 }"
    )
    (part,) = load_vrml(main)
    assert np.ptp(part.vertices[:, 0]) == pytest.approx(3)


def test_unresolved_externproto_raises_naming_it():
    text = 'EXTERNPROTO Far [ field SFFloat x ] "http://example.com/far.wrl#Far"\nFar { x 1 }'
    with pytest.raises(SonarRasterError, match=r"<string>:3: EXTERNPROTO Far .*far\.wrl"):
        parse(text)


def test_inline_relative_to_the_including_file(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "part.wrl").write_text(HEADER + f"DEF inner {shape('Box {}')}")
    main = tmp_path / "main.wrl"
    main.write_text(
        HEADER + 'Transform { translation 0 0 5 children Inline { url [ "sub/part.wrl" ] } }'
        ' Inline { url "sub/part.wrl" }'
    )
    parts = load_vrml(main)
    assert [p.name for p in parts] == ["inner", "inner"]
    np.testing.assert_allclose([bounds([p]).mean(axis=0)[2] for p in parts], [5, 0])
    assert len(parse_vrml(main.read_text(), base_dir=tmp_path)) == 2


def test_inline_missing_file_and_cycle_raise(tmp_path):
    main = tmp_path / "main.wrl"
    main.write_text(HEADER + '\nInline { url "nowhere.wrl" }')
    with pytest.raises(
        SonarRasterError, match=r"main\.wrl:3: Inline file 'nowhere\.wrl' not found"
    ):
        load_vrml(main)
    (tmp_path / "a.wrl").write_text(HEADER + 'Inline { url "b.wrl" }')
    (tmp_path / "b.wrl").write_text(HEADER + 'Group { children Inline { url "a.wrl" } }')
    with pytest.raises(SonarRasterError, match=r"b\.wrl:2: Inline 'a\.wrl' includes itself"):
        load_vrml(tmp_path / "a.wrl")


def test_gzipped_file_loads(tmp_path):
    path = tmp_path / "box.wrl.gz"
    path.write_bytes(gzip.compress((HEADER + shape("Box {}")).encode()))
    (part,) = load_vrml(path)
    assert part.name == "box.wrl_0" and len(part.faces) == 12


# -- errors -------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "solid cube\nfacet normal 0 0 1\n",  # an ASCII STL under a .wrl name
            r"<string>: not a VRML97 file \(no '#VRML V2\.0 utf8' header line, and not readable "
            r"without one: <string>:1: expected '\{' after solid",
        ),
        ("#VRML V1.0 ascii\nSeparator { }", r"<string>:1: VRML 1\.0 is not supported"),
        (
            HEADER + "Transform {\n children [\n Shape { }\n ]\n",
            r"<string>:5: expected a field name "
            r"or '}' to close Transform from line 2, found end of file",
        ),
        (HEADER + "Group { }\n}\n", r"<string>:3: expected a node or end of file, found '}'"),
        (
            HEADER
            + "Shape {\n geometry IndexedFaceSet {\n coord Coordinate { point [ 0 0 0\n 1 x 0 ] }"
            " } }",
            r"<string>:5: expected a number, found 'x'",
        ),
        (
            HEADER + "Coordinate { point [ 0 0 0 }",
            r"<string>:2: expected a number or '\]', found '\}'",
        ),
        (HEADER + "Group { children [ USE nothing ] }", r"<string>:2: USE nothing before any DEF"),
        (HEADER + "hello world", r"<string>:2: expected '\{' after hello, found 'world'"),
        (HEADER + "Group { children [ 'x' ] }", r"<string>:2: unexpected character \"'\""),
        (
            HEADER + "\n" + shape(TRIANGLE.replace("[ 0 1 2 ]", "[ 0 1 3 ]")),
            r"<string>:3: IndexedFaceSet coordIndex 3 is outside its 3 points",
        ),
        (
            HEADER + "Transform { translation 1 2 children [] }",
            r"<string>:2: Transform field 'translation' needs 3 number\(s\), got 2",
        ),
    ],
)
def test_malformed_input_raises_one_line_error_with_line_number(text, message):
    with pytest.raises(SonarRasterError, match=message) as info:
        parse_vrml(text)
    assert "\n" not in str(info.value)


def test_missing_file_raises_naming_it(tmp_path):
    with pytest.raises(SonarRasterError, match=r"nope\.wrl' not found; check the path"):
        load_vrml(tmp_path / "nope.wrl")


# -- numbers beyond float64 (found by tests/io/test_fuzz.py) -------------------------------------


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            HEADER + "\n" + shape(TRIANGLE.replace("2 1 1", "2 1e999 1")),
            r"<string>:3: the number '1e999' is not a finite float64",
        ),
        (
            HEADER + "Transform {\n translation 1 -1e999 0 children [] }",
            r"<string>:3: the number '-1e999' is not a finite float64",
        ),
        (
            HEADER + "Shape { geometry Sphere { radius 0x1" + "0" * 300 + " } }",
            r"<string>:2: the number '0x10000.*' is not a finite float64",
        ),
        (
            HEADER + "\n" + shape(TRIANGLE.replace("[ 0 1 2 ]", "[ 0 1 1e30 ]")),
            r"<string>:3: IndexedFaceSet coordIndex 1e\+30 is outside its 3 points",
        ),
        (
            HEADER + "\n" + shape(TRIANGLE.replace("[ 0 1 2 ]", "[ 0 1 1.5 ]")),
            r"<string>:3: IndexedFaceSet coordIndex 1.5 is outside its 3 points",
        ),
        (
            HEADER + "Transform { scale 1e300 1 1 children [\n"
            "Transform { scale 1e300 1 1 children [ Shape { geometry Box { } } ] } ] }",
            r"<string>:3: Transform gives coordinates beyond float64",
        ),
        (
            HEADER + "Transform { scale 1e300 1 1 children [\n"
            "Shape { geometry Box { size 1e300 1 1 } } ] }",
            r"<string>:3: Box gives coordinates beyond float64",
        ),
        (
            HEADER + "Transform { scale 10 10 10 children [\n"
            "Shape { geometry Sphere { radius 1e308 } } ] }",
            r"<string>:3: Sphere gives coordinates beyond float64",
        ),
    ],
)
def test_numbers_beyond_float64_raise_one_line_without_warnings(text, message):
    with pytest.raises(SonarRasterError, match=message) as info:
        parse_vrml(text)  # filterwarnings = error: an overflow warning would fail here
    assert "\n" not in str(info.value)


def test_huge_but_finite_scale_and_mirroring_keep_faces_outward():
    (part,) = parse("Transform { scale -1e150 1e150 1e150 children [ Shape { geometry Box {} } ] }")
    assert np.all(np.isfinite(part.vertices))
    # the scale's determinant overflows float64, its sign does not: faces stay outward
    assert_outward(SimpleNamespace(vertices=part.vertices / 1e150, faces=part.faces), np.zeros(3))


def test_damaged_gzip_stream_is_one_line_error(tmp_path):
    packed = bytearray(gzip.compress((HEADER + shape("Box { }") * 50).encode()))
    packed[20:30] = b"\xff" * 10  # inside the deflate stream: zlib.error, not OSError
    path = tmp_path / "broken.wrl.gz"
    path.write_bytes(bytes(packed))
    with pytest.raises(SonarRasterError, match=r"broken\.wrl\.gz: broken gzip data") as info:
        load_vrml(path)
    assert "\n" not in str(info.value)


def test_gzip_bomb_is_refused_before_it_fills_memory(tmp_path, monkeypatch):
    from sonar_raster.meshio import vrml

    monkeypatch.setattr(vrml, "MAX_TEXT_BYTES", 10_000)
    bomb = tmp_path / "bomb.wrl"
    bomb.write_bytes(gzip.compress(b"#VRML V2.0 utf8\n" + b" " * 50_000))
    with pytest.raises(SonarRasterError, match="decompresses to more than"):
        vrml.load_vrml(bomb)


def test_multi_member_gzip_is_read_whole(tmp_path):
    from sonar_raster.meshio import vrml

    path = tmp_path / "two.wrl"
    first = b"#VRML V2.0 utf8\nShape { geometry Box { size 1 2 3 } }\n"
    path.write_bytes(gzip.compress(first) + gzip.compress(b"Shape { geometry Box { } }\n"))
    assert len(vrml.load_vrml(path)) == 2


# Two unit squares side by side (x 0..1 and 1..2) and a triangle, on z = 0.
SQUARES = (
    "coord Coordinate { point [0 0 0, 1 0 0, 1 1 0, 0 1 0, 2 0 0, 2 1 0, 3 0 0] }"
    " coordIndex [0 1 2 3 -1, 1 4 5 2 -1, 4 6 5]"
)
MATERIAL = "appearance Appearance { material Material { diffuseColor 0.8 0.8 0.8 } }"


def _face_greys(colours: str, rest: str = "") -> tuple[np.ndarray, np.ndarray]:
    """Each triangle's reflectivity and the x of its centroid, for SQUARES with a Color."""
    ifs = f"IndexedFaceSet {{ {SQUARES} color Color {{ color [{colours}] }} {rest} }}"
    (part,) = parse(shape(ifs, MATERIAL))
    r = np.broadcast_to(part.reflectivity, (len(part.faces),))
    return r, part.vertices[part.faces].mean(axis=1)[:, 0]


@pytest.mark.parametrize(
    ("rest", "expected"),
    [
        ("colorPerVertex FALSE", (0.0, 1.0, 0.5)),  # one colour per face, in order
        ("colorPerVertex FALSE colorIndex [2 0 1]", (0.5, 0.0, 1.0)),  # through colorIndex
    ],
)
def test_colours_per_face_replace_the_material(rest, expected):
    """VRML97: a Color node's colours replace the Material's diffuse colour (0.8 here); per
    face, each polygon's triangles take its colour (RGB mean)."""
    r, x = _face_greys("0 0 0, 1 1 1, 0.2 0.5 0.8", rest)
    face = np.digitize(x, [1.0, 2.0])  # 0, 1: the squares; 2: the triangle
    assert len(r) == 5
    np.testing.assert_allclose(r, np.array(expected)[face], atol=1e-12)


@pytest.mark.parametrize("indexed", [False, True])
def test_colours_per_vertex_give_each_triangle_its_corners_mean(indexed):
    """Per vertex (the default): through coordIndex, or a colorIndex of the same layout."""
    greys = np.arange(7) / 6.0
    colours = ", ".join(f"{g:g} {g:g} {g:g}" for g in greys)
    rest = "colorIndex [0 1 2 3 -1, 1 4 5 2 -1, 4 6 5]" if indexed else ""
    if indexed:  # the same colours, listed backwards and indexed to match
        colours = ", ".join(f"{g:g} {g:g} {g:g}" for g in greys[::-1])
        rest = "colorIndex [6 5 4 3 -1, 5 2 1 4 -1, 2 0 1]"
    ifs = f"IndexedFaceSet {{ {SQUARES} color Color {{ color [{colours}] }} {rest} }}"
    (part,) = parse(shape(ifs, MATERIAL))
    expected = greys[part.faces].mean(axis=1)
    np.testing.assert_allclose(part.reflectivity, expected, atol=1e-6)  # 6 digits in the file


def test_per_face_colours_follow_concave_polygons_cut_into_ears():
    outline = "0 0 0, 2 0 0, 2 2 0, 1 0.5 0, 0 2 0, 3 0 0, 4 0 0, 3 1 0"
    body = f"coord Coordinate {{ point [{outline}] }} coordIndex [0 1 2 3 4 -1, 5 6 7]"
    ifs = (
        f"IndexedFaceSet {{ convex FALSE {body} colorPerVertex FALSE "
        "color Color { color [0.1 0.1 0.1, 0.7 0.7 0.7] } }"
    )
    (part,) = parse(shape(ifs))
    x = part.vertices[part.faces].mean(axis=1)[:, 0]
    np.testing.assert_allclose(part.reflectivity, np.where(x < 2.5, 0.1, 0.7), atol=1e-12)


@pytest.mark.parametrize(
    ("rest", "message"),
    [
        ("colorPerVertex FALSE colorIndex [0 1]", r"colorIndex has 2 entries for 3 faces"),
        ("colorPerVertex FALSE colorIndex [0 1 7]", r"colour index 7 is outside its 3 colours"),
        ("colorIndex [0 1 2]", r"colorIndex has 3 entries for 13 in coordIndex"),
        ("", r"colour index 3 is outside its 3 colours"),  # per vertex through coordIndex
    ],
)
def test_colour_indices_that_do_not_fit_are_a_warning_and_the_material_is_used(rest, message):
    with pytest.warns(InputWarning, match=message):
        r, _ = _face_greys("0 0 0, 1 1 1, 0.5 0.5 0.5", rest)
    np.testing.assert_allclose(r, 0.8)


@pytest.mark.parametrize("per_vertex", [True, False])
def test_elevation_grid_colours_per_point_or_per_cell(per_vertex):
    """A 3 x 2 grid (x fastest): per point each triangle its corners' mean, per cell its cell's."""
    greys = [0.0, 0.2, 0.4, 0.6, 0.8, 1.0] if per_vertex else [0.25, 0.75]
    colours = ", ".join(f"{g:g} {g:g} {g:g}" for g in greys)
    grid = (
        f"ElevationGrid {{ xDimension 3 zDimension 2 height [0 0 0 0 0 0] "
        f"colorPerVertex {'TRUE' if per_vertex else 'FALSE'} color Color {{ color [{colours}] }} }}"
    )
    (part,) = parse(shape(grid, MATERIAL))
    tri = part.vertices[part.faces]
    if per_vertex:  # point (i, j) at x = i, z = j has grey 0.2 (i + 3 j)
        expected = (0.2 * (tri[:, :, 0] + 3 * tri[:, :, 2])).mean(axis=1)
    else:
        expected = np.where(tri[:, :, 0].mean(axis=1) < 1.0, 0.25, 0.75)
    np.testing.assert_allclose(part.reflectivity, expected, atol=1e-9)
    with pytest.warns(InputWarning, match="ElevationGrid has 1 colours"):
        (plain,) = parse(shape(grid.replace(colours, "0.3 0.3 0.3"), MATERIAL))
    np.testing.assert_allclose(plain.reflectivity, 0.8)
