"""sonar_raster: side-looking sonar images from 3D scenes with headless OpenGL, and back.

The data flow, top to bottom, one subpackage per stage:

- ``scenes``: :func:`load_scene` (a bundled scene by name, a ``.toml`` description or a model
  file) gives a :class:`~sonar_raster.scenes.SceneSetup`: a :class:`Scene`, a :class:`Sonar`
  and a :class:`Trajectory` (``meshio`` reads the model files);
- ``rendering``: :func:`render` (``model="raster" | "reference" | "coherent"``) returns a raw
  :class:`SonarImage`; only ``rendering.gl`` knows OpenGL;
- ``effects``: :func:`apply_effects` adds the sensor's effects (:class:`Effects`);
- ``io``: :func:`write_image` writes EXR/PNG with a JSON sidecar, :func:`write_xtf` and
  :func:`read_xtf` sonar records, all-or-nothing;
- ``inversion``: :func:`invert` recovers reflectivity, beam pattern and elevation from one side
  of an image, :func:`write_products` writes them; :func:`track_bottom` and
  :func:`invert_xtf` work on real recordings;
- ``dataset``: :func:`generate_dataset` renders labelled training data;
- ``cli``: the ``sonar-raster`` command.

Heavy modules load on first use, so importing the package stays fast.
"""

from __future__ import annotations

from importlib import metadata as _metadata
from typing import TYPE_CHECKING

from ._lazy import lazy_exports
from .errors import SonarRasterError
from .image import SonarImage
from .scene import MeshPart, Scene, build_scene
from .sonar import BeamPattern, Sonar
from .trajectory import Trajectory

try:
    __version__ = _metadata.version("sonar_raster")
except _metadata.PackageNotFoundError:  # a source tree that was never installed
    __version__ = "0+unknown"

if TYPE_CHECKING:
    from .dataset import DatasetConfig, generate_dataset, load_dataset_config
    from .effects import Effects, apply_effects
    from .inversion import (
        BeamProfile,
        BottomTrack,
        Inversion,
        invert,
        invert_xtf,
        track_bottom,
        write_products,
    )
    from .io import read_exr, read_xtf, write_image, write_xtf
    from .rendering import (
        HorizontalBeam,
        Pulse,
        RasterRenderer,
        RasterSettings,
        render,
        render_coherent,
        render_raster,
        render_reference,
        render_survey,
    )
    from .scenes import SceneSetup, list_bundled, load_scene, load_scene_file

__all__ = [
    "BeamPattern",
    "BeamProfile",
    "BottomTrack",
    "DatasetConfig",
    "Effects",
    "HorizontalBeam",
    "Inversion",
    "MeshPart",
    "Pulse",
    "RasterRenderer",
    "RasterSettings",
    "Scene",
    "SceneSetup",
    "Sonar",
    "SonarImage",
    "SonarRasterError",
    "Trajectory",
    "apply_effects",
    "build_scene",
    "generate_dataset",
    "invert",
    "invert_xtf",
    "list_bundled",
    "load_dataset_config",
    "load_scene",
    "load_scene_file",
    "read_exr",
    "read_xtf",
    "render",
    "render_coherent",
    "render_raster",
    "render_reference",
    "render_survey",
    "track_bottom",
    "write_image",
    "write_products",
    "write_xtf",
]

_EAGER = (
    "BeamPattern",
    "MeshPart",
    "Scene",
    "Sonar",
    "SonarImage",
    "SonarRasterError",
    "Trajectory",
    "build_scene",
)
_HOMES = {
    "dataset": ("DatasetConfig", "generate_dataset", "load_dataset_config"),
    "effects": ("Effects", "apply_effects"),
    "inversion": (
        "BeamProfile",
        "BottomTrack",
        "Inversion",
        "invert",
        "invert_xtf",
        "track_bottom",
        "write_products",
    ),
    "io": ("read_exr", "read_xtf", "write_image", "write_xtf"),
    "rendering": (
        "HorizontalBeam",
        "Pulse",
        "RasterRenderer",
        "RasterSettings",
        "render",
        "render_coherent",
        "render_raster",
        "render_reference",
        "render_survey",
    ),
    "scenes": ("SceneSetup", "list_bundled", "load_scene", "load_scene_file"),
}

__getattr__, _dir = lazy_exports(
    __name__, {name: home for home, names in _HOMES.items() for name in names}
)


def __dir__() -> list[str]:
    return sorted(set(_dir()) | set(_EAGER))
