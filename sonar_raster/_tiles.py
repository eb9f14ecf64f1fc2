"""A grid index of triangles over the horizontal plane, for culling draws to their swath."""

from __future__ import annotations

import math

import numpy as np


class TileIndex:
    """Triangles bucketed by the tile (square, ``size`` metres) holding their first corner.

    A triangle's corners lie within its longest edge of the first one, so widening a query
    rectangle by the longest edge finds every triangle that reaches into it.

    Parameters
    ----------
    vertices : ndarray, shape (n, 3), float64
        Vertex coordinates, metres.
    faces : ndarray, shape (m, 3), int
        Triangle vertex indices.
    size : float
        Tile edge, metres (> 0).
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, size: float):
        corner = vertices[faces[:, 0], :2] if len(faces) else np.zeros((0, 2))
        self.size = float(size)
        self.lo = corner.min(axis=0) if len(corner) else np.zeros(2)
        cells = np.floor((corner - self.lo) / self.size).astype(np.int64)
        self.shape = (cells.max(axis=0) + 1) if len(cells) else np.ones(2, dtype=np.int64)
        nx = int(self.shape[0])
        key = cells[:, 1] * nx + cells[:, 0]
        self.order = np.argsort(key, kind="stable")
        n_tiles = int(self.shape[0] * self.shape[1])
        self.offsets = np.searchsorted(key[self.order], np.arange(n_tiles + 1))

    def query(
        self, xmin: float, xmax: float, ymin: float, ymax: float, margin: float
    ) -> np.ndarray:
        """Indices (ascending) of the triangles that may reach the rectangle, widened by margin."""
        nx, ny = int(self.shape[0]), int(self.shape[1])
        ix0 = max(0, math.floor((xmin - margin - self.lo[0]) / self.size))
        ix1 = min(nx - 1, math.floor((xmax + margin - self.lo[0]) / self.size))
        iy0 = max(0, math.floor((ymin - margin - self.lo[1]) / self.size))
        iy1 = min(ny - 1, math.floor((ymax + margin - self.lo[1]) / self.size))
        if ix0 > ix1 or iy0 > iy1:
            return np.zeros(0, dtype=np.int64)
        parts = [
            self.order[self.offsets[iy * nx + ix0] : self.offsets[iy * nx + ix1 + 1]]
            for iy in range(iy0, iy1 + 1)
        ]
        return np.sort(np.concatenate(parts))
