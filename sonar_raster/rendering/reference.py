"""Reference renderer: the sonar integral summed over small surface patches.

The slow, independent oracle for the raster renderer, and a CPU-only fallback. Every triangle
is cut into ``n²`` equal sub-triangles by uniform barycentric subdivision
(``n = ceil(longest edge / patch_size)``); each sub-triangle is a patch at its centroid with
its exact area. Per straight track segment (see :meth:`Trajectory.segments`) a patch at
along-track coordinate ``t`` belongs to ping ``k = floor(t / spacing + 1/2)`` and is seen from
the point of the track level with it, ``q = origin + t * along`` (an infinitely thin fan beam
that moves continuously). A patch facing ``q``, inside the range window and not occluded
(one ray cast from ``q``) adds ``Φ(α − axis) · R · cos θ · area`` to its ping's range bin.

Work is bounded in memory: patches are generated row by row of the subdivision grid, rows
outside the segment's slab or beyond the maximum range are skipped analytically, and the rest
is processed in fixed-size vectorised chunks (see :mod:`sonar_raster.rendering.patches`).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .._progress import Estimate, announce, check_job, progress_bar
from ..errors import SonarRasterError
from ..image import SonarImage
from ..scene import Scene
from ..sonar import Sonar
from ..trajectory import Trajectory
from .fan import Frame, Surface, check_inputs, ray_caster, segment_frame, visible
from .patches import Runs, overlaps, project, runs_in_box

log = logging.getLogger(__name__)

#: Patches per vectorised chunk (bounds memory to a few hundred MB).
_PATCH_CHUNK = 1 << 20
#: Seconds per patch on the 2-core CI machine (generation, one embree ray, deposit).
_COST_PATCH = 1.0e-6
#: Subdivision-grid rows per block of triangles.
_ROW_CHUNK = 1 << 19


@dataclass(frozen=True)
class _Patches:
    """One chunk of patches in segment coordinates.

    Attributes
    ----------
    face : ndarray, shape (p,), int64
        Parent face index into the scene.
    coords : ndarray, shape (p, 3)
        Centroid (along, starboard, up) relative to the segment origin, metres.
    normal : ndarray, shape (p, 3)
        Parent face's unit normal in (along, starboard, up) components.
    edges : ndarray, shape (p, 3, 2)
        The patch's two edge vectors (segment coordinates), oriented so that its corners are
        ``coords + edges @ (-1/3, -1/3)``, ``(2/3, -1/3)`` and ``(-1/3, 2/3)``.
    """

    face: np.ndarray
    coords: np.ndarray
    normal: np.ndarray
    edges: np.ndarray


@dataclass
class _Stats:
    """Counters for the log and the metadata."""

    patches: int = 0
    rays: int = 0
    visible: int = 0


def render_reference(
    scene: Scene,
    sonar: Sonar,
    trajectory: Trajectory,
    *,
    patch_size: float | None = None,
    progress: bool = False,
    force: bool = False,
) -> SonarImage:
    """Render raw side-scan intensity by summing small visible surface patches.

    Parameters
    ----------
    scene : Scene
        Triangles with reflectivity, world metres.
    sonar : Sonar
        Range sampling, beam pattern, tilt and sides.
    trajectory : Trajectory
        Ping poses; grouped into straight segments with tolerance ``sonar.range_bin / 4``.
    patch_size : float, optional
        Largest patch edge in metres; default ``sonar.range_bin / 4``.
    progress : bool
        Print the estimate (patches, time) and show a progress bar with ETA.
    force : bool
        Run even when the estimate exceeds an hour.

    Returns
    -------
    SonarImage
        One float32 array of shape (pings, ``sonar.n_bins``) per side in ``sonar.sides``,
        holding ``Σ Φ R max(0, cos θ) dA`` in m² (K = 1). ``metadata`` has ``renderer``
        ("reference"), ``patch_size``, ``n_patches`` (patches inside a slab and the range
        window), ``n_rays`` and ``time_s``.

    Raises
    ------
    TypeError
        If an argument has the wrong type.
    SonarRasterError
        If ``patch_size`` is not a positive number, no ray caster is available, or the job is
        estimated over an hour (unless ``force``).
    """
    check_inputs(scene, sonar, trajectory)
    scene = scene.with_back_faces()  # open sheets scatter from both sides, as in GL
    size = sonar.range_bin / 4.0 if patch_size is None else patch_size
    if not (isinstance(size, (int, float)) and math.isfinite(size) and size > 0):
        raise SonarRasterError(f"patch_size must be a positive number of metres, got {size!r}")
    start = time.perf_counter()
    local = scene.bounds.mean(axis=0)
    surface = _surface(scene, local, float(size))
    frames = [
        segment_frame(segment, trajectory, local, size)
        for segment in trajectory.segments(sonar.range_bin / 4.0)
    ]
    work = [_patch_count(surface, sonar, frame) for frame in frames]
    estimate = Estimate(
        f"reference render of {trajectory.n_pings} pings",
        {"patches": float(sum(work)), "rays": float(sum(work))},
        seconds=_COST_PATCH * float(sum(work)),
        work=float(sum(work)),
    )
    check_job(
        estimate,
        "lower --pings or --range, or raise --range-bin (patches are a quarter bin), or use "
        "the raster model",
        force=force,
    )
    if progress:
        announce(estimate)
    caster = ray_caster(scene.vertices - local, scene.faces)
    acc = {side: np.zeros((trajectory.n_pings, sonar.n_bins)) for side in sonar.sides}
    stats = _Stats()
    law = _law(scene, sonar)
    with progress_bar(estimate.work, "reference", progress) as bar:
        for frame, count in zip(frames, work, strict=True):
            _render_segment(surface, caster, sonar, frame, acc, stats, law)
            bar.update(count)
    elapsed = time.perf_counter() - start
    log.info(
        "reference: %d patches, %d rays in %.2f s (%.3g patches/s)",
        stats.patches,
        stats.rays,
        elapsed,
        stats.patches / max(elapsed, 1e-9),
    )
    metadata = {
        "renderer": "reference",
        "patch_size": float(size),
        "n_patches": stats.patches,
        "n_rays": stats.rays,
        "time_s": elapsed,
        "estimate": estimate.to_dict(),
    }
    sides = {side: a.astype(np.float32) for side, a in acc.items()}
    return SonarImage(sides=sides, sonar=sonar, metadata=metadata)


def _patch_count(surface: Surface, sonar: Sonar, frame: Frame) -> float:
    """Patches of a segment, estimated: each face overlapping its box, times its share inside.

    The share is that of the face's along-track extent inside the box's (the slab).
    """
    bounds = _bounds(sonar, frame)
    proj = project(surface.tri, frame.origin, frame.axes)
    ids = np.flatnonzero(overlaps(proj, bounds))
    t0 = proj[ids, 0, 0]
    t = np.stack([t0, t0 + proj[ids, 0, 1], t0 + proj[ids, 0, 2]], axis=1)
    lo, hi = t.min(axis=1), t.max(axis=1)
    span = hi - lo
    inside = np.minimum(hi, bounds[0, 1]) - np.maximum(lo, bounds[0, 0])
    share = np.where(span > 1e-12, np.clip(inside / np.maximum(span, 1e-12), 0.0, 1.0), 1.0)
    return float(np.sum(surface.n_sub[ids].astype(np.float64) ** 2 * share))


def _surface(scene: Scene, local: np.ndarray, patch_size: float) -> Surface:
    """Local-coordinate triangles, normals, subdivision counts and patch weights."""
    tri = scene.triangles() - local
    normal, area = scene.face_normals_areas()
    edges = np.linalg.norm(tri[:, [1, 2, 0]] - tri, axis=2)
    n_sub = np.maximum(1, np.ceil(edges.max(axis=1) / patch_size)).astype(np.int64)
    weight = scene.reflectivity * area / n_sub.astype(np.float64) ** 2
    return Surface(tri, normal, n_sub, weight)


def _bounds(sonar: Sonar, frame: Frame) -> np.ndarray:
    """Box in segment coordinates (along, starboard, up) that can contribute, shape (3, 2)."""
    reach = sonar.n_bins * sonar.range_bin
    x_lo = -reach if "port" in sonar.sides else 0.0
    x_hi = reach if "starboard" in sonar.sides else 0.0
    t_lo, t_hi = frame.t_bounds
    margin = frame.patch_size  # a patch whose centroid is outside may still reach in
    return np.array([[t_lo - margin, t_hi + margin], [x_lo, x_hi], [-reach, reach]])


def _law(scene: Scene, sonar: Sonar) -> Callable[[np.ndarray, np.ndarray], np.ndarray] | None:
    """Per-patch factor of the scene's scattering laws over Lambert (None: Lambert only).

    The factor is ``f(θ) / cos θ`` of each face's law at the sonar's frequency, interpolated
    in incidence angle exactly as the raster's fragment shader does (same table).
    """
    if scene.law is None or not scene.law.any():
        return None
    from ..scenes.sediments import law_factor

    laws = scene.law.astype(np.int64)

    def factor(face: np.ndarray, cos_t: np.ndarray) -> np.ndarray:
        return law_factor(laws[face], cos_t, sonar.frequency_hz, sonar.sound_speed)

    return factor


def _render_segment(
    surface: Surface,
    caster,
    sonar: Sonar,
    frame: Frame,
    acc: dict[str, np.ndarray],
    stats: _Stats,
    law: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
) -> None:
    """Add one segment's patches to ``acc`` (side -> (pings, bins) float64)."""
    bounds = _bounds(sonar, frame)
    proj = project(surface.tri, frame.origin, frame.axes)
    ids = np.flatnonzero(overlaps(proj, bounds))
    if len(ids) == 0:
        return
    normal = surface.normal[ids] @ frame.fan_axes.T
    for runs in runs_in_box(
        proj, surface.n_sub, ids, bounds, row_block=_ROW_CHUNK, chunk=_PATCH_CHUNK
    ):
        patches = _make_patches(runs, ids, proj, normal, surface.n_sub)
        _accumulate(surface, caster, sonar, frame, patches, acc, stats, law)


