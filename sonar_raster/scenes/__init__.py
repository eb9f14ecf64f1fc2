"""Scenes: description files (TOML), bundled scenes and their data, seabeds, objects, sediments.

``load_scene`` turns a bundled scene's name, a description file or a bare model file into a
:class:`SceneSetup` (scene, sonar, trajectory, effects). Bundled files live in ``scenes/data/``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import lazy_exports

if TYPE_CHECKING:
    from .bundled import bundled_scene, list_bundled
    from .description import Overrides, SceneSetup, load_scene, load_scene_file
    from .seabed import Heightfield, make_seabed
    from .sediments import Sediment, material_reflectivity, sediment

__all__ = [
    "Heightfield",
    "Overrides",
    "SceneSetup",
    "Sediment",
    "bundled_scene",
    "list_bundled",
    "load_scene",
    "load_scene_file",
    "make_seabed",
    "material_reflectivity",
    "sediment",
]

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "bundled_scene": "bundled",
        "list_bundled": "bundled",
        "Overrides": "description",
        "SceneSetup": "description",
        "load_scene": "description",
        "load_scene_file": "description",
        "Heightfield": "seabed",
        "make_seabed": "seabed",
        "Sediment": "sediments",
        "material_reflectivity": "sediments",
        "sediment": "sediments",
    },
)
