"""Model loading: format dispatch, scene-graph transforms, reflectivity sources, errors."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from conftest import SHARED_DATA

from sonar_raster.errors import SonarRasterError
from sonar_raster.meshio.load import load_model

trimesh = pytest.importorskip("trimesh")
T = trimesh.transformations

DATA = SHARED_DATA / "vrml"


def box(extents=(1.0, 2.0, 3.0), colour=None):
    mesh = trimesh.creation.box(extents)
    if colour is not None:
        material = trimesh.visual.material.PBRMaterial(baseColorFactor=colour)
        mesh.visual = trimesh.visual.TextureVisuals(material=material)
    return mesh


def moved_scene(colour=None, metadata=None) -> trimesh.Scene:
    """Box 1 x 2 x 3 m turned 90 degrees about z, then moved to (10, 0, 0)."""
    matrix = T.translation_matrix([10, 0, 0]) @ T.rotation_matrix(np.pi / 2, [0, 0, 1])
    scene = trimesh.Scene()
    scene.add_geometry(
        box(colour=colour),
        node_name="hull",
        geom_name="hull_mesh",
        transform=matrix,
        metadata=metadata,
    )
    return scene


def bounds(part) -> np.ndarray:
    return np.stack([part.vertices.min(axis=0), part.vertices.max(axis=0)])


def assert_outward(part, centre) -> None:
    tri = part.vertices[part.faces]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert np.all(np.einsum("ij,ij->i", normals, tri.mean(axis=1) - centre) > 0)


MOVED_BOUNDS = [[9, -0.5, -1.5], [11, 0.5, 1.5]]


@pytest.mark.parametrize("suffix", [".glb", ".gltf", ".obj", ".ply", ".stl", ".off"])
def test_world_bounds_follow_the_node_transform(tmp_path, suffix):
    path = tmp_path / f"model{suffix}"
    scene = moved_scene()
    (scene.to_mesh() if suffix == ".off" else scene).export(path)  # OFF holds one mesh
    parts = load_model(path)
    assert sum(len(p.faces) for p in parts) == 12
    vertices = np.concatenate([p.vertices for p in parts])
    np.testing.assert_allclose(
        [vertices.min(axis=0), vertices.max(axis=0)], MOVED_BOUNDS, atol=1e-6
    )
    assert all(p.vertices.dtype == np.float64 and p.faces.dtype == np.int64 for p in parts)
    assert_outward(parts[0], [10, 0, 0])


def test_gltf_nodes_keep_names_and_compose_parent_transforms(tmp_path):
    scene = trimesh.Scene()
    scene.add_geometry(
        box((1, 1, 1)),
        node_name="base",
        geom_name="cube",
        transform=T.translation_matrix([0, 0, 5]),
    )
    scene.add_geometry(
        box((1, 1, 1)),
        node_name="arm",
        geom_name="cube2",
        parent_node_name="base",
        transform=T.scale_matrix(2),
    )
    scene.add_geometry(trimesh.PointCloud(np.zeros((3, 3))), node_name="dots")
    path = tmp_path / "robot.glb"
    scene.export(path)
    parts = {p.name: p for p in load_model(path)}
    assert sorted(parts) == ["arm", "base"]
    np.testing.assert_allclose(bounds(parts["base"]), [[-0.5, -0.5, 4.5], [0.5, 0.5, 5.5]])
    np.testing.assert_allclose(bounds(parts["arm"]), [[-1, -1, 4], [1, 1, 6]])


def test_mirroring_node_keeps_faces_outward(tmp_path):
    scene = trimesh.Scene()
    scene.add_geometry(box(), node_name="m", transform=np.diag([-1.0, 1.0, 1.0, 1.0]))
    path = tmp_path / "mirror.glb"
    scene.export(path)
    (part,) = load_model(path)
    assert_outward(part, [0, 0, 0])


def test_gltf_material_base_colour_sets_reflectivity(tmp_path):
    path = tmp_path / "painted.glb"
    moved_scene(colour=[0.2, 0.4, 0.6, 1.0]).export(path)
    (part,) = load_model(path)
    assert part.reflectivity == pytest.approx(0.4, abs=1e-3)
    path = tmp_path / "plain.glb"
    moved_scene().export(path)
    assert load_model(path)[0].reflectivity == 0.5


def test_extras_reflectivity_wins_node_before_mesh(tmp_path):
    path = tmp_path / "tagged.gltf"
    moved_scene(colour=[1.0, 1.0, 1.0, 1.0]).export(path)
    assert load_model(path)[0].reflectivity == pytest.approx(1.0)
    document = json.loads(path.read_text())
    document["meshes"][0]["extras"] = {"reflectivity": 0.3}
    path.write_text(json.dumps(document))
    assert load_model(path)[0].reflectivity == pytest.approx(0.3)
    document["nodes"][0]["extras"] = {"reflectivity": 0.9}
    path.write_text(json.dumps(document))
    assert load_model(path)[0].reflectivity == pytest.approx(0.9)
    document["nodes"][0]["extras"] = {"reflectivity": "shiny"}
    path.write_text(json.dumps(document))
    with pytest.raises(
        SonarRasterError, match=r"'tagged\.gltf' node 'hull' has extras reflectivity"
    ):
        load_model(path)


def test_vrml_goes_through_the_vrml_reader(tmp_path):
    path = tmp_path / "cube.WRL"
    path.write_text("#VRML V2.0 utf8\nDEF cube Shape { geometry Box { size 1 1 1 } }")
    (part,) = load_model(path)
    assert part.name == "cube" and len(part.faces) == 12
    tire = DATA / "tire.wrl"
    if tire.is_file():
        assert len(load_model(tire)[0].faces) == 212


@pytest.mark.parametrize(
    ("name", "content", "message"),
    [
        ("model.xyz", b"1 2 3", r"'model\.xyz' is not a known model format; use one of \.wrl"),
        ("bad.glb", b"garbage", r"cannot read 'bad\.glb' as GLB \(ValueError: "),
        (
            "bad.gltf",
            b'{"asset": {"version": "2.0"}, "nodes": {"a": 1}}',
            r"cannot read 'bad\.gltf'",
        ),
        ("bad.ply", b"ply\nformat ascii 1.0\nelement vertex 3\n", r"cannot read 'bad\.ply' as PLY"),
        ("binary.stl", bytes(range(256)) * 3, r"'binary\.stl'"),
        ("empty.obj", b"# nothing here\n", r"'empty\.obj' holds no triangles"),
        (
            "points.ply",
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"
            b"property float y\nproperty float z\nend_header\n0 0 0\n",
            r"'points\.ply' holds no",
        ),
        ("broken.wrl", b"#VRML V2.0 utf8\nGroup {\n", r"broken\.wrl:2: expected a field name"),
        ("empty.gltf", b"", r"cannot read 'empty\.gltf' as GLTF: not JSON \(line 1"),
        (
            "glb.gltf",
            b"glTF\x02\x00\x00\x00\xff\xfe",
            r"'glb\.gltf' is not a \.gltf file: its content is binary glTF; rename it to end in "
            r"\.glb",
        ),
        (
            "old.gltf",  # trimesh raises NotImplementedError
            b'{"asset": {"version": "1.0"}, "scenes": {}}',
            r"cannot read 'old\.gltf' as GLTF \(NotImplementedError: only GLTF 2",
        ),
        (
            "flat.stl",  # every triangle of zero area
            b"solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n"
            b"vertex 2 0 0\nendloop\nendfacet\nendsolid s\n",
            r"'flat\.stl' holds only triangles of zero area",
        ),
        (
            "nothing.wrl",
            b"#VRML V2.0 utf8\nTransform { scale 0 0 0 children Shape { geometry Box {} } }\n",
            r"'nothing\.wrl' holds only triangles of zero area",
        ),
    ],
)
def test_bad_files_raise_one_line_errors(tmp_path, name, content, message):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(SonarRasterError, match=message) as info:
        load_model(path)
    assert "\n" not in str(info.value)


def test_missing_file_and_folder_raise(tmp_path):
    with pytest.raises(SonarRasterError, match=r"model file '.*ghost\.glb' not found"):
        load_model(tmp_path / "ghost.glb")
    (tmp_path / "dir.obj").mkdir()
    with pytest.raises(SonarRasterError, match=r"is a folder, not a file"):
        load_model(tmp_path / "dir.obj")


def test_importing_meshio_does_not_import_trimesh():
    code = "import sys, sonar_raster.meshio.load; print('trimesh' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


@pytest.mark.parametrize("suffix", [".glb", ".obj"])
def test_colour_texture_gives_per_face_reflectivity(tmp_path, suffix):
    """A 2 x 1 texture, black | white: each triangle's UVs sit in one texel."""
    import trimesh
    from PIL import Image

    image = Image.fromarray(np.array([[[0, 0, 0], [255, 255, 255]]], dtype=np.uint8))
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]])
    f = np.array([[0, 1, 3], [1, 2, 3]])
    uv = np.array([[0.05, 0.5], [0.45, 0.5], [0.95, 0.5], [0.2, 0.5]])
    # Face 0 (uv x 0.05..0.45): black; face 1 (x 0.45, 0.95, 0.2): two samples on each texel.
    material = trimesh.visual.material.PBRMaterial(
        baseColorTexture=image, baseColorFactor=[128, 128, 128, 255]
    )
    mesh = trimesh.Trimesh(
        v, f, visual=trimesh.visual.TextureVisuals(uv=uv, material=material), process=False
    )
    path = tmp_path / f"textured{suffix}"
    mesh.export(path)
    (part,) = load_model(path)
    r = np.broadcast_to(part.reflectivity, (2,))
    factor = 128 / 255  # glTF's base colour factor; the OBJ's Kd, which trimesh writes from it
    samples = np.array(
        [[1 / 3] * 3, [2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]]
    )
    expected = [factor * np.mean((samples @ uv[face, 0]) >= 0.5) for face in f]
    np.testing.assert_allclose(r, expected, atol=0.02)
    assert r[0] == pytest.approx(0.0, abs=0.02) and r[1] > 0.3 * factor


