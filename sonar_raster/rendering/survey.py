"""Long tracks: render in blocks of pings and stream them to disk, in bounded memory.

A survey line of 10⁵ pings × 4096 bins is 3.3 GB of float32 per side pair: more than a
laptop wants to hold, and more than a GL buffer may be. :func:`render_survey` renders the
track block by block (:meth:`RasterRenderer.render_chunks`) and appends each block to an EXR
as scanlines (and to an XTF, ping records, when asked), so peak memory follows the block size,
not the track. A PNG is made afterwards
from the finished EXR, block by block again, with its display mapping taken from an even
subsample of the pings. Every output is written under a temporary name and renamed into place
only when all are complete (:func:`~sonar_raster.io.commit.install`, which restores the old
files if a rename fails). Temporary names carry the process id, so a run killed by SIGKILL
leaves files that the next run of the same target removes.
"""

from __future__ import annotations

import math
import os
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
) -> tuple[list[Path], dict]:
    """Render a track block by block straight to EXR/PNG files, with a JSON sidecar per file.

    Parameters
    ----------
    scene, sonar, trajectory
        What to render (see :func:`sonar_raster.render_raster`).
    outputs : list of path
        Files ending in .exr, .png or .xtf (directories must exist); .exr and .png get a JSON
        sidecar.
    chunk_pings : int
        Pings per block; memory grows with ``chunk_pings × bins``, not with the track.
    backend, settings
        GL backend and sampling settings of the renderer.
    bit_depth, dynamic_range_db
        PNG display mapping, as in :func:`sonar_raster.write_image`; an automatic range is
        chosen from an even subsample of :data:`STAT_ROWS` pings.
    metadata : dict, optional
        Added to every file's metadata.
    progress : bool
        Show a progress bar over the blocks.
    effects : Effects, optional
        Sensor effects applied block by block
        (:func:`~sonar_raster.effects.chain.apply_effects_blocks`: exact along track across
        blocks, random fields drawn per block, the first block's full scale throughout).
    seed : int, optional
        Seed of the effects' random stages.

    Returns
    -------
    written : list of Path
        Every file written.
    summary : dict
        Counters summed over the blocks (draws, skipped draws, triangles drawn) and the blocks.
    """
    paths = [Path(p) for p in outputs]
    for path in paths:
        if path.suffix.lower() not in (*sio.SUPPORTED, ".xtf"):
            raise SonarRasterError(f"cannot write {path}: use .exr, .png or .xtf")
        check_writable(path)
        if path.suffix.lower() != ".xtf":
            check_writable(path.with_suffix(".json"))
    xtf_final = next((p for p in paths if p.suffix.lower() == ".xtf"), None)
    if bit_depth not in (8, 16):
        raise SonarRasterError(f"PNG bit depth must be 8 or 16, got {bit_depth!r}")
    exr_final = next((p for p in paths if p.suffix.lower() == ".exr"), None)
    exr_base = exr_final or paths[0].with_suffix(".exr")
    sweep_stale(exr_base)  # a killed run's scanline file of the same target
    exr_tmp = temp_name(exr_base)
    xtf_tmp = temp_name(xtf_final) if xtf_final else None
    temps: list[Path] = [exr_tmp] + ([xtf_tmp] if xtf_tmp else [])
    try:
        stats, summary, meta = _stream_blocks(
            scene,
            sonar,
            trajectory,
            (exr_tmp, xtf_tmp),
            chunk_pings,
            backend,
            settings,
            progress,
            effects=effects,
            seed=seed,
        )
        meta.update(metadata or {})
        levelled = effects is not None  # as write_image shows an image with effects
        if dynamic_range_db is None:
            dynamic_range_db = sio.LEVELLED_RANGE_DB if levelled else sio.auto_dynamic_range(stats)
        ref = sio.median_reference(stats, dynamic_range_db) if levelled else None
        _, ref = sio.display_mapping(stats, dynamic_range_db, ref)
        mapping = {
            "ref_level_m2": ref,
            "dynamic_range_db": float(dynamic_range_db),
            "formula": sio.MAPPING_FORMULA,
            "chosen_from": f"{len(stats)} evenly spaced pings",
        }
        if levelled:
            spacing = float(trajectory.typical_spacing) or None
            geometry = {"columns": "slant range", "column_m": sonar.range_bin, "row_m": spacing}
            mapping.update(level="median", palette="grey", geometry=geometry)
        header = SonarImage({s: np.zeros((1, 1), np.float32) for s in sonar.sides}, sonar, meta)
        jobs: list[tuple[Path, Path]] = []
        for path in paths:
            if path == xtf_final and xtf_tmp is not None:
                jobs.append((xtf_tmp, path))
                continue
            if path.suffix.lower() == ".png":
                tmp = temp_name(path)
                temps.append(tmp)
                _png_from_exr(exr_tmp, tmp, header, mapping, bit_depth, chunk_pings)
                jobs.append((tmp, path))
            elif path == exr_final:
                jobs.append((exr_tmp, path))
            sidecar = temp_name(path.with_suffix(".json"))
            temps.append(sidecar)
            doc = sio.sidecar_document(header, mapping)
            doc["shape"] = [trajectory.n_pings, sonar.n_bins]  # type: ignore[index]
            write_json(sidecar, doc)
            jobs.append((sidecar, path.with_suffix(".json")))
        install(jobs)  # every output replaced, or none
    except OSError as exc:
        raise SonarRasterError(f"cannot write {paths[0]}: {exc.strerror or exc}") from None
    finally:
        for tmp in temps:
            tmp.unlink(missing_ok=True)
    return [final for _, final in jobs], summary


