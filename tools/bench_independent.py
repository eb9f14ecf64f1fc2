"""Bathymetry from images another forward model made, inverted by the CLI as a user runs it.

A benchmark, not a test: it prints a table, writes a plot and a JSON file, and asserts
nothing. ``tools/bench_bathymetry.py`` renders its seabeds with the package's own GL raster,
whose image the surface fit models exactly; a user's images come from other simulators and
from the sea. Here the images come from a forward model written for this script in numpy,
sharing no code with the package, and differing from the bathymetry bench where a simulator
might:

- one side (starboard), the sonar 12 m above the mean seabed, 400 pings 0.1 m apart,
  800 slant-range bins of 5 cm from range 0 (40 m);
- the seabed cut into 1 cm facets across track per ping; each returns ``R · B · cos θ · dA``
  (Lambert, as the seed) with the facet's own 3-D normal (along-track slopes included);
- a Gaussian vertical beam of 60° (full width at half maximum) tilted 15° down (the
  bathymetry bench: 50°, 20°);
- shadows by ray casting: a facet is lit when no nearer facet of its ping is seen at a
  shallower depression angle;
- each facet's return goes whole into the slant-range bin that holds it (a recorder's
  boxes; the package's renderer shares it between two bins);
- speckle: each bin times a Gamma(L, 1/L) draw (``--looks 1``), or none (``--looks 0``).

Each image is saved as a one-side ``.npy`` (rows pings, columns slant-range bins from 0, what
another tool hands a user) and inverted in this process by ``sonar-raster invert IMAGE.npy
--range-bin 0.05`` with every other option at its default (``--spacing`` adds
``--ping-spacing 0.1``, ``--method M`` passes ``--method M``). The products are read back and
scored on ground ranges from 1 m to 2 m short of the swath's end: Z RMSE over the relief's
standard deviation (lower is better); the baseline, from the same run, is a flat seabed at
each ping's first return (:func:`sonar_raster.inversion.bottom.track_side` on the same
image); "1σ" is the fraction of cells whose error lies within ``elevation_std.exr`` (the
surface fit writes it, the profiles do not); "level" the mean error in cm.

Seabeds: sand waves (0.2 m amplitude, 4 m wavelength, crests at 40° to the track); a mound
(0.8 m, σ 2.5 m); a trench crossing the track at 20° (0.5 m deep, σ 1 m); a rough plain
(0.1 m rms, 0.8 m correlation) with two reflectivity patches (2.0 and 0.4 on 1); a wreck-like
box (6 m × 2.5 m × 1.5 m, its long side 30° off the track).

Usage: ``python tools/bench_independent.py [--seabeds sand,mound,...] [--looks 1,0]
[--spacing] [--method auto|surface|profiles] [--out bench_out] [--replot JSON]``.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import tempfile
import time
from pathlib import Path

import numpy as np
from _common import DOCS, parser, pyplot, save_figure
from scipy import ndimage

from sonar_raster.cli import main as cli
from sonar_raster.inversion.bottom import track_side
from sonar_raster.io.images import read_pixels

ALT, BIN, BINS, PINGS, SPACING, FACET = 12.0, 0.05, 800, 400, 0.1, 0.01
TILT, WIDTH = math.radians(15.0), math.radians(60.0)
GROUND = 42.0  # metres of seabed across track, past the last bin's ground range
CELL = 0.05  # the rough plain's grid


def _sand(x, y):
    u = x * math.cos(math.radians(40)) + y * math.sin(math.radians(40))
    return 0.2 * np.sin(2 * np.pi * u / 4.0), 1.0


def _mound(x, y):
    return 0.8 * np.exp(-((x - 16) ** 2 + (y - 20) ** 2) / (2 * 2.5**2)), 1.0


def _trench(x, y):
    a = math.radians(20)
    d = x * math.cos(a) - (y - 20) * math.sin(a) - 14
    return -0.5 * np.exp(-(d**2) / (2 * 1.0**2)), 1.0


def _rough_grid() -> np.ndarray:
    noise = np.random.default_rng(11).normal(size=(int(PINGS * SPACING / CELL) + 40, 880))
    smooth = ndimage.gaussian_filter(noise, 0.8 / CELL / 2)
    return 0.1 * smooth / smooth.std()


_ROUGH = _rough_grid()


def _rough(x, y):
    z = ndimage.map_coordinates(_ROUGH, [y / CELL, x / CELL], order=1, mode="nearest")
    r = np.where((x > 10) & (x < 18) & (y > 8) & (y < 18), 2.0, 1.0)
    return z, np.where((x > 22) & (x < 30) & (y > 24) & (y < 34), 0.4, r)


def _box(x, y):
    a = math.radians(30)
    u = (x - 18) * math.cos(a) + (y - 20) * math.sin(a)  # across the box's long side
    v = -(x - 18) * math.sin(a) + (y - 20) * math.cos(a)
    return np.where((np.abs(u) < 1.25) & (np.abs(v) < 3.0), 1.5, 0.0), 1.0


SEABEDS = {"sand": _sand, "mound": _mound, "trench": _trench, "rough": _rough, "box": _box}


def render(name: str, looks: float, seed: int = 5) -> np.ndarray:
    """The independent model's image of one seabed, shape (PINGS, BINS)."""
    seabed = SEABEDS[name]
    x = np.arange(0.0, GROUND, FACET) + FACET / 2
    image = np.zeros((PINGS, BINS))
    for i in range(PINGS):
        y = np.full_like(x, i * SPACING)
        z, r = seabed(x, y)
        zx = np.gradient(z, FACET)
        zy = (seabed(x, y + 1e-3)[0] - seabed(x, y - 1e-3)[0]) / 2e-3
        height = z - ALT  # relative to the transducer
        rho = np.hypot(x, height)
        tilt = np.sqrt(1.0 + zx**2 + zy**2)
        cos = np.maximum(0.0, (zx * x - height) / (rho * tilt))  # normal · (facet → sonar)
        depression = np.arctan2(-height, x)
        lit = depression <= np.minimum.accumulate(depression) + 1e-12
        beam = np.exp(-4.0 * math.log(2.0) * ((depression - TILT) / WIDTH) ** 2)
        energy = r * beam * cos * FACET * tilt * lit
        bins = (rho / BIN).astype(int)
        inside = bins < BINS
        image[i] = np.bincount(bins[inside], energy[inside], minlength=BINS)[:BINS]
    if looks:
        image *= np.random.default_rng(seed).gamma(looks, 1.0 / looks, size=image.shape)
    return image