@pytest.mark.parametrize("suffix", [".ply", ".glb", ".obj"])
def test_vertex_colours_give_per_face_reflectivity(tmp_path, suffix):
    """A scanned model's vertex colours (PLY, glTF COLOR_0, OBJ ``v x y z r g b``): each face
    the grey of its corners' mean colour."""
    mesh = box()
    grey = np.linspace(0, 255, len(mesh.vertices)).round()
    rgb = np.stack([grey, 255 - grey, grey], axis=1)  # RGB mean (255 + grey) / 3
    colours = np.c_[rgb, np.full(8, 255)].astype(np.uint8)
    mesh.visual = trimesh.visual.ColorVisuals(mesh, vertex_colors=colours)
    path = tmp_path / f"scanned{suffix}"
    if suffix == ".obj":
        path.write_text(trimesh.exchange.obj.export_obj(mesh, include_color=True))
    else:
        mesh.export(path)
    (part,) = load_model(path)
    grey_of = rgb.mean(axis=1) / 255
    by_vertex = {tuple(v): r for v, r in zip(mesh.vertices.round(6), grey_of, strict=True)}
    expected = [np.mean([by_vertex[tuple(v)] for v in tri]) for tri in part.vertices[part.faces]]
    np.testing.assert_allclose(np.broadcast_to(part.reflectivity, (12,)), expected, atol=1e-6)


