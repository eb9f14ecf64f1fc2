"""Profiles against the surface on the bathymetry bench's one-line seabeds at given looks.

Session 13's ``2026-11-27-robustness/profiles_vs_surface.py`` (now a wrapper of this one)
with the looks as an argument (0: clean) and the looks ``method.image_looks`` estimates
printed. Run from the repository
root: ``python docs/notes/2026-11-28-auto-method/profiles_vs_looks.py 8 sand,mounds,box``.
"""

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tools"))
import bench_bathymetry as bb  # noqa: E402

from sonar_raster import invert  # noqa: E402
from sonar_raster.inversion.bottom import track_bottom  # noqa: E402
from sonar_raster.inversion.method import image_looks  # noqa: E402

looks = float(sys.argv[1])

for name in sys.argv[2].split(","):
    field, tracks, images = bb.render(name, 200, looks, 1)
    sides, track = images[0], tracks[0]
    t0 = time.perf_counter()
    fits = bb.fit(tracks, images, True)
    ts = time.perf_counter() - t0
    base = track_bottom(sides, bb.BIN).altitude
    rel_s, flat, _, _ = bb.score(field, fits, [base])
    t0 = time.perf_counter()
    errs, truths, flats = [], [], []
    y = track.positions[:, 1]
    for side, img in sides.items():
        inv = invert(img, bb.BIN, ping_spacing=bb.SPACING)
        x = np.asarray(inv.x)
        keep = (x > 1.0) & (x < x[-1] - 2.0)
        z = np.asarray(inv.elevation)[:, keep]
        xs = x[keep] * (1 if side == "starboard" else -1)
        xx, yy = np.meshgrid(xs, y)
        t = field.height_at(xx, yy) - bb.ALT
        ok = np.isfinite(z)
        errs.append((z - t)[ok])
        truths.append(t[ok])
        flats.append((-base[:, None] - t)[ok])
    tp = time.perf_counter() - t0
    std = np.std(np.concatenate(truths))
    rel_p = np.sqrt(np.mean(np.concatenate(errs) ** 2)) / std
    flat_p = np.sqrt(np.mean(np.concatenate(flats) ** 2)) / std
    print(
        f"{name:9s} L {looks:g} (estimated {image_looks(sides):.3g}) "
        f"surface {rel_s:.3f} ({ts:.0f} s)  profiles {rel_p:.3f} ({tp:.0f} s)  "
        f"flat {flat:.3f} / {flat_p:.3f}",
        flush=True,
    )
