"""XTF files as other recorders lay them out: the sample file's packets rewritten with channels
numbered from 1, a sub-bottom channel of another sample size first, one channel per packet, and
sample types the reader has no decoder for."""

from __future__ import annotations

import copy
import ctypes
from pathlib import Path

import numpy as np
import pytest
from conftest import SHARED_DATA

from sonar_raster.cli.app import main
from sonar_raster.errors import SonarRasterError
from sonar_raster.io.xtf import read_xtf

pyxtf = pytest.importorskip("pyxtf")

SAMPLE = SHARED_DATA / "xtf" / "scotsman-iver2.xtf"
PING, CHAN = pyxtf.XTFPingHeader, pyxtf.XTFPingChanHeader
PINGS = 40

pytestmark = pytest.mark.skipif(not SAMPLE.is_file(), reason=f"{SAMPLE} not present")


def _pings() -> tuple[pyxtf.XTFFileHeader, list[tuple[object, list[tuple[object, np.ndarray]]]]]:
    """The sample's file header and its first pings: (ping header, [(channel header, samples)])."""
    data = SAMPLE.read_bytes()
    header = pyxtf.XTFFileHeader.from_buffer_copy(data)
    out, offset = [], 1024
    for _ in range(PINGS):
        ping = PING.from_buffer_copy(data, offset)
        pos, chans = offset + ctypes.sizeof(PING), []
        for _ in range(ping.NumChansToFollow):
            chan = CHAN.from_buffer_copy(data, pos)
            pos += ctypes.sizeof(CHAN)
            chans.append((chan, np.frombuffer(data, np.uint16, chan.NumSamples, pos)))
            pos += chan.NumSamples * 2
        out.append((ping, chans))
        offset += ping.NumBytesThisRecord
    return header, out


def _packet(ping, chans) -> bytes:
    body = b"".join(bytes(c) + np.ascontiguousarray(d).tobytes() for c, d in chans)
    ping = copy.copy(ping)
    ping.NumChansToFollow = len(chans)
    ping.NumBytesThisRecord = ctypes.sizeof(PING) + len(body)
    return bytes(ping) + body


def _numbered(chan, number: int):
    chan = CHAN.from_buffer_copy(bytes(chan))
    chan.ChannelNumber = number
    return chan


@pytest.fixture(scope="module")
def clean():
    return read_xtf(SAMPLE, pings=(0, PINGS))[0]


def _same(image, clean) -> None:
    assert sorted(image.sides) == ["port", "starboard"]
    for side in ("port", "starboard"):
        np.testing.assert_array_equal(image.sides[side], clean.sides[side])


def test_channels_numbered_from_1_are_read_by_their_place(tmp_path, clean):
    """ChannelNumber 1 and 2 (not 0 and 1): port stays port (it was read as starboard, and
    starboard, number 2, not at all)."""
    header, pings = _pings()
    packets = [
        _packet(p, [(_numbered(c, k + 1), d) for k, (c, d) in enumerate(ch)]) for p, ch in pings
    ]
    path = tmp_path / "from1.xtf"
    path.write_bytes(bytes(header) + b"".join(packets))
    _same(read_xtf(path)[0], clean)


def test_a_sub_bottom_channel_first_with_another_sample_size(tmp_path, clean):
    """ChanInfo [sub-bottom float32, port, starboard], each ping's sub-bottom channel first: the
    side channels are sized by their own entries (they were sized by the side channels' 2 bytes,
    so every ping was skipped)."""
    header, pings = _pings()
    sbp = pyxtf.XTFChanInfo()
    sbp.TypeOfChannel, sbp.BytesPerSample, sbp.SampleFormat = 0, 4, 5
    port, stbd = (pyxtf.XTFChanInfo.from_buffer_copy(bytes(header.ChanInfo[k])) for k in (0, 1))
    header.ChanInfo[0], header.ChanInfo[1], header.ChanInfo[2] = sbp, port, stbd
    header.NumberOfSonarChannels = 3
    chan = CHAN()
    chan.NumSamples, chan.SlantRange = 700, 50.0
    sub = (chan, np.linspace(0, 1, 700, dtype=np.float32))
    packets = [
        _packet(p, [sub] + [(_numbered(c, k + 1), d) for k, (c, d) in enumerate(ch)])
        for p, ch in pings
    ]
    path = tmp_path / "sbp.xtf"
    path.write_bytes(bytes(header) + b"".join(packets))
    _same(read_xtf(path)[0], clean)


def test_one_channel_per_packet_is_joined_into_one_ping(tmp_path, clean, capsys):
    """Port and starboard of each ping in packets of their own (same ping number and time): one
    ping with both sides (the sides alternated and the file was refused as a changing setting);
    ``insert`` writes its objects back into those packets."""
    header, pings = _pings()
    packets = [_packet(p, [c]) for p, ch in pings for c in ch]
    path = tmp_path / "split.xtf"
    path.write_bytes(bytes(header) + b"".join(packets))
    image, nav = read_xtf(path)
    _same(image, clean)
    assert image.metadata["ping_indices"] == list(range(PINGS)) and len(nav.time) == PINGS
    out = tmp_path / "with_box.xtf"
    args = ["insert", str(path), "-o", str(out), "--object", "box:size=2,1,0.8", "--at", "20,-8"]
    assert main([*args, "-q"]) == 0, capsys.readouterr().err
    changed = read_xtf(out)[0]
    assert not np.array_equal(changed.sides["port"][20], image.sides["port"][20])
    np.testing.assert_array_equal(changed.sides["starboard"], image.sides["starboard"])


