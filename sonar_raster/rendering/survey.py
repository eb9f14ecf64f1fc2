"""Long tracks: render in blocks of pings and stream them to disk, in bounded memory.

A survey line of 10⁵ pings × 4096 bins is 3.3 GB of float32 per side pair: more than a
laptop wants to hold, and more than a GL buffer may be. :func:`render_survey` renders the
track block by block (:meth:`RasterRenderer.render_chunks`) and appends each block to an EXR
as scanlines, so peak memory follows the block size, not the track. A PNG is made afterwards
from the finished EXR, block by block again, with its display levels taken from an even
subsample of the pings and its palette and pixel geometry as asked; an XTF likewise.
:func:`render_bands` does the same for several sonars over one track (the bands of a
dual-frequency side-scan), one file per band and one XTF holding them all. Every output is
written under a temporary name and renamed into place only when all are complete
(:func:`~sonar_raster.io.commit.install`, which restores the old files if a rename fails).
Temporary names carry the process id, so a run killed by SIGKILL leaves files that the next
run of the same target removes.
"""

from __future__ import annotations

import math
import os
import shutil
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import OpenImageIO as oiio

from ..errors import SonarRasterError
from ..image import SonarImage
from ..io import images as sio
from ..io.commit import check_writable, install, sweep_stale, temp_name, write_json
from ..scene import Scene
from ..sonar import SIDES, Sonar
from ..trajectory import Trajectory
from .gl.raster import RasterRenderer, RasterSettings

#: Pings kept (evenly spaced) to choose the PNG display mapping of a streamed survey.
STAT_ROWS = 2048
_PER_BLOCK = ("first_ping", "counters")


class ExrStreamWriter:
    """Append blocks of pings to an EXR (channels "port", "starboard"), scanline by scanline.

    Opened on the first block, whose metadata goes into the header; the file is written under
    ``tmp`` and :meth:`close` checks that every ping arrived. The caller renames it into place.
    """

    def __init__(self, tmp: Path, n_pings: int):
        self.tmp, self.n_pings = tmp, n_pings
        self.out: oiio.ImageOutput | None = None
        self.rows = 0
        self.channels: tuple[str, ...] = ()

    def write(self, block: SonarImage) -> None:
        """Append one block; blocks must come in ping order."""
        if self.out is None:
            self._open(block)
        assert self.out is not None
        pixels = np.stack([block.sides[c] for c in self.channels], axis=-1).astype(np.float32)
        first = int(block.metadata["first_ping"])
        if first != self.rows:
            raise SonarRasterError(f"survey block starts at ping {first}, expected {self.rows}")
        if not self.out.write_scanlines(first, first + len(pixels), 0, pixels):
            raise SonarRasterError(f"cannot write {self.tmp}: {self.out.geterror()}")
        self.rows += len(pixels)

    def _open(self, block: SonarImage) -> None:
        self.channels = tuple(s for s in SIDES if s in block.sides)
        spec = oiio.ImageSpec(block.shape[1], self.n_pings, len(self.channels), oiio.FLOAT)
        spec.channelnames = self.channels
        spec.attribute("compression", "zip")
        header = SonarImage(block.sides, block.sonar, _whole_track_metadata(block.metadata))
        for name, value in sio.exr_attributes(header).items():
            spec.attribute(name, value)
        out = oiio.ImageOutput.create(str(self.tmp))
        if out is None or not out.open(str(self.tmp), spec):
            raise SonarRasterError(f"cannot write {self.tmp}: {oiio.geterror()}")
        self.out = out

    def close(self) -> None:
        """Finish the file; raise if pings are missing."""
        if self.out is not None:
            self.out.close()
            self.out = None
        if self.rows != self.n_pings:
            raise SonarRasterError(f"survey stopped after {self.rows} of {self.n_pings} pings")


