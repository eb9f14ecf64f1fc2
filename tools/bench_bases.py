"""Speed of the surface fit's spline bases: closed-form cubic rows against scipy's design matrix.

A benchmark, not a test: it prints a table and asserts nothing. For each point count it builds
the tensor B-spline basis of :func:`sonar_raster.inversion.surface.layout.tensor_basis` at
random points of a 100 m × 200 m grid with 0.2 m knots (the full-resolution cells of a
1000-ping × 2000-bin side), by

- **baseline**: the 1-D rows from ``scipy.interpolate.BSpline.design_matrix`` (a knot search
  per point), sorted by row with ``np.lexsort`` to pair each row's 4 weights — the package
  before 2026-11-27;
- **new**: the package's closed-form rows (:func:`.layout.cubic_rows`);

best of ``--repeat`` runs each, and prints seconds, the ratio and the largest difference.

Usage: ``python tools/bench_bases.py [--points 1000000,4000000] [--repeat 3]``.
"""

from __future__ import annotations

import math
import time

import numpy as np
from _common import parser
from scipy import sparse
from scipy.interpolate import BSpline

from sonar_raster.inversion.surface.layout import tensor_basis

EXTENT = (0.0, 100.0, -99.3, 99.3)
SPACING = 0.2


def _design(points: np.ndarray, start: float, stop: float, spacing: float) -> sparse.coo_matrix:
    spans = max(1, int(math.ceil((stop - start) / spacing - 1e-9)))
    t = start + spacing * np.arange(-3, spans + 4, dtype=np.float64)
    return BSpline.design_matrix(np.clip(points, t[3], t[spans + 3]), t, 3).tocoo()


def baseline(y: np.ndarray, x: np.ndarray) -> sparse.csr_matrix:
    """The tensor basis as the package built it before: design matrices, then a sort."""
    y0, y1, x0, x1 = EXTENT
    by, bx = _design(y, y0, y1, SPACING), _design(x, x0, x1, SPACING)
    n, kx = len(y), bx.shape[1]
    ay, ax = np.lexsort((by.col, by.row)), np.lexsort((bx.col, bx.row))
    cy, vy = by.col[ay].reshape(n, 4), by.data[ay].reshape(n, 4)
    cx, vx = bx.col[ax].reshape(n, 4), bx.data[ax].reshape(n, 4)
    cols = (cy[:, :, None] * kx + cx[:, None, :]).reshape(n, 16)
    vals = (vy[:, :, None] * vx[:, None, :]).reshape(n, 16)
    indptr = np.arange(0, 16 * n + 1, 16)
    return sparse.csr_matrix((vals.ravel(), cols.ravel(), indptr), shape=(n, by.shape[1] * kx))


def main() -> None:
    cli = parser(__doc__)
    cli.add_argument("--points", default="1000000,4000000")
    cli.add_argument("--repeat", type=int, default=3)
    args = cli.parse_args()
    rng = np.random.default_rng(0)
    print(f"{'points':>9s} {'baseline s':>10s} {'new s':>7s} {'ratio':>6s} {'max diff':>9s}")
    for n in (int(v) for v in args.points.split(",")):
        y = rng.uniform(EXTENT[0], EXTENT[1], n)
        x = rng.uniform(EXTENT[2], EXTENT[3], n)
        times = {}
        out = {}
        for name, build in (
            ("baseline", baseline),
            ("new", lambda y, x: tensor_basis(y, x, EXTENT, SPACING)),
        ):
            best = math.inf
            for _ in range(args.repeat):
                start = time.perf_counter()
                out[name] = build(y, x)
                best = min(best, time.perf_counter() - start)
            times[name] = best
        diff = abs(out["baseline"] - out["new"]).max()
        print(
            f"{n:9d} {times['baseline']:10.2f} {times['new']:7.2f} "
            f"{times['baseline'] / times['new']:6.1f} {diff:9.1e}",
            flush=True,
        )


if __name__ == "__main__":
    main()
