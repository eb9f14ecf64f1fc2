"""Clean mounds of the bathymetry bench: the fit from a flat or a true start, the objective.

With ``robust_line_prior.patch`` (beside this script) applied (``git apply``; main does not
have the robust weights), run from the repository root: ``python
docs/notes/2026-11-28-robust-line-prior/mounds.py
[--looks 0] [--start flat|truth] [--plain]`` (``--plain``: the line prior's plain mean, i.e.
``LINE_ROBUST_SCALE = None``). Prints the bench's score, the error on the mounds' cells and on
the flat ones, then, at the last level's problem, the objective's parts at the fit and at the
true surface (R and Φ re-fitted with Z held), each with the line weights of the fit and of the
truth.
"""

import argparse
import sys
from pathlib import Path
from unittest import mock

import numpy as np
from scipy.sparse import vstack
from scipy.sparse.linalg import lsqr

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tools"))
import bench_bathymetry as bb  # noqa: E402

from sonar_raster.inversion.bottom import track_bottom  # noqa: E402
from sonar_raster.inversion.surface import problem as pm  # noqa: E402
from sonar_raster.inversion.surface import solve  # noqa: E402

cli = argparse.ArgumentParser()
cli.add_argument("--looks", type=float, default=0.0)
cli.add_argument("--start", choices=("flat", "truth"), default="flat")
cli.add_argument("--plain", action="store_true")
args = cli.parse_args()
if args.plain:
    pm.LINE_ROBUST_SCALE = None
PINGS = 200
field, tracks, images = bb.render("mounds", PINGS, args.looks)


def true_knots(problem):
    """Z knots of the true mounds: least squares through every view's cells."""
    rows, rhs = [], []
    for v in problem.views:
        y, x = v.points
        rows.append(v.bz)
        rhs.append((bb._mounds(x, y, PINGS * bb.SPACING) - bb.ALT + v.height[:, None]).ravel())
    a, b, flat = vstack(rows).tocsr(), np.concatenate(rhs), problem.flat.ravel()
    return lsqr(a, b - a @ flat, damp=1e-2, atol=1e-12, btol=1e-12, iter_lim=5000)[0] + flat


def free_beam(problem):
    """A mask of the log R and log Φ parameters."""
    free = np.zeros(problem.size, bool)
    free[problem.nz :] = True
    return free


start = solve._start


def true_start(problem):
    """The fit's start with Z at the true mounds and Φ re-fitted."""
    p = start(problem)
    p[: problem.nz] = true_knots(problem)
    free = np.zeros(problem.size, bool)
    free[problem.nz + problem.nr :] = True
    return solve._minimise(problem, p, 60, free)[0]


def data_term(problem, p, view):
    """The Gamma likelihood of one view at parameters ``p``."""
    z, r, beam = problem.fields(p, view)
    return pm.view_objective(view, r, beam.phi, z)[0]


last = {}
gauss_newton = solve._gauss_newton


def kept(problem, p, steps, report=None):
    """The Gauss-Newton loop, its problem and result kept."""
    out = gauss_newton(problem, p, steps, report)
    last["problem"], last["p"] = problem, out[0]
    return out


patches = [mock.patch.object(solve, "_gauss_newton", kept)]
if args.start == "truth":
    patches.append(mock.patch.object(solve, "_start", true_start))
for patch in patches:
    patch.start()
fits = bb.fit(tracks, images, True)
score = bb.score(field, fits, [track_bottom(s, bb.BIN).altitude for s in images])
inside, outside = [], []
for side in ("port", "starboard"):
    f = fits[0]
    keep = (f.x > 1.0) & (f.x < f.x[-1] - 2.0)
    pos = f.position[side][:, keep]
    truth = field.height_at(pos[..., 0], pos[..., 1]) - bb.ALT
    error = f.elevation[side][:, keep] - truth
    inside.append(error[truth + bb.ALT > 0.05])
    outside.append(error[truth + bb.ALT <= 0.05])
for name, e in (("mounds' cells", np.concatenate(inside)), ("flat cells", np.concatenate(outside))):
    print(f"{name}: rms {100 * np.sqrt(np.mean(e * e)):.1f} cm, mean {100 * e.mean():+.1f} cm")
print(f"score {score[0]:.3f}, correlation {score[2]:.2f}")

problem, fitted = last["problem"], last["p"]
true = fitted.copy()
true[: problem.nz] = true_knots(problem)
true = solve._minimise(problem, true, 200, free_beam(problem), problem.held_z(true))[0]
fitted = solve._minimise(problem, fitted, 200, free_beam(problem), problem.held_z(fitted))[0]
weights = {"the fit's": problem.line_weights}
weights["the truth's"] = pm.robust_line_weights(problem, problem.split(true)[0])
for which, w in weights.items():
    problem.line_weights = w
    print(f"line weights at {which} surface")
    for name, p in (("fit", fitted), ("truth", true)):
        zc, rc, lphi = problem.split(p)
        data = sum(data_term(problem, p, v) for v in problem.views)
        line = pm.line_profile(problem, (zc - problem.flat).ravel())[0]
        print(
            f"  {name:5s} total {problem(p)[0]:13.1f}, data {data:13.1f}, line prior {line:10.1f}"
        )
