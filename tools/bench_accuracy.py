"""Time against error of every raster setting and of the coherent model, scene by scene.

A benchmark, not a test: it prints one table (and writes it as CSV with a log-log plot of error
against seconds, Pareto fronts marked) and asserts nothing. Every scene is rendered on a window
of pings around its track's middle (``--window``), so each row is the same job:

* ``raster``    the GL renderer at a sweep of :class:`RasterSettings`: oversample × along_samples
                × split at the default max_edge, then max_edge (triangle subdivision, in range
                bins; "off" = none) at two samplings. Warm time (shaders compiled, geometry
                uploaded), best of ``--repeat`` runs (more, up to 100, until the runs took
                ``--floor`` seconds); a setting stops repeating once its runs took ``--cap``
                seconds.
* ``coherent``  ``render_coherent`` at scatterer spacings from ``--spacings`` wavelengths, coarse
                to fine (default seed, pulse, horizontal beam; time includes sampling the surface
                and building the ray caster). A spacing whose predicted time (fitted as
                ``a + b / s²`` through the two previous spacings, or 4× the previous one) exceeds
                ``--coherent-cap`` seconds is skipped, and the row says so.

Errors (all over the window's rows):

* ``L1/conv``  Σ|I − I_c| / Σ I_c against the converged raster ``conv`` (GL at oversample 16,
               along_samples 8, footprint split, max_edge 5 bins): the raster's sampling error.
* ``L1/ref8``  the same against ``render_reference`` at patch = range_bin / 8 (``ref8``, numpy
               patches): sampling error plus what the two discretisations disagree on; the
               ``conv`` row's value is that disagreement.
* ``prof``     the along-track-averaged intensity profile against range, in 1 m blocks of the
               slant-range band [1.25 × altitude, 0.95 × max_range] (blocks where ``conv`` is
               under 5 % of its median, i.e. beyond the seabed or in full shadow, are left out),
               relative RMS against ``conv`` after fitting one global scale (``scale``: the fit's
               factor, 1 if ``to_raster_units`` got the absolute level right). Coherent images
               are converted with ``coherent.to_raster_units``. This is the one error both models
               have, so both sit on one chart.
* ``noise``    (coherent) the speckle part of ``prof``: the relative RMS of the difference of the
               two half-windows' profiles, halved (what the mean of the whole window scatters by).
               ``prof`` well above ``noise`` is model error; at ``noise`` it is speckle.
* ``contrast`` (coherent) speckle contrast std/mean of bin intensity over the band, each bin
               divided by the along-track-mean profile smoothed over 1 m. Fully developed speckle
               gives 1 for point samples and ~0.87 for bin averages (~1.3 looks per bin). It is
               a pure speckle measure on the uniform patches (``rough_plain``, built here: a
               make_seabed("rough") plain with one straight track; ``flat_calibration``); on
               textured scenes it includes the texture, whose own contrast the ``conv`` row shows
               (same formula on the converged raster). The ``fine bins`` row re-renders
               ``rough_plain`` with bins 8× smaller and the same pulse (c/2B = 8 of its bins): the
               contrast of (nearly) point samples.

``front`` marks Pareto-optimal rows of each scene (no other row of the scene is both faster and
more accurate): ``c`` by L1/conv, ``r`` by L1/ref8, ``p`` by prof (raster and coherent rows
together). ``*`` marks the default setting.

Usage: ``python tools/bench_accuracy.py [--quick] [--scenes a,b] [--out bench_out/]``. On 2 CPU
cores (llvmpipe) the full run takes about 10 minutes (ref8 and the coherent renders are most of
it); ``--quick`` under a minute.
"""

from __future__ import annotations

import argparse
import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from _common import parser, pyplot, save_figure
from bench_render import (  # noqa: E402
    Accuracy,
    Case,
    Timing,
    _fmt,
    best_of,
    bundled_cases,
    reference_accuracy,
    rel_l1,
    timed,
    write_csv,
)

from sonar_raster.rendering.coherent.model import (  # noqa: E402
    SEABED_SPACING,
    Pulse,
    render_coherent,
    to_raster_units,
)
from sonar_raster.rendering.gl.raster import RasterRenderer, RasterSettings  # noqa: E402
from sonar_raster.scene import build_scene  # noqa: E402
from sonar_raster.scenes.bundled import list_bundled  # noqa: E402
from sonar_raster.scenes.seabed import make_seabed  # noqa: E402
from sonar_raster.sonar import BeamPattern, Sonar  # noqa: E402
from sonar_raster.trajectory import Trajectory  # noqa: E402

