"""``sonar-raster scenes``: list the bundled scenes."""

from __future__ import annotations

import argparse
from typing import Any


def add_parser(sub: Any) -> None:
    """Add the ``scenes`` subcommand to an argparse subparsers object."""
    sub.add_parser("scenes", help="list the bundled scenes")


def run(args: argparse.Namespace) -> int:
    """Print each bundled scene's name and description."""
    from ..scenes.bundled import list_bundled

    for name, description in list_bundled():
        print(f"{name:24s} {description}")
    return 0