@dataclass(frozen=True)
class SurveyBand:
    """One sonar of a streamed survey and its image files (one band of a dual-frequency set).

    Attributes
    ----------
    sonar : Sonar
        The band's sonar.
    outputs : tuple of Path
        Its .exr and .png files, each with a JSON sidecar; empty when it only goes into the XTF.
    effects : Effects, optional
        Sensor effects applied block by block
        (:func:`~sonar_raster.effects.chain.apply_effects_blocks`: exact along track across
        blocks, random fields drawn per block, the first block's full scale throughout).
    seed : int, optional
        Seed of the effects' random stages.
    metadata : dict
        Added to its files' metadata.
    display : Display, optional
        Level, palette and pixel geometry of its PNG (:class:`~sonar_raster.io.images.Display`;
        default: levelled when it has effects, grey, slant range, one row per ping).
    name : str, optional
        Shown beside the progress bar.
    """

    sonar: Sonar
    outputs: tuple[Path, ...] = ()
    effects: Any = None
    seed: int | None = None
    metadata: dict = field(default_factory=dict)
    display: sio.Display | None = None
    name: str | None = None


def render_survey(
    scene: Scene,
    sonar: Sonar,
    trajectory: Trajectory,
    outputs: list[str | os.PathLike],
    *,
    chunk_pings: int = 512,
    backend: str | None = None,
    settings: RasterSettings | None = None,
    bit_depth: int = 8,
    dynamic_range_db: float | None = None,
    metadata: dict | None = None,
    progress: bool = False,
    effects: Any = None,
    seed: int | None = None,
    display: sio.Display | None = None,
) -> tuple[list[Path], dict]:
    """Render a track block by block straight to EXR/PNG files, with a JSON sidecar per file.

    Parameters
    ----------
    scene, sonar, trajectory
        What to render (see :func:`sonar_raster.render_raster`).
    outputs : list of path, or one path
        Files ending in .exr, .png or .xtf (directories must exist); .exr and .png get a JSON
        sidecar.
    chunk_pings : int
        Pings per block; memory grows with ``chunk_pings × bins``, not with the track.
    backend, settings
        GL backend and sampling settings of the renderer.
    bit_depth, dynamic_range_db
        PNG display mapping, as in :func:`sonar_raster.write_image`; the levels are taken from
        an even subsample of :data:`STAT_ROWS` pings.
    metadata : dict, optional
        Added to every file's metadata.
    progress : bool
        Show a progress bar over the blocks.
    effects, seed, display
        As :class:`SurveyBand`'s.

    Returns
    -------
    written : list of Path
        Every file written.
    summary : dict
        Counters summed over the blocks (draws, skipped draws, triangles drawn) and the blocks.
    """
    if isinstance(outputs, (str, os.PathLike)):
        outputs = [outputs]  # one file
    paths = [Path(p) for p in outputs]
    if len(set(paths)) < len(paths):
        raise SonarRasterError("an output is given twice; give each file once")
    for path in paths:
        if path.suffix.lower() not in (*sio.SUPPORTED, ".xtf"):
            raise SonarRasterError(f"cannot write {path}: use .exr, .png or .xtf")
    xtfs = [p for p in paths if p.suffix.lower() == ".xtf"]
    images = tuple(p for p in paths if p.suffix.lower() != ".xtf")
    band = SurveyBand(sonar, images, effects, seed, dict(metadata or {}), display)
    written, summaries = render_bands(
        scene,
        [band],
        trajectory,
        xtfs,
        chunk_pings=chunk_pings,
        backend=backend,
        settings=settings,
        bit_depth=bit_depth,
        dynamic_range_db=dynamic_range_db,
        progress=progress,
    )
    return written, summaries[0]


