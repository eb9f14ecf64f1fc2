"""The first bottom return's level in the real file and in its simulation (compare_real's).

Per side, medians over pings (compare_real's skipped ones left out) of the mean intensity of the
water column (bins 20 to 10 before the first return), just past the first return (bins 2-11
after it) and mid-swath (bins 150-249 after it), as dB ratios.

Run from ``tools/``: ``python ../docs/notes/2026-11-29-first-return/nadir_real.py``.
"""

import argparse
import sys

import numpy as np
from scipy import ndimage

sys.path.insert(0, ".")
import compare_real as C  # noqa: E402

real = C.read_real(C.DEFAULT_XTF)
firsts = {s: C.first_returns(real.samples[s]) for s in real.sides}
detected = np.minimum(firsts["port"], firsts["starboard"]) * real.range_bin
altitudes = ndimage.gaussian_filter1d(detected, 10.0, mode="nearest")
options = argparse.Namespace(
    sensor=C.DEFAULT_SENSOR, along_beam_deg=None, range_resolution=None, noise_db=None,
    speckle_looks=None, k_shape=None, downsample="preset", law="apl", micro_relief="on",
    relief_cell=None, attitude=True, seed=0,
)  # fmt: skip
_, sim = C.simulate(real, altitudes, options, None, None)


def levels(image: np.ndarray, first: np.ndarray, name: str) -> None:
    """Print the three ratios of one side."""
    image = image.astype(np.float64)
    water, nadir, mid = [], [], []
    for i in range(C.SKIP_PINGS, image.shape[0]):
        f = int(first[i])
        water.append(image[i, 20 : max(21, f - 10)].mean())
        nadir.append(image[i, f + 2 : f + 12].mean())
        mid.append(image[i, f + 150 : f + 250].mean())
    w, n, m = (float(np.median(v)) for v in (water, nadir, mid))
    db = [10 * np.log10(a / b) for a, b in ((n, w), (m, w), (n, m))]
    print(
        f"{name}: nadir/water {db[0]:5.1f} dB, mid/water {db[1]:5.1f} dB, nadir/mid {db[2]:5.1f} dB"
    )


for side in ("port", "starboard"):
    levels(real.sides[side], firsts[side], f"real {side}")
    levels(sim.sides[side], np.round(altitudes / real.range_bin).astype(int), f"sim  {side}")
