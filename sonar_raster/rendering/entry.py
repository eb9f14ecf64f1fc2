"""One entry for every forward model: :func:`render` picks raster, reference or coherent."""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import InputWarning, SonarRasterError
from ..image import SonarImage
from ..scene import Scene
from ..sonar import Sonar
from ..trajectory import Trajectory
from .fan import check_inputs

if TYPE_CHECKING:
    from .coherent.pulse import Pulse
    from .gl.raster import RasterSettings

__all__ = ["MODELS", "render"]

#: The forward models: GL raster (fast), numpy patch reference (its oracle), coherent (Eq. 10).
MODELS = ("raster", "reference", "coherent")


def render(
    scene: Scene,
    sonar: Sonar,
    trajectory: Trajectory,
    *,
    model: str = "raster",
    settings: RasterSettings | None = None,
    backend: str | None = None,
    pulse: Pulse | None = None,
    coherent: Mapping[str, Any] | None = None,
    raster_units: bool = True,
    labels: bool = False,
    progress: bool = False,
    force: bool = False,
) -> SonarImage:
    """Render raw side-scan intensity of ``scene`` seen by ``sonar`` along ``trajectory``.

    Parameters
    ----------
    scene, sonar, trajectory
        What to image, with what, from where (world metres, z up).
    model : {"raster", "reference", "coherent"}
        "raster": Lambertian intensity (seed Eq. 11) rasterised with OpenGL (headless EGL or
        OSMesa); "reference": the same integral summed over small visible patches in numpy
        (slow, exact up to its patch size); "coherent": point scatterers, pulse and matched
        filter (seed Eq. 10), with speckle (slow).
    settings : RasterSettings, optional
        Sampling of the raster model (ignored by the others).
    backend : {"egl", "osmesa"}, optional
        Headless GL backend of the raster model; default ``$SONAR_RASTER_GL``, else EGL, then
        OSMesa.
    pulse : Pulse, optional
        Transmit pulse of the coherent model (default: a chirp whose resolution is one bin).
    coherent : mapping, optional
        Further keyword arguments of
        :func:`~sonar_raster.rendering.coherent.render_coherent` (``spacing_wavelengths``,
        ``seed``, ``horizontal_beam``, ...).
    raster_units : bool
        Coherent model only: scale its image to the raster's units (m², no 1/r⁴ spreading) so
        that the three models compare directly; False keeps the physical echo level.
    labels : bool
        Raster model only: also return per-pixel object ids (``image.labels``), for datasets.
    progress : bool
        Show a progress bar (every model); the reference and coherent models also print their
        estimated size and time first.
    force : bool
        Reference and coherent models: run even when the job is estimated over an hour or over
        the machine's memory (otherwise refused with one line naming what lowers it).

    Returns
    -------
    SonarImage
        float32 intensity per side, shape (pings, bins): rows are pings in time order, columns
        slant-range bins from the transducer outwards.
    """
    if model not in MODELS:
        raise SonarRasterError(f"unknown model {model!r}; use one of {', '.join(MODELS)}")
    if labels and model != "raster":
        raise SonarRasterError(f"labels come from the raster model only, not {model!r}")
    check_inputs(scene, sonar, trajectory)
    if model == "reference":
        from .reference import render_reference

        image = render_reference(scene, sonar, trajectory, progress=progress, force=force)
    elif model == "coherent":
        from .coherent.model import render_coherent, to_raster_units

        options = {"backend": backend, "force": force, **dict(coherent or {})}
        image = render_coherent(scene, sonar, trajectory, pulse=pulse, progress=progress, **options)
        if raster_units and image.metadata["facet_area_m2"] > 0:
            image = to_raster_units(image)
    else:
        from .gl.raster import render_raster

        image = render_raster(
            scene,
            sonar,
            trajectory,
            backend=backend,
            settings=settings,
            progress=progress,
            labels=labels,
        )
    if not any(np.any(side) for side in image.sides.values()):
        warnings.warn(
            "the image is zero everywhere: nothing in the swath returned an echo (is the track "
            "above the seabed, and the seabed within the sonar's range and beam?)",
            InputWarning,
            stacklevel=2,
        )
    return image
