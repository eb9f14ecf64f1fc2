"""Scale benchmark: run time and peak memory against triangles, pings and bins.

Each case runs in its own fresh process (so its peak resident memory is its own), once with the
new path and once with a baseline beside it:

- triangles (10⁴ … 2·10⁷, a long seabed of which the track sees a fixed stretch): culled draws
  (tile index) against drawing the whole scene every draw (``RasterSettings(cull=False)``);
- pings (10² … 10⁵ over the 2·10⁷-triangle seabed, 4096 bins): the streamed survey
  (``render_survey``, blocks of 512 pings written to EXR as they finish) against rendering the
  whole track into memory and writing it (up to 10⁴ pings; beyond that the baseline is the
  problem being solved);
- bins (512 … 8192, 1000 pings): culled against unculled.

It prints the table, fits the growth exponent of time (and memory) against each size on the
largest three points, and writes ``bench_out/bench_scale.csv`` and ``bench_scale.png``.

Usage: ``python tools/bench_scale.py [--quick] [--out bench_out]``.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _common import pyplot

WIDTH, CELL = 120.0, 0.5  # seabed width and grid cell, metres: 480 triangles per 0.5 m row
SPACING, ALTITUDE, RANGE = 0.2, 10.0, 50.0


def seabed(triangles: int):
    """A gently undulating grid seabed of about ``triangles`` triangles, centred on y = 0."""
    from sonar_raster.scene import build_scene
    from sonar_raster.scenes.seabed import heightfield_mesh

    nx = int(WIDTH / CELL) + 1
    ny = max(2, int(round(triangles / (2 * (nx - 1)))) + 1)
    x = -0.5 * WIDTH + CELL * np.arange(nx)
    y = -0.5 * CELL * (ny - 1) + CELL * np.arange(ny)
    z = 0.2 * np.sin(x / 7.0)[None, :] * np.cos(y / 11.0)[:, None]
    return build_scene([heightfield_mesh(z, x[0], y[0], CELL, CELL)])


def run_case(case: dict) -> dict:
    """Run one case in this process; return seconds, peak memory and the renderer's counters."""
    from sonar_raster.rendering.gl.raster import RasterRenderer, RasterSettings
    from sonar_raster.sonar import Sonar
    from sonar_raster.trajectory import Trajectory

    t0 = time.perf_counter()
    scene = seabed(case["triangles"])
    build = time.perf_counter() - t0
    sonar = Sonar(max_range=RANGE, range_bin=RANGE / case["bins"], sides=("port", "starboard"))
    pings = case["pings"]
    traj = Trajectory.straight((0.0, -0.5 * SPACING * pings, ALTITUDE), 0.0, SPACING, pings)
    settings = RasterSettings(max_edge=1.0, cull=case["path"] != "unculled")
    t0 = time.perf_counter()
    counters: dict = {}
    if case["path"] == "streamed":
        from sonar_raster.rendering.survey import render_survey

        with tempfile.TemporaryDirectory() as tmp:
            _, counters = render_survey(
                scene, sonar, traj, [Path(tmp) / "s.exr"], chunk_pings=512, settings=settings
            )
    else:
        with RasterRenderer(settings=settings) as r:
            image = r.render(scene, sonar, traj)
            counters = image.metadata["counters"]
            if case["path"] != "in-memory":  # again, scene uploaded: the per-render cost
                del image
                t1 = time.perf_counter()
                image = r.render(scene, sonar, traj)
                counters["warm_s"] = time.perf_counter() - t1
        if case["path"] == "in-memory":
            from sonar_raster.io.images import write_image

            with tempfile.TemporaryDirectory() as tmp:
                write_image(image, Path(tmp) / "s.exr")
        del image
    seconds = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # KiB on Linux
    return {**case, "build_s": build, "seconds": seconds, "peak_mb": peak, **counters}


def spawn(case: dict) -> dict:
    """Run a case in a fresh interpreter (its own peak memory)."""
    proc = subprocess.run(
        [sys.executable, __file__, "--case", json.dumps(case)],
        capture_output=True,
        text=True,
        check=False,
    )
    if proc.returncode != 0:
        return {**case, "error": proc.stderr.strip().splitlines()[-1] if proc.stderr else "?"}
    return json.loads(proc.stdout.strip().splitlines()[-1])