@pytest.mark.parametrize(
    ("size", "code", "says"),
    [(4, 1, "IBM floating-point samples (XTF SampleFormat 1)"), (3, 0, "3-byte samples")],
)
def test_a_sample_type_without_decoder_is_one_clear_error(tmp_path, capsys, size, code, says):
    """IBM floats (they were read as 32-bit integers) and 3-byte samples (every ping skipped as
    a bad packet): one line naming the channel and its type, before any ping; exit 2."""
    header, pings = _pings()
    for k in (0, 1):
        header.ChanInfo[k].BytesPerSample, header.ChanInfo[k].SampleFormat = size, code
    packets = [
        _packet(p, [(c, np.zeros(c.NumSamples * size, np.uint8)) for c, _ in ch]) for p, ch in pings
    ]
    path = tmp_path / "odd.xtf"
    path.write_bytes(bytes(header) + b"".join(packets))
    with pytest.raises(SonarRasterError, match="port channel") as err:
        read_xtf(path)
    assert says in str(err.value)
    out = tmp_path / "alt.csv"
    assert main(["track", str(path), "-o", str(out)]) == 2
    assert says in capsys.readouterr().err and not out.exists()
    assert not Path(tmp_path / "none").exists()


def _zeroed(ping, ship: tuple[float, float] = (0.0, 0.0)):
    """A copy of the ping header without the sensor's position (the ship's set to ``ship``)."""
    ping = PING.from_buffer_copy(bytes(ping))
    ping.SensorXcoordinate = ping.SensorYcoordinate = 0.0
    ping.ShipXcoordinate, ping.ShipYcoordinate = ship
    return ping


#: The fixed pings of :func:`_with_fixes`: every fifth from the second, and the last.
FIXED = [*range(1, PINGS, 5), PINGS - 1]


def _fix(ping, raw: bool = False) -> bytes:
    """A navigation packet (type 42) at the ping's time and position.

    ``raw``: the same fix as a raw position packet (type 107, sub-seconds in tenths of ms).
    """
    nav = pyxtf.XTFPosRawNavigation() if raw else pyxtf.XTFHeaderNavigation()
    nav.MagicNumber, nav.HeaderType = 0xFACE, 107 if raw else 42
    nav.NumBytesThisRecord = ctypes.sizeof(nav)
    for name in ("Year", "Month", "Day", "Hour", "Minute", "Second"):
        setattr(nav, name, getattr(ping, name))
    nav.Microsecond = (100 if raw else 10_000) * ping.HSeconds
    nav.RawXcoordinate, nav.RawYcoordinate = ping.SensorXcoordinate, ping.SensorYcoordinate
    return bytes(nav)


def _with_fixes(path: Path, fixes: bool = True, raw: bool = False) -> Path:
    """The sample's first pings without positions, a fix before each of :data:`FIXED`.

    ``fixes`` False: no fix packets.
    """
    header, pings = _pings()
    parts = [
        (_fix(ping, raw) if fixes and k in FIXED else b"") + _packet(_zeroed(ping), chans)
        for k, (ping, chans) in enumerate(pings)
    ]
    path.write_bytes(bytes(header) + b"".join(parts))
    return path


def test_pings_without_a_position_take_the_navigation_packets(tmp_path):
    """Pings whose headers hold no position, and a navigation packet (type 42) before every
    fifth ping: each ping takes the fixes' position interpolated in time; the ping before the
    first fix keeps none. Without the packets no ping has a position."""
    path = _with_fixes(tmp_path / "navpackets.xtf")
    _, nav = read_xtf(path)
    assert not read_xtf(_with_fixes(tmp_path / "bare.xtf", fixes=False))[1].valid.any()
    assert not nav.valid[0] and nav.valid[1:].all()
    pings = [p for p, _ in _pings()[1]]
    x = np.array([p.SensorXcoordinate for p in pings])
    y = np.array([p.SensorYcoordinate for p in pings])
    np.testing.assert_array_equal(nav.x[FIXED], x[FIXED])
    np.testing.assert_array_equal(nav.y[FIXED], y[FIXED])
    expected = np.interp(nav.time[1:], nav.time[FIXED], x[FIXED])
    np.testing.assert_allclose(nav.x[1:], expected, rtol=0, atol=1e-9)
    assert np.max(np.abs(nav.x[1:] - x[1:])) < 2e-6  # degrees: within 0.15 m of the pings' own
    # a ping range ending between two fixes: its last pings as when the whole file is read
    _, part = read_xtf(path, pings=(0, 8))
    np.testing.assert_array_equal(part.valid, nav.valid[:8])
    np.testing.assert_array_equal(part.x, nav.x[:8])
    # the same fixes as raw position packets (type 107) give the same track
    _, raw = read_xtf(_with_fixes(tmp_path / "raw.xtf", raw=True))
    np.testing.assert_array_equal(raw.valid, nav.valid)
    np.testing.assert_allclose(raw.x, nav.x, rtol=0, atol=1e-12, equal_nan=True)
    np.testing.assert_allclose(raw.y, nav.y, rtol=0, atol=1e-12, equal_nan=True)


def test_a_ping_with_only_the_ship_position_takes_it(tmp_path):
    header, pings = _pings()
    packets = [
        _packet(_zeroed(p, (p.SensorXcoordinate, p.SensorYcoordinate)), ch) for p, ch in pings
    ]
    path = tmp_path / "ship.xtf"
    path.write_bytes(bytes(header) + b"".join(packets))
    _, nav = read_xtf(path)
    _, own = read_xtf(SAMPLE, pings=(0, PINGS))
    np.testing.assert_array_equal(nav.valid, own.valid)
    np.testing.assert_array_equal(nav.x[own.valid], own.x[own.valid])
