"""The bathymetry bench in calibrated mode without the line-profile prior (the notes' column).

Run from the repository root:
``python docs/notes/2026-11-27-calibrated-beam/bench_no_line_prior.py --looks 1,0 --lines 1
--beam calibrated --out bench_no_line``
"""

import runpy
import sys
from pathlib import Path

from sonar_raster.inversion.surface import solve

solve.CALIBRATED_LINE_WEIGHT = 0.0
tools = Path(__file__).resolve().parents[3] / "tools"
sys.path.insert(0, str(tools))
sys.argv = [str(tools / "bench_bathymetry.py"), *sys.argv[1:]]
runpy.run_path(str(tools / "bench_bathymetry.py"), run_name="__main__")