def render_bands(
    scene: Scene,
    bands: list[SurveyBand],
    trajectory: Trajectory,
    xtf: str | os.PathLike | Sequence[str | os.PathLike] | None = None,
    *,
    chunk_pings: int = 512,
    backend: str | None = None,
    settings: RasterSettings | None = None,
    bit_depth: int = 8,
    dynamic_range_db: float | None = None,
    progress: bool = False,
) -> tuple[list[Path], list[dict]]:
    """Render several sonars over one track block by block: their files, and one XTF of all.

    Each band is streamed in turn to a temporary EXR (then its PNG, from that EXR); the XTF is
    written last from those EXRs, block by block, every ping holding every band's channels
    (a dual-frequency side-scan's file). Memory follows the block, not the track. Every file
    is replaced, or none.

    Parameters
    ----------
    scene, trajectory
        What to render.
    bands : list of SurveyBand
        The sonars, their effects and their image files.
    xtf : path or list of path, optional
        The XTF of every band (several: the same file under each name).
    chunk_pings, backend, settings, bit_depth, dynamic_range_db, progress
        As for :func:`render_survey`.

    Returns
    -------
    written : list of Path
        Every file written.
    summaries : list of dict
        Each band's counters (:func:`render_survey`).
    """
    if not bands:
        raise SonarRasterError("no sonar to render")
    named = [] if xtf is None else [xtf] if isinstance(xtf, (str, os.PathLike)) else list(xtf)
    xtfs = [Path(p) for p in named]
    for path in xtfs:
        if path.suffix.lower() != ".xtf":
            raise SonarRasterError(f"cannot write {path} as XTF: its name must end in .xtf")
        check_writable(path)
    for band in bands:
        for path in band.outputs:
            if path.suffix.lower() not in sio.SUPPORTED:
                raise SonarRasterError(f"cannot write {path}: use .exr, .png or .xtf")
            check_writable(path)
            check_writable(path.with_suffix(".json"))
    if bit_depth not in (8, 16):
        raise SonarRasterError(f"PNG bit depth must be 8 or 16, got {bit_depth!r}")
    first = bands[0].outputs[0] if bands[0].outputs else (xtfs[0] if xtfs else None)
    if first is None:
        raise SonarRasterError("nothing to write: give an .exr, .png or .xtf output")
    temps: list[Path] = []
    jobs: list[tuple[Path, Path]] = []
    summaries: list[dict] = []
    exrs: list[Path] = []
    try:
        for band in bands:
            exr_final = next((p for p in band.outputs if p.suffix.lower() == ".exr"), None)
            exr_base = exr_final or (band.outputs[0] if band.outputs else first).with_suffix(".exr")
            sweep_stale(exr_base)  # a killed run's scanline file of the same target
            exr_tmp = temp_name(exr_base)
            temps.append(exr_tmp)
            exrs.append(exr_tmp)
            stats, summary, meta = _stream_blocks(
                scene, band, trajectory, exr_tmp, chunk_pings, backend, settings, progress
            )
            summaries.append(summary)
            meta.update(band.metadata)
            header = SonarImage({s: np.zeros((1, 1), np.float32) for s in stats}, band.sonar, meta)
            display = band.display or sio.Display(
                ping_spacing_m=float(trajectory.typical_spacing) or None
            )
            mapping = _levels(header, stats, display, dynamic_range_db)
            for path in band.outputs:
                if path.suffix.lower() == ".png":
                    tmp = temp_name(path)
                    temps.append(tmp)
                    _png_from_exr(exr_tmp, tmp, header, display, mapping, bit_depth, chunk_pings)
                    jobs.append((tmp, path))
                elif path == exr_final:
                    jobs.append((exr_tmp, path))
                else:  # a second EXR name: a copy
                    jobs.append((_copied(exr_tmp, path, temps), path))
                sidecar = temp_name(path.with_suffix(".json"))
                temps.append(sidecar)
                doc = sio.sidecar_document(header, mapping)
                doc["shape"] = [trajectory.n_pings, band.sonar.n_bins]  # type: ignore[index]
                write_json(sidecar, doc)
                jobs.append((sidecar, path.with_suffix(".json")))
        if xtfs:
            xtf_tmp = temp_name(xtfs[0])
            temps.append(xtf_tmp)
            _xtf_from_exrs(xtf_tmp, exrs, bands, trajectory, scene.ground_z, chunk_pings)
            jobs.append((xtf_tmp, xtfs[0]))
            jobs += [(_copied(xtf_tmp, path, temps), path) for path in xtfs[1:]]
        install(jobs)  # every output replaced, or none
    except OSError as exc:
        raise SonarRasterError(f"cannot write {first}: {exc.strerror or exc}") from None
    finally:
        for tmp in temps:
            tmp.unlink(missing_ok=True)
    return [final for _, final in jobs], summaries


