"""Sensor effects applied to a rendered image: beams, losses, gain, speckle, noise, quantisation.

:class:`Effects` says which effects are on; :func:`apply_effects` applies them in a fixed order
to a :class:`~sonar_raster.SonarImage` and returns a new one.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import lazy_exports

if TYPE_CHECKING:
    from .chain import Effects, apply_effects, load_tvg_curve

__all__ = ["Effects", "apply_effects", "load_tvg_curve"]

__getattr__, __dir__ = lazy_exports(__name__, {name: "chain" for name in __all__})
