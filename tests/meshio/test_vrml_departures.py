"""VRML departures from the specification that real model collections contain.

Each case copies the departure as found (see docs/notes/2026-11-24-bare-models.md for the survey
of 473 files from choreonoid, OpenHRP3, rtmros_choreonoid and rtmros_nextage): the file loads
to the same meshes as its corrected text, with one VrmlDepartureWarning per kind that names the
departure and its first line.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from sonar_raster.cli.app import main
from sonar_raster.errors import InputWarning, SonarRasterError
from sonar_raster.meshio.vrml import DEPARTURES, VrmlDepartureWarning, load_vrml, parse_vrml

HEADER = "#VRML V2.0 utf8\n"
#: As choreonoid's share/model/PA10/parts/*.wrl: no header, tabs, a Transform at the top.
PA10_LIKE = """Transform {
  children [
    Shape {
      appearance\tAppearance {
\tmaterial\tMaterial {
\t  diffuseColor\t0.85 0.9 0.85
\t}
      }
      geometry IndexedFaceSet {
        coord Coordinate { point [ 0 0 0, 1 0 0, 1 1 0, 0 1 0 ] }
        coordIndex [ 0 1 2 -1 0 2 3 -1 ]
      }
    }
  ]
}
"""


def parsed(text: str) -> tuple[list, list[str]]:
    """Parts of ``text`` and the messages of the departure warnings it raised."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        parts = parse_vrml(text)
    assert all(issubclass(w.category, VrmlDepartureWarning) for w in caught)
    return parts, [str(w.message) for w in caught]


def same_meshes(a: list, b: list) -> None:
    assert len(a) == len(b) and len(a) > 0
    for p, q in zip(a, b, strict=True):
        np.testing.assert_array_equal(p.vertices, q.vertices)
        np.testing.assert_array_equal(p.faces, q.faces)
        assert p.reflectivity == q.reflectivity


def test_missing_header_reads_as_vrml97_with_one_warning():
    parts, messages = parsed(PA10_LIKE)
    same_meshes(parts, parse_vrml(HEADER + PA10_LIKE))
    assert messages == [f"<string>:1: departs from VRML97: {DEPARTURES['no-header']}"]


def test_header_after_a_comment_line():
    # As OpenHRP3's sample/model/RH2/parts/arm/camera.wrl: a comment line before the header.
    text = "### [parts] ##########\n" + HEADER + PA10_LIKE
    parts, messages = parsed(text)
    same_meshes(parts, parse_vrml(HEADER + PA10_LIKE))
    assert messages == [f"<string>:1: departs from VRML97: {DEPARTURES['late-header']}"]


def test_text_that_is_not_vrml_still_fails_in_one_line():
    with pytest.raises(SonarRasterError, match=r"not a VRML97 file \(no '#VRML V2\.0 utf8'"):
        parse_vrml("solid cube\nfacet normal 0 0 1\n")
    with pytest.raises(SonarRasterError, match="VRML 1.0 is not supported"):
        parse_vrml("#VRML V1.0 ascii\nSeparator { }")


def test_def_without_a_name_reads_as_an_unnamed_node():
    # As choreonoid's share/model/Tank/resource/tank.wrl line 5: "DEF Transform {".
    body = "DEF Scene Group {\n children [\n DEF Transform {\n translation 0 0 0.025\n"
    body += " children [ Shape { geometry Box { size 1 2 3 } } ] } ] }\n"
    parts, messages = parsed(HEADER + body)
    fixed = parse_vrml(HEADER + body.replace("DEF Transform {", "Transform {"))
    same_meshes(parts, fixed)
    assert parts[0].name == fixed[0].name == "Scene"
    assert messages == [f"<string>:4: departs from VRML97: {DEPARTURES['def-no-name']}"]


def test_nan_normals_are_ignored_and_nan_points_drop_their_faces():
    # As OpenHRP3's sample/model/sample3dof.wrl line 1019: "normal Normal { vector [ -nan ...".
    ifs = (
        "Shape {{ geometry IndexedFaceSet {{ coord Coordinate {{ point [ {points} ] }}\n"
        "coordIndex [ 0 1 2 -1 0 2 3 -1 ]\n"
        "normal Normal {{ vector [ -nan -nan -nan, nan NaN -nan ] }} }} }}\n"
    )
    points = "0 0 0, 1 0 0, 1 1 0, 0 1 0"
    parts, messages = parsed(HEADER + ifs.format(points=points))
    clean = parse_vrml(
        HEADER + ifs.format(points=points).replace("-nan -nan -nan, nan NaN -nan", "")
    )
    same_meshes(parts, clean)
    assert messages == [f"<string>:4: departs from VRML97: {DEPARTURES['nan']} (6 places)"]
    # A NaN corner: the face using it is dropped, the other kept.
    parts, messages = parsed(HEADER + ifs.format(points="0 0 0, 1 0 0, 1 1 0, 0 nan 0"))
    np.testing.assert_array_equal(parts[0].faces, [[0, 1, 2]])
    assert len(messages) == 1 and "(7 places)" in messages[0]


def test_infinite_numbers_are_still_errors():
    with pytest.raises(SonarRasterError, match="not a finite float64"):
        parse_vrml(HEADER + "Shape { geometry Box { size 1e999 1 1 } }")


def test_departures_are_warned_once_per_file_and_kind(tmp_path):
    (tmp_path / "part.wrl").write_text(PA10_LIKE + "DEF Transform { children [] }\n")
    main_file = tmp_path / "main.wrl"
    main_file.write_text(HEADER + 'Inline { url "part.wrl" }\nInline { url "part.wrl" }\n')
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        parts = load_vrml(main_file)
    assert len(parts) == 2  # the part twice
    messages = [str(w.message) for w in caught]  # in the order of their lines
    assert messages == [
        f"part.wrl:1: departs from VRML97: {DEPARTURES['no-header']}",
        f"part.wrl:16: departs from VRML97: {DEPARTURES['def-no-name']}",
    ]
    assert issubclass(VrmlDepartureWarning, InputWarning)


def test_cli_prints_a_departure_as_a_warning_line_and_renders(tmp_path, capsys):
    model = tmp_path / "pa10_base.wrl"
    model.write_text(PA10_LIKE)
    out = tmp_path / "o.exr"
    assert main(["render", str(model), "-o", str(out), "--pings", "4", "--up", "z", "-q"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f"sonar-raster: warning: pa10_base.wrl:1: departs from VRML97: {DEPARTURES['no-header']}"
    ]
    assert out.is_file()


def test_a_primitive_size_not_above_zero_leaves_its_shape_out_with_one_warning():
    sizes = ["Box { size -2 1 1 }", "Sphere { radius 0 }", "Cylinder { height -1 }"]
    text = HEADER + "".join(f"Shape {{ geometry {g} }}\n" for g in [*sizes, "Cone { }"])
    parts, seen = parsed(text)
    assert len(parts) == 1 and len(parts[0].faces) > 0  # the cone alone, not inside out
    assert [s for s in seen if "not > 0" in s] == [
        f"<string>:2: departs from VRML97: {DEPARTURES['size']}"
    ]
