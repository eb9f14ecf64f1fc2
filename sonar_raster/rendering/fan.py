"""Fan geometry and visibility shared by the CPU models (patch reference and coherent).

A straight track segment seen as a moving fan (:class:`Frame`), the scene's triangles in local
coordinates (:class:`Surface`), and the ray test that says whether a surface point is the first
thing the transducer sees along its ray (:func:`visible`). The GL raster gets the same answers
from its depth test.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from ..errors import SonarRasterError, SonarRasterTypeError
from ..scene import Scene
from ..sonar import Sonar
from ..trajectory import Segment, Trajectory

log = logging.getLogger(__name__)

#: Relative slant-range tolerance of the visibility test (first hit at >= r (1 - tol) is visible).
VISIBILITY_REL_TOL = 1e-4
#: Absolute slant-range tolerance of the visibility test, metres.
VISIBILITY_ABS_TOL = 1e-5


@dataclass(frozen=True)
class Frame:
    """One track segment in the scene's local coordinates.

    Attributes
    ----------
    origin, along : ndarray, shape (3,)
        First ping position (local metres) and the direction of travel.
    fore, starboard, up : ndarray, shape (3,)
        The fan's orthonormal axes (see :class:`~sonar_raster.trajectory.Segment`).
    spacing, width : float
        Ping spacing and per-ping along-track width, metres (spacing 0: stationary).
    first, count : int
        Trajectory index of the first ping and number of pings.
    roll : ndarray, shape (count,)
        Roll of each ping, radians, positive starboard down.
    """

    origin: np.ndarray
    along: np.ndarray
    starboard: np.ndarray
    up: np.ndarray
    spacing: float
    width: float
    first: int
    count: int
    roll: np.ndarray
    patch_size: float
    fore: np.ndarray
    shear: np.ndarray

    @property
    def t_bounds(self) -> tuple[float, float]:
        """Along-track interval [lo, hi) of surface the segment's pings see, metres."""
        if self.spacing > 0:
            return -0.5 * self.spacing, (self.count - 0.5) * self.spacing
        return -0.5 * self.width, 0.5 * self.width

    @property
    def axes(self) -> np.ndarray:
        """Map to (travel, starboard, up) fan coordinates, shape (3, 3) (``Segment.shear``).

        Orthonormal, rows along, starboard, up, unless the vehicle crabs or pitches.
        """
        return self.shear

    @property
    def fan_axes(self) -> np.ndarray:
        """Rows fore, starboard, up: the fan's orthonormal frame, shape (3, 3)."""
        return np.stack([self.fore, self.starboard, self.up])


@dataclass(frozen=True)
class Surface:
    """Scene triangles in local coordinates, with what the patches need.

    Attributes
    ----------
    tri : ndarray, shape (m, 3, 3)
        Corners, local metres.
    normal : ndarray, shape (m, 3)
        Unit normals ``cross(v1 - v0, v2 - v0)`` normalised.
    n_sub : ndarray, shape (m,), int64
        Subdivisions per edge; a triangle gives ``n_sub²`` patches.
    patch_weight : ndarray, shape (m,)
        Reflectivity times patch area, m².
    """

    tri: np.ndarray
    normal: np.ndarray
    n_sub: np.ndarray
    patch_weight: np.ndarray


def check_inputs(scene: Scene, sonar: Sonar, trajectory: Trajectory) -> None:
    """Raise :class:`SonarRasterTypeError` unless given a Scene, a Sonar and a Trajectory.

    The message says where each comes from (``load_scene(...).scene``, ...).
    """
    for value, kind, name, hint in (
        (scene, Scene, "scene", "load_scene(...).scene or build_scene([...])"),
        (sonar, Sonar, "sonar", "load_scene(...).sonar or Sonar(max_range=..., range_bin=...)"),
        (
            trajectory,
            Trajectory,
            "trajectory",
            "load_scene(...).trajectory or Trajectory.straight(...)",
        ),
    ):
        if not isinstance(value, kind):
            raise SonarRasterTypeError(
                f"the {name} must be a {kind.__name__}, got {type(value).__name__} (e.g. {hint})"
            )


def segment_frame(
    segment: Segment, trajectory: Trajectory, local: np.ndarray, patch_size: float
) -> Frame:
    """The :class:`Frame` of one straight segment, relative to the local origin ``local``."""
    sl = slice(segment.first, segment.first + segment.count)
    return Frame(
        origin=segment.origin - local,
        along=segment.along,
        starboard=segment.starboard,
        up=segment.up,
        spacing=float(segment.spacing),
        width=float(segment.width),
        first=segment.first,
        count=segment.count,
        roll=trajectory.roll[sl],
        patch_size=patch_size,
        fore=segment.fore,
        shear=segment.shear,
    )


def ray_caster(vertices: np.ndarray, faces: np.ndarray):
    """Embree intersector when embreex imports, else trimesh's pure-numpy one."""
    import trimesh

    mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=False, validate=False)
    try:
        # trimesh.ray wraps a failed embreex import instead of raising: test it directly
        import embreex  # noqa: F401
    except ImportError:
        from trimesh.ray import ray_triangle

        log.info("embreex not available: using trimesh's slow ray_triangle intersector")
        return ray_triangle.RayMeshIntersector(mesh)
    from trimesh.ray import ray_pyembree

    return ray_pyembree.RayMeshIntersector(mesh)


def visible(
    caster,
    surface: Surface,
    origins: np.ndarray,
    dirs: np.ndarray,
    r: np.ndarray,
    parent: np.ndarray,
) -> np.ndarray:
    """Test visibility: the first hit from the track is the patch's own face or not nearer."""
    try:
        hit = np.asarray(caster.intersects_first(origins, dirs), dtype=np.int64)
    except ImportError as exc:
        raise SonarRasterError(
            f"no ray caster available ({exc}); install embreex (or rtree for the slow fallback)"
        ) from None
    vis = (hit < 0) | (hit == parent)
    other = np.flatnonzero(~vis)
    if len(other):
        dist = _hit_distance(surface, hit[other], origins[other], dirs[other])
        vis[other] = dist >= r[other] * (1.0 - VISIBILITY_REL_TOL) - VISIBILITY_ABS_TOL
    return vis


def _hit_distance(
    surface: Surface, hit: np.ndarray, origins: np.ndarray, dirs: np.ndarray
) -> np.ndarray:
    """Distance along each ray to the plane of the face it hit, metres, in float64.

    A ray lying in the face's plane (grazing) gets the distance to the nearest corner's
    projection onto the ray, where it enters the face.
    """
    tri = surface.tri[hit]
    normal = surface.normal[hit]
    denom = np.einsum("ij,ij->i", normal, dirs)
    grazing = np.abs(denom) < 1e-9
    num = np.einsum("ij,ij->i", normal, tri[:, 0] - origins)
    along = np.einsum("ikj,ij->ik", tri - origins[:, None, :], dirs).min(axis=1)
    return np.where(grazing, along, num / np.where(grazing, 1.0, denom))
