"""The bottom tracker on the default scene rendered with each sensor preset's sonar.

Renders ``default`` with ``--sensor NAME`` (its range, bins, beam and tilt; 120 pings), with and
without ``--ideal``, into DIR, tracks both sides (``track_bottom``) and prints the median
altitude's error against the scene's 8 m.

Run: ``python docs/notes/2026-11-29-first-return/presets_track.py DIR``.
"""

import subprocess
import sys
from pathlib import Path

import numpy as np

from sonar_raster.effects.presets import PRESETS
from sonar_raster.inversion.bottom import track_bottom
from sonar_raster.io.images import read_exr

out = Path(sys.argv[1])
out.mkdir(parents=True, exist_ok=True)
for name in PRESETS:
    for extra in ([], ["--ideal"]):
        path = out / f"{name}{'_ideal' if extra else ''}.exr"
        cmd = [sys.executable, "-m", "sonar_raster", "render", "default", "--sensor", name]
        cmd += ["--pings", "120"]
        subprocess.run([*cmd, "-o", str(path), "-q", *extra], check=True)
        sides, meta = read_exr(path)
        rb = float(meta["sonar:range_bin_m"])
        track = track_bottom({s: np.asarray(v, float) for s, v in sides.items()}, rb)
        err = float(np.median(track.altitude)) - 8.0
        kind = "ideal" if extra else "real "
        print(f"{name:22s} {kind} bin {100 * rb:5.2f} cm, error {100 * err:+6.1f} cm")
