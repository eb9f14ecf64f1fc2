"""Bathymetry bench seabeds fitted with one setting changed: score, level by ground range.

Run from the repository root: ``python docs/notes/2026-11-28-inner-steps/variants.py LOOKS
SEABEDS`` (``LOOKS`` 0 or 1, ``SEABEDS`` comma-separated names of ``tools/bench_bathymetry.py``,
``flat`` included), with at most one of these environment variables set:
``INNER=N`` (L-BFGS iterations on R and Φ after each Gauss-Newton step, main 20),
``GN=N`` (Gauss-Newton steps per level, main 8), ``DEPOSIT=segment``, and, with
``inner_gauss_newton.patch`` (beside this script) applied, ``STEPS=N`` (Gauss-Newton steps on
log R and log Φ instead of the L-BFGS, the patch's default 3; 0: main's L-BFGS) or
``SKIP=K`` (bins within K bins of each ping's altitude out of the likelihood). Prints per
seabed the final energy, the bench's score (Z RMSE over the relief std), the flat baseline's,
the 1σ coverage, the seconds, and per side the mean error (cm) over ground ranges 0–0.5,
0.5–1.1, 1.1–2, 2–4, 4–10 and 10–27 m.
"""

import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tools"))
import bench_bathymetry as bb  # noqa: E402

from sonar_raster.inversion.bottom import track_bottom  # noqa: E402
from sonar_raster.inversion.surface import solve  # noqa: E402

SETTINGS = {
    "INNER": ("INNER_ITERATIONS", int),
    "GN": ("GAUSS_NEWTON_STEPS", int),
    "DEPOSIT": ("DEPOSIT", str),
    "STEPS": ("INNER_STEPS", int),
    "SKIP": ("NADIR_SKIP_BINS", float),
}
for variable, (name, kind) in SETTINGS.items():
    if variable in os.environ:
        setattr(solve, name, kind(os.environ[variable]))
BANDS = [(0, 0.5), (0.5, 1.1), (1.1, 2), (2, 4), (4, 10), (10, 27)]
looks = float(sys.argv[1])
for name in sys.argv[2].split(","):
    field, tracks, images = bb.render(name, 200, looks)
    start = time.time()
    fits = bb.fit(tracks, images, True)
    seconds = time.time() - start
    fit = fits[0]
    sides = []
    for side in fit.elevation:
        where = fit.position[side]
        error = fit.elevation[side] - (field.height_at(where[..., 0], where[..., 1]) - bb.ALT)
        bands = [error[:, (fit.x >= lo) & (fit.x < hi)].mean() for lo, hi in BANDS]
        sides.append(f"{side[0]} " + " ".join(f"{100 * b:+.2f}" for b in bands))
    line = f"{name} looks {looks:g}: E {fit.energies[-1]:.1f}"
    if name != "flat":
        base = [track_bottom(s, bb.BIN).altitude for s in images]
        score, flat, _, coverage = bb.score(field, fits, base)
        line += f" score {score:.3f} flat {flat:.3f} 1σ {coverage:.2f}"
    print(f"{line} {seconds:.0f} s | " + " | ".join(sides), flush=True)
