"""A/B of ``solve.JOINT_REFLECTIVITY`` (joint_reflectivity.patch applied) on the bench's images.

Run from the repository root with the patch applied (``git apply
docs/notes/2026-12-02-joint-reflectivity/joint_reflectivity.patch``): ``python
docs/notes/2026-12-02-joint-reflectivity/ab.py SEABEDS LOOKS [FLAGS]``, e.g. ``mounds,sand 1
0,1`` (FLAGS: 0 off, 1 on; each seabed rendered once, fitted once per flag, scored as
``tools/bench_bathymetry.py`` scores one line).
"""

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tools"))
import bench_bathymetry as bb  # noqa: E402

from sonar_raster.inversion.bottom import track_bottom  # noqa: E402
from sonar_raster.inversion.surface import solve  # noqa: E402

seabeds = sys.argv[1].split(",")
looks = float(sys.argv[2])
flags = [v == "1" for v in sys.argv[3].split(",")] if len(sys.argv) > 3 else [False, True]
for name in seabeds:
    field, tracks, images = bb.render(name, 200, looks, 1)
    baselines = [track_bottom(sides, bb.BIN).altitude for sides in images]
    for flag in flags:
        solve.JOINT_REFLECTIVITY = flag  # type: ignore[attr-defined]
        start = time.perf_counter()
        fits = bb.fit(tracks, images, True)
        seconds = time.perf_counter() - start
        rel, flat, corr, cov = bb.score(field, fits, baselines)
        print(
            f"{name:9s} looks {looks:g} joint R {flag!s:5s}: fit {rel:.3f} flat {flat:.3f} "
            f"corr {corr:.2f} 1σ {cov:.2f} {seconds:.1f} s",
            flush=True,
        )
