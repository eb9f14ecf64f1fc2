"""Shadows found per ping, by how far below the seabed's level a shadow's mean must be.

For the real file's 100 pings at the wreck (both sides, its own range bin, gap 0.3 m as
``tools/report_real.py``) and the bathymetry bench's single-look renders (sand's APL-UW law or
Lambert's on the faces, gap 1 m as the surface fit): per ``shadow_mean`` (None: no such test,
then 0.2, 0.15, 0.1, 0.05) the pings with a height and the 90th percentile of that height,
and for the detections without the test the median of their unfiltered mean over the ping's
level (the median of the 3 × 7 median-filtered image beyond the first return). Run from the
repository root: ``python docs/notes/2026-12-02-law-in-fit/shadows.py``.
"""

import sys
from dataclasses import replace

import numpy as np
from scipy import ndimage

sys.path.insert(0, "tools")
import bench_bathymetry as bench  # noqa: E402

from sonar_raster.inversion.bottom import track_bottom  # noqa: E402
from sonar_raster.inversion.shadows import find_shadows  # noqa: E402
from sonar_raster.io.xtf import read_xtf  # noqa: E402
from sonar_raster.scenes.sediments import material_index  # noqa: E402

THRESHOLDS = (None, 0.2, 0.15, 0.1, 0.05)
BUILD = bench.build_scene
SAND = material_index("sand")


def report(tag: str, image: np.ndarray, rb: float, gap: float) -> None:
    """One line: pings / p90 height per threshold, and the loose detections' mean ratio."""
    alt = track_bottom({"side": image}, rb).altitude
    cells = []
    for threshold in THRESHOLDS:
        found = find_shadows(image, rb, alt, gap_m=gap, shadow_mean=threshold)
        h = found.height[np.isfinite(found.height)]
        cells.append(f"{h.size}/{np.percentile(h, 90) if h.size else float('nan'):.2f}")
    loose = find_shadows(image, rb, alt, gap_m=gap, shadow_mean=None)
    smooth = ndimage.median_filter(image, size=(3, 7))
    first = np.ceil(alt / rb).astype(int)
    ratios = [
        image[i, loose.start[i] : loose.end[i]].mean() / np.median(smooth[i, first[i] :])
        for i in range(image.shape[0])
        if np.isfinite(loose.height[i])
    ]
    ratio = f"{np.median(ratios):.3f}" if ratios else "-"
    print(f"{tag:28s} {' '.join(cells)}  mean/level {ratio}", flush=True)


def main() -> None:
    """Every case."""
    print("case                         pings/p90 at", THRESHOLDS)
    image, _ = read_xtf("../shared/data/xtf/scotsman-iver2.xtf", slice(250, 350))
    for side in ("port", "starboard"):
        sides = np.square(image.sides[side].astype(np.float64))
        report(f"real {side}", sides, image.sonar.range_bin, 0.3)
    for name, law in (("sand", "apl"), ("sand", "lambert"), ("patches", "apl"), ("box", "apl"),
                      ("box", "lambert"), ("boulders", "apl"), ("mounds", "apl")):  # fmt: skip
        bench.build_scene = (
            (lambda parts: BUILD([replace(p, law=SAND) for p in parts])) if law == "apl" else BUILD
        )
        _, _, images = bench.render(name, 200, 1.0)
        for side, sides in images[0].items():
            report(f"{name} {law} {side}", sides, bench.BIN, 1.0)


main()
