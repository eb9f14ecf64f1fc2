"""Mesh surfaces as point scatterers for the coherent model, generated chunk by chunk.

Triangle ``f`` is cut into ``n_f²`` equal sub-triangles (facets) by uniform barycentric
subdivision, ``n_f = max(1, ceil(max(sqrt(A_f) / s, longest edge / (2 s))))`` for a spacing
``s``: about one facet per ``s²`` of area (facet area ``a² = A_f / n_f² <= s²``, close to
``s²`` on triangles much larger than ``s``), with no facet edge longer than ``2 s``. Facets are
indexed on an ``n × n`` square grid as in :mod:`sonar_raster.rendering.patches` (cell ``(i, j)`` is
upright for ``i + j <= n − 1`` with centroid barycentric ``((i + 1/3)/n, (j + 1/3)/n)``, else
inverted with centroid ``(1 − (i + 1/3)/n, 1 − (j + 1/3)/n)``); the scatterer sits at the
facet centroid moved by an isotropic Gaussian jitter (rms ``σ`` per axis, truncated at 4σ).

The jitter is a pure function of (seed, face index, cell index) through a counter-based hash,
so a scatterer is the same whichever chunk, ping block or track segment generates it: results
do not depend on chunking. Only facets whose centroids fall inside a box (a ping block's reach)
are generated: each subdivision row is clipped to the box analytically.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from ...scene import Scene
from ..patches import Runs, overlaps, project, runs_in_box

#: Subdivision rows handled at once (bounds the per-row arrays to a few tens of MB).
_ROW_BLOCK = 1 << 18
#: Jitter truncation, in standard deviations per axis.
JITTER_CLIP = 4.0

GOLDEN = np.uint64(0x9E3779B97F4A7C15)
MIX1 = np.uint64(0xBF58476D1CE4E5B9)
MIX2 = np.uint64(0x94D049BB133111EB)
#: Per-draw offsets of the hash, ``(c + 1) · golden`` (mod 2⁶⁴) for draw c.
STEPS = np.array(
    [((c + 1) * 0x9E3779B97F4A7C15) & 0xFFFFFFFFFFFFFFFF for c in range(8)], dtype=np.uint64
)


@dataclass(frozen=True)
class ScatterSurface:
    """Scene triangles in local coordinates with their subdivision into facets.

    Attributes
    ----------
    tri : ndarray, shape (m, 3, 3)
        Corners, local metres.
    normal : ndarray, shape (m, 3)
        Unit normals.
    n_sub : ndarray, shape (m,), int64
        Subdivisions per edge; a triangle has ``n_sub²`` facets.
    facet_area : ndarray, shape (m,)
        a², m².
    reflectivity : ndarray, shape (m,)
        R of each face.
    """

    tri: np.ndarray
    normal: np.ndarray
    n_sub: np.ndarray
    facet_area: np.ndarray
    reflectivity: np.ndarray


def scatter_surface(scene: Scene, local: np.ndarray, spacing: float | np.ndarray) -> ScatterSurface:
    """Subdivide ``scene`` (shifted by ``-local``) for a scatterer spacing in metres.

    Parameters
    ----------
    scene : Scene
        The triangles.
    local : ndarray, shape (3,)
        Local origin subtracted from the vertices, metres.
    spacing : float or ndarray, shape (m,)
        Scatterer spacing, metres: one value, or one per face (e.g. coarser on the seabed).
    """
    tri = scene.triangles() - local
    normal, area = scene.face_normals_areas()
    edges = np.linalg.norm(tri[:, [1, 2, 0]] - tri, axis=2).max(axis=1)
    spacing = np.broadcast_to(np.asarray(spacing, dtype=np.float64), area.shape)
    n = np.maximum(np.sqrt(area) / spacing, edges / (2.0 * spacing))
    n_sub = np.maximum(1, np.ceil(n - 1e-9)).astype(np.int64)
    return ScatterSurface(
        tri, normal, n_sub, area / n_sub.astype(np.float64) ** 2, scene.reflectivity
    )


@dataclass(frozen=True)
class Scatterers:
    """One chunk of scatterers in a frame (along, starboard, up) relative to its origin.

    Per-face quantities (normal, facet area, R) are kept once per face and looked up through
    ``face`` when asked for, so culling and the visibility test copy only four arrays.

    Attributes
    ----------
    face : ndarray, shape (k,), int64
        Parent face.
    cell : ndarray, shape (k,), int64
        Facet index ``i n + j`` on the face's subdivision grid (the jitter hash's key).
    nominal : ndarray, shape (k, 3)
        Facet centroid, metres (visibility and culling use it).
    position : ndarray, shape (k, 3)
        Jittered scatterer position, metres (the echo uses it).
    faces : FaceTable
        Normals (frame components), facet areas and R of every face of the surface.
    """

    face: np.ndarray
    cell: np.ndarray
    nominal: np.ndarray
    position: np.ndarray
    faces: FaceTable

    @property
    def normal(self) -> np.ndarray:
        """Unit normal of the parent face in frame components, shape (k, 3)."""
        return self.faces.normal[self.face]

    @property
    def facet_area(self) -> np.ndarray:
        """a², m², shape (k,)."""
        return self.faces.facet_area[self.face]

    @property
    def reflectivity(self) -> np.ndarray:
        """R, shape (k,)."""
        return self.faces.reflectivity[self.face]

    def take(self, keep: np.ndarray | slice) -> Scatterers:
        """The scatterers selected by an index or mask array, or a slice."""
        nominal = self.nominal[keep]
        same = self.position is self.nominal
        position = nominal if same else self.position[keep]
        return Scatterers(self.face[keep], self.cell[keep], nominal, position, self.faces)

    def jittered(self, axes: np.ndarray, jitter: float, seed: int) -> Scatterers:
        """The same scatterers moved by their jitter (rms ``jitter`` metres per axis)."""
        if jitter <= 0 or len(self.face) == 0:
            return self
        moved = _rotate(_gaussian3(self.face, self.cell, seed), jitter * axes)
        moved += self.nominal
        return Scatterers(self.face, self.cell, self.nominal, moved, self.faces)


@dataclass(frozen=True)
class FaceTable:
    """Per-face quantities of a surface in one frame.

    Attributes
    ----------
    normal : ndarray, shape (m, 3)
        Unit normals, frame components.
    facet_area : ndarray, shape (m,)
        a², m².
    reflectivity : ndarray, shape (m,)
        R.
    """

    normal: np.ndarray
    facet_area: np.ndarray
    reflectivity: np.ndarray


def generate(
    surface: ScatterSurface,
    axes: np.ndarray,
    origin: np.ndarray,
    bounds: np.ndarray,
    chunk: int,
    normal_axes: np.ndarray | None = None,
) -> Iterator[Scatterers]:
    """Yield the scatterers whose facet centroid lies in ``bounds``, about ``chunk`` at a time.

    Parameters
    ----------
    surface : ScatterSurface
        The subdivided scene.
    axes : ndarray, shape (3, 3)
        Rows along, starboard, up of the frame (world axes).
    origin : ndarray, shape (3,)
        Frame origin, local metres.
    bounds : ndarray, shape (3, 2)
        Box in frame coordinates (min, max per axis), metres.
    chunk : int
        Scatterers per chunk (whole runs, so a chunk may exceed it by one row).
    normal_axes : ndarray, shape (3, 3), optional
        Orthonormal rows the normals are given in (default ``axes``; the fan's axes when
        ``axes`` is a crabbed or pitched segment's shear map).
    """
    for faces, ids, runs in generate_runs(surface, axes, origin, bounds, chunk, normal_axes):
        yield _expand(surface.n_sub, faces, ids, runs)


def generate_runs(
    surface: ScatterSurface,
    axes: np.ndarray,
    origin: np.ndarray,
    bounds: np.ndarray,
    chunk: int,
    normal_axes: np.ndarray | None = None,
    row_block: int = _ROW_BLOCK,
) -> Iterator[tuple[FaceTable, np.ndarray, Runs]]:
    """:func:`generate`'s facets as runs, not expanded: ``(faces, ids, runs)`` per chunk.

    ``runs.tri`` indexes ``ids`` (face indices); ``faces`` is the same table for every chunk;
    ``row_block``: subdivision rows clipped at once.
    """
    proj = project(surface.tri, origin, axes, _rotate)
    ids = np.flatnonzero(overlaps(proj, bounds))
    if len(ids) == 0:
        return
    normal = _rotate(surface.normal, axes if normal_axes is None else normal_axes)
    faces = FaceTable(normal, surface.facet_area, surface.reflectivity)
    for runs in runs_in_box(proj, surface.n_sub, ids, bounds, row_block=row_block, chunk=chunk):
        yield faces, ids, runs


def _rotate(v: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """Components of vectors ``v`` (k, 3) along the rows of ``axes`` (no BLAS: tiny inner size)."""
    return np.einsum("kj,cj->kc", v, axes)


def _expand(n_sub: np.ndarray, faces: FaceTable, ids: np.ndarray, runs: Runs) -> Scatterers:
    """Materialise the facets of some runs (``runs.tri`` indexes ``ids``) as scatterers."""
    run, offset = runs.cells()
    j = runs.lo[run] + offset
    nominal = runs.base[run] + runs.slope[run] * j[:, None].astype(np.float64)
    face = ids[runs.tri[run]]
    cell = runs.i[run] * n_sub[face] + j
    return Scatterers(face=face, cell=cell, nominal=nominal, position=nominal, faces=faces)


def _splitmix(z: np.ndarray) -> np.ndarray:
    """SplitMix64 finaliser on uint64 arrays (wrapping arithmetic; a new array)."""
    z = z + GOLDEN
    z ^= z >> np.uint64(30)
    z *= MIX1
    z ^= z >> np.uint64(27)
    z *= MIX2
    z ^= z >> np.uint64(31)
    return z


def _uniforms(face: np.ndarray, cell: np.ndarray, seed: int, count: int) -> np.ndarray:
    """``count`` (<= 8) uniforms in (0, 1) per (face, cell), shape (count, k): a pure function."""
    key = face.astype(np.uint64)
    key ^= np.uint64(seed & 0xFFFFFFFFFFFFFFFF)
    key = _splitmix(key)
    key ^= cell.astype(np.uint64)
    key = _splitmix(key)
    out = np.empty((count, len(face)))
    for c in range(count):
        bits = _splitmix(key + STEPS[c])
        bits >>= np.uint64(11)
        np.multiply(bits.view(np.int64), 1.0 / (1 << 53), out=out[c])  # int64: SIMD convert
        out[c] += 0.5 / (1 << 53)
    return out


def _gaussian3(face: np.ndarray, cell: np.ndarray, seed: int) -> np.ndarray:
    """Standard normal 3-vectors (world axes) per (face, cell), truncated at ``JITTER_CLIP``."""
    u = _uniforms(face, cell, seed, 4)
    r1 = np.sqrt(-2.0 * np.log(u[0]))
    r2 = np.sqrt(-2.0 * np.log(u[2]))
    g = np.empty((len(face), 3))
    u[1:4:2] -= 0.5  # angles in [-π, π): the float32 cosine's best range
    cos1, sin1 = cos_sin((2 * math.pi) * u[1])
    cos3, _ = cos_sin((2 * math.pi) * u[3])
    np.multiply(r1, cos1, out=g[:, 0])
    np.multiply(r1, sin1, out=g[:, 1])
    np.multiply(r2, cos3, out=g[:, 2])
    g[:, :2] *= -1.0  # cos(a - π) = -cos a, sin(a - π) = -sin a
    g[:, 2] *= -1.0
    return np.clip(g, -JITTER_CLIP, JITTER_CLIP, out=g)


def cos_sin(angle: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cosine and sine of float64 angles in [-π, π], to ~1e-7 (float32 SIMD, corrected).

    The angle is rounded to float32 for numpy's vectorised float32 cosine and sine (the float64
    ones are several times slower), and the rounding is corrected to first order in float64.
    """
    coarse = angle.astype(np.float32)
    delta = angle - coarse  # |delta| <= 1.2e-7
    c = np.cos(coarse).astype(np.float64)
    s = np.sin(coarse).astype(np.float64)
    cos = s * delta
    np.subtract(c, cos, out=cos)  # cos(a + d) ~ cos a - d sin a
    c *= delta
    c += s  # sin(a + d) ~ sin a + d cos a
    return cos, c
