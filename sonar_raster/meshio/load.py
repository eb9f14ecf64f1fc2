"""Model files to mesh parts: VRML97 with our own reader, other formats through trimesh.

Coordinates are returned as stored in the file (metres assumed), with every scene-graph
transform applied; no axis convention is changed (VRML and glTF are y-up by convention).
"""

from __future__ import annotations

import dataclasses
import io
import logging
import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import SonarRasterError
from ..scene import MeshPart, clean_faces, closed_volume
from .formats import MODEL_SUFFIXES, VRML_SUFFIXES, model_suffix
from .vrml import load_vrml

log = logging.getLogger(__name__)

#: glTF extensions that compress geometry which the reader cannot decode (Draco it decodes,
#: through DracoPy): a file that requires one would load as garbage.
UNDECODED_EXTENSIONS = ("EXT_meshopt_compression", "KHR_meshopt_compression")


_DEFAULT_REFLECTIVITY = 0.5


def load_model(path: str | Path) -> list[MeshPart]:
    """Read a model file as mesh parts in world coordinates.

    ``.wrl``/``.vrml`` (also gzipped) go through the VRML97 reader; ``.gltf .glb .obj .ply
    .stl .off`` through trimesh, one part per scene-graph node that holds triangles (point
    clouds and paths are skipped), named after the node, with its world transform applied.

    Parameters
    ----------
    path : str or Path
        The model file.

    Returns
    -------
    list of MeshPart
        Vertices (n, 3) float64 in metres, faces (m, 3) int64 counter-clockwise. Reflectivity
        is, in order: the node's glTF ``extras.reflectivity``, the mesh's
        ``extras.reflectivity``, the mean RGB of the glTF material ``baseColorFactor``, else
        0.5 (VRML: mean Material ``diffuseColor``).

    Raises
    ------
    SonarRasterError
        If the extension is unknown, the file is missing, unreadable or malformed, or it holds
        no triangles.
    """
    path = Path(path)
    name = path.name.lower()
    if not name.endswith(MODEL_SUFFIXES):
        raise SonarRasterError(
            f"'{path.name}' is not a known model format; use one of {' '.join(MODEL_SUFFIXES)}"
        )
    if not path.is_file():
        what = "is a folder, not a file" if path.is_dir() else "not found"
        raise SonarRasterError(f"model file '{path}' {what}; check the path")
    suffix = model_suffix(path) or ""
    try:
        parts = load_vrml(path) if name.endswith(VRML_SUFFIXES) else _load_trimesh(path)
        if not parts:
            raise SonarRasterError(
                f"model file '{path.name}' holds no triangles; export the model as a triangle mesh"
            )
    except SonarRasterError:
        looks = _content_format(path)
        if looks is not None and looks[1] != _SAME_FORMAT.get(suffix, suffix):
            raise SonarRasterError(
                f"'{path.name}' is not a {suffix} file: its content is {looks[0]}; rename it to "
                f"end in {looks[1]}"
            ) from None
        raise
    parts = [_outward(part) for part in parts]
    with np.errstate(all="ignore"):  # absurd coordinates overflow here; build_scene says so
        kept = any(clean_faces(p.vertices, p.faces).any() for p in parts)  # as build_scene drops
    if not kept:
        raise SonarRasterError(
            f"model file '{path.name}' holds only triangles of zero area (degenerate, or scaled "
            "to nothing); check the model"
        )
    return parts


def _outward(part: MeshPart) -> MeshPart:
    """``part`` with its faces reversed if it is a closed surface wound inside out.

    A closed body whose every face points in (a mirrored CAD export, an STL written clockwise)
    is turned outward, as :func:`~sonar_raster.scene.build_scene` would, so that the part a
    caller gets says which side is outside. Open surfaces keep the file's winding: nothing in
    them says which side is the outside (they scatter from both sides).
    """
    volume = closed_volume(part.vertices, part.faces)
    if volume is None or not volume < 0:
        return part
    return dataclasses.replace(part, faces=np.asarray(part.faces)[:, ::-1].copy())


#: An ASCII STL's first bytes.
_ASCII_STL = rb"(?:\xef\xbb\xbf)?\s*solid[^\n]*\n\s*(?:facet|endsolid)"
#: What a model file's first bytes are, tried in order: (pattern, what it is, its ending).
_SIGNATURES = (
    (rb"glTF", "binary glTF", ".glb"),
    (rb"\x1f\x8b", "gzip-compressed (gzipped VRML is named .wrl.gz)", ".wrl.gz"),
    (rb"(?:\xef\xbb\xbf)?\s*#VRML V2", "VRML97", ".wrl"),
    (rb"(?:\xef\xbb\xbf)?ply\s", "PLY", ".ply"),
    (rb"(?:\xef\xbb\xbf)?\s*[CN]?OFF\s", "OFF", ".off"),
    (_ASCII_STL, "ASCII STL", ".stl"),
    (rb"(?:\xef\xbb\xbf)?\s*\{", "JSON (glTF)", ".gltf"),
    (rb"(?:\xef\xbb\xbf)?(?:\s*(?:#[^\n]*)?\n)*\s*(?:v|vn|vt|o|g|mtllib)[ \t]", "OBJ", ".obj"),
)
#: Endings that name one format.
_SAME_FORMAT = {".vrml": ".wrl", ".wrz": ".wrl.gz"}


