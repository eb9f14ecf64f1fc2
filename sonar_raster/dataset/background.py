"""Dataset samples on real seabeds: a window of a recording with inserted objects.

With a ``[background]`` table a sample draws, from ``default_rng([seed, index])`` in this
order: the recording, the window's first ping (``[dataset] pings`` pings long), each
``[[objects]]`` entry's count and then per instance its parameters, reflectivity, scale and
yaw, and finally the seed of the insertion (places, shadow noise, speckle). Objects are
inserted with :func:`sonar_raster.insert.insert_objects` (on the sides of ``[dataset] sides``
the recording has); the image is the window's composite (no sensor effects: the recording has
its own). ``[sonar]``, ``[track]``, ``[[seabed]]``, ``[placement]`` and ``[effects]`` are not
used. A sample whose objects find no place fails with its reason; the batch goes on.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import SonarRasterError
from ..image import SonarImage
from .config import DatasetConfig, ObjectSpec

__all__ = ["draw_background_sample", "window"]

_RECORDINGS: dict[tuple[str, str, float | str | None], Any] = {}


def _recording(path: str, samples: str, frequency: float | str | None = None) -> Any:
    """The recording of ``path``, read and bottom-tracked once per process."""
    from ..insert.recording import read_recording

    key = (path, samples, frequency)
    if key not in _RECORDINGS:
        _RECORDINGS[key] = read_recording(path, samples=samples, frequency=frequency)
    return _RECORDINGS[key]


def window(rec: Any, start: int, stop: int) -> Any:
    """The pings ``start:stop`` of a recording (bottom track from the whole line).

    Parameters
    ----------
    rec : Recording
    start, stop : int
        Rows, stop excluded.
    """
    rows = slice(start, stop)
    meta = dict(rec.image.metadata)
    for key in ("ping_indices", "ping_numbers"):
        if key in meta:
            meta[key] = list(meta[key][rows])
    image = SonarImage({s: v[rows] for s, v in rec.image.sides.items()}, rec.image.sonar, meta)
    return replace(
        rec,
        intensity={s: v[rows] for s, v in rec.intensity.items()},
        image=image,
        trajectory=rec.trajectory.subset(rows),
        altitude=rec.altitude[rows],
        valid=rec.valid[rows],
    )


def _mesh(spec: ObjectSpec, rng: np.random.Generator, base: Path) -> tuple[Any, dict]:
    from ..insert.objects import resting_mesh
    from .scene import draw_object_params, object_mesh_of

    params = draw_object_params(spec, rng)
    reflectivity = float(spec.reflectivity.draw(rng))
    scale = float(spec.scale.draw(rng))
    yaw = float(spec.yaw_deg.draw(rng))
    if not (scale > 0 and reflectivity >= 0):
        raise SonarRasterError(
            f"drawn scale {scale:g} or reflectivity {reflectivity:g} of '{spec.label}' is out "
            "of range (scale > 0, reflectivity >= 0)"
        )
    v, f = object_mesh_of(spec, params, base)
    mesh = resting_mesh(spec.label, spec.primitive or str(spec.file), v * scale, f,
                        reflectivity, yaw, params)  # fmt: skip
    drawn = {"params": params, "reflectivity": reflectivity, "scale": scale, "yaw_deg": yaw}
    return mesh, drawn


def draw_background_sample(config: DatasetConfig, seed: int, index: int, renderer: Any) -> dict:
    """Draw and insert sample ``index`` of a background dataset.

    Parameters
    ----------
    config : DatasetConfig
        With ``background`` set.
    seed, index : int
        Global seed and sample index.
    renderer : RasterRenderer
        The calling process's renderer.

    Returns
    -------
    dict
        ``insertion`` (:class:`~sonar_raster.insert.Insertion` of the window), ``drawn``
        (per object: class, category id, drawn values) and ``params`` (recording, window,
        insertion seed), JSON-able but for the insertion.
    """
    from ..insert.insertion import insert_objects

    spec = config.background
    if spec is None:
        raise SonarRasterError("the config has no [background] table")
    rng = np.random.default_rng([int(seed), int(index)])
    path = spec.recordings[int(rng.integers(len(spec.recordings)))]
    rec = _recording(path, spec.samples, spec.frequency)
    pings = rec.shape[0]
    length = min(config.pings, pings)
    start = int(rng.integers(0, pings - length + 1))
    part = window(rec, start, start + length)
    meshes, drawn = [], []
    for obj in config.objects:
        for _ in range(int(obj.count.draw(rng))):
            mesh, values = _mesh(obj, rng, config.base)
            meshes.append(mesh)
            category = config.categories.index(obj.label) + 1
            drawn.append({"class": obj.label, "category_id": category, **values})
    insert_seed = int(rng.integers(2**31))
    sides = tuple(s for s in config.sides if s in part.sides)
    if not sides:
        raise SonarRasterError(f"{path} has none of the sides {', '.join(config.sides)}")
    if not meshes:
        raise SonarRasterError("the sample drew no objects; raise the [[objects]] counts")
    ins = insert_objects(
        part, meshes, seed=insert_seed, renderer=renderer, sides=sides,
        seabed_reflectivity=spec.seabed_reflectivity, shadow_ratio=config.shadow_ratio,
        base=config.base,
    )  # fmt: skip
    params = {
        "index": int(index),
        "seed": int(seed),
        "background": {"recording": Path(path).name, "first_ping": start, "pings": length},
        "insert_seed": insert_seed,
    }
    return {"insertion": ins, "drawn": drawn, "params": params}
