"""Labelled dataset generation: randomised scenes from a config, rendered with object-id labels.

Sample ``i`` of a dataset is a function of (config, seed, i) alone (``default_rng([seed, i])``),
so a dataset is the same bit for bit whatever the number of workers, and a stopped run resumes
where it stopped. Layout of the output folder::

    dataset.json            config, seed, categories and class codes (written once)
    index.jsonl             one record per finished sample (ok, or failed with its error)
    coco.json  data.yaml    COCO detection document and YOLO dataset file (written at the end)
    images/000000.png       display image (and .exr: linear float32 per side)
    instances/000000.png    uint16 instance ids (highlight and shadow of instance k = k)
    classes/000000.png      uint8 classes: 0 background, 1 highlight, 2 shadow
    labels/000000.txt       YOLO boxes
    meta/000000.json        every drawn parameter of the sample

Every file is written under a temporary name and renamed into place; a sample counts as done
only once its record is in the index, after all its files are in place.
"""

from __future__ import annotations

import json
import os
import secrets
import sys
import time
from collections.abc import Callable, Generator
from contextlib import ExitStack, closing
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

from ..errors import SonarRasterError
from .config import DatasetConfig, load_dataset_config
from .labels import coco_document
from .sample import CLASS_NAMES

__all__ = ["DatasetConfig", "DatasetSummary", "generate_dataset", "load_dataset_config"]

FORMAT_VERSION = 1
_SUBDIRS = ("images", "instances", "classes", "labels", "meta")
STAGES = ("scene_s", "render_s", "shadow_s", "labels_s", "effects_s", "encode_s", "write_s")


@dataclass
class DatasetSummary:
    """What a :func:`generate_dataset` call did.

    Attributes
    ----------
    out_dir : Path
    requested : int
        Samples asked for (indices ``0 .. requested - 1``).
    done_before : int
        Of those, samples already in the index when the run started (not redone).
    made : int
        Samples made by this run (ok or failed).
    failed : list of (int, str)
        Index and error of every failed sample in the dataset.
    seconds : float
        Wall time of this run.
    stage_seconds : dict of str to float
        Total time per stage over the samples made by this run (worker time).
    """

    out_dir: Path
    requested: int
    done_before: int = 0
    made: int = 0
    failed: list[tuple[int, str]] = field(default_factory=list)
    seconds: float = 0.0
    stage_seconds: dict[str, float] = field(default_factory=dict)

    @property
    def rate(self) -> float:
        """Samples made per second of wall time."""
        return self.made / self.seconds if self.seconds > 0 else 0.0

    def text(self) -> str:
        """A short human summary."""
        ok = self.requested - len([i for i, _ in self.failed if i < self.requested])
        lines = [
            f"dataset {self.out_dir}: {ok} of {self.requested} samples ok, "
            f"{len(self.failed)} failed; made {self.made} in {self.seconds:.1f} s "
            f"({self.rate:.2f} samples/s), {self.done_before} were already done"
        ]
        if self.made and self.stage_seconds:
            per = ", ".join(
                f"{k[:-2]} {1000 * v / self.made:.0f}" for k, v in self.stage_seconds.items()
            )
            lines.append(f"mean ms per sample: {per}")
        for index, error in self.failed[:5]:
            lines.append(f"failed sample {index}: {error}")
        if len(self.failed) > 5:
            lines.append(f"... and {len(self.failed) - 5} more failures (see index.jsonl)")
        return "\n".join(lines)


