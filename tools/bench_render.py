"""Benchmark the GL renderer against the numpy reference and embree ray casting of the same rays.

A benchmark, not a test: it prints tables (and writes them as CSV with a time-against-error plot)
and asserts nothing. All methods run in one process, on the same scenes:

* ``gl``         RasterRenderer with default RasterSettings, warm (shaders compiled, geometry
                 uploaded); ``first s`` is the first render on a fresh renderer, which includes
                 shader compilation and geometry upload (context creation excluded).
* ``gl-raster``  the same with ``heightfield=False``: seabed grids rasterised like any mesh
                 (the path before the heightfield sweep), timed in the same process; its
                 ``t/t_gl`` is the sweep's speed-up.
* ``embree``     the GL path's rays (one per framebuffer texel of every segment and side) cast with
                 trimesh + embreex, weighted ``R Φ dα t row_width`` (Lambert) and deposited with the
                 GL rule ("footprint" split) in float64: see ``tools/_fan_embree.py``. ``first s``
                 includes building the BVH.
* ``reference``  ``render_reference`` (numpy patches, default patch = range_bin / 4).

Relative L1 = Σ|I − I_ref| / Σ I_ref over all sides, against a high-sampling reference named in
the ``vs`` column: ``ref/8`` = ``render_reference`` with patch = range_bin / 8 on a window of pings
around the track's middle (the bundled scenes), or ``gl-hi`` = the GL path at oversample 16,
along_samples 8 (the large seabed, where the numpy reference is unaffordable). A bundled scene is
timed twice: on the window itself (every method) and on its full track (gl, embree), whose error
is taken over the window's rows. ``t/t_gl`` is a method's time over the warm GL time of the same
case. Times are the best of ``--repeat`` runs; a method stops repeating once its runs have taken
``--cap`` seconds (the ``runs`` column says how many were made).

The sweep renders one scene's full track at oversample × along_samples × split and prints time
against error (on the window rows, vs ``ref/8``): the curve that chooses the defaults.

``--coherent`` times the coherent model (Eq. 10) on the bare barrel model (``barrel.wrl``, the
default scene around a bare model) over ``--coherent-pings`` pings, in one process: the earlier
path (one embree ray per scatterer, ``visibility="rays"``) and the new one (the GL raster's
range maps, ``visibility="depth"``) on the same job (λ/4 on the barrel, the default seabed
spacing), with scatterers/s and their ratio; then the new defaults on their own, and the
estimate of the earlier default (λ/4 everywhere) that could not finish. ``--coherent-only``
skips the raster tables.

Usage: ``python tools/bench_render.py [--quick] [--scenes a,b] [--out bench_out/]``.
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from _common import parser, pyplot
from _fan_embree import EmbreeFan  # noqa: E402

from sonar_raster.rendering.gl.raster import RasterRenderer, RasterSettings  # noqa: E402
from sonar_raster.rendering.reference import render_reference  # noqa: E402
from sonar_raster.scene import Scene, build_scene  # noqa: E402
from sonar_raster.scenes.bundled import bundled_scene, list_bundled  # noqa: E402
from sonar_raster.scenes.description import load_scene_file  # noqa: E402
from sonar_raster.scenes.seabed import make_seabed  # noqa: E402
from sonar_raster.sonar import BeamPattern, Sonar  # noqa: E402
from sonar_raster.trajectory import Trajectory  # noqa: E402

SEABED = "seabed_2m"
SWEEP_OVERSAMPLE = (1, 2, 4, 8)
SWEEP_ALONG = (1, 2, 4)
SWEEP_SPLIT = ("nearest", "footprint")
GL_HIGH = RasterSettings(oversample=16.0, along_samples=8)


# -- scenes -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class Case:
    """One timed render job: a scene, a sonar and a trajectory, and where its error is taken.

    ``err_rows`` selects this case's image rows that the accuracy reference covers.
    """

    name: str
    label: str
    scene: Scene
    sonar: Sonar
    trajectory: Trajectory
    err_rows: slice


@dataclass
class Accuracy:
    """A high-sampling reference image (per side) and how it was made."""

    kind: str
    sides: dict
    seconds: float


def window(trajectory: Trajectory, pings: int) -> slice:
    """The ``pings`` pings around the middle of a trajectory."""
    start = max(0, trajectory.n_pings // 2 - pings // 2)
    return slice(start, min(trajectory.n_pings, start + pings))


def bundled_cases(name: str, pings: int) -> list[Case]:
    """The window case and the full-track case of one bundled scene."""
    setup = load_scene_file(bundled_scene(name))
    full = setup.trajectory
    rows = window(full, pings)
    win = full.subset(rows)
    return [
        Case(name, f"{name}[{rows.start}:{rows.stop}]", setup.scene, setup.sonar, win, slice(None)),
        Case(name, f"{name}[full]", setup.scene, setup.sonar, full, rows),
    ]


def seabed_case(quick: bool) -> Case:
    """A rough heightfield at 0.1 m: 100 m × 100 m (2 M triangles), 1000 pings × 4096 bins."""
    size, pings, bins, max_range, altitude = (
        ((20.0, 24.0), 200, 1024, 25.0, 5.0) if quick else ((100.0, 100.0), 1000, 4096, 100.0, 10.0)
    )
    field_ = make_seabed(
        "rough", size=size, center=(0.5 * size[0] - 1.0, 0.0), resolution=0.1, seed=1
    )
    scene = build_scene([field_.mesh(0.3, "seabed")])
    sonar = Sonar(
        frequency_hz=100e3,
        max_range=max_range,
        range_bin=max_range / bins,
        beam=BeamPattern.gaussian(40.0),
        tilt=math.radians(10.0),
        sides=("starboard",),
    )
    spacing = size[1] / pings
    traj = Trajectory.straight((0.0, -0.5 * size[1] + 0.5 * spacing, altitude), 0.0, spacing, pings)
    label = f"{SEABED}[{scene.n_triangles / 1e6:.2g}M tri]"
    return Case(SEABED, label, scene, sonar, traj, slice(None))


# -- timing -----------------------------------------------------------------------------------
@dataclass
class Timing:
    """Best and first wall time of repeated calls, how many calls, and the last result."""

    best: float
    first: float
    runs: int
    result: object


def best_of(fn: Callable[[], object], repeat: int, cap: float) -> Timing:
    """Call ``fn`` up to ``repeat`` times (at least once); stop once the calls took ``cap`` s."""
    times: list[float] = []
    out = None
    while not times or (len(times) < repeat and sum(times) < cap):
        start = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - start)
    return Timing(min(times), times[0], len(times), out)


def timed(fn: Callable[[], object]) -> tuple[float, object]:
    """Wall time of one call and its result."""
    start = time.perf_counter()
    out = fn()
    return time.perf_counter() - start, out


# -- accuracy references ----------------------------------------------------------------------
def rel_l1(sides: dict, acc: Accuracy | None, rows: slice) -> float:
    """Σ|I − I_ref| / Σ I_ref over all sides, on ``rows`` of ``sides``; NaN without a reference."""
    if acc is None:
        return float("nan")
    diff = total = 0.0
    for side, ref in acc.sides.items():
        diff += float(np.abs(sides[side][rows].astype(np.float64) - ref).sum())
        total += float(ref.sum())
    return diff / total if total > 0 else float("nan")


def reference_accuracy(case: Case, divisor: float) -> Accuracy:
    """``render_reference`` at patch = range_bin / divisor on the case's error rows."""
    traj = case.trajectory.subset(case.err_rows)
    patch = case.sonar.range_bin / divisor
    seconds, image = timed(lambda: render_reference(case.scene, case.sonar, traj, patch_size=patch))
    sides = {s: a.astype(np.float64) for s, a in image.sides.items()}
    return Accuracy(f"ref/{divisor:g}", sides, seconds)