def test_ply_face_colours_give_per_face_reflectivity(tmp_path):
    mesh = box()
    grey = np.arange(12) * 20
    mesh.visual = trimesh.visual.ColorVisuals(
        mesh, face_colors=np.c_[grey, grey, grey, np.full(12, 255)].astype(np.uint8)
    )
    path = tmp_path / "faces.ply"
    mesh.export(path)
    (part,) = load_model(path)
    np.testing.assert_allclose(part.reflectivity, grey / 255, atol=1e-6)


def test_ply_colours_per_polygon_are_left_out_with_a_warning(tmp_path, caplog):
    """trimesh cuts a quad into two triangles but keeps one colour per quad: not matched."""
    path = tmp_path / "quad.ply"
    path.write_text(
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n"
        "0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3 10 10 10\n"
    )
    with caplog.at_level("WARNING"):
        (part,) = load_model(path)
    assert len(part.faces) == 2 and np.all(part.reflectivity == 0.5)
    assert "1 face colours for 2 triangles" in caplog.text


def test_obj_material_colour_sets_reflectivity(tmp_path):
    """An OBJ material's Kd sets the reflectivity (RGB mean) as glTF's base colour does; a
    material without Kd, and a missing .mtl, leave the default."""
    (tmp_path / "m.mtl").write_text("newmtl red\nKd 0.8 0.2 0.2\nnewmtl plain\nNs 10\n")
    quad = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 4\nf 2 3 4\n"
    for material, expected in (("red", 0.4), ("plain", 0.5)):
        path = tmp_path / f"{material}.obj"
        path.write_text(f"mtllib m.mtl\nusemtl {material}\n{quad}")
        (part,) = load_model(path)
        np.testing.assert_allclose(part.reflectivity, expected)
    path = tmp_path / "nomtl.obj"
    path.write_text(f"mtllib missing.mtl\nusemtl x\n{quad}")
    np.testing.assert_allclose(load_model(path)[0].reflectivity, 0.5)


