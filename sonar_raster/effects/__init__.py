"""Sensor effects applied to a rendered image: beams, losses, gain, speckle, noise, quantisation.

:class:`Effects` says which effects are on; :func:`apply_effects` applies them in a fixed order
to a :class:`~sonar_raster.SonarImage` and returns a new one. :func:`preset` gives a real
sensor's sonar and effects (:class:`SensorPreset`, figures cited in docs/sensors.md).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import lazy_exports

if TYPE_CHECKING:
    from .chain import Effects, apply_effects, load_tvg_curve
    from .presets import SensorPreset, list_presets, preset

__all__ = ["Effects", "SensorPreset", "apply_effects", "list_presets", "load_tvg_curve", "preset"]

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "Effects": "chain",
        "apply_effects": "chain",
        "load_tvg_curve": "chain",
        "SensorPreset": "presets",
        "list_presets": "presets",
        "preset": "presets",
    },
)
