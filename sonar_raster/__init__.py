"""sonar_raster: side-looking sonar images from 3D scenes with headless OpenGL, and back.

The data flow, top to bottom: a :class:`Scene` (triangles, reflectivity) and a :class:`Sonar`
with a :class:`Trajectory` go into a renderer (:func:`render_raster` on OpenGL, or
:func:`render_reference` in numpy), which returns a :class:`SonarImage`; :func:`apply_effects`
adds the sensor's effects (:class:`Effects`: beams, losses, gain, speckle, quantisation), and
:func:`write_image` writes it as EXR/PNG with a JSON sidecar. Heavy modules load on first use,
so importing the package stays fast.
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

from .errors import SonarRasterError
from .image import SonarImage
from .scene import MeshPart, Scene, build_scene
from .sonar import BeamPattern, Sonar
from .trajectory import Trajectory

__all__ = [
    "BeamPattern",
    "Effects",
    "HorizontalBeam",
    "MeshPart",
    "Pulse",
    "RasterRenderer",
    "RasterSettings",
    "Scene",
    "Sonar",
    "SonarImage",
    "SonarRasterError",
    "Trajectory",
    "apply_effects",
    "build_scene",
    "generate_dataset",
    "load_scene_file",
    "render_coherent",
    "render_raster",
    "read_xtf",
    "render_reference",
    "render_survey",
    "to_raster_units",
    "track_bottom",
    "write_image",
    "write_xtf",
]

_LAZY = {
    "HorizontalBeam": "render.coherent",
    "Pulse": "render.coherent",
    "render_coherent": "render.coherent",
    "to_raster_units": "render.coherent",
    "RasterRenderer": "render.gl.raster",
    "RasterSettings": "render.gl.raster",
    "render_raster": "render.gl.raster",
    "render_reference": "render.reference",
    "render_survey": "render.survey",
    "write_image": "io.images",
    "Effects": "effects.chain",
    "apply_effects": "effects.chain",
    "load_scene_file": "scenes.description",
    "generate_dataset": "dataset.generate",
    "read_xtf": "io.xtf",
    "write_xtf": "io.xtf",
    "track_bottom": "invert.bottom",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module 'sonar_raster' has no attribute {name!r}")
