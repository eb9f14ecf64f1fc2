"""The surface fit's tent deposit against the data's box bins blurred by ``TENT_BLUR`` near nadir.

A flat seabed at 8 m (the default scene's Gaussian 40° beam tilted 15°, 4 cm bins): the data
are the box-binned image (``deposit="segment"``, 1 mm cells) blurred by (0.25, 0.5, 0.25), as
``solve._level`` blurs an image; the model is the tent deposit on the fit's 2 cm points with
the level at 8 m and at the two tracked altitudes of the notes. Prints model / data for bins
198-209 (the true edge is the start of bin 200).

Run: ``python docs/notes/2026-11-29-first-return/tent_phase.py``.
"""

import math

import numpy as np
from scipy import ndimage

from sonar_raster.inversion import model
from sonar_raster.sonar import BeamPattern

BIN, SPACING, R = 0.04, 0.05, 0.3
BEAM, TILT = BeamPattern.gaussian(40.0), math.radians(15.0)


def image(level: float, deposit: str, cell: float) -> np.ndarray:
    """One ping's model image over a flat seabed ``level`` metres below the sonar."""
    x = np.arange(cell / 2, 12.0, cell)
    z = np.full((2, len(x)), -level)
    geom = model.Geometry(x, cell, SPACING, BIN, 300, 1, deposit)
    gain = BEAM(np.arctan2(level, x) - TILT)[None, :].repeat(2, axis=0)
    return model.forward(np.full_like(z, R), gain, z, geom)[0]


data = ndimage.convolve1d(image(8.0, "segment", 0.001), (0.25, 0.5, 0.25), mode="nearest")
for level in (8.0, 8.0175, 8.0263):
    ratio = image(level, "tent", 0.02)[198:210] / np.maximum(data[198:210], 1e-30)
    print(f"level {level} m: " + " ".join(f"{v:.2f}" for v in ratio))
