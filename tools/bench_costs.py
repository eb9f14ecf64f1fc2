"""Job-cost constants: measured render and inversion times against the CLI's estimates.

Runs ``sonar-raster render`` (GL raster, in this process, after one warm-up) over a sweep of
pings, oversampling and along-track samples, with and without sensor effects, and
``sonar-raster invert`` on rendered images of two sizes at the default settings; prints, per
job, the estimate's counts, the estimated and the measured seconds and their ratio, then the
per-ray and per-cell costs fitted to the measurements (least squares) beside the constants the
CLI uses (``cli/render.py`` ``_RAY_SECONDS``, ``_CELL_SECONDS``; ``cli/invert.py``
``_PIXEL_SECONDS``). An estimate is meant to be upper-end: ratios measured/estimated below 1.

    python tools/bench_costs.py [--scene flat_calibration] [--quick]
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np
from _common import parser

from sonar_raster.cli import invert as invert_cli
from sonar_raster.cli import render as render_cli
from sonar_raster.cli.app import _parser, main


def timed(argv: list[str]) -> float:
    start = time.perf_counter()
    status = main(argv)
    if status != 0:
        raise SystemExit(f"{' '.join(argv)} failed ({status})")
    return time.perf_counter() - start


def render_rows(scene: str, folder: Path, quick: bool) -> list[tuple]:
    sweeps = [
        ["--pings", "500", "--no-effects"],
        ["--pings", "5000", "--no-effects"],
        ["--pings", "500", "--oversample", "32", "--no-effects"],
        ["--pings", "500", "--oversample", "8", "--along-samples", "8", "--no-effects"],
        ["--pings", "500"],
        ["--pings", "5000"],
    ]
    if quick:
        sweeps = sweeps[:1] + sweeps[4:5]
    out = str(folder / "r.exr")
    timed(["render", scene, "-o", out, "-q", "--pings", "20"])  # warm-up: GL context, shaders
    rows = []
    for extra in sweeps:
        argv = ["render", scene, "-o", out, "-q", *extra]
        args = _parser().parse_args(argv)
        setup = render_cli.load_setup(args)
        streamed = render_cli._streamed(args, setup)
        estimate = render_cli.raster_estimate(args, setup, streamed, [Path(out)])
        seconds = timed(argv)
        effects = "--no-effects" not in extra
        rows.append((" ".join(extra), estimate.counts["rays"], estimate.counts["cells"],
                     effects, estimate.seconds, seconds))  # fmt: skip
    return rows


def heavy_rows(scene: str, folder: Path) -> list[tuple]:
    """One render of a scene with many triangles, in a fresh renderer (upload included)."""
    argv = ["render", scene, "-o", str(folder / "h.exr"), "-q"]
    args = _parser().parse_args(argv)
    setup = render_cli.load_setup(args)
    estimate = render_cli.raster_estimate(args, setup, False, [folder / "h.exr"])
    seconds = timed(argv)
    name = f"{scene} ({setup.scene.n_triangles} triangles)"
    return [(name, estimate.counts["rays"], estimate.counts["cells"], True, estimate.seconds,
             seconds)]  # fmt: skip


def invert_rows(scene: str, folder: Path, quick: bool) -> list[tuple]:
    rows = []
    for pings in (100,) if quick else (100, 200):
        image = folder / f"i{pings}.exr"
        timed(["render", scene, "-o", str(image), "-q", "--pings", str(pings),
               "--side", "starboard"])  # fmt: skip
        pixels = invert_cli._check_image_size(image)
        argv = ["invert", str(image), "-o", str(folder / f"inv{pings}"), "-q", "--no-mesh",
                "--no-previews"]  # fmt: skip
        seconds = timed(argv)
        rows.append((pings, pixels, invert_cli._PIXEL_SECONDS * pixels, seconds))
    return rows


def main_() -> None:
    ap = parser(__doc__)
    ap.add_argument("--scene", default="flat_calibration")
    ap.add_argument("--quick", action="store_true", help="two renders and one inversion")
    ap.add_argument("--heavy", default="barrel_on_sand", help="a scene with many triangles")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        renders = render_rows(args.scene, folder, args.quick)
        renders += heavy_rows(args.heavy, folder)
        inversions = invert_rows(args.scene, folder, args.quick)
    print("| render | rays | cells | effects | estimated s | measured s | measured/estimated |")
    print("|---|---|---|---|---|---|---|")
    for name, rays, cells, effects, est, got in renders:
        print(f"| {name} | {rays:.3g} | {cells:.3g} | {effects} | {est:.2f} | {got:.2f} | "
              f"{got / est:.2f} |")  # fmt: skip
    plain = [(r, c, s) for _, r, c, e, _, s in renders if not e]
    if len(plain) >= 2:
        a = np.array([[r, c] for r, c, _ in plain])
        fit = np.linalg.lstsq(a, np.array([s for *_, s in plain]), rcond=None)[0]
        cli = (render_cli._RAY_SECONDS, render_cli._CELL_SECONDS[1])
        print(f"fitted without effects: {fit[0]:.3g} s per ray, {fit[1]:.3g} s per cell "
              f"(CLI: {cli[0]:.3g}, {cli[1]:.3g})")  # fmt: skip
    print("| invert | pixels | estimated s | measured s | measured/estimated | s per pixel |")
    print("|---|---|---|---|---|---|")
    for pings, pixels, est, got in inversions:
        print(f"| {pings} pings | {pixels} | {est:.1f} | {got:.1f} | {got / est:.2f} | "
              f"{got / pixels:.3g} |")  # fmt: skip
    print(f"CLI: {invert_cli._PIXEL_SECONDS:.3g} s per pixel")


if __name__ == "__main__":
    main_()