def test_obj_with_texture_coordinates_but_no_material_takes_the_default(tmp_path):
    """trimesh gives such a file a grey placeholder texture (0.39); it is not the model's."""
    path = tmp_path / "uv_only.obj"
    path.write_text(
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
        "f 1/1 2/2 4/4\nf 2/2 3/3 4/4\n"
    )
    (part,) = load_model(path)
    np.testing.assert_array_equal(part.reflectivity, 0.5)


def test_a_gltf_whose_buffer_is_short_is_one_line(tmp_path):
    files = trimesh.exchange.gltf.export_gltf(trimesh.Scene(box()))  # the JSON and its .bins
    for name, data in files.items():
        (tmp_path / ("box.gltf" if name.endswith(".gltf") else name)).write_bytes(data)
    first = sorted(n for n in files if n.endswith(".bin"))[0]
    (tmp_path / first).write_bytes(files[first][:100])  # shorter than the JSON says: an assert
    with pytest.raises(SonarRasterError, match=r"cannot read 'box\.gltf' as GLTF") as info:
        load_model(tmp_path / "box.gltf")
    assert "\n" not in str(info.value)


def _gltf_with_buffers(folder, names):
    """A box as ``box.gltf`` whose buffers are the files ``names``, each referred to by its
    URI (percent-encoded, as the glTF format has it)."""
    from urllib.parse import quote

    files = trimesh.exchange.gltf.export_gltf(trimesh.Scene(box()))
    doc = json.loads(files["model.gltf"])
    for buffer, name in zip(doc["buffers"], names, strict=True):
        (folder / name).write_bytes(files[buffer["uri"]])
        buffer["uri"] = quote(name)
    (folder / "box.gltf").write_text(json.dumps(doc))
    return folder / "box.gltf"


def test_a_gltf_finds_buffers_named_with_spaces_and_reserved_characters(tmp_path):
    """glTF refers to its files by URI: ``my%20hull.bin`` is the file ``my hull.bin``
    (trimesh looked for the encoded name and failed)."""
    path = _gltf_with_buffers(tmp_path, ["my hull.bin", "hull #2 [100%].bin"])
    assert "%20" in path.read_text() and "%25" in path.read_text()
    (part,) = load_model(path)
    assert len(part.faces) == 12
    np.testing.assert_allclose(bounds(part), [[-0.5, -1.0, -1.5], [0.5, 1.0, 1.5]])


def test_a_gltf_whose_buffer_file_is_missing_names_it(tmp_path):
    path = _gltf_with_buffers(tmp_path, ["hull mesh.bin", "hull more.bin"])
    (tmp_path / "hull more.bin").unlink()
    with pytest.raises(SonarRasterError, match=r"'box\.gltf' refers to 'hull more\.bin', which"):
        load_model(path)


def test_a_draco_compressed_glb_loads(tmp_path):
    """Draco (KHR_draco_mesh_compression) is common in downloaded glTF; without its decoder
    trimesh filled the positions with zeros and the model was 'only triangles of zero area'."""
    path = tmp_path / "draco.glb"
    path.write_bytes(trimesh.exchange.gltf.export_glb(moved_scene(), extension_draco=True))
    (part,) = load_model(path)
    assert len(part.faces) == 12
    np.testing.assert_allclose(bounds(part), MOVED_BOUNDS, atol=1e-3)  # Draco quantises


@pytest.mark.parametrize("suffix", [".gltf", ".glb"])
def test_a_gltf_compressed_in_a_way_the_reader_cannot_decode_is_one_line(tmp_path, suffix):
    scene = moved_scene()
    if suffix == ".glb":
        data = trimesh.exchange.gltf.export_glb(scene)
        size = int.from_bytes(data[12:16], "little")
        doc = json.loads(data[20 : 20 + size])
        doc["extensionsRequired"] = ["EXT_meshopt_compression"]
        chunk = json.dumps(doc).encode().ljust(size + 64, b" ")
        body = len(chunk).to_bytes(4, "little") + b"JSON" + chunk + data[20 + size :]
        data = data[:8] + (12 + len(body)).to_bytes(4, "little") + body
        (tmp_path / "packed.glb").write_bytes(data)
    else:
        files = trimesh.exchange.gltf.export_gltf(scene)
        doc = json.loads(files["model.gltf"])
        doc["extensionsRequired"] = ["EXT_meshopt_compression"]
        for name, blob in files.items():
            if name != "model.gltf":
                (tmp_path / name).write_bytes(blob)
        (tmp_path / "packed.gltf").write_text(json.dumps(doc))
    with pytest.raises(SonarRasterError, match=r"'packed\.gl\w+' is compressed with the glTF "):
        load_model(tmp_path / f"packed{suffix}")


