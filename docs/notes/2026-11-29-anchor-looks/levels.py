"""Per seabed of the bench: the score, the level error and the score with the level removed.

``python docs/notes/2026-11-29-anchor-looks/levels.py sand,mounds,... [ANCHOR_BINS]``: single
look then clean; the level is the mean of fit − truth over the scored cells, the level-free
score their std over the relief's. A second argument sets ``problem.ANCHOR_BINS``.
"""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tools"))
import bench_bathymetry as bench  # noqa: E402

from sonar_raster.inversion.surface import problem  # noqa: E402


def level_errors(field, fit):
    """Fit − truth over the bench's scored cells (both sides), and the truth there."""
    keep = (fit.x > 1.0) & (fit.x < fit.x[-1] - 2.0)
    t, f = [], []
    for side in fit.elevation:
        where = fit.position[side][:, keep]
        t.append((field.height_at(where[..., 0], where[..., 1]) - bench.ALT).ravel())
        f.append(fit.elevation[side][:, keep].ravel())
    t = np.concatenate(t)
    return np.concatenate(f) - t, t


if __name__ == "__main__":
    if len(sys.argv) > 2:
        problem.ANCHOR_BINS = float(sys.argv[2])
    for looks in (1, 0):
        for name in sys.argv[1].split(","):
            field, tracks, images = bench.render(name, 200, looks, 1)
            e, t = level_errors(field, bench.fit(tracks, images, True)[0])
            std = t.std()
            print(
                f"{name:9s} looks {looks}: score {np.sqrt(np.mean(e**2)) / std:.3f}, level "
                f"{100 * e.mean():+.2f} cm, level-free {e.std() / std:.3f}",
                flush=True,
            )
