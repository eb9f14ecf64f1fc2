"""The ``sonar-raster`` command: one module per command, :func:`main` the entry point."""

from .app import main

__all__ = ["main"]
