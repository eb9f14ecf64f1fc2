"""``sonar-raster doctor``: which headless GL backends start, and the package versions."""

from __future__ import annotations

import argparse
import os
import sys
from typing import Any

#: Packages whose versions ``doctor`` reports.
PACKAGES = (
    "sonar_raster",
    "moderngl",
    "glcontext",
    "numpy",
    "scipy",
    "trimesh",
    "OpenImageIO",
    "scikit-image",
    "rasterio",
    "embreex",
)


def add_parser(sub: Any) -> None:
    """Add the ``doctor`` subcommand to an argparse subparsers object."""
    sub.add_parser("doctor", help="show which GL backends start and the package versions")


def run(args: argparse.Namespace) -> int:
    """Probe each GL backend and print the versions; exit status 1 when none starts."""
    from importlib import metadata

    from ..rendering.gl.context import BACKENDS, ENV_VAR, probe

    print(f"{ENV_VAR}={os.environ.get(ENV_VAR, '(unset)')}")
    ok = False
    for backend in BACKENDS:
        info = probe(backend)
        if info["ok"] == "yes":
            ok = True
            print(
                f"{backend:7s} ok   {info['renderer']} | OpenGL {info['version']} | "
                f"max texture {info['max_texture_size']}"
            )
        else:
            print(f"{backend:7s} FAIL {info['error']}")
    print(f"python  {sys.version.split()[0]}")
    for pkg in PACKAGES:
        try:
            version = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            version = "not installed"
        print(f"{pkg:13s} {version}")
    return 0 if ok else 1
