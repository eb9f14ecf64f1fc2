"""The bench's boulders, single look: the fit's error near the boulders and away from them.

``python docs/notes/2026-11-29-anchor-looks/boulders.py [LOOKS]``: per side the rms error over
all scored cells, within 20 cells of a boulder and away from them (with its mean), and away
from them by 4 m bands of ground range.
"""

import sys
from pathlib import Path

import numpy as np
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tools"))
import bench_bathymetry as bench  # noqa: E402

looks = float(sys.argv[1]) if len(sys.argv) > 1 else 1.0
field, tracks, images = bench.render("boulders", 200, looks, 1)
fit = bench.fit(tracks, images, True)[0]
x = fit.x
keep = (x > 1.0) & (x < x[-1] - 2.0)
for side in fit.elevation:
    where = fit.position[side][:, keep]
    t = field.height_at(where[..., 0], where[..., 1]) - bench.ALT
    e = fit.elevation[side][:, keep] - t
    near = ndimage.binary_dilation(t > -bench.ALT + 0.01, iterations=20)

    def rms(v):
        """Root mean square, cm."""
        return 100 * np.sqrt(np.mean(v**2))

    print(
        f"{side}: rms {rms(e):.2f} cm, near boulders {rms(e[near]):.2f} cm "
        f"({100 * near.mean():.0f} % of cells), away {rms(e[~near]):.2f} cm "
        f"(mean {100 * e[~near].mean():+.2f} cm)"
    )
    for lo in (1, 4, 8, 12, 16, 20, 24):
        band = (x[keep] >= lo) & (x[keep] < lo + 4)
        away = e[:, band][~near[:, band]]
        print(f"  {lo}-{lo + 4} m: away rms {rms(away):.2f} cm, mean {100 * away.mean():+.2f} cm")
