"""cProfile of one bench fit (sand, single look, one line); the notes' time breakdown.

Run from the repository root: ``python docs/notes/2026-11-27-robustness/profile_one_fit.py``
"""

import cProfile
import pstats
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tools"))
import bench_bathymetry as bb  # noqa: E402

field, tracks, images = bb.render("sand", 200, 1.0, 1)
cProfile.run("fits = bb.fit(tracks, images, True)", "fit.prof")
pstats.Stats("fit.prof").sort_stats("tottime").print_stats(22)