def _stream_blocks(
    scene: Scene,
    sonar: Sonar,
    trajectory: Trajectory,
    temps: tuple[Path, Path | None],
    chunk_pings: int,
    backend: str | None,
    settings: RasterSettings | None,
    progress: bool,
    *,
    effects: Any = None,
    seed: int | None = None,
) -> tuple[np.ndarray, dict, dict]:
    """Render into the temporary EXR (and XTF); return display rows, counters and metadata."""
    n_pings = trajectory.n_pings
    stride = max(1, math.ceil(n_pings / STAT_ROWS))
    exr_tmp, xtf_tmp = temps
    writer = ExrStreamWriter(exr_tmp, n_pings)
    xtf = _XtfStream(xtf_tmp, trajectory, scene.ground_z) if xtf_tmp else None
    rows: list[np.ndarray] = []
    summary = {"blocks": 0, "draws": 0, "draws_skipped_empty": 0, "triangles_drawn": 0}
    meta: dict = {}
    with RasterRenderer(backend, settings) as renderer:
        blocks = renderer.render_chunks(scene, sonar, trajectory, chunk_pings)
        if effects is not None:  # one block behind the renderer: each block sees its neighbours
            from ..effects.chain import apply_effects_blocks

            spacing = trajectory.typical_spacing
            blocks = apply_effects_blocks(blocks, effects, seed=seed, ping_spacing=spacing)
        if progress:
            from tqdm import tqdm

            total = math.ceil(n_pings / chunk_pings)
            blocks = tqdm(blocks, total=total, desc="rendering", unit="block", disable=None)
        try:
            for block in blocks:
                sio.checked_sides(block)  # finite, one shape: raises before anything is kept
                writer.write(block)
                if xtf is not None:
                    xtf.write(block)
                first = int(block.metadata["first_ping"])
                keep = np.arange((-first) % stride, block.shape[0], stride)
                rows.append(block.display()[keep])
                summary["blocks"] += 1
                for key, value in block.metadata["counters"].items():
                    summary[key] += value
                meta = _whole_track_metadata(block.metadata)
        except BaseException:
            _abandon(writer)
            raise
        finally:
            if xtf is not None:
                xtf.close()
    writer.close()
    meta["survey"] = {"chunk_pings": chunk_pings, **summary}
    if "effects" in meta:  # the last block's record, less what is per block
        record = {k: v for k, v in meta["effects"].items() if k not in ("block", "seed")}
        meta["effects"] = {**record, "streamed": "apply_effects_blocks"}  # keeps stream_seed
    return np.concatenate(rows), summary, meta


class _XtfStream:
    """XTF ping records appended block by block (altitude = height above the scene's ground)."""

    def __init__(self, tmp: Path, trajectory: Trajectory, ground_z: float):
        from ..io.xtf import XtfWriter

        self.fh = open(tmp, "xb")  # closed by close(), after the last block
        self.writer = XtfWriter(self.fh)
        self.trajectory, self.ground_z = trajectory, ground_z

    def write(self, block: SonarImage) -> None:
        first = int(block.metadata["first_ping"])
        rows = slice(first, first + block.shape[0])
        poses = self.trajectory.subset(rows)
        self.writer.write(block, poses, poses.positions[:, 2] - self.ground_z)

    def close(self) -> None:
        self.fh.close()


def _abandon(writer: ExrStreamWriter) -> None:
    if writer.out is not None:
        writer.out.close()
        writer.out = None


def _png_from_exr(
    exr: Path, tmp: Path, header: SonarImage, mapping: dict, bit_depth: int, block: int
) -> None:
    """Write the display PNG of a finished EXR, ``block`` pings at a time."""
    inp = oiio.ImageInput.open(str(exr))
    if inp is None:
        raise SonarRasterError(f"cannot read back {exr}: {oiio.geterror()}")
    try:
        spec = inp.spec()
        names = list(spec.channelnames)
        width = spec.width * len(names)
        fmt = sio.png_type(bit_depth)[1]
        out_spec = oiio.ImageSpec(width, spec.height, 1, fmt)
        out_spec.channelnames = ("Y",)
        for name, value in sio.png_attributes(header, mapping, bit_depth).items():
            out_spec.attribute(name, value)
        out = oiio.ImageOutput.create(str(tmp))
        if out is None or not out.open(str(tmp), out_spec):
            raise SonarRasterError(f"cannot write {tmp}: {oiio.geterror()}")
        try:
            for y0 in range(0, spec.height, block):
                y1 = min(spec.height, y0 + block)
                px = inp.read_scanlines(0, 0, y0, y1, 0, 0, len(names), oiio.FLOAT)
                px = np.asarray(px, dtype=np.float32).reshape(y1 - y0, spec.width, len(names))
                sides = {n: px[:, :, i] for i, n in enumerate(names)}
                display = SonarImage(sides, header.sonar).display()
                codes, _ = sio.display_mapping(
                    display, mapping["dynamic_range_db"], mapping["ref_level_m2"]
                )
                quantised = sio.quantised_codes(codes, bit_depth)[0]
                if not out.write_scanlines(y0, y1, 0, quantised[:, :, np.newaxis]):
                    raise SonarRasterError(f"cannot write {tmp}: {out.geterror()}")
        finally:
            out.close()
    finally:
        inp.close()


def _whole_track_metadata(metadata: dict) -> dict:
    return {k: v for k, v in metadata.items() if k not in _PER_BLOCK}
