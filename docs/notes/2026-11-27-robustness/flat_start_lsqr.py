"""Iterations and seconds of the flat start's lsqr in one bench fit (sand, single look).

Run from the repository root: ``python docs/notes/2026-11-27-robustness/flat_start_lsqr.py``
"""

import sys
import time
from pathlib import Path

import scipy.sparse.linalg as sla

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tools"))
import bench_bathymetry as bb  # noqa: E402

lsqr = sla.lsqr


def timed(a, b, **options):
    """Scipy's lsqr, timed and its iterations printed."""
    start = time.perf_counter()
    out = lsqr(a, b, **options)
    print(f"lsqr: A {a.shape}, {out[2]} iterations, {time.perf_counter() - start:.2f} s")
    return out


sla.lsqr = timed  # problem.flat_start_knots imports it from here at call time
field, tracks, images = bb.render("sand", 200, 1.0, 1)
start = time.perf_counter()
bb.fit(tracks, images, True)
print(f"fit {time.perf_counter() - start:.1f} s")