def sweeps(quick: bool) -> list[tuple[str, str, list[dict]]]:
    big = 1_000_000 if quick else 20_000_000
    tris = [10_000, 100_000, 1_000_000] + ([] if quick else [5_000_000, 20_000_000])
    pings = [100, 1_000, 10_000] + ([] if quick else [100_000])
    bins = [512, 1024, 2048, 4096] + ([] if quick else [8192])
    out = []
    cases = []
    for n in tris:
        for path in ("culled", "unculled"):
            cases.append(
                {
                    "sweep": "triangles",
                    "size": n,
                    "path": path,
                    "triangles": n,
                    "pings": 1000,
                    "bins": 2048,
                }
            )
    out.append(("triangles", "culled vs unculled", cases))
    cases = []
    for n in pings:
        cases.append(
            {
                "sweep": "pings",
                "size": n,
                "path": "streamed",
                "triangles": big,
                "pings": n,
                "bins": 4096,
            }
        )
        if n <= 10_000:
            cases.append(
                {
                    "sweep": "pings",
                    "size": n,
                    "path": "in-memory",
                    "triangles": big,
                    "pings": n,
                    "bins": 4096,
                }
            )
    out.append(("pings", "streamed vs in-memory", cases))
    cases = []
    for n in bins:
        for path in ("culled", "unculled"):
            cases.append(
                {
                    "sweep": "bins",
                    "size": n,
                    "path": path,
                    "triangles": 1_000_000,
                    "pings": 1000,
                    "bins": n,
                }
            )
    out.append(("bins", "culled vs unculled", cases))
    return out


def exponent(rows: list[dict], key: str) -> float:
    """Slope of log(key) against log(size) over the largest three sizes."""
    pts = sorted((r["size"], r[key]) for r in rows if "error" not in r and r[key] > 0)[-3:]
    if len(pts) < 2:
        return math.nan
    x, y = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    return float(np.polyfit(x, y, 1)[0])


def report(results: list[dict]) -> None:
    print(
        f"{'sweep':10s} {'size':>10s} {'path':>10s} {'seconds':>9s} {'warm s':>7s} {'peak MB':>9s} "
        f"{'tris drawn':>12s} {'draws':>6s} {'skipped':>7s} {'ratio':>7s}"
    )
    by = {(r["sweep"], r["size"], r["path"]): r for r in results}
    for r in results:
        if "error" in r:
            print(f"{r['sweep']:10s} {r['size']:>10d} {r['path']:>10s}  failed: {r['error']}")
            continue
        base = {"culled": "unculled", "streamed": "in-memory"}.get(r["path"])
        other = by.get((r["sweep"], r["size"], base)) if base else None
        ratio = f"{other['seconds'] / r['seconds']:.2f}x" if other and "error" not in other else ""
        warm = f"{r['warm_s']:7.2f}" if "warm_s" in r else " " * 7
        print(
            f"{r['sweep']:10s} {r['size']:>10d} {r['path']:>10s} {r['seconds']:9.2f} {warm} "
            f"{r['peak_mb']:9.0f} {r.get('triangles_drawn', 0):>12d} {r.get('draws', 0):>6d} "
            f"{r.get('draws_skipped_empty', 0):>7d} {ratio:>7s}"
        )
    print("\ngrowth exponents (log-log slope over the largest three sizes):")
    for sweep in ("triangles", "pings", "bins"):
        for path in sorted({r["path"] for r in results if r["sweep"] == sweep}):
            rows = [r for r in results if r["sweep"] == sweep and r["path"] == path]
            warm = ""
            if all("warm_s" in r for r in rows):
                warm = f"   warm render ~ n^{exponent(rows, 'warm_s'):.2f}"
            print(
                f"  {sweep:10s} {path:10s} time ~ n^{exponent(rows, 'seconds'):.2f}   "
                f"memory ~ n^{exponent(rows, 'peak_mb'):.2f}{warm}"
            )


def plot(results: list[dict], path: Path) -> None:
    plt = pyplot()
    fig, axes = plt.subplots(2, 3, figsize=(13, 7))
    for col, sweep in enumerate(("triangles", "pings", "bins")):
        for path_name in sorted({r["path"] for r in results if r["sweep"] == sweep}):
            rows = sorted(
                (
                    r
                    for r in results
                    if r["sweep"] == sweep and r["path"] == path_name and "error" not in r
                ),
                key=lambda r: r["size"],
            )
            sizes = [r["size"] for r in rows]
            axes[0, col].loglog(sizes, [r["seconds"] for r in rows], "o-", label=path_name)
            axes[1, col].loglog(sizes, [r["peak_mb"] for r in rows], "o-", label=path_name)
        axes[0, col].set_title(f"time against {sweep}")
        axes[1, col].set_title(f"peak memory against {sweep}")
        axes[1, col].set_xlabel(sweep)
        axes[0, col].set_ylabel("seconds")
        axes[1, col].set_ylabel("peak resident MB")
        for ax in axes[:, col]:
            if ax.get_legend_handles_labels()[0]:
                ax.legend()
            ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    print(f"wrote {path}")


