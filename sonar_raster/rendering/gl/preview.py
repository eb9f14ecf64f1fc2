"""Headless preview renders of the recovered seabed mesh from four viewpoints (seed Figs. 6–7).

Drawn by :meth:`~sonar_raster.rendering.gl.raster.RasterRenderer.draw_views`, on the context of the
renderer that owns every GL object (EGL, else OSMesa): the package's one GL path. pyrender, which
the design card names, was tried: its 0.1.45 release pins PyOpenGL 3.1.0, whose OSMesa binding
lacks ``OSMesaCreateContextAttribs`` so its OSMesa platform fails to import, and it picks EGL or
OSMesa for the whole process through the ``PYOPENGL_PLATFORM`` variable at import time rather than
per context.

Views: perspective (40° vertical field of view) from azimuths 45°, 135°, 225° and 315° around
the mesh centre (0° = looking along +Y, the track), 35° above the horizontal, at the distance that
fits the mesh's bounding sphere. Heights are exaggerated so the relief spans a tenth of the
larger horizontal extent (at least 1×, at most 100×). Colour: the mesh's grey texture times
``0.35 + 0.65 |n · l|`` for a light from above-left of each camera.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

#: Azimuths of the four views, degrees.
AZIMUTHS = (45.0, 135.0, 225.0, 315.0)
#: Camera elevation above the horizontal, degrees.
ELEVATION = 35.0
#: Vertical field of view, degrees.
FOV = 40.0
#: Background colour (RGB, 0–1).
BACKGROUND = (0.10, 0.12, 0.18)


def exaggeration(vertices: np.ndarray) -> float:
    """Vertical exaggeration making the relief span 1/10 of the horizontal extent (1–100)."""
    span = np.ptp(vertices, axis=0)
    relief = float(span[2])
    target = 0.1 * float(max(span[0], span[1]))
    if relief <= 0:
        return 1.0
    return float(np.clip(target / relief, 1.0, 100.0))


def _look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    f = target - eye
    f = f / np.linalg.norm(f)
    s = np.cross(f, up)
    s = s / np.linalg.norm(s)
    u = np.cross(s, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = s, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def _perspective(fov_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    f = 1.0 / math.tan(math.radians(fov_deg) / 2.0)
    m = np.zeros((4, 4))
    m[0, 0], m[1, 1] = f / aspect, f
    m[2, 2], m[2, 3] = (far + near) / (near - far), 2.0 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


def view_matrices(
    vertices: np.ndarray, size: tuple[int, int]
) -> list[tuple[np.ndarray, np.ndarray]]:
    """(model-view-projection, light direction) of each of the four views, for centred vertices."""
    radius = float(np.max(np.linalg.norm(vertices, axis=1))) or 1.0
    aspect = size[0] / size[1]
    half = math.radians(FOV) / 2.0
    dist = radius / math.sin(min(half, math.atan(aspect * math.tan(half))))
    proj = _perspective(FOV, aspect, 0.05 * dist, dist + 2.0 * radius)
    out = []
    el = math.radians(ELEVATION)
    for az_deg in AZIMUTHS:
        az = math.radians(az_deg)
        back = np.array([-math.sin(az) * math.cos(el), -math.cos(az) * math.cos(el), math.sin(el)])
        eye = dist * back
        view = _look_at(eye, np.zeros(3), np.array([0.0, 0.0, 1.0]))
        side = np.cross(back, [0.0, 0.0, 1.0])
        light = back + 0.5 * side / (np.linalg.norm(side) or 1.0) + np.array([0.0, 0.0, 1.0])
        out.append((proj @ view, light / np.linalg.norm(light)))
    return out


def render_previews(
    mesh: Any,
    size: tuple[int, int] = (640, 480),
    backend: str | None = None,
    renderer: Any = None,
) -> list[np.ndarray]:
    """Four preview images of a mesh made by :func:`sonar_raster.meshio.export.seabed_mesh`.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        With vertex colours (``visual.kind == "vertex"``); grey is the red channel.
    size : (int, int)
        Width and height in pixels.
    backend : {"egl", "osmesa"} or None
        GL backend of the renderer made for the previews when ``renderer`` is None.
    renderer : RasterRenderer, optional
        Draw on this renderer's context (it owns every GL object) instead of a new one.

    Returns
    -------
    list of ndarray, each shape (height, width, 3), uint8
        Top row first, one per azimuth of :data:`AZIMUTHS`.
    """
    vertices = np.asarray(mesh.vertices, np.float64)
    centred = vertices - 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))
    centred[:, 2] *= exaggeration(vertices)
    normals = _normals(centred, np.asarray(mesh.faces))
    grey = np.asarray(mesh.visual.vertex_colors, np.float64)[:, 0] / 255.0
    data = np.concatenate([centred, normals, grey[:, None]], axis=1).astype("f4")
    index = np.asarray(mesh.faces, dtype="i4")
    views = view_matrices(centred, size)
    if renderer is not None:
        return renderer.draw_views(data, index, views, size, BACKGROUND)
    from .raster import RasterRenderer

    with RasterRenderer(backend) as own:
        return own.draw_views(data, index, views, size, BACKGROUND)


def _normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals, unit length (up where undefined)."""
    tri = vertices[faces]
    face_n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    out = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(out, faces[:, k], face_n)
    length = np.linalg.norm(out, axis=1)
    up = np.tile([0.0, 0.0, 1.0], (len(vertices), 1))
    return np.where(length[:, None] > 0, out / np.where(length > 0, length, 1.0)[:, None], up)