def _atomic_write(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.{secrets.token_hex(6)}.tmp")  # resume sweeps .*.tmp
    try:
        with open(tmp, "xb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


class _Folder:
    """The output folder: lock, manifest, stale temporary files and the index."""

    def __init__(self, root: Path, config: DatasetConfig, seed: int):
        self.root, self.config, self.seed = root, config, seed
        self.records: dict[int, dict] = {}
        self._lock: Any = None
        self._index: Any = None

    def __enter__(self) -> _Folder:
        self._check_empty_or_ours()
        try:
            self.root.mkdir(parents=True, exist_ok=True)
            for sub in _SUBDIRS:
                (self.root / sub).mkdir(exist_ok=True)
        except OSError as exc:
            raise SonarRasterError(f"cannot create {self.root}: {exc.strerror or exc}") from None
        self._take_lock()
        try:
            self._check_manifest()
            self._remove_temporaries()
            self._load_index()
            self._index = open(self.root / "index.jsonl", "a", encoding="utf-8")  # noqa: SIM115
        except BaseException:
            self.__exit__()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        if self._index is not None:
            self._index.close()
        if self._lock is not None:
            self._lock.close()

    def _check_empty_or_ours(self) -> None:
        """Refuse a folder that holds other things than a dataset (or its empty skeleton)."""
        if not self.root.is_dir() or (self.root / "dataset.json").exists():
            return
        for entry in self.root.iterdir():
            if entry.name == ".lock" or (
                entry.name in _SUBDIRS and entry.is_dir() and not any(entry.iterdir())
            ):
                continue
            raise SonarRasterError(
                f"{self.root} is not empty and holds no dataset ({entry.name}); "
                "give a new or empty folder"
            )

    def _take_lock(self) -> None:
        import fcntl

        self._lock = open(self.root / ".lock", "a")  # noqa: SIM115
        try:
            fcntl.flock(self._lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            self._lock.close()
            self._lock = None
            raise SonarRasterError(
                f"another run is writing to {self.root}; wait for it or use another folder"
            ) from None

    def manifest(self) -> dict:
        c = self.config
        return {
            "format_version": FORMAT_VERSION,
            "name": c.name,
            "seed": self.seed,
            "config_digest": c.digest,
            "config": c.raw,
            "categories": list(c.categories),
            "classes": CLASS_NAMES,
            "instance_ids": "k = object instance k (its highlight and its shadow), 0 = none",
            "layout": "rows=pings; columns=port bins far->near, then starboard bins near->far",
        }

    def _check_manifest(self) -> None:
        path = self.root / "dataset.json"
        if not path.exists():
            _atomic_write(path, _json_bytes(self.manifest()))
            return
        try:
            old = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            raise SonarRasterError(f"{path} is unreadable; use a new output folder") from None
        if old.get("config_digest") != self.config.digest or old.get("seed") != self.seed:
            raise SonarRasterError(
                f"{self.root} holds a dataset made with another config or seed "
                f"(seed {old.get('seed')}); use a new folder, or the same config and --seed"
            )

    def _remove_temporaries(self) -> None:
        for folder in (self.root, *(self.root / s for s in _SUBDIRS)):
            for path in folder.glob(".*.tmp"):
                path.unlink(missing_ok=True)

    def _load_index(self) -> None:
        """Read the index and rewrite it compacted.

        Keeps the last valid record per sample whose files all exist; a torn last line from
        a killed run, and failures marked ``retry`` (not bad input), are dropped, so those
        samples are made again.
        """
        path = self.root / "index.jsonl"
        if not path.exists():
            return
        for line in path.read_text(encoding="utf-8").splitlines():
            try:
                rec = json.loads(line)
            except ValueError:
                continue
            if isinstance(rec, dict) and isinstance(rec.get("index"), int):
                self.records[rec["index"]] = rec
        for index, rec in list(self.records.items()):
            files = rec.get("files", {}).values() if rec.get("status") == "ok" else ()
            if (
                rec.get("status") not in ("ok", "failed")
                or rec.get("retry", False)
                or not all((self.root / f).is_file() for f in files)
            ):
                del self.records[index]
        text = "".join(_json_line(self.records[i]) for i in sorted(self.records))
        _atomic_write(path, text.encode())

    def commit(self, files: dict[str, bytes], record: dict) -> None:
        """Put a sample's files in place, then record it in the index."""
        start = time.perf_counter()
        for rel, data in files.items():
            _atomic_write(self.root / rel, data)
        if record.get("status") == "ok":
            record["timings"]["write_s"] = time.perf_counter() - start
        record["committed_unix"] = time.time()
        self._index.write(_json_line(record))
        self._index.flush()
        os.fsync(self._index.fileno())
        self.records[record["index"]] = record

    def finish(self) -> None:
        """Write the COCO document and the YOLO dataset file from the index."""
        ok = [r for r in self.records.values() if r.get("status") == "ok"]
        info = {
            "description": self.config.name,
            "version": str(FORMAT_VERSION),
            "seed": self.seed,
            "config_digest": self.config.digest,
        }
        doc = coco_document(ok, self.config.categories, info)
        _atomic_write(self.root / "coco.json", _json_bytes(doc))
        names = "".join(f"  {k}: {n}\n" for k, n in enumerate(self.config.categories))
        yaml = f"path: .\ntrain: images\nval: images\nnames:\n{names}"
        _atomic_write(self.root / "data.yaml", yaml.encode())


def _json_line(record: dict) -> str:
    return json.dumps(record, separators=(",", ":"), allow_nan=False) + "\n"


def _json_bytes(doc: Any) -> bytes:
    return (json.dumps(doc, indent=1, allow_nan=False) + "\n").encode()


#: Samples drawn (scene geometry, no render) before any output: when all of them fail the
#: config is refused with the first one's reason instead of failing sample by sample.
TRIAL_DRAWS = 3


def _check_draws(config: DatasetConfig, seed: int, count: int) -> None:
    """Refuse, in one line, a config none of whose first samples can be drawn.

    That is a bad fixed value (``altitude = 0``, ``radius = 0``), which would otherwise fail
    once per sample; a draw that fails only sometimes is left to its sample's record. Cost: one
    draw when the first succeeds.
    """
    import numpy as np

    from .scene import draw_sample

    if config.background is not None:
        return
    name = config.name or "the dataset config"
    rng = np.random.default_rng(seed)
    for k, spec in enumerate(config.objects):  # whether or not the samples draw them
        if spec.primitive is None:
            continue
        why = _all_fail([partial(_object_trial, spec, rng, config.base)] * TRIAL_DRAWS)
        if why:
            raise SonarRasterError(
                f"{name}: object {k + 1} ({spec.label}) fails in all {TRIAL_DRAWS} draws, so "
                f"every sample that drew it would: {why}"
            )
    first = min(TRIAL_DRAWS, count)
    why = _all_fail([partial(draw_sample, config, seed, index) for index in range(first)])
    if why:
        raise SonarRasterError(
            f"{name}: the first {first} sample(s) all fail to draw, so every sample would: {why}"
        )


def _object_trial(spec: Any, rng: Any, base: Path) -> None:
    """Draw an object entry's parameters and build its mesh (a bad value raises)."""
    from .scene import draw_object_params, object_mesh_of

    object_mesh_of(spec, draw_object_params(spec, rng), base)


def _all_fail(attempts: list[Callable[[], object]]) -> str | None:
    """The first failure's reason when every one of ``attempts`` fails, else None."""
    first = None
    for attempt in attempts:
        try:
            attempt()
            return None
        except SonarRasterError as exc:
            first = first or str(exc)
        except (ValueError, TypeError, ArithmeticError) as exc:  # a value of the wrong kind
            first = first or f"{type(exc).__name__}: {exc}"
    return first


def _check_effects(config: DatasetConfig) -> None:
    if not config.effects:
        return
    from .sample import effects_of

    names = [None] if config.sensor is None else config.sensor.args
    for name in names:  # a bad key fails here, before any output
        effects_of(config, name)


def _results(
    config: DatasetConfig, seed: int, todo: list[int], workers: int, client: Any
) -> Generator[tuple[dict[str, bytes], dict], None, None]:
    """Finished samples from the chosen runner; closing it stops the workers."""
    from . import runner

    if not todo:
        return
    if client is not None:
        yield from runner.run_dask(config, seed, todo, client, workers)
    elif workers == 1:
        yield from runner.run_in_process(config, seed, todo)
    else:
        yield from runner.run_pool(config, seed, todo, workers)


def generate_dataset(
    config: DatasetConfig | str | Path,
    out_dir: str | Path,
    *,
    count: int | None = None,
    seed: int | None = None,
    workers: int = 1,
    scheduler: str | None = None,
    progress: bool = False,
) -> DatasetSummary:
    """Make (or finish) a labelled dataset in ``out_dir``.

    Samples already recorded in ``out_dir/index.jsonl`` (ok, or failed on bad input) are not
    made again;
    the rest of ``0 .. count - 1`` are made, and ``coco.json`` and ``data.yaml`` are rewritten
    from the index at the end.

    Parameters
    ----------
    config : DatasetConfig, path or name
        The dataset configuration (a ``.toml`` path, or a bundled config's name such as
        ``"dataset_default"``, is loaded).
    out_dir : str or Path
        Output folder; created if missing. It must be empty or hold this dataset (same config
        and seed).
    count : int, optional
        Number of samples; default the config's ``[dataset] count``.
    seed : int, optional
        Global seed, >= 0; default the config's ``[dataset] seed``.
    workers : int
        Worker processes (or Dask workers for ``scheduler="local"``); 1 renders in this process.
    scheduler : str, optional
        A Dask scheduler address (``tcp://host:8786``), or "local" for a local Dask cluster.
    progress : bool
        Show a progress bar (samples/s and ETA).

    Returns
    -------
    DatasetSummary

    Raises
    ------
    SonarRasterError
        On a bad config or arguments, an output folder holding another dataset or in use by
        another run, or a worker pool that died (rerun to resume).
    """
    if not isinstance(config, DatasetConfig):
        config = load_dataset_config(config)
    count = config.count if count is None else count
    seed = config.seed if seed is None else seed
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise SonarRasterError(f"the sample count must be a positive integer, got {count!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise SonarRasterError(f"the seed must be an integer >= 0, got {seed!r}")
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise SonarRasterError(f"workers must be a positive integer, got {workers!r}")
    _check_effects(config)
    _check_draws(config, seed, count)
    summary = DatasetSummary(Path(out_dir), count)
    start = time.perf_counter()
    with ExitStack() as stack:
        client = None
        if scheduler:  # connect first: an unreachable scheduler leaves no output behind
            from .runner import dask_client

            client = stack.enter_context(dask_client(scheduler, workers))
        _run(config, seed, count, workers, client, progress, summary, Path(out_dir))
    summary.seconds = time.perf_counter() - start
    return summary


def _run(
    config: DatasetConfig,
    seed: int,
    count: int,
    workers: int,
    client: Any,
    progress: bool,
    summary: DatasetSummary,
    out_dir: Path,
) -> None:
    """Make the missing samples into ``out_dir`` and fill in ``summary``."""
    start = time.perf_counter()
    with _Folder(out_dir, config, seed) as folder:
        todo = [i for i in range(count) if i not in folder.records]
        summary.done_before = count - len(todo)
        stages = dict.fromkeys(STAGES, 0.0)
        bar = _progress(len(todo), progress)
        try:
            with closing(_results(config, seed, todo, workers, client)) as results:
                for files, record in results:
                    folder.commit(files, record)
                    summary.made += 1
                    for key, value in record.get("timings", {}).items():
                        stages[key] = stages.get(key, 0.0) + value
                    if record["status"] != "ok":
                        bar.set_postfix_str(f"{summary.made} made, failed {record['index']}")
                    bar.update(1)
        finally:
            bar.close()
            summary.seconds = time.perf_counter() - start
            summary.stage_seconds = stages
            summary.failed = sorted(
                (i, r.get("error", "")) for i, r in folder.records.items() if r["status"] != "ok"
            )
        folder.finish()


def _progress(total: int, show: bool) -> Any:
    from tqdm import tqdm

    return tqdm(
        total=total,
        desc="samples",
        unit="sample",
        disable=not show,
        dynamic_ncols=True,
        file=sys.stderr,
    )
