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
