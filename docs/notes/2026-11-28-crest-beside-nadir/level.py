"""One-off: the crest offset a bench fit takes off the tracked altitude, and the gaps behind it.

``python docs/notes/2026-11-28-crest-beside-nadir/level.py SEABED LOOKS`` (a seabed of
``tools/bench_bathymetry.py``, 1 or 0 looks). Prints the offset the true level needs (12 m less
the data's median tracked altitude), the model's crest gap at the nadir per Gauss-Newton step
and the offset taken, the fit's bias, and, at the last level, the gap of the model's seabed
moved in from 0-4 m beside the nadir, at the fit and at the true Z (R and Φ the fit's).
Needs ``crest_beside_nadir.patch`` (beside this script) applied: ``model_first_return``'s
``shift``; with ``solve.CREST_SHIFTS = ()`` set at the top it measures main's fit (the table of
the notes' first section came from an earlier form of this script on main).
"""

import math
import sys
from pathlib import Path
from unittest import mock

import numpy as np
from scipy.sparse import vstack
from scipy.sparse.linalg import lsqr

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tools"))
import bench_bathymetry as bb  # noqa: E402

from sonar_raster.inversion.bottom import track_bottom  # noqa: E402
from sonar_raster.inversion.surface import solve  # noqa: E402

name, looks = sys.argv[1], float(sys.argv[2])
field, tracks, images = bb.render(name, 200, looks)
alt = float(np.median(track_bottom(images[0], bb.BIN).altitude))
print(f"{name} {looks:g}: tracked altitude {alt:.4f} m, needed offset {100 * (alt - 12):+.2f} cm")
steps, last = [], {}
track_model, gauss_newton = solve._track_model, solve._gauss_newton


def spy(problem, p):
    """The package's crest offset, and the nadir's own gap beside it."""
    track_model(problem, p)
    seen, depth = solve.model_first_return(problem, p, 0)
    steps.append((float(np.nanmedian(seen - depth)), problem.anchor_offset[0]))


def kept(problem, p, steps, report=None):
    """The Gauss-Newton loop, its problem and result kept."""
    out = gauss_newton(problem, p, steps, report)
    last["problem"], last["p"] = problem, out[0]
    return out


with mock.patch.object(solve, "_track_model", spy):
    with mock.patch.object(solve, "_gauss_newton", kept):
        fit = bb.fit(tracks, images, True)[0]
print("nadir gap per step, cm:", " ".join(f"{100 * g:+.1f}" for g, _ in steps))
print("offset per step, cm:   ", " ".join(f"{100 * o:+.1f}" for _, o in steps))
keep = (fit.x > 1.0) & (fit.x < fit.x[-1] - 2.0)
for side in fit.elevation:
    where = fit.position[side][:, keep]
    truth = field.height_at(where[..., 0], where[..., 1]) - bb.ALT
    error = fit.elevation[side][:, keep] - truth
    print(f"{side}: bias {100 * error.mean():+.1f} cm, rms about it {100 * error.std():.1f} cm")

problem, p = last["problem"], last["p"]
height = bb.SEABEDS[name][0]
rows, rhs = [], []
for v in problem.views:
    y, x = v.points
    rows.append(v.bz)
    rhs.append((height(x, y, 200 * bb.SPACING) - bb.ALT + v.height[:, None]).ravel())
a, b, flat = vstack(rows).tocsr(), np.concatenate(rhs), problem.flat.ravel()
true = p.copy()
true[: problem.nz] = lsqr(a, b - a @ flat, damp=1e-2, atol=1e-12, btol=1e-12)[0] + flat
h = float(np.nanmedian(problem.views[0].altitude))
for d in (0.0, 1.5, 2.0, 3.0, 4.0):
    gaps = []
    for q in (p, true):
        seen, depth = solve.model_first_return(problem, q, 0, d)
        gaps.append(100 * float(np.nanmedian(seen - depth)))
    print(
        f"{d} m ({d / h:.2f} h) out: gap at the fit {gaps[0]:+.1f} cm, at the truth {gaps[1]:+.1f}"
    )
assert math.isfinite(h)
