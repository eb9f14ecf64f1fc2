"""The only code that knows OpenGL: context, shader programs, the raster renderer, previews.

``create_context`` picks the headless backend (EGL, then OSMesa); :class:`RasterRenderer` owns a
context and every GL object it makes. The GLSL sources sit beside the modules.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..._lazy import lazy_exports

if TYPE_CHECKING:
    from .context import BACKENDS, create_context, probe, release_context
    from .raster import RasterRenderer, RasterSettings, render_raster

__all__ = [
    "BACKENDS",
    "RasterRenderer",
    "RasterSettings",
    "create_context",
    "probe",
    "release_context",
    "render_raster",
]

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "BACKENDS": "context",
        "create_context": "context",
        "probe": "context",
        "release_context": "context",
        "RasterRenderer": "raster",
        "RasterSettings": "raster",
        "render_raster": "raster",
    },
)
