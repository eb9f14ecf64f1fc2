"""XTF side-scan files in and out, through pyxtf's structures.

Reading streams the file packet by packet (:class:`XtfReader`, one :class:`XtfPing` at a time);
:func:`read_xtf` gathers the pings into a :class:`SonarImage` and an :class:`XtfNavigation`.
:func:`write_xtf` writes a :class:`SonarImage` and its :class:`Trajectory` as an XTF file.

Conventions (checked on the OpenSidescan sample and by the round-trip tests):

- The side of a channel is ``TypeOfChannel`` of its ``ChanInfo`` entry (1 port, 2 starboard);
  the first port and the first starboard channel are read, other channels are skipped.
- Port samples are stored from far range to nadir, starboard samples from nadir outward (as
  pyxtf's ``concatenate_channel`` assumes); :class:`SonarImage` sides run from range 0 outward.
- Sample spacing is ``SlantRange / NumSamples`` (or ``TimeDuration · c / 2 / NumSamples`` when
  the slant range is 0); sample values are multiplied by ``2 ** -Weight`` (pyxtf's ``weighted``).
- ``SoundVelocity`` holds half the sound speed in many files (750 m/s, the Triton habit): the
  field is doubled when twice it matches ``2 · SlantRange / TimeDuration`` better than the field
  itself, or, without timing, when it is below 1000 m/s. :func:`write_xtf` writes the half.
- Navigation is ``SensorXcoordinate`` / ``SensorYcoordinate``: longitude / latitude in degrees
  when the file header's ``NavUnits`` is 3, else projected metres (easting, northing). A ping
  whose coordinates are both 0 has no navigation. Heading is the compass heading in degrees;
  roll is positive starboard down; the altitude is ``SensorPrimaryAltitude`` (0 = not known);
  the sensor depth is ``SensorDepth`` (positive down), so the sensor's z is ``-depth``.
"""

from __future__ import annotations

import ctypes
import io
import math
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from ..errors import SonarRasterError
from ..image import SonarImage
from ..sonar import Sonar
from ..trajectory import Trajectory

__all__ = ["XtfNavigation", "XtfPing", "XtfReader", "iter_pings", "read_xtf", "write_xtf"]

#: ``FileFormat`` byte of every XTF file.
XTF_FILE_FORMAT = 0x7B
#: Every packet starts with this 16-bit word.
XTF_MAGIC = 0xFACE
_SONAR_PACKET = 0
_PORT, _STARBOARD = 1, 2
_NAV_DEGREES = 3
_FILE_HEADER_BYTES = 1024
_SAMPLE_FORMATS = {"float32": (5, 4, np.float32), "uint16": (3, 2, np.uint16)}


def _pyxtf() -> Any:
    try:
        import pyxtf
    except ImportError:  # pragma: no cover - a declared dependency
        raise SonarRasterError("XTF support needs pyxtf: pip install pyxtf") from None
    return pyxtf


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
        Compass heading, roll (starboard down) and pitch (nose up), radians.
    altitude : float
        Altitude above the seabed from the file, metres; NaN when the file has none (0).
    depth : float
        Sensor depth below the surface, metres.
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

    @property
    def has_navigation(self) -> bool:
        """True when the ping carries a position."""
        return math.isfinite(self.x) and math.isfinite(self.y)


