"""Gauss-Newton steps on the Z and log R knots together, then L-BFGS on R and Φ (or Φ only).

Replaces ``solve._gauss_newton`` for one run of the test's short sand waves (three draws):
``JOINT_INNER=5 python docs/notes/2026-11-27-three-levels/joint_steps.py`` (``JOINT_PHI_ONLY=1``:
the L-BFGS on Φ alone; ``JOINT=0``: the package's own steps). The joint matrix is the Laplace
uncertainty's (``solve._jacobians`` with R, the Z priors' and log R's roots), preconditioned by
the Z and log R diagonal blocks' own preconditioners.
"""

import os
import sys
import time
from pathlib import Path

import numpy as np
from scipy import sparse
from scipy.sparse.linalg import LinearOperator, cg

ROOT = Path(__file__).resolve().parents[3]
sys.path[:0] = [str(ROOT / "tests" / "inversion"), str(ROOT / "tests")]
import test_surface as ts  # noqa: E402

from sonar_raster.inversion.bottom import track_bottom  # noqa: E402
from sonar_raster.inversion.surface import fit_surface, solve  # noqa: E402
from sonar_raster.inversion.surface.problem import line_profile  # noqa: E402

INNER = int(os.environ.get("JOINT_INNER", "20"))
PHI_ONLY = os.environ.get("JOINT_PHI_ONLY", "0") == "1"


def _joint_matrix(problem, p):
    """Fisher matrix of the Z and log R knots plus their priors' Hessians."""
    nz, nr = problem.nz, problem.nr
    jz, jr = solve._jacobians(problem, p, True)
    jac = sparse.hstack([sparse.vstack(jz), sparse.vstack(jr)]).tocsr()
    h = (jac.T @ jac).tocsc()
    pad = sparse.csr_matrix
    for d in solve._prior_roots(problem):
        root = sparse.hstack([d, pad((d.shape[0], nr))]).tocsr()
        h = h + (root.T @ root).tocsc()
    for d in solve._reflectivity_roots(problem, p):
        root = sparse.hstack([pad((d.shape[0], nz)), d]).tocsr()
        h = h + (root.T @ root).tocsc()
    return h


def joint_gauss_newton(problem, p, steps, report=None):
    """``solve._gauss_newton`` with each step on Z and log R together."""
    nz, nr = problem.nz, problem.nr
    n = nz + nr
    free = np.zeros(problem.size, bool)
    free[n if PHI_ONLY else nz :] = True
    if solve.CREST_OFFSET:
        solve._track_model(problem, p)
    value, grad = problem(p)
    count, damping = 1, 1e-3
    for k in range(int(steps)):
        h = _joint_matrix(problem, p)
        diag = h.diagonal()
        lhs = (h + sparse.diags(damping * diag + 1e-12 * diag.mean())).tocsc()
        pz = solve._preconditioner(lhs[:nz, :nz].tocsc())
        pr = solve._preconditioner(lhs[nz:, nz:].tocsc())

        def matvec(v, lhs=lhs):
            out = np.asarray(lhs @ v)
            if problem.w_line > 0:
                out[:nz] += line_profile(problem, v[:nz])[1]
            return out

        def precondition(v, pz=pz, pr=pr):
            return np.concatenate([pz(v[:nz]), pr(v[nz:])])

        op = LinearOperator((n, n), matvec=matvec)
        step, _ = cg(op, -grad[:n], M=LinearOperator((n, n), matvec=precondition), maxiter=30)
        accepted = False
        for t in (1.0, 0.5, 0.25, 0.125):
            q = p.copy()
            q[:n] += t * step
            trial, g_trial = problem(q)
            count += 1
            if trial < value:
                p, value, grad, accepted = q, trial, g_trial, True
                break
        damping = damping * 0.3 if accepted else damping * 10.0
        if INNER:
            p, value, inner = solve._minimise(problem, p, INNER, free)
            count += inner
        if solve.CREST_OFFSET and k + 1 < steps:
            solve._track_model(problem, p)
            value, grad = problem(p)
        else:
            grad = problem(p)[1]
        if report is not None:
            report(k + 1, int(steps), value)
    return p, value, count


if os.environ.get("JOINT", "1") == "1":
    solve._gauss_newton = joint_gauss_newton
errors, start = [], time.perf_counter()
for seed in (1, 2, 3):
    field, track, sides, alt, rb, spacing = ts._sand_line(seed)
    baseline = track_bottom(sides, rb).altitude
    fit = fit_surface(sides, rb, ping_spacing=spacing, uncertainty=False)
    errors.append(ts._errors(fit, field, track, alt, baseline))
e = np.array(errors)
print(
    f"fit {np.round(e[:, 0], 3)} mean {e[:, 0].mean():.3f} flat {e[:, 1].mean():.3f} "
    f"{time.perf_counter() - start:.1f} s"
)
