"""``sonar-raster dataset``: a labelled dataset (images, masks, YOLO, COCO) from a config."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from .._checks import cli_positive


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
    ds.add_argument("--seed", type=int, default=None, help="global seed (default: config)")
    ds.add_argument("-q", "--quiet", action="store_true", help="no progress bar or summary")


def run(args: argparse.Namespace) -> int:
    """Run ``sonar-raster dataset``; an interrupted run keeps its finished samples.

    Exit status 0 when every requested sample is ok, 1 when some failed, 2 when all did.
    """
    from ..dataset.generate import generate_dataset, load_dataset_config

    config = load_dataset_config(args.config)
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
