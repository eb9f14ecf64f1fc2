"""The whole real file's surface inversion, timed; the notes' "whole real file" numbers.

Run from the repository root, once per path (one process each, for the peak memory):
``python docs/notes/2026-11-27-solver-scaling/real_file_lu_vs_multigrid.py lu OUT_DIR`` and
``... multigrid OUT_DIR2``.
"""

import resource
import sys
import time

from sonar_raster.cli.app import main
from sonar_raster.inversion.surface import solve

XTF = "/work/shared/data/xtf/scotsman-iver2.xtf"

if sys.argv[1] == "lu":
    solve.AMG_KNOTS = 1 << 62
start = time.perf_counter()
rc = main(["invert", XTF, "--method", "surface", "-o", sys.argv[2], "-q"])
seconds = time.perf_counter() - start
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(f"{sys.argv[1]}: exit {rc}, {seconds:.1f} s, peak {peak:.0f} MB")
