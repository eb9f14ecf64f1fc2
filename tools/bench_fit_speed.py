"""Speed of the surface fit at the issue's size, new path against the baseline in one process.

A benchmark, not a test: it prints a table and asserts nothing. It renders one of
``tools/bench_bathymetry.py``'s seabeds at ``--pings`` pings × ``--bins`` range bins of 5 cm per
side (single-look speckle, the seabed mesh at 0.1 m cells, 12 m altitude) and fits it with
``fit_lines(finest=N)`` (``invert --coarsen N``), uncertainty included, once per variant:

- **baseline**: the fit before 2026-11-28 as far as it can be switched back: the inner L-BFGS
  on R and Φ after each Gauss-Newton step evaluates the whole objective (``Problem.held_z``
  returning the problem itself), each step's conjugate gradients preconditioned for the
  Gauss-Newton matrix without the line prior (no ``solve._deflated``), one thread. (Not
  switched back: the views' Z and R bases shared where their knots coincide and the
  products' flat seabed taken from the fit, together ~2 s at this size.)
- **held**, **steps** (the deflation), **threads**: the baseline with one change each;
- **previous**: the package as it was at the end of 2026-11-28's session 21, as far as it can
  be switched back: energy-minimising prolongation and two Gauss-Seidel sweeps each way in
  the V-cycle, the uncertainty's preconditioner and products in float64, each deflated step's
  preconditioner making two products with the Gauss-Newton matrix
  (:func:`_deflated_by_products`), the views' Fisher matrices one after the other
  (:func:`_fisher_one_by_one`), the Jacobian without the cast shadows' change
  (``solve.SHADOW_JACOBIAN = False``, as before session 23). (Not switched back: the
  uncertainty's per-view threads, the tensor bases' index type, the draws' spread in float32;
  together ~2 s at this size.)
- **alternating**: the package as it is with each Gauss-Newton step on Z alone, Φ held
  (``solve.JOINT_BEAM = False``, as before 2026-11-29's session 28; the joint step applies
  only where ``--finest`` is 1 or 2, so at the default 4 the two are the same);
- **nadir-crest**: the package as it is with the first return's crest gap measured at the
  nadir (``solve.CREST_SHIFTS = None``, as before 2026-11-29's session 29; only fits with
  ``--finest`` 1 or 2 move it, so at the default 4 the two are the same);
- **new**: the package as it is.

Per variant: fit seconds (with the uncertainty), seconds in the inner minimisation, in the
Gauss-Newton conjugate gradients (and their iterations, mean / most), in the uncertainty, Z
RMSE over the relief std as the bathymetry bench (the fit moves with rounding-level changes,
so differences below ~0.05 are noise) and the ratio to the baseline's seconds.

Usage: ``python tools/bench_fit_speed.py [--pings 1000] [--bins 2000] [--finest 4]
[--seabed sand] [--variants baseline,held,steps,threads,previous,alternating,nadir-crest,new]``.
"""

from __future__ import annotations

import math
import time
from contextlib import ExitStack
from functools import partial
from unittest import mock

import bench_bathymetry as bb
import numpy as np
import scipy.sparse.linalg as sla
from _common import parser

from sonar_raster.inversion.bottom import track_bottom
from sonar_raster.inversion.surface import problem as problem_module
from sonar_raster.inversion.surface import solve
from sonar_raster.inversion.surface.layout import Line
from sonar_raster.sonar import BeamPattern, Sonar

#: What each variant changes from the package as it is.
VARIANTS = {
    "baseline": {"held": False, "steps": False, "threads": 1},
    "held": {"held": True, "steps": False, "threads": 1},
    "steps": {"held": False, "steps": True, "threads": 1},
    "threads": {"held": False, "steps": False, "threads": None},
    "previous": {"held": True, "steps": True, "threads": None, "previous": True},
    "alternating": {"held": True, "steps": True, "threads": None},
    "nadir-crest": {"held": True, "steps": True, "threads": None, "joint": True, "nadir": True},
    "new": {"held": True, "steps": True, "threads": None, "joint": True},
}
#: The multigrid settings before 2026-11-28's second speed pass.
TWO_SWEEPS = {
    "smooth": "energy",
    "presmoother": ("gauss_seidel", {"sweep": "symmetric", "iterations": 2}),
    "postsmoother": ("gauss_seidel", {"sweep": "symmetric", "iterations": 2}),
}


def _deflated_by_products(problem, lhs, precondition):
    """``solve._deflated`` as it was: ``A Q`` not kept, two products with ``A`` per use."""
    from scipy.linalg import cho_factor, cho_solve

    q, hq = problem.line_subspace()
    coarse = cho_factor(q.T @ np.asarray(lhs @ q) + q.T @ hq)
    matvec = partial(solve._gn_matvec, problem, lhs)

    def apply(r):
        exact = q @ cho_solve(coarse, q.T @ r)
        rest = precondition(r - matvec(exact))
        return exact + rest - q @ cho_solve(coarse, q.T @ matvec(rest))

    return apply


def _fisher_one_by_one(problem, p):
    """``solve._fisher_z`` as it was: the views' Jacobians and products one after the other."""
    h = None
    for view in problem.views:
        jac = solve._view_jacobians(problem, p, False, view)[0]
        block = (jac.T @ jac).tocsc()
        h = block if h is None else h + block
    for root in solve._prior_roots(problem):
        h = h + (root.T @ root).tocsc()
    return h.tocsc()