def gl_accuracy(case: Case, renderer: RasterRenderer) -> Accuracy:
    """The GL path at :data:`GL_HIGH` sampling (oversample 16, along_samples 8)."""
    renderer.settings = GL_HIGH
    seconds, image = timed(lambda: renderer.render(case.scene, case.sonar, case.trajectory))
    renderer.settings = RasterSettings()
    sides = {s: a[case.err_rows].astype(np.float64) for s, a in image.sides.items()}
    return Accuracy("gl-hi", sides, seconds)


# -- the main table ---------------------------------------------------------------------------
@dataclass
class Row:
    """One line of the main table."""

    case: Case
    method: str
    seconds: float
    first: float
    error: float
    vs: str
    runs: int
    notes: str = ""
    ratio: float = float("nan")
    load: float = field(default_factory=lambda: os.getloadavg()[0])  # 1-min load when measured

    def as_dict(self) -> dict:
        c = self.case
        pings = c.trajectory.n_pings
        return {
            "scene": c.label,
            "triangles": c.scene.n_triangles,
            "pings": pings,
            "bins": c.sonar.n_bins,
            "sides": len(c.sonar.sides),
            "method": self.method,
            "seconds": self.seconds,
            "pings_per_s": pings / self.seconds,
            "first_s": self.first,
            "rel_l1": self.error,
            "vs": self.vs,
            "t_over_gl": self.ratio,
            "runs": self.runs,
            "load": self.load,
            "notes": self.notes,
        }


