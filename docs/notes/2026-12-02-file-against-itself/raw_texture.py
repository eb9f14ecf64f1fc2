"""Raw texture of sand's micro-relief: the GL raster against the numpy reference renderer.

A plane of medium sand with its micro-relief (cells of CELL range bins), 40 level pings 0.117 m
apart at ALTITUDE, the ``marine-sonic-600-max`` sonar at the real file's range and bins, no
effects (a thin fan, no pulse, no speckle). Per side and range band: the variance of the
intensity over its running mean (41 bins) and its lag-1 correlation across and along track.

Run: ``python docs/notes/2026-12-02-file-against-itself/raw_texture.py CELL ALTITUDE
[raster,reference]`` (the reference takes about 100 s, the raster 1 s).
"""

import sys
import time
from dataclasses import replace

import numpy as np
from scipy import ndimage

from sonar_raster import Trajectory, build_scene
from sonar_raster.effects.presets import preset
from sonar_raster.rendering.entry import render
from sonar_raster.scenes.seabed import Heightfield, micro_relief
from sonar_raster.scenes.sediments import material_index, material_reflectivity

cell_bins = float(sys.argv[1]) if len(sys.argv) > 1 else 1.5
altitude = float(sys.argv[2]) if len(sys.argv) > 2 else 11.0
models = sys.argv[3].split(",") if len(sys.argv) > 3 else ["raster", "reference"]
sonar = preset("marine-sonic-600-max").sonar(29.98, 29.98 / 1024)
rb = sonar.range_bin
n, spacing = 40, 0.117
field = Heightfield(np.zeros((2, 2)), -31.0, -1.0, 62.0, n * spacing + 2.0)
field = micro_relief(field, "sand", resolution=cell_bins * rb, seed=0)
mesh = field.mesh(material_reflectivity("sand"))
scene = build_scene([replace(mesh, is_seabed=True, law=material_index("sand"))])
positions = np.stack([np.zeros(n), np.arange(n) * spacing, np.full(n, altitude)], axis=1)
track = Trajectory(positions, np.zeros(n), np.zeros(n), np.zeros(n))
images = {}
for model in models:
    start = time.time()
    images[model] = render(scene, sonar, track, model=model, force=True)
    print(f"{model}: {time.time() - start:.1f} s", flush=True)


def texture(a: np.ndarray) -> tuple[float, float, float]:
    """Variance, lag-1 correlation across and along track of ``a`` over its running mean."""
    x = a / np.maximum(ndimage.uniform_filter(a, (1, 41), mode="nearest"), 1e-30) - 1.0
    var = float((x * x).mean())
    return var, float((x[:, 1:] * x[:, :-1]).mean()) / var, float((x[1:] * x[:-1]).mean()) / var


for side in ("starboard", "port"):
    for lo, hi in ((14.1, 19.3), (19.3, 24.5), (24.5, 29.7)):
        a, b = int(lo / rb), int(hi / rb)
        row = []
        for model, image in images.items():
            var, across, along = texture(image.sides[side][2:-2, a:b].astype(np.float64))
            row.append(f"{model}: var {var:.3f}, lag-1 across {across:.3f}, along {along:.3f}")
        print(f"{side} {lo}-{hi} m: " + " | ".join(row))
