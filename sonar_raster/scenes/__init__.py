"""Scenes: description files (TOML), bundled scenes and their data, seabeds, objects, sediments.

``load_scene_file`` turns a description file, a bare model file or a bundled scene's path into a
:class:`SceneSetup` (scene, sonar, trajectory, effects); ``bundled_scene`` finds a bundled one by
name. Bundled files live in ``scenes/data/``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import lazy_exports

if TYPE_CHECKING:
    from .bundled import bundled_scene, list_bundled
    from .description import Overrides, SceneSetup, load_scene_file
    from .seabed import Heightfield, make_seabed
    from .sediments import Sediment, material_reflectivity, sediment

__all__ = [
    "Heightfield",
    "Overrides",
    "SceneSetup",
    "Sediment",
    "bundled_scene",
    "list_bundled",
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
        "load_scene_file": "description",
        "Heightfield": "seabed",
        "make_seabed": "seabed",
        "Sediment": "sediments",
        "material_reflectivity": "sediments",
        "sediment": "sediments",
    },
)
