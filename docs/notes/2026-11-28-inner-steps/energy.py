"""A clean bench seabed's last-level objective at the fit and at the true Z, by part.

Run from the repository root: ``python docs/notes/2026-11-28-inner-steps/energy.py [SEABED]
[LOOKS]`` (default ``flat 0``). R and Φ are re-fitted at both (300 L-BFGS iterations, Z held);
the true Z knots are the least-squares spline through the true heights at every cell. Prints
the total, the data term, the Z priors (with the line prior and the anchor), the R and Φ
priors, and log Φ less the true beam's (aligned on 30–70°) at each node above 75°.
"""

import sys
from pathlib import Path
from unittest import mock

import numpy as np
from scipy.sparse import vstack
from scipy.sparse.linalg import lsqr

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tools"))
import bench_bathymetry as bb  # noqa: E402

from sonar_raster.inversion.surface import problem as pm  # noqa: E402
from sonar_raster.inversion.surface import solve  # noqa: E402

name = sys.argv[1] if len(sys.argv) > 1 else "flat"
field, tracks, images = bb.render(name, 200, float(sys.argv[2]) if len(sys.argv) > 2 else 0.0)
last = {}
gauss_newton = solve._gauss_newton


def kept(problem, p, steps, report=None):
    """The Gauss-Newton loop, its problem and result kept."""
    out = gauss_newton(problem, p, steps, report)
    last["problem"], last["p"] = problem, out[0]
    return out


def true_knots(problem):
    """Z knots of the true seabed: least squares through every view's cells."""
    rows, rhs = [], []
    for v in problem.views:
        y, x = v.points
        rows.append(v.bz)
        rhs.append((field.height_at(x, y) - bb.ALT + v.height[:, None]).ravel())
    a, b, flat = vstack(rows).tocsr(), np.concatenate(rhs), problem.flat.ravel()
    return lsqr(a, b - a @ flat, damp=1e-3, atol=1e-12, btol=1e-12, iter_lim=5000)[0] + flat


with mock.patch.object(solve, "_gauss_newton", kept):
    bb.fit(tracks, images, True)
problem, fitted = last["problem"], last["p"]
free = np.zeros(problem.size, bool)
free[problem.nz :] = True
true = fitted.copy()
true[: problem.nz] = true_knots(problem)
true = solve._minimise(problem, true, 300, free, problem.held_z(true))[0]
fitted = solve._minimise(problem, fitted, 300, free, problem.held_z(fitted))[0]
angles = np.linspace(*problem.grid.angles, problem.grid.nodes)
degrees = np.degrees(angles)
for label, p in (("fit", fitted), ("truth", true)):
    zc, rc, lphi = problem.split(p)
    data = 0.0
    for view in problem.views:
        z, r, beam = problem.fields(p, view)
        data += pm.view_objective(view, r, beam.phi, z)[0]
    z_priors = problem.z_priors(zc, np.zeros(problem.size))
    line = pm.line_profile(problem, (zc - problem.flat).ravel())[0]
    anchor = problem._anchor(zc)[0]
    rb = problem.reflectivity_beam_priors(rc, lphi, np.zeros(problem.size))
    print(
        f"{label:5s} total {problem(p)[0]:.1f} data {data:.1f} Z priors {z_priors:.1f} (line "
        f"{line:.1f}, anchor {anchor:.1f}) R and Φ priors {rb:.1f}"
    )
    for side, values in lphi.items():
        d = values - np.log(bb.SONAR.gain(angles))
        d -= np.median(d[(degrees > 30) & (degrees < 70)])
        shown = " ".join(f"{a:.0f}°:{v:+.2f}" for a, v in zip(degrees, d, strict=True) if a > 75)
        print(f"  log Φ less the true beam, {side}: {shown}")
