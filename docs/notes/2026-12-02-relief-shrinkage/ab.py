"""The surface fit's relief raw and shrunk (inversion.surface.shrink) on the bathymetry bench.

Each seabed is rendered and fitted once with the shrinkage off; the same fit is then shrunk
with each gain scale and scored beside it (``tools/bench_bathymetry.py``'s render, fit and
score). Usage: ``python ab.py SEABEDS LOOKS [SCALES]``, e.g. ``python ab.py
boulders,sand,mounds,trenches,patches,box 1 1,1.5,2``.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tools"))
import bench_bathymetry as bb  # noqa: E402

from sonar_raster.inversion.bottom import track_bottom  # noqa: E402
from sonar_raster.inversion.surface import solve  # noqa: E402
from sonar_raster.inversion.surface.shrink import shrink_relief  # noqa: E402


def shrunk(fits, scale: float):
    """The fits with their relief shrunk at gain scale ``scale``."""
    out = []
    for fit in fits:
        dx = float(np.median(np.diff(fit.x)))
        knot = 4 * bb.BIN  # the fit's Z knots at the finest level (solve.Z_KNOT_BINS)
        elevation = {
            side: shrink_relief(z, fit.elevation_std[side], knot, dx, bb.SPACING, scale)
            for side, z in fit.elevation.items()
        }
        out.append(dataclasses.replace(fit, elevation=elevation))
    return out


def main() -> None:
    """Print raw and shrunk scores per seabed."""
    seabeds, looks = sys.argv[1].split(","), float(sys.argv[2])
    scales = [float(s) for s in (sys.argv[3] if len(sys.argv) > 3 else "1,1.5").split(",")]
    solve.SHRINK_RELIEF = False
    for name in seabeds:
        field, tracks, images = bb.render(name, 200, looks, 1)
        baselines = [track_bottom(sides, bb.BIN).altitude for sides in images]
        fits = bb.fit(tracks, images, True)
        rel, flat, corr, cover = bb.score(field, fits, baselines)
        row = [f"{name:9s} L={looks:g} flat {flat:.3f}"]
        row.append(f"raw {rel:.3f} corr {corr:.2f} 1σ {cover:.2f}")
        for scale in scales:
            rel, _, corr, cover = bb.score(field, shrunk(fits, scale), baselines)
            row.append(f"×{scale:g} {rel:.3f} corr {corr:.2f} 1σ {cover:.2f}")
        print("  ".join(row), flush=True)


if __name__ == "__main__":
    main()
