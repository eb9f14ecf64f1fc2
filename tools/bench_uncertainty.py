"""Speed of the surface fit's Laplace uncertainty: one solve per sample against all at once.

A benchmark, not a test: it prints a table and asserts nothing. Both paths take the same
precision ``H`` and the same 32 right-hand sides (``surface.solve.laplace_draws``) on one
bench seabed (``tools/bench_bathymetry.py``'s renders: 200 pings, 30 m in 5 cm bins, single-look
speckle), at a flat seabed at the first returns (R = 1, Φ at the image's mean; the matrices'
size and structure are the fit's, their values need not be its optimum):

* baseline (the code before 2026-11-27): the diagonal blocks' LU factors one after the other,
  then ``scipy.sparse.linalg.cg`` on one sample at a time, each iteration one triangular solve
  per block and right-hand side;
* new (``surface.solve._symmetric_solver``): incomplete LU factors of the two blocks
  (``BLOCK_ILU``) made in two threads, then conjugate gradients on every sample side by side
  (one sparse product and one multi-right-hand-side triangular solve per iteration), to the
  same tolerance, so the draws agree to about the tolerance (not to rounding).

Rows: Z and log R together (what ``fit_lines`` uses) and Z alone (``reflectivity=False``: one
LU, then its solves). Wall seconds, best of ``--repeats``; ``draws`` is the largest
``|Z draw new − old|`` over the largest ``|Z draw old|``; ``std max / median`` the largest and
the median relative difference of the cells' Z std (``surface.solve.draws_std``, what
``elevation_std`` returns) between the two paths.

Usage: ``python tools/bench_uncertainty.py [--seabed sand] [--pings 200] [--repeats 2]``.
"""

from __future__ import annotations

import math
import time

import numpy as np
from _common import parser
from bench_bathymetry import BIN, render
from scipy.sparse.linalg import LinearOperator, cg, splu

from sonar_raster.inversion.surface import Line
from sonar_raster.inversion.surface import solve as surface_solve
from sonar_raster.inversion.surface.solve import (
    SYMMETRIC_LU,
    draws_std,
    laplace_draws,
    problem_at,
)


def baseline(h, nz: int, rhs: np.ndarray) -> np.ndarray:
    """The solves as they were: per sample, with the blocks factorised one after the other."""
    if h.shape[0] == nz:
        lu = splu(h, **SYMMETRIC_LU)
        return np.stack([lu.solve(rhs[:, k]) for k in range(rhs.shape[1])], axis=1)
    blocks = [splu(h[:nz, :nz].tocsc(), **SYMMETRIC_LU), splu(h[nz:, nz:].tocsc(), **SYMMETRIC_LU)]

    def precondition(v: np.ndarray) -> np.ndarray:
        return np.concatenate([blocks[0].solve(v[:nz]), blocks[1].solve(v[nz:])])

    pre = LinearOperator(h.shape, matvec=precondition)
    return np.stack(
        [cg(h, rhs[:, k], M=pre, rtol=1e-3, maxiter=200)[0] for k in range(rhs.shape[1])], axis=1
    )


def main() -> None:
    cli = parser(__doc__)
    cli.add_argument("--seabed", default="sand")
    cli.add_argument("--pings", type=int, default=200)
    cli.add_argument("--repeats", type=int, default=2)
    args = cli.parse_args()
    _, tracks, images = render(args.seabed, args.pings, 1.0)
    lines = [
        Line(s, BIN, t.positions[:, :2], t.headings) for t, s in zip(tracks, images, strict=True)
    ]
    problem = problem_at(lines)
    p = np.zeros(problem.size)
    p[: problem.nz] = problem.flat.ravel()
    for side in problem.grid.sides:
        values = np.concatenate([v.image[v.mask] for v in problem.views if v.side == side])
        p[problem.phi_slice(side)] = math.log(float(np.mean(values)))
    nz = problem.nz
    print(f"{args.seabed}, {args.pings} pings: {nz} Z knots, {problem.nr} log R knots, 32 samples")
    print(
        f"{'unknowns':12s} {'old s':>7s} {'new s':>7s} {'ratio':>6s} {'draws':>8s} "
        f"{'std max':>8s} {'median':>8s}"
    )
    for label, reflectivity in (("Z and log R", True), ("Z alone", False)):
        h, rhs = laplace_draws(problem, p, 32, reflectivity=reflectivity)
        best = {"old": math.inf, "new": math.inf}
        out = {}
        for _ in range(args.repeats):  # interleaved
            for name in ("old", "new"):
                start = time.perf_counter()
                if name == "old":
                    out[name] = baseline(h, nz, rhs)[:nz]
                else:
                    out[name] = surface_solve._symmetric_solver(h, nz)(rhs)[:nz]
                best[name] = min(best[name], time.perf_counter() - start)
        diff = np.max(np.abs(out["new"] - out["old"])) / np.max(np.abs(out["old"]))
        stds = {name: draws_std(problem, knots) for name, knots in out.items()}
        rel = np.concatenate(
            [np.ravel(np.abs(stds["new"][k] / stds["old"][k] - 1.0)) for k in stds["old"]]
        )
        print(
            f"{label:12s} {best['old']:7.2f} {best['new']:7.2f} "
            f"{best['old'] / best['new']:6.2f} {diff:8.1e} {rel.max():8.1e} {np.median(rel):8.1e}",
            flush=True,
        )


if __name__ == "__main__":
    main()
