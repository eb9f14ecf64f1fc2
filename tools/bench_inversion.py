"""Round trips of the inversion: render known seabeds, invert them, compare with the truth.

A benchmark, not a test: it prints one row per (seabed, mode) and asserts nothing. The setup is
the one of ``tests/test_invert.py``: 32 pings 0.1 m apart at 10 m altitude, starboard, 20 m
range in 5 cm bins, a Gaussian 50° beam tilted 20°, reflectivity 0.5, rendered by the GL path.

Columns: Z RMSE (m) and as a fraction of the relief's standard deviation (of the altitude for
the flat seabed), the same after removing the mean error (the absolute level comes from the
first bottom return), the correlation of Z with the truth, the correlation of the recovered
beam profile with the true one over 30–80° depression, iterations per pyramid level, seconds.
Modes: "free" (R, Φ, Z unknown) and "calibrated" (Φ fixed to the true profile).

Usage: ``python tools/bench_inversion.py [--max-iter 100] [--seabeds flat,ripples,mound]``.
Issue 4 still lacks the trench and two-patch seabeds and the plot.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from sonar_raster.invert import BeamProfile, invert
from sonar_raster.raster import RasterRenderer
from sonar_raster.scene import build_scene
from sonar_raster.seabed import Heightfield, make_seabed
from sonar_raster.sonar import BeamPattern, Sonar
from sonar_raster.trajectory import Trajectory

ALT, PINGS, SPACING = 10.0, 32, 0.1
SONAR = Sonar(
    max_range=20.0,
    range_bin=0.05,
    beam=BeamPattern.gaussian(50.0),
    tilt=math.radians(20.0),
    sides=("starboard",),
)
TRACK = Trajectory.straight((0.0, -1.6, ALT), 0.0, SPACING, PINGS)
COMMON = {"size": (30.0, 8.0), "center": (12.0, 0.0), "resolution": 0.05}
SEABEDS = {
    "flat": lambda: make_seabed("flat", size=(40.0, 8.0), center=(12.0, 0.0)),
    "ripples": lambda: make_seabed(
        "ripples", **COMMON, wavelength=1.0, amplitude=0.05, direction_deg=90.0, seed=1
    ),
    "mound": lambda: make_seabed(
        "bumpy", **COMMON, bump_height=0.4, bump_width=1.5, density=0.02, seed=2
    ),
}


def true_profile() -> BeamProfile:
    """The renderer's beam in the inversion's units (gain times the ping spacing)."""
    dep = np.linspace(0.05, math.pi / 2, 400)
    return BeamProfile(dep, SPACING * SONAR.gain(dep))


def row(name: str, mode: str, field: Heightfield, image: np.ndarray, max_iter: int) -> str:
    beam = true_profile() if mode == "calibrated" else None
    start = time.perf_counter()
    inv = invert(image, SONAR.range_bin, ping_spacing=SPACING, max_iter=max_iter, beam=beam)
    seconds = time.perf_counter() - start
    xx, yy = np.meshgrid(inv.x, TRACK.positions[:, 1])
    truth = field.height_at(xx, yy) - ALT
    ok = np.isfinite(inv.elevation)
    err = (inv.elevation - truth)[ok]
    scale = ALT if name == "flat" else float(np.std(truth[ok]))
    rmse = float(np.sqrt(np.mean(err**2)))
    level_free = float(np.sqrt(np.mean((err - err.mean()) ** 2)))
    corr_z = np.corrcoef(inv.elevation[ok], truth[ok])[0, 1] if name != "flat" else math.nan
    dep = inv.profile.depression
    keep = (dep > math.radians(30)) & (dep < math.radians(80))
    corr_phi = np.corrcoef(inv.profile.gain[keep], SONAR.gain(dep[keep]))[0, 1]
    iters = "/".join(str(len(e) - 1) for e in inv.energies)
    return (
        f"{name:8s} {mode:10s} {rmse:8.4f} {rmse / scale:7.3f} {level_free / scale:9.3f} "
        f"{corr_z:6.2f} {corr_phi:6.3f} {iters:>12s} {seconds:7.1f}"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--max-iter", type=int, default=100, help="iterations per level and start")
    ap.add_argument("--seabeds", default=",".join(SEABEDS), help="comma-separated subset")
    args = ap.parse_args()
    print(
        f"{'seabed':8s} {'mode':10s} {'Z rmse':>8s} {'/scale':>7s} {'lvl-free':>9s} "
        f"{'corr Z':>6s} {'corr Φ':>6s} {'iterations':>12s} {'s':>7s}"
    )
    with RasterRenderer() as renderer:
        for name in args.seabeds.split(","):
            field = SEABEDS[name]()
            scene = build_scene([field.mesh(0.5)])
            image = renderer.render(scene, SONAR, TRACK).sides["starboard"].astype(np.float64)
            for mode in ("free", "calibrated"):
                print(row(name, mode, field, image, args.max_iter), flush=True)


if __name__ == "__main__":
    main()
