"""Scene: triangles with per-face reflectivity and object ids, in world metres (float64).

Conventions: right-handed world, metres, z up. A seabed below the sonar has z < sonar z.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .errors import SonarRasterError

log = logging.getLogger(__name__)

#: Relative area below which a triangle counts as degenerate and is dropped.
_DEGENERATE_REL_AREA = 1e-14


@dataclass(frozen=True)
class MeshPart:
    """One object of a scene before merging.

    Parameters
    ----------
    vertices : ndarray, shape (n, 3), float64
        World coordinates in metres.
    faces : ndarray, shape (m, 3), int
        Vertex indices of each triangle, counter-clockwise seen from the front.
    reflectivity : float or ndarray, shape (m,)
        Backscatter reflectivity R in [0, inf), per object or per face.
    name : str
        Object name (used for labels).
    is_seabed : bool
        True for the seabed surface (its mean level sets the nominal altitude).
    law : int
        Scattering law of the faces: 0 is Lambert, i > 0 the APL-UW law of material
        ``scenes.sediments.MATERIALS[i - 1]``.
    """

    vertices: np.ndarray
    faces: np.ndarray
    reflectivity: float | np.ndarray = 0.5
    name: str = "object"
    is_seabed: bool = False
    law: int = 0

    def __post_init__(self) -> None:
        what = f"object '{self.name}'"
        _check_rows(f"{what}: vertices", "(n, 3) coordinates", self.vertices)
        _check_rows(f"{what}: faces", "(m, 3) vertex indices; triangulate quads", self.faces)
        m = np.size(self.faces) // 3
        shape = np.shape(self.reflectivity)
        if shape not in ((), (1,), (m,)):
            raise SonarRasterError(
                f"{what} has {np.size(self.reflectivity)} reflectivity values for {m} faces: "
                "give one value, or one per face (per vertex: r[faces].mean(axis=1))"
            )


@dataclass(frozen=True)
class Scene:
    """Triangles ready for rendering.

    Attributes
    ----------
    vertices : ndarray, shape (n, 3), float64
        World coordinates in metres.
    faces : ndarray, shape (m, 3), int32 (int64 beyond 2³¹ vertices)
        Triangle vertex indices; no degenerate triangles.
    reflectivity : ndarray, shape (m,), float64
        Reflectivity R of each face.
    object_id : ndarray, shape (m,), int32
        Index into ``names`` for each face.
    names : tuple of str
        Object names; id 0 is the first part.
    ground_z : float
        Nominal seabed level in metres (mean z of the seabed parts, else the scene's lowest z).
    bounds : ndarray, shape (2, 3), float64
        Min and max corner of the used vertices (computed when not given).
    law : ndarray, shape (m,), uint8, or None
        Scattering law of each face (see :attr:`MeshPart.law`); None: Lambert everywhere.
    two_sided : ndarray, shape (m,), bool, or None
        Faces that scatter from both sides: those of an object that is not a closed surface
        wound outward (an open sheet, a model with faces wound both ways). A closed outward
        body's faces and the seabed's (turned to face up) are seen from the front only, the
        only side from which they can be seen. None (a Scene made by hand): every face of an
        object not named "seabed" (:meth:`two_sided_faces`). :func:`build_scene` sets it.
    """

    vertices: np.ndarray
    faces: np.ndarray
    reflectivity: np.ndarray
    object_id: np.ndarray
    names: tuple[str, ...] = field(default_factory=tuple)
    ground_z: float = 0.0
    bounds: Any = field(default=None, repr=False)
    law: np.ndarray | None = field(default=None, repr=False)
    two_sided: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        _check_rows("Scene vertices", "(n, 3) coordinates", self.vertices, empty=False)
        _check_rows("Scene faces", "(m, 3) vertex indices", self.faces, empty=False)
        m = len(self.faces)
        for name in ("reflectivity", "object_id", "law", "two_sided"):
            values = getattr(self, name)
            if values is not None and np.shape(values) != (m,):
                raise SonarRasterError(
                    f"Scene {name} has {np.size(values)} values for {m} faces: give one per "
                    "face (build_scene([MeshPart(...), ...]) makes a checked Scene)"
                )
        if self.bounds is None:
            if m and (np.min(self.faces) < 0 or np.max(self.faces) >= len(self.vertices)):
                raise SonarRasterError(
                    f"Scene faces have a face index outside its {len(self.vertices)} vertices"
                )
            object.__setattr__(self, "bounds", _bounds(self.vertices, self.faces))

    @property
    def n_triangles(self) -> int:
        """Number of triangles."""
        return int(self.faces.shape[0])

    def triangles(self) -> np.ndarray:
        """Corner coordinates, shape (m, 3, 3), float64."""
        return self.vertices[self.faces]

    def face_normals_areas(self) -> tuple[np.ndarray, np.ndarray]:
        """Unit face normals, shape (m, 3), and areas in m², shape (m,)."""
        tri = self.triangles()
        cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        norm = np.linalg.norm(cross, axis=1)
        return cross / norm[:, None], 0.5 * norm

    def two_sided_faces(self) -> np.ndarray:
        """Which faces scatter from both sides, shape (m,) bool (see :attr:`two_sided`)."""
        if self.two_sided is not None:
            return np.asarray(self.two_sided, dtype=bool)
        seabed = np.array([name == "seabed" for name in self.names] or [False])
        return ~seabed[np.clip(self.object_id, 0, len(seabed) - 1)]

    def with_back_faces(self) -> Scene:
        """The scene with a reversed copy of every two-sided face appended (same R, law, id).

        For renderers that see a face from its front only (the numpy reference, the coherent
        model): each copy is the other side of its face, and the copy the ray meets from behind
        coincides with the face it meets from the front, so one of the two counts.
        """
        extra = np.flatnonzero(self.two_sided_faces())
        if not len(extra):
            return self

        def doubled(values: np.ndarray | None) -> np.ndarray | None:
            return None if values is None else np.concatenate([values, values[extra]])

        return Scene(
            self.vertices,
            np.concatenate([self.faces, self.faces[extra][:, ::-1]]),
            np.concatenate([self.reflectivity, self.reflectivity[extra]]),
            np.concatenate([self.object_id, self.object_id[extra]]),
            self.names,
            self.ground_z,
            self.bounds,
            doubled(self.law),
            np.zeros(len(self.faces) + len(extra), dtype=bool),
        )

    def translated(self, offset: np.ndarray) -> Scene:
        """Return the scene moved by ``offset`` (metres, shape (3,))."""
        offset = np.asarray(offset, dtype=np.float64)
        return Scene(
            self.vertices + offset,
            self.faces,
            self.reflectivity,
            self.object_id,
            self.names,
            self.ground_z + float(offset[2]),
            self.bounds + offset,
            self.law,
            self.two_sided,
        )


def _check_rows(label: str, what: str, values: Any, empty: bool = True) -> None:
    """Refuse an array that is not (k, 3); with ``empty``, any empty array passes too."""
    shape = np.shape(values)
    if not (len(shape) == 2 and shape[1] == 3) and not (empty and np.size(values) == 0):
        raise SonarRasterError(f"{label} must be {what}, got shape {shape}")


def _bounds(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Min and max corner, shape (2, 3), of the vertices that faces use."""
    used = np.zeros(len(vertices), dtype=bool)
    used[faces.ravel()] = True
    v = vertices[used] if used.any() else vertices
    return np.stack([v.min(axis=0), v.max(axis=0)])


#: Faces per block of the validity test (bounds its temporaries to about 100 MB).
_FACE_BLOCK = 1 << 20


def clean_faces(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Boolean mask of faces that are non-degenerate (positive area, distinct corners)."""
    span = float(np.ptp(vertices, axis=0).max()) if len(vertices) else 1.0
    scale = 1.0 / span if span > 0 else 1.0  # relative edges: no overflow at absurd sizes
    keep = np.empty(len(faces), dtype=bool)
    for a in range(0, len(faces), _FACE_BLOCK):
        f = faces[a : a + _FACE_BLOCK]
        v0 = vertices[f[:, 0]]
        e1 = (vertices[f[:, 1]] - v0) * scale
        e2 = (vertices[f[:, 2]] - v0) * scale
        # |e1 x e2|², written out by component (np.cross and a (m, 3, 3) gather are slower).
        cx = e1[:, 1] * e2[:, 2] - e1[:, 2] * e2[:, 1]
        cy = e1[:, 2] * e2[:, 0] - e1[:, 0] * e2[:, 2]
        cz = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
        keep[a : a + _FACE_BLOCK] = cx * cx + cy * cy + cz * cz > _DEGENERATE_REL_AREA**2
    return keep


def closed_volume(vertices: np.ndarray, faces: np.ndarray) -> float | None:
    """Signed volume enclosed by a closed surface, m³, or None for a surface that is not closed.

    Closed means every edge is shared by two faces that run along it in opposite directions
    (consistently wound, watertight); the volume is positive when the faces point out.
    """
    faces = np.asarray(faces, dtype=np.int64)
    n = max(len(vertices), 1)
    start, end = faces.ravel(), np.roll(faces, -1, axis=1).ravel()
    edges = start * n + end
    if len(faces) < 4 or len(np.unique(edges)) < len(edges):
        return None
    if not np.all(np.isin(end * n + start, edges)):
        return None
    with np.errstate(all="ignore"):  # absurd coordinates: the sign may be lost, not the rule
        corners = (vertices - vertices.mean(axis=0))[faces]
        triple = np.einsum("ij,ij->", corners[:, 0], np.cross(corners[:, 1], corners[:, 2]))
        return float(triple) / 6.0


def _repeated(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Faces whose three corners are those of an earlier face, either way round.

    A sheet written twice, once per side, as some exporters make a double-sided surface.
    """
    _, vertex_class = np.unique(vertices, axis=0, return_inverse=True)
    corners = np.sort(vertex_class.reshape(-1)[faces], axis=1)
    _, first = np.unique(corners, axis=0, return_index=True)
    repeated = np.ones(len(faces), dtype=bool)
    repeated[first] = False
    return repeated


def _sides(part: MeshPart, v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, bool, np.ndarray]:
    """The part's faces wound so that a seabed faces up and a closed body out.

    Also whether they scatter from both sides (see :attr:`Scene.two_sided`) and which of ``f``
    are kept (a face repeated is kept once).
    """
    kept = np.ones(len(f), dtype=bool)
    if not len(f):
        return f, False, kept
    if part.is_seabed:  # a heightfield: its back is never in sight
        up = 0.0  # twice the area the faces project onto the horizontal, signed
        for a in range(0, len(f), _FACE_BLOCK):  # bounded temporaries on a large seabed
            b = f[a : a + _FACE_BLOCK]
            x0, y0 = v[b[:, 0], 0], v[b[:, 0], 1]
            dx1, dy1 = v[b[:, 1], 0] - x0, v[b[:, 1], 1] - y0
            dx2, dy2 = v[b[:, 2], 0] - x0, v[b[:, 2], 1] - y0
            up += float(np.sum(dx1 * dy2 - dy1 * dx2))
        return (f[:, ::-1].copy() if up < 0 else f), False, kept
    kept = ~_repeated(v, f)
    if not kept.all():
        log.info("object '%s': %d faces repeated (a double-sided sheet): kept once",
                 part.name, int((~kept).sum()))  # fmt: skip
        f = f[kept]
    volume = closed_volume(v, f)
    if volume is None or not math.isfinite(volume) or volume == 0:
        return f, True, kept
    return (f[:, ::-1].copy() if volume < 0 else f), False, kept


def _joined(arrays: list[np.ndarray]) -> np.ndarray:
    """Concatenate, without a copy when there is only one array (large seabeds)."""
    return np.ascontiguousarray(arrays[0]) if len(arrays) == 1 else np.concatenate(arrays)


def build_scene(parts: list[MeshPart]) -> Scene:
    """Merge mesh parts into one validated :class:`Scene`.

    Non-finite vertices raise; degenerate and zero-area triangles are dropped and counted in
    the log.

    Parameters
    ----------
    parts : list of MeshPart
        The objects, in id order.

    Returns
    -------
    Scene

    Raises
    ------
    SonarRasterError
        If there are no triangles, a vertex is NaN or infinite, an index is out of range, or a
        reflectivity is negative or not finite.
    """
    verts, faces, refl, ids, names, ground, laws, both = [], [], [], [], [], [], [], []
    offset = 0
    dropped = 0
    n_vertices = sum(len(np.asarray(p.vertices).reshape(-1, 3)) for p in parts)
    index_type = np.int32 if n_vertices < 2**31 else np.int64  # half the memory of int64
    for k, part in enumerate(parts):
        v = np.asarray(part.vertices, dtype=np.float64).reshape(-1, 3)
        f = np.asarray(part.faces).reshape(-1, 3)
        if f.dtype.kind not in "iu":
            raise SonarRasterError(f"object '{part.name}' has non-integer face indices")
        if not np.all(np.isfinite(v)):
            raise SonarRasterError(
                f"object '{part.name}' has NaN or infinite vertex coordinates; fix the model file"
            )
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            raise SonarRasterError(
                f"object '{part.name}' has a face index outside its {len(v)} vertices; "
                "the model file is corrupt"
            )
        r = np.broadcast_to(np.asarray(part.reflectivity, dtype=np.float64), (len(f),))
        if not np.all(np.isfinite(r)) or np.any(r < 0):
            raise SonarRasterError(
                f"object '{part.name}' has a negative or non-finite reflectivity; use R >= 0"
            )
        keep = clean_faces(v, f) if len(f) else np.zeros(0, dtype=bool)
        dropped += int((~keep).sum())
        if not keep.all():
            f, r = f[keep], r[keep]
        f, two_sided, kept = _sides(part, v, f)
        r = r[kept]
        f = f.astype(index_type, copy=False)
        verts.append(v)
        faces.append(f + index_type(offset) if offset else f)
        refl.append(r)
        ids.append(np.full(len(f), k, dtype=np.int32))
        laws.append(np.full(len(f), part.law, dtype=np.uint8))
        both.append(np.full(len(f), two_sided))
        names.append(part.name)
        if part.is_seabed and len(f):
            used = np.zeros(len(v), dtype=bool)
            used[f.ravel()] = True
            ground.append(float(v[used, 2].mean()))
        offset += len(v)
    if dropped:
        log.warning("dropped %d degenerate or zero-area triangles", dropped)
    all_faces = _joined(faces) if faces else np.zeros((0, 3), dtype=index_type)
    if len(all_faces) == 0:
        raise SonarRasterError("the scene has no triangles; give a model or a seabed to render")
    vertices = _joined(verts)
    bounds = _bounds(vertices, all_faces)
    ground_z = float(np.mean(ground)) if ground else float(bounds[0, 2])
    return Scene(
        vertices=vertices,
        faces=all_faces,
        reflectivity=_joined(refl),
        object_id=_joined(ids),
        names=tuple(names),
        ground_z=ground_z,
        bounds=bounds,
        law=_joined(laws) if any(p.law for p in parts) else None,
        two_sided=_joined(both),
    )
