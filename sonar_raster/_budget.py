"""Jobs sized before they start: a memory estimate checked against the machine's memory.

Each command estimates, from its settings alone, the memory its largest stage will hold, and
calls :func:`check_memory` before allocating anything, so an impossible job ends at once with
one line naming the option that lowers it, instead of a MemoryError (or the OOM killer) after
minutes of work.
"""

from __future__ import annotations

import os
from pathlib import Path

from .errors import SonarRasterError

__all__ = ["check_memory", "physical_memory", "size_text"]

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
