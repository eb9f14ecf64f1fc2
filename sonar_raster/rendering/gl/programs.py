"""Load the GLSL sources beside this module (``rendering/gl/*.glsl``), specialised by #defines."""

from __future__ import annotations

from collections.abc import Mapping
from functools import cache
from importlib import resources

STAGES = ("VERTEX_SHADER", "GEOMETRY_SHADER", "FRAGMENT_SHADER", "COMPUTE_SHADER")


@cache
def shader_source(name: str) -> str:
    """Text of ``render/gl/<name>``; raises FileNotFoundError naming the file if it is missing."""
    path = resources.files("sonar_raster.rendering.gl").joinpath(name)
    if not path.is_file():
        raise FileNotFoundError(f"shader file {name!r} is missing from the sonar_raster package")
    return path.read_text(encoding="utf-8")


def specialise(name: str, stage: str, defines: Mapping[str, object]) -> str:
    """Source of one stage of ``name`` with ``#define`` lines inserted after ``#version``.

    Each stage's section sits in ``#if defined STAGE`` blocks of the file, as moderngl-window
    does; the shaders ``#error`` on any define they need that is missing.
    """
    if stage not in STAGES:
        raise ValueError(f"unknown shader stage {stage!r}")
    text = shader_source(name)
    head, sep, body = text.partition("\n")
    if not head.startswith("#version"):
        raise ValueError(f"shader file {name!r} must start with a #version line")
    lines = [f"#define {stage}"] + [f"#define {k} {v}" for k, v in defines.items()]
    return head + sep + "\n".join(lines) + "\n#line 2\n" + body
