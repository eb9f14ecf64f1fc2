"""Writing and reading images (EXR, PNG + JSON sidecar) and XTF files, all-or-nothing.

Every writer puts its files under temporary names and renames them into place only once all of
them are complete, so a failed run leaves the user's earlier files as they were.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import lazy_exports

if TYPE_CHECKING:
    from .images import read_exr, read_pixels, write_image
    from .xtf import XtfNavigation, XtfReader, XtfWriter, iter_pings, read_xtf, write_xtf

__all__ = [
    "XtfNavigation",
    "XtfReader",
    "XtfWriter",
    "iter_pings",
    "read_exr",
    "read_pixels",
    "read_xtf",
    "write_image",
    "write_xtf",
]

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "read_exr": "images",
        "read_pixels": "images",
        "write_image": "images",
        "XtfNavigation": "xtf",
        "XtfReader": "xtf",
        "XtfWriter": "xtf",
        "iter_pings": "xtf",
        "read_xtf": "xtf",
        "write_xtf": "xtf",
    },
)