def _make_patches(
    runs: Runs, ids: np.ndarray, proj: np.ndarray, normal: np.ndarray, n_sub: np.ndarray
) -> _Patches:
    """Materialise the patches of some runs (``runs.tri`` and ``normal`` index ``ids``)."""
    run, offset = runs.cells()
    kept = runs.tri[run]
    face = ids[kept]
    start = runs.base + runs.slope * runs.lo[:, None]
    scale = runs.sign[run] / n_sub[face]
    return _Patches(
        face=face,
        coords=start[run] + runs.slope[run] * offset[:, None],
        normal=normal[kept],
        edges=proj[face][:, :, 1:] * scale[:, None, None],
    )


def _accumulate(
    surface: Surface,
    caster,
    sonar: Sonar,
    frame: Frame,
    patches: _Patches,
    acc: dict[str, np.ndarray],
    stats: _Stats,
    law: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
) -> None:
    """Test one chunk of patches and add the visible ones to ``acc``.

    A patch's area is shared among the pings whose slabs and the range bins whose rings it
    overlaps (see :func:`_spread`), each direction on its own (a product of the two shares).
    """
    t, x, v = patches.coords.T
    corners = patches.coords[:, None, :] + np.einsum("pcj,kj->pkc", patches.edges, _CORNER_OFFSETS)
    t_lo, t_hi = frame.t_bounds
    inside = (corners[..., 0].max(axis=1) > t_lo) & (corners[..., 0].min(axis=1) < t_hi)
    starboard = x > 0
    on_side = np.where(starboard, "starboard" in sonar.sides, "port" in sonar.sides) & (x != 0)
    r = np.hypot(x, v)
    near = np.hypot(corners[..., 1], corners[..., 2]).min(axis=1)
    candidate = inside & on_side & (near < sonar.n_bins * sonar.range_bin)
    stats.patches += int(np.count_nonzero(candidate))
    cos_num = -(x * patches.normal[:, 1] + v * patches.normal[:, 2])
    sel = np.flatnonzero(candidate & (cos_num > 0))
    if len(sel) == 0:
        return
    origins = frame.origin + t[sel, None] * frame.along
    dirs = (x[sel, None] * frame.starboard + v[sel, None] * frame.up) / r[sel, None]
    vis = visible(caster, surface, origins, dirs, r[sel], patches.face[sel])
    stats.rays += len(sel)
    stats.visible += int(vis.sum())
    keep = sel[vis]
    face = patches.face[keep]
    weight = surface.patch_weight[face] * cos_num[keep] / r[keep]
    if law is not None:  # the face's angular law in place of Lambert's cos θ
        weight = weight * law(face, cos_num[keep] / r[keep])
    depression = np.arctan2(-v[keep], np.abs(x[keep]))
    c = corners[keep]
    bins, in_bin = _spread(np.hypot(c[..., 1], c[..., 2]), sonar.range_bin, 0.0)
    slab = frame.spacing if frame.spacing > 0 else frame.width
    pings, in_slab = _spread(c[..., 0], slab, -0.5 * slab)
    valid = (pings >= 0) & (pings < (frame.count if frame.spacing > 0 else 1))
    in_slab = np.where(valid, in_slab, 0.0)
    shape = (len(keep), pings.shape[1], bins.shape[1])
    _deposit(
        sonar,
        frame,
        acc,
        np.broadcast_to(np.where(valid, pings, 0)[:, :, None], shape).ravel(),
        np.broadcast_to(bins[:, None, :], shape).ravel(),
        np.broadcast_to(starboard[keep, None, None], shape).ravel(),
        np.broadcast_to(depression[:, None, None], shape).ravel(),
        (weight[:, None, None] * in_slab[:, :, None] * in_bin[:, None, :]).ravel(),
    )


