"""The bathymetry bench with the seabed rendered under medium sand's APL-UW law, not Lambert.

The surface fit models a Lambertian seabed (``R cos θ``) times a free beam profile Φ; real
seabeds follow laws like APL-UW's, whose shape in incidence angle differs. Each seabed is
rendered twice from the same heightfield and speckle draw, Lambert and APL sand, and fitted
with the defaults. Run from the repository root:
``python docs/notes/2026-12-02-apl-seabed/ab.py sand,mounds,box 1``.
"""

import sys
from dataclasses import replace

sys.path.insert(0, "tools")
import bench_bathymetry as bench  # noqa: E402

from sonar_raster.scenes.sediments import material_index  # noqa: E402

build = bench.build_scene


def apl_scene(parts):
    """The bench's seabed with the sand law on its faces."""
    return build([replace(p, law=material_index("sand")) for p in parts])


def main() -> None:
    """Score each seabed's fit on its Lambert and its APL render."""
    names = sys.argv[1].split(",")
    looks = float(sys.argv[2]) if len(sys.argv) > 2 else 1.0
    for name in names:
        for law in ("lambert", "apl"):
            bench.build_scene = apl_scene if law == "apl" else build
            field, tracks, images = bench.render(name, 200, looks)
            fits = bench.fit(tracks, images, True)
            baselines = [bench.track_bottom(sides, bench.BIN).altitude for sides in images]
            rel, flat, corr, cover = bench.score(field, fits, baselines)
            print(
                f"{name:9s} {law:8s} fit {rel:.3f} flat {flat:.3f} corr {corr:.2f} 1σ {cover:.2f}"
            )


main()
