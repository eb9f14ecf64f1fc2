"""A bottom track as text: its printable summary and its CSV table.

Light on purpose (numpy only): the ``track`` and ``invert FILE.xtf`` commands print and write
tracks with it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # bottom imports scipy
    from .bottom import BottomTrack

__all__ = ["TRACK_CSV_HEADER", "summary_lines", "write_track_csv"]

#: Columns of the bottom-track CSV (one row per ping; empty cell = no value).
TRACK_CSV_HEADER = "ping,altitude_m,valid,raw_m,contrast_db,file_altitude_m"


def summary_lines(track: BottomTrack, recorded: np.ndarray, range_bin: float) -> list[str]:
    """Printable summary of a track, compared with the file's own altitude where it has one.

    Parameters
    ----------
    track : BottomTrack
        The tracked altitude per ping (metres) and its validity.
    recorded : ndarray, shape (pings,)
        The file's altitude per ping, metres; NaN where it records none.
    range_bin : float
        Slant-range bin size, metres.
    """
    n = len(track.altitude)
    a = track.altitude
    lines = [
        f"{n} pings, {int(track.valid.sum())} with a clear bottom return "
        f"({100.0 * track.valid.mean():.1f} %); range bin {range_bin * 100:.2f} cm",
        f"tracked altitude: min {a.min():.2f} m, median {np.median(a):.2f} m, max {a.max():.2f} m",
    ]
    ok = np.isfinite(recorded)
    if ok.any():
        d = a[ok] - recorded[ok]
        lines.append(
            f"file altitude (SensorPrimaryAltitude) on {int(ok.sum())} pings: tracked - file "
            f"median {np.median(d):+.2f} m, 5-95 % {np.percentile(d, 5):+.2f} to "
            f"{np.percentile(d, 95):+.2f} m"
        )
    else:
        lines.append("the file records no altitude (0 on every ping)")
    return lines


def write_track_csv(
    path: Path, track: BottomTrack, recorded: np.ndarray, pings: Sequence[int] | None = None
) -> None:
    """Write a track as CSV (:data:`TRACK_CSV_HEADER`) to a new file ``path``.

    The file must not exist (it is opened with mode "x"): a writer for
    :func:`sonar_raster.io.commit.commit`, which gives it a temporary name. Metres to 0.1 mm;
    ``recorded`` is the file's altitude per ping (NaN: none, an empty cell). ``pings`` numbers
    the rows (e.g. the XTF ping indices of ``read_xtf``'s ``metadata["ping_indices"]``, which
    leave gaps where bad pings were skipped); default 0, 1, 2...
    """
    numbers = range(len(track.altitude)) if pings is None else pings
    if len(numbers) != len(track.altitude):
        raise ValueError(f"{len(numbers)} ping numbers for {len(track.altitude)} pings")
    with open(path, "x", encoding="utf-8") as fh:
        fh.write(TRACK_CSV_HEADER + "\n")
        for i, ping in enumerate(numbers):
            fh.write(
                f"{ping},{track.altitude[i]:.4f},{int(track.valid[i])},{_num(track.raw[i])},"
                f"{_num(track.contrast_db[i])},{_num(recorded[i])}\n"
            )


def _num(value: float) -> str:
    return f"{value:.4f}" if math.isfinite(value) else ""
