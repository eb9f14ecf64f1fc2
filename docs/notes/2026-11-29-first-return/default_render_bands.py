"""The default render's surface inversion against the flat seabed at -8 m, by ground range.

Per side and ground-range band: mean, rms and share within 5 cm of Z + 8 m, and the std over
pings of each ping's mean error (a common bend has a small one). Starboard pings 160-240
beyond 26 m (the cylinder and its shadow) are left out, as in
``docs/notes/2026-11-28-fit-speed/default_render.py``.

Run: ``sonar-raster render default -o d.exr``, ``sonar-raster invert d.exr -o inv -q``, then
``python docs/notes/2026-11-29-first-return/default_render_bands.py inv``.
"""

import json
import sys
import warnings

import numpy as np
import OpenImageIO as oiio

out = sys.argv[1]
warnings.simplefilter("ignore", RuntimeWarning)
for side in ("port", "starboard"):
    image = oiio.ImageInput.open(f"{out}/{side}/elevation.exr")
    z = np.asarray(image.read_image(format="float32"))
    image.close()
    z = z[..., 0] if z.ndim == 3 else z
    axis = json.load(open(f"{out}/{side}/inversion.json"))["ground_axis"]
    x = axis["first_centre_m"] + axis["spacing_m"] * np.arange(axis["cells"])
    e = z + 8.0
    if side == "starboard":
        e[160:241, x > 26.0] = np.nan
    print(side)
    edges = [0, 1, 2, 4, 8, 12, 16, 20, 25, 30, 35, 40]
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        v = e[:, (x >= a) & (x < b)]
        ok = np.isfinite(v)
        if not ok.any():
            continue
        print(
            f"  {a:2d}-{b:2d} m: mean {100 * np.nanmean(v):+5.1f} cm, rms "
            f"{100 * np.sqrt(np.nanmean(v**2)):4.1f} cm, within 5 cm "
            f"{100 * np.mean(np.abs(v[ok]) < 0.05):3.0f} %, per-ping mean std "
            f"{100 * np.nanstd(np.nanmean(v, axis=1)):4.1f} cm"
        )
