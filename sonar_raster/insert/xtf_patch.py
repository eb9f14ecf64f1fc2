"""Write a recording back as XTF with some pings' side-scan samples replaced, all else kept.

The output is a byte copy of the input file in which only the sample values of the changed
pings' port and starboard channels differ: file header, navigation, attitude, times, ping
numbers, other channels and other packet types stay as recorded, so a survey viewer shows it
as the original line. New values are encoded in each channel's own sample format with the
packet's own ``Weight`` (``value · 2**Weight``, rounded and clipped to the format's range:
a return beyond full scale saturates as it would have in the recorder).

Packets are walked as :class:`sonar_raster.io.xtf.XtfReader` walks them (a side-scan ping
counts when it has a port or starboard channel), and the result is read back with
:func:`sonar_raster.io.xtf.read_xtf` and compared with what was meant before it is kept.
"""

from __future__ import annotations

import logging
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ..errors import SonarRasterError
from ..io.xtf import BadPacket, XtfReader, read_xtf

__all__ = ["encode_samples", "patch_xtf"]

#: A ping header's date, time and ping number (bytes 14-31).
_PING_KEY = slice(14, 32)


def encode_samples(values: np.ndarray, dtype: np.dtype, weight: int) -> tuple[np.ndarray, int]:
    """Samples of ``dtype`` holding ``values`` at ``2**-weight`` per count; and how many clipped.

    Parameters
    ----------
    values : ndarray
        Sample values as the reader returns them (after ``2**-Weight``), >= 0.
    dtype : numpy dtype
        The channel's sample type.
    weight : int
        The channel's ``Weight``.

    Returns
    -------
    samples : ndarray of ``dtype``
    clipped : int
        Values beyond the format's full scale (set to it).
    """
    dtype = np.dtype(dtype)
    scaled = np.asarray(values, dtype=np.float64) * 2.0**weight
    if dtype.kind == "f":
        return scaled.astype(dtype), 0
    top = float(np.iinfo(dtype).max)
    codes = np.rint(scaled)
    clipped = int(np.count_nonzero(codes > top))
    return np.clip(codes, 0, top).astype(dtype), clipped


def _patch_packet(
    buf: bytearray, start: int, raw: bytes, reader: XtfReader, new: dict, stored: dict
) -> tuple[set[str], int]:
    """Replace the side channels' samples of the packet at ``start``; (its sides, clipped).

    The channels are found as the reader finds them (:meth:`XtfReader.layout`). ``stored``
    receives each side's values as the file now holds them (encoded, decoded).
    """
    _, layout = reader.layout(raw)
    sides = {k: s for s, k in reader.channels.items()}
    seen: set[str] = set()
    clipped = 0
    for chan, k, pos, count, dtype in layout:
        side = sides.get(k)
        if side is None or side in seen:
            continue
        seen.add(side)
        if side in new:
            values = new[side][::-1] if side == "port" else new[side]
            if len(values) != count:
                raise SonarRasterError("a patched ping's sample count differs from the file's")
            samples, n = encode_samples(values, dtype, int(chan.Weight))
            buf[start + pos : start + pos + samples.nbytes] = samples.tobytes()
            clipped += n
            decoded = samples.astype(np.float32) * np.float32(2.0 ** -int(chan.Weight))
            stored[side] = decoded[::-1] if side == "port" else decoded
    return seen, clipped


def patch_xtf(
    src: str | Path,
    dst: str | Path,
    samples: dict[int, dict[str, np.ndarray]],
    frequency: float | str | None = None,
) -> int:
    """Copy ``src`` to ``dst`` with the samples of some pings replaced.

    Parameters
    ----------
    src : str or Path
        The recording.
    dst : str or Path
        The new file (e.g. a temporary name of :func:`sonar_raster.io.commit.commit`).
    samples : dict of int to dict of str to ndarray
        Ping index among the file's side-scan pings (``image.metadata["ping_indices"]``) to
        the new values per side, from range 0 outward, as :func:`read_xtf` returns them.
    frequency : float or {"low", "high"}, optional
        A dual-frequency file's pair to rewrite (``read_xtf``'s ``frequency``; the one the
        samples were read from); the other pair is copied as recorded. None: the first pair.

    Returns
    -------
    int
        Samples clipped at the format's full scale.

    Raises
    ------
    SonarRasterError
        When the copy, read back, does not hold the new samples (a file this walk does not
        understand); ``dst`` is then left for the caller to remove.
    """
    with _quiet_reader(), XtfReader(src, frequency) as reader:
        data = bytearray(Path(src).read_bytes())
        index, clipped = 0, 0
        stored: dict[int, dict[str, np.ndarray]] = {}
        held: bytes | None = None  # the key of one side of a ping split over packets
        for pos, raw in reader.packets():  # damaged frames count as pings, as the reader has it
            if isinstance(raw, Exception):
                index += 1
                continue
            key = raw[_PING_KEY]  # date, time and ping number: the same for one ping's packets
            joined = held == key
            index -= int(joined)  # the other side of the ping just counted
            new = samples.get(index, {})
            try:
                sides, n = _patch_packet(data, pos, raw, reader, new, stored.setdefault(index, {}))
            except BadPacket:  # a ping the reader skips: left as recorded
                held, index = None, index + 1
                continue
            clipped += n
            part = bool(sides) and len(sides) < len(reader.channels) and not joined
            held = key if part else None
            index += int(bool(sides))
    with open(dst, "wb") as fh:
        fh.write(data)
    _verify(Path(src), Path(dst), samples, stored, frequency)
    return clipped


@contextmanager
def _quiet_reader() -> Iterator[None]:
    """The XTF reader's warnings off: what it has to say was said when the source was read."""
    reader_log = logging.getLogger(read_xtf.__module__)
    level = reader_log.level
    reader_log.setLevel(logging.ERROR)
    try:
        yield
    finally:
        reader_log.setLevel(level)


def _verify(
    src: Path, dst: Path, samples: dict, stored: dict, frequency: float | str | None
) -> None:
    """Read ``dst`` back: each patched ping must hold exactly the values encoded into it."""
    with _quiet_reader():
        image, _ = read_xtf(dst, frequency=frequency)
    rows = {int(k): r for r, k in enumerate(image.metadata["ping_indices"])}
    for index, sides in samples.items():
        for side in sides:
            want = stored.get(index, {}).get(side)
            if (
                index not in rows
                or want is None
                or not np.array_equal(image.sides[side][rows[index]], want)
            ):
                raise SonarRasterError(
                    f"{src}: rewriting ping {index} ({side}) did not round-trip; the file's "
                    "layout is not one this writer understands"
                )


def copy_unchanged(src: str | Path, dst: str | Path) -> None:
    """Copy ``src`` to ``dst`` byte for byte (no ping changed).

    Parameters
    ----------
    src, dst : str or Path
    """
    shutil.copyfile(src, dst)
