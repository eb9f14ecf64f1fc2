"""Bathymetry from one speckled line: the surface fit against a flat seabed at the first return.

A benchmark, not a test: it prints a table, writes a plot and asserts nothing. Each seabed is
rendered by the GL raster path (both sides, 12 m altitude, 30 m range in 5 cm bins, pings
0.1 m apart, a Gaussian 50° beam tilted 20°), optionally times single-look speckle
(``--looks 1``: each bin times an independent Gamma(1, 1) draw), and inverted by
:func:`sonar_raster.inversion.surface.fit_surface`. The baseline, computed in the same run, is a
flat seabed at each ping's first-return altitude (the package's bottom tracker). Scores are
Z RMSE over the relief's standard deviation (lower is better; the flat baseline scores about 1),
over ground ranges 1 m to 2 m short of the swath's end, both sides; "1σ" is the fraction of
those cells whose error lies within the fit's standard deviation (the issue asks 0.55-0.80).

Seabeds: sand waves (0.15 m amplitude, 3 m wavelength, crests at 30° to the track); two mounds
(0.6 m, σ 2 m and 0.4 m, σ 1.5 m); two trenches along track (0.4 m, σ 0.7 m and 0.3 m, σ 1 m);
a rough plain (0.1 m rms, 1 m correlation) with two reflectivity patches (0.9 and 0.2 on 0.5);
boulders (20 half-spheres, 0.3–0.8 m across, on a flat seabed); a wreck-like box (6 × 2.5 m,
1.5 m high) on a flat seabed.

With ``--beam calibrated`` (or ``free,calibrated`` for both) each seabed is fitted in
calibrated mode: each side's beam profile from a fit of a flat seabed (the same sonar and lines,
its own speckle draw) is passed as ``fit_lines(beam=...)``; such rows are marked ``c`` (the
flat seabed's fit is not timed). ``--finest 1,2`` also fits each seabed with the finest level
pooled 2 × 2 (``fit_lines(finest=2)``, ``invert --coarsen 2``); such rows are marked ``/2``.

Usage: ``python tools/bench_bathymetry.py [--seabeds sand,mound,...] [--looks 0,1]
[--pings 200] [--beam free,calibrated] [--finest 1,2] [--out bench_out]``.
"""

from __future__ import annotations

import itertools
import math
import time
import zlib
from pathlib import Path

import numpy as np
from _common import DOCS, parser, pyplot
from scipy import ndimage

from sonar_raster.inversion.bottom import track_bottom
from sonar_raster.inversion.solver import BeamProfile
from sonar_raster.inversion.surface import Line, fit_lines
from sonar_raster.rendering.gl.raster import RasterRenderer
from sonar_raster.scene import build_scene
from sonar_raster.scenes.seabed import from_grid
from sonar_raster.sonar import BeamPattern, Sonar
from sonar_raster.trajectory import Trajectory

ALT, SPACING, BIN, RANGE, CELL = 12.0, 0.1, 0.05, 30.0, 0.05
SONAR = Sonar(
    max_range=RANGE,
    range_bin=BIN,
    beam=BeamPattern.gaussian(50.0),
    tilt=math.radians(20.0),
    sides=("port", "starboard"),
)


def _sand(x, y, length):
    u = x * math.cos(math.radians(30)) + y * math.sin(math.radians(30))
    return 0.15 * np.sin(2 * np.pi * u / 3.0)


def _mounds(x, y, length):
    a = 0.6 * np.exp(-((x - 12) ** 2 + (y - length / 2) ** 2) / (2 * 2.0**2))
    return a + 0.4 * np.exp(-((x + 9) ** 2 + (y - length / 3) ** 2) / (2 * 1.5**2))


def _trenches(x, y, length):
    a = -0.4 * np.exp(-((x - 10) ** 2) / (2 * 0.7**2))
    return a - 0.3 * np.exp(-((x + 14) ** 2) / (2 * 1.0**2))


def _rough(x, y, length):
    noise = np.random.default_rng(3).normal(size=x.shape)
    smooth = ndimage.gaussian_filter(noise, 1.0 / CELL / 2)
    return 0.1 * smooth / smooth.std()


def _patches(x, y, length):
    r = np.full(x.shape, 0.5)
    r[(x > 6) & (x < 12) & (y < length / 2)] = 0.9
    r[(x < -8) & (x > -15) & (y > length / 3)] = 0.2
    return r


