"""The bathymetry bench's single-line rows with the joint step's trust region varied.

Run: ``python docs/notes/2026-11-29-trust-region/bench_variants.py VARIANT [--seabeds sand,box]
[--looks 1,0]`` from the repository root, VARIANT one of ``trust`` (the default since
2026-11-29), ``held`` (the radius held at ``JOINT_STEP_BINS``: the default before) and
``uncapped`` (no radius). It also fits the tests' flat clean seabeds (60 pings at 6.0125 and
6.0 m), whose rms the one-bin start guards, and prints each level's steps: (level's knots,
radius in bins, bound by it, backtracking factor, actual over predicted decrease).
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[3]
sys.path[:0] = [str(ROOT / "tools"), str(ROOT / "tests" / "inversion")]

import bench_bathymetry as bench  # noqa: E402
import test_surface  # noqa: E402

from sonar_raster.inversion import surface  # noqa: E402
from sonar_raster.inversion.bottom import track_bottom  # noqa: E402
from sonar_raster.inversion.surface import solve  # noqa: E402

cli = argparse.ArgumentParser(description=__doc__.splitlines()[0])
cli.add_argument("variant", choices=("trust", "held", "uncapped"))
cli.add_argument("--seabeds", default="sand,mounds,trenches,patches,boulders,box")
cli.add_argument("--looks", default="1,0")
args = cli.parse_args()

steps: list[tuple] = []
plain = solve._trust_radius


def traced(radius, rho, backtracked, capped):
    """The package's radius update (held in ``held``), each step recorded."""
    steps.append((round(radius, 2), capped, backtracked, round(rho, 2)))
    return radius if args.variant == "held" else plain(radius, rho, backtracked, capped)


solve._trust_radius = traced
if args.variant == "uncapped":
    solve.JOINT_STEP_BINS = 1e9

for alt in (6.0125, 6.0):
    steps.clear()
    sides = test_surface._flat_render(alt)
    fit = surface.fit_surface(sides, 0.05, ping_spacing=0.1, uncertainty=False)
    keep = (fit.x > 0.5) & (fit.x < fit.x[-1] - 1.5)
    error = np.concatenate([fit.elevation[s][:, keep] + alt for s in fit.elevation]) * 100
    print(f"flat {alt} m: mean {np.mean(error):+.2f} cm, rms {np.sqrt(np.mean(error**2)):.2f} cm")
    print("  steps", steps, flush=True)
for name in args.seabeds.split(","):
    for looks in (float(v) for v in args.looks.split(",")):
        steps.clear()
        field, tracks, images = bench.render(name, 200, looks, 1)
        baselines = [track_bottom(sides, bench.BIN).altitude for sides in images]
        start = time.perf_counter()
        fits = bench.fit(tracks, images, True)
        seconds = time.perf_counter() - start
        rel, flat, _, coverage = bench.score(field, fits, baselines)
        score = f"fit {rel:.3f} flat {flat:.3f} 1σ {coverage:.2f}"
        print(f"{name} looks {looks:g}: {score} {seconds:.0f} s")
        print("  steps", steps, flush=True)
