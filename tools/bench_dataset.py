"""Dataset generation speed: samples/s with 1 and 2 workers and a local Dask cluster.

Runs the bundled dataset config (512 pings x 1024 bins, labelled, shadows, PNG + EXR) into
fresh temporary folders, one run per mode, in this one process invocation:

- ``1 worker``: this process renders (the baseline of the ratios);
- ``2 workers``: a local spawn pool;
- ``dask local``: a LocalCluster of 2 processes, 1 thread each.

Each run's wall time includes starting its workers ("steady" counts from the first finished
sample to the last, leaving start-up out); the per-sample split (scene building,
rendering with labels, the seabed-only shadow pass, labels, effects, encoding, writing) is the
mean worker wall time from the index, and CPU s/sample the worker's CPU time (all its threads,
llvmpipe's included): the cost per core, which other jobs on the machine do not inflate. A
last line renders the same scenes without labels or the seabed-only pass (the plain renderer)
to show what labelling costs.

    python tools/bench_dataset.py [-n 8] [--modes 1,2,dask] [--config PATH]
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from pathlib import Path

from _common import DATASET_CONFIG, parser

from sonar_raster.dataset.generate import STAGES, generate_dataset, load_dataset_config  # noqa: E402


def run_mode(config, mode: str, n: int, seed: int) -> dict:
    workers, scheduler = {"1": (1, None), "2": (2, None), "dask": (2, "local")}[mode]
    with tempfile.TemporaryDirectory(prefix="bench-dataset-") as tmp:
        t0 = time.perf_counter()
        summary = generate_dataset(
            config, tmp, count=n, seed=seed, workers=workers, scheduler=scheduler
        )
        wall = time.perf_counter() - t0
        records = [json.loads(x) for x in (Path(tmp) / "index.jsonl").read_text().splitlines()]
    ok = [r for r in records if r["status"] == "ok"]
    stages = {k: sum(r["timings"].get(k, 0.0) for r in ok) / max(1, len(ok)) for k in STAGES}
    cpu = sum(r["timings"]["cpu_s"] for r in ok) / max(1, len(ok))
    done = sorted(r["committed_unix"] for r in records)
    steady = (len(done) - 1) / (done[-1] - done[0]) if len(done) > 1 else float("nan")
    return {
        "mode": mode,
        "wall_s": wall,
        "rate": n / wall,
        "steady": steady,
        "failed": len(summary.failed),
        "stages": stages,
        "worker_s": sum(stages.values()),
        "cpu_s": cpu,
    }


def plain_render(config, n: int, seed: int) -> dict:
    """Baseline: the same scenes rendered without labels and without the seabed-only pass."""
    from sonar_raster.dataset.scene import draw_sample
    from sonar_raster.rendering.gl.raster import RasterRenderer

    times = {"labelled": 0.0, "plain": 0.0}
    with RasterRenderer() as renderer:
        d = draw_sample(config, seed, 0)
        renderer.render(d.scene, d.sonar, d.trajectory, labels=True)  # compile both programs
        renderer.render(d.scene, d.sonar, d.trajectory)
        for i in range(n):
            d = draw_sample(config, seed, i)
            t0 = time.perf_counter()
            renderer.render(d.scene, d.sonar, d.trajectory)
            t1 = time.perf_counter()
            renderer.render(d.scene, d.sonar, d.trajectory, labels=True)
            t2 = time.perf_counter()
            times["plain"] += t1 - t0
            times["labelled"] += t2 - t1
    return {k: v / n for k, v in times.items()}


def main() -> None:
    ap = parser(__doc__)
    ap.add_argument("-n", type=int, default=8, help="samples per mode")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--modes", default="1,2,dask")
    ap.add_argument("--config", default=str(DATASET_CONFIG))
    args = ap.parse_args()
    config = load_dataset_config(args.config)
    print(
        f"config {Path(args.config).name}: {config.pings} pings x {config.bins} bins, "
        f"{args.n} samples per mode, {os.cpu_count()} CPUs, "
        f"load average {os.getloadavg()[0]:.1f} before"
    )
    rows = [run_mode(config, m, args.n, args.seed) for m in args.modes.split(",")]
    base = rows[0]["rate"]
    print()
    print(
        "| mode | wall s | samples/s | x baseline | steady samples/s | worker s/sample | "
        "CPU s/sample | " + " | ".join(k[:-2] + " ms" for k in STAGES) + " | failed |"
    )
    print("|" + "---|" * (8 + len(STAGES)))
    for r in rows:
        stages = " | ".join(f"{1000 * r['stages'][k]:.0f}" for k in STAGES)
        print(
            f"| {r['mode']} | {r['wall_s']:.1f} | {r['rate']:.2f} | {r['rate'] / base:.2f} | "
            f"{r['steady']:.2f} | "
            f"{r['worker_s']:.2f} | {r['cpu_s']:.2f} | {stages} | {r['failed']} |"
        )
    print(
        f"\nload average {os.getloadavg()[0]:.1f} after. CPU s/sample counts every thread of the "
        "worker (llvmpipe's too): the cost per core, whatever else shares the machine."
    )
    plain = plain_render(config, min(args.n, 4), args.seed)
    print()
    print(
        f"render of the full scene only, mean of {min(args.n, 4)}: plain {plain['plain']:.3f} s,"
        f" with labels {plain['labelled']:.3f} s (x{plain['labelled'] / plain['plain']:.2f})"
    )


if __name__ == "__main__":
    main()