def _boulders(x, y, length):
    rng = np.random.default_rng(7)
    z = np.zeros_like(x)
    for _ in range(20):
        cx, cy = rng.uniform(-24, 24), rng.uniform(2, length - 2)
        radius = rng.uniform(0.15, 0.4)
        d2 = (x - cx) ** 2 + (y - cy) ** 2
        z = np.maximum(z, np.sqrt(np.clip(radius**2 - d2, 0, None)))
    return z


def _box(x, y, length):
    inside = (np.abs(x - 11) < 1.25) & (np.abs(y - length / 2) < 3.0)
    return np.where(inside, 1.5, 0.0)


SEABEDS = {
    "flat": (lambda x, y, length: np.zeros_like(x), None),  # calibrates the beam (--beam)
    "sand": (_sand, None),
    "mounds": (_mounds, None),
    "trenches": (_trenches, None),
    "patches": (_rough, _patches),
    "boulders": (_boulders, None),
    "box": (_box, None),
}


def render(name: str, pings: int, looks: float, lines: int = 1, overlap: float = 0.4):
    """The heightfield, the tracks and the (speckled) sides of one seabed.

    ``lines`` parallel lines, alternately north- and southbound (a lawnmower), spaced so
    neighbouring swaths overlap by ``overlap`` of a swath's width.
    """
    length = pings * SPACING
    height, refl = SEABEDS[name]
    reach = math.sqrt(RANGE**2 - ALT**2)
    spacing = 2.0 * reach * (1.0 - overlap)
    offsets = [(k - (lines - 1) / 2) * spacing for k in range(lines)]
    half = max(33.0, reach + 3.0) + max(abs(o) for o in offsets)  # seabed past every swath
    x = np.arange(-half, half + CELL / 2, CELL)
    y = np.arange(-3.0, length + 3.0 + CELL / 2, CELL)
    xx, yy = np.meshgrid(x, y)
    field = from_grid(height(xx, yy, length), CELL, CELL, x0=-half, y0=-3.0)
    r = np.full(xx.shape, 0.5) if refl is None else refl(xx, yy, length)
    scene = build_scene([field.mesh(r)])
    renderer = RasterRenderer()
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    tracks, images = [], []
    for k, offset in enumerate(offsets):
        if k % 2 == 0:
            track = Trajectory.straight((offset, 0.0, ALT), 0.0, SPACING, pings)
        else:
            track = Trajectory.straight((offset, (pings - 1) * SPACING, ALT), 180.0, SPACING, pings)
        image = renderer.render(scene, SONAR, track)
        sides = {k: v.astype(np.float64) for k, v in image.sides.items()}
        if looks > 0:
            sides = {k: v * rng.gamma(looks, 1.0 / looks, v.shape) for k, v in sides.items()}
        tracks.append(track)
        images.append(sides)
    return field, tracks, images


def score(field, fits, baselines) -> tuple[float, float, float, float]:
    """(fit, flat baseline) Z RMSE over the relief std, the fit's Z correlation, and the
    fraction of cells whose error is within the fit's standard deviation (its coverage),
    over every side of every line."""
    fitted, truths, flats, stds = [], [], [], []
    for fit, baseline in zip(fits, baselines, strict=True):
        x = fit.x
        keep = (x > 1.0) & (x < x[-1] - 2.0)
        for side in fit.elevation:
            where = fit.position[side][:, keep]
            truths.append(field.height_at(where[..., 0], where[..., 1]) - ALT)
            fitted.append(fit.elevation[side][:, keep])
            flats.append(np.broadcast_to(-baseline[:, None], where.shape[:2]))
            stds.append(fit.elevation_std[side][:, keep])
    t, f, b, s = (np.concatenate([a.ravel() for a in v]) for v in (truths, fitted, flats, stds))
    std = float(np.std(t))
    rel = float(np.sqrt(np.mean((f - t) ** 2))) / std
    flat = float(np.sqrt(np.mean((b - t) ** 2))) / std
    coverage = float(np.mean(np.abs(f - t) < s))
    return rel, flat, float(np.corrcoef(f, t)[0, 1]), coverage


def fit(tracks, images, joint: bool, beam=None, finest: int = 1):
    """The surface fit of every line together, or of each line alone (``beam``: calibrated;
    ``finest``: the finest level's pooling)."""
    lines = [
        Line(sides, BIN, t.positions[:, :2], t.headings)
        for t, sides in zip(tracks, images, strict=True)
    ]
    if joint:
        return fit_lines(lines, beam=beam, finest=finest)
    return [fit_lines([line], beam=beam, finest=finest)[0] for line in lines]


