"""All-or-nothing output: every file of one command is written beside its target, then renamed.

A failure while any file is being written leaves the target paths as they were (old files kept,
no half-written file); the temporary files are removed.
"""

from __future__ import annotations

import json
import os
import secrets
from collections.abc import Callable
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from ..errors import SonarRasterError

__all__ = ["check_directory", "commit", "temp_name", "write_json", "write_oiio"]


def check_directory(path: Path) -> None:
    """Raise :class:`SonarRasterError` unless ``path``'s directory exists and is a directory."""
    directory = path.parent
    if not directory.exists():
        raise SonarRasterError(
            f"cannot write {path}: directory {directory} does not exist; create it first"
        )
    if not directory.is_dir():
        raise SonarRasterError(f"cannot write {path}: {directory} is not a directory")


def temp_name(final: Path) -> Path:
    """A hidden, unique temporary name beside ``final`` (``.<name>.<token><suffix>``)."""
    return final.with_name(f".{final.name}.{secrets.token_hex(6)}{final.suffix}")


def commit(jobs: list[tuple[Path, Callable[[Path], None]]]) -> list[Path]:
    r"""Write several files all-or-nothing; return their final paths.

    Parameters
    ----------
    jobs : list of (Path, callable)
        Final path and a writer that writes the whole file to the temporary path it is given.

    Each writer runs on a hidden temporary name beside its final path (:func:`temp_name`); only
    when every one has succeeded are they renamed into place. On any failure every temporary
    file is removed and no final path is touched, so a user's earlier files stay as they were.
    OS and encoder errors become one-line :class:`SonarRasterError`\s.
    """
    temps: list[Path] = []
    try:
        for final, writer in jobs:
            tmp = temp_name(final)
            temps.append(tmp)
            try:
                writer(tmp)
            except OSError as exc:
                raise SonarRasterError(f"cannot write {final}: {exc.strerror or exc}") from None
            except RuntimeError as exc:
                raise SonarRasterError(f"cannot write {final}: {exc}") from None
        for tmp, (final, _) in zip(temps, jobs, strict=True):
            try:
                os.replace(tmp, final)
            except OSError as exc:
                raise SonarRasterError(f"cannot write {final}: {exc.strerror or exc}") from None
    finally:
        for tmp in temps:
            tmp.unlink(missing_ok=True)
    return [final for final, _ in jobs]


def write_oiio(tmp: Path, pixels: np.ndarray, spec: oiio.ImageSpec) -> None:
    """Encode (h, w, c) pixels with OpenImageIO; raise RuntimeError on failure."""
    out = oiio.ImageOutput.create(str(tmp))
    if out is None:
        raise RuntimeError(oiio.geterror() or "no OpenImageIO writer for this format")
    try:
        if not out.open(str(tmp), spec):
            raise RuntimeError(out.geterror())
        if not out.write_image(pixels):
            raise RuntimeError(out.geterror())
    finally:
        out.close()


def write_json(tmp: Path, doc: object) -> None:
    """Write ``doc`` as indented JSON to a new file ``tmp`` (NaN refused)."""
    with open(tmp, "x", encoding="utf-8") as fh:
        json.dump(doc, fh, indent=2, allow_nan=False)
        fh.write("\n")