@pytest.mark.parametrize("suffix", [".glb", ".obj", ".ply", ".stl"])
@pytest.mark.parametrize("value", [np.inf, np.nan])
def test_a_non_finite_vertex_is_one_line_naming_the_file(tmp_path, suffix, value):
    """In every format, not only where trimesh keeps it: OBJ, PLY and STL lost such a vertex
    and its faces without a word."""
    mesh = box()
    mesh.vertices[0] = [value, 0.0, 0.0]
    path = tmp_path / f"bad{suffix}"
    with np.errstate(invalid="ignore"):  # STL's normals of the bad faces
        data = mesh.export(file_type=suffix[1:])
    path.write_bytes(data if isinstance(data, bytes) else data.encode())
    with pytest.raises(SonarRasterError, match=rf"'bad\{suffix}': node .* not finite"):
        load_model(path)


@pytest.mark.parametrize("name", ["box.wrz", "box.wrl.gz"])
def test_gzipped_vrml_is_a_model_file_for_scenes_too(tmp_path, name):
    import gzip

    from sonar_raster.scenes.description import load_scene

    path = tmp_path / name
    path.write_bytes(gzip.compress(b"#VRML V2.0 utf8\nShape { geometry Box { size 2 1 1 } }\n"))
    setup = load_scene(path)
    assert setup.notes["placement"]["size_m"] == pytest.approx([2.0, 1.0, 1.0])  # y-up: turned


def test_unread_vrml_geometry_is_a_warning_naming_it(tmp_path):
    from sonar_raster.errors import InputWarning

    path = tmp_path / "x.wrl"
    path.write_text(
        "#VRML V2.0 utf8\nShape { geometry Box {} }\n"
        'Shape { geometry Text { string "A" } }\n'
        'Shape { geometry Text { string "B" } }\n'
    )
    with pytest.warns(InputWarning, match=r"x\.wrl:3: Text geometry is not read") as seen:
        parts = load_model(path)
    assert len(parts) == 1 and len([w for w in seen if "Text" in str(w.message)]) == 1


def test_absurdly_large_coordinates_do_not_overflow_the_zero_area_check(tmp_path):
    path = tmp_path / "huge.wrl"  # found by tests/io/test_fuzz.py: an OverflowError in the check
    box = "Shape { geometry Box {} }"
    path.write_text(f"#VRML V2.0 utf8\nTransform {{ scale 1e200 1e200 1e200 children {box} }}\n")
    assert len(load_model(path)) == 1


#: A 2 x 1 x 0.8 m box as OBJ: eight corners, six quads wound outward.
BOX_OBJ_VERTICES = [f"v {x} {y} {z}" for x in (-1, 1) for y in (-0.5, 0.5) for z in (-0.4, 0.4)]
BOX_OBJ_FACES = ["f 1 2 4 3", "f 5 7 8 6", "f 1 5 6 2", "f 3 4 8 7", "f 1 3 7 5", "f 2 6 8 4"]
BOX_OBJ = "\n".join(BOX_OBJ_VERTICES + BOX_OBJ_FACES) + "\n"


@pytest.mark.parametrize(
    ("form", "text"),
    [
        ("byte-order mark", "\ufeff" + BOX_OBJ),
        ("tabs", BOX_OBJ.replace(" ", "\t")),
        ("indented", "".join(f"  {line}\n" for line in BOX_OBJ.splitlines())),
        ("comment after a statement", BOX_OBJ.replace("\n", "  # note\n")),
        ("old Mac line ends", BOX_OBJ.replace("\n", "\r")),
        ("Latin-1 group name", "g caf\xe9\n" + BOX_OBJ),
    ],
)
def test_obj_text_as_exporters_write_it_keeps_every_statement(tmp_path, form, text):
    path = tmp_path / "box.obj"
    path.write_bytes(text.encode("latin-1" if "Latin" in form else "utf-8"))
    (part,) = load_model(path)
    assert len(part.faces) == 12
    np.testing.assert_allclose(bounds(part), [[-1, -0.5, -0.4], [1, 0.5, 0.4]])