ROUGH = "rough_plain"
DEFAULT = RasterSettings()
DEFAULT_EDGE_BINS = 20.0  # what max_edge=None means (RasterRenderer._render)
# The converged raster rasterises seabed grids too (heightfield=False), as before the sweep
# existed: the reference every row is measured against is the same for both paths.
CONVERGED = RasterSettings(oversample=16.0, along_samples=8, split="footprint", heightfield=False)
CONVERGED_EDGE_BINS = 5.0
EDGE_OFF = 1e6  # metres: no triangle is subdivided
BLOCK_M = 1.0  # profile block and contrast smoothing length, metres
FINE_DIVISOR = 8  # the fine-bin speckle render's bins per original bin

FULL_GRID = ((1, 2, 4, 8), (1, 2, 4), ("nearest", "linear", "footprint"))
QUICK_GRID = ((1, 2, 4), (1, 2), ("nearest", "footprint"))
FULL_EDGES = (5.0, 10.0, 40.0, 80.0, None)  # range bins; None = off
QUICK_EDGES = (5.0, None)
EDGE_BASES = ((2.0, 2), (8.0, 4))  # (oversample, along) of the max_edge sweep, footprint split


# -- scenes -----------------------------------------------------------------------------------
def rough_case(quick: bool) -> Case:
    """A 100 kHz sonar over a make_seabed("rough") plain (0.1 m cells), one straight track.

    Full: 20 m range (400 bins of 5 cm), 64 pings 0.1 m apart; quick: 12 m, 16 pings.
    """
    max_range, pings = (12.0, 16) if quick else (20.0, 64)
    altitude, spacing = 5.0, 0.1
    length = pings * spacing + 2.0  # the track plus the horizontal beam's reach each side
    field_ = make_seabed(
        "rough",
        size=(max_range + 2.0, length),
        center=(0.5 * max_range, 0.0),
        resolution=0.1,
        seed=1,
    )
    scene = build_scene([field_.mesh(0.3, "seabed")])
    sonar = Sonar(
        frequency_hz=100e3,
        max_range=max_range,
        range_bin=0.05,
        beam=BeamPattern.gaussian(40.0),
        tilt=math.radians(10.0),
        sides=("starboard",),
    )
    start = (0.0, -0.5 * (pings - 1) * spacing, altitude)
    traj = Trajectory.straight(start, 0.0, spacing, pings)
    return Case(ROUGH, f"{ROUGH}[{pings}]", scene, sonar, traj, slice(None))


def scene_case(name: str, pings: int, quick: bool) -> Case:
    return rough_case(quick) if name == ROUGH else bundled_cases(name, pings)[0]


# -- the profile and speckle errors ---------------------------------------------------------
@dataclass(frozen=True)
class Band:
    """The slant-range band and block layout of the profile error of one case."""

    k0: int
    k1: int
    block: int  # bins per block

    @classmethod
    def of(cls, case: Case) -> Band:
        sonar = case.sonar
        altitude = float(np.median(case.trajectory.positions[:, 2])) - case.scene.ground_z
        block = max(1, round(BLOCK_M / sonar.range_bin))
        k0 = min(sonar.n_bins, math.ceil(1.25 * altitude / sonar.range_bin))
        k1 = math.floor(0.95 * sonar.n_bins)
        k1 = k0 + (k1 - k0) // block * block
        return cls(k0, k1, block)

    def blocks(self, profile: np.ndarray) -> np.ndarray:
        return profile[self.k0 : self.k1].reshape(-1, self.block).mean(axis=1)


def _profile(sides: dict, rows: slice | None = None) -> np.ndarray:
    """Along-track mean over ``rows`` of every side, concatenated (side by side)."""
    rows = rows or slice(None)
    return np.concatenate([np.asarray(a[rows], np.float64).mean(axis=0) for a in sides.values()])


def _side_blocks(sides: dict, band: Band, rows: slice | None = None) -> np.ndarray:
    n = len(next(iter(sides.values()))[0])
    prof = _profile(sides, rows)
    return np.concatenate([band.blocks(prof[i * n : (i + 1) * n]) for i in range(len(sides))])


