"""Benchmark the coherent model's scatterer throughput against earlier paths, in one process.

A benchmark, not a test: it prints a table (and writes it as CSV) and asserts nothing. Each case
is rendered, in one process and on the same job (same scatterers, spacings, seed), by:

* ``today: embree rays``  the coherent package as committed (``git show REF``, default HEAD),
                          loaded under another module name, with ``visibility="rays"``: one
                          embree ray per scatterer, the path issue 18 measured as today's;
* ``ref: GL range maps``  the same committed package with ``visibility="depth"``;
* ``numpy engine``        this working tree's package with ``engine="numpy"`` (array passes);
* ``new``                 this working tree's package (defaults: the compiled engine, warmed
                          up first so its one-off compilation is not timed).

``scatterers/s`` is ``n_scatterers`` (scatterers generated in reach of a ping block) over
wall seconds; ``new ×`` is a path's seconds over the new path's (its speed-up), ``cpu ×`` the
same in CPU seconds of the process (steadier on a shared machine). ``L1 vs ref`` is the relative L1
difference of the new image from the committed package's with the same visibility (an exact
change should give ~1e-7: the same scatterers and phases, other float rounding). Absolute
seconds depend on the machine's load; the ratios come from runs side by side (interleaved
with ``--repeat``, best kept).

Cases: ``barrel`` (``barrel.wrl``, the default seabed around a bare model, ``--pings`` pings,
λ/4 on the barrel, 4λ on the seabed) and ``seabed`` (``rough_plain`` of
``tools/bench_accuracy.py``: a 100 kHz sonar over a rough grid seabed, 64 pings, λ/2).

Usage: ``python tools/bench_coherent.py [--cases barrel,seabed] [--pings 20] [--ref HEAD]``
(``--ref 0683d49``: the package before the compiled engine).
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import parser  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "sonar_raster/rendering/coherent"
BASELINE = "sonar_raster.rendering._coherent_baseline"


def load_baseline(ref: str) -> Any:
    """The coherent package at git ``ref``, imported as ``BASELINE`` (its ``model`` module)."""
    names = subprocess.run(
        ["git", "ls-tree", "--name-only", f"{ref}:{PACKAGE}"],
        cwd=ROOT,
        check=True,
        capture_output=True,
        text=True,
    ).stdout.split()
    folder = Path(tempfile.mkdtemp(prefix="coherent_baseline_"))
    for name in names:
        if name.endswith(".py"):
            text = subprocess.run(
                ["git", "show", f"{ref}:{PACKAGE}/{name}"],
                cwd=ROOT,
                check=True,
                capture_output=True,
                text=True,
            ).stdout
            (folder / name).write_text(text)
    spec = importlib.util.spec_from_file_location(
        BASELINE, folder / "__init__.py", submodule_search_locations=[str(folder)]
    )
    assert spec is not None and spec.loader is not None
    package = importlib.util.module_from_spec(spec)
    sys.modules[BASELINE] = package
    spec.loader.exec_module(package)
    return importlib.import_module(f"{BASELINE}.model")


def barrel_case(pings: int) -> tuple[str, tuple, dict]:
    """The bare barrel (``barrel.wrl`` on the default seabed), λ/4 on it, 4λ on the seabed."""
    from sonar_raster.scenes.description import Overrides, load_scene

    barrel = ROOT / "sonar_raster/scenes/data/barrel.wrl"
    setup = load_scene(str(barrel), Overrides(pings=pings))
    sonar = setup.sonar
    seabed = min(4.0, 0.5 * sonar.range_bin / sonar.wavelength)
    options = {"spacing_wavelengths": 0.25, "seabed_spacing_wavelengths": seabed}
    return f"barrel[{pings}]", (setup.scene, sonar, setup.trajectory), options


def seabed_case() -> tuple[str, tuple, dict]:
    """``rough_plain`` of ``tools/bench_accuracy.py`` (64 pings, 20 m), λ/2 on the seabed."""
    from bench_accuracy import rough_case

    case = rough_case(False)
    options = {"spacing_wavelengths": 0.5, "seabed_spacing_wavelengths": 0.5}
    return case.label, (case.scene, case.sonar, case.trajectory), options


def run_case(label: str, job: tuple, options: dict, old: Any, repeat: int) -> list[dict]:
    """Time the three paths on one job; print and return one row per path."""
    from sonar_raster.rendering.coherent.model import render_coherent

    paths = (
        ("today: embree rays", old.render_coherent, {"visibility": "rays"}),
        ("ref: GL range maps", old.render_coherent, {"visibility": "depth"}),
        ("numpy engine", render_coherent, {"visibility": "depth", "engine": "numpy"}),
        ("new", render_coherent, {"visibility": "depth"}),
    )
    # compile (or load) the compiled engine before timing it: a one-off per installation
    coarse = {"spacing_wavelengths": 8.0, "seabed_spacing_wavelengths": 8.0}
    render_coherent(*job, **{**options, **coarse}, force=True)
    best: dict[str, float] = {}
    cpu: dict[str, float] = {}
    images: dict[str, Any] = {}
    for _ in range(repeat):  # interleaved, so load changes hit every path alike
        for name, fn, extra in paths:
            start, start_cpu = time.perf_counter(), time.process_time()
            images[name] = fn(*job, **options, **extra, force=True)
            best[name] = min(best.get(name, np.inf), time.perf_counter() - start)
            cpu[name] = min(cpu.get(name, np.inf), time.process_time() - start_cpu)
    rows = []
    new_md = images["new"].metadata
    for name, _, _ in paths:
        md = images[name].metadata
        rows.append(
            {
                "case": label,
                "path": name,
                "seconds": best[name],
                "cpu_seconds": cpu[name],
                "scatterers": md["n_scatterers"],
                "visible": md["n_visible"],
                "terms": md["n_pairs"],
                "scatterers_per_s": md["n_scatterers"] / best[name],
            }
        )
    ref = images["ref: GL range maps"].sides
    new = images["new"].sides
    diff = sum(float(np.abs(new[s] - ref[s]).sum()) for s in new) / sum(
        float(ref[s].sum()) for s in ref
    )
    print(f"\n# coherent, {label}, load {os.getloadavg()[0]:.2f}")
    print(
        f"{'path':20s} {'s':>8s} {'cpu s':>8s} {'scatterers':>11s} {'visible':>10s} "
        f"{'terms':>10s} {'scat/s':>9s} {'new ×':>6s} {'cpu ×':>6s}"
    )
    for row in rows:
        print(
            f"{row['path']:20s} {row['seconds']:8.2f} {row['cpu_seconds']:8.2f} "
            f"{row['scatterers']:11.3g} {row['visible']:10.3g} {row['terms']:10.3g} "
            f"{row['scatterers_per_s']:9.3g} {row['seconds'] / best['new']:6.2f} "
            f"{row['cpu_seconds'] / cpu['new']:6.2f}"
        )
    same = new_md["n_scatterers"] == images["ref: GL range maps"].metadata["n_scatterers"]
    print(f"new vs ref (same scatterers: {same}): {diff:.3g} relative L1")
    for row in rows:
        row["l1_vs_ref"] = diff if row["path"] == "new" else 0.0
    return rows


def main(argv: list[str] | None = None) -> None:
    ap = parser(__doc__, out=Path("bench_out"))
    ap.add_argument("--cases", default="barrel,seabed", help="barrel,seabed")
    ap.add_argument("--pings", type=int, default=20, help="pings of the barrel case (20)")
    ap.add_argument("--ref", default="HEAD", help="git ref of the earlier package (HEAD)")
    ap.add_argument("--repeat", type=int, default=1, help="interleaved runs per path (best kept)")
    args = ap.parse_args(argv)
    old = load_baseline(args.ref)
    rows: list[dict] = []
    for name in args.cases.split(","):
        case = barrel_case(args.pings) if name == "barrel" else seabed_case()
        rows += run_case(*case, old, args.repeat)
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "bench_coherent.csv"
    with path.open("w") as f:
        f.write(",".join(rows[0]) + "\n")
        for row in rows:
            f.write(",".join(str(v) for v in row.values()) + "\n")
    print(f"\nwrote {path}")


if __name__ == "__main__":
    main()