def _content_format(path: Path) -> tuple[str, str] | None:
    """What the file's bytes say it is, and that format's ending; None if they say nothing."""
    with open(path, "rb") as fh:
        head = fh.read(1024)
    for pattern, what, suffix in _SIGNATURES:
        if re.match(pattern, head):
            return what, suffix
    size = path.stat().st_size
    if size >= 84 and size == 84 + 50 * int.from_bytes(head[80:84], "little"):
        return "binary STL", ".stl"
    return None


def _load_trimesh(path: Path) -> list[MeshPart]:
    """One MeshPart per scene-graph node of a trimesh-readable file."""
    import trimesh  # slow to import: only when such a file is read

    kind = path.suffix.lstrip(".").upper()
    if kind == "GLTF":
        _check_extensions(_check_json(path), path)
    elif kind == "GLB":
        _check_extensions(_glb_json(path), path)
    try:
        # processed below (:func:`_finite`), which refuses non-finite vertices; trimesh's
        # arithmetic on them (STL normals) is not the user's concern
        with np.errstate(invalid="ignore", over="ignore"):
            text = _obj_text(path) if kind == "OBJ" else b""
            source: Any = io.BytesIO(text) if kind == "OBJ" else str(path)
            if kind == "STL":
                source = _binary_stl(path) or source
            scene = trimesh.load_scene(
                source, file_type=kind.lower(), process=False, resolver=_resolver(path)
            )
    except _MissingAsset as exc:
        raise SonarRasterError(
            f"'{path.name}' refers to '{exc.name}', which is not in {path.parent}; put it "
            "beside the model file, or export the model as one file (.glb)"
        ) from None
    except ImportError as exc:  # trimesh decodes non-UTF-8 text with an optional package
        raise SonarRasterError(
            f"cannot read '{path.name}' as {kind}: it is corrupt, or text that is not UTF-8; "
            "re-export it"
        ) from exc
    except Exception as exc:  # trimesh raises many kinds (also assertions) on malformed files
        detail = " ".join(str(exc).split())[:120] or "its parts do not fit together"
        raise SonarRasterError(
            f"cannot read '{path.name}' as {kind} ({type(exc).__name__}: {detail}); "
            "check the file or re-export it"
        ) from exc
    # an OBJ without materials gets a placeholder texture from trimesh where it has texture
    # coordinates (grey 0.39): not the model's, so the default reflectivity instead
    bare = kind == "OBJ" and re.search(rb"^(?:usemtl|mtllib) ", text, re.MULTILINE) is None
    parts = []
    for node in scene.graph.nodes_geometry:
        matrix, geometry_name = scene.graph[node]
        mesh = scene.geometry.get(geometry_name)
        if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
            log.debug("%s: skipping node %s without triangles", path.name, node)
            continue
        matrix = np.asarray(matrix, dtype=np.float64)
        mesh = _finite(mesh, path, str(node))
        vertices = np.asarray(mesh.vertices, dtype=np.float64)
        if not (np.all(np.isfinite(vertices)) and np.all(np.isfinite(matrix))):
            raise SonarRasterError(
                f"'{path.name}': node {node} has a transform that is not finite numbers (inf "
                "or NaN); fix the model file"
            )
        vertices = vertices @ matrix[:3, :3].T + matrix[:3, 3]
        faces = np.array(mesh.faces, dtype=np.int64)
        if np.linalg.det(matrix[:3, :3]) < 0:  # a mirroring transform turns faces inside out
            faces = faces[:, ::-1].copy()
        if bare:  # its vertex colours, if it has them ("v x y z r g b")
            colours = _colour_reflectivity(mesh, path)
            reflectivity = _DEFAULT_REFLECTIVITY if colours is None else colours
        else:
            reflectivity = _reflectivity(scene, node, mesh, path)
        parts.append(MeshPart(vertices, faces, reflectivity, str(node)))
    return parts


#: Bytes of a binary STL's header and triangle count, and of each triangle record.
_STL_HEAD, _STL_RECORD = 84, 50