def _stream_blocks(
    scene: Scene,
    band: SurveyBand,
    trajectory: Trajectory,
    exr_tmp: Path,
    chunk_pings: int,
    backend: str | None,
    settings: RasterSettings | None,
    progress: bool,
) -> tuple[dict[str, np.ndarray], dict, dict]:
    """Render one band into its temporary EXR; return its sampled pings, counters, metadata."""
    n_pings = trajectory.n_pings
    stride = max(1, math.ceil(n_pings / STAT_ROWS))
    writer = ExrStreamWriter(exr_tmp, n_pings)
    rows: list[dict[str, np.ndarray]] = []
    summary = {"blocks": 0, "draws": 0, "draws_skipped_empty": 0, "triangles_drawn": 0}
    meta: dict = {}
    with RasterRenderer(backend, settings) as renderer:
        blocks = renderer.render_chunks(scene, band.sonar, trajectory, chunk_pings)
        if band.effects is not None:  # one block behind the renderer: it sees its neighbours
            from ..effects.chain import apply_effects_blocks

            spacing = trajectory.typical_spacing
            blocks = apply_effects_blocks(
                blocks, band.effects, seed=band.seed, ping_spacing=spacing
            )
        if progress:
            from tqdm import tqdm

            total = math.ceil(n_pings / chunk_pings)
            desc = f"rendering {band.name}" if band.name else "rendering"
            blocks = tqdm(blocks, total=total, desc=desc, unit="block", disable=None)
        try:
            for block in blocks:
                sides = sio.checked_sides(block)  # finite, one shape: raises before it is kept
                writer.write(block)
                first = int(block.metadata["first_ping"])
                keep = np.arange((-first) % stride, block.shape[0], stride)
                rows.append({side: values[keep] for side, values in sides.items()})
                summary["blocks"] += 1
                for key, value in block.metadata["counters"].items():
                    summary[key] += value
                meta = _whole_track_metadata(block.metadata)
        except BaseException:
            _abandon(writer)
            raise
    writer.close()
    meta["survey"] = {"chunk_pings": chunk_pings, **summary}
    if "effects" in meta:  # the last block's record, less what is per block
        record = {k: v for k, v in meta["effects"].items() if k not in ("block", "seed")}
        meta["effects"] = {**record, "streamed": "apply_effects_blocks"}  # keeps stream_seed
    stats = {side: np.concatenate([r[side] for r in rows]) for side in rows[0]}
    return stats, summary, meta


def _levels(
    header: SonarImage, stats: dict[str, np.ndarray], display: sio.Display, dr: float | None
) -> dict:
    """The PNG's display mapping from the sampled pings, shown as the display asks."""
    flat = replace(display, square_pixels=False)  # resampling along track is not for levels
    shown, _ = sio.display_sides(header, stats, flat)
    two = {side: values[:2] for side, values in stats.items()}
    _, geometry = sio.display_sides(header, two, display)
    both = SonarImage(shown, header.sonar).display()
    mapping = sio.display_levels(header, both, display, dr, geometry)
    mapping["chosen_from"] = f"{len(next(iter(stats.values())))} evenly spaced pings"
    return mapping


def _xtf_from_exrs(
    tmp: Path,
    exrs: list[Path],
    bands: list[SurveyBand],
    trajectory: Trajectory,
    ground_z: float,
    block: int,
) -> None:
    """Write the XTF of every band from their finished EXRs, ``block`` pings at a time."""
    from ..io.xtf import XtfWriter

    inputs: list[Any] = []
    try:
        inputs += [_open_exr(path) for path in exrs]
        with open(tmp, "xb") as fh:
            writer = XtfWriter(fh)
            for y0 in range(0, trajectory.n_pings, block):
                y1 = min(trajectory.n_pings, y0 + block)
                images = [
                    SonarImage(_read_rows(inp, y0, y1), band.sonar)
                    for inp, band in zip(inputs, bands, strict=True)
                ]
                poses = trajectory.subset(slice(y0, y1))
                writer.write(images, poses, poses.positions[:, 2] - ground_z)
    finally:
        for inp in inputs:
            inp.close()


