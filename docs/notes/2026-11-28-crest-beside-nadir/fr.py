"""One-off: how far the data's first returns rise and fall along a bench line.

``python docs/notes/2026-11-28-crest-beside-nadir/fr.py``: per seabed of
``tools/bench_bathymetry.py`` (one line, port and starboard together as the tracker reads
them), single look and clean, the standard deviation of the tracked altitude less its running
mean over 101 pings (10 m), and of that less its running mean over 9 pings (the ping-to-ping
part).
"""

import sys
from pathlib import Path

from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tools"))
import bench_bathymetry as bb  # noqa: E402

from sonar_raster.inversion.bottom import track_bottom  # noqa: E402

for name in ["flat", "sand", "mounds", "trenches", "patches", "boulders", "box"]:
    for looks in (1.0, 0.0):
        _, _, images = bb.render(name, 200, looks)
        a = track_bottom(images[0], bb.BIN).altitude
        d = a - ndimage.uniform_filter1d(a, 101, mode="nearest")
        rough = d - ndimage.uniform_filter1d(d, 9, mode="nearest")
        print(
            f"{name:9s} {looks:g} looks: {100 * d.std():.2f} cm, per ping {100 * rough.std():.2f}"
        )
