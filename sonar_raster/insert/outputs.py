"""Files of an insertion, written all-or-nothing beside one output stem ``OUT``.

- ``OUT.xtf``: the recording with the objects (a copy of the input XTF in which only the
  changed pings' side-scan samples differ, :mod:`.xtf_patch`);
- ``OUT.png`` and ``OUT.json``: the display image (port on the left) and its sidecar;
- ``OUT.instances.png`` (uint16 instance ids on highlight and shadow), ``OUT.classes.png``
  (uint8: 0 background, 1 highlight, 2 shadow), ``OUT.txt`` (YOLO boxes) and
  ``OUT.coco.json`` (COCO detection document), laid out as the dataset command writes them
  (:mod:`sonar_raster.dataset.labels`);
- ``OUT.objects.json``: every object's class, spec, ping, ground range, size and position,
  and the recording's noise floor and looks per side.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..dataset.labels import coco_document, yolo_lines
from ..errors import SonarRasterError
from .insertion import Insertion
from .xtf_patch import patch_xtf

__all__ = ["LABEL_CLASSES", "insertion_jobs", "output_paths", "write_label_png", "xtf_job"]

LABEL_CLASSES = {0: "background", 1: "highlight", 2: "shadow"}
#: Suffixes of files insert writes, or of images: not taken as part of an output stem.
_PRODUCT_SUFFIXES = (".png", ".json", ".txt", ".exr", ".tif", ".tiff", ".jpg", ".npy", ".csv")


def output_paths(out: str | Path, xtf: bool = True) -> dict[str, Path]:
    """The files written for output stem ``out`` (a trailing ``.xtf`` is dropped), by kind.

    Parameters
    ----------
    out : str or Path
        ``OUT`` or ``OUT.xtf``.
    xtf : bool
        Include the XTF file.
    """
    out = Path(out)
    stem = out.with_suffix("") if out.suffix.lower() == ".xtf" else out
    name = stem.name
    if not name or name in (".", ".."):
        raise SonarRasterError(f"output {out}: give a file name such as line1_inserted.xtf")
    if out.suffix.lower() in _PRODUCT_SUFFIXES:  # 'ins.png' would give ins.png.png, ins.png.xtf
        raise SonarRasterError(
            f"output {out}: give a stem or OUT.xtf (e.g. -o {out.with_suffix('')}); insert "
            "writes OUT.xtf, OUT.png, OUT.json and the label files beside them"
        )
    paths = {
        "image": stem.with_name(f"{name}.png"),
        "sidecar": stem.with_name(f"{name}.json"),
        "instances": stem.with_name(f"{name}.instances.png"),
        "classes": stem.with_name(f"{name}.classes.png"),
        "yolo": stem.with_name(f"{name}.txt"),
        "coco": stem.with_name(f"{name}.coco.json"),
        "objects": stem.with_name(f"{name}.objects.json"),
    }
    if xtf:
        paths = {"xtf": stem.with_name(f"{name}.xtf"), **paths}
    return paths


def write_label_png(tmp: Path, pixels: np.ndarray) -> None:
    """Write a one-channel uint8 or uint16 label image as PNG.

    Parameters
    ----------
    tmp : Path
        The file to write.
    pixels : ndarray, shape (h, w), uint8 or uint16
    """
    import OpenImageIO as oiio

    from ..io.commit import write_oiio

    fmt = oiio.UINT16 if pixels.dtype == np.uint16 else oiio.UINT8
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], 1, fmt)
    spec.channelnames = ("Y",)
    write_oiio(tmp, np.ascontiguousarray(pixels)[:, :, np.newaxis], spec)


def _write_text(tmp: Path, text: str) -> None:
    with open(tmp, "x", encoding="utf-8") as fh:
        fh.write(text)


def _write_xtf(tmp: Path, inserted: list[Insertion]) -> None:
    """The recording with each insertion's changed pings, pair by pair, into ``tmp``."""
    for k, ins in enumerate(inserted):
        indices = ins.recording.image.metadata.get("ping_indices")
        if indices is None:
            raise SonarRasterError("the recording has no ping indices: it was not read from XTF")
        samples = ins.samples()
        new = {int(indices[r]): {s: samples[s][r] for s in samples} for r in ins.rows.tolist()}
        src = ins.recording.source if k == 0 else tmp  # the pairs before it already in tmp
        patch_xtf(src, tmp, new, ins.recording.frequency)


