"""Speed of the surface fit's linear algebra, new path against the baseline in one process.

A benchmark, not a test: it prints a table and asserts nothing. Each ping count renders one of
``tools/bench_bathymetry.py``'s seabeds (one line, single-look speckle by default) and fits it
twice:

- **baseline**: every Gauss-Newton step preconditioned by the complete sparse LU whatever the
  size (``solve.AMG_KNOTS`` above the knots), and the line-profile prior from its ping-by-ping
  definition (``problem.line_profile_reference``: three products the size of the image per view
  and call) — the fit before 2026-11-27;
- **new**: the package as it is (multigrid above ``AMG_KNOTS`` knots, the line profile from
  averages made once per set of objects).

Per run: Z knots at full resolution, fit seconds, seconds in the preconditioners' set-up
(factorisation or multigrid hierarchy) and in the line-profile prior, the largest
preconditioner's storage (LU fill or hierarchy, 12 bytes per entry), conjugate-gradient
iterations per step (mean / most), Z RMSE over the relief std (as the bathymetry bench; the
fit moves with rounding-level changes, so differences below ~0.05 are noise) and the ratio.

Usage: ``python tools/bench_surface_solver.py [--seabed mounds] [--pings 200,600] [--looks 1]``.
"""

from __future__ import annotations

import time
from contextlib import ExitStack
from unittest import mock

import bench_bathymetry as bb
import numpy as np
import pyamg
import scipy.sparse.linalg as sla
from _common import parser

from sonar_raster.inversion.surface import problem as problem_module
from sonar_raster.inversion.surface import solve


class _Meter:
    """Wraps the preconditioner, the line profile and CG to time and count them."""

    def __init__(self) -> None:
        self.setup_s = self.line_s = 0.0
        self.storage = 0
        self.iterations: list[int] = []

    def preconditioner(self, original):
        def wrapped(lhs):
            start = time.perf_counter()
            apply = original(lhs)
            self.setup_s += time.perf_counter() - start
            self.storage = max(self.storage, _storage(apply))
            return apply

        return wrapped

    def multigrid(self, original):
        def wrapped(*args, **kwargs):
            hierarchy = original(*args, **kwargs)
            self.storage = max(self.storage, _hierarchy_storage(hierarchy))
            return hierarchy

        return wrapped

    def line_profile(self, original):
        def wrapped(problem, dev):
            start = time.perf_counter()
            out = original(problem, dev)
            self.line_s += time.perf_counter() - start
            return out

        return wrapped

    def cg(self, original):
        def wrapped(a, b, **kwargs):
            steps: list[object] = []
            out = original(a, b, callback=steps.append, **kwargs)
            self.iterations.append(len(steps))
            return out

        return wrapped


def _storage(apply) -> int:
    """Bytes of a preconditioner's LU factors (values and indices, 12 per entry); 0 if none."""
    owner = getattr(apply, "__self__", None)
    return 12 * int(owner.L.nnz + owner.U.nnz) if hasattr(owner, "L") else 0


def _hierarchy_storage(hierarchy) -> int:
    """Bytes of a multigrid hierarchy: every level's operator and transfers, 12 per entry."""
    entries = 0
    for level in hierarchy.levels:
        for name in ("A", "P", "R"):
            entries += int(getattr(getattr(level, name, None), "nnz", 0))
    return 12 * entries


def _knots(tracks, images) -> int:
    """Z knots of the full-resolution level, from its grid (without making its problem)."""
    lines = [
        bb.Line(s, bb.BIN, t.positions[:, :2], t.headings)
        for t, s in zip(tracks, images, strict=True)
    ]
    _, _, grids = solve._setup(lines, "auto", None, None, 1)
    ky, kx = (len(k) for k in grids[-1][1].knots("z"))
    return ky * kx


def run(field, tracks, images, baseline: bool) -> dict:
    meter = _Meter()
    with ExitStack() as stack:
        patch = stack.enter_context
        timed = meter.preconditioner(solve._preconditioner)
        patch(mock.patch.object(solve, "_preconditioner", timed))
        patch(mock.patch.object(sla, "cg", meter.cg(sla.cg)))
        amg = pyamg.smoothed_aggregation_solver
        patch(mock.patch.object(pyamg, "smoothed_aggregation_solver", meter.multigrid(amg)))
        line = problem_module.line_profile_reference if baseline else problem_module.line_profile
        line = meter.line_profile(line)
        patch(mock.patch.object(problem_module, "line_profile", line))
        patch(mock.patch.object(solve, "line_profile", line))
        if baseline:
            patch(mock.patch.object(solve, "AMG_KNOTS", 1 << 62))
        start = time.perf_counter()
        fits = bb.fit(tracks, images, True)
        seconds = time.perf_counter() - start
    altitude = [np.asarray(f.altitude) for f in fits]
    score = bb.score(field, fits, altitude)[0]
    return {"s": seconds, "meter": meter, "score": score}


def main() -> None:
    cli = parser(__doc__)
    cli.add_argument("--seabed", default="mounds", choices=sorted(bb.SEABEDS))
    cli.add_argument("--pings", default="200,600")
    cli.add_argument("--looks", type=float, default=1.0, help="speckle looks (0: none)")
    args = cli.parse_args()
    print(
        f"{'pings':>5} {'knots':>6} {'run':>8} {'fit s':>6} {'setup s':>7} {'line s':>6} "
        f"{'precond MB':>10} {'CG its':>7} {'Z/std':>6}"
    )
    warm = bb.render(args.seabed, 20, args.looks, 1)  # imports and caches, before any timing
    run(*warm, baseline=False)
    for pings in (int(p) for p in args.pings.split(",")):
        field, tracks, images = bb.render(args.seabed, pings, args.looks, 1)
        knots = _knots(tracks, images)
        rows = {}
        for name in ("baseline", "new"):
            rows[name] = r = run(field, tracks, images, name == "baseline")
            m = r["meter"]
            its = f"{np.mean(m.iterations):.0f}/{max(m.iterations)}"
            print(
                f"{pings:>5} {knots:>6} {name:>8} {r['s']:6.1f} {m.setup_s:7.1f} "
                f"{m.line_s:6.1f} {m.storage / 2**20:10.0f} {its:>7} {r['score']:6.3f}",
                flush=True,
            )
        ratio = rows["baseline"]["s"] / rows["new"]["s"]
        print(f"{pings:>5} {knots:>6} {'ratio':>8} {ratio:6.2f}x", flush=True)


if __name__ == "__main__":
    main()
