"""All-or-nothing output: every file of one command is written beside its target, then renamed.

A failure while any file is being written leaves the target paths as they were (old files kept,
no half-written file); the temporary files are removed. Temporary names carry the writing
process's id (``.<name>.sr<pid>-<token><suffix>``), so a later run that finds one whose process
is gone (killed by SIGKILL, a power cut) removes it: see :func:`sweep_stale`.
"""

from __future__ import annotations

import json
import os
import re
import secrets
import stat
import time
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from ..errors import SonarRasterError

__all__ = [
    "check_can_create",
    "check_directory",
    "check_writable",
    "commit",
    "install",
    "sweep_stale",
    "temp_name",
    "write_json",
    "write_oiio",
]

#: Age (seconds since last change) after which a temporary file of a live process is stale.
STALE_AFTER_S = 3600.0


def check_directory(path: Path) -> None:
    """Raise :class:`SonarRasterError` unless ``path``'s directory exists and is a directory."""
    directory = path.parent
    if not directory.exists():
        raise SonarRasterError(
            f"cannot write {path}: directory {directory} does not exist; create it first"
        )
    if not directory.is_dir():
        raise SonarRasterError(f"cannot write {path}: {directory} is not a directory")


def check_writable(path: str | os.PathLike) -> Path:
    """Check, before any work, that a file can be written at ``path``; return it as a Path.

    The directory must exist and take a new file (a probe file is made and removed at once:
    this catches read-only and pseudo file systems such as /proc, where permission bits lie),
    and ``path`` must not be a directory or another non-regular file. Stale temporary files of
    ``path`` left by killed runs are removed (:func:`sweep_stale`).
    """
    path = Path(path)
    check_directory(path)
    _check_target(path)
    check_can_create(path.parent, what=f"cannot write {path}")
    sweep_stale(path)
    return path


def check_can_create(folder: Path, what: str | None = None) -> None:
    """Raise unless a new file can be made in ``folder`` (a probe is made and removed at once).

    Catches read-only and pseudo file systems such as /proc, where permission bits lie.
    ``what`` starts the error message (default ``"cannot write into <folder>"``). Probes left
    by runs killed between making and removing theirs are removed (:func:`sweep_stale`).
    """
    sweep_stale(folder / "probe")
    probe = temp_name(folder / "probe")
    try:
        with open(probe, "xb"):
            pass
    except OSError as exc:
        lead = what or f"cannot write into {folder}"
        raise SonarRasterError(f"{lead}: {exc.strerror or exc} in {folder}") from None
    finally:
        probe.unlink(missing_ok=True)


def _check_target(path: Path) -> None:
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        return
    except OSError as exc:
        raise SonarRasterError(f"cannot write {path}: {exc.strerror or exc}") from None
    if stat.S_ISDIR(mode):
        raise SonarRasterError(f"cannot write {path}: it is a directory; give a file name")
    if not stat.S_ISREG(mode):
        raise SonarRasterError(f"cannot write {path}: it exists and is not a regular file")


def temp_name(final: Path) -> Path:
    """A hidden, unique temporary name beside ``final``: ``.<name>.sr<pid>-<token><suffix>``."""
    return final.with_name(f".{final.name}.sr{os.getpid()}-{secrets.token_hex(6)}{final.suffix}")


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process
        return True
    return True


def sweep_stale(final: Path, max_age_s: float = STALE_AFTER_S) -> list[Path]:
    """Remove temporary files of ``final`` left by runs that were killed; return them.

    A temporary file (:func:`temp_name`) is stale when the process that made it is gone, or
    when it has not changed for ``max_age_s`` seconds. Names of the older form without a
    process id (``.<name>.<token><suffix>``) are removed by age only. Never touches ``final``.
    """
    final = Path(final)
    pattern = re.compile(
        rf"^\.{re.escape(final.name)}\.(?:sr(\d+)-)?[0-9a-f]{{12}}{re.escape(final.suffix)}$"
    )
    removed: list[Path] = []
    try:
        entries = list(os.scandir(final.parent))
    except OSError:
        return removed
    now = time.time()
    for entry in entries:
        match = pattern.match(entry.name)
        if match is None or not entry.is_file(follow_symlinks=False):
            continue
        pid = int(match.group(1)) if match.group(1) else None
        if pid == os.getpid():
            continue
        try:
            old = now - entry.stat(follow_symlinks=False).st_mtime > max_age_s
        except OSError:
            continue
        if old or (pid is not None and not _pid_alive(pid)):
            Path(entry.path).unlink(missing_ok=True)
            removed.append(Path(entry.path))
    return removed


def commit(jobs: list[tuple[Path, Callable[[Path], None]]]) -> list[Path]:
    r"""Write several files all-or-nothing; return their final paths.

    Parameters
    ----------
    jobs : list of (Path, callable)
        Final path and a writer that writes the whole file to the temporary path it is given.

    Each writer runs on a hidden temporary name beside its final path (:func:`temp_name`); only
    when every one has succeeded are they renamed into place (:func:`install`). On any failure
    every temporary file is removed and no final path is touched, so a user's earlier files
    stay as they were. OS and encoder errors become one-line :class:`SonarRasterError`\s.
    """
    for final, _ in jobs:
        check_directory(final)
        _check_target(final)
        sweep_stale(final)
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
        install(zip(temps, (final for final, _ in jobs), strict=True))
    finally:
        for tmp in temps:
            tmp.unlink(missing_ok=True)
    return [final for final, _ in jobs]


def install(pairs: Iterable[tuple[Path, Path]]) -> None:
    """Rename finished temporary files onto their final paths, all or none.

    Each existing final file is first hard-linked to a backup name; if any rename fails, the
    finals already replaced are restored from their backups (new ones removed), so the user's
    files end as they were. The temporary files are left for the caller to remove.
    """
    pairs = list(pairs)
    done: list[tuple[Path, Path | None]] = []  # (final, backup or None if it was new)
    try:
        for tmp, final in pairs:
            backup = _backup(final)
            try:
                os.replace(tmp, final)
            except OSError as exc:
                if backup is not None:
                    backup.unlink(missing_ok=True)
                raise SonarRasterError(f"cannot write {final}: {exc.strerror or exc}") from None
            done.append((final, backup))
    except BaseException:
        for final, backup in reversed(done):
            if backup is None:
                final.unlink(missing_ok=True)
            else:
                os.replace(backup, final)
        raise
    for _, backup in done:
        if backup is not None:
            backup.unlink(missing_ok=True)


def _backup(final: Path) -> Path | None:
    """Hard-link an existing regular file ``final`` to a temporary name; None if it is new."""
    if not final.is_file():
        return None
    backup = temp_name(final)
    try:
        os.link(final, backup)
    except OSError:  # no hard links here: copy the bytes
        with open(final, "rb") as src, open(backup, "xb") as dst:
            while chunk := src.read(1 << 20):
                dst.write(chunk)
    return backup


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
