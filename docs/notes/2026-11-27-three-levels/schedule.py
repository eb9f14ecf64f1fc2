"""Gauss-Newton steps per level, against today's 8 on each: the bench's scores and seconds.

Run from the repository root on main (2026-11-27, 189ee76), e.g.
``python docs/notes/2026-11-27-three-levels/schedule.py sand,box "8,8;8,4;8,3;8,2;8,4,2"``:
each plan is the steps of each level, coarse to fine, and sets the number of levels. Without
``three-levels.patch`` a three-level plan finds objects on the coarsest level (pooled 4 × 4).
"""

import sys
import time
from functools import partial
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tools"))
import bench_bathymetry as bb  # noqa: E402

from sonar_raster.inversion.bottom import track_bottom  # noqa: E402
from sonar_raster.inversion.surface import solve  # noqa: E402

original = solve._gauss_newton
schedule: list[int] = []


def scheduled(problem, p, steps, report=None):
    """The Gauss-Newton loop with the next level's steps from the plan."""
    return original(problem, p, schedule.pop(0), report)


solve._gauss_newton = scheduled
seabeds = sys.argv[1].split(",")
plans = sys.argv[2].split(";")
pings = int(sys.argv[3]) if len(sys.argv) > 3 else 200
for name in seabeds:
    field, tracks, images = bb.render(name, pings, 1.0)
    baselines = [track_bottom(sides, bb.BIN).altitude for sides in images]
    for plan in plans:
        steps = [int(s) for s in plan.split(",")]
        schedule[:] = steps
        bb.fit_lines = partial(solve.fit_lines, levels=len(steps))
        start = time.perf_counter()
        fits = bb.fit(tracks, images, True)
        seconds = time.perf_counter() - start
        rel, flat, corr, cover = bb.score(field, fits, baselines)
        print(
            f"{name:9s} {plan:8s} fit {rel:.3f} flat {flat:.3f} corr {corr:.2f} "
            f"1sigma {cover:.2f} {seconds:6.1f} s",
            flush=True,
        )
