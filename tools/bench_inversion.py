"""Round trips of the inversion: render known seabeds, invert them, compare with the truth.

A benchmark, not a test: it prints tables and writes a plot, and asserts nothing. The setup is
the one of ``tests/test_invert.py``: 32 pings 0.1 m apart at 10 m altitude, starboard, 20 m
range in 5 cm bins, a Gaussian 50° beam tilted 20°, rendered by the GL path.

Seabeds: flat (R 0.5); ripples (1 m wavelength, 5 cm amplitude); a mound (one Gaussian,
0.4 m high, σ 1.5 m, at 12 m ground range); a trench (along track, 0.3 m deep, σ 0.5 m, at
10 m); a rough plain (5 cm rms, 2 m correlation length) with two reflectivity patches (0.8 at
6–9 m and 0.25 at 14–17 m ground range, on half the track each, 0.5 elsewhere); "mound96":
the mound under a track three times as long (96 pings), where it covers a minority of the pings
at its ranges.

Table 1, per seabed and mode ("free": R, Φ, Z unknown; "calibrated": Φ fixed to the true
profile): Z RMSE (m) and as a fraction of the relief's standard deviation (of the altitude for
the flat seabed), the same after removing the mean error (the absolute level comes from the
first bottom return), the correlation of Z, of R (where R varies) and of the beam profile over
30–80° depression with the truth, iterations per pyramid level (of the start kept), seconds.

Table 2, run time against error on the ripples (free): levels 1, 2, 3 × a fixed number of
iterations per level and start, then 3 levels with the stopping threshold ``tol`` (default 1e-2).

Table 1 can also run with the flat-seabed prior (``--flat-prior W``), the true altitude
(``--known-altitude``) instead of the first return, on images with L-look speckle
(``--speckle L``: each cell times an independent Gamma(L, 1/L) draw), and with the speckle
looks given to the inversion (``--looks``: ``auto``, the default, estimates them; ``none``
leaves the noise priors out; a number fixes them).

Usage: ``python tools/bench_inversion.py [--max-iter 100] [--seabeds flat,ripples,...]
[--sweep 10,30,100] [--flat-prior 0.25] [--known-altitude] [--speckle 1] [--looks auto]
[--out bench_out]``; the plot goes
to ``OUT/inversion_time_vs_error.png`` and a small copy to ``docs/inversion_time_vs_error.png``.
"""

from __future__ import annotations

import math
import time
import zlib
from pathlib import Path

import numpy as np
from _common import DOCS, ROOT, parser, pyplot

from sonar_raster.inversion.solver import BeamProfile, Inversion, invert
from sonar_raster.rendering.gl.raster import RasterRenderer
from sonar_raster.scene import build_scene
from sonar_raster.scenes.seabed import Heightfield, from_grid, make_seabed
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
#: The mound again under a track three times longer (9.6 m; the mound spans about 4.5 m).
LONG_TRACK = Trajectory.straight((0.0, -4.8, ALT), 0.0, SPACING, 3 * PINGS)
COMMON = {"size": (30.0, 8.0), "center": (12.0, 0.0), "resolution": 0.05}


def _grid(fn, half_length: float = 4.0) -> Heightfield:
    """A 30 m x 2·half_length grid (5 cm) centred at (12, 0) with heights ``fn(x, y)``."""
    x = np.linspace(-3.0, 27.0, 601)
    y = np.linspace(-half_length, half_length, int(round(40 * half_length)) + 1)
    xx, yy = np.meshgrid(x, y)
    return from_grid(fn(xx, yy), 0.05, 0.05, x0=-3.0, y0=-half_length)


def _mound(x, y):
    return 0.4 * np.exp(-((x - 12.0) ** 2 + y**2) / (2 * 1.5**2))


def _patches(field: Heightfield) -> np.ndarray:
    xx, yy = np.meshgrid(field.x, field.y)
    r = np.full(xx.shape, 0.5)
    r[(xx >= 6.0) & (xx <= 9.0) & (yy < 0.0)] = 0.8
    r[(xx >= 14.0) & (xx <= 17.0) & (yy >= 0.0)] = 0.25
    return r


SEABEDS = {
    "flat": lambda: make_seabed("flat", size=(40.0, 8.0), center=(12.0, 0.0)),
    "ripples": lambda: make_seabed(
        "ripples", **COMMON, wavelength=1.0, amplitude=0.05, direction_deg=90.0, seed=1
    ),
    "mound": lambda: _grid(_mound),
    "trench": lambda: _grid(lambda x, y: -0.3 * np.exp(-((x - 10.0) ** 2) / (2 * 0.5**2))),
    "patches": lambda: make_seabed(
        "rough", **COMMON, rms_height=0.05, correlation_length=2.0, seed=3
    ),
    "mound96": lambda: _grid(_mound, half_length=8.0),
}


