"""Profiles against the surface on the bathymetry bench's single-look one-line seabeds.

The same renders and cells for both (the notes' table). Run from the repository root:
``python docs/notes/2026-11-27-robustness/profiles_vs_surface.py sand,mounds,box`` (any of
sand, mounds, trenches, patches, boulders, box). Since 2026-11-28 it runs
``../2026-11-28-auto-method/profiles_vs_looks.py 1 SEABEDS``, the same script with the looks
as an argument.
"""

import runpy
import sys
from pathlib import Path

sys.argv = [sys.argv[0], "1", *sys.argv[1:]]
here = Path(__file__).resolve().parents[1]
runpy.run_path(str(here / "2026-11-28-auto-method" / "profiles_vs_looks.py"), run_name="__main__")