@dataclass
class Bench:
    """Options and shared state of one benchmark run."""

    repeat: int
    cap: float
    backend: str | None
    ref_divisor: float = 8.0
    accuracy: dict = field(default_factory=dict)  # scene name -> Accuracy
    fans: dict = field(default_factory=dict)  # scene name -> (EmbreeFan, build seconds)

    def fan(self, case: Case) -> tuple[EmbreeFan, float]:
        if case.name not in self.fans:
            seconds, fan = timed(lambda: EmbreeFan(case.scene))
            self.fans[case.name] = (fan, seconds)
        return self.fans[case.name]


def gl_row(
    bench: Bench,
    case: Case,
    acc: Accuracy | None,
    settings: RasterSettings | None = None,
    method: str = "gl",
) -> Row:
    """Warm GL time (best of repeats) and the first render on a fresh renderer."""
    with RasterRenderer(bench.backend, settings) as renderer:
        render = lambda: renderer.render(case.scene, case.sonar, case.trajectory)  # noqa: E731
        first, _ = timed(render)
        t = best_of(render, bench.repeat, bench.cap)
    meta = t.result.metadata
    return Row(
        case,
        method,
        t.best,
        first,
        rel_l1(t.result.sides, acc, case.err_rows),
        acc.kind if acc else "-",
        t.runs,
        f"{meta['draws']} draw(s) of {meta['triangles']} triangles, "
        f"{meta.get('grid_sweeps', 0)} grid sweep(s)",
    )


def embree_row(bench: Bench, case: Case, planner: RasterRenderer, acc: Accuracy | None) -> Row:
    """Embree casting of the default GL rays; ``first`` includes building the BVH."""
    fan, build = bench.fan(case)
    settings = RasterSettings()
    t = best_of(
        lambda: fan.render(case.sonar, case.trajectory, settings, planner), bench.repeat, bench.cap
    )
    tt = fan.times
    notes = (
        f"{tt.rays / 1e6:.2f} M rays: cast {tt.cast:.2f} s + weight/deposit "
        f"{tt.deposit:.2f} s; BVH build {build:.2f} s"
    )
    return Row(
        case,
        "embree",
        t.best,
        build + t.first,
        rel_l1(t.result.sides, acc, case.err_rows),
        acc.kind if acc else "-",
        t.runs,
        notes,
    )


def reference_row(bench: Bench, case: Case, acc: Accuracy | None) -> Row:
    """The numpy reference at its default patch size (range_bin / 4)."""
    t = best_of(
        lambda: render_reference(case.scene, case.sonar, case.trajectory), bench.repeat, bench.cap
    )
    meta = t.result.metadata
    return Row(
        case,
        "reference",
        t.best,
        t.first,
        rel_l1(t.result.sides, acc, case.err_rows),
        acc.kind if acc else "-",
        t.runs,
        f"patch bin/4: {meta['n_patches'] / 1e6:.2f} M patches, {meta['n_rays'] / 1e6:.2f} M rays",
    )


def accuracy_row(case: Case, acc: Accuracy) -> Row:
    return Row(
        case,
        f"{acc.kind} (acc. ref)",
        acc.seconds,
        acc.seconds,
        float("nan"),
        "-",
        1,
        "the high-sampling reference itself",
    )


