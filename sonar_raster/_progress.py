"""Long jobs say what they will cost before they start, and show progress while they run.

A job estimates, from its settings alone, its size (scatterers, rays, patches, ...), its time
(a per-item cost measured on the project's 2-core CI machine, so an upper-end guess on faster
ones) and its peak memory; :func:`check_job` refuses it, in one line naming the option that
lowers it, when it would take more than :data:`TIME_LIMIT_S` or more memory than the machine
has, unless forced; :func:`announce` prints the estimate; :func:`progress_bar` shows a bar with
an ETA over the job's estimated work.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from typing import Any

from ._budget import check_memory, size_text
from .errors import SonarRasterError

__all__ = [
    "ANNOUNCE_S",
    "TIME_LIMIT_S",
    "Estimate",
    "announce",
    "check_job",
    "duration_text",
    "progress_bar",
]

#: Jobs estimated longer than this are refused unless forced, seconds.
TIME_LIMIT_S = 3600.0
#: Fast jobs (raster renders, inversions) print their estimate only from this long, seconds.
ANNOUNCE_S = 10.0


@dataclass(frozen=True)
class Estimate:
    """What a job will cost, from its settings.

    Attributes
    ----------
    what : str
        The job, as a user would name it ("coherent render of 20 pings").
    counts : dict of str to float
        Sizes by name, e.g. ``{"scatterers": 1.2e8, "rays": 2.3e6}``.
    seconds : float
        Estimated run time, seconds.
    memory : float
        Estimated peak memory, bytes (0: not estimated).
    work : float
        Total of the progress bar's units (default: the estimated seconds).
    disk : float
        Estimated bytes written, (0: not estimated).
    """

    what: str
    counts: dict[str, float] = field(default_factory=dict)
    seconds: float = 0.0
    memory: float = 0.0
    work: float = 0.0
    disk: float = 0.0

    def with_memory(self, memory: float) -> Estimate:
        """The same estimate with a peak memory, bytes.

        Parameters
        ----------
        memory : float
            Peak bytes.
        """
        return replace(self, memory=float(memory))

    def line(self) -> str:
        """One line: sizes, time and memory."""
        sizes = ", ".join(f"{_count_text(v)} {k}" for k, v in self.counts.items())
        mem = f", {size_text(self.memory)} of memory" if self.memory > 0 else ""
        disk = f", {size_text(self.disk)} on disk" if self.disk > 0 else ""
        return f"{self.what}: about {sizes}; estimated {duration_text(self.seconds)}{mem}{disk}"

    def to_dict(self) -> dict[str, Any]:
        """Plain description for metadata."""
        return {
            "counts": dict(self.counts),
            "seconds": self.seconds,
            "memory_bytes": self.memory,
            "disk_bytes": self.disk,
        }


def duration_text(seconds: float) -> str:
    """Seconds as a short duration: ``'45 s'``, ``'12 min'``, ``'3.4 h'``.

    Parameters
    ----------
    seconds : float
        Duration.
    """
    if seconds < 90:
        return f"{seconds:.0f} s" if seconds >= 10 else f"{seconds:.1f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    if seconds < 172800:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86400:.3g} days"


def _count_text(n: float) -> str:
    return f"{n:.0f}" if n < 1e4 else f"{n:.2g}"


def check_job(estimate: Estimate, lower: str, *, force: bool = False) -> None:
    """Refuse a job estimated over :data:`TIME_LIMIT_S` or over the machine's memory.

    Parameters
    ----------
    estimate : Estimate
        The job's estimate.
    lower : str
        What lowers it, naming options ("raise --scatterer-spacing or lower --pings").
    force : bool
        Skip both checks (the user's ``--force``).

    Raises
    ------
    SonarRasterError
        One line: the estimate, the limit, what lowers it, and ``--force``.
    """
    if force:
        return
    if estimate.seconds > TIME_LIMIT_S:
        raise SonarRasterError(
            f"{estimate.line()}, over the {duration_text(TIME_LIMIT_S)} limit; {lower} "
            "(or add --force to run it anyway)"
        )
    if estimate.memory > 0:
        check_memory(estimate.memory, estimate.what, f"{lower} (or add --force)")


def announce(estimate: Estimate) -> None:
    """Print the estimate as one line on stderr.

    Parameters
    ----------
    estimate : Estimate
        The job's estimate.
    """
    print(estimate.line(), file=sys.stderr, flush=True)


class _NoBar:
    def update(self, n: float = 1) -> None:
        """Do nothing."""


@contextmanager
def progress_bar(total: float, desc: str, show: bool) -> Iterator[Any]:
    """A tqdm bar over ``total`` units of work with its ETA (a no-op object when not shown).

    Parameters
    ----------
    total : float
        Units of work in the job (e.g. its estimated seconds).
    desc : str
        Label of the bar.
    show : bool
        Show it (tqdm hides it anyway when stderr is not a terminal).
    """
    if not show:
        yield _NoBar()
        return
    from tqdm import tqdm

    fmt = "{desc}: {percentage:3.0f}%|{bar}| [{elapsed}<{remaining}]"
    bar = tqdm(total=max(float(total), 1e-9), desc=desc, bar_format=fmt, disable=None, leave=False)
    try:
        yield bar
    finally:
        bar.close()
