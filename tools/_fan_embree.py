"""Ray-cast the GL renderer's fan with embree: the same rays, weights and range deposit, on the CPU.

Private helper of ``tools/bench_render.py``. For every (segment, side) draw the GL renderer
plans, each framebuffer texel is one ray: row ``r`` is ping ``first + r // along`` at along-track
offset ``((r + 1/2) / along - 1/2) * spacing`` from the segment origin, and column ``c`` has the
look angle ``Warp.columns`` gives it. Each ray is cast with embree (trimesh's
``RayMeshIntersector.intersects_first``: one nearest hit, front or back face); the hit distance
is recomputed in float64 from the hit face's plane, as the fragment shader does. A front-facing
hit (Lambert) weighs ``R · Φ(α − axis) dα · t · row_width`` and is deposited into range bins by
the rule of ``gl/range_accumulate.glsl``, in float64 instead of fixed point: "footprint"
shares it among the bins its patch of surface covers, whose ranges are spread like the sum of two
uniform variables (the range width cut by the column's edge rays, and that of the row's
along-track extent; a trapezoid, at most 16 bins wide); "nearest" puts it in the bin of the
patch's centre range; "linear" splits it between the two nearest bin centres.

The draw plan comes from the renderer itself (``RasterRenderer._plan`` and ``_columns_total``,
private), so the rays are exactly the GL ones; if those change, this module must follow.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from sonar_raster.image import SonarImage
from sonar_raster.rendering.gl.raster import RasterRenderer, RasterSettings
from sonar_raster.scene import Scene
from sonar_raster.sonar import Sonar
from sonar_raster.trajectory import Trajectory

MAX_SPREAD = 16  # as in range_accumulate.glsl
#: Spread a sample over its row's along-track range extent too (the trapezoid rule of
#: range_accumulate.glsl); False gives the earlier rule, uniform over the look-angle extent only.
ALONG_TRACK_SPREAD = True
_RAYS_PER_CHUNK = 1 << 21  # bounds memory to a few hundred MB


@dataclass
class FanTimes:
    """Where the time of one :meth:`EmbreeFan.render` went, seconds."""

    cast: float = 0.0
    deposit: float = 0.0
    rays: int = 0


class EmbreeFan:
    """An embree BVH of one scene, rendering the GL renderer's rays.

    Parameters
    ----------
    scene : Scene
        The scene; its vertices are shifted to the centre of its bounds before the float32 BVH.
    """

    def __init__(self, scene: Scene):
        import trimesh
        from trimesh.ray import ray_pyembree

        self.scene = scene
        self.local = scene.bounds.mean(axis=0)
        mesh = trimesh.Trimesh(
            scene.vertices - self.local, scene.faces, process=False, validate=False
        )
        self._caster = ray_pyembree.RayMeshIntersector(mesh)
        self._caster.intersects_first(np.zeros((1, 3)), np.array([[0.0, 0.0, -1.0]]))  # build BVH
        tri = scene.triangles() - self.local
        normal, _ = scene.face_normals_areas()
        self._normal = normal
        self._offset = np.einsum("ij,ij->i", normal, tri[:, 0])  # plane: n·p = offset
        self.times = FanTimes()

    def render(
        self,
        sonar: Sonar,
        trajectory: Trajectory,
        settings: RasterSettings,
        planner: RasterRenderer,
    ) -> SonarImage:
        """Render one (pings × bins) float32 image per side, like ``planner.render`` would.

        ``planner`` only supplies the draw plan (no GL work is done with it).
        """
        self.times = FanTimes()
        saved = planner.settings
        planner.settings = settings
        try:
            draws = planner._plan(self.scene, sonar, trajectory)
            totals = [planner._columns_total(d.warp, sonar) for d in draws]
        finally:
            planner.settings = saved
        acc = {s: np.zeros(trajectory.n_pings * sonar.n_bins) for s in sonar.sides}
        for draw, total in zip(draws, totals, strict=True):
            self._render_draw(draw, total, sonar, settings, acc[draw.side])
        sides = {}
        for side, flat in acc.items():
            image = flat.reshape(trajectory.n_pings, sonar.n_bins)
            for draw in draws:  # a stationary segment renders one row for all its pings
                seg = draw.segment
                if draw.side == side and draw.rows == 1 and seg.count > 1:
                    image[seg.first + 1 : seg.first + seg.count] = image[seg.first]
            sides[side] = image.astype(np.float32)
        return SonarImage(sides=sides, sonar=sonar, metadata={"renderer": "embree-fan"})

    def _render_draw(
        self, draw, total: int, sonar: Sonar, settings: RasterSettings, acc: np.ndarray
    ) -> None:
        seg = draw.segment
        along = settings.along_samples
        alpha, dalpha = draw.warp.columns(0, total, total)
        cols = _Columns.make(alpha, dalpha, sonar.beam(alpha - draw.beam_axis) * dalpha)
        planes = self._planes(draw)
        dirs = np.cos(alpha)[:, None] * draw.axis_side - np.sin(alpha)[:, None] * seg.up
        rows = draw.rows * along
        rows_per_chunk = max(1, _RAYS_PER_CHUNK // total)
        for lo in range(0, rows, rows_per_chunk):
            r = np.arange(lo, min(rows, lo + rows_per_chunk))
            y = ((r + 0.5) / along - 0.5) * draw.spacing  # along-track offset, metres
            origins = (seg.origin - self.local) + y[:, None] * seg.along
            start = time.perf_counter()
            face = np.asarray(
                self._caster.intersects_first(
                    np.repeat(origins, total, axis=0), np.tile(dirs, (len(r), 1))
                ),
                dtype=np.int64,
            )
            self.times.cast += time.perf_counter() - start
            self.times.rays += len(face)
            start = time.perf_counter()
            hit = np.flatnonzero(face >= 0)
            row, col = np.divmod(hit, total)
            front, footprint, w = _weigh(
                planes, face[hit], y[row], col, cols, seg.width / along, self.scene.reflectivity
            )
            ping = seg.first + r[row[front]] // along
            _deposit(acc, ping, footprint, w, sonar, settings.split)
            self.times.deposit += time.perf_counter() - start

    def _planes(self, draw) -> np.ndarray:
        """Face planes in the draw's frame: rows n·along, n·side, n·up and n·(p0 − origin)."""
        seg = draw.segment
        offset = self._offset - self._normal @ (seg.origin - self.local)
        return np.stack(
            [self._normal @ seg.along, self._normal @ draw.axis_side, self._normal @ seg.up, offset]
        )


