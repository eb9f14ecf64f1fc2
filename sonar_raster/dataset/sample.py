"""One dataset sample: draw, render with labels, derive shadows, apply effects, encode files.

:func:`make_sample` returns the sample's files as bytes (so a worker on another machine needs
no shared file system) and a record for the index and the COCO document. Files hold nothing
that depends on the worker (no times, host names or GL strings), so they are identical bit for
bit whichever process makes them.
"""

from __future__ import annotations

import atexit
import json
import os
import shutil
import tempfile
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import SonarRasterError
from ..image import SonarImage
from .config import DatasetConfig
from .labels import annotate, instances_from_labels, shadow_owners, to_display, yolo_lines
from .scene import SampleScene, draw_sample

CLASS_NAMES = {0: "background", 1: "highlight", 2: "shadow"}
_TMP: dict[str, str] = {}
_EPOCH = "1970:01:01 00:00:00"


@dataclass(frozen=True)
class Sample:
    """A made sample: ``files`` maps paths relative to the dataset folder to their bytes."""

    files: dict[str, bytes]
    record: dict


def sample_paths(index: int, formats: tuple[str, ...]) -> dict[str, str]:
    """Relative paths of sample ``index``'s files, by kind."""
    stem = f"{index:06d}"
    paths = {"image": f"images/{stem}.png"}
    if "exr" in formats:
        paths["exr"] = f"images/{stem}.exr"
    paths.update(
        {
            "yolo": f"labels/{stem}.txt",
            "instances": f"instances/{stem}.png",
            "classes": f"classes/{stem}.png",
            "sidecar": f"meta/{stem}.json",
        }
    )
    return paths


def _render(renderer: Any, sample: SampleScene) -> SonarImage:
    """The full scene with labels."""
    image = renderer.render(sample.scene, sample.sonar, sample.trajectory, labels=True)
    if getattr(image, "labels", None) is None:
        raise SonarRasterError("this renderer has no object-id label pass (labels=True)")
    return image


def _seabed_alone(renderer: Any, sample: SampleScene, image: SonarImage) -> dict[str, np.ndarray]:
    """The seabed alone over the pings that objects reach (zeros elsewhere)."""
    seabed = {s: np.zeros_like(a) for s, a in image.sides.items()}
    rows = sample.object_pings
    if rows is not None:  # one render of just those pings: the track splits at the gaps
        alone = renderer.render(sample.seabed, sample.sonar, sample.trajectory.subset(rows))
        for side, values in alone.sides.items():
            seabed[side][rows] = values
    return seabed


def _labels(
    image: SonarImage, seabed: dict[str, np.ndarray], config: DatasetConfig
) -> tuple[np.ndarray, np.ndarray]:
    """Display-layout instance ids (uint16) and classes (uint8)."""
    inst_sides, class_sides = {}, {}
    for side, raw in image.sides.items():
        assert image.labels is not None  # checked by _render
        labels = image.labels[side]
        highlight = instances_from_labels(labels)
        shadow = shadow_owners(raw, seabed[side], highlight, config.shadow_ratio)
        inst_sides[side] = highlight + shadow
        cls = np.zeros(raw.shape, dtype=np.uint8)
        cls[highlight > 0] = 1
        cls[shadow > 0] = 2
        class_sides[side] = cls
    return to_display(inst_sides), to_display(class_sides)


def _effects(image: SonarImage, config: DatasetConfig, drawn: SampleScene) -> SonarImage:
    """Apply the config's effects (:func:`effects_of`); none enabled: the raw image."""
    effects = effects_of(config, drawn.params["sonar"].get("preset"))
    if not effects.stages:
        return image
    from ..effects.chain import apply_effects

    return apply_effects(image, effects, seed=drawn.effects_seed, trajectory=drawn.trajectory)


def effects_of(config: DatasetConfig, sensor: str | None = None) -> Any:
    """:class:`sonar_raster.effects.chain.Effects` of a config.

    Without an ``[effects]`` table: every effect of the sample's sensor preset (``[sonar]
    preset``), else of the default sensor (:data:`~sonar_raster.effects.presets.DEFAULT_SENSOR`).
    A table is the complete effect set (keywords of :class:`~sonar_raster.effects.Effects`)
    unless it names a ``sensor``, or the config a preset, whose effects its other keys then
    replace; ``sensor = "ideal"`` starts from none (raw images).

    Parameters
    ----------
    config : DatasetConfig
        The dataset config.
    sensor : str, optional
        The sample's drawn ``[sonar] preset``.
    """
    from ..effects.chain import Effects
    from ..effects.presets import DEFAULT_SENSOR, preset

    if config.effects is None:
        return preset(sensor or DEFAULT_SENSOR).effects()
    where = f"{Path(config.source).name} [effects]"
    table = config.effects if sensor is None else {"sensor": sensor, **config.effects}
    return Effects.from_table(table, base=config.base, where=where)