def _copied(tmp: Path, final: Path, temps: list[Path]) -> Path:
    """A copy of the finished temporary ``tmp`` under a temporary name of ``final``."""
    copy = temp_name(final)
    temps.append(copy)
    shutil.copyfile(tmp, copy)
    return copy


def _open_exr(path: Path) -> Any:
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise SonarRasterError(f"cannot read back {path}: {oiio.geterror()}")
    return inp


def _read_rows(inp: Any, y0: int, y1: int) -> dict[str, np.ndarray]:
    """Pings ``y0`` to ``y1`` (excluded) of an open EXR, per side."""
    spec = inp.spec()
    names = list(spec.channelnames)
    px = inp.read_scanlines(0, 0, y0, y1, 0, 0, len(names), oiio.FLOAT)
    if px is None:
        raise SonarRasterError(f"cannot read back pings {y0}-{y1}: {inp.geterror()}")
    px = np.asarray(px, dtype=np.float32).reshape(y1 - y0, spec.width, len(names))
    return {name: px[:, :, i] for i, name in enumerate(names)}


def _abandon(writer: ExrStreamWriter) -> None:
    if writer.out is not None:
        writer.out.close()
        writer.out = None


def _png_from_exr(
    exr: Path,
    tmp: Path,
    header: SonarImage,
    display: sio.Display,
    mapping: dict,
    bit_depth: int,
    block: int,
) -> None:
    """Write the display PNG of a finished EXR, ``block`` rows at a time.

    The rows are the display's (:func:`~sonar_raster.io.images.display_sides`): pings, or with
    square pixels rows one range bin long, each read with the two pings it lies between.
    """
    inp = _open_exr(exr)
    try:
        pings = inp.spec().height
        lo, hi, w = np.arange(pings), np.arange(pings), np.zeros(pings)
        if display.square_pixels:
            spacing = sio.display_ping_spacing(header, display)
            if spacing is None:  # _levels said so first
                raise SonarRasterError("square pixels need the ping spacing")
            lo, hi, w = sio.square_pixel_rows(pings, spacing, header.sonar.range_bin)
        flat = replace(display, square_pixels=False)
        out = None
        try:
            for r0 in range(0, len(lo), block):
                r1 = min(len(lo), r0 + block)
                p0, p1 = int(lo[r0]), int(hi[r1 - 1]) + 1
                sides = _read_rows(inp, p0, p1)
                a, b, f = lo[r0:r1] - p0, hi[r0:r1] - p0, w[r0:r1, None]
                sides = {n: (1.0 - f) * v[a] + f * v[b] for n, v in sides.items()}
                shown, _ = sio.display_sides(header, sides, flat)
                codes, _ = sio.display_mapping(
                    SonarImage(shown, header.sonar).display(),
                    mapping["dynamic_range_db"],
                    mapping["ref_level_m2"],
                )
                pixels = sio.palette_codes(codes, mapping.get("palette", "grey"))
                quantised, fmt = sio.quantised_codes(pixels, bit_depth)
                if out is None:
                    out = _open_png(tmp, header, mapping, bit_depth, quantised, len(lo), fmt)
                if not out.write_scanlines(r0, r1, 0, quantised):
                    raise SonarRasterError(f"cannot write {tmp}: {out.geterror()}")
        finally:
            if out is not None:
                out.close()
    finally:
        inp.close()


def _open_png(
    tmp: Path, header: SonarImage, mapping: dict, bit_depth: int, first: np.ndarray, rows: int,
    fmt: Any,
) -> Any:  # fmt: skip
    """Open the PNG for ``rows`` rows shaped as its first block of codes."""
    spec = oiio.ImageSpec(first.shape[1], rows, first.shape[2], fmt)
    spec.channelnames = ("Y",) if first.shape[2] == 1 else ("R", "G", "B")
    for name, value in sio.png_attributes(header, mapping, bit_depth).items():
        spec.attribute(name, value)
    out = oiio.ImageOutput.create(str(tmp))
    if out is None or not out.open(str(tmp), spec):
        raise SonarRasterError(f"cannot write {tmp}: {oiio.geterror()}")
    return out


def _whole_track_metadata(metadata: dict) -> dict:
    return {k: v for k, v in metadata.items() if k not in _PER_BLOCK}
