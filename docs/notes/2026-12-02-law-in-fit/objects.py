"""Knots the surface fit's shadow start marks as objects, per bench seabed and law.

The bench's single-look renders (one line, 200 pings), the coarse level's problem
(``solve.problem_at(level=2)``) and ``solve._raise_objects`` as the fit runs it. Run from the
repository root: ``python docs/notes/2026-12-02-law-in-fit/objects.py sand,mounds,box``.
"""

import sys
from dataclasses import replace

sys.path.insert(0, "tools")
import bench_bathymetry as bench  # noqa: E402

import sonar_raster.inversion.surface.solve as S  # noqa: E402
from sonar_raster.inversion.surface import Line  # noqa: E402
from sonar_raster.scenes.sediments import material_index  # noqa: E402

BUILD = bench.build_scene


def main() -> None:
    """Object and shadowed knots of each seabed rendered with each law."""
    sand = material_index("sand")
    for name in sys.argv[1].split(","):
        for law in ("lambert", "apl"):
            bench.build_scene = (
                (lambda parts: BUILD([replace(p, law=sand) for p in parts]))
                if law == "apl"
                else BUILD
            )
            _, tracks, images = bench.render(name, 200, 1.0)
            line = Line(images[0], bench.BIN, tracks[0].positions[:, :2], tracks[0].headings)
            problem = S.problem_at([line], level=2)
            S._raise_objects(problem)
            print(
                f"{name} {law}: object knots {int(problem.objects.sum())} of {problem.nz}, "
                f"shadowed {int(problem.shadowed.sum())}",
                flush=True,
            )


main()