def _tmpdir() -> Path:
    """A private scratch folder of this process for the image encoders."""
    key = f"{os.getpid()}-{threading.get_ident()}"  # Dask workers may run several threads
    if key not in _TMP or not Path(_TMP[key]).is_dir():
        _TMP[key] = tempfile.mkdtemp(prefix="sonar-raster-dataset-")
        atexit.register(shutil.rmtree, _TMP[key], True)
    return Path(_TMP[key])


def _encode_png(pixels: np.ndarray, path: Path) -> bytes:
    import OpenImageIO as oiio

    fmt = oiio.UINT16 if pixels.dtype == np.uint16 else oiio.UINT8
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], 1, fmt)
    spec.channelnames = ("Y",)
    out = oiio.ImageOutput.create(str(path))
    try:
        if out is None or not out.open(str(path), spec):
            raise SonarRasterError(f"cannot encode a PNG label image: {oiio.geterror()}")
        if not out.write_image(np.ascontiguousarray(pixels)[:, :, np.newaxis]):
            raise SonarRasterError(f"cannot encode a PNG label image: {out.geterror()}")
    finally:
        if out is not None:
            out.close()
    return _take(path)


def _encode_exr(image: SonarImage, path: Path) -> bytes:
    """Encode a linear float32 EXR: one channel per side, ``sonar:*`` attributes.

    ``DateTime`` is fixed: OpenImageIO stamps the clock otherwise, and the bytes would differ.
    """
    import OpenImageIO as oiio

    pixels = np.stack(list(image.sides.values()), axis=-1).astype(np.float32)
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], oiio.FLOAT)
    spec.channelnames = tuple(image.sides)
    spec.attribute("compression", "zip")
    spec.attribute("DateTime", _EPOCH)
    for key, value in image.sonar.to_dict().items():
        text = ",".join(map(str, value)) if isinstance(value, list) else value
        spec.attribute(f"sonar:{key}", text if isinstance(text, (str, int, float)) else str(text))
    spec.attribute("sonar:layout", "rows=pings, columns=slant-range bins near->far")
    out = oiio.ImageOutput.create(str(path))
    try:
        if out is None or not out.open(str(path), spec) or not out.write_image(pixels):
            raise SonarRasterError(f"cannot encode the EXR image: {oiio.geterror()}")
    finally:
        if out is not None:
            out.close()
    return _take(path)


def _take(path: Path) -> bytes:
    data = path.read_bytes()
    path.unlink()
    return data


def _encode(
    image: SonarImage,
    instance: np.ndarray,
    classes: np.ndarray,
    config: DatasetConfig,
) -> dict[str, bytes]:
    from ..io.images import write_image

    tmp = _tmpdir()
    path = tmp / "image.png"
    write_image(
        image, path, bit_depth=config.bits, dynamic_range_db=config.dynamic_range_db, sidecar=False
    )
    out = {"image": _take(path)}
    if "exr" in config.formats:
        out["exr"] = _encode_exr(image, tmp / "image.exr")
    out["instances"] = _encode_png(instance, tmp / "instances.png")
    out["classes"] = _encode_png(classes, tmp / "classes.png")
    return out


def make_sample(config: DatasetConfig, seed: int, index: int, renderer: Any) -> Sample:
    """Make sample ``index`` of the dataset ``(config, seed)``.

    Parameters
    ----------
    config : DatasetConfig
    seed, index : int
        Global seed and sample index; together with the config they fix every byte.
    renderer : RasterRenderer
        A renderer with the object-id pass, owned by the calling process.

    Returns
    -------
    Sample
        Files (image PNG [and EXR], instance-id PNG uint16, class PNG uint8, YOLO txt, JSON
        sidecar) as bytes by relative path, and the record: ``index``, ``status`` "ok",
        ``image`` (COCO image entry), ``annotations``, ``files`` and ``timings`` (seconds).
    """
    if config.background is not None:
        return _background_sample(config, seed, index, renderer)
    t0, cpu0 = time.perf_counter(), time.process_time()
    drawn = draw_sample(config, seed, index)
    t1 = time.perf_counter()
    image = _render(renderer, drawn)
    t_render = time.perf_counter()
    seabed = _seabed_alone(renderer, drawn, image)
    t2 = time.perf_counter()
    instance, classes = _labels(image, seabed, config)
    categories = [i["category_id"] for i in drawn.instances]
    annotations = annotate(instance, classes, categories, config.box, config.min_pixels)
    t3 = time.perf_counter()
    image = _effects(image, config, drawn)
    t4 = time.perf_counter()
    deterministic_meta = {"dataset": config.name, "index": int(index), "seed": int(seed)}
    image = SonarImage(image.sides, image.sonar, deterministic_meta)
    encoded = _encode(image, instance, classes, config)
    height, width = instance.shape
    paths = sample_paths(index, config.formats)
    encoded["yolo"] = yolo_lines(annotations, width, height).encode()
    sidecar = _sidecar(config, drawn, annotations, renderer, (height, width), paths)
    text = json.dumps(sidecar, indent=1, allow_nan=False, default=_plain)
    encoded["sidecar"] = (text + "\n").encode()
    t5 = time.perf_counter()
    record = {
        "index": int(index),
        "status": "ok",
        "files": paths,
        "image": {"file_name": paths["image"], "width": int(width), "height": int(height)},
        "annotations": annotations,
        "timings": {
            "scene_s": t1 - t0,
            "render_s": t_render - t1,
            "shadow_s": t2 - t_render,
            "labels_s": t3 - t2,
            "effects_s": t4 - t3,
            "encode_s": t5 - t4,
            "cpu_s": time.process_time() - cpu0,  # every thread of this process (llvmpipe's too)
        },
        "pid": os.getpid(),
    }
    return Sample({paths[kind]: data for kind, data in encoded.items()}, record)