def calibrate(pings: int, looks: float, lines: int, overlap: float) -> dict[str, BeamProfile]:
    """Each side's beam profile from a flat seabed's lines (their own speckle draw)."""
    _, tracks, images = render("flat", pings, looks, lines, overlap)
    first = fit(tracks, images, True)[0]
    return {side: BeamProfile(*first.profile[side]) for side in first.profile}


def main() -> None:
    cli = parser(__doc__, out=Path("bench_out"))
    cli.add_argument("--seabeds", default=",".join(s for s in SEABEDS if s != "flat"))
    cli.add_argument("--looks", default="0,1", help="speckle looks per run (0: none)")
    cli.add_argument("--pings", type=int, default=200)
    cli.add_argument("--lines", default="1", help="line counts to run, e.g. 1,3")
    cli.add_argument("--overlap", type=float, default=0.4, help="swath overlap of neighbours")
    cli.add_argument("--docs", action="store_true", help="also write docs/bathymetry.png")
    cli.add_argument(
        "--independent", action="store_true", help="with several lines, also fit each alone"
    )
    cli.add_argument(
        "--beam",
        default="free",
        help="free and/or calibrated (each side's profile from a flat seabed's fit, reused)",
    )
    cli.add_argument(
        "--finest", default="1", help="finest level's pooling per run, e.g. 1,2 (invert --coarsen)"
    )
    args = cli.parse_args()
    finests = [int(v) for v in args.finest.split(",")]
    modes_beam = args.beam.split(",")
    if not set(modes_beam) <= {"free", "calibrated"}:
        cli.error("--beam takes free and/or calibrated")
    profiles: dict[tuple[float, int], dict[str, BeamProfile]] = {}
    rows = []
    print(
        f"{'seabed':9s} {'lines':>5s} {'looks':>5s} {'fit':>6s} {'flat':>6s} {'ratio':>6s} "
        f"{'corr':>5s} {'1σ':>5s} {'s':>6s}"
    )
    for name in args.seabeds.split(","):
        for count in (int(v) for v in args.lines.split(",")):
            for looks in (float(v) for v in args.looks.split(",")):
                field, tracks, images = render(name, args.pings, looks, count, args.overlap)
                baselines = [track_bottom(sides, BIN).altitude for sides in images]
                modes = [True, False] if args.independent and count > 1 else [True]
                for joint, mode, finest in itertools.product(modes, modes_beam, finests):
                    beam = None
                    if mode == "calibrated":
                        key = (looks, count)
                        if key not in profiles:
                            profiles[key] = calibrate(args.pings, looks, count, args.overlap)
                        beam = profiles[key]
                    start = time.perf_counter()
                    fits = fit(tracks, images, joint, beam, finest)
                    seconds = time.perf_counter() - start
                    rel, flat, corr, coverage = score(field, fits, baselines)
                    label = f"{count}" + ("" if joint or count == 1 else "x1")
                    label += "c" if beam else ""
                    label += f"/{finest}" if finest > 1 else ""
                    rows.append((name, looks, rel, flat, seconds, label))
                    print(
                        f"{name:9s} {label:>5s} {looks:5g} {rel:6.3f} {flat:6.3f} "
                        f"{rel / flat:6.2f} {corr:5.2f} {coverage:5.2f} {seconds:6.1f}",
                        flush=True,
                    )
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 3.2))
    labels = [
        f"{n}\n{'speckle' if lk else 'clean'}\n{c.split('/')[0].rstrip('c')} line(s)"
        + ("\ncal." if "c" in c else "")
        + (f"\npooled {c.split('/')[1]}" if "/" in c else "")
        for n, lk, *_, c in rows
    ]
    pos = np.arange(len(rows))
    ax.bar(pos - 0.2, [r[3] for r in rows], 0.4, label="flat at the first return", color="0.7")
    ax.bar(pos + 0.2, [r[2] for r in rows], 0.4, label="surface fit", color="tab:blue")
    ax.set_xticks(pos, labels, fontsize=7)
    ax.set_ylabel("Z RMSE / relief std")
    ax.axhline(0.6, color="k", lw=0.8, ls="--")
    ax.legend(fontsize=8)
    fig.tight_layout()
    args.out.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out / "bathymetry.png", dpi=110)
    if args.docs:
        fig.savefig(DOCS / "bathymetry.png", dpi=70)
    print(f"plot: {args.out / 'bathymetry.png'}")


if __name__ == "__main__":
    main()