def xtf_job(inserted: list[Insertion], out: str | Path) -> tuple[Path, Callable[[Path], None]]:
    """The (final path, writer) job of ``OUT.xtf`` holding several insertions of one recording.

    Each insertion went into one channel pair of the same file (a dual-frequency recording);
    every other sample is copied as recorded.
    """
    sources = {str(ins.recording.source) for ins in inserted}
    if len(sources) != 1:
        raise SonarRasterError(f"insertions into different recordings: {sorted(sources)}")
    return output_paths(out)["xtf"], lambda tmp: _write_xtf(tmp, inserted)


def insertion_jobs(
    ins: Insertion,
    out: str | Path,
    *,
    box: str = "highlight",
    min_pixels: int = 1,
    seed: int = 0,
    xtf: bool = True,
) -> list[tuple[Path, Callable[[Path], None]]]:
    """The (final path, writer) jobs of an insertion, for one ``io.commit.commit``.

    Parameters
    ----------
    ins : Insertion
    out : str or Path
        Output stem (see :func:`output_paths`).
    box : {"highlight", "highlight+shadow"}
        What YOLO and COCO boxes cover.
    min_pixels : int
        Smallest highlight labelled.
    seed : int
        The seed used (recorded).
    xtf : bool
        Write the XTF copy (the recording must have been read from an XTF file).
    """
    from ..io.images import Display, image_jobs

    paths = output_paths(out, xtf)
    meta = {
        "source": ins.recording.source,
        "inserted": [o.record() for o in ins.objects],
        "samples": "amplitude" if ins.recording.amplitude else "intensity",
    }
    image = ins.image({**ins.recording.image.metadata, **meta})
    jobs = list(image_jobs(image, paths["image"], display=Display(level="median")))
    instance, classes = ins.display_labels()
    annotations = ins.annotations(box, min_pixels)
    height, width = instance.shape
    record = {
        "index": 0,
        "image": {"file_name": paths["image"].name, "width": int(width), "height": int(height)},
        "annotations": annotations,
    }
    info = {"description": f"objects inserted into {Path(ins.recording.source).name}"}
    coco = coco_document([record], ins.categories(), info)
    objects = {
        "recording": ins.recording.source,
        "seed": int(seed),
        "samples": meta["samples"],
        "layout": "rows=pings; columns=port bins far->near, then starboard bins near->far",
        "classes": LABEL_CLASSES,
        "categories": list(ins.categories()),
        "rows_changed": [int(ins.rows.min()), int(ins.rows.max())] if ins.rows.size else [],
        "objects": [{"instance": k + 1, **o.record()} for k, o in enumerate(ins.objects)],
        "sides": {s: st.record() for s, st in ins.stats.items()},
        "files": {k: p.name for k, p in paths.items()},
    }
    jobs += [
        (paths["instances"], lambda tmp: write_label_png(tmp, instance)),
        (paths["classes"], lambda tmp: write_label_png(tmp, classes)),
        (paths["yolo"], lambda tmp: _write_text(tmp, yolo_lines(annotations, width, height))),
        (paths["coco"], lambda tmp: _write_text(tmp, json.dumps(coco, indent=1) + "\n")),
        (paths["objects"], lambda tmp: _write_text(tmp, json.dumps(objects, indent=1) + "\n")),
    ]
    if xtf:
        jobs.insert(0, xtf_job([ins], out))
    return jobs
