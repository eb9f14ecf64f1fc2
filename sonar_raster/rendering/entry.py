"""One entry for every forward model: :func:`render` picks raster, reference or coherent."""

from __future__ import annotations

import inspect
import warnings
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from .._checks import did_you_mean
from ..errors import InputWarning, SonarRasterError, SonarRasterTypeError
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

        options = {"backend": backend, "force": force, **_coherent_options(coherent)}
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
        why = _why_blank(scene, sonar, trajectory)
        warnings.warn(f"the image is zero everywhere: {why}", InputWarning, stacklevel=2)
    return image


def _why_blank(scene: Scene, sonar: Sonar, trajectory: Trajectory) -> str:
    """Why a render returned nothing: the whole scene out of range, else the general causes."""
    height = float(trajectory.positions[:, 2].min() - scene.bounds[1, 2])
    if height >= sonar.max_range:
        return (
            f"every ping is {height:.4g} m or more above the scene's highest point, at or beyond "
            f"the sonar's max_range ({sonar.max_range:g} m); lower the altitude or raise max_range"
        )
    return (
        "nothing in the swath returned an echo (is the track above the seabed, and the seabed "
        "within the sonar's range and beam?)"
    )


def _coherent_options(coherent: Mapping[str, Any] | None) -> dict[str, Any]:
    """``coherent`` as keyword arguments of ``render_coherent``; an unknown key is named."""
    from .coherent.model import render_coherent

    if coherent is None:
        return {}
    if not isinstance(coherent, Mapping):
        raise SonarRasterTypeError(
            "coherent must be a dict of render_coherent's options, e.g. {'seed': 1}, got "
            f"{type(coherent).__name__}"
        )
    own = ("pulse", "progress")  # render's own arguments
    keys = [
        name
        for name, p in inspect.signature(render_coherent).parameters.items()
        if p.kind is p.KEYWORD_ONLY and name not in own
    ]
    unknown = [k for k in coherent if k not in keys]
    if unknown:
        raise SonarRasterError(
            f"unknown coherent option(s) {', '.join(map(repr, unknown))}; the options are "
            f"{', '.join(keys)}{did_you_mean(unknown, keys)}"
        )
    return dict(coherent)