def profile_error(sides: dict, conv: dict, band: Band) -> tuple[float, float]:
    """(relative RMS of the block profile after one global scale, the scale) against ``conv``."""
    if band.k1 <= band.k0:
        return float("nan"), float("nan")
    a, b = _side_blocks(sides, band), _side_blocks(conv, band)
    keep = b > 0.05 * np.median(b)
    a, b = a[keep], b[keep]
    if not (len(a) and a @ a > 0):
        return float("nan"), float("nan")
    scale = float(a @ b / (a @ a))
    return float(np.sqrt(np.mean((scale * a / b - 1.0) ** 2))), scale


def speckle_noise(sides: dict, band: Band, n_pings: int) -> float:
    """Relative RMS scatter of the window's block profile, from its two halves' difference."""
    if band.k1 <= band.k0 or n_pings < 2:
        return float("nan")
    half = n_pings // 2
    a = _side_blocks(sides, band, slice(0, half))
    b = _side_blocks(sides, band, slice(half, 2 * half))
    keep = (a + b) > 0.05 * np.median(a + b)
    return float(np.sqrt(np.mean(((a - b) / (a + b))[keep] ** 2)))


def contrast(sides: dict, band: Band) -> float:
    """std/mean of bin intensity over the band, divided by the smoothed along-track profile."""
    if band.k1 <= band.k0:
        return float("nan")
    ratios = []
    kernel = np.ones(band.block) / band.block
    for img in sides.values():
        img = np.asarray(img, np.float64)
        smooth = np.convolve(img.mean(axis=0), kernel, mode="same")[band.k0 : band.k1]
        ok = smooth > 0.05 * np.median(smooth)
        ratios.append((img[:, band.k0 : band.k1] / np.where(ok, smooth, 1.0))[:, ok])
    r = np.concatenate([x.ravel() for x in ratios])
    return float(r.std() / r.mean()) if r.size and r.mean() > 0 else float("nan")


def best_time(fn: Callable[[], object], repeat: int, cap: float, floor: float) -> Timing:
    """:func:`best_of`, but a fast call repeats until the calls took ``floor`` s (≤ 100 runs)."""
    times: list[float] = []
    out = None
    while (
        not times
        or (len(times) < repeat and sum(times) < cap)
        or (sum(times) < floor and len(times) < 100)
    ):
        start = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - start)
    return Timing(min(times), times[0], len(times), out)


# -- rows -------------------------------------------------------------------------------------
@dataclass
class Row:
    """One line of the table."""

    case: Case
    model: str
    setting: str
    seconds: float = float("nan")
    runs: int = 0
    l1_conv: float = float("nan")
    l1_ref: float = float("nan")
    prof: float = float("nan")
    scale: float = float("nan")
    contrast: float = float("nan")
    noise: float = float("nan")
    default: bool = False
    front: str = ""
    notes: str = ""
    load: float = field(default_factory=lambda: os.getloadavg()[0])  # 1-min load when measured

    def as_dict(self) -> dict:
        c = self.case
        return {
            "scene": c.label,
            "triangles": c.scene.n_triangles,
            "pings": c.trajectory.n_pings,
            "bins": c.sonar.n_bins,
            "sides": len(c.sonar.sides),
            "model": self.model,
            "setting": self.setting,
            "default": self.default,
            "seconds": self.seconds,
            "runs": self.runs,
            "l1_conv": self.l1_conv,
            "l1_ref8": self.l1_ref,
            "prof_rms": self.prof,
            "prof_scale": self.scale,
            "contrast": self.contrast,
            "noise": self.noise,
            "front": self.front,
            "load": self.load,
            "notes": self.notes,
        }


@dataclass
class Refs:
    """The two accuracy references of one case and its profile band."""

    conv: Accuracy
    ref: Accuracy | None
    band: Band


def raster_label(s: RasterSettings, bin_m: float) -> str:
    edge = DEFAULT_EDGE_BINS if s.max_edge is None else s.max_edge / bin_m
    e = "off" if edge * bin_m >= EDGE_OFF else f"{edge:g}"
    grid = "" if s.heightfield else " grid-raster"
    return f"o{s.oversample:g} a{s.along_samples} {s.split} e{e}{grid}"