def _sidecar(
    config: DatasetConfig,
    drawn: SampleScene,
    annotations: list[dict],
    renderer: Any,
    shape: tuple[int, int],
    paths: dict[str, str],
) -> dict:
    visible = {a["instance"]: a for a in annotations}
    objects = []
    for inst in drawn.instances:
        a = visible.get(inst["instance"])
        objects.append(
            {
                **inst,
                "visible": a is not None,
                "bbox": None if a is None else a["bbox"],
                "area": 0 if a is None else a["area"],
                "shadow_bbox": None if a is None else a["shadow_bbox"],
                "shadow_area": 0 if a is None else a["shadow_area"],
            }
        )
    return {
        "dataset": config.name,
        "config_digest": config.digest,
        **drawn.params,
        "objects": objects,
        "image": {"height": shape[0], "width": shape[1], "sides": list(config.sides)},
        "files": paths,
        "layout": "rows=pings; columns=port bins far->near, then starboard bins near->far",
        "classes": CLASS_NAMES,
        "labels": {"shadow_ratio": config.shadow_ratio, "box": config.box},
        "render": asdict(renderer.settings),
        "effects": config.effects,
    }


def _plain(value: Any) -> Any:
    """JSON for numpy scalars and arrays (``json.dumps`` default)."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def _background_sample(config: DatasetConfig, seed: int, index: int, renderer: Any) -> Sample:
    """A sample on a real recording's window (``[background]``, :mod:`.background`)."""
    from .background import draw_background_sample

    t0, cpu0 = time.perf_counter(), time.process_time()
    made = draw_background_sample(config, seed, index, renderer)
    ins, drawn = made["insertion"], made["drawn"]
    t1 = time.perf_counter()
    sides = [s for s in config.sides if s in ins.intensity]
    instance = to_display({s: ins.instance[s] for s in sides})
    classes = to_display({s: ins.classes[s] for s in sides})
    categories = [d["category_id"] for d in drawn]
    annotations = annotate(instance, classes, categories, config.box, config.min_pixels)
    deterministic_meta = {"dataset": config.name, "index": int(index), "seed": int(seed)}
    full = ins.image(deterministic_meta)
    image = SonarImage({s: full.sides[s] for s in sides}, full.sonar, deterministic_meta)
    t2 = time.perf_counter()
    encoded = _encode(image, instance, classes, config)
    height, width = instance.shape
    paths = sample_paths(index, config.formats)
    encoded["yolo"] = yolo_lines(annotations, width, height).encode()
    visible = {a["instance"]: a for a in annotations}
    objects = [
        {"instance": k + 1, **d, **o.record(), "visible": k + 1 in visible,
         "bbox": visible[k + 1]["bbox"] if k + 1 in visible else None,
         "shadow_bbox": visible[k + 1]["shadow_bbox"] if k + 1 in visible else None}
        for k, (d, o) in enumerate(zip(drawn, ins.objects, strict=True))
    ]  # fmt: skip
    sidecar = {
        "dataset": config.name,
        "config_digest": config.digest,
        **made["params"],
        "objects": objects,
        "recording_stats": {s: ins.stats[s].record() for s in sides},
        "image": {"height": height, "width": width, "sides": sides},
        "files": paths,
        "layout": "rows=pings; columns=port bins far->near, then starboard bins near->far",
        "classes": CLASS_NAMES,
        "labels": {"shadow_ratio": config.shadow_ratio, "box": config.box},
    }
    text = json.dumps(sidecar, indent=1, allow_nan=False, default=_plain)
    encoded["sidecar"] = (text + "\n").encode()
    t3 = time.perf_counter()
    record = {
        "index": int(index),
        "status": "ok",
        "files": paths,
        "image": {"file_name": paths["image"], "width": int(width), "height": int(height)},
        "annotations": annotations,
        "timings": {
            "scene_s": 0.0,
            "render_s": t1 - t0,  # drawing, rendering and compositing the insertion
            "shadow_s": 0.0,
            "labels_s": t2 - t1,
            "effects_s": 0.0,
            "encode_s": t3 - t2,
            "cpu_s": time.process_time() - cpu0,
        },
        "pid": os.getpid(),
    }
    return Sample({paths[kind]: data for kind, data in encoded.items()}, record)
