"""``sonar-raster scenes``: list the bundled scenes."""

from __future__ import annotations

import argparse
from typing import Any


def add_parser(sub: Any) -> None:
    """Add the ``scenes`` subcommand to an argparse subparsers object."""
    scenes = sub.add_parser(
        "scenes",
        help="list the bundled scenes",
        description="List the bundled scenes, each usable by name in 'sonar-raster render "
        "NAME'; 'default' is one of them under a second name.",
    )
    scenes.add_argument("-q", "--quiet", action="store_true", help="names only, one a line")


def run(args: argparse.Namespace) -> int:
    """Print each bundled scene's name and description; ``default`` first."""
    from ..scenes.bundled import DEFAULT_SCENE, list_bundled

    bundled = list_bundled()
    descriptions = dict(bundled)
    rows = [("default", f"= {DEFAULT_SCENE}: {descriptions.get(DEFAULT_SCENE, '')}"), *bundled]
    for name, description in rows:
        print(name if args.quiet else f"{name:24s} {description}")
    return 0