def _binary_stl(path: Path) -> io.BytesIO | None:
    """A binary STL whose triangle count disagrees with its size, made whole; else None.

    Exporters pad the file after the last triangle, or leave the count 0; trimesh then reads
    it as ASCII and fails. Trailing bytes are left out; a count of 0 (or one larger than the
    file holds) is taken from the size when the records fill the file exactly.
    """
    size = path.stat().st_size
    with open(path, "rb") as fh:
        head = fh.read(1024)
    if size < _STL_HEAD + _STL_RECORD or re.match(_ASCII_STL, head):
        return None
    count = int.from_bytes(head[80:84], "little")
    body = size - _STL_HEAD
    if 0 < count and _STL_RECORD * count <= body:
        if _STL_RECORD * count == body:
            return None
        log.info(
            "%s: %d bytes after the last of its %d triangles left out",
            path.name,
            body - _STL_RECORD * count,
            count,
        )
    elif body % _STL_RECORD == 0:
        log.info(
            "%s: triangle count %d in its header, %d in the file: those read",
            path.name,
            count,
            body // _STL_RECORD,
        )
        count = body // _STL_RECORD
    else:
        return None
    data = bytearray(path.read_bytes()[: _STL_HEAD + _STL_RECORD * count])
    data[80:84] = count.to_bytes(4, "little")
    return io.BytesIO(bytes(data))


def _obj_text(path: Path) -> bytes:
    """The OBJ file's statements one to a line, single-spaced, without comments.

    trimesh finds OBJ statements by a line break and their keyword (``v``, ``f``...), so it
    loses those after a byte-order mark, a tab, an indent or a lone CR line end, and fails on a
    comment after a statement; all are valid OBJ that exporters write. Text that is not UTF-8
    (Latin-1 names) is read
    with its odd characters replaced.
    """
    text = path.read_bytes().decode("utf-8-sig", errors="replace")
    text = re.sub(r"#[^\r\n]*", "", text)  # comments run to the end of the line
    text = re.sub(r"[ \t\f\v]+", " ", re.sub(r"\r\n?", "\n", text))
    return re.sub(r"^ | $", "", text, flags=re.MULTILINE).encode("utf-8")


class _MissingAsset(FileNotFoundError):
    """A file the model refers to (a glTF buffer or image, an OBJ material) is not there."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.name = name


def _resolver(path: Path) -> Any:
    """The reader trimesh gets for the files a model refers to, in the model's folder.

    glTF refers to them by URI, so a name with a space or other reserved character is
    percent-encoded (``my%20hull.bin`` for ``my hull.bin``): a name not found as written is
    looked up decoded. A name found neither way raises :class:`_MissingAsset`.
    """
    from urllib.parse import unquote

    from trimesh.resolvers import FilePathResolver

    class Decoding(FilePathResolver):
        def get(self, name: str) -> bytes:
            for candidate in dict.fromkeys((name, unquote(name))):
                try:
                    return super().get(candidate)
                except FileNotFoundError:
                    continue
            raise _MissingAsset(unquote(name))

    return Decoding(str(path))


def _finite(mesh: Any, path: Path, node: str) -> Any:
    """``mesh`` processed as trimesh loads it by default (vertices merged).

    A vertex that is not a finite number is a one-line error: trimesh would drop its faces
    without a word.
    """
    bad = ~np.all(np.isfinite(mesh.vertices), axis=1)
    if bad.any():
        used = int(np.any(bad[mesh.faces], axis=1).sum())
        raise SonarRasterError(
            f"'{path.name}': node {node} has {int(bad.sum())} vertices that are not finite "
            f"numbers (inf or NaN), used by {used} faces; fix the model file"
        )
    mesh.process()
    return mesh


def _check_extensions(doc: Any, path: Path) -> None:
    """A one-line error if the glTF document requires an extension the reader cannot decode."""
    required = doc.get("extensionsRequired", []) if isinstance(doc, dict) else []
    missing = [e for e in required if e in UNDECODED_EXTENSIONS]
    if missing:
        raise SonarRasterError(
            f"'{path.name}' is compressed with the glTF extension {missing[0]}, which the reader "
            "cannot decode; re-export it without that compression (e.g. gltf-transform copy)"
        )


def _glb_json(path: Path) -> Any:
    """The JSON chunk of a ``.glb`` file, or None where it is not one (trimesh says why)."""
    import json
    import struct

    with open(path, "rb") as fh:
        head = fh.read(20)
        if len(head) < 20 or head[:4] != b"glTF" or head[16:20] != b"JSON":
            return None
        size = struct.unpack("<I", head[12:16])[0]
        try:
            return json.loads(fh.read(size))
        except ValueError:
            return None


def _check_json(path: Path) -> Any:
    """The ``.gltf`` file's JSON; a one-line error if it is none (trimesh blames a file)."""
    import json

    try:
        with open(path, encoding="utf-8") as fh:
            return json.load(fh)
    except UnicodeDecodeError:
        raise SonarRasterError(
            f"cannot read '{path.name}' as GLTF: it is not UTF-8 JSON (a binary glTF is named "
            ".glb); check the file or re-export it"
        ) from None
    except json.JSONDecodeError as exc:
        raise SonarRasterError(
            f"cannot read '{path.name}' as GLTF: not JSON (line {exc.lineno}: {exc.msg}); "
            "check the file or re-export it"
        ) from None