def truth(name: str, x: np.ndarray, pings: int) -> np.ndarray:
    """Z relative to the transducer at ground ranges ``x`` of each ping, (pings, len(x))."""
    y = np.arange(pings)[:, None] * SPACING * np.ones_like(x)[None, :]
    return SEABEDS[name](np.broadcast_to(x, y.shape), y)[0] - ALT


def invert(image: np.ndarray, folder: Path, spacing: bool, method: str) -> tuple[dict, float]:
    """``sonar-raster invert`` on the image saved as .npy: its products, and seconds."""
    path = folder / "image.npy"
    np.save(path, image.astype(np.float32))
    args = ["invert", str(path), "--range-bin", str(BIN), "-o", str(folder / "inv")]
    args += ["--no-mesh", "--no-previews", "--quiet"]
    if spacing:
        args += ["--ping-spacing", str(SPACING)]
    if method != "auto":
        args += ["--method", method]
    start = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):
        code = cli(args)
    seconds = time.perf_counter() - start
    if code != 0:
        raise RuntimeError(f"invert exited {code}")
    meta = json.loads((folder / "inv" / "inversion.json").read_text())
    products = {
        name: read_pixels(path)[0][..., 0]
        for name in ("elevation", "elevation_std")
        if (path := folder / "inv" / f"{name}.exr").is_file()  # no std from the profiles
    }
    return {"meta": meta, **products}, seconds


