"""``sonar-raster dataset``: a labelled dataset (images, masks, YOLO, COCO) from a config."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

from .._checks import cli_positive, cli_seed


def add_parser(sub: Any) -> None:
    """Add the ``dataset`` subcommand to an argparse subparsers object."""
    ds = sub.add_parser(
        "dataset",
        help="generate a labelled dataset (images, masks, YOLO, COCO) from a config",
        description="Render N randomised, labelled samples from a dataset config (.toml, or a "
        "bundled one such as 'dataset_default') into DIR; rerunning resumes a stopped run.",
    )
    ds.add_argument("config", help="dataset config file or bundled name")
    ds.add_argument("-o", "--output", required=True, metavar="DIR", help="output directory")
    ds.add_argument(
        "-n", dest="count", type=cli_positive(int), metavar="N", help="samples (default: config)"
    )
    ds.add_argument("--workers", type=cli_positive(int), default=1, help="worker processes")
    ds.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler tcp://... or 'local'")
    ds.add_argument("--seed", type=cli_seed, default=None, help="global seed (default: config)")
    ds.add_argument(
        "--force",
        action="store_true",
        help="start even when the samples are estimated over the free disk of DIR or the "
        "workers over this machine's memory",
    )
    ds.add_argument("-q", "--quiet", action="store_true", help="no progress bar or summary")


def run(args: argparse.Namespace) -> int:
    """Run ``sonar-raster dataset``; an interrupted run keeps its finished samples.

    Exit status 0 when every requested sample is ok, 1 when some failed, 2 when all did.
    """
    from ..dataset.generate import generate_dataset, load_dataset_config

    config = load_dataset_config(args.config)
    check_dataset_size(config, args)
    try:
        summary = generate_dataset(
            config,
            args.output,
            count=args.count,
            seed=args.seed,
            workers=args.workers,
            scheduler=args.scheduler,
            progress=not args.quiet,
        )
    except KeyboardInterrupt:
        print(
            f"sonar-raster: interrupted; finished samples are kept in {args.output}; "
            "run the same command again to resume",
            file=sys.stderr,
        )
        return 130
    if not args.quiet:
        print(summary.text())
    failed = len([i for i, _ in summary.failed if i < summary.requested])
    if failed:
        every = failed == summary.requested
        print(
            f"sonar-raster: {'all ' if every else ''}{failed} of {summary.requested} samples "
            f"failed (see {Path(args.output) / 'index.jsonl'})",
            file=sys.stderr,
        )
        return 2 if every else 1
    return 0


#: Bytes per image cell (ping x bin x side) of one sample's files, uncompressed (an upper
#: bound): the display PNG (1 or 2 bytes), the EXR (4, when asked), instances (2), classes (1).
_SAMPLE_BYTES = {"instances": 2, "classes": 1, "exr": 4}
#: Bytes of one sample's small files (YOLO labels, meta JSON, its index record).
_SAMPLE_EXTRA = 16384
#: Peak bytes per image cell in a worker (the render's, with labels and the effects' copies).
_WORKER_CELL_BYTES = 64
#: Bytes per texel of a worker's GL targets (as ``render``).
_TEXEL_BYTES = 24
#: Peak bytes per object in one sample (its mesh, placement, labels and share of the render):
#: 270-340 KB measured with 1000 cylinders (192 triangles) or tyres (1600) per sample of
#: 512 pings x 1024 bins, no dependence on the triangles seen.
_OBJECT_BYTES = 350e3
#: A worker's own peak before its image: imports, GL context, a small scene and the effects
#: (350 MB measured per worker with 16 pings x 64 bins and no micro-relief).
_WORKER_BASE_BYTES = 350e6
#: The main process beside its pool of workers (its trial draws, the results' queue): 295 MB
#: measured with two workers on ``dataset_default``. With one worker it is the worker.
_MAIN_BYTES = 300e6
#: Peak bytes per node of a seabed's micro-relief grid (its mesh, normals and GL buffers):
#: 280 MB over 787 k nodes measured on a ``dataset_default`` sample.
_RELIEF_NODE_BYTES = 400.0


def _image_bins(config: Any) -> tuple[int, int]:
    """Bins per side and sides of the largest sample image.

    The config's, or with a ``[background]`` its recordings' (a window keeps its recording's
    samples per ping). A recording that cannot be read here is left to the run, which names
    what is wrong.
    """
    bins, sides = int(config.bins), len(config.sides)
    background = getattr(config, "background", None)
    if background is None:
        return bins, sides
    from ..errors import SonarRasterError
    from ..io.xtf import iter_pings

    for recording in background.recordings:
        try:
            first = next(iter(iter_pings(recording, background.frequency)), None)
        except (OSError, SonarRasterError):
            continue
        if first is not None and first.sides:
            bins = max(bins, max(len(v) for v in first.sides.values()))
            sides = max(sides, len(first.sides))
    return bins, sides


def check_dataset_size(config: Any, args: argparse.Namespace) -> None:
    """Estimate the dataset's disk (per sample x count) and its workers' memory; refuse it early.

    Refused before the first sample when over the free disk of the output folder or the
    machine's memory, unless ``--force``; the estimate is printed unless ``--quiet``.

    Parameters
    ----------
    config : DatasetConfig
        The parsed config (``pings``, ``bins``, ``sides``, ``formats``, ``bits``, ``render``).
    args : argparse.Namespace
        ``count``, ``workers``, ``output``, ``force``, ``quiet``.
    """
    from .._budget import check_disk, check_memory, size_text

    count = args.count or config.count
    bins, sides = _image_bins(config)
    cells = float(config.pings) * bins * sides
    per_cell = config.bits // 8 + _SAMPLE_BYTES["instances"] + _SAMPLE_BYTES["classes"]
    if "exr" in config.formats:
        per_cell += _SAMPLE_BYTES["exr"]
    per_sample = cells * per_cell + _SAMPLE_EXTRA
    what = f"{count} samples of {config.pings} pings x {bins} bins x {sides} sides"
    check_disk([(Path(args.output) / "images" / "x", per_sample * count)], what,
               "lower -n, or write fewer formats", force=args.force)  # fmt: skip
    oversample = float(config.render.get("oversample", 2.0))
    along = int(config.render.get("along_samples", 2))
    texels = min(1 << 26, math.ceil(oversample * bins * 1.2) * config.pings * along)
    objects = sum(_most_drawn(spec.count) for spec in config.objects)
    per_worker = (
        _WORKER_BASE_BYTES
        + cells * _WORKER_CELL_BYTES
        + texels * _TEXEL_BYTES
        + objects * _OBJECT_BYTES
        + _most_relief_nodes(config) * _RELIEF_NODE_BYTES
    )
    workers = max(1, args.workers) if args.scheduler is None else 1
    what_objects = f" and up to {objects} objects" if objects else ""
    lower = "lower --workers, or the config's pings or bins"
    if objects * _OBJECT_BYTES > 0.5 * per_worker:
        lower = "lower the objects' count in the config, or --workers"
    main = _MAIN_BYTES if workers > 1 else 0.0
    check_memory(per_worker * workers + main,
                 f"{workers} workers rendering {what.split(' of ')[1]}{what_objects}",
                 f"{lower} (or add --force)", force=args.force)  # fmt: skip
    if not args.quiet:
        beside = f" and {size_text(main)} beside them" if main else ""
        print(f"dataset: {what}{what_objects} each: about {size_text(per_sample * count)} on "
              f"disk at most, {size_text(per_worker)} of memory per worker{beside}",
              file=sys.stderr)  # fmt: skip


def _most_relief_nodes(config: Any) -> float:
    """The most nodes a sample's seabed micro-relief grid can have (0 when no seabed has one).

    The grid covers the swath's ground range and the track, each with a margin, at
    ``MICRO_RESOLUTION_BINS`` range bins: most at the shortest range and the widest ping spacing
    the config draws, and never past ``MICRO_MAX_NODES``.
    """
    from ..dataset.config import range_bounds
    from ..dataset.scene import SEABED_MARGIN
    from ..scenes.seabed import MICRO_MAX_NODES, MICRO_RESOLUTION_BINS

    if not any(spec.micro_relief is not None for spec in config.seabeds):
        return 0.0
    shortest = range_bounds(config.sonar, config.sensor)[0]
    widest = config.track["spacing"].bounds[1]
    if not (math.isfinite(shortest) and shortest > 0 and math.isfinite(widest)):
        return float(MICRO_MAX_NODES)
    cell = MICRO_RESOLUTION_BINS * shortest / config.bins
    across = len(config.sides) * (shortest + SEABED_MARGIN) / cell
    along = ((config.pings - 1) * widest + 2.0 * SEABED_MARGIN) / cell
    return min(across * along, float(MICRO_MAX_NODES))


def _most_drawn(count: Any) -> int:
    """The most objects an entry's ``count`` draws in one sample.

    A Poisson count: its mean plus six standard deviations and six (exceeded with a chance
    below 1e-8).
    """
    if count.kind == "poisson":
        mean = float(count.args[0])
        return int(math.ceil(mean + 6.0 * math.sqrt(mean) + 6.0))
    return int(count.bounds[1])
