"""Uniform barycentric subdivision of triangles whose longest edge exceeds a size."""

from __future__ import annotations

from functools import lru_cache

import numpy as np


@lru_cache(maxsize=64)
def _pattern(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Barycentric (u, v) of the n² sub-triangles' corners, shape (n², 3, 2), orientation kept."""
    tris = []
    for i in range(n):
        for j in range(n - i):
            tris.append(((i, j), (i + 1, j), (i, j + 1)))
            if i + j <= n - 2:
                tris.append(((i + 1, j), (i + 1, j + 1), (i, j + 1)))
    return np.asarray(tris, dtype=np.float64) / n, np.asarray(n)


def subdivision_counts(vertices: np.ndarray, faces: np.ndarray, max_edge: float) -> np.ndarray:
    """Pieces per edge for each face: ceil(longest edge / max_edge), at least 1.

    Parameters
    ----------
    vertices : ndarray, shape (n, 3)
    faces : ndarray, shape (m, 3), int
    max_edge : float
        Longest edge allowed after subdivision, metres.
    """
    counts = np.empty(len(faces), dtype=np.int64)
    block = 1 << 20  # faces at a time: bounds the temporaries for huge scenes
    for s in range(0, len(faces), block):
        f = faces[s : s + block]
        corners = [vertices[f[:, k]] for k in range(3)]
        longest2 = np.zeros(len(f))
        for a, b in ((0, 1), (1, 2), (2, 0)):
            d = corners[b] - corners[a]
            np.maximum(
                longest2, d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2], out=longest2
            )
        counts[s : s + block] = np.maximum(1, np.ceil(np.sqrt(longest2) / max_edge))
    return counts


def subdivide(tri: np.ndarray, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split each triangle ``k`` into ``counts[k]**2`` congruent pieces.

    Parameters
    ----------
    tri : ndarray, shape (m, 3, 3)
        Triangle corners.
    counts : ndarray, shape (m,), int
        Pieces per edge for each triangle.

    Returns
    -------
    pieces : ndarray, shape (p, 3, 3)
        Sub-triangle corners, same orientation as their parent.
    parent : ndarray, shape (p,), int64
        Index of each piece's parent triangle.
    """
    if len(tri) == 0:
        return np.empty((0, 3, 3)), np.empty(0, dtype=np.int64)
    out, parents = [], []
    for n in np.unique(counts):
        idx = np.nonzero(counts == n)[0]
        if n == 1:
            out.append(tri[idx])
            parents.append(idx)
            continue
        uv, _ = _pattern(int(n))
        t = tri[idx]
        e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
        pts = (
            t[:, None, None, 0]
            + uv[None, :, :, 0, None] * e1[:, None, None]
            + uv[None, :, :, 1, None] * e2[:, None, None]
        )
        out.append(pts.reshape(-1, 3, 3))
        parents.append(np.repeat(idx, len(uv)))
    order = np.argsort(np.concatenate(parents), kind="stable")
    return np.concatenate(out)[order], np.concatenate(parents)[order]


def subdivide_within(
    tri: np.ndarray,
    max_edge: float,
    box: tuple[float, float, float, float],
    split: int = 16,
) -> tuple[np.ndarray, np.ndarray]:
    """Subdivide triangles to ``max_edge``, keeping only pieces that reach into a box.

    Each triangle is cut into ``split²`` congruent pieces (:func:`subdivide`), the pieces whose
    bounding rectangle misses the vertical box ``x0 <= x <= x1, y0 <= y <= y1`` are dropped,
    and the rest cut again until their edges are short enough; so a triangle kilometres wide
    costs what the box holds, and every piece is similar to its triangle (no slivers, which
    the raster resolves badly near nadir).

    Parameters
    ----------
    tri : ndarray, shape (m, 3, 3)
        Triangle corners.
    max_edge : float
        Longest edge allowed after subdivision, metres.
    box : tuple of float
        ``(x0, x1, y0, y1)``.
    split : int
        Pieces per edge of each coarse cut.

    Returns
    -------
    pieces : ndarray, shape (p, 3, 3)
    parent : ndarray, shape (p,), int64
        Index of each piece's triangle; a triangle wholly outside the box has none.
    """
    x0, x1, y0, y1 = box
    pieces, parent = np.asarray(tri, dtype=np.float64), np.arange(len(tri))
    while True:
        flat = pieces.reshape(-1, 3)
        counts = subdivision_counts(flat, np.arange(len(flat)).reshape(-1, 3), max_edge)
        coarse = np.minimum(counts, split)
        if np.all(counts <= split):
            pieces, within = subdivide(pieces, counts)
            return pieces, parent[within]
        pieces, within = subdivide(pieces, coarse)
        parent = parent[within]
        lo, hi = pieces[:, :, :2].min(axis=1), pieces[:, :, :2].max(axis=1)
        near = (hi[:, 0] >= x0) & (lo[:, 0] <= x1) & (hi[:, 1] >= y0) & (lo[:, 1] <= y1)
        pieces, parent = pieces[near], parent[near]
