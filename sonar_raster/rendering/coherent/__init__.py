"""Coherent model (seed Eq. 10): point scatterers, pulse, two-way propagation, matched filter."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..._lazy import lazy_exports

if TYPE_CHECKING:
    from .model import (
        Echo,
        HorizontalBeam,
        PointScatterers,
        Pulse,
        ping_echo,
        render_coherent,
        to_raster_units,
    )

__all__ = [
    "Echo",
    "HorizontalBeam",
    "PointScatterers",
    "Pulse",
    "ping_echo",
    "render_coherent",
    "to_raster_units",
]

__getattr__, __dir__ = lazy_exports(__name__, {name: "model" for name in __all__})