def track_of(name: str) -> Trajectory:
    return LONG_TRACK if name == "mound96" else TRACK


def true_profile() -> BeamProfile:
    """The renderer's beam in the inversion's units (gain times the ping spacing)."""
    dep = np.linspace(0.05, math.pi / 2, 400)
    return BeamProfile(dep, SPACING * SONAR.gain(dep))


def render(renderer: RasterRenderer, name: str) -> tuple[Heightfield, np.ndarray, np.ndarray]:
    """The seabed, its node reflectivity map and its rendered starboard image."""
    field = SEABEDS[name]()
    refl = _patches(field) if name == "patches" else np.full(field.shape, 0.5)
    scene = build_scene([field.mesh(refl)])
    image = renderer.render(scene, SONAR, track_of(name)).sides["starboard"]
    return field, refl, image.astype(np.float64)


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    if np.std(a) == 0 or np.std(b) == 0:
        return math.nan
    return float(np.corrcoef(a, b)[0, 1])


def score(name: str, field: Heightfield, refl: np.ndarray, inv: Inversion) -> dict:
    """Errors of one inversion against the truth (see the module notes)."""
    xx, yy = np.meshgrid(inv.x, track_of(name).positions[:, 1])
    truth = field.height_at(xx, yy) - ALT
    r_truth = from_grid(refl, field.dx, field.dy, field.x0, field.y0).height_at(xx, yy)
    ok = np.isfinite(inv.elevation)
    err = (inv.elevation - truth)[ok]
    scale = ALT if name == "flat" else float(np.std(truth[ok]))
    rmse = float(np.sqrt(np.mean(err**2)))
    dep = inv.profile.depression
    keep = (dep > math.radians(30)) & (dep < math.radians(80))
    return {
        "rmse": rmse,
        "rel": rmse / scale,
        "level_free": float(np.std(err)) / scale,
        "corr_z": _corr(inv.elevation[ok], truth[ok]) if name != "flat" else math.nan,
        "corr_r": _corr(inv.reflectivity[ok], r_truth[ok]),
        "corr_phi": _corr(inv.profile.gain[keep], SONAR.gain(dep[keep])),
        "iters": "/".join(str(len(e) - 1) for e in inv.energies),
    }


def timed(image: np.ndarray, **kwargs) -> tuple[Inversion, float]:
    start = time.perf_counter()
    inv = invert(image, SONAR.range_bin, ping_spacing=SPACING, **kwargs)
    return inv, time.perf_counter() - start


def speckled(image: np.ndarray, looks: float, name: str) -> np.ndarray:
    """``image`` times fully developed L-look speckle: Gamma(L, 1/L), unit mean, one
    independent draw per cell, seeded by the seabed's name (0 looks: the image itself)."""
    if looks <= 0:
        return image
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    return image * rng.gamma(looks, 1.0 / looks, image.shape)


def scenes_table(
    renderer, names: list[str], max_iter: int, speckle: float = 0.0, **options
) -> list[tuple[str, str, dict, float]]:
    print(
        f"{'seabed':8s} {'mode':10s} {'Z rmse':>8s} {'/scale':>7s} {'lvl-free':>9s} "
        f"{'corr Z':>6s} {'corr R':>6s} {'corr Φ':>6s} {'iterations':>12s} {'s':>6s}"
    )
    rows = []
    for name in names:
        field, refl, image = render(renderer, name)
        image = speckled(image, speckle, name)
        for mode in ("free", "calibrated"):
            beam = true_profile() if mode == "calibrated" else None
            inv, seconds = timed(image, max_iter=max_iter, beam=beam, **options)
            s = score(name, field, refl, inv)
            rows.append((name, mode, s, seconds))
            print(
                f"{name:8s} {mode:10s} {s['rmse']:8.4f} {s['rel']:7.3f} {s['level_free']:9.3f} "
                f"{s['corr_z']:6.2f} {s['corr_r']:6.2f} {s['corr_phi']:6.3f} {s['iters']:>12s} "
                f"{seconds:6.1f}",
                flush=True,
            )
    return rows


def sweep(
    renderer, iters: list[int], tols: list[float]
) -> list[tuple[str, str, float, float, float]]:
    """(series, label, Z error / relief std, level-free error, seconds) on the ripples (free).

    Series "N level(s)": a fixed number of iterations per level and start (``tol=0``, so a
    start stops only when no step lowers E); series "3 levels, tol": ``max_iter=300`` and the
    relative-decrease threshold ``tol``.
    """
    field, refl, image = render(renderer, "ripples")
    print(f"\n{'series':>16s} {'setting':>8s} {'Z/std':>7s} {'lvl-free':>9s} {'s':>6s}")
    runs = [
        (f"{lv} level(s)", str(n), {"levels": lv, "max_iter": n, "tol": 0.0})
        for lv in (1, 2, 3)
        for n in iters
    ]
    runs += [("3 levels, tol", f"{t:g}", {"levels": 3, "max_iter": 300, "tol": t}) for t in tols]
    out = []
    for series, label, kwargs in runs:
        inv, seconds = timed(image, **kwargs)
        s = score("ripples", field, refl, inv)
        out.append((series, label, s["rel"], s["level_free"], seconds))
        print(f"{series:>16s} {label:>8s} {s['rel']:7.3f} {s['level_free']:9.3f} {seconds:6.1f}")
    return out


