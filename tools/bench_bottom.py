"""Bottom tracking: ``sonar_raster.inversion.bottom`` against the true altitude.

A benchmark, not a test: renders a flat seabed (GL raster, both sides, 300 pings 0.1 m
apart, 20 m range in 5 cm bins, Gaussian 50° beam tilted 20°) at several altitudes, adds
exponential speckle and exponential water-column noise at a fraction of the seabed level just
after the first return (plus bright specks on 0.2 % of the bins at 3 times that level), and
prints, per case, for ``track_side`` (starboard; what ``invert`` uses) and the two-side
``track_bottom`` (the XTF path), the fraction of pings within one bin of the true altitude,
the mean and largest error in bins, and the run time. The default altitudes put the first
return 0.2, 0.6 and 0.4 of the way into its bin.

Usage: ``python tools/bench_bottom.py [--altitudes 2.61,7.33,12.87] [--noise 0,0.05,0.1,0.2]``
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

from sonar_raster import render_raster
from sonar_raster.inversion.bottom import track_bottom, track_side
from sonar_raster.scene import MeshPart, build_scene
from sonar_raster.sonar import BeamPattern, Sonar
from sonar_raster.trajectory import Trajectory

BIN = 0.05


def _plane(size: float) -> MeshPart:
    """A flat square seabed at z = 0 (two triangles, counter-clockwise from above), R 0.5."""
    h = size / 2
    v = np.array([[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]])
    return MeshPart(v, np.array([[0, 1, 2], [0, 2, 3]]), 0.5, "seabed", is_seabed=True)


def _noisy(image: np.ndarray, altitude: float, level: float, rng) -> np.ndarray:
    k = int(altitude / BIN)
    seabed = float(image[:, k : k + 10].mean())
    noise = level * seabed * rng.exponential(size=image.shape)
    specks = rng.random(image.shape) < 0.002
    noise[specks] += 3.0 * seabed * rng.exponential(size=int(specks.sum()))
    return image * rng.exponential(size=image.shape) + noise


def _row(name: str, alt: np.ndarray, truth: float, seconds: float) -> str:
    err = (alt - truth) / BIN
    ok = np.mean(np.abs(err) <= 1.0)
    return (
        f"  {name:22s} within 1 bin {100 * ok:6.1f} %  mean {np.mean(err):+6.2f}  "
        f"max {np.max(np.abs(err)):7.2f} bins  {seconds * 1e3:7.1f} ms"
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--altitudes", default="2.61,7.33,12.87")
    parser.add_argument("--noise", default="0,0.05,0.1,0.2")
    args = parser.parse_args()
    sonar = Sonar(
        max_range=20.0, range_bin=BIN, beam=BeamPattern.gaussian(50.0), tilt=math.radians(20)
    )
    rng = np.random.default_rng(1)
    for altitude in (float(a) for a in args.altitudes.split(",")):
        track = Trajectory.straight((0.0, -15.0, altitude), 0.0, 0.1, 300)
        image = render_raster(build_scene([_plane(200.0)]), sonar, track)
        clean = {s: v.astype(np.float64) for s, v in image.sides.items()}
        cases = [("clean", clean)] + [
            (
                f"speckle + water {100 * n:.0f} %",
                {s: _noisy(v, altitude, n, rng) for s, v in clean.items()},
            )  # fmt: skip
            for n in (float(x) for x in args.noise.split(","))
        ]
        for label, sides in cases:
            print(f"altitude {altitude} m, {label}:")
            t = time.perf_counter()
            side = track_side(sides["starboard"], BIN).altitude
            print(_row("bottom.track_side", side, altitude, time.perf_counter() - t))
            t = time.perf_counter()
            both = track_bottom(sides, BIN).altitude
            print(_row("bottom.track_bottom", both, altitude, time.perf_counter() - t))
    return 0


if __name__ == "__main__":
    sys.exit(main())