#: Barycentric offsets of a patch's corners from its centroid along its two edges.
_CORNER_OFFSETS = np.array([[-1.0, -1.0], [2.0, -1.0], [-1.0, 2.0]]) / 3.0


def _spread(r: np.ndarray, bin_size: float, offset: float) -> tuple[np.ndarray, np.ndarray]:
    """Share each patch's area among the bins ``[offset + k b, offset + (k + 1) b)`` it covers.

    Used for range bins and for along-track ping slabs. A flat triangle over which a
    coordinate varies linearly has a "hat" area density in it, rising
    linearly from its nearest to its middle corner and falling to its farthest; its cumulative
    area is ``(s - r0)² / ((r1 - r0)(r2 - r0))`` up to ``r1`` and
    ``1 - (r2 - s)² / ((r2 - r0)(r2 - r1))`` after. Integrating it over each bin removes the
    aliasing of putting a whole patch in the bin of its centroid.

    Parameters
    ----------
    r : ndarray, shape (p, 3)
        The coordinate (slant range, or along-track position) at each patch corner, metres.
    bin_size : float
        Bin width b, metres.
    offset : float
        Where bin 0 starts, metres.

    Returns
    -------
    bins : ndarray, shape (p, k), int64
        Bin indices (``-1`` where unused).
    fractions : ndarray, shape (p, k)
        Share of the patch's area in each bin; rows sum to 1.
    """
    r0, r1, r2 = (c[:, None] for c in np.sort(r - offset, axis=1).T)  # columns over bins
    first = np.floor(r0[:, 0] / bin_size).astype(np.int64)
    last = np.floor(r2[:, 0] / bin_size).astype(np.int64)
    k = int((last - first).max(initial=0)) + 1
    span = r2 - r0
    tiny = span <= 1e-12 * np.maximum(r2, 1.0)
    d01 = np.where(tiny, 1.0, np.maximum(r1 - r0, 0.0) * np.where(tiny, 1.0, span))
    d12 = np.where(tiny, 1.0, np.maximum(r2 - r1, 0.0) * np.where(tiny, 1.0, span))

    def cdf(s: np.ndarray) -> np.ndarray:
        rising = (s - r0) ** 2 / np.where(d01 > 0, d01, 1.0)
        falling = 1.0 - (r2 - s) ** 2 / np.where(d12 > 0, d12, 1.0)
        out = np.where(s <= r1, np.where(d01 > 0, rising, 1.0), falling)
        out = np.where(s <= r0, 0.0, np.where(s >= r2, 1.0, out))
        return np.where(tiny, (s >= r0).astype(np.float64), out)

    bins = first[:, None] + np.arange(k)
    edges = bins * bin_size
    fractions = cdf(np.minimum(edges + bin_size, r2 + 1.0)) - cdf(edges)
    fractions = np.where(tiny, (np.arange(k) == 0).astype(np.float64), fractions)
    used = bins <= last[:, None]
    return np.where(used, bins, -1), np.where(used, fractions, 0.0)