@dataclass(frozen=True)
class _Columns:
    """Per framebuffer column: Φ(α − axis) dα, and cos, sin of its centre and edge angles.

    ``trig[k]`` holds (cos, sin) of the centre (k = 0), lower (1) and upper (2) edge angle.
    """

    phi_dalpha: np.ndarray
    trig: np.ndarray

    @classmethod
    def make(cls, alpha: np.ndarray, dalpha: np.ndarray, phi_dalpha: np.ndarray) -> _Columns:
        angles = np.stack([alpha, alpha - 0.5 * dalpha, alpha + 0.5 * dalpha])
        return cls(phi_dalpha, np.stack([np.cos(angles), np.sin(angles)], axis=1))


def _weigh(
    planes: np.ndarray,
    face: np.ndarray,
    y: np.ndarray,
    col: np.ndarray,
    cols: _Columns,
    row_width: float,
    reflectivity: np.ndarray,
):
    """Front-facing mask, then range footprint and weight of those hits (as the fragment shader).

    A ray at along-track offset ``y`` and depression ``a`` has direction (0, cos a, −sin a) in the
    draw's (along, side, up) frame; it meets the plane n·q = d at t = (d − n_along y) / (n·dir).
    The footprint is a centre range, the range width cut by the column's edge rays, and the range
    width of the row's along-track extent, ``|n_along / cos θ| · row_width``.
    """
    n_along, n_side, n_up, d = planes[:, face]
    num = d - n_along * y
    denom = n_side * cols.trig[0, 0, col] - n_up * cols.trig[0, 1, col]
    front = denom < -1e-9  # a front face (Lambert weight > 0); t > 0 as embree hit it
    n_along, n_side, n_up, num, denom, col = (
        v[front] for v in (n_along, n_side, n_up, num, denom, col)
    )
    t = num / denom
    ta = _plane_hit(n_side, n_up, num, cols.trig[1, :, col].T)
    tb = _plane_hit(n_side, n_up, num, cols.trig[2, :, col].T)
    lo = np.minimum(t, np.minimum(np.where(ta > 0, ta, t), np.where(tb > 0, tb, t)))
    hi = np.maximum(t, np.maximum(ta, tb))
    along = np.abs(n_along / denom) * row_width if ALONG_TRACK_SPREAD else np.zeros_like(t)
    w = reflectivity[face[front]] * cols.phi_dalpha[col] * t * row_width
    return front, _Footprint(0.5 * (lo + hi), hi - lo, along), w


