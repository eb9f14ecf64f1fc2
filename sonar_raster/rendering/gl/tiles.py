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
        self.size = float(size)
        first = faces[:, 0]
        block = 1 << 20
        self.lo, hi = np.zeros(2), np.zeros(2)
        if len(faces):
            spans = [_span(vertices[first[a : a + block], :2]) for a in range(0, len(faces), block)]
            self.lo = np.min([lo for lo, _ in spans], axis=0)
            hi = np.max([h for _, h in spans], axis=0)
        self.shape = np.floor((hi - self.lo) / self.size).astype(np.int64) + 1
        nx, n_tiles = int(self.shape[0]), int(self.shape[0] * self.shape[1])
        # Tile of each face's first corner, a block at a time (huge scenes stay in memory).
        key = np.empty(len(faces), dtype=np.int32 if n_tiles < 2**31 else np.int64)
        for a in range(0, len(faces), block):
            xy = vertices[first[a : a + block], :2].astype(np.float64)
            cell = np.floor((xy - self.lo) / self.size).astype(np.int64)
            np.minimum(cell, self.shape - 1, out=cell)
            key[a : a + block] = cell[:, 1] * nx + cell[:, 0]
        order = np.argsort(key, kind="stable")
        self.order = order.astype(np.int32) if len(faces) < 2**31 else order
        del order
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


def _span(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return xy.min(axis=0).astype(np.float64), xy.max(axis=0).astype(np.float64)
