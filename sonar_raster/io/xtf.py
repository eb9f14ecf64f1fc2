"""XTF side-scan files in and out, through pyxtf's structures.

Reading streams the file packet by packet (:class:`XtfReader`, one :class:`XtfPing` at a time);
:func:`read_xtf` gathers the pings into a :class:`SonarImage` and an :class:`XtfNavigation`.
:func:`write_xtf` writes a :class:`SonarImage` and its :class:`Trajectory` as an XTF file.

Conventions (checked on the OpenSidescan sample and by the round-trip tests):

- The side of a channel is ``TypeOfChannel`` of its ``ChanInfo`` entry (1 port, 2 starboard);
  one port and one starboard channel are read (a dual-frequency file's pairs are told apart
  by ``Frequency``, else by order; the first pair unless ``frequency`` asks), other channels
  are skipped. A side the header's ``NumberOfSonarChannels`` leaves out is read from an entry
  past the count that describes it (with a sample size), with a warning. With one side known,
  pings that carry more channels than the header describes draw a warning that the others
  are not read. A packet's channel is described by the entry its ``ChannelNumber`` names
  (by its place where the numbers count from 1 or repeat, :meth:`XtfReader.layout`); a ping
  written as one packet per side is joined.
- Port samples are stored from far range to nadir, starboard samples from nadir outward (as
  pyxtf's ``concatenate_channel`` assumes); :class:`SonarImage` sides run from range 0 outward.
- Sample spacing is ``SlantRange / NumSamples`` (or ``TimeDuration · c / 2 / NumSamples`` when
  the slant range is 0); sample values are multiplied by ``2 ** -Weight`` (pyxtf's ``weighted``).
- ``SoundVelocity`` holds half the sound speed in many files (750 m/s, the Triton habit): the
  field is doubled when twice it matches ``2 · SlantRange / TimeDuration`` better than the field
  itself, or, without timing, when it is below 1000 m/s. :func:`write_xtf` writes the half.
- Navigation is ``SensorXcoordinate`` / ``SensorYcoordinate`` (``ShipXcoordinate`` /
  ``ShipYcoordinate`` where the sensor's are both 0): longitude / latitude in degrees
  when the file header's ``NavUnits`` is 3, else projected metres (easting, northing), unless
  the fixes contradict the header (none a place on Earth in degrees; or longitudes and
  latitudes that stand still as metres), then the other, with a warning. A ping
  whose coordinates are both 0 has no navigation of its own; where the file holds navigation
  packets (type 42, ``RawXcoordinate`` / ``RawYcoordinate`` with their own time), such a ping
  takes their position interpolated linearly in time (between two fixes at most
  :data:`MAX_FIX_GAP` s apart; none beyond the first or last). Heading is the compass
  heading in degrees; roll is positive starboard down; the altitude is
  ``SensorPrimaryAltitude`` (0 = not known); the sensor depth is ``SensorDepth`` (positive
  down), so the sensor's z is ``-depth``.

Field recordings have glitches; a ping is skipped, not the file refused, when its packet is
framed correctly (marker and length) but a field is impossible: a date or time of day that
does not exist, ``|Weight|`` above :data:`MAX_WEIGHT`, sample counts that do not fit the packet,
non-finite samples or sample spacing, or (in :func:`read_xtf`) a few isolated pings whose
sides, sample count or spacing differ from the rest. Fixes outside the globe, and fixes further
from the running median of their neighbours than :data:`MAX_SPEED` allows (a GPS jump), are
rejected and interpolated like pings without navigation; so are heading spikes beyond
:data:`MAX_TURN_RATE` and the few times out of order (a clock reset to a real date).
:func:`read_xtf` logs one warning line saying what it skipped or repaired and lists it in the
image's metadata. A damaged packet frame (no marker, an empty packet, one running past the
file's end) costs one ping, skipped like the others, and reading goes on at the next correctly
framed packet; only a file that starts damaged with nothing good after it, or with no usable
ping, is an error.
"""

from __future__ import annotations

import bisect
import ctypes
import datetime
import logging
import math
import os
import struct
from collections import Counter
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from .._checks import non_negative, positive
from ..errors import SonarRasterError
from ..image import NO_DATA_LEVEL, SonarImage
from ..sonar import Sonar
from ..trajectory import Trajectory

__all__ = [
    "SkippedPing", "XtfNavigation", "XtfPing", "XtfReader", "iter_pings", "read_xtf",
    "read_xtf_track", "track_jumps", "write_xtf", "xtf_frequencies",
]  # fmt: skip

log = logging.getLogger(__name__)

#: ``FileFormat`` byte of every XTF file.
XTF_FILE_FORMAT = 0x7B
#: Every packet starts with this 16-bit word.
XTF_MAGIC = 0xFACE
_SONAR_PACKET = 0
#: ``XTFHEADER_NAVIGATION``: a time-stamped fix from the navigation source, between pings.
_NAVIGATION_PACKET = 42
#: ``XTFPOSRAWNAVIGATION``: a fix as the navigation source gave it; its ``MicroSeconds`` field
#: holds tenths of milliseconds (0-9999), as the XTF specification says.
_POSITION_PACKET = 107
_PORT, _STARBOARD = 1, 2
_NAV_DEGREES = 3
_FILE_HEADER_BYTES = 1024
_SAMPLE_FORMATS = {"float32": (5, 4, np.float32), "uint16": (3, 2, np.uint16)}
#: Sample type by ``ChanInfo.SampleFormat``, else by ``BytesPerSample`` (as pyxtf reads them).
_FORMAT_DTYPES = {2: np.uint32, 3: np.uint16, 5: np.float32, 8: np.uint8}
_SIZE_DTYPES = {1: np.uint8, 2: np.uint16, 4: np.uint32, 8: np.uint64}
_IBM_FLOAT = 1
_EPOCH_DAY = datetime.date(1970, 1, 1).toordinal()

#: Largest ``|Weight|`` read: samples are scaled by ``2 ** -Weight``, and beyond this a float32
#: sample under- or overflows (a corrupt field, not a gain).
MAX_WEIGHT = 64
#: Navigation filter: a fix further from the running median of its :data:`NAV_WINDOW`
#: neighbours on each side than ``MAX_SPEED`` (m/s) times the window's time span plus
#: ``FIX_NOISE`` (m) is a jump.
MAX_SPEED = 10.0
FIX_NOISE = 10.0
#: A heading further from the median of its neighbours than ``MAX_TURN_RATE`` (degrees per
#: second) times the window's time span plus ``HEADING_NOISE`` (degrees) is a spike.
MAX_TURN_RATE = 20.0
HEADING_NOISE = 30.0
NAV_WINDOW = 10
#: Pings whose layout (sides, sample count, spacing) differs from the file's usual one are
#: glitches, skipped, in runs of at most this many (and at most a tenth of the pings read);
#: longer runs mean the sonar's setting changed.
GLITCH_RUN = 3
#: Longest time between two navigation packets a ping's position is interpolated across, s.
MAX_FIX_GAP = 10.0
#: Plausible depth and altitude, metres (deeper than any ocean is a corrupt field).
_MAX_DEPTH = 12000.0


def _pyxtf() -> Any:
    try:
        import pyxtf
    except ImportError:  # pragma: no cover - a declared dependency
        raise SonarRasterError("XTF support needs pyxtf: pip install pyxtf") from None
    return pyxtf


#: Largest share of a float channel's samples that may be NaN or infinite and set to 0.
MAX_BLANKED = 0.1


@dataclass(frozen=True)
class XtfPing:
    """One side-scan ping of an XTF file.

    Attributes
    ----------
    index : int
        Position among the file's sonar pings, from 0.
    number : int
        The file's ``PingNumber``.
    time : float
        Seconds since 1970-01-01 UTC.
    sides : dict of str to ndarray, shape (samples,), float32
        "port" and/or "starboard" samples from range 0 outward (``2 ** -Weight`` applied).
    range_bin : float
        Slant-range sample spacing, metres.
    sound_speed : float
        Speed of sound, m/s (the full speed, whatever the file stored).
    x, y : float
        Longitude, latitude (degrees) or easting, northing (metres); NaN without navigation.
    heading, roll, pitch : float
        Compass heading, roll (starboard down) and pitch (nose up), radians; NaN when the field
        holds no angle (not finite, beyond ±720°).
    altitude : float
        Altitude above the seabed from the file, metres; NaN when the file has none (0) or the
        field is not an altitude.
    depth : float
        Sensor depth below the surface, metres; NaN when the field is not a depth.
    blanked : int
        NaN or infinite samples of a float channel set to 0 (see :data:`MAX_BLANKED`).
    """

    index: int
    number: int
    time: float
    sides: dict[str, np.ndarray]
    range_bin: float
    sound_speed: float
    x: float
    y: float
    heading: float
    roll: float
    pitch: float
    altitude: float
    depth: float
    blanked: int = 0

    @property
    def has_navigation(self) -> bool:
        """True when the ping carries a position."""
        return math.isfinite(self.x) and math.isfinite(self.y)


@dataclass(frozen=True)
class SkippedPing:
    """A side-scan ping left out because a field of its packet is impossible.

    Attributes
    ----------
    index : int
        Position among the file's sonar pings, from 0 (skipped pings keep their place, so the
        indices of the others do not move).
    kind : str
        What was wrong: "time", "Weight", "samples", "spacing", "packet", "layout", or the
        packet's frame: "truncated" (it runs past the file's end) or "corrupt" (no marker,
        empty).
    detail : str
        The offending value, e.g. "date 2013-09-40".
    """

    index: int
    kind: str
    detail: str


class BadPacket(Exception):
    """A sonar packet that is not a usable ping, or a damaged frame (``kind``, ``detail``).

    Raised by :meth:`XtfReader.layout` (and caught by the reader, which counts the ping as
    skipped); ``insert`` leaves such a packet as recorded.
    """

    def __init__(self, kind: str, detail: str) -> None:
        super().__init__(detail)
        self.kind, self.detail = kind, detail