def score(name: str, image: np.ndarray, products: dict) -> dict[str, float]:
    """Fit and flat baseline against the truth over the scored ground ranges."""
    axis = products["meta"]["ground_axis"]
    x = axis["first_centre_m"] + axis["spacing_m"] * np.arange(axis["cells"])
    keep = (x > 1.0) & (x < math.sqrt((BINS * BIN) ** 2 - ALT**2) - 2.0)
    z = products["elevation"][:, keep]
    std = products.get("elevation_std", np.full_like(products["elevation"], np.nan))[:, keep]
    true = truth(name, x[keep], z.shape[0])
    flat = np.broadcast_to(-track_side(image, BIN).altitude[:, None], z.shape)
    ok = np.isfinite(z) & np.isfinite(flat)
    err, relief = (z - true)[ok], true[ok]
    spread = relief.std()
    return {
        "fit": float(np.sqrt(np.mean(err**2)) / spread),
        "flat": float(np.sqrt(np.mean((flat - true)[ok] ** 2)) / spread),
        "corr": float(np.corrcoef(z[ok], relief)[0, 1]),
        "coverage": float(np.mean(np.abs(err) < std[ok]))
        if "elevation_std" in products
        else math.nan,
        "level_cm": float(100 * err.mean()),
        "cells": float(ok.mean()),
        "method": products["meta"]["settings"]["method"],
    }


def main() -> None:
    ap = parser(__doc__, out=Path("bench_out"))
    ap.add_argument("--seabeds", default=",".join(SEABEDS))
    ap.add_argument("--looks", default="1,0", help="comma-separated; 0 = clean")
    ap.add_argument("--spacing", action="store_true", help="also give --ping-spacing 0.1")
    ap.add_argument(
        "--method",
        choices=("auto", "surface", "profiles"),
        default="auto",
        help="invert's --method (default auto)",
    )
    ap.add_argument("--plot", type=Path, default=DOCS / "bathymetry_independent.png")
    ap.add_argument("--replot", type=Path, default=None, help="plot a JSON this script wrote")
    args = ap.parse_args()
    if args.replot is not None:
        plot(json.loads(args.replot.read_text()), args.plot)
        return
    rows = []
    print("seabed   looks  method    fit    flat   corr  1σ    level cm  s")
    for name in args.seabeds.split(","):
        for looks in (float(v) for v in args.looks.split(",")):
            image = render(name, looks)
            with tempfile.TemporaryDirectory() as tmp:
                products, seconds = invert(image, Path(tmp), args.spacing, args.method)
            row = {"seabed": name, "looks": looks, **score(name, image, products)}
            row["seconds"] = seconds
            rows.append(row)
            print(
                f"{name:8s} {looks:5g}  {row['method']:8s}  {row['fit']:.3f}  {row['flat']:.3f}  "
                f"{row['corr']:.2f}  {row['coverage']:.2f}  {row['level_cm']:+6.1f}  {seconds:.0f}",
                flush=True,
            )
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "bench_independent.json").write_text(json.dumps(rows, indent=1))
    plot(rows, args.plot)
    print(f"wrote {args.out / 'bench_independent.json'} and {args.plot}")


def plot(rows: list[dict], path: Path) -> None:
    """Bars of each seabed's fit per looks, the flat baseline as a dash, the method on top."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 3.5))
    names = list(dict.fromkeys(r["seabed"] for r in rows))
    for k, looks in enumerate(dict.fromkeys(r["looks"] for r in rows)):
        got = {r["seabed"]: r for r in rows if r["looks"] == looks}
        where = np.arange(len(names)) + 0.2 * k
        label = "single look" if looks == 1 else ("clean" if looks == 0 else f"{looks:g} looks")
        heights = [got[n]["fit"] for n in names]
        ax.bar(where, heights, 0.2, label=f"fit, {label}")
        ax.plot(where, [got[n]["flat"] for n in names], "k_", markersize=14)
        for x, h, n in zip(where, heights, names, strict=True):
            ax.text(x, h + 0.02, got[n]["method"][0], ha="center", fontsize=7)
    ax.axhline(0.6, color="grey", lw=0.8, ls="--")
    ax.set_xticks(np.arange(len(names)) + 0.1, names)
    ax.set_ylabel("Z RMSE / relief std (—: flat)")
    ax.set_title("Another forward model's images, `sonar-raster invert` (s: surface, p: profiles)")
    ax.legend(fontsize=8)
    save_figure(fig, path)


if __name__ == "__main__":
    main()
