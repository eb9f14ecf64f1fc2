"""Rendering: a scene, a sonar and a trajectory in, a raw intensity image out.

:func:`render` is the one entry, ``model="raster" | "reference" | "coherent"``.
Three models of the same integral: the GL raster (:func:`render_raster`, fast, in ``gl/``), the
numpy patch reference (:func:`render_reference`, slow, the oracle of the raster) and the coherent
model (:func:`render_coherent`, point scatterers and a matched filter, with speckle).
:func:`render_survey` streams long tracks in blocks to disk; :func:`render_bands` several sonars
over one track (a dual-frequency side-scan), each :class:`SurveyBand` to its own files.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import lazy_exports

if TYPE_CHECKING:
    from .analytic import flat_seabed_profile, shadow_length
    from .coherent import HorizontalBeam, Pulse, render_coherent, to_raster_units
    from .entry import MODELS, render
    from .gl import RasterRenderer, RasterSettings, render_raster
    from .reference import render_reference
    from .survey import SurveyBand, render_bands, render_survey

__all__ = [
    "MODELS",
    "HorizontalBeam",
    "Pulse",
    "RasterRenderer",
    "RasterSettings",
    "SurveyBand",
    "flat_seabed_profile",
    "render",
    "render_bands",
    "render_coherent",
    "render_raster",
    "render_reference",
    "render_survey",
    "shadow_length",
    "to_raster_units",
]

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "MODELS": "entry",
        "render": "entry",
        "flat_seabed_profile": "analytic",
        "shadow_length": "analytic",
        "HorizontalBeam": "coherent",
        "Pulse": "coherent",
        "render_coherent": "coherent",
        "to_raster_units": "coherent",
        "RasterRenderer": "gl.raster",
        "RasterSettings": "gl.raster",
        "render_raster": "gl.raster",
        "render_reference": "reference",
        "render_survey": "survey",
        "render_bands": "survey",
        "SurveyBand": "survey",
    },
)
