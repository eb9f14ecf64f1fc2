"""The model's image of a flat, clean seabed at the true Z, R and Φ against the GL render.

Run from the repository root: ``python docs/notes/2026-11-28-inner-steps/nadir.py``. The
bench's geometry (``tools/bench_bathymetry.py``: 12 m altitude, 5 cm bins and cells); for the
tent deposit the render is blurred by ``solve.TENT_BLUR`` as the fit compares it, for the
segment deposit not. Prints the mean intensity per metre of slant range and of track, data and
model, and their log ratio per slant-range band.
"""

import math
import sys
from pathlib import Path

import numpy as np
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tools"))
import bench_bathymetry as bb  # noqa: E402

from sonar_raster.inversion import model  # noqa: E402
from sonar_raster.inversion.ground import ground_axis  # noqa: E402
from sonar_raster.inversion.surface import solve  # noqa: E402

BANDS = [(11.9, 12.0), (12.0, 12.05), (12.05, 12.1), (12.1, 12.2), (12.2, 12.5), (12.5, 13)]
BANDS += [(13, 14), (14, 16), (16, 20), (20, 29)]
field, tracks, images = bb.render("flat", 40, 0)
data = images[0]["starboard"][5:35] / bb.BIN / bb.SPACING
blurred = ndimage.convolve1d(data, solve.TENT_BLUR, axis=1, mode="nearest")
bins = data.shape[1]
centres = (np.arange(bins) + 0.5) * bb.BIN
for deposit in ("tent", "segment"):
    x = ground_axis(np.full(data.shape[0], bb.ALT), bb.BIN, bins, bb.BIN)
    z = np.full((data.shape[0], x.size), -bb.ALT)
    geom = model.Geometry(x, bb.BIN, bb.SPACING, bb.BIN, bins, solve.SUBSAMPLES, deposit)
    phi = np.broadcast_to(bb.SONAR.gain(np.arctan2(bb.ALT, x)), z.shape)
    modelled = model.forward(np.full_like(z, 0.5), phi, z, geom)
    reference = blurred if deposit == "tent" else data
    print(deposit)
    for lo, hi in BANDS:
        k = (centres > lo) & (centres < hi)
        a, b = reference[:, k].mean(), modelled[:, k].mean()
        ratio = math.log(max(a, 1e-30) / max(b, 1e-30))
        print(f"  slant {lo}-{hi} m: data {a:.4g} model {b:.4g} log ratio {ratio:+.3f}")
