"""Mesh input and output: one loader for every model format (trimesh formats and VRML), export.

``load_model`` reads ``.wrl .vrml .gltf .glb .obj .ply .stl .off`` into :class:`MeshPart` lists;
``export`` writes a trimesh mesh as glTF/PLY bytes.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import lazy_exports

if TYPE_CHECKING:
    from .export import export, seabed_mesh
    from .load import load_model
    from .vrml import load_vrml, parse_vrml

__all__ = ["export", "load_model", "load_vrml", "parse_vrml", "seabed_mesh"]

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "export": "export",
        "seabed_mesh": "export",
        "load_model": "load",
        "load_vrml": "vrml",
        "parse_vrml": "vrml",
    },
)