class XtfReader:
    """Stream the side-scan pings of an XTF file, one at a time.

    Use as a context manager; iterating yields :class:`XtfPing` in file order. The file header
    is checked on opening and each packet as it is read, so a wrong or empty file, or one whose
    first packet is damaged with no good one after it, raises :class:`SonarRasterError` naming
    the file and the byte offset. A damaged frame further on, and a packet that is framed
    correctly but holds an impossible field, is skipped and listed in :attr:`skipped`; a file
    none of whose pings is usable raises.

    Parameters
    ----------
    path : str or PathLike
        The ``.xtf`` file.
    frequency : float or {"low", "high"}, optional
        Which channels of a dual-frequency file to read: the pair nearest this frequency (Hz,
        within 5 %), or the lower or higher one; default the first pair, with a warning line
        naming the others. An error where the file has no such channels.

    Attributes
    ----------
    header : pyxtf.XTFFileHeader
        The file header.
    channels : dict of str to int
        Side name to index in the file header's ``ChanInfo``.
    units : str
        "degrees" (longitude, latitude) or "metres" (easting, northing).
    frequency_hz : float
        Centre frequency of the side-scan channels read, Hz (0 when the file does not say).
    tilt_deg : float
        Depression of the first side-scan channel's beam axis, degrees (0 when not given).
    skipped : list of SkippedPing
        Pings skipped so far (packets framed correctly but with an impossible field).
    count : int
        Side-scan pings read so far, skipped ones included.
    """

    def __init__(self, path: str | os.PathLike, frequency: float | str | None = None) -> None:
        self.path = Path(path)
        self._size = _file_size(self.path)
        self._fh: BinaryIO | None = open(self.path, "rb")  # noqa: SIM115 - closed by close()
        try:
            self.header = self._read_header()
            self.channels = _side_channels(self.header, self.path, frequency)
            for side, k in self.channels.items():
                _check_sample_type(self.header.ChanInfo[k], k, side, self.path)
        except BaseException:
            self.close()
            raise
        info = self.header.ChanInfo
        self.units = "degrees" if self.header.NavUnits == _NAV_DEGREES else "metres"
        first = info[next(iter(self.channels.values()))]
        frequency, tilt = float(first.Frequency), float(first.TiltAngle)
        self.frequency_hz = frequency * 1e3 if 0.0 < frequency < 1e6 else 0.0
        self.tilt_deg = tilt if 0.0 < tilt < 90.0 else 0.0
        self.skipped: list[SkippedPing] = []
        #: (time, x, y) of each navigation packet read so far (type 42), in file order.
        self.fixes: list[tuple[float, float, float]] = []
        self.count = 0
        self._unread_told = False

    def _read_header(self) -> Any:
        assert self._fh is not None
        header = _checked_header(self._fh.read(_FILE_HEADER_BYTES), self.path)
        n = header.channel_count()
        if n > 6:  # each further 6 channels add 1024 bytes of ChanInfo
            first = _FILE_HEADER_BYTES * (1 + (n - 1) // 6)
            self._fh.seek(first)
            if self._fh.read(2) != struct.pack("<H", XTF_MAGIC):  # a wrong count: see packets
                first = _FILE_HEADER_BYTES
            self._fh.seek(first)
        return header

    def __enter__(self) -> XtfReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Close the file; safe to call twice."""
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def __iter__(self) -> Iterator[XtfPing]:
        if self._fh is None:
            raise SonarRasterError(f"{self.path}: the reader is closed")
        index = 0
        held: XtfPing | None = None  # one side of a ping whose other side may be the next packet
        for offset, raw in self.packets():
            try:
                if not isinstance(raw, bytes):
                    raise raw
                ping = self._ping(raw, index)
            except BadPacket as bad:
                self.skipped.append(SkippedPing(index, bad.kind, f"{bad.detail} at byte {offset}"))
                index = self.count = index + 1
                continue
            if ping is None:
                continue
            if held is not None and _completes(held, ping):
                yield _joined(held, ping)  # a recorder writing one channel per packet
                held = None
                continue
            if held is not None:
                yield held
                held = None
            if len(ping.sides) < len(self.channels):
                held = ping
            else:
                yield ping
            index = self.count = index + 1
        if held is not None:
            yield held
        if index == 0:
            raise SonarRasterError(f"{self.path} has no side-scan pings")
        if len(self.skipped) == index:
            raise SonarRasterError(
                f"{self.path} has no usable side-scan ping: {skip_summary(self.skipped, index)}"
            )

    def packets(self) -> Iterator[tuple[int, bytes | Exception]]:
        """(offset, bytes) of each sonar packet, from the first; others are skipped unread.

        A damaged frame (no packet marker, an empty packet, one that runs past the file's end)
        comes as (offset, an exception saying what is wrong), which the reader counts as a
        skipped ping, and reading goes on at the next correctly framed packet
        (:meth:`_next_packet`); with none, the file ends there (a recorder stopped in the middle
        of a write, a tail of zeros or junk). Raises when the first packet is damaged and none
        follows (a truncated or non-XTF file).
        """
        pyxtf = _pyxtf()
        fh = self._fh
        assert fh is not None
        start_size = ctypes.sizeof(pyxtf.XTFPacketStart)
        first, seen = True, False  # at the first packet; any packet yielded
        while True:
            offset = fh.tell()
            head = fh.read(start_size)
            if not head:
                return
            bad = None
            if len(head) < start_size:
                bad = BadPacket("truncated", f"the file ends {len(head)} bytes into a packet")
            else:
                start = pyxtf.XTFPacketStart.from_buffer_copy(head)
                size = int(start.NumBytesThisRecord)
                if start.MagicNumber != XTF_MAGIC:
                    bad = BadPacket("corrupt", "no packet marker (0xFACE)")
                elif size < start_size:
                    bad = BadPacket("corrupt", "an empty packet")
                elif offset + size > self._size:
                    left = self._size - offset
                    bad = BadPacket("truncated", f"a packet of {size} bytes, {left} left")
            if bad is not None:
                # the first packet may sit at byte 1024 whatever the header's channel count says
                resume = self._next_packet(_FILE_HEADER_BYTES if first else offset + 1)
                if resume is None and not seen:
                    what = "is truncated" if bad.kind == "truncated" else "is corrupt or not XTF"
                    raise SonarRasterError(f"{self.path} {what}: {bad} at byte {offset}")
                if resume != _FILE_HEADER_BYTES or not first:
                    seen = True
                    yield offset, bad
                if resume is None:
                    return
                fh.seek(resume)
                first = False
                continue
            first = False
            if start.HeaderType in (_NAVIGATION_PACKET, _POSITION_PACKET):
                fix = _navigation_fix(fh.read(size - start_size), head, start.HeaderType)
                if fix is not None:
                    self.fixes.append(fix)
            if start.HeaderType != _SONAR_PACKET:
                fh.seek(offset + size)
                continue
            seen = True
            yield offset, head + fh.read(size - start_size)

    def _next_packet(self, begin: int) -> int | None:
        """Offset of the first correctly framed packet at or after ``begin``, or None.

        Framed correctly: its marker, a size of at least a packet start that ends within the
        file, and at its end the file's end or another marker (so a marker that happens to lie
        in sample data is not taken). Reads the file on in 1 MiB blocks.
        """
        fh = self._fh
        assert fh is not None
        marker = struct.pack("<H", XTF_MAGIC)
        block = 1 << 20
        here = begin
        while here < self._size:
            fh.seek(here)
            data = fh.read(block + 1)  # one byte more: a marker across the blocks' seam
            at = data.find(marker)
            while 0 <= at < block:
                fh.seek(here + at + 10)
                size = struct.unpack("<I", (fh.read(4) + bytes(4))[:4])[0]
                end = here + at + size
                if size >= 14 and end <= self._size:
                    fh.seek(end)
                    if end == self._size or fh.read(2) == marker:
                        return here + at
                at = data.find(marker, at + 1)
            here += block
        return None

    def _ping(self, raw: bytes, index: int) -> XtfPing | None:
        """The ping of a sonar packet, None without side-scan channels; BadPacket if unusable."""
        ping, channels = self._decode(raw)
        sides: dict[str, np.ndarray] = {}
        blanked = 0
        spacing: dict[str, float] = {}
        speed = 0.0
        for chan, k, data in channels:
            side = self._side_of(k)
            if side is None or side in sides:
                continue
            if (len(data) != chan.NumSamples and chan.NumSamples > 0) or len(data) == 0:
                raise BadPacket("samples", f"{len(data)} of {chan.NumSamples} samples")
            speed = _sound_speed(float(ping.SoundVelocity), chan)
            values, blank = _scaled(data, int(chan.Weight))
            blanked += blank
            sides[side] = values[::-1].copy() if side == "port" else values
            spacing[side] = _sample_spacing(chan, len(data), speed)
        if not sides:
            return None
        bins = list(spacing.values())
        if not all(math.isfinite(b) and b > 0 for b in bins) or max(bins) > min(bins) * (1 + 1e-5):
            shown = " and ".join(f"{b:.4g}" for b in bins)
            raise BadPacket("spacing", f"sample spacing {shown} m")
        return replace(_make_ping(ping, index, sides, bins[0], speed), blanked=blanked)

    def _decode(self, raw: bytes) -> tuple[Any, list[tuple[Any, int, np.ndarray]]]:
        """Ping header and (channel header, ChanInfo index, samples) of the channels read."""
        ping, layout = self.layout(raw)
        channels = []
        for chan, k, pos, count, dtype in layout:
            channels.append((chan, k, np.frombuffer(raw, dtype, count, pos)))
        return ping, channels

    def layout(self, raw: bytes) -> tuple[Any, list[tuple[Any, int, int, int, np.dtype]]]:
        """The ping header and its channels to read; BadPacket if they do not fit the packet.

        Per channel: (channel header, ChanInfo index, byte offset of its samples in ``raw``,
        sample count, sample type).

        A channel is described by the ``ChanInfo`` entry its ``ChannelNumber`` names, unless
        the packet's numbers count from 1 (1, 2, ... where ChanInfo has no entry for the last)
        or repeat: then by its place in the packet. Reading stops at a channel no entry
        describes with a sample size, and once the sides wanted are read.
        """
        pyxtf = _pyxtf()
        head = ctypes.sizeof(pyxtf.XTFPingHeader)
        if len(raw) < head:
            raise BadPacket("packet", f"{len(raw)} bytes, less than a ping header ({head})")
        ping = pyxtf.XTFPingHeader.from_buffer_copy(raw)
        wanted = set(self.channels.values())
        count = int(ping.NumChansToFollow)
        if len(wanted) < 2 and not self._unread_told:
            # one side known: a channel the header leaves out may be the other one
            described = sum(map(self._described, range(6)))
            if count > described:
                self._unread_told = True
                log.warning(
                    "%s: pings carry %d channels but the header describes %d (the %s side "
                    "only); the others are not read: set their ChanInfo (TypeOfChannel 1 port, "
                    "2 starboard) to read them",
                    self.path, count, described, next(iter(self.channels)),
                )  # fmt: skip
        numbers = [int(chan.ChannelNumber) for chan, *_ in self._walk(raw, head, count, None)]
        by_place = len(set(numbers)) < len(numbers) or (
            len(numbers) > 1 and numbers == list(range(1, len(numbers) + 1))
            and not self._described(len(numbers))
        )  # fmt: skip
        layout = []
        for chan, k, pos, n, dtype in self._walk(raw, head, count, not by_place):
            layout.append((chan, k, pos, n, dtype))
            if wanted <= {c[1] for c in layout}:
                break  # both sides read; later channels are not used
        return ping, layout

    def _walk(
        self, raw: bytes, pos: int, count: int, by_number: bool | None
    ) -> Iterator[tuple[Any, int, int, int, np.dtype]]:
        """The packet's channels from byte ``pos``, as :meth:`layout` gives them.

        Each is described by the ChanInfo entry its number names (``by_number``, where one
        gives a sample size), else by its place; None: a trial walk by place that stops
        quietly where the packet does not hold what the entries say.
        """
        chan_header = _pyxtf().XTFPingChanHeader
        chan_size = ctypes.sizeof(chan_header)
        for place in range(count):
            if pos + chan_size > len(raw):
                if by_number is None:
                    return
                raise BadPacket("samples", f"channel {place} starts past the packet's end")
            chan = chan_header.from_buffer_copy(raw, pos)
            pos += chan_size
            k = int(chan.ChannelNumber) if by_number else place
            k = k if self._described(k) else place  # a number no entry has: its place
            if not self._described(k):
                return  # no entry gives its sample size: the rest cannot be found
            info = self.header.ChanInfo[k]
            n = int(chan.NumSamples) or int(info.Reserved)
            size, dtype = int(info.BytesPerSample), _sample_dtype(info)
            if dtype is None or (n * size) % dtype.itemsize:
                if by_number is None:
                    return
                raise BadPacket("samples", f"sample format {info.SampleFormat} of {size} bytes")
            if pos + n * size > len(raw):
                if by_number is None:
                    return
                raise BadPacket(
                    "samples", f"{n} samples of channel {place} do not fit the packet "
                    f"({len(raw) - pos} bytes are left)"
                )  # fmt: skip
            yield chan, k, pos, n * size // dtype.itemsize, dtype
            pos += n * size

    def _described(self, k: int) -> bool:
        """True when ChanInfo entry ``k`` (of the first 6) gives a sample size."""
        return 0 <= k < 6 and int(self.header.ChanInfo[k].BytesPerSample) > 0

    def _side_of(self, channel_number: int) -> str | None:
        for side, k in self.channels.items():
            if k == channel_number:
                return side
        return None


def _sample_dtype(info: Any) -> np.dtype | None:
    """A ChanInfo entry's sample type: by ``SampleFormat``, else by ``BytesPerSample``.

    None for IBM floats (format 1) and sizes no type has.
    """
    code, size = int(info.SampleFormat), int(info.BytesPerSample)
    kind = _FORMAT_DTYPES.get(code) or (None if code == _IBM_FLOAT else _SIZE_DTYPES.get(size))
    return None if kind is None else np.dtype(kind)


def _check_sample_type(info: Any, k: int, side: str, path: Path) -> None:
    """An error naming the side channel's sample type when the reader has no such type."""
    code, size = int(info.SampleFormat), int(info.BytesPerSample)
    if code == _IBM_FLOAT:
        raise SonarRasterError(
            f"{path}: the {side} channel (ChanInfo {k}) holds IBM floating-point samples (XTF "
            "SampleFormat 1), which are not read; export the file with IEEE float (5) or "
            "integer samples"
        )
    dtype = _sample_dtype(info)
    if dtype is None or size % dtype.itemsize:
        raise SonarRasterError(
            f"{path}: the {side} channel (ChanInfo {k}) has {size}-byte samples of "
            f"SampleFormat {code}, not an XTF sample type (1, 2 or 4 bytes; 8 bit 8, 16 bit 3, "
            "32 bit 2, IEEE float 5)"
        )


def _completes(held: XtfPing, ping: XtfPing) -> bool:
    """True when ``ping`` holds the other side of ``held``: one ping written as two packets."""
    return (
        (ping.number, ping.time) == (held.number, held.time)
        and not ping.sides.keys() & held.sides.keys()
        and math.isclose(ping.range_bin, held.range_bin, rel_tol=1e-5)
    )


def _joined(held: XtfPing, ping: XtfPing) -> XtfPing:
    """One ping of ``held``'s header and both packets' sides (port first)."""
    both = {**held.sides, **ping.sides}
    sides: dict[str, np.ndarray] = {s: both[s] for s in ("port", "starboard") if s in both}
    return replace(held, sides=sides, blanked=held.blanked + ping.blanked)


def _file_size(path: Path) -> int:
    if not path.is_file():
        raise SonarRasterError(f"{path}: no such file")
    size = path.stat().st_size
    if size == 0:
        raise SonarRasterError(f"{path} is empty, not an XTF file")
    if size < _FILE_HEADER_BYTES:
        raise SonarRasterError(
            f"{path} is not an XTF file (or is truncated): {size} bytes, shorter than the "
            f"{_FILE_HEADER_BYTES}-byte XTF file header"
        )
    return size


def _checked_header(raw: bytes, path: Path) -> Any:
    """The XTF file header in ``raw`` (its first 1024 bytes); an error if it is not one."""
    header = _pyxtf().XTFFileHeader.create_from_buffer(raw)
    if header.FileFormat != XTF_FILE_FORMAT:
        raise SonarRasterError(
            f"{path} is not an XTF file (format byte {header.FileFormat}, expected "
            f"{XTF_FILE_FORMAT})"
        )
    return header


def xtf_frequencies(path: str | os.PathLike) -> list[float]:
    """The frequencies of a file's side-scan channel pairs, Hz, as its header lists them.

    One entry per pair of a port and a starboard channel (two for a dual-frequency side-scan);
    0 where the header does not record the pair's frequency.

    Raises
    ------
    SonarRasterError
        If the file is missing, not XTF, or has no side-scan channel.
    """
    p = Path(path)
    _file_size(p)
    with open(p, "rb") as fh:
        header = _checked_header(fh.read(_FILE_HEADER_BYTES), p)
    return [1e3 * khz for khz, _ in _channel_sets(header, p)]


def _side_channels(header: Any, path: Path, frequency: float | str | None = None) -> dict[str, int]:
    """Side name to ChanInfo index: the port and starboard channels of one frequency.

    ``frequency`` picks one of the :func:`_channel_sets` (:func:`_chosen_set`), by default the
    first, with a line naming the others. A side taken from past the header's count is said.
    """
    n = min(int(header.NumberOfSonarChannels), 6)
    out = _chosen_set(_channel_sets(header, path), frequency, path)
    for side, k in out.items():
        if k >= n:
            log.warning(
                "%s: the header counts %d sonar channel(s) but ChanInfo %d describes the %s "
                "side: reading it too",
                path, n, k, side,
            )  # fmt: skip
    return dict(sorted(out.items()))


def _channel_sets(header: Any, path: Path) -> list[tuple[float, dict[str, int]]]:
    """The file's side-scan channels grouped into pairs: (kHz or 0, side to ChanInfo index).

    A side missing from the channels the header counts is taken from the ChanInfo entries past
    the count (of the first file header's 6) when one describes it with a sample size, so a
    count of 1 in a two-sided file does not drop starboard. The counted side-scan channels are
    grouped into sets of one port and one starboard channel (by ``Frequency`` where the header
    gives it, else in order: a dual-frequency file's two pairs).
    """
    n = min(int(header.NumberOfSonarChannels), 6)
    sets: list[tuple[float, dict[str, int]]] = []
    for k in range(6):
        info = header.ChanInfo[k]
        side = {_PORT: "port", _STARBOARD: "starboard"}.get(int(info.TypeOfChannel))
        if side is None or (k >= n and int(info.BytesPerSample) not in _SIZE_DTYPES):
            continue
        khz = _channel_khz(info)
        for i, (f, members) in enumerate(sets):
            if side not in members and (_same_khz(f, khz) or 0.0 in (f, khz) or k >= n):
                members[side] = k
                sets[i] = (f or khz, members)
                break
        else:
            if k < n or not sets:  # past the count an entry only completes a pair
                sets.append((khz, {side: k}))
    if not sets:
        raise SonarRasterError(f"{path} has no port or starboard side-scan channel")
    return sets


def _channel_khz(info: Any) -> float:
    """A ChanInfo entry's frequency in kHz (0 where the file does not say)."""
    khz = float(info.Frequency)
    return khz if 0.0 < khz < 1e6 else 0.0


def _same_khz(a: float, b: float) -> bool:
    """Two recorded frequencies of one pair: within 5 % (a header may round them apart)."""
    return abs(a - b) <= 0.05 * max(a, b)


def _chosen_set(
    sets: list[tuple[float, dict[str, int]]], frequency: float | str | None, path: Path
) -> dict[str, int]:
    """The channel set ``frequency`` asks for: None (the first), "low", "high" or a number (Hz).

    A file with several sets read without a choice says which one is read and how to read the
    others; a choice the file cannot meet is an error naming what it has.
    """
    known = all(f > 0 for f, _ in sets)
    names = ", ".join(f"{f:g} kHz" if f > 0 else f"channels {sorted(m.values())}" for f, m in sets)
    if frequency is None:
        if len(sets) > 1:
            f, members = sets[0]
            what = f"{f:g} kHz" if f > 0 else f"ChanInfo {sorted(members.values())}"
            log.warning(
                "%s: side-scan channels at %s; reading %s (choose with --xtf-frequency "
                "low/high/kHz; Python: read_xtf(frequency=...))",
                path, names, what,
            )  # fmt: skip
        return sets[0][1]
    if isinstance(frequency, str):
        if frequency not in ("low", "high"):
            raise SonarRasterError(
                f"frequency must be 'low', 'high' or a number in Hz, got {frequency!r}"
            )
        if len(sets) == 1:
            return sets[0][1]
        if not known:
            raise SonarRasterError(
                f"{path} does not record its channels' frequencies ({names}): 'low' and "
                "'high' cannot be told apart"
            )
        pick = min if frequency == "low" else max
        return pick(sets, key=lambda item: item[0])[1]
    hz = float(frequency)
    if not (math.isfinite(hz) and hz > 0):
        raise SonarRasterError(f"frequency must be a positive number of Hz, got {frequency!r}")
    for f, members in sets:
        if f > 0 and _same_khz(f * 1e3, hz):
            return members
    if len(sets) == 1 and sets[0][0] == 0.0:
        return sets[0][1]  # one set, no frequency recorded: the only choice there is
    raise SonarRasterError(
        f"{path} has no side-scan channels at {hz / 1e3:g} kHz (it has {names}); give one of "
        "those, or low / high"
    )


def _sound_speed(field: float, chan: Any) -> float:
    """Full sound speed from the ping's ``SoundVelocity`` field, which may hold half of it."""
    if not (math.isfinite(field) and field > 0):
        field = 750.0  # the usual default: half of 1500 m/s
    if chan.TimeDuration > 0 and chan.SlantRange > 0:
        implied = 2.0 * chan.SlantRange / chan.TimeDuration
        return 2.0 * field if abs(2.0 * field - implied) < abs(field - implied) else field
    return 2.0 * field if field < 1000.0 else field


def _sample_spacing(chan: Any, samples: int, speed: float) -> float:
    if samples == 0:
        return 0.0
    if chan.SlantRange > 0:
        return float(chan.SlantRange) / samples
    return float(chan.TimeDuration) * speed / 2.0 / samples


def _scaled(data: np.ndarray, weight: int) -> tuple[np.ndarray, int]:
    """Samples as float32 times ``2 ** -weight``, and how many no-data ones were set to 0.

    A few NaN, infinite or huge (:data:`..image.NO_DATA_LEVEL` or more) samples of a float
    channel (at most :data:`MAX_BLANKED` of them; a processing program's "no data") become 0,
    no echo; more, or any from a weight that overflows, make the packet a BadPacket, as does a
    wild weight.
    """
    if abs(weight) > MAX_WEIGHT:
        raise BadPacket("Weight", f"Weight {weight}, beyond {MAX_WEIGHT} either way")
    values = data.astype(np.float32)
    if weight:
        with np.errstate(over="ignore"):
            values *= np.float32(2.0**-weight)
    if data.dtype.kind != "f" and weight >= 0:
        return values, 0
    with np.errstate(invalid="ignore"):
        bad = ~(np.abs(values) < NO_DATA_LEVEL)
    blanked = int(bad.sum())
    if blanked and (data.dtype.kind != "f" or blanked > MAX_BLANKED * len(values)):
        shown = f"{blanked} non-finite or no-data sample values of {len(values)}"
        raise BadPacket("samples", shown)
    if blanked:
        with np.errstate(invalid="ignore"):  # the file's own, not an overflow of the weight
            bad &= ~(np.abs(data) < NO_DATA_LEVEL)
        if int(bad.sum()) != blanked:
            raise BadPacket("samples", "non-finite sample values")
        values[bad] = 0.0
    return values, blanked


def _ping_time(ping: Any) -> float:
    """Seconds since 1970 of the ping's date and time fields; BadPacket if they do not exist."""
    year, month, day = int(ping.Year), int(ping.Month), int(ping.Day)
    hour, minute, second, hundredths = (
        int(ping.Hour), int(ping.Minute), int(ping.Second), int(ping.HSeconds)
    )  # fmt: skip
    try:
        days = datetime.date(year, month, day).toordinal() - _EPOCH_DAY
    except ValueError:
        raise BadPacket("time", f"date {year:04d}-{month:02d}-{day:02d}") from None
    if hour > 23 or minute > 59 or second > 60 or hundredths > 99:
        raise BadPacket(
            "time", f"time of day {hour:02d}:{minute:02d}:{second:02d}.{hundredths:02d}"
        )
    ms = (((days * 24 + hour) * 60 + minute) * 60 + second) * 1000 + 10 * hundredths
    return float(ms * 1000) * 1e-6  # as pyxtf's datetime64 in microseconds


def _navigation_fix(
    body: bytes, head: bytes, kind: int = _NAVIGATION_PACKET
) -> tuple[float, float, float] | None:
    """(time, x, y) of a navigation packet, or None when it holds no usable fix.

    Type 42 (``XTFHEADER_NAVIGATION``) or 107 (``XTFPOSRAWNAVIGATION``).
    """
    raw_kind = kind == _POSITION_PACKET
    nav = _pyxtf().XTFPosRawNavigation if raw_kind else _pyxtf().XTFHeaderNavigation
    raw = head + body
    if len(raw) < ctypes.sizeof(nav):
        return None
    packet = nav.from_buffer_copy(raw)
    x, y = float(packet.RawXcoordinate), float(packet.RawYcoordinate)
    if (x == 0.0 and y == 0.0) or not (math.isfinite(x) and math.isfinite(y)):
        return None
    try:
        day = datetime.date(int(packet.Year), int(packet.Month), int(packet.Day))
    except ValueError:
        return None
    hour, minute, second = int(packet.Hour), int(packet.Minute), int(packet.Second)
    micro = int(packet.Microsecond)
    if raw_kind:  # tenths of milliseconds
        micro = micro * 100 if micro <= 9999 else 1_000_000
    if hour > 23 or minute > 59 or second > 60 or micro > 999_999:
        return None
    seconds = ((day.toordinal() - _EPOCH_DAY) * 24 + hour) * 3600 + minute * 60 + second
    return float(seconds * 1_000_000 + micro) * 1e-6, x, y  # as _ping_time rounds


def _angle(value: float) -> float:
    """Degrees to radians; NaN for a value no angle field holds (non-finite, beyond ±720)."""
    return math.radians(value) if abs(value) <= 720.0 else math.nan


def _make_ping(
    ping: Any, index: int, sides: dict[str, np.ndarray], range_bin: float, speed: float
) -> XtfPing:
    x, y = float(ping.SensorXcoordinate), float(ping.SensorYcoordinate)
    if x == 0.0 and y == 0.0:  # some recorders fill the ship's position only
        x, y = float(ping.ShipXcoordinate), float(ping.ShipYcoordinate)
    if x == 0.0 and y == 0.0:
        x = y = math.nan
    altitude, depth = float(ping.SensorPrimaryAltitude), float(ping.SensorDepth)
    return XtfPing(
        index=index,
        number=int(ping.PingNumber),
        time=_ping_time(ping),
        sides=sides,
        range_bin=range_bin,
        sound_speed=speed,
        x=x,
        y=y,
        heading=_angle(float(ping.SensorHeading)),
        roll=_angle(float(ping.SensorRoll)),
        pitch=_angle(float(ping.SensorPitch)),
        altitude=altitude if 0.0 < altitude < _MAX_DEPTH else math.nan,
        depth=depth if abs(depth) < _MAX_DEPTH else math.nan,
    )


def iter_pings(path: str | os.PathLike, frequency: float | str | None = None) -> Iterator[XtfPing]:
    """Yield the side-scan pings of an XTF file one at a time (see :class:`XtfReader`).

    Skipped pings are logged in one warning line once the file has been read through.
    """
    with XtfReader(path, frequency) as reader:
        blanked = [0, 0]
        for ping in reader:
            blanked[0] += ping.blanked
            blanked[1] += ping.blanked > 0
            yield ping
        if reader.skipped or blanked[0]:
            summary = skip_summary(reader.skipped, reader.count, None, (blanked[0], blanked[1]))
            log.warning("%s: %s", path, summary)


def skip_summary(
    skipped: list[SkippedPing],
    total: int | None = None,
    rejected: dict[int, str] | None = None,
    blanked: tuple[int, int] = (0, 0),
) -> str:
    """One line saying which pings were skipped and why, and which fixes were interpolated.

    Parameters
    ----------
    skipped : list of SkippedPing
    total : int, optional
        Pings read (skipped included), for "skipped 2 of 461 pings".
    rejected : dict of int to str, optional
        Ping index to the reason its position or heading was rejected and interpolated.
    blanked : (int, int)
        Non-finite samples set to 0, and the pings they were in.
    """
    parts = []
    if skipped:
        of = f" of {total}" if total else ""
        why = _grouped([(s.index, s.kind, s.detail) for s in skipped])
        parts.append(f"skipped {len(skipped)}{of} pings ({why})")
    if rejected:
        n = len(rejected)
        why = _grouped([(k, "", reason) for k, reason in sorted(rejected.items())])
        parts.append(f"interpolated the navigation of {n} {'ping' if n == 1 else 'pings'} ({why})")
    if blanked[0]:
        parts.append(
            f"set {blanked[0]} non-finite or no-data samples to 0 (no echo) in {blanked[1]} "
            f"{'ping' if blanked[1] == 1 else 'pings'}"
        )
    return "; ".join(parts)


def _grouped(items: list[tuple[int, str, str]], shown: int = 3) -> str:
    """Reasons by kind ("time: ping 17 date 2013-09-40, ..."), at most ``shown`` of each."""
    kinds: dict[str, list[str]] = {}
    for index, kind, detail in items:
        kinds.setdefault(kind, []).append(f"ping {index} {detail}")
    out = []
    for kind, lines in kinds.items():
        more = f", {len(lines) - shown} more" if len(lines) > shown else ""
        out.append(f"{kind}: " * bool(kind) + ", ".join(lines[:shown]) + more)
    return "; ".join(out)


@dataclass(frozen=True)
class XtfNavigation:
    """Per-ping navigation and attitude of an XTF file; arrays of shape (pings,), float64.

    Attributes
    ----------
    time : ndarray
        Seconds since 1970-01-01 UTC; a few times out of order are interpolated.
    x, y : ndarray
        Longitude, latitude (degrees) or easting, northing (metres); NaN where ``valid`` is
        False.
    units : str
        "degrees" or "metres".
    heading, roll, pitch : ndarray
        Radians: compass heading, roll (starboard down), pitch (nose up); NaN where the file's
        value is not an angle or the heading was rejected as a spike.
    altitude : ndarray
        Altitude above the seabed from the file, metres; NaN where the file has none.
    depth : ndarray
        Sensor depth, metres, positive down; NaN where the field is not a depth.
    valid : ndarray, bool
        Pings with a position (rejected fixes are not valid).
    rejected : dict of int to str
        Row to the reason its time, fix or heading was rejected by the navigation filter (see
        the module's notes); those rows are interpolated like pings without navigation.
    """

    time: np.ndarray
    x: np.ndarray
    y: np.ndarray
    units: str
    heading: np.ndarray
    roll: np.ndarray
    pitch: np.ndarray
    altitude: np.ndarray
    depth: np.ndarray
    valid: np.ndarray = field(repr=False)
    rejected: dict[int, str] = field(default_factory=dict, repr=False)

    @property
    def crs(self) -> str | None:
        """CRS of :meth:`projected`: the UTM zone of the first fix for degrees, else None."""
        if self.units != "degrees":
            return None
        if not self.valid.any():
            raise SonarRasterError("the file has no navigation: no ping has a position")
        k = int(np.argmax(self.valid))
        lon, lat = float(self.x[k]), float(self.y[k])
        zone = int((lon + 180.0) // 6.0) % 60 + 1
        return f"EPSG:{32600 + zone if lat >= 0 else 32700 + zone}"

    def fresh(self) -> np.ndarray:
        """Pings with a new fix: a position different from the previous ping with one.

        Navigation often updates slower than the pings, which repeat the last fix.
        """
        idx = np.flatnonzero(self.valid)
        out = np.zeros(len(self.valid), dtype=bool)
        if len(idx):
            moved = (np.diff(self.x[idx]) != 0) | (np.diff(self.y[idx]) != 0)
            out[idx[np.concatenate([[True], moved])]] = True
        return out

    def projected(self) -> tuple[np.ndarray, np.ndarray]:
        """Easting and northing in metres (UTM for degrees) of every ping.

        Positions are interpolated linearly in time between the :meth:`fresh` fixes (in ping
        index when the times do not increase), and held beyond the first and last fix, so
        repeated fixes and pings without a position get positions too.
        """
        if not self.valid.any():
            raise SonarRasterError("the file has no navigation: no ping has a position")
        fresh = self.fresh()
        east, north = self.x[fresh], self.y[fresh]
        wild = _out_of_range(east, north, self.units)
        if wild.any():
            k = int(np.flatnonzero(fresh)[np.argmax(wild)])
            raise SonarRasterError(
                f"ping {k} has the position ({self.x[k]:.6g}, {self.y[k]:.6g}), not a place on "
                f"Earth in {self.units}; read the file with read_xtf, which rejects such fixes"
            )
        if self.units == "degrees":
            from rasterio.warp import transform

            e, n = transform("EPSG:4326", self.crs, east.tolist(), north.tolist())
            east, north = np.asarray(e), np.asarray(n)
        clock = (
            self.time if np.all(np.diff(self.time) > 0) else np.arange(len(self.time), dtype=float)
        )
        return np.interp(clock, clock[fresh], east), np.interp(clock, clock[fresh], north)

    def filled_heading(self) -> np.ndarray:
        """Headings (radians), interpolated where a ping lacks navigation or a heading.

        0 where no ping has both.
        """
        ok = self.valid & np.isfinite(self.heading)
        if not ok.any():
            return np.nan_to_num(self.heading, nan=0.0)
        idx = np.flatnonzero(ok)
        unwrapped = np.unwrap(self.heading[ok])
        return np.mod(np.interp(np.arange(len(ok)), idx, unwrapped), 2 * math.pi)

    def filled(self, name: str) -> np.ndarray:
        """``roll``, ``pitch``, ``depth`` or ``altitude``, with gaps interpolated from neighbours.

        A gap is NaN or a ping without navigation (a blank record's zeros are no attitude or
        depth). Pings without navigation keep their own values when no ping has both; 0 where
        no ping has a value.
        """
        values = getattr(self, name)
        ok = np.isfinite(values) & self.valid
        if not ok.any():
            ok = np.isfinite(values)
        if not ok.any():
            return np.zeros_like(values)
        return np.interp(np.arange(len(values)), np.flatnonzero(ok), values[ok])

    def to_trajectory(self, origin: tuple[float, float] = (0.0, 0.0)) -> Trajectory:
        """The track as a :class:`Trajectory` in metres, x east, y north, z = -depth.

        Positions are :meth:`projected` minus ``origin`` (metres in the projected CRS); pings
        without navigation take interpolated positions, depths and headings.
        """
        east, north = self.projected()
        pos = np.stack([east - origin[0], north - origin[1], -self.filled("depth")], axis=1)
        return Trajectory(pos, self.filled_heading(), self.filled("roll"), self.filled("pitch"))

    def along_track_spacing(self) -> float:
        """Mean distance between pings, metres (NaN with fewer than two fixes).

        The path through the :meth:`fresh` fixes over the number of pings it spans.
        """
        idx = np.flatnonzero(self.fresh())
        if len(idx) < 2:
            return math.nan
        east, north = self.projected()
        path = float(np.sum(np.hypot(np.diff(east[idx]), np.diff(north[idx]))))
        return path / float(idx[-1] - idx[0])


def _read_to_next_fix(reader: XtfReader, rows: list[XtfPing]) -> None:
    """Read on past the last ping kept to the first navigation fix after it.

    Only where the file has navigation packets: the pings between the last fix and the range's
    end are then interpolated towards it, as when the whole file is read.
    """
    times = [p.time for p in rows if math.isfinite(p.time)]
    if not reader.fixes or not times:
        return
    last = max(times)
    for _ in reader.packets():
        if reader.fixes[-1][0] > last:
            return


def _ping_slice(pings: Any) -> slice:
    """``pings`` of :func:`read_xtf` as a slice.

    A slice, a ``range`` of step 1, a ``(start, stop)`` pair, or None (every ping).
    """
    if pings is None:
        return slice(None)
    if isinstance(pings, slice):
        return pings
    if isinstance(pings, range) and pings.step == 1:
        return slice(pings.start, pings.stop)
    if (
        isinstance(pings, tuple)
        and len(pings) == 2
        and all(v is None or isinstance(v, (int, np.integer)) for v in pings)
    ):
        return slice(*pings)
    raise SonarRasterError(
        f"pings must be a slice of ping indices, e.g. slice(0, 100) or (0, 100), got {pings!r}"
    )


def read_xtf(
    path: str | os.PathLike, pings: slice | None = None, frequency: float | str | None = None
) -> tuple[SonarImage, XtfNavigation]:
    """Read the side-scan pings of an XTF file into an image and its navigation.

    Parameters
    ----------
    path : str or PathLike
        The ``.xtf`` file.
    pings : slice, optional
        Which pings to keep (a slice, a ``(start, stop)`` pair or a ``range``; by index among
        the side-scan pings, skipped ones included), e.g.
        ``slice(100, 200)``.
    frequency : float or {"low", "high"}, optional
        A dual-frequency file's channels to read (as :class:`XtfReader`): Hz, or "low" /
        "high"; default the first port and starboard pair.

    Returns
    -------
    image : SonarImage
        ``sides`` "port" and/or "starboard", float32, shape (pings, samples), columns from
        range 0 outward; ``sonar`` with the file's frequency, sample spacing, slant range,
        sound speed (the median of the pings') and tilt (the :class:`Sonar` defaults where the
        file gives 0, and a uniform beam); ``metadata`` with the file's names, the per-ping
        ping numbers and indices, and what was skipped or repaired ("skipped_pings",
        "rejected_fixes": lists of {"index", "reason"}).
    navigation : XtfNavigation
        One row per ping of the image; fixes and headings the filter rejected are NaN.

    Raises
    ------
    SonarRasterError
        For a file that is missing, empty, not XTF, damaged from its first packet on, has no
        usable side-scan ping in the range, or whose sample spacing or sample count changes
        between pings for longer than a glitch (:data:`GLITCH_RUN`).

    Notes
    -----
    What was skipped or interpolated is logged as one warning line (logger ``sonar_raster.io
    .xtf``).
    """
    keep = _ping_slice(pings)
    forward = all(v is None or v >= 0 for v in (keep.start, keep.stop))
    rows: list[XtfPing] = []
    with XtfReader(path, frequency) as reader:
        for ping in reader:
            if forward and keep.stop is not None and ping.index >= keep.stop:
                _read_to_next_fix(reader, rows)
                break
            rows.append(ping)
        chosen = range(*keep.indices(reader.count))
        skipped = [s for s in reader.skipped if s.index in chosen]
        channels, units, freq = reader.channels, reader.units, reader.frequency_hz
        fixes = reader.fixes
        header, tilt = reader.header, reader.tilt_deg
    rows = [p for p in rows if p.index in chosen]
    if not rows:
        why = f": {skip_summary(skipped)}" if skipped else ""
        raise SonarRasterError(
            f"{path}: the ping range {keep.start}:{keep.stop} has no usable ping{why}"
        )
    rows, glitches = _drop_glitches(rows, Path(path))
    skipped = sorted(skipped + glitches, key=lambda s: s.index)
    first = rows[0]
    sides = {s: np.stack([p.sides[s] for p in rows]) for s in first.sides}
    bins = next(iter(sides.values())).shape[1]
    sonar = Sonar(
        frequency_hz=freq if freq > 0 else Sonar.frequency_hz,
        max_range=bins * first.range_bin,
        range_bin=first.range_bin,
        tilt=math.radians(tilt) if tilt > 0 else Sonar.tilt,
        sides=tuple(sides),
        sound_speed=float(np.median([p.sound_speed for p in rows])),
    )
    nav = _navigation(rows, units, Path(path), fixes)
    rejected = {rows[k].index: why for k, why in nav.rejected.items()}
    blanked = (sum(p.blanked for p in rows), sum(p.blanked > 0 for p in rows))
    if skipped or rejected or blanked[0]:
        log.warning("%s: %s", path, skip_summary(skipped, len(chosen), rejected, blanked))
    meta = {
        "source": str(path),
        "format": "xtf",
        "sonar_name": header.SonarName.decode("ascii", "replace"),
        "recording_program": header.RecordingProgramName.decode("ascii", "replace"),
        "channels": {s: int(k) for s, k in channels.items()},
        "ping_numbers": [p.number for p in rows],
        "ping_indices": [p.index for p in rows],
        "first_ping_index": first.index,
        "skipped_pings": [{"index": s.index, "reason": f"{s.kind}: {s.detail}"} for s in skipped],
        "rejected_fixes": [{"index": k, "reason": why} for k, why in sorted(rejected.items())],
        "blanked_samples": blanked[0],
    }
    return SonarImage(sides, sonar, meta), nav


def read_xtf_track(
    path: str | os.PathLike, pings: slice | None = None, frequency: float | str | None = None
) -> tuple[Trajectory, np.ndarray, SonarImage]:
    """The track of an XTF recording in local metres, its recorded altitude, and its image.

    Parameters
    ----------
    path : str or PathLike
        The ``.xtf`` file; it must have navigation.
    pings : slice, optional
        Which pings to keep, as in :func:`read_xtf`.
    frequency : float or {"low", "high"}, optional
        A dual-frequency file's channels, as in :func:`read_xtf`.

    Returns
    -------
    trajectory : Trajectory
        x east, y north in metres from the first ping (UTM for files in degrees), z = minus
        the sensor depth; headings, roll and pitch from the file, interpolated where missing
        (:meth:`XtfNavigation.to_trajectory`). Positions that jump off the track are
        interpolated from their neighbours.
    altitude : ndarray, shape (pings,), float64
        The file's altitude above the seabed per ping, metres; NaN where it has none.
    image : SonarImage
        The recording (:func:`read_xtf`), e.g. to bottom-track the pings without altitude.

    Raises
    ------
    SonarRasterError
        As :func:`read_xtf`, or if no ping has a position.
    """
    image, nav = read_xtf(path, pings, frequency)
    if not nav.valid.any():
        raise SonarRasterError(f"{path}: no ping has a position; the file has no track to reuse")
    east, north = nav.projected()
    jumps = track_jumps(east, north, nav.time)
    if jumps.any() and not jumps.all():
        k, good = np.arange(len(east)), np.flatnonzero(~jumps)
        east, north = np.interp(k, good, east[good]), np.interp(k, good, north[good])
    traj = nav.to_trajectory()
    positions = traj.positions.copy()
    positions[:, 0], positions[:, 1] = east - east[0], north - north[0]
    track = Trajectory(positions, traj.headings, traj.roll, traj.pitch)
    return track, np.asarray(nav.altitude, dtype=np.float64), image


def _layout(ping: XtfPing) -> tuple[tuple[tuple[str, int], ...], str]:
    return tuple((s, len(v)) for s, v in ping.sides.items()), f"{ping.range_bin:.4e}"


def _drop_glitches(rows: list[XtfPing], path: Path) -> tuple[list[XtfPing], list[SkippedPing]]:
    """Rows with the usual layout, and the few isolated others as skipped pings.

    Raises when the layout changes for longer than a glitch: the sonar's setting changed.
    """
    keys = [_layout(p) for p in rows]
    usual = Counter(keys).most_common(1)[0][0]
    odd = np.array([k != usual for k in keys])
    if not odd.any():
        return rows, []
    ref = rows[int(np.argmin(odd))]
    edges = np.diff(np.concatenate([[0], odd.astype(np.int8), [0]]))
    longest = int(np.max(np.flatnonzero(edges < 0) - np.flatnonzero(edges > 0)))
    if longest > GLITCH_RUN or odd.sum() > max(GLITCH_RUN, len(rows) // 10):
        raise SonarRasterError(_setting_change(rows, keys, path))
    skipped = []
    for p, bad in zip(rows, odd, strict=True):
        if bad:
            mine = ", ".join(f"{s} {len(v)}" for s, v in p.sides.items())
            usual_sides = ", ".join(f"{s} {n}" for s, n in usual[0])
            detail = (
                f"samples {mine} where the others have {usual_sides}"
                if _layout(p)[0] != usual[0]
                else f"sample spacing {p.range_bin:.5g} m where the others have "
                f"{ref.range_bin:.5g} m"
            )
            skipped.append(SkippedPing(p.index, "layout", detail))
    return [p for p, bad in zip(rows, odd, strict=True) if not bad], skipped


def _setting_change(rows: list[XtfPing], keys: list[Any], path: Path) -> str:
    """One line naming where the sonar's setting first changes and the runs of one setting."""
    runs: list[tuple[int, int]] = []  # [start, stop) in rows; glitches of a few pings merge
    start = 0
    for k in range(1, len(rows) + 1):
        if k == len(rows) or keys[k] != keys[start]:
            if runs and k - start <= GLITCH_RUN:
                runs[-1] = (runs[-1][0], k)
            else:
                runs.append((start, k))
            start = k
    # where the second run starts (a glitch before it is not the change), else the first change
    if len(runs) > 1:
        a, b = rows[runs[1][0] - 1], rows[runs[1][0]]
        a = a if keys[runs[1][0] - 1] == keys[runs[0][0]] else rows[runs[0][0]]
    else:
        change = next(k for k in range(1, len(rows)) if keys[k] != keys[k - 1])
        a, b = rows[change - 1], rows[change]
    if _layout(a)[0] != _layout(b)[0]:
        was = ", ".join(f"{s} {len(v)}" for s, v in a.sides.items())
        now = ", ".join(f"{s} {len(v)}" for s, v in b.sides.items())
        what = f"the sides or sample counts change at ping {b.index} ({was} to {now} samples)"
    else:
        what = (
            f"the sample spacing changes at ping {b.index} "
            f"({a.range_bin:.5g} to {b.range_bin:.5g} m)"
        )
    shown = [f"{rows[i].index}:{rows[j - 1].index + 1}" for i, j in runs[:4]]
    if len(runs) < 2:  # it changes back and forth: no long run of either
        changes = sum(keys[k] != keys[k - 1] for k in range(1, len(rows)))
        return f"{path}: {what}, and {changes} times in all; the file cannot be read as one image"
    more = ", ..." if len(runs) > 4 else ""
    return (
        f"{path}: {what}; read one setting at a time, e.g. --pings {' or --pings '.join(shown[:2])}"
        f" (runs of one setting: {', '.join(shown)}{more}; Python: pings=slice(a, b))"
    )


def _navigation(
    rows: list[XtfPing], units: str, path: Path, fixes: Sequence[tuple[float, float, float]] = ()
) -> XtfNavigation:
    def col(name: str) -> np.ndarray:
        return np.array([getattr(p, name) for p in rows], dtype=np.float64)

    x, y, heading, time = col("x"), col("y"), col("heading"), col("time")
    _fill_from_fixes(x, y, time, fixes, path)
    units = _fix_units(x, y, time, units, path)
    rejected = _filter_navigation(x, y, heading, time, units)
    return XtfNavigation(
        time=time,
        x=x,
        y=y,
        units=units,
        heading=heading,
        roll=col("roll"),
        pitch=col("pitch"),
        altitude=col("altitude"),
        depth=col("depth"),
        valid=np.isfinite(x) & np.isfinite(y),
        rejected=rejected,
    )


def _fill_from_fixes(
    x: np.ndarray,
    y: np.ndarray,
    time: np.ndarray,
    fixes: Sequence[tuple[float, float, float]],
    path: Path,
) -> None:
    """Give pings without a position one from the navigation packets, in place.

    Linear in time between the two fixes around the ping, when they are at most
    :data:`MAX_FIX_GAP` s apart; a ping before the first fix or after the last keeps none.
    """
    missing = ~(np.isfinite(x) & np.isfinite(y))
    if not fixes or not missing.any():
        return
    t, fx, fy = (np.asarray(v, dtype=np.float64) for v in zip(*fixes, strict=True))
    order = np.argsort(t, kind="stable")
    t, fx, fy = t[order], fx[order], fy[order]
    keep = np.concatenate([[True], np.diff(t) > 0])  # one fix per time
    t, fx, fy = t[keep], fx[keep], fy[keep]
    after = np.searchsorted(t, time, side="right")  # the first fix later than the ping
    inside = (after > 0) & (after < len(t))
    earlier, later = t[np.clip(after - 1, 0, len(t) - 1)], t[np.clip(after, 0, len(t) - 1)]
    at = np.minimum(np.abs(time - earlier), np.abs(time - later)) < 1e-3  # at a fix, ends too
    usable = missing & ((inside & (later - earlier <= MAX_FIX_GAP)) | at)
    if not usable.any():
        return
    x[usable] = np.interp(time[usable], t, fx)
    y[usable] = np.interp(time[usable], t, fy)
    log.info(
        "%s: positions of %d of %d pings from its %d navigation packets (type 42)",
        path.name, int(usable.sum()), len(x), len(t),
    )  # fmt: skip


#: Slowest mean speed of a moving vehicle, m/s: a track in metres slower than this whose numbers
#: are longitudes and latitudes that move at a vehicle's speed is in degrees.
_STILL_SPEED = 0.05
#: Fastest mean speed a survey vehicle has, m/s.
_FAST_SPEED = 30.0


def _fix_units(x: np.ndarray, y: np.ndarray, time: np.ndarray, units: str, path: Path) -> str:
    """The units the fixes are in: the header's ``NavUnits``, unless the fixes contradict it.

    Fixes marked as degrees of which none is a place on Earth in degrees (beyond ±180°, ±90°)
    and all are in metres are projected metres; fixes marked as metres that all lie within
    ±180, ±90, hardly move as metres (mean speed below :data:`_STILL_SPEED`) and move at a
    vehicle's speed as degrees are longitudes and latitudes. Either way a warning says so.
    """
    has = np.isfinite(x) & np.isfinite(y)
    if has.sum() < 3:
        return units
    other = "metres" if units == "degrees" else "degrees"
    if units == "degrees":
        wrong = bool(np.all(_out_of_range(x[has], y[has], units)))
        wrong &= not np.any(_out_of_range(x[has], y[has], other))
    else:
        wrong = not np.any(_out_of_range(x[has], y[has], other))
        speed = [_track_speed(x[has], y[has], time[has], u) for u in (units, other)]
        wrong = wrong and speed[0] < _STILL_SPEED <= speed[1] <= _FAST_SPEED
    if not wrong:
        return units
    log.warning(
        "%s: the header marks positions as %s but they are %s (x %.6g to %.6g, y %.6g to %.6g): "
        "read as %s",
        path, units,
        "no place on Earth in degrees" if units == "degrees" else "longitudes and latitudes "
        "that stand still in metres", np.min(x[has]), np.max(x[has]), np.min(y[has]),
        np.max(y[has]), other,
    )  # fmt: skip
    return other


def _track_speed(x: np.ndarray, y: np.ndarray, time: np.ndarray, units: str) -> float:
    """Path length over time span of fixes in time order, m/s; NaN without a time span.

    A fix repeated between navigation updates adds nothing to the path.
    """
    order = np.argsort(time, kind="stable")
    east, north = _local_metres(x[order], y[order], units)
    span = float(time[order][-1] - time[order][0])
    if not span > 0:
        return math.nan
    return float(np.sum(np.hypot(np.diff(east), np.diff(north)))) / span


def _out_of_range(x: np.ndarray, y: np.ndarray, units: str) -> np.ndarray:
    """Positions that are no place on Earth: beyond ±180°, ±90° or ±1e8 m."""
    lx, ly = (180.0, 90.0) if units == "degrees" else (1e8, 1e8)
    with np.errstate(invalid="ignore"):
        return ~((np.abs(x) <= lx) & (np.abs(y) <= ly))


def _filter_navigation(
    x: np.ndarray, y: np.ndarray, heading: np.ndarray, time: np.ndarray, units: str
) -> dict[int, str]:
    """Reject impossible fixes, jumps and heading spikes in place (set NaN); row -> reason.

    A fix is a jump when it lies further from the running median of the fixes within
    :data:`NAV_WINDOW` rows each side than the vehicle can travel at :data:`MAX_SPEED` in the
    window's time span, plus :data:`FIX_NOISE`; a heading is a spike when the median of its
    differences to its neighbours exceeds :data:`MAX_TURN_RATE` times the span plus
    :data:`HEADING_NOISE`. An outlier run longer than the window is not caught.
    """
    reasons = _repair_clock(time)
    has = np.isfinite(x) & np.isfinite(y)
    for k in np.flatnonzero(has & _out_of_range(x, y, units)):
        reasons[int(k)] = f"position ({x[k]:.6g}, {y[k]:.6g}) is not on Earth"
    idx = np.flatnonzero(has & ~_out_of_range(x, y, units))
    clock = _clock(time)
    if len(idx) >= 3:
        east, north = _local_metres(x[idx], y[idx], units)
        off = _off_track(east, north, clock[idx])
        for k in np.flatnonzero(off > 0):
            reasons[int(idx[k])] = f"fix {off[k]:.0f} m off the track"
    x[list(reasons)] = y[list(reasons)] = np.nan
    idx = np.flatnonzero(np.isfinite(heading))
    if len(idx) >= 3:
        deg = np.degrees(heading[idx])
        windows = _windows(deg)
        with np.errstate(invalid="ignore"):
            turn = np.abs(np.nanmedian((windows - deg[:, None] + 180.0) % 360.0 - 180.0, axis=1))
        spike = turn > MAX_TURN_RATE * _window_span(clock[idx]) + HEADING_NOISE
        for k in np.flatnonzero(spike):
            why = f"heading {deg[k]:.0f} deg, {turn[k]:.0f} deg off its neighbours"
            reasons.setdefault(int(idx[k]), why)
        heading[idx[spike]] = np.nan
    return dict(sorted(reasons.items()))


def _off_track(east: np.ndarray, north: np.ndarray, clock: np.ndarray) -> np.ndarray:
    """Distance (m) of each jump from the running median track, 0 for the fixes that fit."""
    span = _window_span(clock)
    off = np.hypot(east - _running_median(east), north - _running_median(north))
    return np.where(off > MAX_SPEED * span + FIX_NOISE, off, 0.0)


def track_jumps(east: np.ndarray, north: np.ndarray, time: np.ndarray) -> np.ndarray:
    """Positions that jump off the track, by the speed limit :func:`read_xtf` applies.

    Parameters
    ----------
    east, north : ndarray, shape (pings,)
        Positions in metres (finite).
    time : ndarray, shape (pings,)
        Seconds (ping index × the median interval is used when they go back).

    Returns
    -------
    ndarray of bool, shape (pings,)
        True where a position lies further from the running median of its neighbours than
        :data:`MAX_SPEED` allows in the time between them, plus :data:`FIX_NOISE`.
    """
    if len(east) < 3:
        return np.zeros(len(east), dtype=bool)
    return _off_track(np.asarray(east, float), np.asarray(north, float), _clock(time)) > 0


def _repair_clock(time: np.ndarray) -> dict[int, str]:
    """Interpolate (in place) the few times out of order, e.g. a clock reset; row -> reason.

    The times kept are the longest non-decreasing run through the pings; when more than
    :data:`GLITCH_RUN` pings or a tenth of them fall outside it, the clock is left as is.
    """
    if len(time) < 3 or np.all(np.diff(time) >= 0):
        return {}
    tails: list[float] = []  # patience sort: smallest tail of a run of each length
    tail_at: list[int] = []
    before = np.full(len(time), -1)
    for i, t in enumerate(time.tolist()):
        k = bisect.bisect_right(tails, t)
        before[i] = tail_at[k - 1] if k else -1
        if k == len(tails):
            tails.append(t)
            tail_at.append(i)
        else:
            tails[k], tail_at[k] = t, i
    keep = np.zeros(len(time), dtype=bool)
    i = tail_at[-1]
    while i >= 0:
        keep[i], i = True, int(before[i])
    bad = np.flatnonzero(~keep)
    if len(bad) > max(GLITCH_RUN, len(time) // 10):
        return {}
    shown = {int(k): np.datetime64(int(round(time[k] * 1000)), "ms") for k in bad}
    time[bad] = np.interp(bad, np.flatnonzero(keep), time[keep])
    return {k: f"time {t} out of order" for k, t in shown.items()}


def _clock(time: np.ndarray) -> np.ndarray:
    """Seconds for the filter: the times when they never go back, else ping index × interval."""
    step = np.diff(time)
    if np.all(step >= 0):
        return time - time[0]
    forward = step[step > 0]
    return np.arange(len(time)) * (float(np.median(forward)) if len(forward) else 1.0)


def _local_metres(x: np.ndarray, y: np.ndarray, units: str) -> tuple[np.ndarray, np.ndarray]:
    """Positions in metres about their median (equirectangular for degrees)."""
    x0, y0 = float(np.median(x)), float(np.median(y))
    if units != "degrees":
        return x - x0, y - y0
    east = ((x - x0 + 180.0) % 360.0 - 180.0) * 111_320.0 * math.cos(math.radians(y0))
    return east, (y - y0) * 110_574.0


def _windows(values: np.ndarray) -> np.ndarray:
    """(n, 2 NAV_WINDOW + 1) neighbourhoods of each value, NaN beyond the ends."""
    padded = np.concatenate([np.full(NAV_WINDOW, np.nan), values, np.full(NAV_WINDOW, np.nan)])
    return np.lib.stride_tricks.sliding_window_view(padded, 2 * NAV_WINDOW + 1)


def _running_median(values: np.ndarray) -> np.ndarray:
    return np.nanmedian(_windows(values), axis=1)


def _window_span(clock: np.ndarray) -> np.ndarray:
    """Seconds from each row to the furthest row of its window."""
    return np.nanmax(np.abs(_windows(clock) - clock[:, None]), axis=1)


def write_xtf(
    path: str | os.PathLike,
    image: SonarImage | Sequence[SonarImage],
    trajectory: Trajectory,
    *,
    altitude: float | np.ndarray | None = None,
    origin: tuple[float, float] = (0.0, 0.0),
    start_time: float = 946684800.0,
    ping_interval: float | None = None,
    sample_format: str = "float32",
) -> Path:
    """Write a sonar image and its track as an XTF file (pyxtf's structures).

    Parameters
    ----------
    path : str or PathLike
        Output ``.xtf``; written to a temporary name and renamed into place.
    image : SonarImage or sequence of SonarImage
        Pings × range bins per side, linear intensity >= 0. Several images (the same pings,
        e.g. the two frequencies of a dual-frequency side-scan) are written as one file, their
        channels in order, each with its own frequency, range and sample count.
    trajectory : Trajectory
        One pose per ping: positions in metres (x east, y north, z up), compass heading, roll.
    altitude : float or ndarray of shape (pings,), optional
        Altitude above the seabed per ping, metres, stored in ``SensorPrimaryAltitude``
        (default: 0, "not known").
    origin : (float, float)
        Easting, northing added to x, y: coordinates are written as projected metres
        (``NavUnits`` 0), e.g. UTM with the track's origin in that zone.
    start_time : float
        Time of the first ping, seconds since 1970 UTC (default 2000-01-01).
    ping_interval : float, optional
        Seconds between pings (default: the two-way travel time of the maximum range). XTF
        ping times have 10 ms resolution.
    sample_format : {"float32", "uint16"}
        "float32" (XTF sample format 5) stores the intensities exactly. "uint16" (format 3)
        stores ``round(I · 2**N)`` with ``Weight`` = N per channel and ping, N the largest
        integer keeping the ping's maximum below 65536, so the absolute error is at most
        ``2**-(N+1)``, below ``max / 65535`` of the ping.

    Returns
    -------
    Path
        The file written.

    Notes
    -----
    ``SoundVelocity`` is written as half the sound speed (the Triton habit that readers
    expect); ``SensorDepth`` as ``-z``, so the world z = 0 plane is the datum.
    """
    if sample_format not in _SAMPLE_FORMATS:
        raise SonarRasterError(f"sample_format must be float32 or uint16, got {sample_format!r}")
    bands = _bands(image)
    pings = bands[0].shape[0]
    if trajectory.n_pings != pings:
        raise SonarRasterError(
            f"the trajectory has {trajectory.n_pings} poses for {pings} pings; give one per ping"
        )
    for band in bands:
        for side, values in band.sides.items():
            if not (np.all(np.isfinite(values)) and np.all(values >= 0)):
                raise SonarRasterError(f"the {side} side has negative or non-finite intensities")
    given = np.asarray(0.0 if altitude is None else altitude, float)
    if given.size not in (1, pings) or not (np.all(np.isfinite(given)) and np.all(given >= 0)):
        raise SonarRasterError(
            f"altitude must be one finite value >= 0 or one per ping ({pings}), got "
            f"{given.size} value(s)" + ("" if np.all(np.isfinite(given)) else " with NaN or inf")
        )
    alt = np.broadcast_to(given.reshape(-1) if given.size > 1 else given, (pings,))
    if ping_interval is not None:
        positive("ping_interval (seconds)", ping_interval)
    non_negative("start_time (seconds since 1970)", start_time)
    try:
        pair = [float(v) for v in origin]
    except (TypeError, ValueError):
        pair = []
    if len(pair) != 2 or not all(math.isfinite(v) for v in pair):
        raise SonarRasterError(f"origin must be two finite numbers (x, y), got {origin!r}")
    interval = ping_interval or _listen_time(bands)
    from .commit import commit

    final = Path(path)
    if final.suffix.lower() != ".xtf":
        raise SonarRasterError(f"cannot write {final} as XTF: name it .xtf")
    if not final.parent.is_dir():
        raise SonarRasterError(f"cannot write {final}: directory {final.parent} does not exist")

    def writer(tmp: Path) -> None:
        with open(tmp, "xb") as fh:
            XtfWriter(fh, sample_format, origin, start_time, interval).write(bands, trajectory, alt)

    commit([(final, writer)])
    return final


class XtfWriter:
    """Append blocks of pings to an open XTF file: the file header, then one packet per ping.

    Used by :func:`write_xtf` (one block) and by long surveys streamed block by block
    (:func:`~sonar_raster.render_survey`). Ping numbers and times run on across blocks.
    """

    def __init__(
        self,
        fh: Any,
        sample_format: str = "float32",
        origin: tuple[float, float] = (0.0, 0.0),
        start_time: float = 946684800.0,
        interval: float | None = None,
    ) -> None:
        if sample_format not in _SAMPLE_FORMATS:
            raise SonarRasterError(
                f"sample_format must be float32 or uint16, got {sample_format!r}"
            )
        self.fh, self.sample_format, self.origin = fh, sample_format, origin
        self.start_time, self.interval = start_time, interval
        self.pings = 0

    def write(
        self,
        image: SonarImage | Sequence[SonarImage],
        trajectory: Trajectory,
        altitude: np.ndarray,
    ) -> None:
        """Append ``image``'s pings with their poses (``trajectory``) and altitudes (metres).

        Several images (the same pings at several frequencies) are written as one ping's
        channels, in order.
        """
        bands = _bands(image)
        if self.pings == 0:
            self.fh.write(_file_header(bands, self.sample_format).to_bytes())
        interval = self.interval or _listen_time(bands)
        for i in range(bands[0].shape[0]):
            n = self.pings + i
            packet = _ping_packet(
                bands, trajectory, i, float(altitude[i]), self.origin,
                self.start_time + n * interval, interval, self.sample_format,
            )  # fmt: skip
            packet.PingNumber = n
            self.fh.write(packet.to_bytes())
        self.pings += bands[0].shape[0]


def _bands(image: SonarImage | Sequence[SonarImage]) -> list[SonarImage]:
    """The images of one file (one per frequency), checked to share their pings."""
    bands = [image] if isinstance(image, SonarImage) else list(image)
    if not bands:
        raise SonarRasterError("no image to write")
    if len({b.shape[0] for b in bands}) > 1:
        counts = ", ".join(str(b.shape[0]) for b in bands)
        raise SonarRasterError(f"the images to write in one file have {counts} pings; give equal")
    if sum(len(b.sides) for b in bands) > 6:
        raise SonarRasterError("an XTF file header describes at most 6 channels")
    return bands


def _listen_time(bands: Sequence[SonarImage]) -> float:
    """Two-way travel time of the longest range among the images, seconds."""
    return max(2.0 * b.shape[1] * b.sonar.range_bin / b.sonar.sound_speed for b in bands)


def _file_header(bands: Sequence[SonarImage], sample_format: str) -> Any:
    pyxtf = _pyxtf()
    code, nbytes, _ = _SAMPLE_FORMATS[sample_format]
    header = pyxtf.XTFFileHeader()
    header.RecordingProgramName = b"sonar_ra"
    header.RecordingProgramVersion = b"1"
    header.SonarName = b"sonar_raster"
    header.NoteString = b"simulated by sonar_raster; positions in metres, x east, y north"
    header.NavUnits = 0
    channels = [(band.sonar, side) for band in bands for side in band.sides]
    header.NumberOfSonarChannels = len(channels)
    for k, (sonar, side) in enumerate(channels):
        info = header.ChanInfo[k]
        info.TypeOfChannel = _PORT if side == "port" else _STARBOARD
        info.SubChannelNumber = k
        info.CorrectionFlags = 1  # slant range
        info.UniPolar = 1
        info.BytesPerSample = nbytes
        info.SampleFormat = code
        info.ChannelName = side.upper().encode()
        info.Frequency = sonar.frequency_hz / 1e3
        info.TiltAngle = math.degrees(sonar.tilt)
        info.BeamsPerArray = 1
    return header


def _ping_packet(
    bands: Sequence[SonarImage],
    track: Trajectory,
    i: int,
    altitude: float,
    origin: tuple[float, float],
    time: float,
    interval: float,
    sample_format: str,
) -> Any:
    pyxtf = _pyxtf()
    sonar = bands[0].sonar
    ping = pyxtf.XTFPingHeader()
    ping.MagicNumber = XTF_MAGIC
    _set_time(ping, time)
    ping.PingNumber = i
    ping.SoundVelocity = sonar.sound_speed / 2.0
    x, y, z = (float(v) for v in track.positions[i])
    ping.SensorXcoordinate = ping.ShipXcoordinate = x + origin[0]
    ping.SensorYcoordinate = ping.ShipYcoordinate = y + origin[1]
    ping.SensorHeading = ping.ShipGyro = math.degrees(float(track.headings[i])) % 360.0
    ping.SensorRoll = math.degrees(float(track.roll[i]))
    ping.SensorPitch = math.degrees(float(track.pitch[i]))
    ping.SensorPrimaryAltitude = altitude
    ping.SensorDepth = -z
    chans, data = [], []
    channels = [(band.sonar, side, values) for band in bands for side, values in band.sides.items()]
    for k, (sonar, side, values) in enumerate(channels):
        samples, weight = _encode(values[i], sample_format)
        chan = pyxtf.XTFPingChanHeader()
        chan.ChannelNumber = k
        chan.SlantRange = len(samples) * sonar.range_bin
        chan.TimeDuration = 2.0 * chan.SlantRange / sonar.sound_speed
        chan.SecondsPerPing = interval
        chan.Frequency = int(round(sonar.frequency_hz / 1e3))
        chan.NumSamples = len(samples)
        chan.Weight = weight
        chans.append(chan)
        data.append(samples[::-1].copy() if side == "port" else samples)
    ping.ping_chan_headers, ping.data = chans, data
    ping.NumChansToFollow = len(chans)
    ping.NumBytesThisRecord = ctypes.sizeof(ping) + sum(
        ctypes.sizeof(c) + d.nbytes for c, d in zip(chans, data, strict=True)
    )
    return ping


def _set_time(ping: Any, time: float) -> None:
    stamp = np.datetime64(int(round(time * 100)) * 10, "ms").astype(object)
    ping.Year, ping.Month, ping.Day = stamp.year, stamp.month, stamp.day
    ping.Hour, ping.Minute, ping.Second = stamp.hour, stamp.minute, stamp.second
    ping.HSeconds = stamp.microsecond // 10000
    ping.JulianDay = stamp.timetuple().tm_yday


def _encode(values: np.ndarray, sample_format: str) -> tuple[np.ndarray, int]:
    """Samples in the file's type and the ``Weight`` N with ``value = sample * 2**-N``."""
    if sample_format == "float32":
        return np.ascontiguousarray(values, dtype=np.float32), 0
    top = float(np.max(values)) if values.size else 0.0
    weight = 0 if top <= 0 else int(math.floor(math.log2(65535.0 / top)))
    weight = max(-32768, min(32767, weight))
    codes = np.rint(values.astype(np.float64) * 2.0**weight)
    return np.clip(codes, 0, 65535).astype(np.uint16), weight