def raster_settings(grid: tuple, edges: tuple, bin_m: float) -> list[RasterSettings]:
    """The sweep: the sampling grid at the default max_edge, then max_edge at EDGE_BASES."""
    out = [
        RasterSettings(oversample=float(o), along_samples=a, split=s)
        for s in grid[2]
        for a in grid[1]
        for o in grid[0]
    ]
    for over, along in EDGE_BASES:
        for edge in edges:
            metres = EDGE_OFF if edge is None else edge * bin_m
            out.append(RasterSettings(oversample=over, along_samples=along, max_edge=metres))
    return out


def make_refs(case: Case, renderer: RasterRenderer, with_ref: bool) -> tuple[Refs, list[Row]]:
    """The converged raster and (optionally) ref/8, and their rows."""
    renderer.settings = replace(CONVERGED, max_edge=CONVERGED_EDGE_BINS * case.sonar.range_bin)
    seconds, image = timed(lambda: renderer.render(case.scene, case.sonar, case.trajectory))
    conv = Accuracy("conv", {s: a.astype(np.float64) for s, a in image.sides.items()}, seconds)
    ref = reference_accuracy(case, 8.0) if with_ref else None
    band = Band.of(case)
    rows = [
        Row(
            case,
            "raster",
            f"conv: {raster_label(renderer.settings, case.sonar.range_bin)}",
            seconds,
            1,
            l1_ref=rel_l1(conv.sides, ref, slice(None)),
            contrast=contrast(conv.sides, band),
            notes="converged raster (accuracy reference); contrast = texture only",
        )
    ]
    if ref is not None:
        rows.append(
            Row(
                case,
                "reference",
                "ref8: patch = bin/8",
                ref.seconds,
                1,
                l1_conv=rel_l1(ref.sides, conv, slice(None)),
                prof=profile_error(ref.sides, conv.sides, band)[0],
                notes="numpy reference (accuracy reference)",
            )
        )
    return Refs(conv, ref, band), rows


def raster_rows(case: Case, refs: Refs, renderer: RasterRenderer, args) -> list[Row]:
    rows = []
    render = lambda: renderer.render(case.scene, case.sonar, case.trajectory)  # noqa: E731
    bin_m = case.sonar.range_bin
    sweep = raster_settings(args.grid, args.edges, bin_m)
    if args.grid_raster:  # each setting also with seabed grids rasterised, the earlier path
        sweep = [v for s in sweep for v in (s, replace(s, heightfield=False))]
    for settings in sweep:
        renderer.settings = settings
        render()  # compile the split's program and upload (subdivided) geometry first
        t = best_time(render, args.repeat, args.cap, args.floor)
        sides = t.result.sides
        prof, scale = profile_error(sides, refs.conv.sides, refs.band)
        rows.append(
            Row(
                case,
                "raster",
                raster_label(settings, bin_m),
                t.best,
                t.runs,
                rel_l1(sides, refs.conv, slice(None)),
                rel_l1(sides, refs.ref, slice(None)),
                prof,
                scale,
                default=settings == DEFAULT,
                notes=f"{t.result.metadata['triangles']} triangles, "
                f"{t.result.metadata.get('grid_sweeps', 0)} grid sweep(s)",
            )
        )
    return rows


def _predict(done: list[tuple[float, float]], spacing: float) -> float:
    """Seconds at ``spacing``: ``a + b / s²`` through the last two (spacing, seconds) points."""
    if not done:
        return 0.0
    if len(done) == 1:
        s0, t0 = done[-1]
        return t0 * (s0 / spacing) ** 2
    (s1, t1), (s2, t2) = done[-2], done[-1]
    b = max((t2 - t1) / (s2**-2 - s1**-2), 0.0)
    return max(t2 - b * s2**-2, 0.0) + b * spacing**-2