def _deposit(
    sonar: Sonar,
    frame: Frame,
    acc: dict[str, np.ndarray],
    ping: np.ndarray,
    rbin: np.ndarray,
    starboard: np.ndarray,
    depression: np.ndarray,
    weight: np.ndarray,
) -> None:
    """Multiply by the beam and sum into the pings' range bins of each side."""
    n_bins = sonar.n_bins
    inside = (rbin >= 0) & (rbin < n_bins) & (weight > 0)
    ping, rbin, starboard = ping[inside], rbin[inside], starboard[inside]
    depression, weight = depression[inside], weight[inside]
    for side, sign, mask in (("starboard", 1.0, starboard), ("port", -1.0, ~starboard)):
        if side not in acc or not mask.any():
            continue
        rows = acc[side]
        if frame.spacing > 0:
            roll = frame.roll[ping[mask]]
            w = weight[mask] * _beam(sonar, depression[mask] - sonar.tilt - sign * roll)
            flat = (frame.first + ping[mask]) * n_bins + rbin[mask]
            lo = int(flat.min())
            sums = np.bincount(flat - lo, weights=w)
            rows.reshape(-1)[lo : lo + len(sums)] += sums  # a view: acc is C-contiguous
            continue
        for roll in np.unique(frame.roll):
            w = weight[mask] * _beam(sonar, depression[mask] - sonar.tilt - sign * roll)
            row = np.bincount(rbin[mask], weights=w, minlength=n_bins)
            pings = frame.first + np.flatnonzero(frame.roll == roll)
            rows[pings] += row


def _beam(sonar: Sonar, off_axis: np.ndarray) -> np.ndarray:
    """Two-way beam gain Φ at angles off the beam axis; 1 without evaluating a uniform beam."""
    if sonar.beam.is_uniform:
        return np.ones_like(off_axis)
    return sonar.beam(off_axis)