def _reflectivity(scene: Any, node: str, mesh: Any, path: Path) -> float | np.ndarray:
    """Node extras, mesh extras, then texture x colour factor, colour factor, else 0.5.

    A face or vertex colour (PLY, OBJ, glTF ``COLOR_0``) stands in for a texture. The colour
    factor is glTF's ``baseColorFactor`` or an OBJ material's ``Kd`` (RGB mean).
    """
    transforms = scene.graph.transforms
    parent = transforms.parents.get(node)
    node_extras = transforms.edge_data.get((parent, node), {}).get("metadata") or {}
    for extras in (node_extras, mesh.metadata or {}):
        if "reflectivity" in extras:
            return _checked(extras["reflectivity"], node, path)
    material = getattr(mesh.visual, "material", None)
    colour = getattr(material, "baseColorFactor", None)
    if colour is None:  # an OBJ's material: its Kd where the .mtl gives one (trimesh keeps it)
        colour = (getattr(material, "kwargs", None) or {}).get("kd")
    factor = 1.0
    if colour is not None:
        colour = np.asarray(colour)
        scale = 255.0 if np.issubdtype(colour.dtype, np.integer) else 1.0
        factor = float(colour[:3].mean()) / scale
    texture = _texture_reflectivity(mesh)
    if texture is None:
        texture = _colour_reflectivity(mesh, path)
    if texture is not None:
        return factor * texture
    return factor if colour is not None else _DEFAULT_REFLECTIVITY


def _colour_reflectivity(mesh: Any, path: Path) -> np.ndarray | None:
    """Per-face reflectivity from face or vertex colours (PLY, OBJ, glTF ``COLOR_0``).

    The grey of the face's colour (RGB mean / 255), or the mean of its corners'; None when the
    file gives no colours, or colours per polygon that trimesh left unmatched to the triangles
    it cut the polygons into (a warning).
    """
    visual = mesh.visual
    kind = getattr(visual, "kind", None)
    if kind == "face":
        rgb = np.asarray(visual.face_colors, dtype=np.float64)[:, :3]
        if len(rgb) != len(mesh.faces):
            log.warning(
                "%s: %d face colours for %d triangles (polygons cut into triangles): colours "
                "not used; export triangles to keep them",
                path.name, len(rgb), len(mesh.faces),
            )  # fmt: skip
            return None
    elif kind == "vertex":
        corners = np.asarray(visual.vertex_colors, dtype=np.float64)[np.asarray(mesh.faces)]
        rgb = corners[:, :, :3].mean(axis=1)
    else:
        return None
    return rgb.mean(axis=1) / 255.0


#: Barycentric points at which a face samples its texture (centroid and towards each corner).
_TEXTURE_SAMPLES = np.array(
    [[1 / 3, 1 / 3, 1 / 3], [2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]]
)


def _texture_reflectivity(mesh: Any) -> np.ndarray | None:
    """Per-face reflectivity from a colour texture: mean grey (RGB mean / 255) at 4 points.

    The renderer takes one reflectivity per face, so a texture varies R across a surface at
    the mesh's resolution (subdivide coarse meshes to see finer texture detail). None when the
    mesh has no UVs or no image.
    """
    from trimesh.visual.color import uv_to_color

    visual = mesh.visual
    uv = getattr(visual, "uv", None)
    material = getattr(visual, "material", None)
    image = getattr(material, "baseColorTexture", None) or getattr(material, "image", None)
    if uv is None or image is None or len(uv) != len(mesh.vertices):
        return None
    corners = np.asarray(uv, dtype=np.float64)[np.asarray(mesh.faces)]
    grey = [
        uv_to_color(np.einsum("k,mkj->mj", w, corners), image)[:, :3].mean(axis=1) / 255.0
        for w in _TEXTURE_SAMPLES
    ]
    return np.mean(grey, axis=0)


def _checked(value: Any, node: str, path: Path) -> float:
    """Return a reflectivity from extras after checking it is a finite number >= 0."""
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if not (number and math.isfinite(value) and value >= 0):
        raise SonarRasterError(
            f"'{path.name}' node '{node}' has extras reflectivity {value!r}; "
            "set it to a number >= 0"
        )
    return float(value)