def coherent_rows(case: Case, refs: Refs, args) -> list[Row]:
    rows, done = [], []
    n = case.trajectory.n_pings
    for spacing in [*sorted(args.spacings, reverse=True), None]:
        label = f"s={spacing:g}λ" if spacing is not None else f"default ≤{SEABED_SPACING:g}λ"
        if spacing is None:  # the defaults: λ/4 on objects, SEABED_SPACING on the seabed
            options, guess = {}, 0.0
        else:
            options = {"spacing_wavelengths": spacing, "seabed_spacing_wavelengths": spacing}
            guess = _predict(done, spacing)
        if guess > args.coherent_cap and spacing is not None:
            rows.append(
                Row(
                    case,
                    "coherent",
                    label,
                    notes=f"skipped: predicted {guess:.0f} s > {args.coherent_cap:g} s cap",
                )
            )
            continue
        t = best_of(
            lambda o=options: render_coherent(case.scene, case.sonar, case.trajectory, **o),
            args.repeat,
            args.cap,
        )
        if spacing is not None:
            done.append((spacing, t.best))
        md = t.result.metadata
        sides = to_raster_units(t.result).sides
        prof, scale = profile_error(sides, refs.conv.sides, refs.band)
        rows.append(
            Row(
                case,
                "coherent",
                label,
                t.best,
                t.runs,
                prof=prof,
                scale=scale,
                contrast=contrast(sides, refs.band),
                noise=speckle_noise(sides, refs.band, n),
                default=spacing is None,
                notes=(
                    f"{md['n_scatterers'] / 1e6:.3g} M scatterers, {md['n_pairs'] / 1e6:.3g} M "
                    f"pairs, peak {md['peak_memory_bytes'] / 2**20:.0f} MiB; predicted "
                    f"{guess:.1f} s"
                ),
            )
        )
    return rows


