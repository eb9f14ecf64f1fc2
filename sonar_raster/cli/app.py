"""The ``sonar-raster`` command line: the top-level parser, error handling and dispatch.

Each command lives in its own module (``render``, ``invert``, ``dataset``, ``track``,
``scenes``, ``doctor``) with ``add_parser(sub)`` and ``run(args) -> int``. Heavy modules
(moderngl, trimesh, OpenImageIO) load inside the commands, so ``--help`` answers at once. Bad
input ends with one line on stderr and exit status 2, with no traceback and no output file
left behind.
"""

from __future__ import annotations

import argparse
import logging
import sys

from ..errors import SonarRasterError
from . import dataset, doctor, invert, render, scenes, track

EXIT_BAD_INPUT = 2

#: The commands in the order ``--help`` lists them.
COMMANDS = {
    "render": render,
    "invert": invert,
    "dataset": dataset,
    "track": track,
    "scenes": scenes,
    "doctor": doctor,
}


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: ``sonar-raster: error: ... (see --help)``, exit 2."""

    def error(self, message: str):  # type: ignore[override]
        print(f"sonar-raster: error: {message} (see '{self.prog} --help')", file=sys.stderr)
        sys.exit(EXIT_BAD_INPUT)


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="sonar-raster",
        description="Side-scan sonar images from 3D scenes, rendered with headless OpenGL.",
    )
    sub = parser.add_subparsers(
        dest="command", required=True, metavar="COMMAND", parser_class=_Parser
    )
    for command in COMMANDS.values():
        command.add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    args = _parser().parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="sonar-raster: %(message)s")
    try:
        return COMMANDS[args.command].run(args)
    except SonarRasterError as exc:
        print(f"sonar-raster: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("sonar-raster: interrupted; nothing was written", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
