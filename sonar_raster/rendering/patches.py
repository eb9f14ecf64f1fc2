"""Patches of subdivided triangles, clipped to a box, in chunks.

Triangle ``f`` is cut into ``n_f²`` equal sub-triangles (patches) by uniform barycentric
subdivision. The patches are indexed on an ``n × n`` square grid ``(i, j)``: cells with
``i + j <= n − 1`` are the upright pieces, with centroid barycentric coordinates
``a = (i + 1/3) / n``, ``b = (j + 1/3) / n``; cells with ``i + j >= n`` are the inverted
pieces, with centroid ``(1 − a, 1 − b)``. Along a row (fixed ``i``, one half) a centroid is
affine in ``j``, so each row is clipped to a box analytically, leaving one run of consecutive
cells, widened by one cell at each end (a caller that needs the exact test makes it per
patch). Rows are generated a block of triangles at a time and the runs handed out in chunks of
about a fixed number of patches, so memory stays bounded on any scene.

Shared by the patch reference (:mod:`sonar_raster.rendering.reference`) and the coherent model's
scatterer generation (:mod:`sonar_raster.rendering.coherent.scatter`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, fields, replace

import numpy as np

#: Coordinate change (metres) below which a subdivision row counts as constant.
_FLAT_ROW = 1e-9

#: Components of vectors (k, 3) along the rows of axes (3, 3), giving shape (k, 3).
Rotate = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Runs:
    """Runs of consecutive patches along subdivision rows (one triangle, row ``i``, one half).

    Attributes
    ----------
    tri : ndarray, shape (q,), int64
        Triangle of each run, as an index into the ``ids`` given to :func:`runs_in_box`.
    i : ndarray, shape (q,), int64
        Subdivision row.
    lo : ndarray, shape (q,), int64
        Cell ``j`` of the run's first patch.
    length : ndarray, shape (q,), int64
        Patches in the run, >= 1.
    base : ndarray, shape (q, 3)
        Centroid of the row's cell ``j = 0`` (box coordinates, metres); cell ``j`` has
        centroid ``base + slope * j``.
    slope : ndarray, shape (q, 3)
        Centroid offset from one cell of the row to the next, metres.
    sign : ndarray, shape (q,)
        +1 for upright pieces, -1 for inverted ones (their edges point the other way).
    """

    tri: np.ndarray
    i: np.ndarray
    lo: np.ndarray
    length: np.ndarray
    base: np.ndarray
    slope: np.ndarray
    sign: np.ndarray

    def select(self, keep: np.ndarray | slice) -> Runs:
        """The runs selected by a mask, index array or slice."""
        return Runs(*(getattr(self, f.name)[keep] for f in fields(self)))

    def chunks(self, size: int) -> Iterator[Runs]:
        """Split into consecutive groups of whole runs with about ``size`` patches each."""
        if len(self.length) == 0:
            return
        ends = np.cumsum(self.length)
        cuts = np.searchsorted(ends, np.arange(size, ends[-1], size), side="left") + 1
        edges = [0, *cuts.tolist(), len(ends)]
        for lo, hi in zip(edges[:-1], edges[1:], strict=True):
            if hi > lo:
                yield self.select(slice(lo, hi))

    def cells(self) -> tuple[np.ndarray, np.ndarray]:
        """Run of every patch and its place in the run (``j − lo``), both shape (p,), int64."""
        run = np.repeat(np.arange(len(self.length)), self.length)
        offset = np.arange(len(run)) - (np.cumsum(self.length) - self.length)[run]
        return run, offset


def _matmul(v: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """Components of vectors ``v`` (k, 3) along the rows of ``axes`` by a matrix product."""
    return v @ axes.T


def project(
    tri: np.ndarray, origin: np.ndarray, axes: np.ndarray, rotate: Rotate = _matmul
) -> np.ndarray:
    """Corner 0 and edges 1, 2 of triangles in box coordinates.

    Parameters
    ----------
    tri : ndarray, shape (m, 3, 3)
        Corners, metres.
    origin : ndarray, shape (3,)
        Origin of the box coordinates, metres.
    axes : ndarray, shape (3, 3)
        Rows are the unit axes of the box coordinates.
    rotate : callable, optional
        ``rotate(v, axes)`` gives the components of vectors ``v`` (k, 3) along ``axes``;
        default a matrix product.

    Returns
    -------
    ndarray, shape (m, 3 coords, 3 = p0, e1, e2)
    """
    p0 = rotate(tri[:, 0] - origin, axes)
    e1 = rotate(tri[:, 1] - tri[:, 0], axes)
    e2 = rotate(tri[:, 2] - tri[:, 0], axes)
    return np.stack([p0, e1, e2], axis=2)


def overlaps(proj: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """Triangles whose coordinate box meets ``bounds``, shape (m,) bool.

    Parameters
    ----------
    proj : ndarray, shape (m, 3, 3)
        Triangles from :func:`project`.
    bounds : ndarray, shape (3, 2)
        Box (min, max per coordinate), metres.
    """
    corners = np.stack(
        [proj[:, :, 0], proj[:, :, 0] + proj[:, :, 1], proj[:, :, 0] + proj[:, :, 2]], axis=2
    )
    lo, hi = corners.min(axis=2), corners.max(axis=2)
    return np.all((hi >= bounds[:, 0]) & (lo <= bounds[:, 1]), axis=1)


def runs_in_box(
    proj: np.ndarray,
    n_sub: np.ndarray,
    ids: np.ndarray,
    bounds: np.ndarray,
    *,
    row_block: int,
    chunk: int,
) -> Iterator[Runs]:
    """Yield the runs of patches of triangles ``ids`` that may lie in ``bounds``, in chunks.

    Parameters
    ----------
    proj : ndarray, shape (m, 3, 3)
        Triangles from :func:`project`.
    n_sub : ndarray, shape (m,), int64
        Subdivisions per edge.
    ids : ndarray, shape (k,), int64
        Triangles to subdivide (those :func:`overlaps` keeps).
    bounds : ndarray, shape (3, 2)
        Box (min, max per coordinate), metres.
    row_block : int
        Subdivision rows clipped at once (whole triangles, so a block may exceed it).
    chunk : int
        Patches per yielded group of runs (whole runs, so a group may exceed it by one row).

    Yields
    ------
    Runs
        Runs whose ``tri`` indexes ``ids``.
    """
    if len(ids) == 0:
        return
    rows = np.cumsum(n_sub[ids])
    starts = np.searchsorted(rows, np.arange(0, rows[-1], row_block), side="right")
    for lo, hi in zip(starts, [*starts[1:], len(ids)], strict=True):
        if hi <= lo:
            continue
        block = ids[lo:hi]
        runs = _row_runs(proj[block], n_sub[block], bounds)
        yield from replace(runs, tri=runs.tri + lo).chunks(chunk)


def _row_runs(proj: np.ndarray, n_sub: np.ndarray, bounds: np.ndarray) -> Runs:
    """Clip every subdivision row (both halves) of the triangles ``proj`` to ``bounds``."""
    tri = np.repeat(np.arange(len(n_sub)), n_sub)
    i = np.arange(len(tri)) - (np.cumsum(n_sub) - n_sub)[tri]
    n = n_sub[tri].astype(np.float64)
    p = proj[tri]
    a = (i + 1.0 / 3.0) / n
    third = 1.0 / (3.0 * n)
    halves = (
        # upright pieces: centroid (a, b), j in [0, n - 1 - i]
        (p[:, :, 1] * a[:, None] + p[:, :, 2] * third[:, None], 1.0, np.zeros_like(n), n - 1 - i),
        # inverted pieces: centroid (1 - a, 1 - b), j in [n - i, n - 1]
        (p[:, :, 1] * (1 - a)[:, None] + p[:, :, 2] * (1 - third)[:, None], -1.0, n - i, n - 1),
    )
    parts = []
    for offset, sign, j_min, j_max in halves:
        base = p[:, :, 0] + offset
        slope = sign * p[:, :, 2] / n[:, None]
        lo, hi = _clip_rows(base, slope, bounds, j_min, j_max)
        ok = hi >= lo
        parts.append(
            Runs(
                tri=tri[ok],
                i=i[ok],
                lo=lo[ok].astype(np.int64),
                length=(hi - lo + 1)[ok].astype(np.int64),
                base=base[ok],
                slope=slope[ok],
                sign=np.full(int(ok.sum()), sign),
            )
        )
    return Runs(*(np.concatenate([getattr(r, f.name) for r in parts]) for f in fields(Runs)))


def _clip_rows(
    base: np.ndarray, slope: np.ndarray, bounds: np.ndarray, j_min: np.ndarray, j_max: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Intersect [j_min, j_max] with ``lo_c <= base[:, c] + slope[:, c] j <= hi_c`` for each c.

    Returns the float ``(lo, hi)`` bounds of j per row, each widened by one cell; ``hi < lo``
    where a row misses the box.
    """
    lo, hi = j_min.copy(), j_max.copy()
    span = np.maximum(j_max, 0.0) + 2.0  # j runs from 0 (base) to at most j_max
    for c in range(3):
        b_lo, b_hi = bounds[c]
        s = slope[:, c]
        # a row whose coordinate moves less than a nanometre is constant along it
        flat = np.abs(s) * span <= _FLAT_ROW
        safe = np.where(flat, 1.0, s)
        j1 = (b_lo - base[:, c]) / safe
        j2 = (b_hi - base[:, c]) / safe
        lo = np.where(flat, lo, np.maximum(lo, np.floor(np.minimum(j1, j2)) - 1.0))
        hi = np.where(flat, hi, np.minimum(hi, np.ceil(np.maximum(j1, j2)) + 1.0))
        outside = flat & ((base[:, c] < b_lo - _FLAT_ROW) | (base[:, c] > b_hi + _FLAT_ROW))
        hi = np.where(outside, lo - 1.0, hi)
    return lo, np.maximum(hi, lo - 1.0)
