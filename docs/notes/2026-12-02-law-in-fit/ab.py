"""The surface fit with the seabed's scattering law in its model (``invert --law``).

Each bench seabed is rendered twice from the same heightfield and speckle draw, Lambert and
medium sand's APL-UW law at the bench sonar's frequency, and each render is fitted twice:
with the model's Lambert law (the default) and with sand's law (``Line.law``). The
mismatched pairs show what naming the wrong law costs. Run from the repository root:
``python docs/notes/2026-12-02-law-in-fit/ab.py sand,mounds,box 1``.
"""

import sys
import time
from dataclasses import replace

sys.path.insert(0, "tools")
import bench_bathymetry as bench  # noqa: E402

from sonar_raster.inversion.law import scattering_law  # noqa: E402
from sonar_raster.inversion.surface import Line, fit_lines  # noqa: E402
from sonar_raster.scenes.sediments import material_index  # noqa: E402

build = bench.build_scene
SAND = scattering_law("sand", bench.SONAR.frequency_hz)


def apl_scene(parts):
    """The bench's seabed with the sand law on its faces."""
    return build([replace(p, law=material_index("sand")) for p in parts])


def main() -> None:
    """Score each seabed's fit on its Lambert and its APL render, with each law."""
    names = sys.argv[1].split(",")
    looks = float(sys.argv[2]) if len(sys.argv) > 2 else 1.0
    renders = sys.argv[3].split(",") if len(sys.argv) > 3 else ["lambert", "apl"]
    for name in names:
        for rendered in renders:
            bench.build_scene = apl_scene if rendered == "apl" else build
            field, tracks, images = bench.render(name, 200, looks)
            baselines = [bench.track_bottom(sides, bench.BIN).altitude for sides in images]
            for law in (None, SAND):
                lines = [
                    Line(sides, bench.BIN, t.positions[:, :2], t.headings, law=law)
                    for t, sides in zip(tracks, images, strict=True)
                ]
                start = time.perf_counter()
                fits = fit_lines(lines)
                seconds = time.perf_counter() - start
                rel, flat, corr, cover = bench.score(field, fits, baselines)
                print(
                    f"{name:9s} render {rendered:8s} model {'sand' if law else 'lambert':8s} "
                    f"fit {rel:.3f} flat {flat:.3f} corr {corr:.2f} 1σ {cover:.2f} "
                    f"{seconds:.0f} s",
                    flush=True,
                )


main()
