"""The surface fit at the issue's size, 1000 pings x 2000 bins per side, against its pooling.

The bathymetry bench's seabed and sonar with the range raised to 2000 bins of 5 cm (100 m),
the seabed mesh at 0.1 m cells, single-look speckle; each ``finest`` fitted in turn, printing
Z RMSE / relief std (the bench's score), the flat baseline, the coverage, seconds and the
process's peak resident memory so far.

Run from the repository root:
``python docs/notes/2026-11-27-coarser-fits/scale.py 4,2 1000 2000 12 sand``
(finest values, pings, bins, altitude, seabed).
"""

import math
import resource
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tools"))
import bench_bathymetry as bb  # noqa: E402

from sonar_raster.inversion.bottom import track_bottom  # noqa: E402
from sonar_raster.inversion.surface import Line, fit_lines  # noqa: E402
from sonar_raster.sonar import BeamPattern, Sonar  # noqa: E402

finests, pings, bins = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
bb.RANGE = bins * bb.BIN
bb.ALT = float(sys.argv[4])
bb.CELL = 0.1
bb.SONAR = Sonar(
    max_range=bb.RANGE,
    range_bin=bb.BIN,
    beam=BeamPattern.gaussian(50.0),
    tilt=math.radians(20.0),
    sides=("port", "starboard"),
)
start = time.perf_counter()
field, tracks, images = bb.render(sys.argv[5], pings, 1.0)
shapes = {k: v.shape for k, v in images[0].items()}
print(f"render {time.perf_counter() - start:.1f} s {shapes}", flush=True)
baselines = [track_bottom(s, bb.BIN).altitude for s in images]
lines = [
    Line(s, bb.BIN, t.positions[:, :2], t.headings) for t, s in zip(tracks, images, strict=True)
]
for finest in (int(v) for v in finests.split(",")):
    start = time.perf_counter()
    fits = fit_lines(lines, finest=finest, progress=lambda s: print("  ", s, flush=True))
    seconds = time.perf_counter() - start
    rel, flat, corr, cov = bb.score(field, fits, baselines)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
    print(
        f"finest {finest}: {rel:.3f} flat {flat:.3f} corr {corr:.2f} 1σ {cov:.2f}"
        f" {seconds:.1f} s, peak {peak:.1f} GB",
        flush=True,
    )