def lod_table(quick: bool) -> list[dict]:
    """Level of detail: a rough seabed at finer and finer grids, drawn as is and coarsened.

    The error is the image's relative L1 against the full-detail render (pixel by pixel, and of
    the along-track mean profile), beside the height error the coarse grid reports.
    """
    from sonar_raster.rendering.gl.raster import RasterRenderer
    from sonar_raster.scene import build_scene
    from sonar_raster.scenes.seabed import level_of_detail, rough
    from sonar_raster.sonar import Sonar
    from sonar_raster.trajectory import Trajectory

    sonar = Sonar(max_range=30.0, range_bin=0.05, sides=("starboard",))
    traj = Trajectory.straight((0.0, -10.0, 8.0), 0.0, 0.1, 200)
    rows = []
    with RasterRenderer() as r:
        for res in [0.05, 0.025, 0.0125] + ([] if quick else [0.00625]):
            fine = rough(
                size=(34.0, 24.0),
                center=(15.0, 0.0),
                resolution=res,
                rms_height=0.03,
                correlation_length=0.5,
                seed=3,
            )
            coarse, report = level_of_detail(fine, 0.5 * sonar.range_bin)
            out = {}
            for name, field in (("full", fine), ("lod", coarse)):
                scene = build_scene([field.mesh(0.5)])
                r.render(scene, sonar, traj)  # upload and warm up
                t0 = time.perf_counter()
                image = r.render(scene, sonar, traj).sides["starboard"].astype(np.float64)
                out[name] = (image, time.perf_counter() - t0, scene.n_triangles)
            full, lod = out["full"][0], out["lod"][0]
            rows.append(
                {
                    "grid_m": res,
                    "triangles_full": out["full"][2],
                    "triangles_lod": out["lod"][2],
                    "seconds_full": out["full"][1],
                    "seconds_lod": out["lod"][1],
                    "l1_pixels": float(np.abs(lod - full).sum() / full.sum()),
                    "l1_profile": float(
                        np.abs(lod.mean(0) - full.mean(0)).sum() / full.mean(0).sum()
                    ),
                    "height_rms_m": report.get("rms_m", 0.0),
                    "height_max_m": report.get("max_m", 0.0),
                }
            )
    print("\nlevel of detail (rough seabed, 5 cm bins, LOD cell = half a bin):")
    print(
        f"{'grid m':>8s} {'tris full':>10s} {'tris lod':>9s} {'s full':>7s} {'s lod':>7s} "
        f"{'speed-up':>8s} {'L1 px':>7s} {'L1 prof':>7s} {'dz rms':>7s} {'dz max':>7s}"
    )
    for x in rows:
        print(
            f"{x['grid_m']:8.4f} {x['triangles_full']:10d} {x['triangles_lod']:9d} "
            f"{x['seconds_full']:7.3f} {x['seconds_lod']:7.3f} "
            f"{x['seconds_full'] / x['seconds_lod']:7.2f}x {x['l1_pixels']:7.4f} "
            f"{x['l1_profile']:7.4f} {x['height_rms_m']:7.4f} {x['height_max_m']:7.4f}"
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smaller sizes (about a minute)")
    parser.add_argument("--out", type=Path, default=Path("bench_out"))
    parser.add_argument("--case", help=argparse.SUPPRESS)
    parser.add_argument("--only", choices=("triangles", "pings", "bins", "lod"), help="one sweep")
    args = parser.parse_args()
    if args.case:
        print(json.dumps(run_case(json.loads(args.case))))
        return
    args.out.mkdir(parents=True, exist_ok=True)
    results = []
    for name, label, cases in sweeps(args.quick):
        if args.only and name != args.only:
            continue
        print(f"{name}: {label} ({len(cases)} runs)", flush=True)
        for case in cases:
            results.append(spawn(case))
            r = results[-1]
            status = r.get("error") or f"{r['seconds']:.2f} s, {r['peak_mb']:.0f} MB"
            print(f"  {case['path']:10s} {case['size']:>10d}: {status}", flush=True)
    if args.only in (None, "lod"):
        lod_rows = lod_table(args.quick)
        with open(args.out / "bench_lod.csv", "w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=list(lod_rows[0]))
            writer.writeheader()
            writer.writerows(lod_rows)
    if not results:
        return
    print()
    report(results)
    fields = sorted({k for r in results for k in r})
    with open(args.out / "bench_scale.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=fields)
        writer.writeheader()
        writer.writerows(results)
    print(f"wrote {args.out / 'bench_scale.csv'}")
    plot(results, args.out / "bench_scale.png")


if __name__ == "__main__":
    main()