@dataclass(frozen=True)
class _Footprint:
    """Centre slant range and the two range widths of each sample's patch, metres."""

    centre: np.ndarray
    width_angle: np.ndarray
    width_along: np.ndarray


def _plane_hit(n_side: np.ndarray, n_up: np.ndarray, num: np.ndarray, trig: np.ndarray):
    """Distance to the plane along depression (cos, sin) = ``trig``, or -1 (no front face)."""
    denom = n_side * trig[0] - n_up * trig[1]
    ok = denom < -1e-9
    return np.where(ok, num / np.where(ok, denom, -1.0), -1.0)


def _deposit(
    acc: np.ndarray, ping: np.ndarray, fp: _Footprint, w: np.ndarray, sonar: Sonar, split: str
) -> None:
    """Add weights to ``acc`` (flat pings × bins) by the rule of ``range_accumulate.glsl``."""
    centre = fp.centre / sonar.range_bin
    everyone = np.arange(len(w))
    if split == "footprint":
        pieces = _footprint_shares(
            centre, fp.width_angle / sonar.range_bin, fp.width_along / sonar.range_bin
        )
    elif split == "linear":
        c = np.floor(centre - 0.5)
        f = centre - 0.5 - c
        pieces = [(everyone, c, 1.0 - f), (everyone, c + 1.0, f)]
    else:
        pieces = [(everyone, np.floor(centre), np.ones_like(w))]
    for sel, b, share in pieces:
        ok = (b >= 0) & (b < sonar.n_bins) & (share > 0)
        sel = sel[ok]
        flat = ping[sel] * sonar.n_bins + b[ok].astype(np.int64)
        if len(flat) == 0:
            continue
        lo = int(flat.min())  # a chunk's pings are consecutive: add a short run
        sums = np.bincount(flat - lo, weights=w[sel] * share[ok])
        acc[lo : lo + len(sums)] += sums


def _footprint_shares(centre: np.ndarray, width_1: np.ndarray, width_2: np.ndarray):
    """Yield (samples, bin, share) arrays: the trapezoid of two uniform spreads (in bins).

    The total width is capped at ``MAX_SPREAD - 1`` bins keeping its shape, as the shader does.
    Bin ``k`` of the spread only visits the samples that reach it.
    """
    wa, wb = np.maximum(width_1, width_2), np.minimum(width_1, width_2)
    total = wa + wb
    shrink = np.where(total > MAX_SPREAD - 1, (MAX_SPREAD - 1) / np.maximum(total, 1e-300), 1.0)
    wa, wb, total = wa * shrink, wb * shrink, total * shrink
    narrow = total < 1e-4
    lo = centre - 0.5 * total
    first = np.where(narrow, np.floor(centre), np.floor(lo))
    shape = _Trapezoid(wa, wb)
    live = np.arange(len(centre))
    before = np.zeros(len(centre))
    for k in range(MAX_SPREAD + 1):
        s = first[live] + (k + 1) - lo[live]
        after = np.where(narrow[live], 1.0, shape.cdf(s, live))
        yield live, first[live] + k, after - before
        more = (s < total[live]) & ~narrow[live]
        live, before = live[more], after[more]
        if len(live) == 0:
            return


class _Trapezoid:
    """The sum of uniform spreads of widths ``wa >= wb`` (bins), as ``trapezoid_cdf`` in GLSL."""

    def __init__(self, wa: np.ndarray, wb: np.ndarray) -> None:
        self.wa, self.wb = wa, wb
        self.inv_a = 1.0 / np.where(wa > 0, wa, 1.0)
        self.inv_2ab = np.where(wb >= 1e-6, 0.5 * self.inv_a / np.where(wb > 0, wb, 1.0), 0.0)

    def cdf(self, s: np.ndarray, i: np.ndarray) -> np.ndarray:
        """Share below ``s`` (bins from the lower end) for samples ``i``."""
        wa, wb, inv_a, inv_2ab = self.wa[i], self.wb[i], self.inv_a[i], self.inv_2ab[i]
        u = wa + wb - s
        inner = np.where(
            s < wb,
            s * s * inv_2ab,
            np.where(s <= wa, (s - 0.5 * wb) * inv_a, 1.0 - u * u * inv_2ab),
        )
        inner = np.where(wb < 1e-6, s * inv_a, inner)
        return np.where(s <= 0.0, 0.0, np.where(s >= wa + wb, 1.0, inner))
