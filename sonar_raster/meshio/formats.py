"""The model file formats the package reads, by file name ending (no heavy imports here)."""

from __future__ import annotations

from pathlib import Path

__all__ = ["MODEL_SUFFIXES", "TRIMESH_SUFFIXES", "VRML_SUFFIXES", "Y_UP_SUFFIXES", "model_suffix"]

#: VRML97, read by the package's own reader (``.wrz`` and ``.wrl.gz``: gzipped).
VRML_SUFFIXES = (".wrl", ".vrml", ".wrz", ".wrl.gz")
#: Read through trimesh.
TRIMESH_SUFFIXES = (".gltf", ".glb", ".obj", ".ply", ".stl", ".off")
#: Every model file ending, lower case.
MODEL_SUFFIXES = VRML_SUFFIXES + TRIMESH_SUFFIXES
#: Formats whose specification makes y the up axis.
Y_UP_SUFFIXES = VRML_SUFFIXES + (".gltf", ".glb")


def model_suffix(path: str | Path) -> str | None:
    """The model format ending of ``path`` (lower case, e.g. ``".wrl.gz"``), or None."""
    name = Path(path).name.lower()
    return max((s for s in MODEL_SUFFIXES if name.endswith(s)), key=len, default=None)