class _Meter:
    """Times the inner minimisation, the Gauss-Newton CG and the uncertainty; counts CG."""

    def __init__(self) -> None:
        self.seconds = {"inner": 0.0, "cg": 0.0, "std": 0.0}
        self.iterations: list[int] = []

    def timed(self, name: str, original):
        def wrapped(*args, **kwargs):
            start = time.perf_counter()
            try:
                return original(*args, **kwargs)
            finally:
                self.seconds[name] += time.perf_counter() - start

        return wrapped

    def cg(self, original):
        def wrapped(a, b, **kwargs):
            steps: list[object] = []
            start = time.perf_counter()
            out = original(a, b, callback=steps.append, **kwargs)
            self.seconds["cg"] += time.perf_counter() - start
            self.iterations.append(len(steps))
            return out

        return wrapped


def render(seabed: str, pings: int, bins: int):
    """The bench's seabed and sonar at ``bins`` bins of 5 cm per side and 12 m altitude."""
    bb.RANGE = bins * bb.BIN
    bb.ALT = 12.0
    bb.CELL = 0.1
    bb.SONAR = Sonar(
        max_range=bb.RANGE,
        range_bin=bb.BIN,
        beam=BeamPattern.gaussian(50.0),
        tilt=math.radians(20.0),
        sides=("port", "starboard"),
    )
    return bb.render(seabed, pings, 1.0)


def run(field, tracks, images, finest: int, variant: dict) -> dict:
    meter = _Meter()
    lines = [
        Line(s, bb.BIN, t.positions[:, :2], t.headings) for t, s in zip(tracks, images, strict=True)
    ]
    with ExitStack() as stack:
        patch = stack.enter_context
        if not variant["held"]:
            patch(mock.patch.object(problem_module.Problem, "held_z", lambda self, p: self))
        if not variant["steps"]:
            patch(mock.patch.object(solve, "_deflated", lambda problem, lhs, plain: plain))
        if variant.get("previous"):
            patch(mock.patch.object(solve, "AMG", TWO_SWEEPS))
            patch(mock.patch.object(solve, "UNCERTAINTY_DTYPE", np.float64))
            patch(mock.patch.object(solve, "_deflated", _deflated_by_products))
            patch(mock.patch.object(solve, "_fisher_z", _fisher_one_by_one))
            patch(mock.patch.object(solve, "SHADOW_JACOBIAN", False))
        if not variant.get("joint"):  # every variant but new and nadir-crest steps on Z alone
            patch(mock.patch.object(solve, "JOINT_BEAM", False))
        if variant.get("nadir"):
            patch(mock.patch.object(solve, "CREST_SHIFTS", None))
        if variant["threads"] is not None:
            patch(mock.patch.object(problem_module, "THREADS", variant["threads"]))
        patch(mock.patch.object(solve, "_minimise", meter.timed("inner", solve._minimise)))
        patch(mock.patch.object(solve, "elevation_std", meter.timed("std", solve.elevation_std)))
        patch(mock.patch.object(sla, "cg", meter.cg(sla.cg)))
        start = time.perf_counter()
        fits = solve.fit_lines(lines, finest=finest)
        seconds = time.perf_counter() - start
    baselines = [track_bottom(s, bb.BIN).altitude for s in images]
    score = bb.score(field, fits, baselines)[0]
    return {"s": seconds, "meter": meter, "score": score}


def main() -> None:
    cli = parser(__doc__)
    cli.add_argument("--seabed", default="sand", choices=sorted(bb.SEABEDS))
    cli.add_argument("--pings", type=int, default=1000)
    cli.add_argument("--bins", type=int, default=2000)
    cli.add_argument("--finest", type=int, default=4)
    cli.add_argument("--variants", default="baseline,new")
    args = cli.parse_args()
    names = args.variants.split(",")
    unknown = sorted(set(names) - set(VARIANTS))
    if unknown:
        cli.error(f"unknown variants {unknown}; choose from {sorted(VARIANTS)}")
    start = time.perf_counter()
    field, tracks, images = render(args.seabed, args.pings, args.bins)
    print(
        f"{args.seabed}, {args.pings} pings x {args.bins} bins per side, finest {args.finest}"
        f" (render {time.perf_counter() - start:.0f} s)"
    )
    print(
        f"{'variant':>9} {'fit s':>6} {'inner s':>7} {'CG s':>5} {'CG its':>7} {'std s':>6}"
        f" {'Z/std':>6} {'ratio':>6}"
    )
    first = None
    for name in names:
        r = run(field, tracks, images, args.finest, VARIANTS[name])
        m = r["meter"]
        first = first or r["s"]
        its = f"{np.mean(m.iterations):.0f}/{max(m.iterations)}" if m.iterations else "-"
        print(
            f"{name:>9} {r['s']:6.1f} {m.seconds['inner']:7.1f} {m.seconds['cg']:5.1f}"
            f" {its:>7} {m.seconds['std']:6.1f} {r['score']:6.3f} {first / r['s']:5.2f}x",
            flush=True,
        )


if __name__ == "__main__":
    main()
