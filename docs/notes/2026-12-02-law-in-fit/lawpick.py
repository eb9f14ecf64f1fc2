"""Would the fit's final objective pick the seabed's law? Each render fitted with each law.

Sand waves of the bathymetry bench, single look, rendered with the laws named in the third
argument and fitted with each law of the second; prints each fit's final E and its Z RMSE over
the relief's std. Run from the repository root:
``python docs/notes/2026-12-02-law-in-fit/lawpick.py sand lambert,sand,mud,gravel lambert,sand``.
"""

import sys
from dataclasses import replace

sys.path.insert(0, "tools")
import bench_bathymetry as bench  # noqa: E402

from sonar_raster.inversion.law import scattering_law  # noqa: E402
from sonar_raster.inversion.surface import Line, fit_lines  # noqa: E402
from sonar_raster.scenes.sediments import material_index  # noqa: E402

BUILD = bench.build_scene


def main() -> None:
    """Every seabed, rendered law and fitted law."""
    for name in sys.argv[1].split(","):
        for truth in sys.argv[3].split(","):
            if truth == "lambert":
                bench.build_scene = BUILD
            else:
                index = material_index(truth)
                bench.build_scene = lambda parts, i=index: BUILD([replace(p, law=i) for p in parts])
            field, tracks, images = bench.render(name, 200, 1.0)
            baselines = [bench.track_bottom(s, bench.BIN).altitude for s in images]
            for law_name in sys.argv[2].split(","):
                law = scattering_law(law_name, bench.SONAR.frequency_hz)
                lines = [
                    Line(s, bench.BIN, t.positions[:, :2], t.headings, law=law)
                    for t, s in zip(tracks, images, strict=True)
                ]
                fits = fit_lines(lines)
                rel = bench.score(field, fits, baselines)[0]
                print(
                    f"{name} rendered {truth:8s} model {law_name:8s} "
                    f"E {fits[0].energies[-1]:.1f} fit {rel:.3f}",
                    flush=True,
                )


main()
