"""The default render's surface inversion against the flat seabed at -8 m, away from the cylinder.

Per side: mean and rms of Z + 8 m and the share of cells within 5 cm (starboard pings 160-240
beyond 26 m ground range, the cylinder and its shadow, left out), and the median altitude.

Run (any folder): ``sonar-raster render default -o d.exr``, ``sonar-raster invert d.exr
--method surface -o inv -q``, then ``python docs/notes/2026-11-28-fit-speed/default_render.py
inv``.
"""

import json
import sys

import numpy as np
import OpenImageIO as oiio

out = sys.argv[1]
for side in ("port", "starboard"):
    image = oiio.ImageInput.open(f"{out}/{side}/elevation.exr")
    z = np.asarray(image.read_image(format="float32"))
    image.close()
    z = z[..., 0] if z.ndim == 3 else z
    meta = json.load(open(f"{out}/{side}/inversion.json"))
    axis = meta["ground_axis"]
    x = axis["first_centre_m"] + axis["spacing_m"] * np.arange(axis["cells"])
    keep = np.isfinite(z)
    if side == "starboard":
        keep[160:241, x > 26.0] = False
    e = z[keep] + 8.0
    print(
        f"{side}: mean {100 * e.mean():+.1f} cm, rms {100 * np.sqrt((e**2).mean()):.1f} cm,"
        f" within 5 cm {100 * np.mean(abs(e) < 0.05):.0f} %,"
        f" altitude median {np.median(meta['altitude_m']):.4f} m"
    )
