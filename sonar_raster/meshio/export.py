"""The recovered seabed as a textured triangle mesh (trimesh): glTF binary and PLY.

Vertex (i, j) is ground cell j of ping i at ``(s · x_j, i · dy, Z_ij)`` in metres: X across
track (``s = +1`` starboard, ``−1`` port, so X is positive to starboard), Y along track (the
ping spacing ``dy``), Z the recovered elevation relative to the transducer (z up). Cells with no
estimate (NaN) are left out with every triangle touching them. Each grid square gives two
triangles, counter-clockwise seen from above (normals up on both sides).

The texture is a grey image (one texel per cell) of the evenly illuminated image (or R),
mapped linearly from its 1st to its 99th percentile onto 0–255: the glTF carries it as an image
with UV coordinates at the cell centres, the PLY as vertex colours (PLY has no standard texture).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import SonarRasterError


def grey_levels(values: np.ndarray) -> np.ndarray:
    """Map finite values from their 1st–99th percentile to uint8 0–255 (NaN → 0), same shape."""
    v = np.asarray(values, np.float64)
    ok = np.isfinite(v)
    if not ok.any():
        return np.zeros(v.shape, np.uint8)
    lo, hi = np.percentile(v[ok], [1.0, 99.0])
    span = hi - lo if hi > lo else 1.0
    scaled = np.clip((np.where(ok, v, lo) - lo) / span, 0.0, 1.0)
    return np.where(ok, np.round(255.0 * scaled), 0).astype(np.uint8)


def _faces(ok: np.ndarray) -> np.ndarray:
    """Triangles (flat vertex indices of the full grid) of every square with 4 known corners."""
    pings, cells = ok.shape
    idx = np.arange(pings * cells).reshape(pings, cells)
    a, b = idx[:-1, :-1], idx[:-1, 1:]  # ping i: cells j, j + 1
    c, d = idx[1:, :-1], idx[1:, 1:]  # ping i + 1
    keep = (ok[:-1, :-1] & ok[:-1, 1:] & ok[1:, :-1] & ok[1:, 1:]).ravel()
    tri1 = np.stack([a.ravel(), b.ravel(), d.ravel()], axis=1)[keep]
    tri2 = np.stack([a.ravel(), d.ravel(), c.ravel()], axis=1)[keep]
    return np.concatenate([tri1, tri2])


def seabed_mesh(
    x: np.ndarray,
    elevation: np.ndarray,
    texture: np.ndarray,
    ping_spacing: float,
    side: str = "starboard",
    *,
    textured: bool = True,
) -> Any:
    """Triangle mesh of the recovered seabed (layout in the module notes).

    Parameters
    ----------
    x : ndarray, shape (cells,)
        Ground-range cell centres, metres.
    elevation : ndarray, shape (pings, cells)
        Z relative to the transducer, metres; NaN where unknown.
    texture : ndarray, shape (pings, cells)
        Values to show as grey (e.g. the evenly illuminated image); NaN shows black.
    ping_spacing : float
        Along-track distance between pings, metres, > 0.
    side : {"starboard", "port"}
    textured : bool
        True: a texture image with UV coordinates (for glTF); False: vertex colours (PLY).

    Returns
    -------
    trimesh.Trimesh
        Only the vertices used by a triangle, in ping-major order.

    Raises
    ------
    SonarRasterError
        If no square of four known cells exists or the arguments disagree in shape.
    """
    import trimesh

    z = np.asarray(elevation, np.float64)
    if z.ndim != 2 or z.shape[1] != len(x) or np.shape(texture) != z.shape:
        raise SonarRasterError(f"mesh: elevation {z.shape}, x {len(x)}, texture mismatch")
    if not (np.isfinite(ping_spacing) and ping_spacing > 0):
        raise SonarRasterError(f"mesh: ping spacing must be > 0 metres, got {ping_spacing!r}")
    sign = -1.0 if side == "port" else 1.0
    faces = _faces(np.isfinite(z))
    if faces.size == 0:
        raise SonarRasterError("mesh: no 2 x 2 block of cells has an elevation estimate")
    pings, cells = z.shape
    yy, xx = np.meshgrid(np.arange(pings) * ping_spacing, sign * np.asarray(x), indexing="ij")
    used = np.unique(faces)
    remap = np.full(z.size, -1, np.int64)
    remap[used] = np.arange(used.size)
    faces = remap[faces]
    if sign < 0:
        faces = faces[:, ::-1]  # mirrored X: keep the triangles counter-clockwise from above
    vertices = np.stack([xx.ravel(), yy.ravel(), z.ravel()], axis=1)[used]
    grey = grey_levels(texture)
    if textured:
        from PIL import Image

        jj, ii = np.meshgrid(np.arange(cells), np.arange(pings))
        uv = np.stack([(jj.ravel() + 0.5) / cells, (ii.ravel() + 0.5) / pings], axis=1)[used]
        image = Image.fromarray(np.ascontiguousarray(grey[::-1])).convert("RGB")
        visual: Any = trimesh.visual.TextureVisuals(uv=uv, image=image)
    else:
        rgb = np.repeat(grey.ravel()[used, None], 3, axis=1)
        colours = np.concatenate([rgb, np.full((used.size, 1), 255, np.uint8)], axis=1)
        visual = trimesh.visual.ColorVisuals(vertex_colors=colours)
    return trimesh.Trimesh(vertices, faces, visual=visual, process=False)


def export(mesh: Any, file_type: str) -> bytes:
    """The mesh encoded as ``"glb"`` or ``"ply"`` (binary) bytes."""
    data = mesh.export(file_type=file_type)
    return data if isinstance(data, bytes) else str(data).encode()