def run_scene(bench: Bench, name: str, pings: int, quick: bool, gl_high: bool) -> list[Row]:
    """All rows of one scene: per case gl, embree (and, on a window, reference)."""
    cases = [seabed_case(quick)] if name == SEABED else bundled_cases(name, pings)
    rows: list[Row] = []
    with RasterRenderer(bench.backend) as planner:
        acc = scene_accuracy(bench, cases[0], planner, gl_high)
        if acc is not None:
            rows.append(accuracy_row(cases[0], acc))
            print_rows(rows[-1:], header=False)
        for case in cases:
            case_rows = [
                gl_row(bench, case, acc),
                gl_row(bench, case, acc, RasterSettings(heightfield=False), "gl-raster"),
                embree_row(bench, case, planner, acc),
            ]
            if name != SEABED and case.err_rows == slice(None):
                case_rows.append(reference_row(bench, case, acc))
            for row in case_rows:
                row.ratio = row.seconds / case_rows[0].seconds
                print_rows([row], header=False)
            rows.extend(case_rows)
    return rows


def scene_accuracy(
    bench: Bench, case: Case, planner: RasterRenderer, gl_high: bool
) -> Accuracy | None:
    """The scene's high-sampling reference (cached): ref/8 on the window, or GL at 16 × 8."""
    if case.name not in bench.accuracy:
        if case.name != SEABED:
            bench.accuracy[case.name] = reference_accuracy(case, bench.ref_divisor)
        elif gl_high:
            bench.accuracy[case.name] = gl_accuracy(case, planner)
        else:
            return None
    return bench.accuracy[case.name]


# -- the sweep --------------------------------------------------------------------------------
@dataclass
class SweepPoint:
    oversample: float
    along: int
    split: str
    seconds: float
    runs: int
    error: float
    pings: int


def run_sweep(bench: Bench, name: str, pings: int, grid: tuple) -> list[SweepPoint]:
    """Time the full track of ``name`` at every setting; error on the window rows vs ref/8."""
    full = bundled_cases(name, pings)[1]
    acc = bench.accuracy.get(name) or reference_accuracy(full, bench.ref_divisor)
    bench.accuracy[name] = acc
    points = []
    with RasterRenderer(bench.backend) as renderer:
        render = lambda: renderer.render(full.scene, full.sonar, full.trajectory)  # noqa: E731
        for split in grid[2]:  # compile each split's program before timing
            renderer.settings = RasterSettings(oversample=1.0, along_samples=1, split=split)
            render()
        for split in grid[2]:
            for along in grid[1]:
                for over in grid[0]:
                    renderer.settings = RasterSettings(
                        oversample=float(over), along_samples=along, split=split
                    )
                    t = best_of(render, bench.repeat, bench.cap)
                    err = rel_l1(t.result.sides, acc, full.err_rows)
                    points.append(
                        SweepPoint(over, along, split, t.best, t.runs, err, full.trajectory.n_pings)
                    )
                    print_sweep([points[-1]], header=False)
    return points


# -- where GL time goes -----------------------------------------------------------------------
class _Clocked:
    """Proxy timing one method of a GL object (with ``ctx.finish()`` before and after)."""

    def __init__(self, obj: object, method: str, clock: Callable) -> None:
        self._obj = obj
        setattr(self, method, clock(getattr(obj, method)))

    def __getattr__(self, name: str) -> object:
        return getattr(self._obj, name)

    def __getitem__(self, key: str) -> object:
        return self._obj[key]

    def __contains__(self, key: str) -> bool:
        return key in self._obj


