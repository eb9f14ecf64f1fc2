"""Fitting the surface: levels coarse to fine, Gauss-Newton on Z, L-BFGS on R and Φ.

Also the Laplace uncertainty of Z.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import partial
from typing import TYPE_CHECKING

import numpy as np
from scipy import ndimage, optimize, sparse

from ..._checks import integer
from ...errors import SonarRasterError
from ..model import Geometry, deposit_matrix, forward, jacobian_z
from . import problem as prob
from .layout import (
    Frame,
    Line,
    View,
    cell_points,
    check_lines,
    pool,
    pool_heading,
    pool_image,
    tensor_basis,
)
from .problem import (
    SYMMETRIC_LU,
    Beam,
    Grid,
    Problem,
    each,
    flat_start_knots,
    line_profile,
    shade_jacobian,
    soft_shadow,
)
from .shrink import shrink_relief

if TYPE_CHECKING:
    from ..solver import BeamProfile

#: The line-profile prior's weight (a factor on its own) and low-pass (a fraction of the
#: altitude) on a calibrated side: Φ's shape known, it only keeps the swath's level (without it
#: sand waves' far swath floated 5 cm up; a quarter of the altitude held trenches flat).
CALIBRATED_LINE_WEIGHT = 1.0
CALIBRATED_LINE_SCALE = 1.0
#: Knot spacing of Z and of log R in range bins when not given.
Z_KNOT_BINS = 4.0
R_KNOT_BINS = 4.0
#: Points per ground cell in the model (sonar_raster.inversion.model).
SUBSAMPLES = 2
#: How the model shares a point's return among the range bins (``Geometry.deposit``):
#: "segment" spreads it over its slant-range interval and overlaps that with the bins' boxes,
#: as the renderer bins; "tent" splits it between the two nearest bin centres.
DEPOSIT = "tent"
#: A one-bin box in range sampled on the bins: what the tent deposit adds to the renderer's
#: binning.
TENT_BLUR = (0.25, 0.5, 0.25)
#: Take the crests the first return reads off its altitude before each Gauss-Newton step
#: (:func:`_track_model`).
CREST_OFFSET = True

#: Largest number of looks the likelihood trusts (the model's own error on clean images).
MAX_LOOKS = 30.0
#: Gauss-Newton steps on the Z knots per level (each followed by L-BFGS on R and Φ); 0: plain
#: L-BFGS on everything.
GAUSS_NEWTON_STEPS = 8
#: L-BFGS iterations on R and Φ after each Gauss-Newton step.
INNER_ITERATIONS = 20
#: Relative residual to which each Gauss-Newton step's conjugate gradients solve (at most 30
#: iterations). Looser is not worth it: 1e-2 moved a flat seabed 1.3 cm (its level is the
#: smooth mode CG reaches last); 1e-3 saved little once the steps were deflated, and on the
#: default render left 62 % of starboard's open seabed within 5 cm against 70 % at 1e-5
#: (docs/notes/2026-11-28-fit-speed.md).
GAUSS_NEWTON_RTOL = 1e-5
#: A restart of L-BFGS after its line search failed must lower E by this much (E is divided by
#: looks × bins, so per bin) for another restart.
RESTART_GAIN = 1e-6
#: Ground cells whose slant range at the altitude lies within this many bins of the image's
#: end get no estimate (NaN) in the per-side results; bins of the finest level fitted (the
#: outermost knots, as wide as its bins, are barely seen by the image).
EDGE_BINS = 6
#: The Gauss-Newton Jacobian includes Z's change of the cast shadows (else shadows held).
SHADOW_JACOBIAN = True
#: Each Gauss-Newton step solves for the Z knots and the log Φ nodes together (Φ eliminated:
#: a Schur complement of low rank) instead of Z with Φ held. Φ and Z are coupled wherever
#: every ping shares a bend (most near the nadir), and alternating the two creeps along that
#: valley (docs/notes/2026-11-29-joint-beam.md).
JOINT_BEAM = True
#: With ``JOINT_BEAM``, only in fits whose finest level pools the images at most this much
#: (``finest``, ``invert --coarsen``). Φ free to follow it, the level rests on the first-return
#: anchor less the crests it reads (``CREST_OFFSET``), which the model shows only where its
#: knots resolve the relief beside the nadir: at ``--coarsen 4`` they do not, and sand waves
#: came out at their crests.
JOINT_BEAM_MAX_POOLING = 2
#: The joint step's trust region, in range bins: no Z knot moves by more than this per step
#: (the step scaled down whole, Φ's part with it). Each level's fit starts at this radius, and
#: :func:`_trust_radius` updates it after each step. Without a bound, the fine level's first
#: step threw the knots beside the nadir −3.7 / +2.2 cm with Φ's nadir nodes (the model's
#: first bins, where the Gauss-Newton model is poorest), and the fit stayed there: a clean
#: flat seabed 1.5 cm rms off.
JOINT_STEP_BINS = 1.0
#: The radius halves after a step whose decrease of E fell below the first of these fractions
#: of the decrease the Gauss-Newton model predicted (or that had to backtrack), and doubles
#: after a step that reached the radius and did better than the second. A radius held at one
#: bin cost single-look sand waves 0.51 → 0.76 (docs/notes/2026-11-29-trust-region.md).
JOINT_TRUST_RATIO = (0.25, 0.75)
#: Depression-angle nodes of log Φ, per degree.
BEAM_NODES_PER_DEGREE = 1.0
#: A line's scattering law (``Line.law``) is modelled at the finest level fitted only; the
#: coarser levels model Lambert's law and hand their seabed on. From the flat start a steep
#: law (APL-UW sand falls 3.8 nats from 30° to 6° grazing) leads the coarse fit astray: on the
#: bench's single-look sand waves rendered with sand's law, the law at every level 0.819, at
#: the finest only 0.639, Lambert's throughout 0.728 (docs/notes/2026-12-02-law-in-fit.md).
LAW_AT_FINEST_ONLY = True
#: Objects whose cast shadow (:func:`..shadows.find_shadows` on the coarsest level's image)
#: gives at least this height, in range bins of that level, start the fit at that height
#: (None: every fit starts flat). From a flat start the shadow's darkness is cheaper to
#: explain by low R or a hollow behind the object than by growing it, since no shadow, hence
#: no gradient towards one, exists until the object is tall enough to cast it.
SHADOW_START_BINS: float | None = 2.0
#: Largest gap between the highlight and the shadow it must follow there, metres: an
#: object's top can be no brighter than the seabed for a metre before its shadow (single look,
#: 4-look coarse level: 0.3 m found 4 of 15 pings of a 2 m wide box, 1 m all 15).
SHADOW_HIGHLIGHT_GAP_M = 1.0
#: Widest start given to an object across track, metres, back from the edge that casts the
#: shadow: the highlight's start is no measure of the near edge far out (near range is
#: brighter than the ping's median, so with a 1 m gap the bright run reaches back towards
#: nadir: a 2.5 m box 22 m out started 14 m wide); 1 m was too narrow for the fit to widen
#: (bench box, one line: 0.71 against 0.52).
SHADOW_OBJECT_M = 3.0
#: Most pings between two pings with shadow heights that are filled from them.
_SHADOW_GAP = 3
#: Fewest pings in a row whose shadows give heights for an object to be raised (two gave
#: rough-seabed bumps at grazing range: the rough plain's score 1.26 -> 1.29).
_SHADOW_PINGS = 3

#: Z knots above which the Gauss-Newton steps are preconditioned by algebraic multigrid
#: (pyamg's smoothed aggregation) instead of the complete LU factors, whose fill grows faster
#: than the knots (28.7 k knots: 1.8e7 entries, 1.3 s; 84 k: 6.7e7, 5.6 s). The bench's
#: 200-ping fit 1.23x and its 600-ping one 1.51x faster, scores within their noise
#: (tools/bench_surface_solver.py; docs/notes/2026-11-27-solver-scaling.md).
AMG_KNOTS = 20_000
#: Smoothed aggregation settings: Jacobi-smoothed prolongation, one symmetric Gauss-Seidel
#: sweep before and after (symmetric, so the V-cycle is a valid conjugate-gradient
#: preconditioner). At the issue's size, against energy-minimising prolongation: set-up 0.25
#: against 0.45 s, 14.2 against 15.4 iterations per step; two sweeps each way took 10 % fewer
#: iterations but 15-20 % more time in the steps' CG (docs/notes/2026-11-28-fit-speed-2.md).
AMG = {
    "smooth": "jacobi",
    "presmoother": ("gauss_seidel", {"sweep": "symmetric", "iterations": 1}),
    "postsmoother": ("gauss_seidel", {"sweep": "symmetric", "iterations": 1}),
}
#: Draws of the Laplace approximation behind each cell's Z std (32 estimate a std to ~12 %).
LAPLACE_SAMPLES = 32
#: Incomplete LU of the uncertainty's diagonal blocks (Z, log R) as its preconditioner: on the
#: bench's 2 x 28 737 knots 3.4-3.6 s for the 32 samples against 9.7 s with complete LU
#: factors, the cells' Z std within 0.8 % (median 0.02 %) of theirs (tools/bench_uncertainty.py).
BLOCK_ILU = {"drop_tol": 1e-4, "fill_factor": 10}
#: Precision of that preconditioner and of the products in its conjugate gradients (the
#: iterates stay float64): at the issue's size float32 took the 32 samples' CG 7.3 → 5.4 s and
#: the factorisation 2.5 → 2.0 s, the same 18 iterations, the knots' Z std within 0.15 % of
#: float64's (docs/notes/2026-11-28-fit-speed-2.md).
UNCERTAINTY_DTYPE = np.float32

#: Shrink the relief the fit's own noise could explain towards its smooth trend (:mod:`.shrink`;
#: needs the uncertainty).
SHRINK_RELIEF = True

Progress = Callable[[str], None]


@dataclass
class SurfaceFit:
    """Result of the fit for one line; maps are (pings, ground cells) per side.

    Attributes
    ----------
    x : ndarray, shape (cells,)
        Ground-range cell centres, metres (on each side).
    elevation, reflectivity, beam : dict of str to ndarray
        Z (metres relative to the transducer), R and Φ per side.
    elevation_std : dict of str to ndarray
        Standard deviation of Z per cell, metres (Laplace approximation; see
        :func:`elevation_std`); empty without ``uncertainty``.
    profile : dict of str to (ndarray, ndarray)
        Per side, depression angles (radians) and Φ there (shared by every line).
    looks : dict of str to float
        Looks used by the likelihood per side.
    altitude : ndarray, shape (pings,)
        First-return (or given) altitude per ping, metres.
    position : dict of str to ndarray, each shape (pings, cells, 2)
        Where each cell is, in the lines' frame (e.g. easting, northing), metres.
    energies : list of float
        Objective after each level (of the joint fit of every line).
    evaluations : list of int
        Objective evaluations per level.
    """

    x: np.ndarray
    elevation: dict[str, np.ndarray]
    reflectivity: dict[str, np.ndarray]
    beam: dict[str, np.ndarray]
    elevation_std: dict[str, np.ndarray]
    profile: dict[str, tuple[np.ndarray, np.ndarray]]
    looks: dict[str, float]
    altitude: np.ndarray = field(default_factory=lambda: np.zeros(0))
    position: dict[str, np.ndarray] = field(default_factory=dict)
    energies: list[float] = field(default_factory=list)
    evaluations: list[int] = field(default_factory=list)


def fit_lines(
    lines: Sequence[Line],
    *,
    looks: float | str = "auto",
    z_knot: float | None = None,
    r_knot: float | None = None,
    levels: int = 2,
    finest: int = 1,
    max_iter: int = 150,
    uncertainty: bool = True,
    beam: BeamProfile | Mapping[str, BeamProfile] | str | os.PathLike | None = None,
    progress: Progress | None = None,
) -> list[SurfaceFit]:
    """Fit one seabed surface, its reflectivity and each side's beam profile to several lines.

    Every side of every line is fitted in one problem: Z and log R are splines on one grid in
    a frame along the first line, so where lines overlap they share the unknowns (and a swath's
    far range, seen by the next line at near range, fixes the bend the beam would absorb);
    Φ is one profile per side shared by all lines; each line's first return anchors its nadir.

    Parameters
    ----------
    lines : sequence of Line
        The lines; one is enough.
    looks : float or "auto"
        Speckle looks of the images; "auto" estimates them per view from neighbouring pings.
    z_knot, r_knot : float, optional
        Knot spacing of Z and of log R, metres (default 4 range bins of the first line, at least
        its ping spacing).
    levels : int
        Resolution levels (each halves pings and bins), coarse to fine.
    finest : int
        Pooling of the finest level fitted: 1 (default) fits the images as they are; 2 or 4
        stop at the images pooled 2 × 2 or 4 × 4 (knots that much wider), about 4 or 16 times
        faster; the products still come at every ping and bin, from the wider knots. What it
        costs in accuracy: docs/inversion.md, "Coarser fits".
    max_iter : int
        Most L-BFGS iterations per level where the fit is plain L-BFGS
        (``GAUSS_NEWTON_STEPS = 0``).
    uncertainty : bool
        Estimate the standard deviation of Z per cell (:func:`elevation_std`).
    beam : BeamProfile, mapping of str to BeamProfile, or path, optional
        Calibrated mode: a beam profile from an earlier fit of the same sensor (e.g. a
        ``beam_profile.json``, or an earlier run's output folder), one for every side or one
        per side. Its shape is held where its
        angles reach (:data:`.problem.CALIBRATED_BEAM_STD`), its level is fitted; relief that
        every ping shares (a trench along the track), which a free Φ would absorb, is then
        seen; the prior on the line-averaged profile of Z, which stood in for the calibration,
        only keeps the swath's level there (its low-pass widened, ``CALIBRATED_LINE_SCALE``).
    progress : callable, optional
        Called with a line of text after each level.

    Returns
    -------
    list of SurfaceFit
        One per line, in order.
    """
    start = time.perf_counter()
    if isinstance(beam, (str, os.PathLike)):
        from ..solver import load_beams

        beam = load_beams(beam)
    prepared, frame, grids = _setup(lines, looks, z_knot, r_knot, levels, finest)
    params: np.ndarray | None = None
    previous: Problem | None = None
    energies, evaluations = [], []
    for k, (f, grid) in enumerate(grids):
        # "level 2/2 (1/1 res.)": the level's place, then its pooling (as the profiles say)
        label = f"level {k + 1}/{len(grids)} (1/{f} res.)"
        problem = _level(prepared, frame, grid, f, finest)
        if beam:
            problem.beam_reference = beam_reference(grid, beam)
            calibrated = (CALIBRATED_LINE_WEIGHT, CALIBRATED_LINE_SCALE)
            problem.line_prior = dict.fromkeys(problem.beam_reference, calibrated)
        if params is None or previous is None:
            params = _start(problem)
            if SHADOW_START_BINS is not None:
                params[: problem.nz] += _raise_objects(problem)
        else:
            params = _transfer(previous, params, problem)
        previous = problem
        step = None
        if progress is not None:
            step = partial(_report_step, progress, label, start)
        if GAUSS_NEWTON_STEPS:
            # the options only where asked (older wrappers of _gauss_newton take neither)
            options: dict = {}
            if JOINT_BEAM and finest <= JOINT_BEAM_MAX_POOLING:
                options["joint"] = True
            if CREST_SHIFTS and finest <= CREST_SHIFTS_MAX_POOLING:
                options["shifts"] = CREST_SHIFTS
            params, value, count = _gauss_newton(
                problem, params, GAUSS_NEWTON_STEPS, step, **options
            )
        else:
            params, value, count = _minimise(problem, params, max_iter)
        energies.append(value)
        evaluations.append(count)
        if progress is not None:
            progress(
                f"{label}: E {value:.6g} after {count} evaluations"
                f" ({time.perf_counter() - start:.0f} s)"
            )
    assert params is not None and previous is not None
    if uncertainty and progress is not None:
        progress(
            f"uncertainty of Z: {LAPLACE_SAMPLES} samples of {previous.nz + previous.nr} knots"
        )
    # the products at every ping and bin, from the knots of the finest level fitted
    full = (
        previous if finest == 1 else _level(prepared, frame, previous.grid, 1, flat=previous.flat)
    )
    std = elevation_std(previous, params, cells=full) if uncertainty else {}
    if progress is not None:
        progress(f"done in {time.perf_counter() - start:.0f} s")
    return _results(full, params, frame, std, energies, evaluations)


def beam_reference(
    grid: Grid, beam: BeamProfile | Mapping[str, BeamProfile]
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per side of ``grid``, a calibrated profile's log Φ at the Φ nodes and where it holds.

    A node holds where its angle lies within the profile's angles and the profile is > 0
    there; a side a mapping lacks stays free.
    """
    theta = np.linspace(*grid.angles, grid.nodes)
    out = {}
    for side in grid.sides:
        profile = beam.get(side) if isinstance(beam, Mapping) else beam
        if profile is None:
            continue
        gain = profile(theta)
        lo, hi = float(np.min(profile.depression)), float(np.max(profile.depression))
        held = (theta >= lo) & (theta <= hi) & (gain > 0)
        if held.sum() < 2:
            raise SonarRasterError(
                f"the {side} beam profile covers {math.degrees(lo):.1f}-{math.degrees(hi):.1f}°"
                f" of depression, the lines need {math.degrees(grid.angles[0]):.1f}-"
                f"{math.degrees(grid.angles[1]):.1f}°; calibrate on a line of similar altitude"
            )
        out[side] = (np.log(np.where(held, gain, 1.0)), held.astype(np.float64))
    return out


def _report_step(
    progress: Progress, level: str, start: float, k: int, steps: int, value: float
) -> None:
    """One progress line after Gauss-Newton step ``k`` of ``steps`` at a level."""
    elapsed = time.perf_counter() - start
    progress(f"{level}: Gauss-Newton step {k}/{steps}, E {value:.6g} ({elapsed:.0f} s)")


def _setup(lines, looks, z_knot, r_knot, levels, finest=1):
    """Checked lines with their altitude, height and looks; the frame; the grid per level."""
    from ..bottom import track_bottom
    from ..ground import check_slant
    from ..priors import estimate_looks

    check_lines(lines)
    integer("levels", levels)
    if not (looks == "auto" or (isinstance(looks, (int, float)) and 0 < looks < math.inf)):
        raise SonarRasterError(f"looks must be 'auto' or a number > 0, not {looks!r}")
    if isinstance(finest, bool) or not float(finest).is_integer() or finest < 1:
        raise SonarRasterError(f"finest must be a whole number of 1 or more, not {finest!r}")
    finest = int(finest)
    prepared = []
    for line in lines:
        images = {n: check_slant(v, line.range_bin, min_pings=2) for n, v in line.sides.items()}
        if line.altitude is None:
            alt = track_bottom(images, line.range_bin).altitude
        else:
            alt = np.broadcast_to(np.asarray(line.altitude, np.float64), (line.pings,)).copy()
        height = np.zeros(line.pings) if line.height is None else np.asarray(line.height, float)
        look = {}
        for name, image in images.items():
            est = estimate_looks(image, image > 0) if looks == "auto" else float(looks)
            look[name] = float(min(max(est, 1.0), MAX_LOOKS))
        prepared.append((line, images, alt, height, look))
    frame = Frame.of(lines)
    first = lines[0]
    spacing = first.spacing
    zs = float(z_knot or max(Z_KNOT_BINS * first.range_bin, spacing))
    rs = float(r_knot or max(R_KNOT_BINS * first.range_bin, spacing))
    extent, angles = _extent(prepared, frame)
    sides = tuple(s for s in ("port", "starboard") if any(s in p[1] for p in prepared))
    grids = [
        (f, Grid(extent, zs * f, rs * f, angles[:2], angles[2], sides))
        for f in [finest * 2**k for k in range(levels - 1, -1, -1)]
    ]
    return prepared, frame, grids


def problem_at(
    lines: Sequence[Line],
    *,
    looks: float | str = "auto",
    z_knot: float | None = None,
    r_knot: float | None = None,
    level: int = 1,
) -> Problem:
    """The problem :func:`fit_lines` solves at pooling ``level`` (1: full resolution)."""
    prepared, frame, grids = _setup(lines, looks, z_knot, r_knot, int(math.log2(level)) + 1)
    f, grid = grids[0]
    return _level(prepared, frame, grid, f)


def fit_surface(
    sides: Mapping[str, np.ndarray],
    range_bin: float,
    *,
    ping_spacing: float,
    altitude: np.ndarray | None = None,
    **options,
) -> SurfaceFit:
    """:func:`fit_lines` of one straight line, pings ``ping_spacing`` apart.

    Parameters
    ----------
    sides : mapping of str to ndarray, each shape (pings, bins)
        ``"port"`` and/or ``"starboard"`` images, linear intensity >= 0, bins from range 0.
    range_bin : float
        Slant-range bin, metres.
    ping_spacing : float
        Along-track distance between pings, metres.
    altitude : ndarray, shape (pings,), optional
        Altitude per ping (default: the first bottom return of the sides).
    **options
        As for :func:`fit_lines`.

    Returns
    -------
    SurfaceFit
    """
    if not sides or any(n not in ("port", "starboard") for n in sides):
        raise SonarRasterError("sides must be 'port' and/or 'starboard'")
    if len({np.asarray(v).shape[0] for v in sides.values()}) != 1:
        raise SonarRasterError("both sides must have the same number of pings")
    line = Line.straight(sides, range_bin, ping_spacing, altitude)
    return fit_lines([line], **options)[0]


def _extent(prepared, frame: Frame) -> tuple[tuple[float, float, float, float], tuple]:
    """The frame box every cell of every line falls in, and the Φ node angles."""
    from ..ground import ground_axis

    ys, xs, lows, highs = [], [], [], []
    for line, images, alt, _, _ in prepared:
        bins = next(iter(images.values())).shape[1]
        reach = float(ground_axis(alt, line.range_bin, bins, line.range_bin)[-1])
        reach += line.range_bin
        for side in images:
            y, x = cell_points(frame, line.position, line.heading, side, np.array([0.0, reach]))
            ys.append(y.ravel())
            xs.append(x.ravel())
        lows.append(math.atan2(float(np.min(alt)), reach))
        highs.append(math.atan2(float(np.max(alt)), 0.5 * line.range_bin))
    y, x = np.concatenate(ys), np.concatenate(xs)
    spacing = prepared[0][0].spacing
    y0, y1 = float(y.min()), float(max(y.max(), y.min() + spacing))
    lo, hi = min(lows), max(highs)
    nodes = max(4, int(math.degrees(hi - lo) * BEAM_NODES_PER_DEGREE) + 2)
    return (y0, y1, float(x.min()), float(x.max())), (lo, hi, nodes)


def _level(
    prepared, frame: Frame, grid: Grid, f: int, finest: int = 1, flat: np.ndarray | None = None
) -> Problem:
    """Every view at pooling ``f`` (``finest``: the finest level's), and the problem over them.

    ``flat``: the flat seabed's knots where they are known (the products' problem on the
    fitted grid), else made from the views' first returns.
    """
    from ..ground import ground_axis

    views = []
    for k, (line, images, alt, height, look) in enumerate(prepared):
        rb = line.range_bin * f
        h = pool(alt, f)
        position = pool(np.asarray(line.position, float), f)
        heading = pool_heading(np.asarray(line.heading, float), f)
        dy = line.spacing * f
        for side, image in images.items():
            pooled = pool_image(image, f) / rb  # per metre of slant range
            if DEPOSIT == "tent":
                # the tent shares each return between two bins where the image's bins are
                # boxes: in expectation the model is the image blurred by a one-bin box in
                # range, so it is compared with the image blurred likewise (unblurred, the fit
                # moves a flat seabed deeper to keep the tent's spill out of the water column
                # before the first return)
                pooled = ndimage.convolve1d(pooled, TENT_BLUR, axis=1, mode="nearest")
            bins = pooled.shape[1]
            x = ground_axis(h, rb, bins, rb)
            law = None if LAW_AT_FINEST_ONLY and f > finest else line.law
            geom = Geometry(x, rb, dy, rb, bins, SUBSAMPLES, DEPOSIT, law)
            y_pts, x_pts = cell_points(frame, position, heading, side, x)
            bz = tensor_basis(y_pts.ravel(), x_pts.ravel(), grid.extent, grid.z_spacing)
            br = bz
            if grid.r_spacing != grid.z_spacing:
                br = tensor_basis(y_pts.ravel(), x_pts.ravel(), grid.extent, grid.r_spacing)
            ny, nx = frame.to_frame(position)
            centres = (np.arange(bins) + 0.5) * rb
            first = centres[None, :] >= 0.9 * h[:, None]
            mask = first & (centres[None, :] < (bins - 3) * rb)
            water = (~first) & (centres[None, :] > 0.3 * h[:, None])
            lit = pooled[mask]
            level = float(np.mean(lit)) if lit.size else 1.0
            floor = float(np.mean(pooled[water])) if water.any() else 0.0
            views.append(
                View(
                    line=k,
                    side=side,
                    image=pooled,
                    mask=mask,
                    floor=max(floor, 1e-3 * level),
                    looks=min(look[side] * f * f, MAX_LOOKS),
                    geom=geom,
                    tau=float(np.nanmedian(h)) * rb / np.maximum(x, rb) ** 2,
                    altitude=h,
                    height=pool(height, f),
                    bz=bz,
                    br=br,
                    nadir=tensor_basis(ny, nx, grid.extent, grid.z_spacing),
                    points=(y_pts, x_pts),
                    # the images' own bin at the finest level fitted (their tracker's error),
                    # pooled like the rest above it
                    anchor_bin=line.range_bin * f / finest,
                    anchor_looks=look[side],  # the image's own, before pooling
                )
            )
    if flat is None:
        ky, kx = (len(k) for k in grid.knots("z"))
        flat = flat_start_knots(views, grid, (ky, kx))
    return Problem(views, grid, flat)


def _start(problem: Problem) -> np.ndarray:
    """Flat seabed at the first returns, R = 1, Φ fitted with Z and R held."""
    p = np.zeros(problem.size)
    p[: problem.nz] = problem.flat.ravel()
    for side in problem.grid.sides:
        data = [v.image[v.mask] for v in problem.views if v.side == side]
        values = np.concatenate(data) if data else np.ones(1)
        p[problem.phi_slice(side)] = math.log(max(float(np.mean(values)), 1e-30))
    free = np.zeros(problem.size, bool)
    free[problem.nz + problem.nr :] = True  # Φ only: R left to the joint fit, which shares
    # the shading between R and Z by their priors (fitted first, R would keep it all)
    p[:], _, _ = _minimise(problem, p, 60, free)
    return p


def _raise_objects(problem: Problem) -> np.ndarray:
    """Z knot offsets of the objects found by their shadows (:func:`_shadow_start`).

    Marks their knots (dilated by one) as ``problem.objects`` and the ground in their shadows
    as ``problem.shadowed``.
    """
    raised, shadowed = _shadow_start(problem)
    rb = problem.views[0].geom.range_bin
    tall = (raised >= 0.5 * (SHADOW_START_BINS or 0.0) * rb).reshape(problem.kz)
    problem.objects = ndimage.binary_dilation(tall).astype(np.float64)
    dark = (shadowed > 0.5).reshape(problem.kz) & (problem.objects == 0)
    problem.shadowed = dark.astype(np.float64)
    return raised


def _shadow_start(problem: Problem) -> tuple[np.ndarray, np.ndarray]:
    """Z knot offsets that raise each object found by its shadow to the shadow's height.

    Per view and ping, :func:`..shadows.find_shadows` gives the highlight's first bin ``k``,
    the shadow's ``[a, b)`` and the height ``H = Ls h / (R + Ls)``; the object stands ``H``
    high over the ground ranges whose top (``h − H`` below the transducer) is seen from slant
    range ``k`` (its near edge, at most ``SHADOW_OBJECT_M`` from the other) to ``a`` (the edge
    that casts the shadow). Heights found on fewer than ``_SHADOW_PINGS`` pings in a row are
    dropped; gaps of up to ``_SHADOW_GAP`` pings between pings with heights take the nearer
    one's. Each knot takes the basis-weighted mean of those bumps (zero elsewhere) over the
    cells it covers (a least-squares fit rings at the bumps' edges), shape (nz,); likewise
    the share of each knot's cells in those shadows (on the flat seabed: ground ranges seen
    from slant ranges ``a`` to ``b``), shape (nz,).
    """
    from ..shadows import find_shadows

    total = np.zeros(problem.nz)
    dark = np.zeros(problem.nz)
    weight = np.zeros(problem.nz)
    for view in problem.views:
        rb = view.geom.range_bin
        known = np.isfinite(view.altitude) & (view.altitude > 0)
        if not known.any():  # no first return anywhere: nothing to measure shadows from
            continue
        alt = np.where(known, view.altitude, float(np.median(view.altitude[known])))
        found = find_shadows(view.image, rb, alt, gap_m=SHADOW_HIGHLIGHT_GAP_M)
        height = np.where(known, np.nan_to_num(found.height), 0.0)
        tall = height >= (SHADOW_START_BINS or 0.0) * rb
        runs, count = ndimage.label(tall)  # seen on at least _SHADOW_PINGS pings in a row
        sizes = np.bincount(runs.ravel(), minlength=count + 1)
        tall &= sizes[runs] >= _SHADOW_PINGS
        source = _nearest_within(tall, _SHADOW_GAP)
        bump = np.zeros(view.shape)
        shade = np.zeros(view.shape)
        x = view.geom.x
        for i in np.flatnonzero(source >= 0):
            j = source[i]
            h = alt[i]
            top = h - height[j]
            near = math.sqrt(max((found.highlight[j] * rb) ** 2 - top * top, 0.0))
            far = math.sqrt(max((found.start[j] * rb) ** 2 - top * top, 0.0))
            near = max(near, far - SHADOW_OBJECT_M)
            bump[i, (x >= near) & (x <= far)] = height[j]
            start = math.sqrt(max((found.start[j] * rb) ** 2 - h * h, 0.0))
            end = math.sqrt(max((found.end[j] * rb) ** 2 - h * h, 0.0))
            shade[i, (x > max(start, far)) & (x < end)] = 1.0
        total += view.bz.T @ bump.ravel()
        dark += view.bz.T @ shade.ravel()
        weight += np.asarray(view.bz.sum(axis=0)).ravel()
    safe = np.maximum(weight, 1e-30)
    return np.where(weight > 0, total / safe, 0.0), np.where(weight > 0, dark / safe, 0.0)


def _nearest_within(found: np.ndarray, gap: int) -> np.ndarray:
    """Per ping, the nearest ping with ``found`` (itself if found), else -1.

    -1 also where the ping lies in a gap of more than ``gap`` pings, or outside the first and
    last found.
    """
    idx = np.flatnonzero(found)
    out = np.full(found.size, -1, np.int64)
    if idx.size == 0:
        return out
    out[idx] = idx
    for a, b in zip(idx[:-1], idx[1:], strict=True):
        if 1 < b - a <= gap + 1:
            mid = np.arange(a + 1, b)
            out[mid] = np.where(mid - a <= b - mid, a, b)
    return out


def _transfer(old: Problem, p: np.ndarray, new: Problem) -> np.ndarray:
    """Parameters of ``new`` (finer knots) from those of ``old``.

    Each new coefficient takes the old surface at its knot centre; the Φ nodes are the same.
    """
    out = np.zeros(new.size)
    zc, rc, lphi = old.split(p)
    out[: new.nz] = old.grid.sample(zc, new.grid.knots("z"), "z").ravel()
    out[new.nz : new.nz + new.nr] = old.grid.sample(rc, new.grid.knots("r"), "r").ravel()
    new.flat = old.grid.sample(old.flat, new.grid.knots("z"), "z")
    knots = new.grid.knots("z")
    if old.objects.any():
        new.objects = (old.grid.sample(old.objects, knots, "z") > 0.25).astype(np.float64)
    if old.shadowed.any():
        dark = (old.grid.sample(old.shadowed, knots, "z") > 0.75) & (new.objects == 0)
        new.shadowed = dark.astype(np.float64)
    for side in new.grid.sides:
        out[new.phi_slice(side)] = lphi[side]
    return out


def _minimise(
    problem: Problem,
    p: np.ndarray,
    max_iter: int,
    free: np.ndarray | None = None,
    objective: Callable[[np.ndarray], tuple[float, np.ndarray]] | None = None,
) -> tuple[np.ndarray, float, int]:
    """L-BFGS on the ``free`` parameters of ``objective`` (default the problem's own)."""
    keep = np.ones(p.size, bool) if free is None else free
    scale = problem.scales()[keep]
    norm = problem.norm
    base = p.copy()
    evaluate = problem if objective is None else objective

    def fun(q: np.ndarray) -> tuple[float, np.ndarray]:
        full = base.copy()
        full[keep] = q * scale
        value, grad = evaluate(full)
        if not np.isfinite(value):
            return math.inf, np.zeros_like(q)
        return value / norm, grad[keep] * scale / norm

    x0 = base[keep] / scale
    # L-BFGS stops early where its line search fails on a kink of the model (a shadow's edge,
    # a facet turning away); it restarts from there with a fresh memory while that still
    # lowers E by a useful amount and iterations are left
    left, count, best = max_iter, 0, math.inf
    while left > 0:
        res = optimize.minimize(
            fun,
            x0,
            jac=True,
            method="L-BFGS-B",
            options={"maxiter": left, "maxcor": 20, "ftol": 1e-12, "gtol": 1e-12},
        )
        count += int(res.nfev)
        left -= max(int(res.nit), 1)
        gain = best - float(res.fun)
        x0, best = res.x, min(best, float(res.fun))
        if res.status != 2 or gain < RESTART_GAIN:  # 2: line search failed
            break
    out = base.copy()
    out[keep] = x0 * scale
    return out, best * norm, count


def _results(
    problem: Problem,
    p: np.ndarray,
    frame: Frame,
    std: Mapping[tuple[int, str], np.ndarray],
    energies: list[float],
    evaluations: list[int],
) -> list[SurfaceFit]:
    _, _, lphi = problem.split(p)
    theta = np.linspace(*problem.grid.angles, problem.grid.nodes)
    profile = {s: (theta, np.exp(lphi[s])) for s in problem.grid.sides}
    fits: dict[int, SurfaceFit] = {}
    for view in problem.views:
        z, r, beam = problem.fields(p, view)
        fit = fits.setdefault(
            view.line,
            SurfaceFit(
                view.geom.x,
                {},
                {},
                {},
                {},
                {},
                {},
                altitude=view.altitude,
                energies=energies,
                evaluations=evaluations,
            ),
        )
        fit.elevation[view.side], fit.reflectivity[view.side] = z, r
        fit.beam[view.side] = beam.phi
        fit.profile[view.side] = profile[view.side]
        fit.looks[view.side] = view.looks
        fit.position[view.side] = frame.to_world(*view.points)
        if (view.line, view.side) in std:
            fit.elevation_std[view.side] = sd = std[(view.line, view.side)]
            if SHRINK_RELIEF:
                knot = problem.grid.z_spacing
                fit.elevation[view.side] = shrink_relief(z, sd, knot, view.geom.dx, view.geom.dy)
    return [fits[k] for k in sorted(fits)]


def elevation_std(
    problem: Problem,
    p: np.ndarray,
    samples: int = LAPLACE_SAMPLES,
    seed: int = 0,
    reflectivity: bool = True,
    cells: Problem | None = None,
) -> dict[tuple[int, str], np.ndarray]:
    """Standard deviation of Z per cell of each view (line, side), Laplace approximation.

    The posterior of the Z and log R knots, Φ held at the fit, is approximated by a Gaussian
    with the Gauss-Newton (Fisher) precision ``H = Jᵀ W J + P``: ``J`` the exact Jacobian of the
    model image wrt both sets of knots (the cast shadows' change included), ``W = L / μ²``
    the Gamma likelihood's Fisher weight per bin and ``P`` the Hessian of the priors (on Z the
    quadratic ones, on log R its edge-preserving roughness at the fit; ``reflectivity=False``
    holds R too). R belongs in it because shading can be explained by either. Samples
    ``H⁻¹ (Jᵀ ε₁ + Σ Dᵀ ε₂)`` with ``ε`` standard normal have exactly that covariance
    (:func:`laplace_draws`), all solved together (:func:`_symmetric_solver`). A cell's standard
    deviation is that of its interpolated Z over the samples; ``cells`` (a problem on the
    same grid, e.g. at full resolution where ``problem`` is pooled) gives the cells.
    """
    h, rhs = laplace_draws(problem, p, samples, seed, reflectivity)
    draws = _symmetric_solver(h, problem.nz)(rhs)[: problem.nz]
    return draws_std(problem if cells is None else cells, draws)


def draws_std(problem: Problem, knots: np.ndarray) -> dict[tuple[int, str], np.ndarray]:
    """Per view (line, side), each cell's standard deviation of Z over drawn Z knots (nz, k).

    The draws are centred on the knots, then interpolated in :data:`UNCERTAINTY_DTYPE` (a
    spread, not a level: float32 is exact to 1e-6 relative here, and twice as fast).
    """
    low = UNCERTAINTY_DTYPE
    centred = (knots - knots.mean(axis=1, keepdims=True)).astype(low)
    scale = 1.0 / max(knots.shape[1] - 1, 1)

    def spread_of(view: View) -> np.ndarray:
        cells = np.asarray(view.bz.astype(low) @ centred)
        spread = np.sqrt(scale * np.einsum("ij,ij->i", cells, cells))
        return spread.astype(np.float64).reshape(view.shape)

    spread = each(spread_of, problem.views)
    return {(v.line, v.side): s for v, s in zip(problem.views, spread, strict=True)}


def laplace_draws(
    problem: Problem, p: np.ndarray, samples: int, seed: int = 0, reflectivity: bool = True
) -> tuple[sparse.csc_matrix, np.ndarray]:
    """The precision ``H`` of :func:`elevation_std` and its draws' right-hand sides.

    ``samples`` columns ``Jᵀ ε₁ + Σ Dᵀ ε₂`` (Fortran order), whose solves ``H⁻¹ b`` are the
    draws.
    """
    rng = np.random.default_rng(seed)
    nz = problem.nz
    nr = problem.nr if reflectivity else 0

    def view_jacobian(view: View) -> sparse.csr_matrix:
        jz, jr, _ = _view_jacobians(problem, p, reflectivity, view)
        return jz if jr is None else sparse.hstack([jz, jr], format="csr")

    jacs = each(view_jacobian, problem.views)
    pad = sparse.csr_matrix
    roots = [sparse.hstack([d, pad((d.shape[0], nr))]).tocsr() for d in _prior_roots(problem)]
    if reflectivity:
        roots += [
            sparse.hstack([pad((d.shape[0], nz)), d]).tocsr()
            for d in _reflectivity_roots(problem, p)
        ]
    # each view's JᵀJ on its own thread, the priors' roots in one product
    grams = each(lambda jac: (jac.T @ jac).tocsc(), jacs)
    h = _summed(grams + ([_gram(roots)] if roots else []))
    # the draws in the order one sample at a time takes them: the views' rows, then each root's
    sizes = [jac.shape[0] for jac in jacs] + [root.shape[0] for root in roots]
    draws = rng.standard_normal((samples, sum(sizes)))
    parts = np.split(draws, np.cumsum(sizes)[:-1], axis=1)
    rhs = np.zeros((nz + nr, samples))
    for matrix, part in zip(jacs + roots, parts, strict=True):
        rhs += np.asarray(matrix.T @ part.T)
    return h, np.asfortranarray(rhs)


def _symmetric_solver(h: sparse.csc_matrix, nz: int) -> Callable[[np.ndarray], np.ndarray]:
    """``B -> H⁻¹ B`` for the symmetric positive definite ``H``, every column of ``B`` at once.

    Z alone: its sparse LU. Z and log R together (their factors fill in beyond SuperLU's memory
    at tens of thousands of knots): conjugate gradients preconditioned by incomplete LU factors
    of the two diagonal blocks (:data:`BLOCK_ILU`; factors and products in
    :data:`UNCERTAINTY_DTYPE`), to a relative residual of 1e-3 per column
    (a sample needs no more: 32 of them estimate a spread to 12 %), all columns in one sweep
    (:func:`_block_cg`).
    """
    from scipy.sparse.linalg import spilu, splu

    n = h.shape[0]
    if n == nz:
        return splu(h, **SYMMETRIC_LU).solve
    low = UNCERTAINTY_DTYPE
    diagonal = (h[:nz, :nz].astype(low).tocsc(), h[nz:, nz:].astype(low).tocsc())
    # SuperLU's factorisation and solves and the sparse products release the GIL: the two
    # blocks, and the product's two halves of rows, side by side
    blocks = each(lambda block: spilu(block, **BLOCK_ILU, **SYMMETRIC_LU), diagonal)

    def precondition(v: np.ndarray) -> np.ndarray:
        parts = ((blocks[0], v[:nz]), (blocks[1], v[nz:]))
        solved = each(lambda part: part[0].solve(part[1].astype(low)), parts)
        return np.concatenate(solved).astype(np.float64)

    h = h.astype(low).tocsr()
    half = h.shape[0] // 2
    rows = (h[:half], h[half:])

    def product(d: np.ndarray) -> np.ndarray:
        d = d.astype(low)
        return np.concatenate(each(lambda part: np.asarray(part @ d), rows)).astype(np.float64)

    return partial(_block_cg, product, precondition, 1e-3, 200)


def _block_cg(
    h: Callable[[np.ndarray], np.ndarray],
    precondition: Callable[[np.ndarray], np.ndarray],
    rtol: float,
    maxiter: int,
    b: np.ndarray,
) -> np.ndarray:
    """Preconditioned conjugate gradients on every column of ``b`` (n × k) side by side.

    Each column runs the textbook recursion (its own step lengths, stopping when its residual
    is below ``rtol`` of its right-hand side, as ``scipy.sparse.linalg.cg``); the columns still
    running share one product ``h(d)`` and one preconditioner call (the LU factors' triangular
    solves take many right-hand sides at once) per iteration.
    """
    x = np.zeros_like(b)
    r = b.copy()
    goal = rtol * np.linalg.norm(b, axis=0)
    z = precondition(r)
    d = z.copy()
    rz = np.einsum("ij,ij->j", r, z)
    live = np.arange(b.shape[1])  # the columns still running; r, d, rz, goal hold only those
    for _ in range(maxiter):
        running = np.linalg.norm(r, axis=0) > goal  # a zero column is solved by 0
        if not running.all():  # drop the finished columns once, not on every iteration
            live, r, d, rz, goal = (
                live[running],
                r[:, running],
                d[:, running],
                rz[running],
                goal[running],
            )
        if live.size == 0:
            break
        hd = h(d)
        alpha = rz / np.einsum("ij,ij->j", d, hd)
        if live.size == x.shape[1]:
            x += alpha * d
        else:
            x[:, live] += alpha * d
        r -= alpha * hd
        z = precondition(r)
        rz_new = np.einsum("ij,ij->j", r, z)
        d = z + (rz_new / rz) * d
        rz = rz_new
    return x


def _reflectivity_roots(problem: Problem, p: np.ndarray) -> list[sparse.csr_matrix]:
    """Square roots of the Hessian of log R's edge-preserving roughness at ``p``."""
    _, rc, _ = problem.split(p)
    ky, kx = problem.kr
    eps = prob.REFLECTIVITY_EDGE
    roots = []
    for axis in (0, 1):
        n = (ky, kx)[axis]
        if n < 2:
            continue
        d1 = sparse.diags([-1.0, 1.0], [0, 1], shape=(n - 1, n))
        eye = sparse.identity((kx, ky)[axis])
        diff = sparse.kron(d1, eye) if axis == 0 else sparse.kron(eye, d1)
        d = diff @ rc.ravel()
        curvature = problem.w_r * 2.0 * eps * eps * eps / (d * d + eps * eps) ** 1.5
        roots.append((sparse.diags(np.sqrt(curvature)) @ diff).tocsr())
    # no root for the gauge (mean log R): with Φ held the data fix R's level, and its rank-one
    # Hessian would make H dense
    return roots


def _prior_roots(problem: Problem) -> list[sparse.csr_matrix]:
    """Square roots ``D`` (``P = Σ DᵀD``) of the Hessians of the quadratic priors on Z knots."""
    ky, kx = problem.kz
    step = problem.grid.z_spacing
    roots = []
    for axis, w in ((0, problem.w_z_along), (1, problem.w_z)):
        n = (ky, kx)[axis]
        if n < 3:
            continue
        d2 = sparse.diags([1.0, -2.0, 1.0], [0, 1, 2], shape=(n - 2, n)) / step**2
        eye = sparse.identity((kx, ky)[axis])
        d = sparse.kron(d2, eye) if axis == 0 else sparse.kron(eye, d2)
        roots.append((math.sqrt(2.0 * w) * d).tocsr())
    relief = problem.relief_weights()
    if relief is not None:
        roots.append(sparse.diags(np.sqrt(2.0 * relief.ravel()), format="csr"))
    for i in problem.anchored.values():
        view = problem.views[i]
        w = 1.0 / (2.0 * problem.anchor_std(view) ** 2)
        known = sparse.diags(np.isfinite(view.altitude).astype(np.float64))
        roots.append(math.sqrt(2.0 * w) * (known @ view.nadir).tocsr())
    return roots


def _jacobians(
    problem: Problem, p: np.ndarray, reflectivity: bool = False
) -> tuple[list[sparse.csr_matrix], list[sparse.csr_matrix]]:
    """Per view, ``sqrt(W) ∂μ/∂(Z knots)`` and (with ``reflectivity``) ``∂μ/∂(log R knots)``.

    ``W = L / μ²`` is the Gamma likelihood's Fisher weight per bin; the Z Jacobian includes the
    beam's change of depression angle and of the cast shadows (:func:`.problem.shade_jacobian`, with
    ``SHADOW_JACOBIAN``); Φ nodes are held.
    """
    parts = each(partial(_view_jacobians, problem, p, reflectivity), problem.views)
    return [jz for jz, _, _ in parts], [jr for _, jr, _ in parts if jr is not None]


def _view_jacobians(
    problem: Problem, p: np.ndarray, reflectivity: bool, view: View, beam_nodes: bool = False
) -> tuple[sparse.csr_matrix, sparse.csr_matrix | None, sparse.csr_matrix | None]:
    """One view's part of :func:`_jacobians`; with ``beam_nodes`` also its Φ part.

    That is ``sqrt(W) ∂μ/∂(log Φ nodes)``, one column per node of every side.
    """
    z, r, beam = problem.fields(p, view)
    shade, occluder, slope = soft_shadow(z, view.geom.x, view.tau)
    mu = forward(r * shade, beam.phi, z, view.geom) + view.floor
    weight = np.where(view.mask, view.looks / (mu * mu), 0.0)
    # the deposit once: each per-cell factor's Jacobian is it times a diagonal
    deposit = deposit_jacobian(weight, np.ones_like(z), z, view.geom)
    through = sparse.diags((r * shade * beam.dz).ravel())  # Z through the beam's angle
    if SHADOW_JACOBIAN and slope.any():  # and through the cast shadows
        through = through + sparse.diags((r * beam.phi).ravel()) @ shade_jacobian(
            occluder, slope, view.geom.x
        )
    per_cell = jacobian_z(weight, r * shade, beam.phi, z, view.geom) + deposit @ through
    jz = (per_cell @ view.bz).tocsr()
    # ∂μ/∂log R and ∂μ/∂log Φ of a cell: its whole return
    whole = deposit @ sparse.diags((r * shade * beam.phi).ravel())
    jr = (whole @ view.br).tocsr() if reflectivity else None
    jphi = (whole @ _node_matrix(problem, view, beam)).tocsr() if beam_nodes else None
    return jz, jr, jphi


def _node_matrix(problem: Problem, view: View, beam: Beam) -> sparse.csr_matrix:
    """(pings·cells) × (every side's Φ nodes): each cell's log Φ from its side's two nodes."""
    n = problem.grid.nodes
    index = beam.index.ravel() + problem.grid.sides.index(view.side) * n
    w = beam.weight.ravel()
    rows = np.arange(index.size)
    return sparse.csr_matrix(
        (np.concatenate([1.0 - w, w]), (np.tile(rows, 2), np.concatenate([index, index + 1]))),
        shape=(index.size, n * len(problem.grid.sides)),
    )


def _fisher_z(problem: Problem, p: np.ndarray) -> sparse.csc_matrix:
    """Gauss-Newton (Fisher) matrix of the objective wrt the Z knots.

    ``Σ_views (J B)ᵀ (J B)`` (:func:`_jacobians`, each view's product on its own thread) plus
    the Hessians of the quadratic priors on Z; the line-profile prior is applied separately
    (:func:`.problem.line_profile`).
    """

    def gram(view: View) -> sparse.csc_matrix:
        jac = _view_jacobians(problem, p, False, view)[0]
        return (jac.T @ jac).tocsc()

    roots = _prior_roots(problem)
    return _summed(each(gram, problem.views) + ([_gram(roots)] if roots else []))


def _fisher_z_beam(
    problem: Problem, p: np.ndarray
) -> tuple[sparse.csc_matrix, sparse.csc_matrix, np.ndarray]:
    """:func:`_fisher_z`, and the Fisher blocks of the log Φ nodes: ``(H_zz, H_zΦ, H_ΦΦ)``.

    ``H_ΦΦ`` includes the Hessians of the priors on log Φ (its curvature, a calibrated shape).
    """

    def blocks(view: View) -> tuple:
        jz, _, jphi = _view_jacobians(problem, p, False, view, beam_nodes=True)
        assert jphi is not None
        return (jz.T @ jz).tocsc(), (jz.T @ jphi).tocsc(), (jphi.T @ jphi).toarray()

    roots = _prior_roots(problem)
    parts = each(blocks, problem.views)
    hzz = _summed([b[0] for b in parts] + ([_gram(roots)] if roots else []))
    hzphi = _summed([b[1] for b in parts])
    hphi = sum(b[2] for b in parts) + problem.beam_prior_hessian()
    return hzz, hzphi, hphi


def _gram(roots: Sequence[sparse.spmatrix]) -> sparse.csc_matrix:
    """``Σ DᵀD`` over ``roots`` (stacked: one product, not one sum per root)."""
    stacked = sparse.vstack(roots, format="csr")
    return (stacked.T @ stacked).tocsc()


def _summed(matrices: Sequence[sparse.spmatrix]) -> sparse.csc_matrix:
    """The sum of sparse matrices of one shape."""
    total = matrices[0].tocsc()
    for m in matrices[1:]:
        total = total + m
    return total.tocsc()


def deposit_jacobian(
    weight: np.ndarray, values: np.ndarray, z: np.ndarray, geom: Geometry
) -> sparse.csr_matrix:
    """``sqrt(w) D diag(values q dx / range_bin)``, (pings·bins) × (pings·cells).

    ``D`` is the model's deposit (:func:`..model.deposit_matrix`), so this is the Jacobian of
    the image wrt any per-cell factor ``f`` of the return ``Φ R q dx / range_bin`` with
    ``values = ∂(Φ R)/∂f``: ``R ∂Φ/∂Z`` for Z through the beam, ``Φ R`` for log R.
    """
    deposit, q = deposit_matrix(z, geom)
    amp = (values * q).ravel() * (geom.dx / geom.range_bin)
    return (sparse.diags(np.sqrt(weight).ravel()) @ deposit @ sparse.diags(amp)).tocsr()


#: The crest offset is measured with the model's surface moved across track so that the ground
#: at these fractions of the altitude, each side, lies under the nadir (None: at the nadir
#: itself). There, 63–73° of depression, the shading shows the relief; beside the nadir it
#: does not, the fitted troughs fill in, and sand waves read 2 cm of crests where the data's
#: tracker read 6 cm (docs/notes/2026-11-29-trust-region.md).
CREST_SHIFTS: tuple[float, ...] | None = (0.3, 0.4, 0.5)
#: ... only in fits whose finest level pools the images at most this much (``finest``,
#: ``invert --coarsen``). Sand waves at ``--coarsen 4`` (the issue's size) scored 0.58 moved
#: against 0.54, and took 18 % longer. At ``--coarsen 2`` it depends on the scene: the bench's
#: 200 pings 0.420 moved against 1.072 (the level 9 cm deep), the issue's size 0.568 against
#: 0.444; kept for the worse failure it prevents.
CREST_SHIFTS_MAX_POOLING = 2


def _shifted(port: np.ndarray, starboard: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Both sides' cells with the nadir moved ``k`` cells to port (to starboard if negative).

    The cells are (pings, ground range outwards); port cell ``j`` takes what lay ``k`` cells
    further out, and the cells beyond either end repeat the end.
    """
    n = port.shape[1]
    full = np.concatenate([starboard[:, ::-1], port], axis=1)
    j = np.arange(n)
    return (
        full[:, np.clip(n + j + k, 0, 2 * n - 1)],
        full[:, np.clip(n - 1 - j + k, 0, 2 * n - 1)],
    )


def model_first_return(
    problem: Problem,
    p: np.ndarray,
    line: int,
    shift: int = 0,
    fields: Mapping[str, tuple[np.ndarray, np.ndarray]] | None = None,
) -> tuple[np.ndarray, np.ndarray] | None:
    """The bottom tracker's altitude on the model's image of one line, and the model's level.

    The image is the model's with the renderer's box bins (``deposit="segment"``), both sides;
    the level per ping is the mean depth below the transducer over the nadir's fold (ground
    within ``√(2 h Δ)`` of nadir, where the slant range stays within one bin of the altitude
    h). With ``shift`` the model's Z and R are first moved that many cells across track
    (:func:`_shifted`; the line's port and starboard views). ``fields``: each side's Z and R
    at ``p`` where the caller has them already. None where the tracker finds no return.
    """
    from ..bottom import track_bottom

    views = [v for v in problem.views if v.line == line]
    sides, depths = {}, []
    lead = views[0]
    fold = math.sqrt(2.0 * float(np.nanmedian(lead.altitude)) * lead.geom.range_bin)
    if fields is None:
        fields = {view.side: problem.fields(p, view)[:2] for view in views}
    if shift:
        zp, zs = _shifted(fields["port"][0], fields["starboard"][0], shift)
        rp, rs = _shifted(fields["port"][1], fields["starboard"][1], shift)
        fields = {"port": (zp, rp), "starboard": (zs, rs)}
    _, _, lphi = problem.split(p)
    for view in views:
        z, r = fields[view.side]
        beam = problem.beam(view, lphi[view.side], z)
        shade = soft_shadow(z, view.geom.x, view.tau)[0]
        g = view.geom
        boxes = replace(g, deposit="segment")
        sides[view.side] = forward(r * shade, beam.phi, z, boxes)
        depths.append(-z[:, g.x <= fold])
    if not any(d.size for d in depths):
        return None
    try:
        seen = track_bottom(sides, lead.geom.range_bin).altitude
    except SonarRasterError:
        return None
    return seen, np.concatenate(depths, axis=1).mean(axis=1)


def _track_model(problem: Problem, p: np.ndarray, shifts: tuple[float, ...] | None = None) -> None:
    """Set each line's anchor offset (:attr:`.problem.Problem.anchor_offset`).

    The first return reads a rough seabed's crests, not its level. The offset is how far the
    tracker on the model's own image reads above the model's level (:func:`model_first_return`,
    the median over pings; with ``shifts``, measured with the nadir moved to where the shading
    shows the relief, :func:`_shifted_gap`), times how much of that the data confirm: the
    regression slope, over pings, of the data's first-return height on the model's (heights in
    the lines' common datum, so the sonar's heave drops out where the transducer height is
    known), clipped to [0, 1]. Where the model's relief near nadir is real its crests come and
    go with the data's; where it is the fit's noise, they do not, and the offset vanishes.
    """
    for line, lead in problem.anchored.items():
        found = model_first_return(problem, p, line)
        if found is None:
            continue
        seen, depth = found
        altitude, height = problem.views[lead].altitude, problem.views[lead].height
        ok = np.isfinite(seen) & np.isfinite(altitude)
        if ok.sum() < 3:
            continue
        # the first returns' heights in the common datum: the sonar's own heave drops out
        a, b = (height - seen)[ok], (height - altitude)[ok]
        # a centred is enough for the slope; b less its median stays exactly zero where the
        # data's heights are all equal (less its mean, rounding left 1e-28 of trust)
        a, b = a - a.mean(), b - np.median(b)
        norm = float(np.sum(a * a))
        trust = min(max(float(np.sum(a * b)) / norm, 0.0), 1.0) if norm > 0 else 0.0
        gap = float(np.median((seen - depth)[ok]))
        if shifts:
            gap = _shifted_gap(problem, p, line, float(np.nanmedian(altitude)), gap, shifts)
        problem.anchor_offset[line] = trust * gap


def _shifted_gap(
    problem: Problem,
    p: np.ndarray,
    line: int,
    altitude: float,
    gap: float,
    shifts: Sequence[float],
) -> float:
    """The crest gap of :func:`_track_model` with the nadir moved across track.

    The mean, over ``shifts`` (fractions of the altitude) on either side, of each move's median
    over pings; ``gap`` (the nadir's own) where the line lacks a side or every move falls off
    the swath.
    """
    views = [v for v in problem.views if v.line == line]
    if {v.side for v in views} != {"port", "starboard"} or views[0].shape != views[1].shape:
        return gap
    cells = views[0].shape[1]
    fields = {view.side: problem.fields(p, view)[:2] for view in views}  # once for every move
    gaps = []
    for fraction in shifts:
        k = round(fraction * altitude / float(views[0].geom.dx))
        if not 0 < k < cells // 2:
            continue
        for sign in (1, -1):
            found = model_first_return(problem, p, line, sign * k, fields)
            if found is not None and np.isfinite(found[0]).sum() >= 3:
                seen, depth = found
                gaps.append(float(np.nanmedian(seen - depth)))
    return float(np.mean(gaps)) if gaps else gap


def _preconditioner(lhs: sparse.csc_matrix) -> Callable[[np.ndarray], np.ndarray]:
    """``v -> M⁻¹ v`` for the symmetric positive definite Gauss-Newton matrix ``lhs``.

    Its complete sparse LU up to :data:`AMG_KNOTS` unknowns, one V-cycle of smoothed
    aggregation multigrid beyond (linear in the knots, in time and memory).
    """
    from scipy.sparse.linalg import splu

    if lhs.shape[0] <= AMG_KNOTS:
        return splu(lhs, **SYMMETRIC_LU).solve
    import pyamg

    hierarchy = pyamg.smoothed_aggregation_solver(lhs.tocsr(), **AMG)
    return hierarchy.aspreconditioner(cycle="V").matvec


def _deflated(
    problem: Problem, lhs: sparse.csc_matrix, precondition: Callable[[np.ndarray], np.ndarray]
) -> Callable[[np.ndarray], np.ndarray]:
    """``precondition`` (for ``lhs``) made one for the Gauss-Newton matrix with the line prior.

    The line-profile prior adds ``H`` of low rank but large to ``lhs``: a preconditioner for
    ``lhs`` alone leaves the conjugate gradients a few tens of outlying eigenvalues to find,
    one iteration each. On its strongest directions ``Q`` (:meth:`.Problem.line_subspace`) the
    system is solved exactly, the rest preconditioned as before (the balancing preconditioner
    ``M⁻¹ = P + (I − P A) M₀⁻¹ (I − A P)``, ``P = Q (Qᵀ A Q)⁻¹ Qᵀ``, ``A = lhs + H``;
    symmetric positive definite when ``M₀`` is). ``A Q`` is formed once per step (``H Q`` once
    per set of objects), so applying ``M⁻¹`` takes one ``M₀⁻¹`` and no product with ``A``.
    """
    from scipy.linalg import cho_factor, cho_solve

    if problem.w_line <= 0:
        return precondition
    q, hq = problem.line_subspace()
    if q.shape[1] == 0:
        return precondition
    aq = np.asarray(lhs @ q) + hq  # A Q, so that applying M⁻¹ takes no product with A
    coarse = cho_factor(q.T @ aq)

    def apply(r: np.ndarray) -> np.ndarray:
        c = cho_solve(coarse, q.T @ r)
        rest = precondition(r - aq @ c)
        return q @ (c - cho_solve(coarse, aq.T @ rest)) + rest

    return apply


def _schur(
    problem: Problem,
    lhs: sparse.csc_matrix,
    hzphi: sparse.csc_matrix,
    hphi: np.ndarray,
    gz: np.ndarray,
    gphi: np.ndarray,
) -> tuple[Callable[[np.ndarray], np.ndarray], np.ndarray, Callable[[np.ndarray], np.ndarray]]:
    """The joint Z-Φ Gauss-Newton system with the log Φ nodes eliminated.

    ``[[A, U], [Uᵀ, C]] [δz, δφ] = −[g_z, g_φ]`` (``A`` the Z matrix with the line prior,
    ``U = H_zΦ``, ``C = H_ΦΦ``: a few hundred nodes, so ``C`` is factored directly) becomes
    ``S δz = −(g_z − U C⁻¹ g_φ)`` with ``S = A − U C⁻¹ Uᵀ``, then ``δφ = −C⁻¹ (g_φ + Uᵀ δz)``.
    Returns the product with ``S``, the right-hand side and ``δz -> δφ``. ``A``'s own
    preconditioner serves ``S`` as well: a Woodbury correction for the low-rank term (one
    preconditioner application per node) changed neither the steps nor the result on the
    default render and doubled the fit's time (docs/notes/2026-11-29-joint-beam.md).
    """
    from scipy.linalg import cho_factor, cho_solve

    c = cho_factor(hphi)

    def matvec(v: np.ndarray) -> np.ndarray:
        return _gn_matvec(problem, lhs, v) - hzphi @ cho_solve(c, hzphi.T @ v)

    rhs = -(gz - hzphi @ cho_solve(c, gphi))
    return matvec, rhs, lambda dz: -cho_solve(c, gphi + hzphi.T @ dz)


def _model_curvature(
    problem: Problem,
    lhs: sparse.csc_matrix,
    hzphi: sparse.csc_matrix,
    hphi: np.ndarray,
    dz: np.ndarray,
    dphi: np.ndarray,
) -> float:
    """The Gauss-Newton model's curvature along the joint step ``s = (δz, δφ)``.

    ``sᵀ M s`` with ``M`` the joint system's matrix (:func:`_schur`'s ``[[A, U], [Uᵀ, C]]``).
    """
    return float(
        dz @ _gn_matvec(problem, lhs, dz) + 2.0 * dz @ (hzphi @ dphi) + dphi @ (hphi @ dphi)
    )


def _trust_radius(radius: float, rho: float, backtracked: bool, capped: bool) -> float:
    """The joint step's next trust radius, in range bins.

    ``rho`` is the step's decrease of E over the model's predicted decrease (0 for a rejected
    step). The radius halves, down to a quarter of ``JOINT_STEP_BINS``, where the model was
    poor or the step backtracked, and doubles where it bound the step and the model was good
    (``JOINT_TRUST_RATIO``).
    """
    low, high = JOINT_TRUST_RATIO
    if rho < low or backtracked:
        return max(0.5 * radius, 0.25 * JOINT_STEP_BINS)
    if rho > high and capped:
        return 2.0 * radius
    return radius


def _gn_matvec(problem: Problem, lhs: sparse.csc_matrix, v: np.ndarray) -> np.ndarray:
    out = np.asarray(lhs @ v)
    if problem.w_line > 0:
        out = out + line_profile(problem, v)[1]
    return out


def _gauss_newton(
    problem: Problem,
    p: np.ndarray,
    steps: int,
    report: Callable[[int, int, float], None] | None = None,
    joint: bool = False,
    shifts: tuple[float, ...] | None = None,
) -> tuple:
    """Alternate Gauss-Newton steps on the Z knots and log Φ nodes with L-BFGS on R and Φ.

    Each step solves ``(H + H_line + μ D) δ = −g`` for Z and Φ together (``joint``; Φ's few
    nodes eliminated, :func:`_schur`, and no Z knot moving by more than a trust radius,
    :func:`_trust_radius`; else for Z with Φ held) to ``GAUSS_NEWTON_RTOL`` by
    conjugate gradients preconditioned with the sparse LU factors of Z's ``H + μ D``, or a
    multigrid V-cycle on it beyond ``AMG_KNOTS`` knots (D its diagonal; μ shrinks after a
    good step and grows after a bad one), deflated on the line prior's strongest directions
    (:func:`_deflated`), then backtracks on the full objective, which never rises within a
    step (with ``CREST_OFFSET`` the anchor's crest offset is measured anew before each step,
    at the nadir moved by ``shifts`` where given, :func:`_shifted_gap`).
    R and Φ then take L-BFGS steps on the objective with Z held (:meth:`.Problem.held_z`).
    """
    from scipy.sparse.linalg import LinearOperator, cg

    nz = problem.nz
    free = np.zeros(problem.size, bool)
    free[nz:] = True
    if CREST_OFFSET:
        _track_model(problem, p, shifts)
    value, grad = problem(p)
    count, damping = 1, 1e-3
    phis = slice(nz + problem.nr, problem.size)
    radius = JOINT_STEP_BINS
    for k in range(int(steps)):
        if joint:
            h, hzphi, hphi = _fisher_z_beam(problem, p)
        else:
            h = _fisher_z(problem, p)
        diag = h.diagonal()
        lhs = (h + sparse.diags(damping * diag + 1e-12 * diag.mean())).tocsc()
        matvec: Callable[[np.ndarray], np.ndarray] = partial(_gn_matvec, problem, lhs)
        rhs, back = -grad[:nz], None
        if joint:
            hphi = hphi + np.diag(damping * np.diag(hphi) + 1e-12 * np.mean(np.diag(hphi)))
            try:
                matvec, rhs, back = _schur(problem, lhs, hzphi, hphi, grad[:nz], grad[phis])
            except np.linalg.LinAlgError:  # Φ's block not positive definite: Z alone
                pass
        op = LinearOperator((nz, nz), matvec=matvec)
        pre = LinearOperator((nz, nz), matvec=_deflated(problem, lhs, _preconditioner(lhs)))
        step, _ = cg(op, rhs, M=pre, maxiter=30, rtol=GAUSS_NEWTON_RTOL)
        step_phi = None if back is None else back(step)
        value_before, capped = value, False
        if step_phi is not None:  # the joint step's trust region
            biggest = float(np.max(np.abs(step))) if step.size else 0.0
            cap = radius * problem.views[0].geom.range_bin
            if biggest > cap:
                step, step_phi = step * (cap / biggest), step_phi * (cap / biggest)
                capped = True
            slope = float(grad[:nz] @ step + grad[phis] @ step_phi)
            curve = _model_curvature(problem, lhs, hzphi, hphi, step, step_phi)
        accepted = False
        for t in (1.0, 0.5, 0.25, 0.125):
            q = p.copy()
            q[:nz] += t * step
            if step_phi is not None:
                q[phis] += t * step_phi
            trial, g_trial = problem(q)
            count += 1
            if trial < value:
                p, value, grad, accepted = q, trial, g_trial, True
                break
        if step_phi is not None:
            predicted = -(t * slope + 0.5 * t * t * curve)
            rho = (value_before - value) / predicted if accepted and predicted > 0 else 0.0
            radius = _trust_radius(radius, rho, t < 1.0, capped)
        damping = damping * 0.3 if accepted else damping * 10.0
        p, value, n = _minimise(problem, p, INNER_ITERATIONS, free, problem.held_z(p))
        count += n
        if CREST_OFFSET and k + 1 < steps:  # the next step's anchor, at the surface it starts from
            _track_model(problem, p, shifts)
            value, grad = problem(p)
        else:
            grad = problem(p)[1]
        if report is not None:
            report(k + 1, int(steps), value)
    return p, value, count
