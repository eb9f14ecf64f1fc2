"""One captured Gauss-Newton matrix: SuperLU (symmetric mode) against smoothed aggregation.

``python docs/notes/2026-11-27-solver-scaling/factor_vs_multigrid.py lhs_fine.npz``: the LU's
factorisation time and fill, and for three multigrid settings the set-up time and the CG
iterations and time to relative residuals 1e-2, 1e-3, 1e-5 (error against the LU's solution).
"""

import sys
import time

import numpy as np
import pyamg
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from sonar_raster.inversion.surface.solve import AMG, SYMMETRIC_LU

a = sp.load_npz(sys.argv[1]).tocsr()
b = np.random.default_rng(0).standard_normal(a.shape[0])
print("knots", a.shape[0], "entries", a.nnz)
start = time.perf_counter()
lu = sla.splu(a.tocsc(), **SYMMETRIC_LU)
print(f"LU: factor {time.perf_counter() - start:.2f} s, fill {lu.L.nnz + lu.U.nnz}")
exact = lu.solve(b)
settings = {
    "defaults": {},
    "theta 0, energy": {"strength": ("symmetric", {"theta": 0.0}), "smooth": "energy"},
    "kept (solve.AMG)": AMG,
}
for name, kwargs in settings.items():
    start = time.perf_counter()
    hierarchy = pyamg.smoothed_aggregation_solver(a, **kwargs)
    setup = time.perf_counter() - start
    m = hierarchy.aspreconditioner(cycle="V")
    for rtol in (1e-2, 1e-3, 1e-5):
        steps = []
        start = time.perf_counter()
        x, _ = sla.cg(a, b, M=m, rtol=rtol, maxiter=300, callback=steps.append)
        error = np.linalg.norm(x - exact) / np.linalg.norm(exact)
        print(
            f"{name}: set-up {setup:.2f} s; rtol {rtol:g}: {len(steps)} iterations, "
            f"{time.perf_counter() - start:.2f} s, error {error:.1e}"
        )
