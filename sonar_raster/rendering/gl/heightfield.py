"""Find the seabed grid in a scene, for the renderer's heightfield sweep (no OpenGL here).

A grid is one object's faces laid out as :func:`sonar_raster.scenes.seabed.heightfield_mesh`
makes them: vertex ``v0 + j * nx + i`` at ``(x0, y0) + i u + j v`` horizontally (``u = (dx, 0)``,
``v = (0, dy)`` there; any rotation or mirror image of that too), cell ``(j, i)`` giving the
faces ``(a, b, c)`` and ``(a, c, d)`` in row-major order, or both with their corners reversed.
On such a surface every vertical fan meets the triangles in the order of a walk through the
cells along the fan's trace, so a compute shader can find each ray's first hit without
rasterising the triangles (``range_accumulate.glsl``, ``SWEEP``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...scene import Scene

#: Smallest grid (cells) worth the sweep; smaller seabeds are rasterised like any object.
MIN_CELLS = 64
#: Relative tolerance of the regular-spacing test on the vertex coordinates.
_SPACING_TOL = 1e-9


@dataclass(frozen=True)
class Grid:
    """A regular heightfield among a scene's faces.

    Attributes
    ----------
    first_face : int
        Scene index of the grid's first face; its ``2 (ny - 1)(nx - 1)`` faces follow in order.
    first_vertex : int
        Scene index of node ``(0, 0)``; node ``(j, i)`` is vertex ``first_vertex + j nx + i``.
    nx, ny : int
        Nodes along i and along j.
    x0, y0 : float
        World position of node ``(0, 0)``, metres.
    u, v : tuple of float
        Horizontal steps from node ``(j, i)`` to ``(j, i + 1)`` and to ``(j + 1, i)``, metres.
    winding : int
        1 for the faces of ``heightfield_mesh``, -1 for the same with corners reversed.
    z_max : float
        Highest node, world metres.
    object_id : int
        The object the grid's faces belong to.
    """

    first_face: int
    first_vertex: int
    nx: int
    ny: int
    x0: float
    y0: float
    u: tuple[float, float]
    v: tuple[float, float]
    z_max: float
    object_id: int
    winding: int = 1

    @property
    def n_faces(self) -> int:
        """Faces of the grid."""
        return 2 * (self.nx - 1) * (self.ny - 1)

    @property
    def faces(self) -> slice:
        """The grid's faces among the scene's."""
        return slice(self.first_face, self.first_face + self.n_faces)

    @property
    def inverse(self) -> np.ndarray:
        """Map from horizontal offsets (metres) to grid units (i, j), shape (2, 2)."""
        return np.linalg.inv(np.array([self.u, self.v]).T)

    def grid_coordinates(self, xy: np.ndarray) -> np.ndarray:
        """Grid coordinates (i, j) of points ``xy`` (shape (n, 2), world metres)."""
        return (xy - [self.x0, self.y0]) @ self.inverse.T

    def contains(self, xy: np.ndarray) -> bool:
        """Whether every point ``xy`` (shape (n, 2), world metres) lies inside the grid."""
        ij = self.grid_coordinates(xy)
        inside = (ij[:, 0] > 0) & (ij[:, 0] < self.nx - 1) & (ij[:, 1] > 0)
        return bool(np.all(inside & (ij[:, 1] < self.ny - 1)))


def find_grid(scene: Scene) -> Grid | None:
    """The largest object of ``scene`` whose faces form a regular heightfield grid, or None.

    Parameters
    ----------
    scene : Scene
        The scene, as built (degenerate faces dropped: a grid that lost faces is not found).

    Returns
    -------
    Grid or None
        None when no object's faces follow the layout of ``heightfield_mesh`` exactly.
    """
    ids = scene.object_id
    if len(ids) == 0:
        return None
    starts = np.flatnonzero(np.diff(ids, prepend=ids[0] - 1))
    stops = np.append(starts[1:], len(ids))
    best = None
    for a, b in sorted(zip(starts, stops, strict=True), key=lambda ab: ab[0] - ab[1]):
        if b - a < 2 * MIN_CELLS:
            break
        best = _grid_at(scene, int(a), int(b))
        if best is not None:
            break
    return best


def _grid_at(scene: Scene, a: int, b: int) -> Grid | None:
    """The grid formed by faces ``a .. b - 1``, or None."""
    faces = scene.faces[a:b]
    f0 = faces[0].astype(np.int64)
    winding = 1 if f0[0] < f0[2] else -1
    if winding < 0:
        faces = faces[:, ::-1]
        f0 = f0[::-1]
    v0, nx = int(f0[0]), int(f0[2] - f0[0] - 1)
    if nx < 2 or (b - a) % (2 * (nx - 1)):
        return None
    ny = (b - a) // (2 * (nx - 1)) + 1
    if v0 + nx * ny > len(scene.vertices) or not _faces_match(faces, v0, ny, nx):
        return None
    nodes = scene.vertices[v0 : v0 + nx * ny].reshape(ny, nx, 3)[..., :2]
    p0 = nodes[0, 0]
    u, v = nodes[0, 1] - p0, nodes[1, 0] - p0
    if abs(float(u[0] * v[1] - u[1] * v[0])) <= 1e-12 * float(u @ u + v @ v):
        return None
    want = p0 + np.arange(nx)[None, :, None] * u + np.arange(ny)[:, None, None] * v
    tol = _SPACING_TOL * max(1.0, float(np.abs(nodes).max()))
    if float(np.abs(nodes - want).max()) > tol:
        return None
    return Grid(
        first_face=a,
        first_vertex=v0,
        nx=nx,
        ny=ny,
        x0=float(p0[0]),
        y0=float(p0[1]),
        u=(float(u[0]), float(u[1])),
        v=(float(v[0]), float(v[1])),
        z_max=float(scene.vertices[v0 : v0 + nx * ny, 2].max()),
        object_id=int(scene.object_id[a]),
        winding=winding,
    )


def _faces_match(faces: np.ndarray, v0: int, ny: int, nx: int) -> bool:
    """Whether ``faces`` are exactly the faces of an (ny, nx) node grid from vertex ``v0``."""
    f = faces.reshape(ny - 1, nx - 1, 2, 3)
    a = v0 + np.arange(ny - 1)[:, None] * nx + np.arange(nx - 1)[None, :]
    want = (
        (f[:, :, 0, 0] == a)
        & (f[:, :, 0, 1] == a + 1)
        & (f[:, :, 0, 2] == a + nx + 1)
        & (f[:, :, 1, 0] == a)
        & (f[:, :, 1, 1] == a + nx + 1)
        & (f[:, :, 1, 2] == a + nx)
    )
    return bool(want.all())
