"""Bundled primitive objects for datasets: cylinders, barrels, cones, tyres, boxes, rocks.

Every builder returns ``(vertices, faces)`` in metres, centred on the z axis with the object's
resting pose: it lies on z = 0 when moved up by its lowest point. Faces are counter-clockwise
seen from outside (outward normals). Cylinders lie on their side (axis along x, a mine-like
shape); barrels and truncated cones stand upright; tyres lie flat (axis along z); rocks are
perturbed icospheres. Parameters are in metres.
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable

import numpy as np

from .._checks import did_you_mean, non_negative, positive
from ..errors import SonarRasterError
from ..scene import closed_volume

Mesh = tuple[np.ndarray, np.ndarray]


def _as_arrays(mesh: object) -> Mesh:
    vertices = np.asarray(mesh.vertices, dtype=np.float64)  # type: ignore[attr-defined]
    faces = np.asarray(mesh.faces, dtype=np.int64)  # type: ignore[attr-defined]
    return _outward(vertices, faces)


def _outward(vertices: np.ndarray, faces: np.ndarray) -> Mesh:
    """Flip the winding of a closed surface whose faces point in (negative signed volume)."""
    volume = closed_volume(vertices, faces)
    return (vertices, faces if volume is None or volume >= 0 else faces[:, ::-1].copy())


def _length(name: str, value: float) -> float:
    """A length parameter, a finite number of metres > 0."""
    return positive(f"object parameter '{name}' (metres)", value)


def cylinder(radius: float = 0.3, length: float = 1.8, sections: int = 48) -> Mesh:
    """Closed cylinder lying on its side, axis along x."""
    import trimesh

    r, h = _length("radius", radius), _length("length", length)
    mesh = trimesh.creation.cylinder(radius=r, height=h, sections=sections)
    v, f = _as_arrays(mesh)
    return v[:, [2, 1, 0]] * [1.0, -1.0, 1.0], f  # z axis -> x axis (a proper rotation)


def _revolved(profile: np.ndarray, sections: int) -> Mesh:
    """Surface of revolution about z of a closed (radius, z) profile from axis to axis."""
    import trimesh

    return _as_arrays(trimesh.creation.revolve(profile, sections=sections))


def barrel(
    radius: float = 0.3, height: float = 0.9, bulge: float = 0.12, sections: int = 40
) -> Mesh:
    """Upright barrel: radius ``radius`` at its ends, ``radius * (1 + bulge)`` at mid height."""
    r, h = _length("radius", radius), _length("height", height)
    if not (0.0 <= float(bulge) < 1.0):
        raise SonarRasterError(f"barrel 'bulge' must be in [0, 1), got {bulge!r}")
    z = np.linspace(-0.5 * h, 0.5 * h, 9)
    radii = r * (1.0 + float(bulge) * (1.0 - (2.0 * z / h) ** 2))
    profile = np.concatenate([[[0.0, -0.5 * h]], np.stack([radii, z], axis=1), [[0.0, 0.5 * h]]])
    return _revolved(profile, sections)


def truncated_cone(
    bottom_radius: float = 0.5, top_radius: float = 0.2, height: float = 0.6, sections: int = 40
) -> Mesh:
    """Upright truncated cone (a frustum), closed at both ends."""
    rb, h = _length("bottom_radius", bottom_radius), _length("height", height)
    rt = non_negative("cone 'top_radius' (metres)", top_radius)
    profile = np.array([[0.0, -0.5 * h], [rb, -0.5 * h], [rt, 0.5 * h], [0.0, 0.5 * h]])
    if rt == 0:
        profile = profile[:3]
    return _revolved(profile, sections)


def tyre(major_radius: float = 0.45, minor_radius: float = 0.15, sections: int = 40) -> Mesh:
    """Torus lying flat: ring radius ``major_radius``, tube radius ``minor_radius``."""
    import trimesh

    big, small = _length("major_radius", major_radius), _length("minor_radius", minor_radius)
    if small >= big:
        raise SonarRasterError("tyre 'minor_radius' must be smaller than 'major_radius'")
    return _as_arrays(trimesh.creation.torus(big, small, sections, max(12, sections // 2)))


def box(size: tuple[float, float, float] | list[float] = (1.0, 0.6, 0.5)) -> Mesh:
    """Axis-aligned box of edge lengths ``size`` (x, y, z)."""
    import trimesh

    extents = [_length("size", s) for s in size]
    if len(extents) != 3:
        raise SonarRasterError("box 'size' must be three lengths [x, y, z]")
    return _as_arrays(trimesh.creation.box(extents=extents))


def rock(
    radius: float = 0.4,
    roughness: float = 0.25,
    flatness: float = 0.6,
    seed: int = 0,
    subdivisions: int = 2,
) -> Mesh:
    """Perturbed icosphere: a lumpy, flattened stone.

    The radius at unit direction ``u`` is ``radius * (1 + roughness * s(u))`` with
    ``s(u) = mean_k cos(4 d_k . u + phi_k)`` over six seeded random directions ``d_k`` and
    phases ``phi_k``; then z is scaled by ``flatness``.
    """
    import trimesh

    r = _length("radius", radius)
    if not (0.0 <= float(roughness) < 1.0 and 0.0 < float(flatness) <= 1.0):
        raise SonarRasterError("rock 'roughness' must be in [0, 1) and 'flatness' in (0, 1]")
    rng = np.random.default_rng(int(seed))
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    u, f = _as_arrays(mesh)
    d = rng.normal(size=(6, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    phase = rng.uniform(0.0, 2.0 * math.pi, 6)
    lumps = np.cos(4.0 * u @ d.T + phase).mean(axis=1)
    v = u * (r * (1.0 + float(roughness) * lumps))[:, None]
    v[:, 2] *= float(flatness)
    return v, f


#: Primitive builders by name, with the parameter names each takes.
PRIMITIVES: dict[str, Callable[..., Mesh]] = {
    "cylinder": cylinder,
    "barrel": barrel,
    "truncated_cone": truncated_cone,
    "tyre": tyre,
    "box": box,
    "rock": rock,
}


def build_primitive(kind: str, params: dict) -> Mesh:
    """Build a bundled primitive by name.

    Parameters
    ----------
    kind : str
        One of :data:`PRIMITIVES`.
    params : dict
        Keyword parameters of that builder (lengths in metres).

    Returns
    -------
    vertices : ndarray, shape (n, 3), float64
    faces : ndarray, shape (m, 3), int64
    """
    builder = PRIMITIVES.get(kind)
    if builder is None:
        raise SonarRasterError(
            f"unknown primitive {kind!r}; use one of {', '.join(sorted(PRIMITIVES))}"
        )
    keys = list(inspect.signature(builder).parameters)
    unknown = [k for k in params if k not in keys]
    if unknown:
        raise SonarRasterError(
            f"unknown key(s) {', '.join(map(repr, unknown))} for a {kind}; its keys are "
            f"{', '.join(keys)}{did_you_mean(unknown, keys)}"
        )
    return builder(**params)
