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


class TooManyPieces(Exception):
    """Subdivision stopped: it would make more pieces than asked for (``args[0]`` so far)."""


def subdivide_within(
    tri: np.ndarray,
    max_edge: float,
    box: tuple[float, ...],
    most: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Split triangles until no edge exceeds ``max_edge``, keeping only pieces near a box.

    Each round halves every piece still too long at the midpoint of its longest edge (the
    two halves keep the parent's orientation) and drops the pieces whose bounding box misses
    ``x0 <= x <= x1, y0 <= y <= y1, z0 <= z <= z1``; so a triangle kilometres wide, or a wall
    kilometres tall, costs what the box holds. Longest-edge bisection keeps the pieces' angles
    bounded by the triangle's (no slivers beyond its own: the raster resolves slivers badly
    near nadir), and halves a right triangle into similar ones.

    Parameters
    ----------
    tri : ndarray, shape (m, 3, 3)
        Triangle corners.
    max_edge : float
        Longest edge allowed after subdivision, metres.
    box : tuple of float
        ``(x0, x1, y0, y1, z0, z1)``.
    most : int, optional
        Raise :class:`TooManyPieces` once more pieces than this are made or in the making.

    Returns
    -------
    pieces : ndarray, shape (p, 3, 3)
    parent : ndarray, shape (p,), int64
        Index of each piece's triangle; a triangle wholly outside the box has none.
    """
    lower, upper = np.asarray(box[0::2]), np.asarray(box[1::2])
    pieces, parent = np.asarray(tri, dtype=np.float64), np.arange(len(tri))
    done, done_parent = [], []
    limit = max_edge * max_edge
    while len(pieces):
        near = np.all((pieces.max(axis=1) >= lower) & (pieces.min(axis=1) <= upper), axis=1)
        pieces, parent = pieces[near], parent[near]
        edges = np.stack([pieces[:, (k + 1) % 3] - pieces[:, k] for k in range(3)], axis=1)
        length2 = np.einsum("mkj,mkj->mk", edges, edges)
        short = length2.max(axis=1) <= limit
        done.append(pieces[short])
        done_parent.append(parent[short])
        pieces, parent, length2 = pieces[~short], parent[~short], length2[~short]
        made = sum(len(d) for d in done) + 2 * len(pieces)
        if most is not None and made > most:
            raise TooManyPieces(made)
        # longest edge k runs from corner k to k+1; the opposite corner is k+2
        k = np.argmax(length2, axis=1)
        rows = np.arange(len(pieces))
        a, b, c = (pieces[rows, (k + j) % 3] for j in range(3))
        mid = 0.5 * (a + b)
        pieces = np.concatenate([np.stack([a, mid, c], 1), np.stack([mid, b, c], 1)])
        parent = np.concatenate([parent, parent])
    return np.concatenate(done), np.concatenate(done_parent)
