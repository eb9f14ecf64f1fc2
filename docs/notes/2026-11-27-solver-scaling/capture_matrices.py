"""Save the Gauss-Newton matrices of one bench fit (the first of each level) as .npz files.

Run from the repository root:
``python docs/notes/2026-11-27-solver-scaling/capture_matrices.py mounds 600`` writes
``lhs_coarse.npz`` and ``lhs_fine.npz`` here (the cwd), for ``factor_vs_multigrid.py``.
"""

import sys
from pathlib import Path

import scipy.sparse as sp

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tools"))
import bench_bathymetry as bb  # noqa: E402

from sonar_raster.inversion.surface import solve  # noqa: E402

caught = []
original = solve._preconditioner


def capture(lhs):
    """Keep a copy of each matrix the fit preconditions."""
    caught.append(lhs.copy())
    return original(lhs)


solve._preconditioner = capture
field, tracks, images = bb.render(sys.argv[1], int(sys.argv[2]), 1.0, 1)
bb.fit(tracks, images, True)
sizes = sorted({m.shape[0] for m in caught})
for name, n in zip(("coarse", "fine"), sizes, strict=False):
    sp.save_npz(f"lhs_{name}.npz", next(m for m in caught if m.shape[0] == n).tocsc())
print("knots per level:", sizes)