def fine_contrast_row(case: Case, spacing: float, pings: int) -> Row:
    """Speckle contrast of (nearly) point samples: bins 8× finer, the same pulse and beam."""
    sonar = case.sonar
    fine = replace(sonar, range_bin=sonar.range_bin / FINE_DIVISOR)
    rows = slice(max(0, case.trajectory.n_pings // 2 - pings // 2), None)
    rows = slice(rows.start, min(case.trajectory.n_pings, rows.start + pings))
    traj = case.trajectory.subset(rows)
    from sonar_raster.rendering.coherent.model import HorizontalBeam

    seconds, image = timed(
        lambda: render_coherent(
            case.scene,
            fine,
            traj,
            pulse=Pulse.for_range_bin(sonar.range_bin, sonar.sound_speed),
            horizontal_beam=HorizontalBeam.for_track(sonar, case.trajectory),
            spacing_wavelengths=spacing,
            seabed_spacing_wavelengths=spacing,
        )
    )
    band = Band.of(replace(case, sonar=fine, trajectory=traj))
    return Row(
        case,
        "coherent",
        f"s={spacing:g}λ fine bins",
        seconds,
        1,
        contrast=contrast(to_raster_units(image).sides, band),
        notes=f"bins/{FINE_DIVISOR}, same pulse (c/2B = {FINE_DIVISOR} bins), {pings} pings",
    )


# -- Pareto fronts ----------------------------------------------------------------------------
def pareto(points: list[tuple[float, float]]) -> list[int]:
    """Indices of the non-dominated (seconds, error) points, fastest first."""
    order = sorted(
        (i for i, (t, e) in enumerate(points) if math.isfinite(t) and math.isfinite(e) and e > 0),
        key=lambda i: points[i],
    )
    front, best = [], math.inf
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


FRONTS = (("c", "l1_conv", ("raster",)), ("r", "l1_ref", ("raster",)),
          ("p", "prof", ("raster", "coherent")))  # fmt: skip


def mark_fronts(rows: list[Row]) -> None:
    """Set ``front`` on the rows of one scene (accuracy references excluded)."""
    for letter, attr, models in FRONTS:
        cand = [r for r in rows if r.model in models and not r.setting.startswith("conv")]
        for i in pareto([(r.seconds, getattr(r, attr)) for r in cand]):
            cand[i].front += letter


# -- output -----------------------------------------------------------------------------------
COLUMNS = (
    ("scene", 26), ("model", 9), ("setting", 28), ("s", 8), ("runs", 4), ("L1/conv", 8),
    ("L1/ref8", 8), ("prof", 8), ("scale", 6), ("contrast", 8), ("noise", 7), ("front", 5),
    ("load", 5), ("notes", 0),
)  # fmt: skip


def _line(cells: tuple[str, ...]) -> str:
    pairs = zip(cells, COLUMNS, strict=True)
    return " ".join(c.ljust(width) for c, (_, width) in pairs).rstrip()


def print_rows(rows: list[Row], header: bool = False) -> None:
    if header:
        print(_line(tuple(h for h, _ in COLUMNS)))
    for r in rows:
        cells = (
            r.case.label, r.model, ("* " if r.default else "") + r.setting,
            "-" if not math.isfinite(r.seconds) else f"{r.seconds:.3f}", str(r.runs),
            _fmt(r.l1_conv), _fmt(r.l1_ref), _fmt(r.prof), _fmt(r.scale), _fmt(r.contrast),
            _fmt(r.noise, 2), r.front or "", f"{r.load:.2f}", r.notes,
        )  # fmt: skip
        print(_line(cells), flush=True)


def print_summary(rows: list[Row]) -> None:
    """Per scene: the raster's L1/conv front, and where the default stands against it."""
    print("\n# raster Pareto front by L1/conv (fastest first), and the default")
    for label in dict.fromkeys(r.case.label for r in rows):
        mine = [
            r for r in rows
            if r.case.label == label and r.model == "raster" and not r.setting.startswith("conv")
        ]  # fmt: skip
        front = sorted((r for r in mine if "c" in r.front), key=lambda r: r.seconds)
        print(f"{label}:")
        for r in front:
            print(f"    front   {r.setting:<24} {r.seconds:8.3f} s  L1/conv {r.l1_conv:.3g}")
        for d in (r for r in mine if r.default):
            print(f"    default {d.setting:<24} {d.seconds:8.3f} s  L1/conv {d.l1_conv:.3g}: "
                  f"{_standing(d, mine)}")  # fmt: skip


def _standing(d: Row, rows: list[Row]) -> str:
    """Whether ``d`` is on the L1/conv front, within timing noise of it, or clearly dominated."""
    if "c" in d.front:
        return "on the front"
    clear = [
        r for r in rows
        if r is not d and r.seconds <= d.seconds and r.l1_conv <= d.l1_conv
        and (r.seconds < 0.9 * d.seconds or r.l1_conv < 0.9 * d.l1_conv)
    ]  # fmt: skip
    if not clear:
        return "off the front only by < 10 % in time and error (timing noise)"
    clear.sort(key=lambda r: r.l1_conv)
    return "dominated (faster and at least as accurate) by " + ", ".join(
        f"{r.setting} ({r.seconds:.3f} s, {r.l1_conv:.3g})" for r in clear[:3]
    )


def plot(path: Path, rows: list[Row]) -> None:
    """Log-log error against seconds: L1/conv, L1/ref8 (raster) and prof (both models)."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(19, 6))
    labels = list(dict.fromkeys(r.case.label for r in rows))
    marker = {"nearest": "x", "linear": "+", "footprint": "o"}
    panels = (
        ("l1_conv", "c", "raster: relative L1 vs converged raster"),
        ("l1_ref", "r", "raster: relative L1 vs reference (patch bin/8)"),
        ("prof", "p", "profile rel. RMS vs converged raster (▲ coherent)"),
    )
    for ax, (attr, letter, title) in zip(axes, panels, strict=True):
        for k, label in enumerate(labels):
            colour = f"C{k}"
            mine = [
                r for r in rows
                if r.case.label == label and r.model in ("raster", "coherent")
                and not r.setting.startswith("conv")
                and math.isfinite(r.seconds) and math.isfinite(getattr(r, attr))
                and getattr(r, attr) > 0
            ]  # fmt: skip
            for r in mine:
                if r.model == "coherent":
                    ax.loglog(r.seconds, r.prof, "^", color=colour, ms=7)
                    ax.annotate(r.setting, (r.seconds, r.prof), fontsize=6)
                    if math.isfinite(r.noise):
                        ax.loglog(r.seconds, r.noise, "_", color=colour, ms=10)
                else:
                    split = r.setting.split()[2]
                    ax.loglog(r.seconds, getattr(r, attr), marker[split], color=colour,
                              mfc="none", ms=5, alpha=0.6)  # fmt: skip
                if r.default:
                    ax.loglog(r.seconds, getattr(r, attr), "*", color=colour, ms=14, mec="k")
            front = sorted((r for r in mine if letter in r.front), key=lambda r: r.seconds)
            if front:
                ax.loglog([r.seconds for r in front], [getattr(r, attr) for r in front], "-",
                          color=colour, lw=1.5, label=label)  # fmt: skip
        ax.set(xlabel="seconds (one window of pings)", ylabel="error", title=title)
        ax.grid(True, which="both", alpha=0.2)
    for split, m in marker.items():
        axes[0].plot([], [], m, color="grey", mfc="none", label=f"raster {split}")
    axes[0].plot([], [], "*", color="grey", ms=12, mec="k", label="default")
    axes[2].plot([], [], "_", color="grey", ms=10, label="coherent speckle noise")
    axes[0].legend(fontsize=7)
    axes[2].legend(fontsize=7)
    fig.suptitle("time against error; lines: Pareto fronts per scene", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, dpi=120)


# -- main -------------------------------------------------------------------------------------
def run_scene(name: str, args) -> list[Row]:
    case = scene_case(name, args.window, args.quick)
    with RasterRenderer(args.backend) as renderer:
        refs, rows = make_refs(case, renderer, not args.no_reference)
        rows += raster_rows(case, refs, renderer, args)
    rows += coherent_rows(case, refs, args)
    if name == ROUGH and args.fine_spacing > 0:
        rows.append(fine_contrast_row(case, args.fine_spacing, args.fine_pings))
    mark_fronts(rows)
    return rows


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    bundled = [n for n, _ in list_bundled()]
    ap = parser(__doc__, out=Path("bench_out"))
    ap.add_argument(
        "--quick",
        action="store_true",
        help="flat_calibration and a small rough_plain, 4-ping window, a small grid (< 2 min)",
    )
    ap.add_argument("--scenes", help=f"comma-separated subset of {', '.join(bundled + [ROUGH])}")
    ap.add_argument("--window", type=int, help="pings in a bundled scene's window (16; quick 4)")
    ap.add_argument("--repeat", type=int, default=3, help="timing runs per setting (best kept)")
    ap.add_argument(
        "--cap", type=float, default=5.0, help="stop repeating once a setting's runs took this"
    )
    ap.add_argument(
        "--floor",
        type=float,
        default=0.3,
        help="repeat a fast raster setting until its runs took this many seconds (<= 100 runs)",
    )
    ap.add_argument(
        "--spacings",
        help="coherent scatterer spacings, wavelengths (4,2,1,0.5,0.25; quick 4,2,1)",
    )
    ap.add_argument(
        "--coherent-cap",
        type=float,
        default=60.0,
        help="skip a coherent spacing predicted to take longer than this many seconds",
    )
    ap.add_argument(
        "--fine-spacing",
        type=float,
        default=1.0,
        help="spacing (wavelengths) of the fine-bin speckle render of rough_plain; 0 skips it",
    )
    ap.add_argument("--fine-pings", type=int, help="pings of the fine-bin render (8; quick 4)")
    ap.add_argument("--no-reference", action="store_true", help="skip ref/8 (the slow part)")
    ap.add_argument(
        "--grid-raster",
        action="store_true",
        help="also render every raster setting with seabed grids rasterised (heightfield=False)",
    )
    ap.add_argument("--backend", choices=("egl", "osmesa"), help="GL backend")
    args = ap.parse_args(argv)
    names = bundled + [ROUGH]
    default = ["flat_calibration", ROUGH] if args.quick else names
    args.scenes = args.scenes.split(",") if args.scenes else default
    unknown = sorted(set(args.scenes) - set(names))
    if unknown:
        ap.error(f"unknown scene(s) {', '.join(unknown)}; choose from {', '.join(names)}")
    args.window = args.window or (4 if args.quick else 16)
    args.fine_pings = args.fine_pings or (4 if args.quick else 8)
    spacings = args.spacings or ("4,2,1" if args.quick else "4,2,1,0.5,0.25")
    args.spacings = [float(s) for s in spacings.split(",")]
    args.grid = QUICK_GRID if args.quick else FULL_GRID
    args.edges = QUICK_EDGES if args.quick else FULL_EDGES
    return args


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    with RasterRenderer(args.backend) as probe:
        info = probe.gl_info
    print(
        f"# {info['gl_backend']}: {info['gl_renderer']}; {os.cpu_count()} cores, load "
        f"{os.getloadavg()[0]:.2f}; window {args.window} pings; raster best of {args.repeat} "
        f"(cap {args.cap:g} s); coherent cap {args.coherent_cap:g} s; default {DEFAULT}"
    )
    print_rows([], header=True)
    rows: list[Row] = []
    for name in args.scenes:
        scene_rows = run_scene(name, args)
        print_rows(scene_rows)
        rows += scene_rows
    write_csv(args.out / "bench_accuracy.csv", [r.as_dict() for r in rows])
    print_summary(rows)
    plot(args.out / "bench_accuracy.png", rows)
    print(
        f"\nwrote {args.out}/bench_accuracy.csv, bench_accuracy.png "
        f"({time.perf_counter() - start:.0f} s)"
    )


if __name__ == "__main__":
    main()
