"""The GL renderer: scene + sonar + trajectory → raw side-scan intensity, on moderngl.

Pass 1 (``gl/ping_samples.glsl``) draws the scene once per straight track segment and
side into a (ping row × look-angle column) float framebuffer: each texel is one ray of the fan,
holding the slant range of its nearest hit (exact ray-plane intersection), the range spread of
its ray bundle on that plane (across the column's angle and along the row's width) and the
weight ``Φ R r dα dy`` (Lambert). The depth test keeps the nearest hit, so objects shadow what
lies behind them. Pass 2 (``gl/range_accumulate.glsl``) shares each weight among the range
bins its spread overlaps, with exact fixed-point integer atomics. This module and
:mod:`sonar_raster.rendering.gl.context` are the only ones that know OpenGL.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from ...errors import SonarRasterError, SonarRasterTypeError
from ...image import SonarImage
from ...scene import Scene
from ...sonar import Sonar
from ...trajectory import Segment, Trajectory
from .context import create_context, release_context
from .heightfield import Grid, find_grid
from .programs import specialise
from .subdivide import TooManyPieces, subdivide, subdivide_within, subdivision_counts
from .tiles import TileIndex
from .warp import Warp

log = logging.getLogger(__name__)

#: Most pieces subdivision may add (16.8 M: 0.6 GB of float32 corners, more in temporaries).
MAX_PIECES = 1 << 24


def _too_many(pieces: int, max_edge: float) -> SonarRasterError:
    """The one-line error for subdivision adding more than :data:`MAX_PIECES` triangles."""
    return SonarRasterError(
        f"the scene's triangles would be cut into over {pieces:,} pieces of at most "
        f"{max_edge:g} m: relief far too steep or a model far too large (check its units, "
        "amplitude or scale), or use a coarser --range-bin"
    )


#: Pieces per edge beyond which only the pieces of a triangle that the track can see are
#: made (256² = 65 536 pieces: a plane 256 × 20 range bins wide is left whole).
CLIP_COUNT = 256

MAX_TEXTURE = 16384
MAX_TEXELS = 1 << 26  # largest framebuffer per draw (64 M samples, 768 MiB of targets)
_FIXED_POINT_TOP = float(1 << 30)
_GL_DEPTH_CLAMP = 0x864F
_SPLITS = ("nearest", "linear", "footprint")
_RELEASED = "this renderer was released; make a new one"


@dataclass(frozen=True)
class RasterSettings:
    """Sampling settings of the GL renderer.

    Attributes
    ----------
    oversample : float
        Look-angle samples per range bin over flat ground at the nominal altitude.
    along_samples : int
        Rays per ping along track (rows per ping); their weights share the ping's width.
    split : {"footprint", "nearest", "linear"}
        How a sample's weight goes into range bins: spread over the range interval its ray
        bundle covers on the surface (exact for planar pieces), all into the bin holding its
        centre range, or split between the two nearest bin centres.
    max_edge : float or None
        Triangles with a longer edge (metres) are subdivided so their outlines follow the
        curved projection; None uses 20 range bins.
    near_nadir : float
        Floor of the warp's slope near nadir, as a fraction of the altitude (see ``_warp``).
    cull : bool
        Draw only the triangles near each draw's swath (default); False draws the whole scene
        every time (the baseline the scale benchmark compares against).
    heightfield : bool
        Find each ray's hit on a seabed grid (the faces of ``heightfield_mesh``) by a compute
        sweep along the fan instead of rasterising the grid's triangles (default), where the
        draw's fans are level and its pings lie over the grid and above its highest node;
        the other objects are rasterised as before and the nearer hit is kept. False
        rasterises the grid too (the baseline the render benchmark compares against).
    """

    oversample: float = 2.0
    along_samples: int = 2
    split: str = "footprint"
    max_edge: float | None = None
    near_nadir: float = 1.0
    cull: bool = True
    heightfield: bool = True

    def __post_init__(self) -> None:
        if not (math.isfinite(self.oversample) and 0 < self.oversample <= 64):
            raise SonarRasterError("oversample must be in (0, 64] samples per range bin")
        if not (isinstance(self.along_samples, int) and 1 <= self.along_samples <= 64):
            raise SonarRasterError("along_samples must be an integer from 1 to 64")
        if self.split not in _SPLITS:
            raise SonarRasterError(f"split must be one of {', '.join(_SPLITS)}")
        if self.max_edge is not None and not self.max_edge > 0:
            raise SonarRasterError("max_edge must be > 0 metres")


@dataclass(frozen=True)
class _Draw:
    """Everything one (segment, side) draw needs, computed on the CPU in float64."""

    segment: Segment
    side: str
    axis_side: np.ndarray
    motion: np.ndarray  # direction of travel in (fore, side, up) fan coordinates
    frame_sign: float
    warp: Warp
    beam_axis: float
    rows: int  # pings rendered (1 for a stationary segment)
    spacing: float  # along-track metres per ping row block


class RasterRenderer:
    """Owns one headless GL context and every GL object made on it.

    Use as a context manager, or call :meth:`release` (safe to call twice).

    Parameters
    ----------
    backend : {"egl", "osmesa"} or None
        GL backend; None reads ``SONAR_RASTER_GL`` then tries EGL and OSMesa.
    settings : RasterSettings
        Sampling settings.
    """

    def __init__(self, backend: str | None = None, settings: RasterSettings | None = None):
        if settings is not None and not isinstance(settings, RasterSettings):
            raise SonarRasterTypeError(
                "settings must be a RasterSettings (e.g. RasterSettings(oversample=4.0)) or "
                f"None, got {type(settings).__name__}"
            )
        self.settings = settings or RasterSettings()
        self.ctx, self.backend = create_context(backend)
        self._programs: dict[str, Any] = {}
        self._scene_key: tuple | None = None
        self._scene: Scene | None = None  # the uploaded scene (held, so its id cannot be reused)
        self._geometry: dict[str, Any] = {}
        self._targets: dict[str, Any] = {}

    # -- lifetime ---------------------------------------------------------------------------
    def release(self) -> None:
        """Release every GL object and the context."""
        if self.ctx is None:
            return
        with self.ctx:
            self._release_geometry()
            self._release_targets()
            for prog in self._programs.values():
                prog.release()
            self._programs.clear()
        release_context(self.ctx)
        self.ctx = None

    def __enter__(self) -> RasterRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    @property
    def gl_info(self) -> dict[str, str]:
        """Backend, renderer and version strings of the context."""
        if self.ctx is None:
            raise SonarRasterError(_RELEASED)
        return {
            "gl_backend": self.backend,
            "gl_renderer": self.ctx.info["GL_RENDERER"],
            "gl_version": self.ctx.info["GL_VERSION"],
        }

    def live_objects(self) -> list[str]:
        """Names of the GL objects this renderer holds now, for diagnostics and tests.

        Programs read ``"program <kind>"``, render targets ``"target <name>"`` and scene
        buffers ``"geometry <name>"``; anything that exists only for the object-id label pass
        has ``labels`` in its name.
        """
        names = [
            f"program {key.split(':')[0]}" + (" labels" if key.endswith(":1") else "")
            for key in self._programs
        ]
        names += [f"target {key}" for key in self._targets]
        names += [
            f"geometry {key.replace(':1', ' labels').replace(':0', '')}"
            for key, obj in self._geometry.items()
            if hasattr(obj, "release")
        ]
        return sorted(names)

    # -- programs ---------------------------------------------------------------------------
    def _program(self, kind: str, labels: bool = False) -> Any:
        scattering = self._geometry.get("scattering", 1) if kind != "accumulate" else 1
        # Pass 1 does not depend on the split: one program, so the scene's vertex array (made
        # with it, and drawing with it) never runs a program whose uniforms another split set.
        split = "any" if kind == "samples" else self.settings.split
        key = f"{kind}:{split}:{scattering}:{int(labels)}"
        if key not in self._programs:
            if kind == "samples":
                d = {"SCATTERING": scattering, "LABELS": int(labels)}
                self._programs[key] = self.ctx.program(
                    vertex_shader=specialise("ping_samples.glsl", "VERTEX_SHADER", d),
                    geometry_shader=specialise("ping_samples.glsl", "GEOMETRY_SHADER", d),
                    fragment_shader=specialise("ping_samples.glsl", "FRAGMENT_SHADER", d),
                )
            else:
                d = {
                    "SPLIT": _SPLITS.index(self.settings.split),
                    "LABELS": int(labels),
                    "SWEEP": int(kind == "sweep"),
                    "SWEEP_GROUP": _SWEEP_GROUP,
                    "SCATTERING": scattering,
                }
                self._programs[key] = self.ctx.compute_shader(
                    specialise("range_accumulate.glsl", "COMPUTE_SHADER", d)
                )
        return self._programs[key]

    # -- previews ---------------------------------------------------------------------------
    def draw_views(
        self,
        vertices: np.ndarray,
        faces: np.ndarray,
        views: list[tuple[np.ndarray, np.ndarray]],
        size: tuple[int, int],
        background: tuple[float, float, float],
    ) -> list[np.ndarray]:
        """Draw a shaded, grey-coloured mesh once per view (``preview.glsl``) on this context.

        Parameters
        ----------
        vertices : ndarray, shape (n, 7), float32
            Position (3), unit normal (3) and grey level in [0, 1] (1) per vertex.
        faces : ndarray, shape (m, 3), int32
            Vertex indices.
        views : list of (ndarray (4, 4), ndarray (3,))
            Model-view-projection matrix and unit light direction of each view.
        size : (int, int)
            Width and height in pixels.
        background : (float, float, float)
            RGB of the background, in [0, 1].

        Returns
        -------
        list of ndarray, each shape (height, width, 3), uint8
            Top row first, one per view.
        """
        if "preview" not in self._programs:
            self._programs["preview"] = self.ctx.program(
                vertex_shader=specialise("preview.glsl", "VERTEX_SHADER", {}),
                fragment_shader=specialise("preview.glsl", "FRAGMENT_SHADER", {}),
            )
        prog = self._programs["preview"]
        width, height = size
        images = []
        with self.ctx:
            vbo = self.ctx.buffer(np.ascontiguousarray(vertices, dtype="f4").tobytes())
            ibo = self.ctx.buffer(np.ascontiguousarray(faces, dtype="i4").tobytes())
            layout = [(vbo, "3f 3f 1f", "in_pos", "in_normal", "in_grey")]
            vao = self.ctx.vertex_array(prog, layout, ibo)
            fbo = self.ctx.simple_framebuffer((width, height), components=4)
            try:
                fbo.use()
                self.ctx.enable(self.ctx.DEPTH_TEST)
                for mvp, light in views:
                    fbo.clear(*background, 1.0, depth=1.0)
                    prog["mvp"].write(mvp.T.astype("f4").tobytes())
                    prog["light_dir"].value = tuple(float(v) for v in light)
                    vao.render()
                    raw = np.frombuffer(fbo.read(components=3), np.uint8)
                    images.append(raw.reshape(height, width, 3)[::-1].copy())
            finally:
                self.ctx.disable(self.ctx.DEPTH_TEST)
                for obj in (vao, fbo, vbo, ibo):
                    obj.release()
        return images

    # -- geometry ---------------------------------------------------------------------------
    def _release_geometry(self) -> None:
        for obj in self._geometry.values():
            if hasattr(obj, "release"):
                obj.release()
            elif isinstance(obj, dict):  # the objects' geometry of sweeping draws
                for inner in obj.values():
                    if hasattr(inner, "release"):
                        inner.release()
        self._geometry.clear()
        self._scene_key = None
        self._scene = None

    def _upload(
        self,
        scene: Scene,
        origin: np.ndarray,
        max_edge: float,
        box: tuple[float, ...] | None = None,
    ) -> None:
        """Shift the scene to ``origin`` (float64), subdivide long triangles, upload vertices.

        Triangles that subdivision would cut into more than ``CLIP_COUNT²`` pieces keep only
        the pieces that reach into ``box`` (local ``x0, x1, y0, y1, z0, z1``: what the track
        can see; :func:`subdivide_within`), so a model read in the wrong units, or a
        two-triangle plane kilometres wide, costs what the swath holds. More than
        :data:`MAX_PIECES` added pieces is a :class:`SonarRasterError`.

        Memory is kept near one float32 copy of the vertices: the index and reflectivity
        buffers of the whole scene are made only if a draw needs the whole scene, and labels
        only if asked for.
        """
        key = (tuple(origin), max_edge, box)
        if self._scene is scene and key == self._scene_key:
            return
        self._release_geometry()
        vertices = _local_float32(scene.vertices, origin)
        faces = scene.faces
        source = None  # scene face of each uploaded face, when subdivision reordered them
        counts = subdivision_counts(vertices, faces, max_edge)
        big = counts > 1
        if big.any():
            huge = (counts[big] > CLIP_COUNT) & (box is not None)
            uniform = int(np.sum(counts[big][~huge] ** 2))
            if uniform > MAX_PIECES:
                raise _too_many(uniform, max_edge)
            corners = vertices[faces[big]].astype(np.float64)
            if huge.any() and box is not None:  # only what the track can see is cut up
                try:  # one budget for both kinds of cuts
                    near, within = subdivide_within(
                        corners[huge], max_edge, box, MAX_PIECES - uniform
                    )
                except TooManyPieces as stop:
                    raise _too_many(uniform + int(stop.args[0]), max_edge) from None
                rest, whole = subdivide(corners[~huge], counts[big][~huge])
                pieces = np.concatenate([rest, near])
                parent = np.concatenate(
                    [np.flatnonzero(~huge)[whole], np.flatnonzero(huge)[within]]
                )
            else:
                pieces, parent = subdivide(corners, counts[big])
            extra = pieces.reshape(-1, 3).astype(np.float32)
            new_faces = len(vertices) + np.arange(len(extra)).reshape(-1, 3)
            vertices = np.concatenate([vertices, extra])
            faces = np.concatenate([faces[~big], new_faces.astype(faces.dtype)])
            source = np.concatenate([np.flatnonzero(~big), np.flatnonzero(big)[parent]])
            log.info("subdivided %d large triangles into %d", int(big.sum()), len(pieces))
        refl = scene.reflectivity if source is None else scene.reflectivity[source]
        law = None if scene.law is None or not scene.law.any() else scene.law
        if law is not None and source is not None:
            law = law[source]
        self._geometry = {
            "vertices": vertices,
            "faces_cpu": faces,
            "refl_cpu": refl,
            # Scattering law per face (SCATTERING 2: a per-material angular table), else None.
            "law_cpu": law,
            "scattering": 1 if law is None else 2,
            "r_max_law": _max_by_law(refl, law),
            "source": source,
            "max_edge": max_edge,
            "vbo": self.ctx.buffer(vertices),
            "n_faces": len(faces),
            "r_max": float(refl.max(initial=0.0)),
            # Height range of the vertices (local metres): bounds what tilted fans can see.
            "z_span": _z_span(vertices),
            **_grid_entries(scene, source, len(faces)),
        }
        self._scene_key = key
        self._scene = scene

    def _whole_objects(self) -> dict[str, Any]:
        """The uploaded faces outside the seabed grid, kept for every draw that sweeps."""
        geo = self._geometry
        if "objects" not in geo:
            whole = self._subset(np.flatnonzero(~geo["grid_mask"]))
            whole["subset"] = False  # kept with the scene, released with it
            geo["objects"] = whole
        return geo["objects"]

    def _whole_scene(self) -> dict[str, Any]:
        """The uploaded geometry with its whole-scene index and reflectivity buffers."""
        geo = self._geometry
        if "ibo" not in geo:
            geo["ibo"] = self.ctx.buffer(geo["faces_cpu"].astype("u4"))
            geo["faces"] = self.ctx.buffer(_face_data(geo["refl_cpu"], geo["law_cpu"], None))
        return geo

    def _law_texture(self, sonar: Sonar) -> None:
        """Per-material angular law table (materials x incidence angle) for this sonar.

        Also sets the geometry's ``r_max`` (largest reflectivity times law factor) that bounds
        the fixed-point scale. A no-op besides that for Lambert-only scenes.
        """
        geo = self._geometry
        if geo.get("scattering", 1) == 1:
            geo["r_max"] = float(geo["r_max_law"][0]) if len(geo["r_max_law"]) else 0.0
            return
        from ...scenes.sediments import law_tables

        table = law_tables(sonar.frequency_hz, sonar.sound_speed)
        key = (sonar.frequency_hz, sonar.sound_speed)
        if geo.get("laws_key") != key:
            if "laws" in geo:
                geo["laws"].release()
            rows, cols = table.shape
            data = np.ascontiguousarray(table, dtype="f4").tobytes()
            geo["laws"] = self.ctx.texture((cols, rows), 1, data, dtype="f4")
            geo["laws_key"] = key
        used = geo["r_max_law"]
        geo["r_max"] = float(np.max(used * table[: len(used)].max(axis=1), initial=0.0))

    def _face_labels(self, ids: np.ndarray | None) -> np.ndarray:
        """Labels (object id + 1; 0 means "no return") of uploaded faces ``ids`` (None: all)."""
        source = self._geometry["source"]
        if source is not None:
            ids = source if ids is None else source[ids]
        object_id = self._scene.object_id if self._scene is not None else np.zeros(0, np.int32)
        return (object_id if ids is None else object_id[ids]).astype(np.uint32) + 1

    def _vao(self, geometry: dict[str, Any], labels: bool) -> Any:
        """The vertex array of ``geometry`` for the pass-1 program (made on first use)."""
        key = f"vao:{int(labels)}"
        if key not in geometry:
            geometry[key] = self.ctx.vertex_array(
                self._program("samples", labels),
                [(self._geometry["vbo"], "3f", "in_pos")],
                index_buffer=geometry["ibo"],
                index_element_size=4,
            )
            if geometry.get("empty"):
                geometry[key].vertices = 0
        return geometry[key]

    def _labels_buffer(self, geometry: dict[str, Any], ids: np.ndarray | None) -> Any:
        """Per-face labels (object id + 1) as a storage buffer, made on first use."""
        if "labels" not in geometry:
            data = self._face_labels(ids)
            geometry["labels"] = self.ctx.buffer(data if len(data) else b"\0" * 4)
        return geometry["labels"]

    def _release_targets(self) -> None:
        for obj in self._targets.values():
            obj.release()
        self._targets.clear()

    def _framebuffer(self, width: int, height: int, labels: bool) -> dict[str, Any]:
        """Sample targets at least this size, reused across draws (each draws in a viewport).

        With ``labels`` a second, uint32 target holds each texel's label; it is kept once made
        (a draw without labels leaves it untouched and nothing reads it).
        """
        if self._targets:
            old_w, old_h = self._targets["color"].size
            has_labels = "labels" in self._targets
            if old_w >= width and old_h >= height and (has_labels or not labels):
                return self._targets
            width, height = max(width, old_w), max(height, old_h)
            labels = labels or has_labels
        color = self.ctx.texture((width, height), 4, dtype="f4")
        attachments = [color]
        if labels:
            attachments.append(self.ctx.texture((width, height), 1, dtype="u4"))
        depth = self.ctx.depth_texture((width, height))
        depth.compare_func = ""  # pass 2 reads the depth itself: < 1 where a fragment landed
        fbo = self.ctx.framebuffer(attachments, depth)
        fbo.use()  # bind the new one first: releasing a bound framebuffer upsets moderngl
        self._release_targets()
        self._targets = {"fbo": fbo, "color": color, "depth": depth}
        if labels:
            self._targets["labels"] = attachments[1]
        return self._targets

    # -- planning ---------------------------------------------------------------------------
    def _plan(self, scene: Scene, sonar: Sonar, trajectory: Trajectory) -> list[_Draw]:
        tol = sonar.range_bin / 4.0
        along = self.settings.along_samples
        max_rows = (
            max(1, min(MAX_TEXTURE, MAX_TEXELS // self._columns_total_estimate(sonar))) // along
        )
        draws = []
        # Fans of one draw share an orientation: their spread moves far-range points along
        # track by max_range x angle; keep that under half a ping (0.05 to 0.5 degrees).
        angle = min(max(0.5 * trajectory.typical_spacing / sonar.max_range, 8.7e-4), 8.7e-3)
        for seg in trajectory.segments(tol, max_count=max(1, max_rows), angle_tolerance=angle):
            roll = float(np.mean(trajectory.roll[seg.first : seg.first + seg.count]))
            draws += self._plan_segment(scene, sonar, seg, roll)
        return draws

    def _columns_total_estimate(self, sonar: Sonar) -> int:
        return min(MAX_TEXTURE, int(math.ceil(self.settings.oversample * sonar.n_bins * 1.2)) + 1)

    def _columns_total(self, warp: Warp, sonar: Sonar) -> int:
        rho_lo, rho_hi = warp.rho_range
        return max(
            8, int(math.ceil(self.settings.oversample * (rho_hi - rho_lo) / sonar.range_bin))
        )

    # -- rendering --------------------------------------------------------------------------
    def render(
        self,
        scene: Scene,
        sonar: Sonar,
        trajectory: Trajectory,
        progress: bool = False,
        labels: bool = False,
    ) -> SonarImage:
        """Render one image per side.

        Parameters
        ----------
        scene : Scene
        sonar : Sonar
        trajectory : Trajectory
        progress : bool
            Show a progress bar over the draws.
        labels : bool
            Also label each cell with the object its largest share of weight came from
            (``SonarImage.labels``); off, no label work is done at all.

        Returns
        -------
        SonarImage
            float32 (pings × bins) per side; see :class:`SonarImage` for units.
        """
        chunks = self.render_chunks(
            scene, sonar, trajectory, trajectory.n_pings, progress=progress, labels=labels
        )
        return next(iter(chunks))

    def render_chunks(
        self,
        scene: Scene,
        sonar: Sonar,
        trajectory: Trajectory,
        chunk_pings: int = 1024,
        *,
        progress: bool = False,
        labels: bool = False,
    ) -> Iterator[SonarImage]:
        """Render the track in blocks of pings, yielding each block's image as it finishes.

        Memory stays bounded by the block, not the track: write each block out (see
        :class:`.survey.ExrStreamWriter`) and drop it. The track is split into straight
        segments once for the whole track, then cut at block edges, so the blocks put together
        equal :meth:`render` of the whole track to float32 rounding. Each draw draws only the
        triangles near its block's swath (a tile index over the scene), and a draw with no
        triangle near it is skipped. Rendering another scene with this renderer between two
        blocks is allowed: the next block uploads its scene again.

        Parameters
        ----------
        scene, sonar, trajectory, progress, labels
            As for :meth:`render`.
        chunk_pings : int
            Pings per block, >= 1.

        Yields
        ------
        SonarImage
            Rows ``metadata["first_ping"]`` onwards of the track; ``metadata["counters"]``
            counts what the block drew and skipped.
        """
        if self.ctx is None:
            raise SonarRasterError(_RELEASED)
        if not (isinstance(chunk_pings, (int, np.integer)) and chunk_pings >= 1):
            raise SonarRasterError(f"chunk_pings must be a positive integer, got {chunk_pings!r}")
        with self.ctx:
            origin = trajectory.positions[0].copy()
            max_edge = self.settings.max_edge or 20.0 * sonar.range_bin
            local = trajectory.positions - origin
            reach = sonar.max_range + max_edge  # no echo comes from further than max_range
            lo, hi = local.min(axis=0) - reach, local.max(axis=0) + reach
            box = tuple(float(v) for v in (lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]))
            self._upload(scene, origin, max_edge, box)
            plan = self._plan(scene, sonar, trajectory)
            if self.settings.cull and self._rasters(plan, sonar):
                # built now, before the sample targets take their memory
                self._tile_index(self._reach(sonar))
        for first in range(0, trajectory.n_pings, int(chunk_pings)):
            last = min(trajectory.n_pings, first + int(chunk_pings))
            draws = [d for d in (_clip(d, first, last) for d in plan) if d is not None]
            with self.ctx:
                # A render of another scene between two blocks replaced the uploaded one:
                # upload this generator's scene again (a no-op when it is still there).
                self._upload(scene, origin, max_edge, box)
                image = self._render_block(
                    scene, sonar, draws, origin, (first, last), progress, labels
                )
            yield image

    def _render_block(
        self,
        scene: Scene,
        sonar: Sonar,
        draws: list[_Draw],
        origin: np.ndarray,
        pings: tuple[int, int],
        progress: bool,
        labels: bool,
    ) -> SonarImage:
        """Render pings ``pings[0] .. pings[1] - 1`` from their draws."""
        tables = [self._column_tables(d, sonar) for d in draws]
        self._law_texture(sonar)
        scale = self._fixed_point_scale(draws, tables, sonar.max_range, sonar.range_bin)
        first_ping = pings[0]
        n_pings, n_bins = pings[1] - pings[0], sonar.n_bins
        counters = {"draws": 0, "draws_skipped_empty": 0, "triangles_drawn": 0}
        swept = 0
        sweeps = [self._sweeps(d, sonar) for d in draws]
        raster = [
            (tiles, d)
            for d, tiles, sweep in zip(draws, tables, sweeps, strict=True)
            if not sweep or self._has_objects()
        ]
        self._framebuffer(  # (1 texel when every draw sweeps a grid that stands alone)
            max((t[1] for tiles, _ in raster for t in tiles), default=1),
            max((d.rows for _, d in raster), default=1) * self.settings.along_samples,
            labels,
        )
        cells = {side: self.ctx.buffer(reserve=n_pings * n_bins * 8) for side in sonar.sides}
        if labels:
            for side in sonar.sides:
                cells[f"{side}:labels"] = self.ctx.buffer(reserve=n_pings * n_bins * 4)
        for buf in cells.values():
            buf.clear()
        try:
            items = list(zip(draws, tables, sweeps, strict=True))
            if progress:
                from tqdm import tqdm

                items = tqdm(items, desc="rendering", unit="draw", disable=None, leave=False)
            for draw, table, sweep in items:
                geometry = self._geometry_for(draw, sonar, origin, objects_only=sweep)
                try:
                    if geometry["n_faces"] == 0 and not sweep:
                        counters["draws_skipped_empty"] += 1
                        continue
                    self._draw(
                        draw, table, origin, sonar, scale, cells, geometry, labels, first_ping,
                        sweep,
                    )  # fmt: skip
                    counters["draws"] += 1
                    swept += int(sweep)
                    counters["triangles_drawn"] += int(geometry["n_faces"])
                finally:
                    self._release_subset(geometry)
            shape = (first_ping, n_pings, n_bins)
            sides = {s: self._read(cells[s], draws, scale, shape, s) for s in sonar.sides}
            label_images = None
            if labels:
                label_images = {
                    s: self._read_labels(cells[f"{s}:labels"], draws, shape, s) for s in sonar.sides
                }
        finally:
            for buf in cells.values():
                buf.release()
        meta = {
            "renderer": "gl",
            "settings": asdict(self.settings),
            **self.gl_info,
            "draws": len(draws),
            "triangles": int(self._geometry["n_faces"]),
            "first_ping": first_ping,
            "counters": counters,
            # draws whose seabed grid was swept instead of rasterised (RasterSettings.heightfield)
            "grid_sweeps": swept,
        }
        if labels:
            meta["label_names"] = ["(no return)", *scene.names]
        return SonarImage(sides=sides, sonar=sonar, metadata=meta, labels=label_images)

    def _column_tables(self, draw: _Draw, sonar: Sonar) -> list[tuple[int, int, int, np.ndarray]]:
        """Per column tile: (first column, count, total, (alpha, Φ dα) float32 array)."""
        total = self._columns_total(draw.warp, sonar)
        out = []
        for first in range(0, total, MAX_TEXTURE):
            count = min(MAX_TEXTURE, total - first)
            alpha, dalpha = draw.warp.columns(first, count, total)
            phi = sonar.beam(alpha - draw.beam_axis)
            table = np.stack([alpha, phi * dalpha, 0.5 * dalpha, np.zeros_like(alpha)], axis=1)
            out.append((first, count, total, table.astype("f4")))
        return out

    def _fixed_point_scale(
        self, draws: list[_Draw], tables: list, max_range: float, range_bin: float
    ) -> float:
        """Fixed-point units per weight unit: the largest possible sample weight maps to 2^30.

        Only samples whose spread reaches the image are deposited, so their range is below the
        maximum range plus half the largest spread (``MAX_SPREAD`` = 16 bins in the shader).
        """
        reach = max_range + 16.0 * range_bin
        bound = 0.0
        for draw, tiles in zip(draws, tables, strict=True):
            phid = max(float(t[3][:, 1].max()) for t in tiles)
            row_width = draw.segment.width / self.settings.along_samples
            bound = max(bound, self._geometry["r_max"] * phid * reach * row_width)
        return _FIXED_POINT_TOP / bound if bound > 0 else 1.0

    @staticmethod
    def _pass1_uniforms(draw: Any, origin: np.ndarray, far: float, along: int) -> dict:
        """Uniforms of the pass-1 (samples) program for one draw, ``along`` rows per ping."""
        seg = draw.segment
        return {
            "seg_origin": tuple((seg.origin - origin).astype("f4")),
            "axis_along": tuple(seg.fore),
            "motion": tuple(draw.motion),
            "axis_side": tuple(draw.axis_side),
            "axis_up": tuple(seg.up),
            "warp_h": draw.warp.h,
            "warp_c": draw.warp.c,
            "alpha0": draw.warp.alpha0,
            "rho0": draw.warp.rho0,
            "slope0": draw.warp.slope0,
            "row_scale": 2.0 / (draw.spacing * draw.rows),
            "row_offset": 1.0 / draw.rows - 1.0,
            "far_range": far,
            # A triangle can only span more than pi of look angle by wrapping over the top.
            "alpha_span_max": math.pi,
            "spacing": draw.spacing,
            "rows_per_ping": float(along),
            "row_width": seg.width / along,
            # -1 when the (along, side, up) frame is left-handed: flips the computed normals.
            "frame_sign": draw.frame_sign,
        }

    def _draw(
        self,
        draw: _Draw,
        tiles: list,
        origin: np.ndarray,
        sonar: Sonar,
        scale: float,
        cells: dict[str, Any],
        geometry: dict[str, Any],
        labels: bool,
        ping_base: int,
        sweep: bool = False,
    ) -> None:
        comp = self._program("sweep" if sweep else "accumulate", labels)
        buffers = self._sweep_inputs(comp, draw, tiles, origin, sonar, labels) if sweep else ()
        try:
            self._draw_tiles(
                draw, tiles, origin, sonar, scale, cells, geometry, labels, ping_base, sweep
            )
        finally:
            for buf in buffers:
                buf.release()

    def _draw_tiles(
        self,
        draw: _Draw,
        tiles: list,
        origin: np.ndarray,
        sonar: Sonar,
        scale: float,
        cells: dict[str, Any],
        geometry: dict[str, Any],
        labels: bool,
        ping_base: int,
        sweep: bool,
    ) -> None:
        ctx = self.ctx
        seg = draw.segment
        along = self.settings.along_samples
        height = draw.rows * along
        prog = self._program("samples", labels)
        comp = self._program("sweep" if sweep else "accumulate", labels)
        vao = self._vao(geometry, labels)
        has_raster = int(geometry["n_faces"] > 0)
        far = 1.5 * sonar.max_range
        rho_lo_all, rho_hi_all = draw.warp.rho_range
        uniforms = self._pass1_uniforms(draw, origin, far, along)
        for name, value in uniforms.items():
            if name in prog:
                prog[name].value = value
        geometry["faces"].bind_to_storage_buffer(0)
        if "laws" in self._geometry:
            self._geometry["laws"].use(location=_LAW_UNIT)
            prog["laws"].value = _LAW_UNIT
        if labels:
            self._labels_buffer(geometry, geometry.get("ids")).bind_to_storage_buffer(2)
            cells[f"{draw.side}:labels"].bind_to_storage_buffer(3)
            self._targets["labels"].use(location=3)
            comp["sample_labels"].value = 3
        ctx.enable_direct(_GL_DEPTH_CLAMP)
        targets = self._targets
        fbo = targets["fbo"]
        for first, count, total, table in tiles:
            d_rho = (rho_hi_all - rho_lo_all) / total
            prog["rho_lo"].value = rho_lo_all + first * d_rho
            prog["rho_hi"].value = rho_lo_all + (first + count) * d_rho
            col_tex = ctx.texture((count, 1), 4, table.tobytes(), dtype="f4")
            try:
                if has_raster:
                    self._raster_tile(fbo, count, height, col_tex, prog, vao)
                targets["color"].use(location=0)
                targets["depth"].use(location=2)
                cells[draw.side].bind_to_storage_buffer(1)
                comp["samples"].value = 0
                comp["depth"].value = 2
                comp["size"].value = (count, height)
                comp["rows_per_ping"].value = along
                comp["ping_offset"].value = seg.first - ping_base
                comp["n_bins"].value = sonar.n_bins
                comp["inv_bin"].value = 1.0 / sonar.range_bin
                comp["scale"].value = scale
                if sweep:
                    comp["col_first"].value = first
                    comp["has_raster"].value = has_raster
                    chunk = self._sweep_chunk(draw, sonar)
                    comp["chunk"].value = chunk
                    for begin in range(0, count, chunk):
                        comp["col_begin"].value = begin
                        comp.run(group_x=-(-height // _SWEEP_GROUP))
                        ctx.memory_barrier()
                else:
                    comp.run(group_x=(count + 63) // 64, group_y=(height + 3) // 4)
                ctx.memory_barrier()
            finally:
                col_tex.release()

    def _raster_tile(
        self, fbo: Any, count: int, height: int, col_tex: Any, prog: Any, vao: Any
    ) -> None:
        """Pass 1 of one column tile into the sample targets (depth cleared first)."""
        ctx = self.ctx
        fbo.use()
        fbo.viewport = (0, 0, count, height)
        # Clear the depth only: pass 2 skips texels whose depth stayed at 1, so stale
        # colour from an earlier draw is never read (and the colour clear is saved).
        n_targets = len(fbo.color_attachments)
        fbo.color_mask = _masks(False, n_targets)
        fbo.use()  # moderngl applies the colour mask when the framebuffer is bound
        fbo.clear(depth=1.0, viewport=(0, 0, count, height))
        fbo.color_mask = _masks(True, n_targets)
        fbo.use()
        ctx.enable(ctx.DEPTH_TEST)
        col_tex.use(location=1)
        prog["columns"].value = 1
        vao.render(mode=ctx.TRIANGLES)

    # -- the heightfield sweep --------------------------------------------------------------
    def _has_objects(self) -> bool:
        """Whether the uploaded scene has faces outside its seabed grid (or no grid)."""
        mask = self._geometry.get("grid_mask")
        return mask is None or not bool(mask.all())

    def _rasters(self, draws: list[_Draw], sonar: Sonar) -> bool:
        """Whether any of these draws rasterises triangles."""
        return self._has_objects() or not all(self._sweeps(d, sonar) for d in draws)

    def _sweeps(self, draw: _Draw, sonar: Sonar) -> bool:
        """Whether the seabed grid's hits of this draw come from the sweep.

        The fans must be level (their up axis vertical: the trace of a fan on the grid is a
        straight line), and every row's origin must lie over the grid, above its highest node.
        """
        grid: Grid | None = self._geometry.get("grid")
        if grid is None or not self.settings.heightfield:
            return False
        seg = draw.segment
        if abs(float(seg.fore[2])) > 1e-12 or abs(float(seg.up[2]) - 1.0) > 1e-12:
            return False
        along = self.settings.along_samples
        rows = draw.rows * along
        ends = np.array([((r + 0.5) / along - 0.5) * draw.spacing for r in (0, rows - 1)])
        points = seg.origin[None, :] + ends[:, None] * seg.along[None, :]
        if not (grid.contains(points[:, :2]) and bool(np.all(points[:, 2] > grid.z_max))):
            return False
        # a walk that alone would use most of a dispatch's loop budget: rasterise instead
        return self._walk_cells(draw, sonar) < _LOOP_BUDGET // 2

    def _walk_cells(self, draw: _Draw, sonar: Sonar) -> int:
        """Most grid cells one row's walk can cross before it stops (``s_stop``), plus slack."""
        grid: Grid = self._geometry["grid"]
        side = draw.axis_side
        reach = sonar.max_range + 16.0 * sonar.range_bin
        e = grid.inverse @ side[:2]  # grid units per metre along the trace
        return int(math.ceil(reach * (abs(float(e[0])) + abs(float(e[1]))))) + 4

    def _sweep_chunk(self, draw: _Draw, sonar: Sonar) -> int:
        """Columns per sweep dispatch that keep an invocation under llvmpipe's loop budget."""
        spare = _LOOP_BUDGET - 1000 - self._walk_cells(draw, sonar)
        return max(64, spare // _ITERATIONS_PER_COLUMN)

    def _sweep_inputs(
        self, comp: Any, draw: _Draw, tiles: list, origin: np.ndarray, sonar: Sonar, labels: bool
    ) -> Any:
        """Bind the grid, the draw's column table and the sweep's uniforms.

        Returns the column table's and the walk state's buffers, for the caller to release
        after the draw.
        """
        geo = self._geometry
        grid: Grid = geo["grid"]
        seg = draw.segment
        if "grid_faces" not in geo:
            ids = np.arange(grid.first_face, grid.first_face + grid.n_faces)
            law = None if self._scene is None or self._scene.law is None else self._scene.law
            refl = self._scene.reflectivity if self._scene is not None else np.zeros(0)
            geo["grid_faces"] = self.ctx.buffer(_face_data(refl, law, ids))
        geo["vbo"].bind_to_storage_buffer(4)
        geo["grid_faces"].bind_to_storage_buffer(5)
        trig = self.ctx.buffer(_column_trig(tiles))
        trig.bind_to_storage_buffer(6)
        rows = draw.rows * self.settings.along_samples
        state = self.ctx.buffer(reserve=rows * 32)
        state.bind_to_storage_buffer(7)
        local = np.array([grid.x0, grid.y0]) - origin[:2]
        uniforms = {
            "grid_n": (grid.nx, grid.ny),
            "grid_v0": grid.first_vertex,
            "grid_origin": tuple(local.astype("f4")),
            "grid_inverse": tuple(grid.inverse.T.reshape(-1)),  # column-major mat2
            "grid_winding": float(grid.winding),
            "seg_origin": tuple((seg.origin - origin).astype("f4")),
            "axis_along": tuple(seg.fore),
            "axis_side": tuple(draw.axis_side),
            "axis_up": tuple(seg.up),
            "motion": tuple(draw.motion),
            "travel": tuple(seg.along),
            "frame_sign": draw.frame_sign,
            "spacing": draw.spacing,
            "row_width": seg.width / self.settings.along_samples,
            "far_range": 1.5 * sonar.max_range,
            "s_stop": sonar.max_range + 16.0 * sonar.range_bin,
            "grid_label": grid.object_id + 1,
        }
        for name, value in uniforms.items():
            if name in comp:
                comp[name].value = value
        if "laws" in geo:
            comp["laws"].value = _LAW_UNIT
        return trig, state

    # -- range maps (visibility for the CPU models) ----------------------------------------
    def fan_ranges(
        self,
        scene: Scene,
        sonar: Sonar,
        segment: Segment,
        side: str,
        t0: float,
        dt: float,
        rows: int,
        origin: np.ndarray,
    ) -> tuple[np.ndarray, Warp, int]:
        """Slant range of the first surface along every ray of a fan swept along a segment.

        Pass 1 alone (no accumulation): row ``i`` is the fan at travel ``t0 + i dt`` from the
        segment's first ping, column ``c`` the look angle of the warp's column ``c``; the depth
        test keeps the nearest hit, so a surface point at slant range r is hidden when the rays
        around it all stop short of r. Used by the coherent model for its visibility.

        Parameters
        ----------
        scene, sonar : Scene, Sonar
            What is drawn, and the range reach and sampling (``settings.oversample`` columns per
            range bin over flat ground).
        segment : Segment
            The straight piece of track whose fans are swept.
        side : {"port", "starboard"}
            The side looked at.
        t0, dt : float
            Travel of row 0 from the segment's first ping, and between rows, metres (dt > 0).
        rows : int
            Rows, 1 to ``MAX_TEXTURE``.
        origin : ndarray, shape (3,)
            Local origin subtracted from the scene (float64) before upload, world metres.

        Returns
        -------
        ranges : ndarray, shape (rows, columns), float32
            Slant range of the nearest hit, metres; +inf where a ray meets nothing.
        warp : Warp
            The look-angle warp of the columns.
        columns : int
            Column count (the warp's ``total``).
        """
        if not (dt > 0 and 1 <= rows <= MAX_TEXTURE):
            raise SonarRasterError(f"fan_ranges needs dt > 0 and 1..{MAX_TEXTURE} rows")
        piece = replace(
            segment,
            origin=segment.origin + t0 * segment.along,
            spacing=float(dt),
            width=float(dt),
            count=int(rows),
        )
        with self.ctx:
            self._upload(scene, origin, self.settings.max_edge or 20.0 * sonar.range_bin)
            draw = next(d for d in self._plan_segment(scene, sonar, piece, 0.0) if d.side == side)
            tables = self._column_tables(draw, sonar)
            self._framebuffer(max(t[1] for t in tables), rows, False)
            geometry = self._geometry_for(draw, sonar, origin)
            out = []
            try:
                for first, count, total, table in tables:
                    if geometry["n_faces"] == 0:
                        out.append(np.full((rows, count), np.inf, np.float32))
                        continue
                    out.append(
                        self._draw_ranges(
                            draw, (first, count, total, table), origin, sonar, geometry
                        )
                    )
            finally:
                self._release_subset(geometry)
        return np.concatenate(out, axis=1), draw.warp, tables[0][2]

    def _plan_segment(self, scene: Scene, sonar: Sonar, seg: Segment, roll: float) -> list[_Draw]:
        """The draws (one per side) of one segment; a stationary one renders a single row."""
        altitude = float(seg.origin[2] - scene.ground_z)
        # Nothing at or below the scene's top within the image's reach (max range plus the
        # largest spread of a sample, 8 bins) lies at a smaller depression than this.
        reach = sonar.max_range + 8.0 * sonar.range_bin
        alpha_top = _alpha_top(seg, float(scene.bounds[1, 2]), reach)
        warp = Warp.make(altitude, sonar.max_range, alpha_top, self.settings.near_nadir)
        stationary = seg.spacing == 0.0
        draws = []
        for side in sonar.sides:
            sign = 1.0 if side == "starboard" else -1.0
            axis_side = sign * seg.starboard
            det = float(np.linalg.det(np.stack([seg.fore, axis_side, seg.up])))
            motion = np.array([seg.along @ seg.fore, seg.along @ axis_side, seg.along @ seg.up])
            draws.append(
                _Draw(
                    segment=seg,
                    side=side,
                    axis_side=axis_side,
                    motion=motion,
                    frame_sign=det,
                    warp=warp,
                    beam_axis=sonar.tilt + sign * roll,
                    rows=1 if stationary else seg.count,
                    spacing=seg.width if stationary else seg.spacing,
                )
            )
        return draws

    def _draw_ranges(
        self, draw: _Draw, tile: tuple, origin: np.ndarray, sonar: Sonar, geometry: dict
    ) -> np.ndarray:
        """Pass 1 of one column tile; the sample targets' slant ranges (inf: no hit)."""
        ctx = self.ctx
        first, count, total, table = tile
        prog = self._program("samples", False)
        vao = self._vao(geometry, False)
        rho_lo_all, rho_hi_all = draw.warp.rho_range
        d_rho = (rho_hi_all - rho_lo_all) / total
        uniforms = self._pass1_uniforms(draw, origin, 1.5 * sonar.max_range, 1)
        uniforms["rho_lo"] = rho_lo_all + first * d_rho
        uniforms["rho_hi"] = rho_lo_all + (first + count) * d_rho
        for name, value in uniforms.items():
            if name in prog:
                prog[name].value = value
        geometry["faces"].bind_to_storage_buffer(0)
        ctx.enable_direct(_GL_DEPTH_CLAMP)
        fbo = self._targets["fbo"]
        col_tex = ctx.texture((count, 1), 4, table.tobytes(), dtype="f4")
        try:
            fbo.use()
            fbo.viewport = (0, 0, count, draw.rows)
            fbo.clear(depth=1.0, viewport=(0, 0, count, draw.rows))
            ctx.enable(ctx.DEPTH_TEST)
            col_tex.use(location=1)
            prog["columns"].value = 1
            vao.render(mode=ctx.TRIANGLES)
            viewport = (0, 0, count, draw.rows)
            color = np.frombuffer(
                fbo.read(viewport=viewport, components=4, dtype="f4"), dtype=np.float32
            ).reshape(draw.rows, count, 4)[:, :, 0]
            depth = np.frombuffer(
                fbo.read(viewport=viewport, components=1, attachment=-1, dtype="f4"),
                dtype=np.float32,
            ).reshape(draw.rows, count)
        finally:
            col_tex.release()
        return np.where(depth < 1.0, color, np.float32(np.inf)).astype(np.float32)

    # -- culling ----------------------------------------------------------------------------
    def _geometry_for(
        self, draw: _Draw, sonar: Sonar, origin: np.ndarray, objects_only: bool = False
    ) -> dict[str, Any]:
        """The uploaded scene, or only its triangles that can reach this draw's image.

        With ``objects_only`` the seabed grid's faces are left out (the sweep finds their hits).

        A triangle can reach the image when one of its points lies in the draw's fan
        coordinates ``(u, s, v)`` (``Segment.shear``: travel, to the side, up in the fan plane;
        every attitude the fans have, crab and pitch included, is in that map) within the
        along-track window of the rows, on the draw's side (``s >= 0``) and within the reach
        ``hypot(s, v)``. Every point of a triangle lies within ``L / sqrt(3)`` of one of its
        corners (``L`` its longest edge: the circumradius of an acute triangle, at most half
        the longest edge otherwise), so within ``‖shear‖ L / sqrt(3)`` in fan coordinates, and
        a corner test widened by that margin keeps every such triangle. Candidates come from
        a tile index over the plane: the horizontal bounding box of the fan-coordinate box
        (its ``v`` bounded by the scene's heights, :func:`_swath_box`) widened by ``L``. When
        half the scene or more is kept, the whole scene is drawn and nothing is uploaded.
        """
        geo = self._geometry
        if objects_only and not self._has_objects():
            return self._whole_objects()  # empty: the grid is the whole scene
        if not self.settings.cull:
            return self._whole_objects() if objects_only else self._whole_scene()
        seg = draw.segment
        shear = seg.shear  # (travel, starboard, up) of a point relative to the segment origin
        margin = geo["max_edge"] * float(np.linalg.norm(shear, 2)) / math.sqrt(3.0)
        t_lo = -0.5 * seg.width - margin
        t_hi = (seg.count - 1) * seg.spacing + 0.5 * seg.width + margin
        reach = self._reach(sonar) - geo["max_edge"] + margin
        start = seg.origin - origin
        box = _swath_box(seg, draw.axis_side, start, (t_lo, t_hi), margin, reach, geo["z_span"])
        index = self._tile_index(self._reach(sonar))
        candidates = index.query(*box, geo["max_edge"])
        if objects_only:
            candidates = candidates[~geo["grid_mask"][candidates]]
        if len(candidates) > 0.5 * geo["n_faces"]:
            # most of the scene is near: the exact test cannot pay
            return self._whole_objects() if objects_only else self._whole_scene()
        f = geo["faces_cpu"][candidates]
        rel = geo["vertices"][f.reshape(-1)] - start
        t = _dot(rel, shear[0])
        side = _dot(rel, shear[1] * float(draw.axis_side @ seg.starboard))
        near = (t >= t_lo) & (t <= t_hi) & (side >= -margin)
        near &= np.hypot(side, _dot(rel, shear[2])) <= reach
        ids = candidates[near.reshape(-1, 3).any(axis=1)]
        if len(ids) > 0.5 * geo["n_faces"]:
            return self._whole_objects() if objects_only else self._whole_scene()
        return self._subset(ids)

    def _subset(self, ids: np.ndarray) -> dict[str, Any]:
        """Index and face buffers of the uploaded faces ``ids`` (released after the draw)."""
        geo = self._geometry
        faces = geo["faces_cpu"][ids].astype("u4")
        refl = _face_data(geo["refl_cpu"], geo["law_cpu"], ids)
        ibo = self.ctx.buffer(faces if len(ids) else b"\0" * 12)
        refl = self.ctx.buffer(refl if len(ids) else b"\0" * 8)
        return {
            "ibo": ibo,
            "faces": refl,
            "ids": ids,
            "n_faces": len(ids),
            "empty": len(ids) == 0,
            "subset": True,
        }

    def _reach(self, sonar: Sonar) -> float:
        """Distance from the track within which a triangle can reach the image, metres."""
        return sonar.max_range + 8.0 * sonar.range_bin + self._geometry["max_edge"]

    def _tile_index(self, reach: float) -> TileIndex:
        """The tile index of the uploaded scene, tiles about a quarter of the reach (cached)."""
        geo = self._geometry
        size = max(0.25 * reach, 2.0 * geo["max_edge"])
        index = geo.get("tile_index")
        if index is None or not (0.5 * size <= index.size <= 2.0 * size):
            index = TileIndex(geo["vertices"], geo["faces_cpu"], size)
            geo["tile_index"] = index
        return index

    @staticmethod
    def _release_subset(geometry: dict[str, Any]) -> None:
        if geometry.get("subset"):
            for obj in geometry.values():
                if hasattr(obj, "release"):
                    obj.release()

    def _read(
        self, cells: Any, draws: list[_Draw], scale: float, shape: tuple[int, int, int], side: str
    ) -> np.ndarray:
        # Each cell is a (low, high) pair of uint32: read as one little-endian uint64.
        total = np.frombuffer(cells.read(), dtype="<u8").reshape(shape[1:])
        image = (total * (1.0 / scale)).astype(np.float32)
        return _fill_stationary(image, draws, side, shape[0])

    def _read_labels(
        self, cells: Any, draws: list[_Draw], shape: tuple[int, int, int], side: str
    ) -> np.ndarray:
        # The low 16 bits of each cell's key are the label (see range_accumulate.glsl).
        keys = np.frombuffer(cells.read(), dtype="<u4").reshape(shape[1:])
        return _fill_stationary((keys & 0xFFFF).astype(np.uint16), draws, side, shape[0])


def _fill_stationary(image: np.ndarray, draws: list[_Draw], side: str, base: int) -> np.ndarray:
    """Copy the one rendered row of each stationary segment to all its pings (in place)."""
    for draw in draws:
        seg = draw.segment
        if draw.side == side and draw.rows == 1 and seg.count > 1:
            first = seg.first - base
            image[first + 1 : first + seg.count] = image[first]
    return image


def _clip(draw: _Draw, first: int, last: int) -> _Draw | None:
    """The part of a draw that renders pings ``first .. last - 1``, or None if it has none."""
    seg = draw.segment
    lo, hi = max(first, seg.first), min(last, seg.first + seg.count)
    if lo >= hi:
        return None
    if lo == seg.first and hi == seg.first + seg.count:
        return draw
    shift = (lo - seg.first) * seg.spacing
    piece = replace(seg, first=lo, count=hi - lo, origin=seg.origin + shift * seg.along)
    rows = 1 if draw.rows == 1 else hi - lo
    return replace(draw, segment=piece, rows=rows)


def _local_float32(vertices: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """``vertices - origin`` in float64, stored as float32, a block at a time."""
    out = np.empty(vertices.shape, dtype=np.float32)
    block = 1 << 20
    for a in range(0, len(vertices), block):
        out[a : a + block] = vertices[a : a + block] - origin
    return out


def _z_span(vertices: np.ndarray) -> tuple[float, float]:
    """Lowest and highest vertex height, metres ((0, 0) for no vertices)."""
    if len(vertices) == 0:
        return 0.0, 0.0
    return float(vertices[:, 2].min()), float(vertices[:, 2].max())


def _masks(write: bool, n_targets: int) -> Any:
    """A colour mask for every target (moderngl wants a plain tuple for a single target)."""
    one = (write,) * 4
    return one if n_targets == 1 else [one] * n_targets


def _dot(points: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Row-wise dot product of (n, 3) points with one axis (elementwise: BLAS is slower here)."""
    return points[:, 0] * axis[0] + points[:, 1] * axis[1] + points[:, 2] * axis[2]


def render_raster(
    scene: Scene,
    sonar: Sonar,
    trajectory: Trajectory,
    *,
    backend: str | None = None,
    settings: RasterSettings | None = None,
    progress: bool = False,
    labels: bool = False,
) -> SonarImage:
    """Render with a temporary :class:`RasterRenderer`, released afterwards.

    Parameters
    ----------
    scene, sonar, trajectory
        What to image, with what, from where (world metres, z up).
    backend : {"egl", "osmesa"}, optional
        Headless GL backend; default ``$SONAR_RASTER_GL``, else EGL, then OSMesa.
    settings : RasterSettings, optional
        Sampling settings.
    progress : bool
        Show a progress bar.
    labels : bool
        Also return per-pixel object ids (``image.labels``).

    Returns
    -------
    SonarImage
        float32 intensity per side, shape (pings, bins). Many renders: make one
        :class:`RasterRenderer` and call its ``render`` (the context and scene upload are kept).
    """
    with RasterRenderer(backend, settings) as renderer:
        return renderer.render(scene, sonar, trajectory, progress=progress, labels=labels)


#: Rows per workgroup of the sweep (``local_size_x`` of range_accumulate.glsl with SWEEP 1).
_SWEEP_GROUP = 8
#: Loop iterations llvmpipe allows one shader invocation in all (gallivm's loop limiter); a
#: sweep dispatch must stay below it.
_LOOP_BUDGET = 65535
#: Most loop iterations one column of the sweep costs: the walk's column loop and the
#: footprint loop over at most MAX_SPREAD (16) bins.
_ITERATIONS_PER_COLUMN = 18
#: Texture unit of the per-material law table (units 0-2 hold the pass targets and columns).
_LAW_UNIT = 5


def _max_by_law(refl: np.ndarray, law: np.ndarray | None) -> np.ndarray:
    """Largest reflectivity per law index (index 0 only for a Lambert scene)."""
    if law is None:
        return np.array([float(refl.max(initial=0.0))])
    out = np.zeros(int(law.max()) + 1)
    np.maximum.at(out, law.astype(np.int64), refl)
    return out


def _face_data(refl: np.ndarray, law: np.ndarray | None, ids: np.ndarray | None) -> np.ndarray:
    """The pass-1 face buffer: (reflectivity, law index) float32 pairs of faces ``ids``."""
    r = refl if ids is None else refl[ids]
    out = np.zeros((len(r), 2), dtype="f4")
    out[:, 0] = r
    if law is not None:
        out[:, 1] = law if ids is None else law[ids]
    return out


def _alpha_top(seg: Segment, z_top: float, reach: float) -> float:
    """Smallest depression (radians) of a point below ``z_top`` and ``reach`` from a ping.

    A point at height z in the fan of the ping at travel u has the fan coordinate
    ``v = (z - z_ping(u)) / up_z`` (``up_z`` = cos pitch) and a depression whose sine is
    ``-v / r``, so the segment's lowest ping (a descending track's last) and the pitch both
    set the bound. Where ``z_top`` is above that ping, points above it nearer than ``reach``
    are steeper than the bound (the columns do not reach them; as before).
    """
    lo = -0.5 * seg.width
    hi = (seg.count - 1) * seg.spacing + 0.5 * seg.width
    z_ping = float(seg.origin[2]) + min(lo * float(seg.along[2]), hi * float(seg.along[2]))
    return math.asin(min(1.0, max(-1.0, (z_ping - z_top) / (float(seg.up[2]) * reach))))


def _swath_box(
    seg: Segment,
    axis_side: np.ndarray,
    start: np.ndarray,
    t_range: tuple[float, float],
    margin: float,
    reach: float,
    z_span: tuple[float, float],
) -> tuple[float, float, float, float]:
    """Horizontal bounding box ``(xmin, xmax, ymin, ymax)`` of the points a draw's fans can see.

    The points are ``start + u along + s axis_side + v up`` (the inverse of ``Segment.shear``)
    with travel ``u`` in ``t_range``, side ``s`` from ``-margin`` to ``reach`` and ``v`` within
    ``±reach``, narrowed to the heights ``z_span`` of the scene: a pitched fan's ``up`` leans
    along track, so the seabed it sees lies ahead of or behind the ping, and a climbing track
    changes its height with ``u``. The box is the image of a box under an affine map, so its
    eight corners bound it.
    """
    up_z = float(seg.up[2])  # cos(pitch) > 0: the trajectory refuses pitch beyond 80 degrees
    v = [(z - float(start[2]) - u * float(seg.along[2])) / up_z for z in z_span for u in t_range]
    v_lo, v_hi = max(min(v), -reach), min(max(v), reach)
    v_hi = max(v_hi, v_lo)
    corners = np.array(
        [
            start + u * seg.along + s * axis_side + w * seg.up
            for u in t_range
            for s in (-margin, reach)
            for w in (v_lo, v_hi)
        ]
    )
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    return float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])


def _grid_entries(scene: Scene, source: np.ndarray | None, n_faces: int) -> dict[str, Any]:
    """The scene's seabed grid and a mask of the uploaded faces that belong to it."""
    grid = find_grid(scene)
    if grid is None:
        return {"grid": None, "grid_mask": None}
    if source is None:
        mask = np.zeros(n_faces, dtype=bool)
        mask[grid.faces] = True
    else:
        mask = (source >= grid.first_face) & (source < grid.first_face + grid.n_faces)
    return {"grid": grid, "grid_mask": mask}


def _column_trig(tiles: list) -> np.ndarray:
    """The sweep's column table of a draw (all its tiles), float32, shape (columns, 4).

    Per column: (cos α, sin α, Φ dα, dα / 2).
    """
    table = np.concatenate([t[3] for t in tiles]).astype(np.float64)
    alpha = table[:, 0]
    out = np.stack([np.cos(alpha), np.sin(alpha), table[:, 1], table[:, 2]], axis=1)
    return out.astype("f4")