def gl_stages(bench: Bench, case: Case, settings: RasterSettings | None = None) -> dict[str, float]:
    """Seconds per stage of one warm GL render (relies on RasterRenderer internals).

    ``ctx.finish()`` around every timed call serialises CPU and GL work, so the stages add up to
    a little more than a plain warm render.
    """
    out: dict[str, float] = {}
    with RasterRenderer(bench.backend, settings) as r:
        render = lambda: r.render(case.scene, case.sonar, case.trajectory)  # noqa: E731
        render()
        out["plain warm render"] = best_of(render, bench.repeat, bench.cap).best
        ctx = r.ctx

        def clock(label: str) -> Callable:
            def wrap(fn: Callable) -> Callable:
                def timed_call(*args: object, **kwargs: object) -> object:
                    ctx.finish()
                    start = time.perf_counter()
                    result = fn(*args, **kwargs)
                    ctx.finish()
                    out[label] = out.get(label, 0.0) + time.perf_counter() - start
                    return result

                return timed_call

            return wrap

        for name in ("_plan", "_column_tables", "_fixed_point_scale", "_framebuffer", "_read"):
            setattr(r, name, clock(name)(getattr(r, name)))
        if "vao:0" in r._geometry:
            r._geometry["vao:0"] = _Clocked(r._geometry["vao:0"], "render", clock("pass 1: draw"))
        for key in [k for k in r._programs if k.endswith(":0") and ":" in k]:
            kind = key.split(":")[0]
            if kind in ("accumulate", "sweep"):
                label = "pass 2: accumulate" if kind == "accumulate" else "grid sweep + pass 2"
                r._programs[key] = _Clocked(r._programs[key], "run", clock(label))
        total, _ = timed(clock("instrumented render")(render))
    out["other (clears, uploads, uniforms)"] = total - sum(
        v for k, v in out.items() if k not in ("plain warm render", "instrumented render")
    )
    return out


# -- output -----------------------------------------------------------------------------------
#: (header, width) of the printed main table; the CSV has the same fields, unformatted.
MAIN_COLUMNS = (
    ("scene", 27), ("tri", 8), ("pings×bins×sides", 16), ("method", 18), ("s", 8),
    ("pings/s", 8), ("first s", 8), ("rel L1", 9), ("vs", 6), ("t/t_gl", 7), ("runs", 4),
    ("load", 5), ("notes", 0),
)  # fmt: skip


def _fmt(value: float, digits: int = 3) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{value:.{digits}g}"


def _line(cells: tuple[str, ...]) -> str:
    pairs = zip(cells, MAIN_COLUMNS, strict=True)
    return " ".join(c.ljust(width) for c, (_, width) in pairs).rstrip()


def print_rows(rows: list[Row], header: bool = True) -> None:
    """Print main-table rows (and the header)."""
    if header:
        print(_line(tuple(h for h, _ in MAIN_COLUMNS)))
    for row in rows:
        d = row.as_dict()
        cells = (
            d["scene"], str(d["triangles"]), f"{d['pings']}×{d['bins']}×{d['sides']}",
            d["method"], f"{d['seconds']:.3f}", _fmt(d["pings_per_s"]), f"{d['first_s']:.3f}",
            _fmt(d["rel_l1"]), d["vs"], _fmt(d["t_over_gl"]), str(d["runs"]),
            f"{d['load']:.2f}", d["notes"],
        )  # fmt: skip
        print(_line(cells), flush=True)


def print_sweep(points: list[SweepPoint], header: bool = True) -> None:
    if header:
        print(
            f"{'oversample':>10} {'along':>5} {'split':>9} {'s':>8} {'pings/s':>8} "
            f"{'rel L1':>9} {'runs':>4}"
        )
    for p in points:
        print(
            f"{p.oversample:>10g} {p.along:>5d} {p.split:>9} {p.seconds:>8.3f} "
            f"{p.pings / p.seconds:>8.3g} {p.error:>9.3g} {p.runs:>4d}",
            flush=True,
        )


