"""Speckle contrast and KS of the port side, real and simulated, over five ping sets.

The port side has no wreck, so it can be scored over (a) every ping, (b) the pings the
starboard statistics keep (the wreck's rows 98-377 left out), (c) those rows only, and (b)
split into the start of the file (rows 8-97, high) and its end (rows 378-460, low). Run from
the repository root: ``python docs/notes/2026-12-02-file-against-itself/ping_sets.py`` (about
55 s; the default simulation of ``tools/compare_real.py``, seed 0).
"""

import math
import sys
from pathlib import Path

import numpy as np
from scipy import ndimage, stats

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tools"))
import compare_real as cr  # noqa: E402

real = cr.read_real(cr.DEFAULT_XTF)
firsts = {s: cr.first_returns(real.samples[s]) for s in real.sides}
detected = np.minimum(firsts["port"], firsts["starboard"]) * real.range_bin
altitudes = ndimage.gaussian_filter1d(detected, 10.0, mode="nearest")
n_bins = real.sides["port"].shape[1]
lo = int(math.ceil((altitudes[cr.SKIP_PINGS :].max() + 1.5) / real.range_bin))
window = slice(lo, n_bins - 8)
opts = cr.argparse.Namespace(
    sensor=cr.DEFAULT_SENSOR,
    along_beam_deg=None,
    range_resolution=None,
    noise_db=None,
    speckle_looks=None,
    k_shape=None,
    downsample="preset",
    law="apl",
    sediment="sand",
    micro_relief="on",
    relief_cell=None,
    attitude=True,
    seed=0,
)
_, sim = cr.simulate(real, altitudes, opts, None, None)
everything = cr.seabed_mask(firsts["port"], real.sides["port"].shape, [], "port")
kept = cr.seabed_mask(firsts["port"], real.sides["port"].shape, real.hits, "starboard")
rows = np.arange(everything.shape[0])[:, None]
sets = {
    "every ping": everything,
    "starboard's pings": kept,
    "wreck rows only": everything & ~kept,
    "rows 8-97": kept & (rows < 98),
    "rows 378-460": kept & (rows >= 378),
}
rng = np.random.default_rng(0)
images = {"real": real.sides["port"], "sim": sim.sides["port"].astype(np.float64)}
norms = {k: v / np.maximum(cr.local_mean(v), 1e-30) for k, v in images.items()}
print(
    f"port altitude (m): rows 8-97 {altitudes[8:98].mean():.1f}, 98-377 "
    f"{altitudes[98:378].mean():.1f}, 378- {altitudes[378:].mean():.1f}"
)
for name, mask in sets.items():
    for a, b in cr.band_edges(window, 3):
        m = mask.copy()
        m[:, :a] = False
        m[:, b:] = False
        c = {k: np.median(cr.patch_contrasts(v, m)) for k, v in images.items()}
        s = [rng.choice(norms[k][m], min(100_000, int(m.sum()))) for k in images]
        print(
            f"{name:18s} {a * real.range_bin:4.1f}-{b * real.range_bin:4.1f} m: contrast "
            f"real {c['real']:.3f} sim {c['sim']:.3f}, KS {stats.ks_2samp(*s).statistic:.3f}"
        )
