"""Coherent model (the seed's Eq. 10): point scatterers, a transmit pulse and a matched filter.

Mesh surfaces are sampled into point scatterers (facets of area a² about ``spacing`` apart,
jittered; see :mod:`.scatter`). Per ping, a visible scatterer k at distance
``r_k`` from the transducer contributes the complex baseband amplitude

``c_k = (a_k² / λ) · sqrt(R_k · Φ(α_k − axis) · Φ_h(ψ_k)) · L(n̂_k · r̂_k) / r_k² ·
exp(−4πi r_k / λ)``

delayed by ``2 r_k / c``, where λ is the centre wavelength, ``Φ`` the sonar's two-way vertical
beam pattern (an intensity gain, so the amplitude carries its square root), ``Φ_h`` the two-way
horizontal beam (:class:`HorizontalBeam`), and ``L`` the scattering law: ``"lambert"`` (default,
``L = sqrt(cos θ)``) gives a mean speckle intensity ``Σ Φ R cos θ dA`` per bin, the same integral
the raster and reference renderers compute, so the models compare pixel by pixel; ``"eq10"``
(``L = cos θ``) is the seed's rigid Kirchhoff obliquity (mean intensity ∝ cos² θ). R is the
intensity reflectivity of Eq. 11, hence ``sqrt(R)`` in the amplitude. The echo is matched
filtered (pulse compression, :class:`Pulse`), its envelope power ``|y|²`` is averaged over each
range bin's samples (an integral per bin, as the raster image is), and spherical spreading is
kept (intensity ∝ 1/r⁴; no TVG): :func:`to_raster_units` removes it for comparisons.

Geometry matches :mod:`..reference`: the trajectory is split into the same straight
segments, each with its frame (the shear map of a crabbed or pitched segment: travel of the fan
a point lies in, and its place in that fan); a scatterer's side is the sign of its across-track
coordinate, its visibility is tested at its facet centroid from the track point whose fan holds
it (the GL raster's first-hit range maps, :mod:`.visibility`, or one embree ray), and image bins
are ``[k, k+1) · range_bin`` of slant range. The echo uses the exact distance from each ping's
position (in the fan's orthonormal frame), so phases are right, and ``Φ_h`` the direction cosine
on the fan's normal (the vehicle's fore axis).

Scatterers are generated per block of pings, only inside the block's reach (the horizontal
beam's along-track footprint at the maximum range), in chunks of ``chunk``; those inside no
ping's beam are dropped before the visibility test; the terms of ``_TERM_BATCH`` scatterers at a
time are computed (:func:`_terms`) and deposited. Memory is bounded by the chunk size and the
block's fine delay grid (see ``peak_memory_bytes`` in the metadata).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..._budget import usable_cores
from ..._checks import non_negative, positive
from ..._progress import Estimate, announce, check_job, progress_bar
from ...errors import SonarRasterError
from ...image import SonarImage
from ...scene import Scene
from ...sonar import SIDES, Sonar
from ...trajectory import Trajectory, heading_axes
from .echo import KERNEL_TAPS, EchoGrid
from .pulse import Pulse
from .scatter import (
    JITTER_CLIP,
    Scatterers,
    ScatterSurface,
    cos_sin,
    generate,
    generate_runs,
    scatter_surface,
)

__all__ = [
    "Echo",
    "HorizontalBeam",
    "PointScatterers",
    "Pulse",
    "ping_echo",
    "render_coherent",
    "to_raster_units",
]

log = logging.getLogger(__name__)

METHODS = ("fast", "direct")
LAWS = ("lambert", "eq10")
VISIBILITY = ("depth", "rays")
#: "compiled": the per-scatterer loop of :mod:`.compiled` (numba); "numpy": array passes (the
#: earlier path, kept as the independent check); "auto": compiled where it applies (the fast
#: method with range-map visibility), else numpy.
ENGINES = ("auto", "compiled", "numpy")
#: Default scatterer spacing on the seabed: this many wavelengths, but no coarser than
#: ``_SEABED_BINS`` range bins (two scatterers per bin each way); random-phase seabeds keep their
#: mean level at such spacings (tools/bench_accuracy.py; docs/coherent.md).
SEABED_SPACING = 4.0
_SEABED_BINS = 0.5
#: Travel between the rows of the visibility range maps, in range bins.
_MAP_ROW_BINS = 1.0
#: Measured cost on the 2-core CI machine (tools/bench_coherent.py, bare barrel): seconds per
#: scatterer generated in reach, and per estimated scatterer-ping term (the estimate counts
#: about twice the terms made; 11.7 s estimated for 12.4 s measured at load 5.8).
_COST_SCATTERER = 0.15e-6
_COST_PAIR = 0.05e-6
#: The compiled engine's speed over those (tools/bench_coherent.py, unloaded, both cores: the
#: barrel's 20 pings estimated 1.4 s for 1.2 s measured; 3.3 s before the SIMD loops).
_COMPILED_SPEEDUP = 8.0
#: Scatterers beyond ``max_range`` + this many range bins are left out (their compressed main
#: lobes still reach the last bins).
RANGE_MARGIN_BINS = 3.0
#: Scatterers whose terms are computed and deposited at once (their arrays stay in cache:
#: 1.3-1.4x faster than 65536 at a time).
_TERM_BATCH = 8192
#: The compiled engine clips runs in chunks of this many ``chunk``s and hands them to the
#: threads in this many parts per thread (a thread that finishes early takes the next part).
_RUN_CHUNKS = 4
#: Subdivision rows the compiled engine clips at once (the first chunk comes sooner).
_RUN_ROW_BLOCK = 1 << 15
#: Fine-grid bytes one ping block may hold (sets the pings per block).
_BLOCK_BYTES = 96 << 20
#: Argument of ``np.sinc`` where ``sinc⁴ = 1/2`` (half-power point of a two-way sinc pattern).
_SINC4_HALF = 0.31911
#: Direction of travel in fan components without crab or pitch (see _travel).
_LEVEL = np.array([1.0, 0.0, 0.0])
#: Bytes per scatterer and per (scatterer, ping) pair in flight (for the memory estimate).
_SCATTERER_BYTES = 400
_PAIR_BYTES = (4 * KERNEL_TAPS + 24) * 8


@dataclass(frozen=True)
class HorizontalBeam:
    """Two-way along-track beam pattern ``Φ_h(u)`` of the direction cosine ``u = sin ψ``.

    ψ is the angle between the direction to the scatterer and the ping's across-track plane.

    Attributes
    ----------
    width : float
        Full width at half power of the two-way pattern, radians (small-angle: in ``u``).
    kind : {"gaussian", "sinc"}
        ``exp(−4 ln 2 (u / width)²)``, cut at ``|u| = 2 width`` (gain 1.5e-5); or a uniform
        line aperture, ``sinc⁴(x₀ 2u / width)`` with ``sinc⁴(x₀) = 1/2``, cut at its fourth null.
    """

    width: float
    kind: str = "gaussian"

    def __post_init__(self) -> None:
        if not (isinstance(self.width, (int, float)) and 0 < self.width < 1):
            raise SonarRasterError(
                f"horizontal beam width must be in (0, 1) rad, got {self.width!r}"
            )
        if self.kind not in ("gaussian", "sinc"):
            raise SonarRasterError(
                f"horizontal beam kind must be gaussian or sinc, got {self.kind!r}"
            )

    @classmethod
    def for_track(cls, sonar: Sonar, trajectory: Trajectory) -> HorizontalBeam:
        """Default: a Gaussian whose half-power footprint at mid range is one ping spacing."""
        return cls(min(trajectory.typical_spacing / (0.5 * sonar.max_range), 0.5))

    @property
    def cutoff(self) -> float:
        """Largest ``|u|`` with a non-zero gain."""
        if self.kind == "gaussian":
            return min(2.0 * self.width, 0.99)
        return min(4.0 * self.width / (2.0 * _SINC4_HALF), 0.99)

    def __call__(self, u: np.ndarray) -> np.ndarray:
        """Two-way intensity gain at direction cosines ``u`` (any shape)."""
        u = np.asarray(u, dtype=np.float64)
        if self.kind == "gaussian":
            g = np.exp(-4.0 * math.log(2.0) * np.minimum((u / self.width) ** 2, 16.0))
        else:
            g = np.sinc(_SINC4_HALF * 2.0 * u / self.width) ** 4
        return np.where(np.abs(u) <= self.cutoff, g, 0.0)

    def footprint(self, slant_range: np.ndarray | float) -> np.ndarray:
        """Along-track integral ``∫ Φ_h dy`` at a slant range, metres (small-angle)."""
        r = np.asarray(slant_range, dtype=np.float64)
        if self.kind == "gaussian":
            return r * self.width * math.sqrt(math.pi / (4.0 * math.log(2.0)))
        return r * self.width / (2.0 * _SINC4_HALF) * (2.0 / 3.0)

    def to_dict(self) -> dict:
        """Plain description for metadata."""
        return {"width_rad": self.width, "kind": self.kind}


@dataclass(frozen=True)
class PointScatterers:
    """Explicit point scatterers (world metres), e.g. point targets for :func:`ping_echo`.

    Attributes
    ----------
    positions : ndarray, shape (k, 3)
        Positions, metres.
    normals : ndarray, shape (k, 3)
        Unit normals.
    areas : ndarray, shape (k,)
        Facet areas a², m².
    reflectivity : ndarray, shape (k,)
        R (intensity reflectivity).
    """

    positions: np.ndarray
    normals: np.ndarray
    areas: np.ndarray
    reflectivity: np.ndarray = field(default_factory=lambda: np.ones(1))

    def __post_init__(self) -> None:
        p = np.asarray(self.positions, dtype=np.float64).reshape(-1, 3)
        n = np.broadcast_to(np.asarray(self.normals, dtype=np.float64), p.shape).copy()
        a = np.broadcast_to(np.asarray(self.areas, dtype=np.float64), p.shape[:1]).copy()
        r = np.broadcast_to(np.asarray(self.reflectivity, dtype=np.float64), p.shape[:1]).copy()
        norm = np.linalg.norm(n, axis=1)
        if not (np.all(np.isfinite(p)) and np.all(norm > 0) and np.all(a >= 0) and np.all(r >= 0)):
            raise SonarRasterError(
                "point scatterers need finite positions, non-zero normals, "
                "and areas and reflectivities >= 0"
            )
        object.__setattr__(self, "positions", p)
        object.__setattr__(self, "normals", n / norm[:, None])
        object.__setattr__(self, "areas", a)
        object.__setattr__(self, "reflectivity", r)


@dataclass(frozen=True)
class Echo:
    """One ping's compressed echo per side.

    Attributes
    ----------
    ranges : ndarray, shape (n_bins * M,)
        Slant range of each fine sample (bin midpoints of M equal parts per bin), metres.
    signal : dict of str to ndarray, shape (n_bins * M,), complex128
        Matched-filter output (complex baseband) per side.
    intensity : dict of str to ndarray, shape (n_bins,)
        ``|signal|²`` averaged over each range bin, as in the image.
    """

    ranges: np.ndarray
    signal: dict[str, np.ndarray]
    intensity: dict[str, np.ndarray]


@dataclass(frozen=True)
class _Model:
    """What every (scatterer, ping) pair needs."""

    sonar: Sonar
    beam_h: HorizontalBeam | None
    law: str
    wavelength: float
    r_limit: float
    # With random phases (jitter > 0) echo energies add, so a facet's energy must grow with its
    # area, not its area squared: amplitudes use sqrt(a_k * area_ref), area_ref = spacing².
    # 0 keeps Eq. 10's a_k (smooth, coherent surfaces).
    area_ref: float = 0.0

    @property
    def u_cut(self) -> float:
        return self.beam_h.cutoff if self.beam_h is not None else 1.0


def render_coherent(
    scene: Scene,
    sonar: Sonar,
    trajectory: Trajectory,
    *,
    pulse: Pulse | None = None,
    spacing_wavelengths: float = 0.25,
    seed: int = 0,
    method: str = "fast",
    chunk: int = 1 << 16,
    horizontal_beam: HorizontalBeam | None = None,
    jitter_wavelengths: float = 0.5,
    scattering: str = "lambert",
    samples_per_bin: int | None = None,
    progress: bool = False,
    seabed_spacing_wavelengths: float | None = None,
    visibility: str = "depth",
    backend: str | None = None,
    force: bool = False,
    engine: str = "auto",
) -> SonarImage:
    """Render raw side-scan intensity with the coherent point-scatterer model (Eq. 10).

    Parameters
    ----------
    scene, sonar, trajectory
        As for :func:`sonar_raster.rendering.reference.render_reference`.
    pulse : Pulse, optional
        Transmit pulse; default :meth:`Pulse.for_range_bin` (a Taylor-weighted chirp whose
        ``c / (2B)`` is one range bin).
    spacing_wavelengths : float
        Scatterer spacing s in wavelengths (default 1/4, the seed's sub-wavelength sampling).
        Coarser spacing is faster (cost ∝ 1/s²) and keeps the mean level of a rough surface in
        raster units, but smooth surfaces then alias (their coherent sums need s <= λ/4).
    seed : int
        Seed of the position jitter (a pure function of seed, face and facet).
    method : {"fast", "direct"}
        "fast": deposit on a fine delay grid and one FFT convolution per ping; "direct": the
        frequency-domain sum of Eq. 10 at every in-band frequency (exact; tiny scenes only).
    chunk : int
        Scatterers per vectorised chunk (memory ~1.5 kB each); results do not depend on it.
    horizontal_beam : HorizontalBeam, optional
        Along-track beam; default :meth:`HorizontalBeam.for_track`.
    jitter_wavelengths : float
        Rms scatterer displacement per axis in wavelengths (isotropic Gaussian, truncated at 4σ).
        The default 1/2 makes the two-way phases uniformly random at every incidence (fully
        developed speckle on every surface); 0 keeps scatterers on their facets (smooth,
        specular surfaces).
    scattering : {"lambert", "eq10"}
        Scattering law of the amplitude (module docstring).
    samples_per_bin : int, optional
        Fine delay samples per range bin (default: four times the band's Nyquist rate, >= 4).
    progress : bool
        Print the job's estimate (scatterers, rays, time) and show a progress bar with ETA.
    seabed_spacing_wavelengths : float, optional
        Scatterer spacing on the seabed (faces of parts named "seabed"), in wavelengths;
        default ``SEABED_SPACING`` (4) wavelengths or half a range bin, whichever is finer,
        and never finer than ``spacing_wavelengths``. Random-phase seabeds keep their
        mean level at coarse spacing (``tools/bench_accuracy.py``); objects keep
        ``spacing_wavelengths``.
    visibility : {"depth", "rays"}
        "depth": from the GL raster's first-hit range maps (:mod:`.visibility`; no ray caster
        needed); "rays": one embree (or trimesh) ray per scatterer, the earlier path.
    backend : {"egl", "osmesa"}, optional
        GL backend of the range maps.
    force : bool
        Run even when the estimate exceeds an hour or the machine's memory.
    engine : {"auto", "compiled", "numpy"}
        "compiled": compiled loops over buffers of facets (:mod:`.compiled`; needs
        ``method="fast"`` and ``visibility="depth"``), "numpy": array passes; "auto" (default):
        compiled where it applies. The two give the same image to ~1e-6.

    Returns
    -------
    SonarImage
        float32 (pings, ``sonar.n_bins``) per side: bin-averaged matched-filter envelope power,
        with spreading (∝ r⁻⁴), in Eq. 10 units (see :func:`to_raster_units`). ``metadata``:
        renderer "coherent", settings, ``n_scatterers`` (inside reach, summed over ping blocks),
        ``n_rays``, ``n_visible`` (visible among those inside some ping's beam), ``n_pairs``
        (scatterer-ping terms), ``facet_area_m2``, ``ping_width_m`` (trajectory spacing times
        the fan's mean advance per metre of travel), ``peak_memory_bytes`` (estimate),
        ``time_s``.

    Raises
    ------
    TypeError
        If an argument has the wrong type.
    SonarRasterError
        On an invalid setting, when no ray caster is available (``visibility="rays"``), when
        the vehicle crabs or pitches more than the horizontal beam allows (its reach along
        travel would be unbounded), or when the job is estimated over an hour or over the
        machine's memory (unless ``force``).
    """
    from ..fan import check_inputs, segment_frame

    check_inputs(scene, sonar, trajectory)
    scene = scene.with_back_faces()  # open sheets scatter from both sides, as in GL
    pulse = Pulse.for_range_bin(sonar.range_bin, sonar.sound_speed) if pulse is None else pulse
    beam_h = (
        HorizontalBeam.for_track(sonar, trajectory) if horizontal_beam is None else horizontal_beam
    )
    _check_settings(sonar, pulse, beam_h, method, scattering)
    if visibility not in VISIBILITY:
        raise SonarRasterError(f"visibility must be one of {VISIBILITY}, got {visibility!r}")
    engine = _engine(engine, method, visibility)
    spacing = positive("spacing_wavelengths", spacing_wavelengths) * sonar.wavelength
    if seabed_spacing_wavelengths is None:
        coarse = min(SEABED_SPACING * sonar.wavelength, _SEABED_BINS * sonar.range_bin)
        seabed_spacing = max(coarse, spacing)
    else:
        seabed_spacing = (
            positive("seabed_spacing_wavelengths", seabed_spacing_wavelengths) * sonar.wavelength
        )
    jitter = non_negative("jitter_wavelengths", jitter_wavelengths) * sonar.wavelength
    if not (isinstance(chunk, (int, np.integer)) and chunk >= 1):
        raise SonarRasterError(f"chunk must be a positive integer, got {chunk!r}")
    start = time.perf_counter()
    grid = _grid(sonar, pulse, samples_per_bin)
    local = scene.bounds.mean(axis=0)
    surface = scatter_surface(scene, local, face_spacing(scene, spacing, seabed_spacing))
    sides = tuple(s for s in SIDES if s in sonar.sides)
    work = _Work(
        surface=surface,
        grid=grid,
        model=replace(
            _model(sonar, beam_h, scattering), area_ref=spacing**2 if jitter > 0 else 0.0
        ),
        sides=sides,
        jitter=jitter,
        seed=int(seed),
        chunk=int(chunk),
        method=method,
        visibility=visibility,
        engine=engine,
    )
    out = {side: np.zeros((trajectory.n_pings, sonar.n_bins)) for side in sides}
    stats = _Stats()
    block = max(1, _BLOCK_BYTES // grid.nbytes(len(sides)))
    blocks = []
    for segment in trajectory.segments(sonar.range_bin / 4.0):
        frame = segment_frame(segment, trajectory, local, spacing)
        travel = _travel(frame)
        sl = slice(segment.first, segment.first + segment.count)
        pings = (trajectory.positions[sl] - local - frame.origin) @ frame.axes.T
        for j0 in range(0, segment.count, block):
            j1 = min(segment.count, j0 + block)
            bounds, off = _block_bounds(work.model, pings[j0:j1], sides, jitter, travel)
            blocks.append(
                _Block(
                    segment,
                    frame,
                    segment.first + j0,
                    pings[j0:j1],
                    frame.roll[j0:j1],
                    bounds,
                    off,
                    travel,
                )
            )
    estimate = _estimate(work, blocks, trajectory, block)
    peak = _memory_estimate(surface, grid, len(sides), block, int(chunk), work.model, trajectory)
    if engine == "compiled":  # one more accumulator per extra thread
        peak += (_threads() - 1) * block * len(sides) * grid.n * 16
    estimate = estimate.with_memory(peak)
    check_job(
        estimate,
        lower="raise the scatterer spacing (--scatterer-spacing, now "
        f"{float(spacing_wavelengths):g} wavelengths on objects), or lower --pings",
        force=force,
    )
    if progress:
        announce(estimate)
    casters: dict[str, Any] = {"backend": backend}
    try:
        with progress_bar(estimate.work, "coherent", progress) as bar:
            for item in blocks:
                power = _render_block(work, item, scene, sonar, local, casters, stats)
                for slot, side in enumerate(sides):
                    out[side][item.first : item.first + len(item.pings)] = power[:, slot]
                bar.update(item.work)
    finally:
        if "gl" in casters:
            casters["gl"].release()
    elapsed = time.perf_counter() - start
    log.info(
        "coherent: %d scatterers, %d visible, %d pairs in %.2f s (%.3g scatterers/s)",
        stats.scatterers,
        stats.visible,
        stats.pairs,
        elapsed,
        stats.scatterers / max(elapsed, 1e-9),
    )
    metadata = {
        "renderer": "coherent",
        "method": method,
        "pulse": pulse.to_dict(),
        "horizontal_beam": beam_h.to_dict(),
        "scattering": scattering,
        "spacing_wavelengths": float(spacing_wavelengths),
        "spacing_m": spacing,
        "jitter_wavelengths": float(jitter_wavelengths),
        "seed": int(seed),
        "chunk": int(chunk),
        "wavelength_m": sonar.wavelength,
        "samples_per_bin": grid.samples_per_bin,
        # the fan advances a_f = along·fore per metre of travel (crab, pitch): the raster's
        # ping sweeps a slab w a_f thick, the coherent beam one ∫Φ_h thick (to_raster_units)
        "ping_width_m": trajectory.typical_spacing * _mean_advance(blocks),
        # The a² that to_raster_units divides by: spacing² for random-phase scatterers.
        "facet_area_m2": work.model.area_ref or stats.facet_area(),
        "n_scatterers": stats.scatterers,
        "n_rays": stats.rays,
        "n_visible": stats.visible,
        "n_pairs": stats.pairs,
        "peak_memory_bytes": peak,
        "visibility": visibility,
        "engine": engine,
        "seabed_spacing_m": seabed_spacing,
        "estimate": estimate.to_dict(),
        "time_s": elapsed,
        "units": "Eq. 10 intensity |sum a^2/lambda ...|^2 with 1/r^4 spreading (to_raster_units)",
    }
    images = {side: a.astype(np.float32) for side, a in out.items()}
    return SonarImage(sides=images, sonar=sonar, metadata=metadata)


@dataclass
class _Stats:
    scatterers: int = 0
    rays: int = 0
    visible: int = 0
    pairs: int = 0
    area: float = 0.0
    area2: float = 0.0

    def facet_area(self) -> float:
        """Area-weighted mean facet area of the visible scatterers, m² (0 if none)."""
        return self.area2 / self.area if self.area > 0 else 0.0


@dataclass(frozen=True)
class _Work:
    """Everything a ping block needs besides its pings."""

    surface: ScatterSurface
    grid: EchoGrid
    model: _Model
    sides: tuple[str, ...]
    jitter: float
    seed: int
    chunk: int
    method: str
    visibility: str
    engine: str = "numpy"


@dataclass(frozen=True)
class _Block:
    """A block of pings of one segment: where they are and the box their scatterers lie in."""

    segment: Any
    frame: Any
    first: int
    pings: np.ndarray  # (p, 3) frame coordinates
    roll: np.ndarray
    bounds: np.ndarray
    off: float
    travel: np.ndarray  # (3,) direction of travel in fan components (see _travel)
    work: float = 0.0  # estimated seconds (progress bar units)


def face_spacing(scene: Scene, spacing: float, seabed_spacing: float) -> np.ndarray:
    """Scatterer spacing of every face, metres: ``seabed_spacing`` on parts named "seabed".

    Parameters
    ----------
    scene : Scene
        The scene (``names`` and ``object_id`` say which faces are seabed).
    spacing, seabed_spacing : float
        Spacing on objects and on the seabed, metres.
    """
    seabed = np.array([name == "seabed" for name in scene.names] or [False])
    is_seabed = seabed[np.clip(scene.object_id, 0, len(seabed) - 1)]
    return np.where(is_seabed, seabed_spacing, spacing)


def _render_block(
    work: _Work,
    item: _Block,
    scene: Scene,
    sonar: Sonar,
    local: np.ndarray,
    casters: dict[str, Any],
    stats: _Stats,
) -> np.ndarray:
    """Intensity of a block of pings of one segment, shape (pings, sides, bins).

    Scatterers are generated only inside the block's reach, culled, tested for visibility,
    jittered, and their terms for every ping of the block deposited on the block's fine grid.
    """
    if work.engine == "compiled":
        return _render_block_compiled(work, item, scene, sonar, local, casters, stats)
    grid, sides, frame = work.grid, work.sides, item.frame
    acc = grid.accumulator(len(item.pings) * len(sides), work.method)
    test = _visibility_test(work, item, scene, sonar, local, casters, stats)
    factor = _face_factor(work.surface.facet_area, work.surface.reflectivity, work.model)
    slack = _slack(work, item)
    for sc in generate(
        work.surface, frame.axes, frame.origin, item.bounds, work.chunk, frame.fan_axes
    ):
        sc = _cull(sc, work.model, sides, slack, stats, item)
        if len(sc.face) == 0:
            continue
        vis = test(sc)
        stats.rays += len(vis) if work.visibility == "rays" else 0
        stats.visible += int(vis.sum())
        sc = sc.take(np.flatnonzero(vis))
        area = sc.facet_area
        stats.area += float(area.sum())
        stats.area2 += float(np.einsum("i,i", area, area))  # not BLAS: its threads spin
        sc = sc.jittered(frame.axes, work.jitter, work.seed)
        for lo in range(0, len(sc.face), _TERM_BATCH):  # cache-sized batches
            part = sc.take(slice(lo, lo + _TERM_BATCH)) if len(sc.face) > _TERM_BATCH else sc
            terms = _terms(
                part, item.pings, item.roll, sides, work.model, item.off, item.travel, factor
            )
            stats.pairs += terms.count
            grid.add_parts(acc, terms.row, grid.position(terms.r), terms.re, terms.im)
    return grid.intensity(acc).reshape(len(item.pings), len(sides), grid.n_bins)


def _compiled_arguments(work: _Work, item: _Block, sonar: Sonar, maps: Any) -> tuple:
    """The arguments of ``compiled.render_runs`` after the facets' (see its docstring)."""
    from . import compiled as cc
    from .visibility import BIN_TOL, REL_TOL

    grid, sides, frame, model = work.grid, work.sides, item.frame, work.model
    order = np.argsort(item.pings[:, 0], kind="stable")
    tp = np.ascontiguousarray(item.pings[order, 0])
    travel = np.asarray(item.travel, dtype=np.float64)
    params = np.zeros(cc.N_PARAMS)
    params[cc.P_R_LIMIT] = model.r_limit
    params[cc.P_SLACK] = _slack(work, item)
    params[cc.P_U_CUT] = model.u_cut
    params[cc.P_DEN] = travel[0] * math.sqrt(1.0 - model.u_cut**2) - model.u_cut * _skew(travel)
    params[cc.P_OFF] = item.off
    params[cc.P_WAVELENGTH] = model.wavelength
    params[cc.P_TILT] = sonar.tilt
    params[cc.P_ORIGIN] = grid.origin
    params[cc.P_STEP] = grid.step
    params[cc.P_BIN_TOL] = BIN_TOL
    params[cc.P_REL_TOL] = REL_TOL
    flags = np.zeros(cc.N_FLAGS, dtype=np.int64)
    flags[cc.F_PORT] = "port" in sides
    flags[cc.F_STARBOARD] = "starboard" in sides
    flags[cc.F_TWO_SIDES] = len(sides) == 2
    flags[cc.F_LAMBERT] = model.law == "lambert"
    if model.beam_h is not None:
        flags[cc.F_BEAM_H] = cc.BEAM_GAUSSIAN if model.beam_h.kind == "gaussian" else cc.BEAM_SINC
        params[cc.P_BEAM_WIDTH] = model.beam_h.width
        params[cc.P_BEAM_CUT] = model.beam_h.cutoff
    beam = sonar.beam
    flags[cc.F_VERTICAL] = not beam.is_uniform
    flags[cc.F_VISIBILITY] = maps is not None
    flags[cc.F_JITTER] = work.jitter > 0
    level = travel[1] == 0 and travel[2] == 0
    flags[cc.F_LINE] = level and np.ptp(item.pings[:, 1]) == 0 and np.ptp(item.pings[:, 2]) == 0
    flags[cc.F_ONE_ROLL] = np.ptp(item.roll) == 0
    steps = np.diff(beam.angles)
    flags[cc.F_UNIFORM_TABLE] = bool(np.all(np.abs(steps - steps[0]) <= 1e-9 * steps[0]))
    empty = np.full((2, 2), np.inf, dtype=np.float32)
    map_rows = np.zeros((2, cc.N_MAP))
    map_ranges = [empty, empty]
    for slot, side in enumerate(("port", "starboard")):
        if maps is not None and side in maps.maps:
            m = maps.maps[side]
            map_ranges[slot] = np.ascontiguousarray(m.ranges, dtype=np.float32)
            map_rows[slot] = (
                m.t0,
                m.dt,
                m.h,
                m.c,
                m.alpha0,
                m.rho0,
                m.slope0,
                m.rho_lo,
                m.rho_hi,
                m.columns,
            )
    seed_key = np.uint64(work.seed & 0xFFFFFFFFFFFFFFFF)
    jitter_axes = np.ascontiguousarray(work.jitter * frame.axes, dtype=np.float64)
    table = np.ascontiguousarray(grid.kernel.table().T)  # (T, 2W): a term's taps together

    return (
        tp, order, np.ascontiguousarray(item.pings, dtype=np.float64),
        np.ascontiguousarray(item.roll, dtype=np.float64), travel,
        params, flags, beam.angles, beam.values,
        map_ranges[0], map_ranges[1], map_rows, sonar.range_bin,
        jitter_axes, seed_key, table, grid.kernel.taps,
    )  # fmt: skip


def _slack(work: _Work, item: _Block) -> float:
    """Travel and range slack of the cull: the jitter's reach, the pings' offset, the skew."""
    slack = (JITTER_CLIP * math.sqrt(3.0) * work.jitter + item.off) / item.travel[0]
    return slack + _reach(work.model.r_limit + slack, work.model, item.travel) * _skew(item.travel)


def _engine(engine: str, method: str, visibility: str) -> str:
    """The engine that runs: "compiled" or "numpy" (see ``ENGINES``)."""
    if engine not in ENGINES:
        raise SonarRasterError(f"engine must be one of {ENGINES}, got {engine!r}")
    fits = method == "fast" and visibility == "depth"
    if engine == "compiled" and not fits:
        raise SonarRasterError(
            "the compiled engine needs method='fast' and visibility='depth'; "
            "use engine='numpy' for the others"
        )
    if engine == "auto":
        return "compiled" if fits and _numba_available() else "numpy"
    return engine


def _numba_available() -> bool:
    """Whether numba imports (a dependency, but not every platform has its wheels)."""
    import importlib.util

    return importlib.util.find_spec("numba") is not None


def _render_block_compiled(
    work: _Work,
    item: _Block,
    scene: Scene,
    sonar: Sonar,
    local: np.ndarray,
    casters: dict[str, Any],
    stats: _Stats,
) -> np.ndarray:
    """:func:`_render_block` with the compiled loops of :mod:`.compiled`, on every core.

    Runs are clipped in chunks (the first while the GL draws the range maps, the next while
    the threads work on the last); each chunk is cut into parts of about equal facet counts
    that the pool's threads take in turn, each depositing on its own accumulator (the loop
    releases the GIL); the accumulators are summed at the end of the block.
    """
    from . import compiled as cc

    grid, sides, frame = work.grid, work.sides, item.frame
    rows = len(item.pings) * len(sides)
    threads = _threads()
    accs = [np.zeros((rows, grid.n, 2)) for _ in range(threads)]  # a term's taps together
    counts = [np.zeros(cc.N_STATS) for _ in range(threads)]
    factor = _face_factor(work.surface.facet_area, work.surface.reflectivity, work.model)
    slots: dict[int, int] = {}
    lock = threading.Lock()
    with _pool(threads) as pool:
        chunks = generate_runs(
            work.surface, frame.axes, frame.origin, item.bounds, _RUN_CHUNKS * work.chunk,
            frame.fan_axes, row_block=_RUN_ROW_BLOCK,
        )  # fmt: skip
        first = pool.submit(next, chunks, None)  # clipped while the GL draws the range maps
        maps = _range_maps(work, item, scene, sonar, local, casters, stats)
        args = _compiled_arguments(work, item, sonar, maps)
        render_runs: Any = cc.render_runs  # a numba dispatcher: no signature to check

        def run(face: np.ndarray, runs: Any, lo: int, hi: int, faces: Any) -> None:
            with lock:  # each pool thread deposits on its own accumulator
                n = slots.setdefault(threading.get_ident(), len(slots))
            render_runs(
                face[lo:hi], runs.i[lo:hi], runs.lo[lo:hi], runs.length[lo:hi],
                runs.base[lo:hi], runs.slope[lo:hi], work.surface.n_sub,
                faces.normal, factor, faces.facet_area, *args, accs[n], counts[n],
            )  # fmt: skip

        pending: list[Any] = []
        chunk = first.result()
        while chunk is not None:
            faces, ids, runs = chunk
            face = np.ascontiguousarray(ids[runs.tri])
            for job in pending:
                job.result()
            pending = [
                pool.submit(run, face, runs, lo, hi, faces)
                for lo, hi in _split_runs(runs.length, _RUN_CHUNKS * threads)
            ]
            chunk = next(chunks, None)  # clipped while the threads work on this one
        for job in pending:
            job.result()
    total = np.sum(counts, axis=0)
    if total[cc.S_OUTSIDE] > 0:
        raise ValueError("a scatterer lies outside the echo grid")
    acc = accs[0]
    for other in accs[1:]:
        acc += other
    acc = acc.transpose(2, 1, 0)  # EchoGrid's (2, N, rows) layout, as a view
    stats.scatterers += int(total[cc.S_SCATTERERS])
    stats.visible += int(total[cc.S_VISIBLE])
    stats.pairs += int(total[cc.S_PAIRS])
    stats.area += float(total[cc.S_AREA])
    stats.area2 += float(total[cc.S_AREA2])
    return grid.intensity(acc).reshape(len(item.pings), len(sides), grid.n_bins)


def _threads() -> int:
    """Threads of the compiled engine: the cores this process may use (at most 8)."""
    return min(usable_cores(), 8)


def _pool(threads: int) -> Any:
    from concurrent.futures import ThreadPoolExecutor

    return ThreadPoolExecutor(max_workers=threads, thread_name_prefix="coherent")


def _split_runs(length: np.ndarray, parts: int) -> list[tuple[int, int]]:
    """Index ranges cutting runs of ``length`` facets into ``parts`` of about equal counts."""
    if len(length) == 0:
        return []
    cum = np.cumsum(length)
    cuts = np.searchsorted(cum, cum[-1] * np.arange(1, parts) / parts)
    edges = [0, *[int(c) for c in cuts], len(length)]
    return [(a, b) for a, b in zip(edges[:-1], edges[1:], strict=True) if b > a]


def _range_maps(work, item, scene, sonar, local, casters, stats):
    """The block's GL range maps (:class:`.visibility.RangeMaps`)."""
    from ..gl.raster import RasterRenderer
    from .visibility import RangeMaps

    if "gl" not in casters:
        casters["gl"] = RasterRenderer(casters.get("backend"))
    t_lo, t_hi = (float(b) for b in item.bounds[0])
    maps = RangeMaps(
        casters["gl"],
        scene,
        sonar,
        item.segment,
        work.sides,
        t_lo,
        t_hi,
        _MAP_ROW_BINS * sonar.range_bin,
        local + 0.0,
    )
    stats.rays += maps.rays
    return maps


def _visibility_test(work, item, scene, sonar, local, casters, stats):
    """A function of a scatterer chunk giving each scatterer's visibility."""
    if work.visibility == "rays":
        from ..fan import Surface, ray_caster, visible

        if "rays" not in casters:
            surface = work.surface
            casters["rays"] = (
                ray_caster(scene.vertices - local, scene.faces),
                Surface(surface.tri, surface.normal, surface.n_sub, surface.facet_area),
            )
        caster, ray_surface = casters["rays"]
        frame = item.frame

        def by_rays(sc: Scatterers) -> np.ndarray:
            t, x, v = sc.nominal.T
            r = np.hypot(x, v)
            origins = frame.origin + t[:, None] * frame.along
            dirs = (x[:, None] * frame.starboard + v[:, None] * frame.up) / r[:, None]
            return visible(caster, ray_surface, origins, dirs, r, sc.face)

        return by_rays
    maps = _range_maps(work, item, scene, sonar, local, casters, stats)
    return lambda sc: maps.visible(sc.nominal)


def _estimate(work: _Work, blocks: list[_Block], trajectory: Trajectory, block: int) -> Estimate:
    """Scatterers, scatterer-ping terms and seconds of a render, before generating anything.

    Scatterers: per block, each face overlapping the block's box contributes its facets times
    the share of its along-track extent inside the box. Terms: each scatterer meets the pings
    within the horizontal beam's reach at mid range. Seconds: ``_COST_*`` per item (divided by
    ``_COMPILED_SPEEDUP`` for the compiled engine).
    """
    from ..patches import overlaps, project

    surface, model = work.surface, work.model
    count = surface.n_sub.astype(np.float64) ** 2
    u = model.u_cut
    reach = 0.5 * model.r_limit * u / math.sqrt(1.0 - u * u)
    spacing = max(trajectory.typical_spacing, 1e-9)
    per = min(float(block), 2.0 * reach / spacing + 1.0)
    scatterers = pairs = 0.0
    speed = _COMPILED_SPEEDUP if work.engine == "compiled" else 1.0
    blocks_out = []
    for item in blocks:
        proj = project(surface.tri, item.frame.origin, item.frame.axes)
        ids = np.flatnonzero(overlaps(proj, item.bounds))
        t = proj[ids, 0, 0][:, None] + np.stack(
            [np.zeros(len(ids)), proj[ids, 0, 1], proj[ids, 0, 2]], axis=1
        )
        lo, hi = t.min(axis=1), t.max(axis=1)
        b_lo, b_hi = item.bounds[0]
        share = (np.minimum(hi, b_hi) - np.maximum(lo, b_lo)) / np.maximum(hi - lo, 1e-12)
        share = np.where(hi - lo > 1e-12, np.clip(share, 0.0, 1.0), 1.0)
        n = float(np.sum(count[ids] * share))
        pings = min(float(len(item.pings)), per)
        scatterers += n
        pairs += n * pings
        blocks_out.append(n * (_COST_SCATTERER + pings * _COST_PAIR) / speed)
    for k, seconds in enumerate(blocks_out):
        blocks[k] = replace(blocks[k], work=seconds)
    total = float(sum(blocks_out))
    return Estimate(
        f"coherent render of {trajectory.n_pings} pings",
        {"scatterers": scatterers, "scatterer-ping terms": pairs},
        seconds=total,
        work=total,
    )


def _check_settings(
    sonar: Sonar, pulse: Pulse, beam_h: HorizontalBeam | None, method: str, scattering: str
) -> None:
    if not isinstance(sonar, Sonar):
        raise TypeError(f"sonar must be a Sonar, got {type(sonar).__name__}")
    if not isinstance(pulse, Pulse):
        raise TypeError(f"pulse must be a Pulse, got {type(pulse).__name__}")
    if beam_h is not None and not isinstance(beam_h, HorizontalBeam):
        raise TypeError(f"horizontal_beam must be a HorizontalBeam, got {type(beam_h).__name__}")
    if method not in METHODS:
        raise SonarRasterError(f"method must be one of {METHODS}, got {method!r}")
    if scattering not in LAWS:
        raise SonarRasterError(f"scattering must be one of {LAWS}, got {scattering!r}")
    if pulse.band_hz >= 2.0 * sonar.frequency_hz:
        raise SonarRasterError(
            f"the pulse band ({pulse.band_hz:.4g} Hz) must be below twice the centre frequency "
            f"({sonar.frequency_hz:.4g} Hz); use a larger range bin or a higher frequency"
        )


def _grid(sonar: Sonar, pulse: Pulse, samples_per_bin: int | None) -> EchoGrid:
    if samples_per_bin is not None and not (
        isinstance(samples_per_bin, (int, np.integer)) and 1 <= samples_per_bin <= 1024
    ):
        raise SonarRasterError(
            f"samples_per_bin must be an integer in [1, 1024], got {samples_per_bin!r}"
        )
    return EchoGrid.make(
        sonar.range_bin,
        sonar.n_bins,
        sonar.sound_speed,
        pulse.compressed,
        pulse.band_hz,
        0.5 * sonar.sound_speed * pulse.duration_s,
        samples_per_bin,
    )


def _model(sonar: Sonar, beam_h: HorizontalBeam | None, law: str) -> _Model:
    r_limit = sonar.n_bins * sonar.range_bin + RANGE_MARGIN_BINS * sonar.range_bin
    return _Model(sonar, beam_h, law, sonar.wavelength, r_limit)


def _travel(frame: Any) -> np.ndarray:
    """Direction of travel in the fan's orthonormal components (fore, starboard, up), (3,).

    ``(1, 0, 0)`` without crab or pitch. Frame coordinates ``(t, x, v)`` (the segment's shear
    map: travel of the fan a point lies in, and its place in that fan) differ from the fan's
    orthonormal components by ``t`` times this vector, so the offset from a ping at travel
    ``t_p`` to a scatterer is ``(t − t_p) a + (0, x − y_p, v − z_p)`` in fan components.
    """
    a = frame.fan_axes @ frame.along
    if abs(a[1]) < 1e-12 and abs(a[2]) < 1e-12:
        return np.array([1.0, 0.0, 0.0])
    return a


def _mean_advance(blocks: list[_Block]) -> float:
    """Ping-weighted mean of ``a_f`` (the fan's advance per metre of travel) over the blocks."""
    pings = np.array([len(b.pings) for b in blocks], dtype=np.float64)
    advance = np.array([b.travel[0] for b in blocks])
    return float(pings @ advance / pings.sum()) if len(blocks) else 1.0


def _skew(travel: np.ndarray) -> float:
    """In-fan part of the direction of travel, ``sqrt(a_s² + a_u²)`` (0 without crab/pitch)."""
    return math.hypot(float(travel[1]), float(travel[2]))


def _reach(rho: np.ndarray | float, model: _Model, travel: np.ndarray) -> np.ndarray | float:
    """Largest travel between a ping and a scatterer ``rho`` from its line inside the beam.

    ``|u| <= u_c`` with ``u = Δt a_f / r`` and ``r >= |Δt| a_f``, the in-fan distance at most
    ``rho + |Δt| skew``: ``|Δt| <= u_c rho / (a_f sqrt(1 − u_c²) − u_c skew)``.
    """
    u = model.u_cut
    den = float(travel[0]) * math.sqrt(1.0 - u * u) - u * _skew(travel)
    if den <= 0:
        raise SonarRasterError(
            "the vehicle crabs or pitches more than the horizontal beam's reach allows; "
            "use a narrower horizontal beam or the raster model"
        )
    return rho * u / den


def _block_bounds(
    model: _Model,
    pings: np.ndarray,
    sides: tuple[str, ...],
    jitter: float,
    travel: np.ndarray,
) -> tuple[np.ndarray, float]:
    """Box (frame coordinates) of facet centroids that can reach a block of pings.

    Returns the box and the pings' largest distance from the segment's line (metres).
    """
    off = float(np.max(np.hypot(pings[:, 1], pings[:, 2]), initial=0.0))
    # the shear map stretches world lengths by up to 1 / a_f
    margin = (JITTER_CLIP * jitter * math.sqrt(3.0) + 1e-6) / float(travel[0])
    r = model.r_limit + off + margin
    reach = float(_reach(r, model, travel)) + off + margin
    r += reach * _skew(travel)  # a ping off along travel sees the fan's points shifted
    t_lo, t_hi = float(pings[:, 0].min()), float(pings[:, 0].max())
    x_lo = -r if "port" in sides else -margin
    x_hi = r if "starboard" in sides else margin
    return np.array([[t_lo - reach, t_hi + reach], [x_lo, x_hi], [-r, r]]), off


def _cull(
    sc: Scatterers,
    model: _Model,
    sides: tuple[str, ...],
    slack: float,
    stats: _Stats,
    item: _Block | None = None,
) -> Scatterers:
    """Keep scatterers on an imaged side, within range reach, facing the track.

    With ``item``, also only those inside some ping's horizontal beam (their facet centroid
    within the beam's reach of a ping of the block, with the jitter's and the pings' slack):
    the rest would add no term. ``stats.scatterers`` counts the scatterers in range reach.
    """
    t, x, v = sc.nominal.T
    side_ok = np.where(x > 0, "starboard" in sides, "port" in sides) & (x != 0)
    rho = np.hypot(x, v)
    near = rho < model.r_limit + slack
    keep = side_ok & near
    stats.scatterers += int(np.count_nonzero(keep))
    normal = sc.faces.normal
    keep &= x * normal[sc.face, 1] + v * normal[sc.face, 2] < 0
    if item is not None:
        tp = np.sort(item.pings[:, 0])
        reach = _reach(rho + slack, model, item.travel) + slack + 1e-9
        lo = np.searchsorted(tp, t - reach, side="left")
        keep &= np.searchsorted(tp, t + reach, side="right") > lo
    return sc.take(np.flatnonzero(keep))


@dataclass(frozen=True)
class _Terms:
    """Scatterer-ping terms of one chunk: grid row, distance and complex amplitude.

    Terms outside the beams (or facing away) have amplitude 0 and ``count`` leaves them out.
    """

    row: np.ndarray  # (p,) int64: ping * sides + side slot
    r: np.ndarray  # (p,) metres
    re: np.ndarray  # (p,)
    im: np.ndarray  # (p,)
    count: int


def _terms(
    sc: Scatterers,
    pings: np.ndarray,
    roll: np.ndarray,
    sides: tuple[str, ...],
    model: _Model,
    off: float,
    travel: np.ndarray | None = None,
    face_factor: np.ndarray | None = None,
) -> _Terms:
    """Every scatterer-ping term of a chunk and a block of pings (Eq. 10, vectorised).

    A scatterer meets the pings within the horizontal beam's reach of it (one ``searchsorted``
    per chunk); the amplitude is :func:`_amplitudes`'s, with the per-scatterer factors
    (area, R, the across-track distance when the block's pings share one line) computed once
    per scatterer and the phase reduced to a fraction of a cycle before its cosine and sine.
    ``travel`` (:func:`_travel`, default level) maps frame offsets to the fan's orthonormal
    components; positions and pings are in frame coordinates, normals in fan ones.
    ``face_factor`` (:func:`_face_factor`) is computed when not given.
    """
    travel = _LEVEL if travel is None else travel
    k, j = _pair_index(sc.position, pings, model, off, travel)
    t, x, v = (np.ascontiguousarray(c) for c in sc.position.T)
    normal = sc.faces.normal[sc.face]
    nt, nx, nv = (np.ascontiguousarray(c) for c in normal.T)
    dt = t[k]
    dt -= pings[j, 0]  # travel between the ping and the fan the scatterer lies in
    level = travel[1] == 0 and travel[2] == 0
    if level and np.ptp(pings[:, 1]) == 0 and np.ptp(pings[:, 2]) == 0:
        # no crab or pitch, pings on one line: the across-track part is per scatterer
        dx, dv = x - pings[0, 1], v - pings[0, 2]
        r = (dx * dx + dv * dv)[k]
        nd = (nx * dx + nv * dv)[k]
        depression = np.arctan2(-dv, np.abs(dx))[k] if not model.sonar.beam.is_uniform else None
        fore = dt
    else:
        dx = x[k] - pings[j, 1] + dt * travel[1]
        dv = v[k] - pings[j, 2] + dt * travel[2]
        r = dx * dx + dv * dv
        nd = nx[k] * dx + nv[k] * dv
        depression = np.arctan2(-dv, np.abs(dx)) if not model.sonar.beam.is_uniform else None
        fore = dt * travel[0]
    r += fore * fore
    np.sqrt(r, out=r)
    nd += nt[k] * fore
    inv = 1.0 / np.maximum(r, 1e-12)
    u = fore * inv  # direction cosine on the fan's normal
    cos_inc = nd * inv
    np.negative(cos_inc, out=cos_inc)
    ok = (r < model.r_limit) & (np.abs(u) <= model.u_cut) & (cos_inc > 0) & (r > 1e-9)
    np.maximum(cos_inc, 0.0, out=cos_inc)
    amp = np.sqrt(cos_inc) if model.law == "lambert" else cos_inc
    amp *= inv
    amp *= inv
    if face_factor is None:
        face_factor = _face_factor(sc.faces.facet_area, sc.faces.reflectivity, model)
    amp *= face_factor[sc.face][k]
    amp *= _beam_h_root(u, model.beam_h)
    if depression is not None:
        sign = np.where(sc.nominal[:, 1] > 0, 1.0, -1.0)
        tilt = depression - model.sonar.tilt - sign[k] * roll[j]
        amp *= np.sqrt(model.sonar.beam(tilt))
    amp[~ok] = 0.0
    re, im = _phasor(r, model.wavelength)
    re *= amp
    im *= amp
    slot = (sc.nominal[:, 1] > 0).astype(np.int64) if len(sides) == 2 else None
    row = j * len(sides)
    if slot is not None:
        row += slot[k]
    np.minimum(r, model.r_limit, out=r)  # dead terms (amplitude 0) stay on the grid
    return _Terms(row, r, re, im, int(np.count_nonzero(amp)))


def _phasor(r: np.ndarray, wavelength: float) -> tuple[np.ndarray, np.ndarray]:
    """Real and imaginary parts of ``exp(−4πi r / λ)``, to ~1e-7.

    The two-way path is reduced to a fraction of a cycle in float64 before :func:`cos_sin`.
    """
    angle = r * (2.0 / wavelength)  # two-way path in wavelengths
    angle -= np.rint(angle)
    angle *= -2.0 * math.pi
    return cos_sin(angle)


def _pair_index(
    position: np.ndarray,
    pings: np.ndarray,
    model: _Model,
    off: float,
    travel: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Scatterer and ping indices of the pairs within the horizontal beam's reach."""
    order = np.argsort(pings[:, 0], kind="stable")
    tp = pings[order, 0]
    rho = np.hypot(position[:, 1], position[:, 2]) + off
    reach = _reach(rho, model, _LEVEL if travel is None else travel) + off + 1e-9
    t = position[:, 0]
    lo = np.searchsorted(tp, t - reach, side="left")
    hi = np.searchsorted(tp, t + reach, side="right")
    counts = hi - lo
    k = np.repeat(np.arange(len(t)), counts)
    j = np.arange(len(k)) - np.repeat(np.cumsum(counts) - counts - lo, counts)
    return k, order[j]


def _face_factor(facet_area: np.ndarray, reflectivity: np.ndarray, model: _Model) -> np.ndarray:
    """``size sqrt(R) / λ`` per face (size ``sqrt(a² area_ref)``, or ``a²`` if 0), (m,)."""
    size = np.sqrt(facet_area * model.area_ref) if model.area_ref > 0 else facet_area
    return size * np.sqrt(reflectivity) / model.wavelength


def _beam_h_root(u: np.ndarray, beam_h: HorizontalBeam | None) -> np.ndarray | float:
    """Square root of the two-way horizontal gain at direction cosines u (amplitude gain)."""
    if beam_h is None:
        return 1.0
    if beam_h.kind == "gaussian":
        a = u * (1.0 / beam_h.width)
        a *= a
        np.minimum(a, 16.0, out=a)
        a *= -2.0 * math.log(2.0)
        g = np.exp(a, out=a)
        g[np.abs(u) > beam_h.cutoff] = 0.0
        return g
    return np.sqrt(beam_h(u))


def _amplitudes(
    sc: Scatterers | PointScatterers,
    k: np.ndarray,
    ping: np.ndarray,
    roll: np.ndarray,
    sign: np.ndarray,
    model: _Model,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eq. 10 terms of pairs (scatterer ``k``, ping at ``ping`` in frame coordinates).

    Returns the distance r, the complex amplitude and a mask of the terms that count.
    """
    position = sc.position if isinstance(sc, Scatterers) else sc.positions
    normal = sc.normal if isinstance(sc, Scatterers) else sc.normals
    area = sc.facet_area if isinstance(sc, Scatterers) else sc.areas
    d = position[k] - ping
    r = np.sqrt(np.einsum("ij,ij->i", d, d))
    safe = np.maximum(r, 1e-12)
    u = d[:, 0] / safe
    cos_inc = -np.einsum("ij,ij->i", normal[k], d) / safe
    ok = (r < model.r_limit) & (np.abs(u) <= model.u_cut) & (cos_inc > 0) & (r > 1e-9)
    gain = sc.reflectivity[k] * (model.beam_h(u) if model.beam_h is not None else 1.0)
    beam = model.sonar.beam
    if not beam.is_uniform:
        depression = np.arctan2(-d[:, 2], np.abs(d[:, 1]))
        gain = gain * beam(depression - model.sonar.tilt - sign * roll)
    cos_inc = np.where(ok, cos_inc, 0.0)
    law = np.sqrt(cos_inc) if model.law == "lambert" else cos_inc
    size = np.sqrt(area[k] * model.area_ref) if model.area_ref > 0 else area[k]
    amp = size / model.wavelength * np.sqrt(gain) * law / (safe * safe)
    c = amp * np.exp(-4j * math.pi / model.wavelength * r)
    return r, c, ok & (amp > 0)


def _memory_estimate(
    surface: ScatterSurface,
    grid: EchoGrid,
    n_sides: int,
    block: int,
    chunk: int,
    model: _Model,
    trajectory: Trajectory,
) -> int:
    """Rough peak bytes: surface and ray-caster tables, one block's grid, one chunk in flight."""
    spacing = trajectory.typical_spacing
    u = model.u_cut
    reach = model.r_limit * u / math.sqrt(1.0 - u * u)
    pings_per_scatterer = min(block, int(2 * reach / spacing) + 2)
    per_chunk = chunk * (_SCATTERER_BYTES + pings_per_scatterer * _PAIR_BYTES)
    tables = len(surface.n_sub) * (200 + 150)  # surface arrays, embree BVH
    return int(tables + grid.nbytes(block * n_sides) + per_chunk)


def ping_echo(
    points: PointScatterers,
    sonar: Sonar,
    position: np.ndarray,
    heading: float = 0.0,
    *,
    roll: float = 0.0,
    pulse: Pulse | None = None,
    horizontal_beam: HorizontalBeam | None = None,
    scattering: str = "lambert",
    method: str = "fast",
    samples_per_bin: int | None = None,
) -> Echo:
    """Compressed echo of explicit point scatterers for one ping (no visibility test).

    Parameters
    ----------
    points : PointScatterers
        The scatterers, all taken as visible.
    sonar : Sonar
        Range sampling, beam, tilt, sides, frequency.
    position : ndarray, shape (3,)
        Transducer position, world metres.
    heading : float
        Compass heading, radians (0 = +y).
    roll : float
        Roll, radians, positive starboard down.
    pulse, scattering, method, samples_per_bin
        As for :func:`render_coherent`.
    horizontal_beam : HorizontalBeam, optional
        Along-track beam; None applies none (every along-track angle has gain 1).

    Returns
    -------
    Echo
    """
    if not isinstance(points, PointScatterers):
        raise TypeError(f"points must be PointScatterers, got {type(points).__name__}")
    pulse = Pulse.for_range_bin(sonar.range_bin, sonar.sound_speed) if pulse is None else pulse
    _check_settings(sonar, pulse, horizontal_beam, method, scattering)
    grid = _grid(sonar, pulse, samples_per_bin)
    model = _model(sonar, horizontal_beam, scattering)
    along, starboard = heading_axes(float(heading))
    axes = np.stack([along, starboard, np.cross(starboard, along)])
    local = PointScatterers(
        (points.positions - np.asarray(position, dtype=np.float64)) @ axes.T,
        points.normals @ axes.T,
        points.areas,
        points.reflectivity,
    )
    sides = tuple(s for s in SIDES if s in sonar.sides)
    x = local.positions[:, 1]
    on_side = np.where(x > 0, "starboard" in sides, "port" in sides) & (x != 0)
    k = np.flatnonzero(on_side)
    sign = np.where(x[k] > 0, 1.0, -1.0)
    r, c, ok = _amplitudes(
        local, k, np.zeros((len(k), 3)), np.full(len(k), float(roll)), sign, model
    )
    slot = (x[k] > 0).astype(np.int64) if len(sides) == 2 else np.zeros(len(k), np.int64)
    acc = grid.accumulator(len(sides), method)
    grid.add(acc, slot[ok], grid.position(r[ok]), c[ok])
    signal = grid.signal(acc)
    power = signal.real**2 + signal.imag**2
    binned = power.reshape(len(sides), sonar.n_bins, grid.samples_per_bin).mean(axis=2)
    return Echo(
        ranges=grid.image_ranges,
        signal={side: signal[i] for i, side in enumerate(sides)},
        intensity={side: binned[i] for i, side in enumerate(sides)},
    )


def to_raster_units(image: SonarImage) -> SonarImage:
    """Convert a coherent image to the raster's units (``Σ Φ R cos θ dA`` per bin, m², K = 1).

    Multiplies bin k (centre range ``r_k``) by ``r_k⁴ λ² / a² · w / F(r_k)``: undoes the
    spherical spreading and Eq. 10's ``a⁴ / λ²`` per scatterer (``a²`` the area-weighted mean
    facet area), and rescales the horizontal beam's footprint ``F(r) = ∫ Φ_h dy`` to the raster's
    ping width ``w``. For a rough surface (fully developed speckle) with the "lambert" law, the
    expected result equals the raster image, blurred by the compressed pulse.

    Raises
    ------
    SonarRasterError
        If the image is not from :func:`render_coherent` or has no visible scatterers.
    """
    md = image.metadata
    if md.get("renderer") != "coherent":
        raise SonarRasterError("to_raster_units needs an image from render_coherent")
    area = float(md["facet_area_m2"])
    if not area > 0:
        raise SonarRasterError("the coherent image saw no scatterers; nothing to scale")
    beam = md["horizontal_beam"]
    beam_h = HorizontalBeam(float(beam["width_rad"]), str(beam["kind"]))
    sonar = image.sonar
    r = (np.arange(sonar.n_bins) + 0.5) * sonar.range_bin
    lam = float(md["wavelength_m"])
    factor = r**4 * lam**2 / area * float(md["ping_width_m"]) / beam_h.footprint(r)
    sides = {s: (a * factor).astype(np.float32) for s, a in image.sides.items()}
    return SonarImage(sides=sides, sonar=sonar, metadata={**md, "units": "m^2 (raster units)"})
