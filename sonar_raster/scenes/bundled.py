"""The scenes shipped inside the package (``sonar_raster/scenes/data/``)."""

from __future__ import annotations

import sys
from importlib import resources
from pathlib import Path

from ..errors import SonarRasterError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

DEFAULT_SCENE = "cylinder_on_flat"


def data_folder() -> Path:
    """The folder of the bundled scene files, dataset configs and their models."""
    return Path(str(resources.files("sonar_raster.scenes").joinpath("data")))


def list_bundled() -> list[tuple[str, str]]:
    """(name, description) of every bundled scene, sorted by name."""
    out = []
    for path in sorted(data_folder().glob("*.toml")):
        if path.stem.startswith("dataset_"):  # dataset configs (sonar_raster.dataset.generate)
            continue
        data = tomllib.loads(path.read_text(encoding="utf-8"))
        out.append((path.stem, str(data.get("description", data.get("name", "")))))
    return out


def bundled_scene(name: str) -> Path:
    """Path of a bundled scene by name; ``"default"`` is :data:`DEFAULT_SCENE`."""
    name = DEFAULT_SCENE if name == "default" else name
    path = data_folder() / f"{name}.toml"
    if not path.is_file():
        names = ", ".join(n for n, _ in list_bundled())
        raise SonarRasterError(f"no scene file or bundled scene named {name!r}; bundled: {names}")
    return path


def bundled_dataset_config(name: str) -> Path | None:
    """Path of a bundled dataset config (``dataset_*``) by name, or None if there is none."""
    path = data_folder() / f"{name}.toml"
    return path if name.startswith("dataset_") and path.is_file() else None
