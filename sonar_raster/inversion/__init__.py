"""From sonar images back to the seabed: bottom tracking, reflectivity R, beam Φ, elevation Z.

:func:`invert` estimates R, Φ and Z of one side by expectation-maximisation with Gauss-Newton
steps over a multi-resolution pyramid; :func:`track_bottom` finds the altitude in each ping;
:func:`choose_method` says whether an image wants the per-ping profiles or one surface
(``sonar-raster invert --method auto``);
:func:`write_products` writes an :class:`Inversion` as maps, a mesh and previews;
:func:`invert_xtf` runs both sides of a real recording and georeferences the result.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import lazy_exports

if TYPE_CHECKING:
    from .bottom import BottomTrack, track_bottom
    from .method import MethodChoice, choose_method
    from .shadows import Shadows, find_shadows
    from .solver import BeamProfile, Inversion, invert
    from .write import write_products
    from .xtf import XtfInversion, invert_xtf

__all__ = [
    "BeamProfile",
    "BottomTrack",
    "Inversion",
    "MethodChoice",
    "Shadows",
    "XtfInversion",
    "choose_method",
    "find_shadows",
    "invert",
    "invert_xtf",
    "track_bottom",
    "write_products",
]

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "BottomTrack": "bottom",
        "track_bottom": "bottom",
        "MethodChoice": "method",
        "choose_method": "method",
        "Shadows": "shadows",
        "find_shadows": "shadows",
        "BeamProfile": "solver",
        "Inversion": "solver",
        "invert": "solver",
        "write_products": "write",
        "XtfInversion": "xtf",
        "invert_xtf": "xtf",
    },
)
