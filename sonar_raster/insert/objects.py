"""Objects to insert: a bundled primitive or a model file, with size, turn and reflectivity.

A spec is written ``KIND[:key=value[:key=value ...]]`` on the command line, e.g. ``box``,
``box:size=2,1,0.8:yaw=30``, ``cylinder:radius=0.4:length=2``, ``wreck.glb:scale=0.01:up=y``.
``KIND`` is a primitive of :mod:`sonar_raster.scenes.objects` or the path of a model file;
common keys: ``yaw`` (degrees: the object turned clockwise seen from above; at 0 its x axis
points across the track, away from the sonar on starboard), ``reflectivity`` (default 0.9),
``class`` (the label's class name, default the primitive's name or the file's stem), and for
model files ``scale`` and ``up`` (y or z).
Other keys are the primitive's own parameters (lengths in metres; lists comma-separated).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._checks import non_negative, number, positive
from ..errors import SonarRasterError
from ..meshio.formats import MODEL_SUFFIXES, Y_UP_SUFFIXES
from ..scenes.objects import PRIMITIVES, build_primitive

__all__ = ["DEFAULT_REFLECTIVITY", "ObjectMesh", "object_mesh", "parse_object", "resting_mesh"]

DEFAULT_REFLECTIVITY = 0.9
_COMMON = ("yaw", "reflectivity", "class", "scale", "up")


@dataclass(frozen=True)
class ObjectMesh:
    """An object ready to place: its mesh in its resting pose, footprint centred on the origin.

    Attributes
    ----------
    label : str
        Class name for the labels.
    source : str
        Primitive name or model path.
    vertices : ndarray, shape (n, 3), float64
        Metres in the track frame (x across the track to starboard, y along it, z up), turned
        by ``yaw``, footprint centred on x = y = 0, lowest point at z = 0.
    faces : ndarray, shape (m, 3), int64
    reflectivity : float
        Reflectivity R of every face.
    params : dict
        The spec's values, for the record.
    """

    label: str
    source: str
    vertices: np.ndarray
    faces: np.ndarray
    reflectivity: float
    params: dict

    @property
    def size(self) -> np.ndarray:
        """Extent along x, y, z, metres."""
        return np.ptp(self.vertices, axis=0)


def _value(text: str) -> float | list[float] | str:
    parts = text.split(",")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        return text
    return values if len(values) > 1 else values[0]


def parse_object(spec: str) -> tuple[str, dict]:
    """Split an object spec into its kind (primitive or path) and its keys.

    Parameters
    ----------
    spec : str
        ``KIND[:key=value ...]`` (see the module docstring).

    Returns
    -------
    kind : str
    options : dict
        Numbers as float, comma lists as lists of float, other values as str.
    """
    if not isinstance(spec, str) or not spec.strip():
        raise SonarRasterError("an object spec is empty; give a primitive name or a model file")
    kind, *rest = spec.strip().split(":")
    options: dict = {}
    for item in rest:
        key, sep, value = item.partition("=")
        if not sep or not key or not value:
            raise SonarRasterError(
                f"object {spec!r}: '{item}' is not key=value (e.g. box:size=1,0.6,0.5:yaw=30)"
            )
        options[key.strip()] = _value(value.strip())
    return kind, options


def _rotation_z(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _model_mesh(path: Path, up: str) -> tuple[np.ndarray, np.ndarray]:
    from ..meshio.load import load_model

    parts = load_model(path)
    verts, faces, offset = [], [], 0
    for p in parts:
        f = np.asarray(p.faces, dtype=np.int64).reshape(-1, 3)
        verts.append(np.asarray(p.vertices, dtype=np.float64).reshape(-1, 3))
        faces.append(f + offset)
        offset += len(verts[-1])
    v = np.concatenate(verts)
    if up == "y":  # y-up to z-up: (x, y, z) -> (x, -z, y)
        v = np.stack([v[:, 0], -v[:, 2], v[:, 1]], axis=1)
    return v, np.concatenate(faces)


def resting_mesh(
    label: str,
    source: str,
    vertices: np.ndarray,
    faces: np.ndarray,
    reflectivity: float,
    yaw_deg: float = 0.0,
    params: dict | None = None,
) -> ObjectMesh:
    """An :class:`ObjectMesh` from a mesh: turned by ``yaw_deg``, footprint centred, base at 0.

    Parameters
    ----------
    label, source : str
        Class name and where the mesh came from.
    vertices : ndarray, shape (n, 3)
        Metres, z up.
    faces : ndarray, shape (m, 3)
    reflectivity : float
        R >= 0.
    yaw_deg : float
        Clockwise turn seen from above, degrees.
    params : dict, optional
        Recorded with the object.
    """
    v = np.asarray(vertices, dtype=np.float64) @ _rotation_z(-math.radians(yaw_deg)).T
    f = np.asarray(faces, dtype=np.int64)
    if len(v) == 0 or len(f) == 0 or not np.all(np.isfinite(v)):
        raise SonarRasterError(f"object {source!r} has no usable triangles")
    low, high = v.min(axis=0), v.max(axis=0)
    v = v - np.array([0.5 * (low[0] + high[0]), 0.5 * (low[1] + high[1]), low[2]])
    return ObjectMesh(label, source, v, f, float(reflectivity), dict(params or {}))


def object_mesh(spec: str, base: Path | None = None) -> ObjectMesh:
    """Build the object of a spec in its resting pose, footprint centred, lowest point at z = 0.

    Parameters
    ----------
    spec : str
        ``KIND[:key=value ...]``: a primitive (``box``, ``cylinder``, ``barrel``,
        ``truncated_cone``, ``tyre``, ``rock``) or a model file.
    base : Path, optional
        Folder relative model paths are resolved against (default: the working folder).

    Returns
    -------
    ObjectMesh

    Raises
    ------
    SonarRasterError
        For an unknown kind or key, a bad value, or a model file that cannot be read.
    """
    kind, options = parse_object(spec)
    opts = dict(options)
    yaw = math.radians(number(f"object {spec!r} 'yaw'", opts.pop("yaw", 0.0)))
    refl = non_negative(
        f"object {spec!r} 'reflectivity'", opts.pop("reflectivity", DEFAULT_REFLECTIVITY)
    )
    label = str(opts.pop("class", ""))
    if kind in PRIMITIVES:
        for key in ("scale", "up"):
            if key in opts:
                raise SonarRasterError(f"object {spec!r}: '{key}' is for model files")
        params = {k: v for k, v in opts.items()}
        try:
            v, f = build_primitive(kind, params)
        except (TypeError, SonarRasterError) as exc:
            every = ", ".join(k for k in _COMMON if k not in ("scale", "up"))
            raise SonarRasterError(
                f"object {spec!r}: {exc} (any object also takes {every})"
            ) from None
        label = label or kind
    elif kind.lower().endswith(MODEL_SUFFIXES):
        path = Path(kind) if base is None or Path(kind).is_absolute() else base / kind
        scale = positive(f"object {spec!r} 'scale'", opts.pop("scale", 1.0))
        up = str(opts.pop("up", "y" if kind.lower().endswith(Y_UP_SUFFIXES) else "z"))
        if up not in ("y", "z"):
            raise SonarRasterError(f"object {spec!r}: 'up' must be y or z")
        if opts:
            raise SonarRasterError(
                f"object {spec!r}: unknown key(s) {', '.join(sorted(opts))} for a model file; "
                f"use {', '.join(_COMMON)}"
            )
        v, f = _model_mesh(path, up)
        v = v * scale
        label = label or path.stem
    else:
        raise SonarRasterError(
            f"object {kind!r} is neither a primitive ({', '.join(sorted(PRIMITIVES))}) nor a "
            f"model file ({' '.join(MODEL_SUFFIXES)})"
        )
    return resting_mesh(label, kind, v, f, refl, math.degrees(yaw), options)
