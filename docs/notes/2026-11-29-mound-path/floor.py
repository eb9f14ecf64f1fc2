"""What one line with a free beam profile cannot see: each seabed's line-average profile.

Usage (from the repository root)::

    python docs/notes/2026-11-29-mound-path/floor.py

With Φ free per depression angle and shared along the line, relief that every ping shares is
some Φ (docs/notes/2026-11-27-calibrated-beam.md), and the line-profile prior holds the line's
average across-track profile of Z at the flat seabed. A fit perfect in every other way then
misses the truth's line average; with a robust average (the median over the pings) it misses
the median. Printed: that error's RMS over the relief's standard deviation, the bench's score,
on the bench's scoring cells (tools/bench_bathymetry.py: 200 pings, ground range 1 m to 2 m
short of the swath's end, both sides).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tools"))

import bench_bathymetry as bench  # noqa: E402


def main() -> None:
    """One line per seabed."""
    pings = 200
    length = pings * bench.SPACING
    reach = math.sqrt(bench.RANGE**2 - bench.ALT**2)
    y = np.arange(pings) * bench.SPACING
    ground = np.arange(1.0, reach - 2.0, bench.BIN)
    for name in ("sand", "mounds", "trenches", "patches", "boulders", "box"):
        height, _ = bench.SEABEDS[name]
        sides = []
        for sign in (-1.0, 1.0):
            xx, yy = np.meshgrid(sign * ground, y)
            sides.append(height(xx, yy, length))
        truth = np.concatenate(sides, axis=1)
        std = float(np.std(truth))
        mean = np.broadcast_to(truth.mean(axis=0), truth.shape)
        median = np.broadcast_to(np.median(truth, axis=0), truth.shape)
        print(
            f"{name:9s} relief std {100 * std:5.1f} cm; missing the line mean "
            f"{np.sqrt(np.mean(mean**2)) / std:.3f}, the line median "
            f"{np.sqrt(np.mean(median**2)) / std:.3f}"
        )


if __name__ == "__main__":
    main()