@pytest.mark.parametrize("suffix", [".stl", ".obj", ".wrl"])
def test_a_closed_surface_wound_inside_out_is_turned_outward(tmp_path, suffix):
    inside_out = box((2.0, 1.0, 0.8))
    inside_out.invert()
    path = tmp_path / f"inverted{suffix}"
    if suffix == ".wrl":
        points = ", ".join(" ".join(map(str, v)) for v in inside_out.vertices)
        index = " ".join(f"{a} {b} {c} -1" for a, b, c in inside_out.faces)
        path.write_text(
            "#VRML V2.0 utf8\nShape { geometry IndexedFaceSet { solid FALSE coord Coordinate "
            f"{{ point [ {points} ] }} coordIndex [ {index} ] }} }}\n"
        )
    else:
        inside_out.export(path)
    (part,) = load_model(path)
    assert_outward(part, np.zeros(3))


def test_an_open_surface_keeps_its_winding(tmp_path):
    half = box((2.0, 1.0, 0.8))
    half.update_faces(half.face_normals[:, 2] >= 0)  # the lid and the walls, no floor
    half.invert()
    path = tmp_path / "open.stl"
    half.export(path)
    (part,) = load_model(path)
    tri = part.vertices[part.faces]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert np.all(np.einsum("ij,ij->i", normals, tri.mean(axis=1)) < 0)  # as the file says


@pytest.mark.parametrize(
    ("name", "content", "looks"),
    [
        (
            "model.gltf",
            b"glTF\x02\x00\x00\x00",
            r"its content is binary glTF; rename it to end in \.glb",
        ),
        (
            "model.glb",
            b'{"asset": {"version": "2.0"}}',
            r"JSON \(glTF\); rename it to end in \.gltf",
        ),
        (
            "model.obj",
            b"solid part\n  facet normal 0 0 1\n",
            r"ASCII STL; rename it to end in \.stl",
        ),
        ("model.stl", BOX_OBJ.encode(), r"'model\.stl' is not a \.stl file: its content is OBJ"),
        ("model.obj", b"ply\nformat ascii 1.0\nend_header\n", r"PLY; rename it to end in \.ply"),
        ("model.obj", b"#VRML V2.0 utf8\nShape {}\n", r"VRML97; rename it to end in \.wrl"),
        ("model.ply", bytes(80) + (1).to_bytes(4, "little") + bytes(50), r"binary STL"),
    ],
)
def test_a_file_whose_content_is_another_format_says_which(tmp_path, name, content, looks):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(SonarRasterError, match=looks):
        load_model(path)


def _binary_stl(tmp_path, name: str, edit) -> SonarRasterError | list:
    """A binary STL of a box, its bytes changed by ``edit``, loaded (or the error raised)."""
    data = box().export(file_type="stl")
    path = tmp_path / name
    path.write_bytes(edit(data))
    try:
        return load_model(path)
    except SonarRasterError as exc:
        return exc


@pytest.mark.parametrize(
    ("name", "edit"),
    [
        ("padded.stl", lambda d: d + bytes(7)),  # bytes after the last triangle
        ("zero.stl", lambda d: d[:80] + bytes(4) + d[84:]),  # the count left 0
        ("over.stl", lambda d: d[:80] + (99).to_bytes(4, "little") + d[84:]),  # a count too large
        ("solid.stl", lambda d: b"solid by an exporter" + d[20:] + bytes(2)),  # 'solid' header
    ],
)
def test_a_binary_stl_whose_count_disagrees_with_its_size_reads_its_triangles(tmp_path, name, edit):
    (whole,) = _binary_stl(tmp_path, "whole.stl", lambda d: d)
    (part,) = _binary_stl(tmp_path, name, edit)
    np.testing.assert_array_equal(part.vertices[part.faces], whole.vertices[whole.faces])


def test_a_binary_stl_cut_inside_a_triangle_is_one_line(tmp_path):
    error = _binary_stl(tmp_path, "cut.stl", lambda d: d[:80] + bytes(4) + d[84:-20])
    assert isinstance(error, SonarRasterError)
    assert "cut.stl" in str(error) and "\n" not in str(error)
