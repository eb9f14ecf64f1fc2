"""Jobs sized before they start: memory and disk estimates checked against the machine's.

Each command estimates, from its settings alone, the memory its largest stage will hold and
the bytes it will write, and calls :func:`check_memory` and :func:`check_disk` before
allocating or rendering anything, so an impossible job ends at once with one line naming the
option that lowers it, instead of a MemoryError (or the OOM killer, or a full disk) after
minutes of work.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterable
from pathlib import Path

from .errors import SonarRasterError

__all__ = [
    "check_disk",
    "check_memory",
    "free_disk",
    "physical_memory",
    "size_text",
    "usable_cores",
]

#: Share of the machine's memory one job may plan to use.
SHARE = 0.8


def physical_memory() -> int:
    """Bytes of memory this process may use: the machine's RAM, or a smaller cgroup limit."""
    try:
        total = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):  # not POSIX: no check
        return 1 << 62
    for limit_file in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            text = Path(limit_file).read_text().strip()
        except OSError:
            continue
        if text.isdigit():
            total = min(total, int(text))
    return total


def usable_cores() -> int:
    """Cores this process may run on (its CPU affinity where the system has one)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def size_text(n: float) -> str:
    """Bytes as a short binary size: ``'59.5 GiB'``."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if n < 1024 or unit == "PiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    raise AssertionError("unreachable")


def check_memory(need: float, what: str, lower: str, *, force: bool = False) -> None:
    """Raise :class:`SonarRasterError` when ``need`` bytes exceed the share of memory a job gets.

    Parameters
    ----------
    need : float
        Estimated peak bytes of the job.
    what : str
        The job, as the user would say it ("rendering 1000000000 pings x 600 bins x 2 sides").
    lower : str
        What lowers it, naming options ("lower --pings or use --chunk-pings").
    force : bool
        Skip the check (the user's ``--force``).
    """
    if force:
        return
    have = physical_memory()
    if need > SHARE * have:
        raise SonarRasterError(
            f"{what} would need about {size_text(need)} of memory, more than this machine's "
            f"{size_text(have)}; {lower}"
        )


def free_disk(folder: str | os.PathLike) -> int:
    """Bytes free to this user on the file system of ``folder`` (or its nearest existing parent).

    Parameters
    ----------
    folder : str or path-like
        A folder that will receive output (it may not exist yet).
    """
    path = Path(folder).absolute()
    while not path.exists() and path != path.parent:
        path = path.parent
    return shutil.disk_usage(path).free


def check_disk(
    outputs: Iterable[tuple[str | os.PathLike, float]],
    what: str,
    lower: str,
    *,
    force: bool = False,
) -> None:
    """Raise :class:`SonarRasterError` when the files would not fit on their disks.

    Outputs on the same file system are added up and compared with its free space.

    Parameters
    ----------
    outputs : iterable of (path, bytes)
        Each file (or folder) to be written and its estimated size.
    what : str
        The job, as the user would say it.
    lower : str
        What lowers it, naming options.
    force : bool
        Skip the check (the user's ``--force``).
    """
    if force:
        return
    need: dict[int, list] = {}
    for path, size in outputs:
        folder = Path(path).absolute().parent
        while not folder.exists() and folder != folder.parent:
            folder = folder.parent
        entry = need.setdefault(folder.stat().st_dev, [folder, 0.0])
        entry[1] += float(size)
    for folder, size in need.values():
        have = free_disk(folder)
        if size > have:
            raise SonarRasterError(
                f"{what} would write about {size_text(size)}, more than the "
                f"{size_text(have)} free in {folder}; {lower} (or add --force)"
            )