def write_csv(path: Path, dicts: list[dict]) -> None:
    if not dicts:
        return
    with path.open("w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(dicts[0]))
        writer.writeheader()
        writer.writerows(dicts)


def plot(path: Path, rows: list[Row], points: list[SweepPoint], sweep_name: str) -> None:
    """Time against error, log-log: the main table's rows (left), the settings sweep (right)."""
    plt = pyplot()
    fig, (left, right) = plt.subplots(1, 2, figsize=(13, 5.5))
    markers = {"gl": ("o", "C0"), "embree": ("s", "C1"), "reference": ("^", "C2")}
    for row in rows:
        if row.method in markers and math.isfinite(row.error) and row.error > 0:
            marker, colour = markers[row.method]
            left.loglog(row.seconds, row.error, marker, color=colour)
            left.annotate(row.case.label, (row.seconds, row.error), fontsize=6)
    for method, (marker, colour) in markers.items():
        left.plot([], [], marker, color=colour, label=method)
    left.set(xlabel="seconds", ylabel="relative L1", title="methods per scene")
    left.legend()
    for (split, along), group in _groups(points).items():
        xs, ys = [p.seconds for p in group], [p.error for p in group]
        style = "o-" if split == "footprint" else "x--"
        colour = f"C{sorted({p.along for p in points}).index(along)}"
        right.loglog(xs, ys, style, color=colour, label=f"{split}, along {along}")
        for p in group:
            right.annotate(f"{p.oversample:g}", (p.seconds, p.error), fontsize=6)
    right.set(
        xlabel="seconds",
        ylabel="relative L1 vs ref/8",
        title=f"GL settings sweep on {sweep_name} (labels: oversample)",
    )
    if points:
        right.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _groups(points: list[SweepPoint]) -> dict:
    groups: dict = {}
    for p in points:
        groups.setdefault((p.split, p.along), []).append(p)
    return groups


# -- main -------------------------------------------------------------------------------------
# -- coherent model ---------------------------------------------------------------------------
def coherent_bench(pings: int) -> list[dict]:
    """Old (embree rays) and new (GL range maps) coherent paths on the bare barrel, side by side.

    Prints one row per run and returns them as dicts.
    """
    from sonar_raster.rendering.coherent.model import SEABED_SPACING, render_coherent
    from sonar_raster.scenes.description import Overrides, load_scene

    barrel = Path(__file__).resolve().parents[1] / "sonar_raster/scenes/data/barrel.wrl"
    setup = load_scene(str(barrel), Overrides(pings=pings))
    job = (setup.scene, setup.sonar, setup.trajectory)
    seabed = min(SEABED_SPACING, 0.5 * setup.sonar.range_bin / setup.sonar.wavelength)
    same = {"spacing_wavelengths": 0.25, "seabed_spacing_wavelengths": seabed}
    runs = [
        ("old: embree rays", {**same, "visibility": "rays"}),
        ("new: GL range maps", {**same, "visibility": "depth"}),
        ("new: defaults", {}),
    ]
    print(
        f"\n# coherent, bare barrel ({setup.scene.n_triangles} triangles), {pings} pings, "
        f"load {os.getloadavg()[0]:.2f}"
    )
    head = ("path", "seconds", "scatterers", "visible", "terms", "scatterers/s", "est. s")
    print(_cline(head))
    out, images = [], {}
    for label, options in runs:
        seconds, image = timed(lambda o=options: render_coherent(*job, **o))
        md = image.metadata
        row = {
            "path": label,
            "seconds": seconds,
            "scatterers": md["n_scatterers"],
            "visible": md["n_visible"],
            "terms": md["n_pairs"],
            "scatterers_per_s": md["n_scatterers"] / seconds,
            "estimated_s": md["estimate"]["seconds"],
        }
        images[label] = image
        out.append(row)
        print(
            _cline(
                (
                    label,
                    _fmt(seconds),
                    f"{row['scatterers']:.3g}",
                    f"{row['visible']:.3g}",
                    f"{row['terms']:.3g}",
                    f"{row['scatterers_per_s']:.3g}",
                    _fmt(row["estimated_s"]),
                )
            )
        )
    a, b = (images[label].sides for label, _ in runs[:2])
    diff = sum(float(np.abs(a[k] - b[k]).sum()) for k in a) / sum(float(a[k].sum()) for k in a)
    print(
        f"new / old scatterers/s: {out[1]['scatterers_per_s'] / out[0]['scatterers_per_s']:.2f}×; "
        f"images differ by {100 * diff:.3g} % relative L1 (visibility at shadow edges)"
    )
    # the earlier default (λ/4 everywhere) is no longer refused (estimated ~22 min since the
    # coherent-throughput work): tools/bench_coherent.py compares the paths instead
    return out


def _cline(cells: tuple[str, ...]) -> str:
    widths = (20, 9, 11, 11, 11, 13, 8)
    return " ".join(c.ljust(w) for c, w in zip(cells, widths, strict=True)).rstrip()


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    bundled = [n for n, _ in list_bundled()]
    ap = parser(__doc__, out=Path("bench_out"))
    ap.add_argument(
        "--quick",
        action="store_true",
        help="small sizes (two small scenes, a 96 k-triangle seabed, 2-ping windows)",
    )
    ap.add_argument("--scenes", help=f"comma-separated subset of {', '.join(bundled + [SEABED])}")
    ap.add_argument("--window", type=int, help="pings in a bundled scene's window (16; quick 2)")
    ap.add_argument("--repeat", type=int, default=3, help="timing runs per method (best is kept)")
    ap.add_argument(
        "--cap",
        type=float,
        default=20.0,
        help="stop repeating a method once its runs took this many seconds",
    )
    ap.add_argument(
        "--sweep-scene",
        help="scene of the settings sweep, or 'none' (truck_wheel_on_clay; quick flat_calibration)",
    )
    ap.add_argument(
        "--no-gl-high",
        action="store_true",
        help=f"skip the GL oversample 16 × along 8 accuracy reference of {SEABED}",
    )
    ap.add_argument(
        "--stages",
        action="store_true",
        help="print where a warm GL render of the largest case spends its time",
    )
    ap.add_argument("--backend", choices=("egl", "osmesa"), help="GL backend")
    ap.add_argument(
        "--coherent", action="store_true", help="also time the coherent model, old and new paths"
    )
    ap.add_argument("--coherent-only", action="store_true", help="time the coherent model only")
    ap.add_argument(
        "--coherent-pings", type=int, default=20, help="pings of the coherent runs (20)"
    )
    args = ap.parse_args(argv)
    default = ["flat_calibration", "cylinder_on_flat", SEABED] if args.quick else bundled + [SEABED]
    args.scenes = args.scenes.split(",") if args.scenes else default
    unknown = sorted(set(args.scenes) - set(bundled) - {SEABED})
    if unknown:
        ap.error(
            f"unknown scene(s) {', '.join(unknown)}; choose from {', '.join(bundled + [SEABED])}"
        )
    args.window = args.window or (2 if args.quick else 16)
    args.sweep_scene = args.sweep_scene or (
        "flat_calibration" if args.quick else "truck_wheel_on_clay"
    )
    if args.sweep_scene not in bundled + ["none"]:
        ap.error(f"--sweep-scene must be a bundled scene or 'none', got {args.sweep_scene!r}")
    return args


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    if args.coherent_only:
        write_csv(args.out / "bench_coherent.csv", coherent_bench(args.coherent_pings))
        return
    bench = Bench(args.repeat, args.cap, args.backend)
    with RasterRenderer(args.backend) as probe:
        info = probe.gl_info
    print(
        f"# {info['gl_backend']}: {info['gl_renderer']}, {info['gl_version']}; "
        f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}; best of {args.repeat} "
        f"(cap {args.cap:g} s); defaults {RasterSettings()}"
    )
    print_rows([])
    rows: list[Row] = []
    for name in args.scenes:
        rows.extend(run_scene(bench, name, args.window, args.quick, not args.no_gl_high))
    write_csv(args.out / "bench_render.csv", [r.as_dict() for r in rows])
    points: list[SweepPoint] = []
    if args.sweep_scene != "none":
        grid = (
            ((1, 4), (1, 2), SWEEP_SPLIT)
            if args.quick
            else (SWEEP_OVERSAMPLE, SWEEP_ALONG, SWEEP_SPLIT)
        )
        print(
            f"\n# sweep: {args.sweep_scene}, full track timed, rel L1 on the window rows vs "
            f"ref/{bench.ref_divisor:g}"
        )
        print_sweep([])
        points = run_sweep(bench, args.sweep_scene, args.window, grid)
        write_csv(args.out / "bench_sweep.csv", [vars(p) for p in points])
    if args.stages and rows:
        big = max(
            (r.case for r in rows),
            key=lambda c: c.trajectory.n_pings * c.sonar.n_bins * c.scene.n_triangles,
        )
        for label, settings in (
            ("heightfield sweep", RasterSettings()),
            ("grid rasterised", RasterSettings(heightfield=False)),
        ):
            print(f"\n# where a warm GL render of {big.label} spends its time (s), {label}")
            for stage, seconds in gl_stages(bench, big, settings).items():
                print(f"{stage:>36} {seconds:8.3f}")
    if args.coherent:
        write_csv(args.out / "bench_coherent.csv", coherent_bench(args.coherent_pings))
    plot(args.out / "bench_render.png", rows, points, args.sweep_scene)
    print(f"\nwrote {args.out}/bench_render.csv, bench_sweep.csv, bench_render.png")


if __name__ == "__main__":
    main()