def plot(rows, points, path: Path, small: Path | None) -> None:
    plt = pyplot()
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9.0, 3.4))
    markers = ("o", "s", "^", "D")
    for k, series in enumerate(dict.fromkeys(p[0] for p in points)):
        pts = [p for p in points if p[0] == series]
        ax1.plot([p[4] for p in pts], [p[2] for p in pts], marker=markers[k % 4], label=series)
        for p in pts:
            ax1.annotate(p[1], (p[4], p[2]), fontsize=7, xytext=(3, 3), textcoords="offset points")
    ax1.axhline(0.3, color="grey", ls=":", lw=1)
    ax1.set_xlabel("seconds")
    ax1.set_ylabel("Z RMSE / relief std")
    ax1.set_title("ripples, free: time vs error (labels: max iter or tol)", fontsize=9)
    ax1.legend(fontsize=7)
    names = sorted({r[0] for r in rows if r[0] != "flat"}, key=[r[0] for r in rows].index)
    width = 0.38
    for k, mode in enumerate(("free", "calibrated")):
        vals = [next(r[2]["rel"] for r in rows if r[0] == n and r[1] == mode) for n in names]
        ax2.bar(np.arange(len(names)) + (k - 0.5) * width, vals, width, label=mode)
    ax2.axhline(0.3, color="grey", ls=":", lw=1)
    ax2.set_xticks(np.arange(len(names)), names, fontsize=8)
    ax2.set_ylabel("Z RMSE / relief std")
    ax2.set_title("per seabed", fontsize=9)
    ax2.legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    if small is not None:
        fig.savefig(small, dpi=60)
    plt.close(fig)
    print(f"\nwrote {path}" + (f" and {small}" if small else ""))


def main() -> None:
    ap = parser(__doc__)
    ap.add_argument("--max-iter", type=int, default=100, help="iterations per level and start")
    ap.add_argument("--seabeds", default=",".join(SEABEDS), help="comma-separated subset")
    ap.add_argument(
        "--sweep", default="10,30,100", help="max iterations of the time sweep ('' skips)"
    )
    ap.add_argument("--tols", default="0.1,0.01,0.001,0.0001", help="tol values of the sweep")
    ap.add_argument("--out", default=str(ROOT / "bench_out"), help="plot directory")
    ap.add_argument("--no-docs", action="store_true", help="do not update docs/")
    ap.add_argument(
        "--flat-prior", type=float, default=0.0, help="invert(flat_prior=...) of table 1"
    )
    ap.add_argument(
        "--known-altitude",
        action="store_true",
        help="table 1 passes the true altitude instead of the first return",
    )
    ap.add_argument(
        "--speckle",
        type=float,
        default=0.0,
        metavar="LOOKS",
        help="table 1 on images times L-look speckle (Gamma(L, 1/L) per cell; 0: none)",
    )
    ap.add_argument(
        "--subsamples",
        type=int,
        default=None,
        help="set inversion.solver.SUBSAMPLES (points per cell's return) for every run",
    )
    ap.add_argument(
        "--looks",
        default="auto",
        help="invert(looks=...) of table 1: 'auto' (default), 'none' or a number",
    )
    args = ap.parse_args()
    if args.subsamples is not None:
        import sonar_raster.inversion.solver

        sonar_raster.inversion.solver.SUBSAMPLES = args.subsamples
    looks = None if args.looks == "none" else args.looks
    looks = looks if looks in (None, "auto") else float(looks)
    options: dict = {"flat_prior": args.flat_prior, "speckle": args.speckle, "looks": looks}
    if args.known_altitude:
        options["altitude"] = ALT
    with RasterRenderer() as renderer:
        rows = scenes_table(renderer, args.seabeds.split(","), args.max_iter, **options)
        tols = [float(t) for t in args.tols.split(",") if t]
        points = sweep(renderer, [int(n) for n in args.sweep.split(",") if n], tols)
    if points and any(r[0] != "flat" for r in rows):
        small = None if args.no_docs else DOCS / "inversion_time_vs_error.png"
        plot(rows, points, Path(args.out) / "inversion_time_vs_error.png", small)


if __name__ == "__main__":
    main()
