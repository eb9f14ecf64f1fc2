"""The scenes shipped inside the package (``scenes/`` in the source tree)."""

from __future__ import annotations

import sys
from importlib import resources
from pathlib import Path

from .errors import SonarRasterError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

DEFAULT_SCENE = "cylinder_on_flat"


def _folder() -> Path:
    return Path(str(resources.files("sonar_raster.scenes")))


def list_bundled() -> list[tuple[str, str]]:
    """(name, description) of every bundled scene, sorted by name."""
    out = []
    for path in sorted(_folder().glob("*.toml")):
        if path.stem.startswith("dataset_"):  # dataset configs (sonar_raster.dataset)
            continue
        data = tomllib.loads(path.read_text(encoding="utf-8"))
        out.append((path.stem, str(data.get("description", data.get("name", "")))))
    return out


def bundled_scene(name: str) -> Path:
    """Path of a bundled scene by name; ``"default"`` is :data:`DEFAULT_SCENE`."""
    name = DEFAULT_SCENE if name == "default" else name
    path = _folder() / f"{name}.toml"
    if not path.is_file():
        names = ", ".join(n for n, _ in list_bundled())
        raise SonarRasterError(f"no scene file or bundled scene named {name!r}; bundled: {names}")
    return path