class XtfReader:
    """Stream the side-scan pings of an XTF file, one at a time.

    Use as a context manager; iterating yields :class:`XtfPing` in file order. The file header
    is checked on opening and each packet as it is read, so a wrong, empty or truncated file
    raises :class:`SonarRasterError` naming the file and the byte offset.

    Parameters
    ----------
    path : str or PathLike
        The ``.xtf`` file.

    Attributes
    ----------
    header : pyxtf.XTFFileHeader
        The file header.
    channels : dict of str to int
        Side name to index in the file header's ``ChanInfo``.
    units : str
        "degrees" (longitude, latitude) or "metres" (easting, northing).
    frequency_hz : float
        Centre frequency of the first side-scan channel, Hz (0 when the file does not say).
    tilt_deg : float
        Depression of the first side-scan channel's beam axis, degrees (0 when not given).
    """

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        self._size = _file_size(self.path)
        self._fh: BinaryIO | None = open(self.path, "rb")  # noqa: SIM115 - closed by close()
        try:
            self.header = self._read_header()
        except BaseException:
            self.close()
            raise
        info = self.header.ChanInfo
        self.channels = _side_channels(self.header, self.path)
        self.units = "degrees" if self.header.NavUnits == _NAV_DEGREES else "metres"
        first = info[next(iter(self.channels.values()))]
        self.frequency_hz = float(first.Frequency) * 1e3
        self.tilt_deg = float(first.TiltAngle)

    def _read_header(self) -> Any:
        pyxtf = _pyxtf()
        assert self._fh is not None
        raw = self._fh.read(_FILE_HEADER_BYTES)
        header = pyxtf.XTFFileHeader.create_from_buffer(raw)
        if header.FileFormat != XTF_FILE_FORMAT:
            raise SonarRasterError(
                f"{self.path} is not an XTF file (format byte {header.FileFormat}, expected "
                f"{XTF_FILE_FORMAT})"
            )
        n = header.channel_count()
        if n > 6:  # each further 6 channels add 1024 bytes of ChanInfo
            self._fh.seek(_FILE_HEADER_BYTES * (1 + (n - 1) // 6))
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
        for offset, raw in self._packets():
            ping = self._ping(raw, offset, index)
            if ping is not None:
                yield ping
                index += 1
        if index == 0:
            raise SonarRasterError(f"{self.path} has no side-scan pings")

    def _packets(self) -> Iterator[tuple[int, bytes]]:
        """(offset, bytes) of each side-scan packet; others are skipped unread."""
        pyxtf = _pyxtf()
        fh = self._fh
        assert fh is not None
        start_size = ctypes.sizeof(pyxtf.XTFPacketStart)
        while True:
            offset = fh.tell()
            head = fh.read(start_size)
            if not head:
                return
            if len(head) < start_size:
                raise self._truncated(offset, start_size)
            start = pyxtf.XTFPacketStart.from_buffer_copy(head)
            if start.MagicNumber != XTF_MAGIC:
                raise SonarRasterError(
                    f"{self.path} is corrupt or not XTF: no packet marker (0xFACE) at byte {offset}"
                )
            size = int(start.NumBytesThisRecord)
            if size < start_size:
                raise SonarRasterError(f"{self.path} is corrupt: packet at byte {offset} is empty")
            if offset + size > self._size:
                raise self._truncated(offset, size)
            if start.HeaderType != _SONAR_PACKET:
                fh.seek(offset + size)
                continue
            yield offset, head + fh.read(size - start_size)

    def _truncated(self, offset: int, size: int) -> SonarRasterError:
        return SonarRasterError(
            f"{self.path} is truncated: the packet at byte {offset} needs {size} bytes, "
            f"{self._size - offset} are left"
        )

    def _ping(self, raw: bytes, offset: int, index: int) -> XtfPing | None:
        pyxtf = _pyxtf()
        try:
            ping = pyxtf.XTFPingHeader.create_from_buffer(io.BytesIO(raw), self.header)
        except (RuntimeError, ValueError, IndexError, KeyError) as exc:
            raise SonarRasterError(
                f"{self.path}: bad sonar packet at byte {offset}: {exc}"
            ) from None
        sides: dict[str, np.ndarray] = {}
        spacing: dict[str, float] = {}
        speed = 0.0
        for chan, data in zip(ping.ping_chan_headers, ping.data, strict=True):
            side = self._side_of(int(chan.ChannelNumber))
            if side is None or side in sides:
                continue
            if len(data) != chan.NumSamples and chan.NumSamples > 0:
                raise SonarRasterError(
                    f"{self.path}: ping at byte {offset} has {len(data)} of {chan.NumSamples} "
                    "samples (truncated or corrupt)"
                )
            speed = _sound_speed(float(ping.SoundVelocity), chan)
            values = np.asarray(data, dtype=np.float32) * np.float32(2.0 ** -int(chan.Weight))
            sides[side] = values[::-1].copy() if side == "port" else values
            spacing[side] = _sample_spacing(chan, len(data), speed)
        if not sides:
            return None
        bins = list(spacing.values())
        if min(bins) <= 0 or max(bins) > min(bins) * (1 + 1e-5):
            raise SonarRasterError(
                f"{self.path}: ping {index} has no usable sample spacing (slant range "
                "and recording time are 0, or the sides differ)"
            )
        return _make_ping(ping, index, sides, bins[0], speed)

    def _side_of(self, channel_number: int) -> str | None:
        for side, k in self.channels.items():
            if k == channel_number:
                return side
        return None


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


def _side_channels(header: Any, path: Path) -> dict[str, int]:
    """Side name to ChanInfo index: the first port and the first starboard channel."""
    out: dict[str, int] = {}
    n = min(int(header.NumberOfSonarChannels), 6)
    for k in range(n):
        kind = int(header.ChanInfo[k].TypeOfChannel)
        side = {_PORT: "port", _STARBOARD: "starboard"}.get(kind)
        if side and side not in out:
            out[side] = k
    if not out:
        raise SonarRasterError(f"{path} has no port or starboard side-scan channel")
    return dict(sorted(out.items()))


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


def _make_ping(
    ping: Any, index: int, sides: dict[str, np.ndarray], range_bin: float, speed: float
) -> XtfPing:
    x, y = float(ping.SensorXcoordinate), float(ping.SensorYcoordinate)
    if x == 0.0 and y == 0.0:
        x = y = math.nan
    time = (ping.get_time() - np.datetime64("1970-01-01T00:00:00")) / np.timedelta64(1, "us")
    altitude = float(ping.SensorPrimaryAltitude)
    return XtfPing(
        index=index,
        number=int(ping.PingNumber),
        time=float(time) * 1e-6,
        sides=sides,
        range_bin=range_bin,
        sound_speed=speed,
        x=x,
        y=y,
        heading=math.radians(float(ping.SensorHeading)),
        roll=math.radians(float(ping.SensorRoll)),
        pitch=math.radians(float(ping.SensorPitch)),
        altitude=altitude if altitude > 0 else math.nan,
        depth=float(ping.SensorDepth),
    )


def iter_pings(path: str | os.PathLike) -> Iterator[XtfPing]:
    """Yield the side-scan pings of an XTF file one at a time (see :class:`XtfReader`)."""
    with XtfReader(path) as reader:
        yield from reader


@dataclass(frozen=True)
class XtfNavigation:
    """Per-ping navigation and attitude of an XTF file; arrays of shape (pings,), float64.

    Attributes
    ----------
    time : ndarray
        Seconds since 1970-01-01 UTC.
    x, y : ndarray
        Longitude, latitude (degrees) or easting, northing (metres); NaN where ``valid`` is
        False.
    units : str
        "degrees" or "metres".
    heading, roll, pitch : ndarray
        Radians: compass heading, roll (starboard down), pitch (nose up).
    altitude : ndarray
        Altitude above the seabed from the file, metres; NaN where the file has none.
    depth : ndarray
        Sensor depth, metres, positive down.
    valid : ndarray, bool
        Pings with a position.
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
        if self.units == "degrees":
            from rasterio.warp import transform

            e, n = transform("EPSG:4326", self.crs, east.tolist(), north.tolist())
            east, north = np.asarray(e), np.asarray(n)
        clock = (
            self.time if np.all(np.diff(self.time) > 0) else np.arange(len(self.time), dtype=float)
        )
        return np.interp(clock, clock[fresh], east), np.interp(clock, clock[fresh], north)

    def filled_heading(self) -> np.ndarray:
        """Headings (radians) with pings lacking navigation interpolated from their neighbours."""
        if not self.valid.any():
            return self.heading.copy()
        idx = np.flatnonzero(self.valid)
        unwrapped = np.unwrap(self.heading[self.valid])
        return np.mod(np.interp(np.arange(len(self.valid)), idx, unwrapped), 2 * math.pi)

    def to_trajectory(self, origin: tuple[float, float] = (0.0, 0.0)) -> Trajectory:
        """The track as a :class:`Trajectory` in metres, x east, y north, z = -depth.

        Positions are :meth:`projected` minus ``origin`` (metres in the projected CRS); pings
        without navigation take interpolated positions, depths and headings.
        """
        east, north = self.projected()
        idx = np.flatnonzero(self.valid)
        depth = np.interp(np.arange(len(self.valid)), idx, self.depth[self.valid])
        pos = np.stack([east - origin[0], north - origin[1], -depth], axis=1)
        return Trajectory(pos, self.filled_heading(), self.roll, self.pitch)

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


def read_xtf(
    path: str | os.PathLike, pings: slice | None = None
) -> tuple[SonarImage, XtfNavigation]:
    """Read the side-scan pings of an XTF file into an image and its navigation.

    Parameters
    ----------
    path : str or PathLike
        The ``.xtf`` file.
    pings : slice, optional
        Which pings to keep (by index among the side-scan pings), e.g. ``slice(100, 200)``.

    Returns
    -------
    image : SonarImage
        ``sides`` "port" and/or "starboard", float32, shape (pings, samples), columns from
        range 0 outward; ``sonar`` with the file's frequency, sample spacing, slant range,
        sound speed and tilt (the :class:`Sonar` defaults where the file gives 0, and a
        uniform beam); ``metadata`` with the file's names and the per-ping ping numbers.
    navigation : XtfNavigation

    Raises
    ------
    SonarRasterError
        For a file that is missing, empty, not XTF, truncated, has no side-scan pings, or
        whose sample spacing or sample count changes between pings.
    """
    keep = pings or slice(None)
    rows: list[XtfPing] = []
    with XtfReader(path) as reader:
        for ping in reader:
            if keep.stop is not None and ping.index >= keep.stop:
                break
            rows.append(ping)
        channels, units, freq = reader.channels, reader.units, reader.frequency_hz
        header, tilt = reader.header, reader.tilt_deg
    rows = rows[keep]
    if not rows:
        raise SonarRasterError(f"{path}: the ping range {keep.start}:{keep.stop} is empty")
    _check_uniform(rows, Path(path))
    first = rows[0]
    sides = {s: np.stack([p.sides[s] for p in rows]) for s in first.sides}
    bins = next(iter(sides.values())).shape[1]
    sonar = Sonar(
        frequency_hz=freq if freq > 0 else Sonar.frequency_hz,
        max_range=bins * first.range_bin,
        range_bin=first.range_bin,
        tilt=math.radians(tilt) if tilt > 0 else Sonar.tilt,
        sides=tuple(sides),
        sound_speed=first.sound_speed,
    )
    meta = {
        "source": str(path),
        "format": "xtf",
        "sonar_name": header.SonarName.decode("ascii", "replace"),
        "recording_program": header.RecordingProgramName.decode("ascii", "replace"),
        "channels": {s: int(k) for s, k in channels.items()},
        "ping_numbers": [p.number for p in rows],
        "first_ping_index": first.index,
    }
    return SonarImage(sides, sonar, meta), _navigation(rows, units)


def _check_uniform(rows: list[XtfPing], path: Path) -> None:
    first = rows[0]
    for p in rows[1:]:
        shapes = {s: len(v) for s, v in p.sides.items()}
        if shapes != {s: len(v) for s, v in first.sides.items()}:
            raise SonarRasterError(
                f"{path}: ping {p.index} has other sides or sample counts than ping "
                f"{first.index}; read ping ranges with one setting (pings=slice(a, b))"
            )
        if not math.isclose(p.range_bin, first.range_bin, rel_tol=1e-5):
            raise SonarRasterError(
                f"{path}: the sample spacing changes at ping {p.index} ({first.range_bin:.5g} "
                f"to {p.range_bin:.5g} m); read ping ranges with one setting (pings=slice(a, b))"
            )


def _navigation(rows: list[XtfPing], units: str) -> XtfNavigation:
    def col(name: str) -> np.ndarray:
        return np.array([getattr(p, name) for p in rows], dtype=np.float64)

    x, y = col("x"), col("y")
    return XtfNavigation(
        time=col("time"),
        x=x,
        y=y,
        units=units,
        heading=col("heading"),
        roll=col("roll"),
        pitch=col("pitch"),
        altitude=col("altitude"),
        depth=col("depth"),
        valid=np.isfinite(x) & np.isfinite(y),
    )


def write_xtf(
    path: str | os.PathLike,
    image: SonarImage,
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
    image : SonarImage
        Pings × range bins per side, linear intensity >= 0.
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
    pings, bins = image.shape
    if trajectory.n_pings != pings:
        raise SonarRasterError(
            f"the trajectory has {trajectory.n_pings} poses for {pings} pings; give one per ping"
        )
    for side, values in image.sides.items():
        if not (np.all(np.isfinite(values)) and np.all(values >= 0)):
            raise SonarRasterError(f"the {side} side has negative or non-finite intensities")
    alt = np.broadcast_to(np.asarray(0.0 if altitude is None else altitude, float), (pings,))
    sonar = image.sonar
    interval = ping_interval or 2.0 * bins * sonar.range_bin / sonar.sound_speed
    from .commit import commit

    final = Path(path)
    if not final.parent.is_dir():
        raise SonarRasterError(f"cannot write {final}: directory {final.parent} does not exist")

    def writer(tmp: Path) -> None:
        with open(tmp, "xb") as fh:
            XtfWriter(fh, sample_format, origin, start_time, interval).write(image, trajectory, alt)

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

    def write(self, image: SonarImage, trajectory: Trajectory, altitude: np.ndarray) -> None:
        """Append ``image``'s pings with their poses (``trajectory``) and altitudes (metres)."""
        if self.pings == 0:
            self.fh.write(_file_header(image, self.sample_format).to_bytes())
        sonar = image.sonar
        interval = self.interval or 2.0 * image.shape[1] * sonar.range_bin / sonar.sound_speed
        for i in range(image.shape[0]):
            n = self.pings + i
            packet = _ping_packet(
                image, trajectory, i, float(altitude[i]), self.origin,
                self.start_time + n * interval, interval, self.sample_format,
            )  # fmt: skip
            packet.PingNumber = n
            self.fh.write(packet.to_bytes())
        self.pings += image.shape[0]


def _file_header(image: SonarImage, sample_format: str) -> Any:
    pyxtf = _pyxtf()
    code, nbytes, _ = _SAMPLE_FORMATS[sample_format]
    header = pyxtf.XTFFileHeader()
    header.RecordingProgramName = b"sonar_ra"
    header.RecordingProgramVersion = b"1"
    header.SonarName = b"sonar_raster"
    header.NoteString = b"simulated by sonar_raster; positions in metres, x east, y north"
    header.NavUnits = 0
    header.NumberOfSonarChannels = len(image.sides)
    for k, side in enumerate(image.sides):
        info = header.ChanInfo[k]
        info.TypeOfChannel = _PORT if side == "port" else _STARBOARD
        info.SubChannelNumber = k
        info.CorrectionFlags = 1  # slant range
        info.UniPolar = 1
        info.BytesPerSample = nbytes
        info.SampleFormat = code
        info.ChannelName = side.upper().encode()
        info.Frequency = image.sonar.frequency_hz / 1e3
        info.TiltAngle = math.degrees(image.sonar.tilt)
        info.BeamsPerArray = 1
    return header


def _ping_packet(
    image: SonarImage,
    track: Trajectory,
    i: int,
    altitude: float,
    origin: tuple[float, float],
    time: float,
    interval: float,
    sample_format: str,
) -> Any:
    pyxtf = _pyxtf()
    sonar = image.sonar
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
    for k, (side, values) in enumerate(image.sides.items()):
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
