"""The anchor's crest gap and trust at each Gauss-Newton step on the bench's sand waves.

``python docs/notes/2026-11-29-anchor-looks/crest_trace.py LOOKS`` (0: clean). Prints, per
step, the anchor's offset (what comes off the tracked altitude), the trust and the gap at the
nadir, the model's mean depth over the nadir's fold against the tracked altitude; then the
score and the level error (mean of fit − truth over the scored cells).
"""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tools"))
sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_bathymetry as bench  # noqa: E402
from levels import level_errors  # noqa: E402

from sonar_raster.inversion.surface import solve  # noqa: E402

original = solve._track_model


def traced(problem, p, shifts=None):
    """The anchor's offset as ``solve._track_model`` sets it, and its parts, printed."""
    original(problem, p, shifts)
    for line, lead in problem.anchored.items():
        seen, depth = solve.model_first_return(problem, p, line)
        v = problem.views[lead]
        ok = np.isfinite(seen) & np.isfinite(v.altitude)
        a, b = (v.height - seen)[ok], (v.height - v.altitude)[ok]
        a, b = a - a.mean(), b - np.median(b)
        trust = min(max(float(np.sum(a * b)) / float(np.sum(a * a)), 0.0), 1.0)
        gap = float(np.median((seen - depth)[ok]))
        print(
            f"  knots {problem.nz}: offset {100 * problem.anchor_offset[line]:+.2f} cm, trust "
            f"{trust:.2f}, nadir gap {100 * gap:+.2f} cm, model depth {np.mean(depth):.4f} m, "
            f"tracked {np.nanmean(v.altitude):.4f} m",
            flush=True,
        )


solve._track_model = traced
field, tracks, images = bench.render("sand", 200, float(sys.argv[1]), 1)
e, t = level_errors(field, bench.fit(tracks, images, True)[0])
print(f"score {np.sqrt(np.mean(e**2)) / t.std():.3f}, level {100 * e.mean():+.2f} cm")
