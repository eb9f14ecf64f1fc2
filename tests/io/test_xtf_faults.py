"""Field glitches in a real XTF file: corrupted copies of the shared sample, read and run
through ``track`` and ``invert``; each bad ping is skipped or repaired and reported in one line."""

from __future__ import annotations

import ctypes
import logging
import math
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import SHARED_DATA

from sonar_raster.cli.app import main
from sonar_raster.errors import SonarRasterError
from sonar_raster.io.xtf import XtfNavigation, iter_pings, read_xtf

pyxtf = pytest.importorskip("pyxtf")

SAMPLE = SHARED_DATA / "xtf" / "scotsman-iver2.xtf"
PING, CHAN = pyxtf.XTFPingHeader, pyxtf.XTFPingChanHeader
CHAN_BYTES = ctypes.sizeof(CHAN) + 1024 * 2  # a channel of the sample: header, 1024 uint16


def packet_offsets(data: bytes) -> list[int]:
    """Byte offset of each packet (all sonar pings in the sample file)."""
    out, offset = [], 1024
    while offset < len(data):
        out.append(offset)
        offset += pyxtf.XTFPacketStart.from_buffer_copy(data, offset).NumBytesThisRecord
    return out


def put(buf: bytearray, at: int, struct: type, name: str, value) -> None:
    """Overwrite field ``name`` of the ``struct`` (a pyxtf ctypes type) starting at ``at``."""
    descriptor = getattr(struct, name)
    ctype = dict(struct._fields_)[name]
    buf[at + descriptor.offset : at + descriptor.offset + descriptor.size] = bytes(ctype(value))


def get(buf: bytes, at: int, struct: type, name: str):
    return getattr(struct.from_buffer_copy(buf, at), name)


# name: (ping, where, field, value, what happens, words of the report)
FAULTS = {
    "day 40": (10, "ping", "Day", 40, "skipped", "date 2013-09-40"),
    "month 13": (11, "ping", "Month", 13, "skipped", "date 2013-13-10"),
    "Weight -32768": (12, "port", "Weight", -32768, "skipped", "Weight -32768"),
    "Weight -200": (13, "starboard", "Weight", -200, "skipped", "Weight -200"),
    "too many samples": (14, "port", "NumSamples", 5000, "skipped", "5000 samples"),
    "too few samples": (15, "starboard", "NumSamples", 1000, "skipped", "sample spacing"),
    "samples misaligned": (16, "port", "NumSamples", 1000, "skipped", "do not fit the packet"),
    "fix moved 0.01 deg": (20, "ping", "SensorYcoordinate", 0.01, "repaired", "off the track"),
    "longitude 1e300": (21, "ping", "SensorXcoordinate", 1e300, "repaired", "not on Earth"),
    "heading spike": (22, "ping", "SensorHeading", 180.0, "repaired", "heading"),
    "clock reset": (23, "ping", "Year", 2000, "repaired", "out of order"),
}


def corrupted(directory: Path, fault: str) -> tuple[Path, int]:
    """A copy of the sample with ``fault`` written into one ping; (path, ping index)."""
    ping, where, name, value, _, _ = FAULTS[fault]
    data = bytearray(SAMPLE.read_bytes())
    at = packet_offsets(data)[ping]
    if where == "ping":
        if name in ("SensorYcoordinate", "SensorHeading"):  # moved, not replaced
            value = get(data, at, PING, name) + value
        put(data, at, PING, name, value)
    else:  # the sample's channels: port first, then starboard
        put(data, at + ctypes.sizeof(PING) + CHAN_BYTES * (where == "starboard"), CHAN, name, value)
    path = directory / f"{fault.replace(' ', '_')}.xtf"
    path.write_bytes(bytes(data))
    return path, ping


@pytest.fixture(scope="module")
def clean():
    if not SAMPLE.is_file():
        pytest.skip(f"{SAMPLE} not present")
    return read_xtf(SAMPLE)


def reports(caplog, ping: int, words: str) -> None:
    """Exactly one warning line, naming the ping and what was wrong with it."""
    lines = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(lines) == 1, lines
    assert "\n" not in lines[0] and f"ping {ping} " in lines[0] and words in lines[0], lines[0]


@pytest.mark.parametrize("fault", FAULTS)
def test_reader_skips_or_repairs_the_bad_ping(tmp_path, caplog, clean, fault):
    path, k = corrupted(tmp_path, fault)
    image, nav = read_xtf(path)
    reports(caplog, k, FAULTS[fault][5])
    clean_image, clean_nav = clean
    rows = [i for i in range(461) if i != k]
    if FAULTS[fault][4] == "skipped":
        assert image.metadata["ping_indices"] == rows
        assert [s["index"] for s in image.metadata["skipped_pings"]] == [k]
        for side in ("port", "starboard"):
            np.testing.assert_array_equal(image.sides[side], clean_image.sides[side][rows])
        np.testing.assert_array_equal(nav.time, clean_nav.time[rows])
        assert image.sonar.to_dict() == clean_image.sonar.to_dict()
        return
    # repaired: the ping stays, its navigation is interpolated from its neighbours
    assert image.shape == clean_image.shape and k in nav.rejected
    assert [r["index"] for r in image.metadata["rejected_fixes"]] == [k]
    np.testing.assert_array_equal(image.sides["port"], clean_image.sides["port"])
    east, north = nav.projected()
    ref_east, ref_north = clean_nav.projected()
    assert np.max(np.hypot(east - ref_east, north - ref_north)) < 1.0  # metres
    heading = nav.filled_heading()
    turn = np.angle(np.exp(1j * (heading - clean_nav.filled_heading())))
    assert np.max(np.abs(turn)) < math.radians(2.0)
    assert np.all(np.diff(nav.time) > 0)
    assert abs(nav.time[k] - clean_nav.time[k]) < 0.2


# name: the file's bytes -> damaged bytes; the ping lost (None: none); words of the report
FRAMES = {
    "cut in a packet": (lambda d, at: d[: at[400] + 3000], 400, "truncated: ping 400 a packet"),
    "cut in a packet start": (lambda d, at: d[: at[400] + 8], 400, "the file ends 8 bytes into"),
    "zeros after the end": (lambda d, at: d + bytes(5000), 461, "no packet marker"),
    "marker lost": (lambda d, at: d[: at[200]] + b"\0" + d[at[200] + 1 :], 200, "0xFACE"),
    "packet 64 bytes too long": (  # ping 200 reads right; ping 201 is lost finding the next
        lambda d, at: _set_size(d, at[200], 4480 + 64),
        201,
        "corrupt: ping 201 no packet marker",
    ),
    "packet empty": (lambda d, at: _set_size(d, at[200], 8), 200, "an empty packet"),
    "packet past the end": (lambda d, at: _set_size(d, at[200], 2**32 - 16), 200, "truncated"),
    "channel count 7": (  # a header count beyond 6 puts the first packet past byte 2048
        lambda d, at: d[:166] + (7).to_bytes(2, "little") + d[168:],  # NumberOfSonarChannels
        None,
        "",
    ),
}


def _set_size(data: bytes, at: int, size: int) -> bytes:
    buf = bytearray(data)
    put(buf, at, pyxtf.XTFPacketStart, "NumBytesThisRecord", size)
    return bytes(buf)


@pytest.mark.parametrize("fault", FRAMES)
def test_a_damaged_frame_loses_one_ping_and_the_rest_is_read(tmp_path, caplog, clean, fault):
    damage, lost, words = FRAMES[fault]
    data = SAMPLE.read_bytes()
    path = tmp_path / "damaged.xtf"
    path.write_bytes(damage(data, packet_offsets(data)))
    image, nav = read_xtf(path)
    rows = list(range(lost)) if fault.startswith("cut") else [i for i in range(461) if i != lost]
    assert image.metadata["ping_indices"] == rows  # the file's ping numbers are kept
    clean_image, clean_nav = clean
    for side in ("port", "starboard"):
        np.testing.assert_array_equal(image.sides[side], clean_image.sides[side][rows])
    np.testing.assert_array_equal(nav.time, clean_nav.time[rows])
    if lost is None:
        assert [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING] == []
    else:
        reports(caplog, lost, words)
        assert [s["index"] for s in image.metadata["skipped_pings"]] == [lost]


def test_a_header_counting_one_channel_of_two_still_reads_both_sides(tmp_path, caplog, clean):
    """NumberOfSonarChannels 1 in a file whose ChanInfo and packets hold port and starboard:
    both sides are read as in the clean file (not starboard dropped), with one warning line
    saying why."""
    data = SAMPLE.read_bytes()
    path = tmp_path / "one.xtf"
    path.write_bytes(data[:166] + (1).to_bytes(2, "little") + data[168:])
    image, _ = read_xtf(path)
    assert sorted(image.sides) == ["port", "starboard"]
    for side in ("port", "starboard"):
        np.testing.assert_array_equal(image.sides[side], clean[0].sides[side])
    lines = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(lines) == 1 and "counts 1 sonar channel" in lines[0] and "starboard" in lines[0]


def test_a_stale_chaninfo_entry_past_the_count_is_not_read(tmp_path, caplog, clean):
    """A one-channel file whose ChanInfo 1 says starboard but holds no sample size (a blank
    entry with a stale type): it is not read, so port comes out as in the clean file, and one
    warning says the pings carry a channel the header does not describe."""
    data = bytearray(SAMPLE.read_bytes())
    data[166:168] = (1).to_bytes(2, "little")
    size = ctypes.sizeof(pyxtf.XTFChanInfo)
    info = pyxtf.XTFFileHeader.ChanInfo.offset + size  # ChanInfo 1
    data[info : info + size] = bytes(size)
    put(data, info, pyxtf.XTFChanInfo, "TypeOfChannel", 2)
    path = tmp_path / "port.xtf"
    path.write_bytes(bytes(data))
    image, _ = read_xtf(path)
    assert list(image.sides) == ["port"]
    np.testing.assert_array_equal(image.sides["port"], clean[0].sides["port"])
    lines = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(lines) == 1 and "pings carry 2 channels but the header describes 1" in lines[0]
    assert "the port side only" in lines[0]


def test_longitudes_and_latitudes_marked_as_metres_are_read_as_degrees(tmp_path, caplog, clean):
    """The sample's fixes with NavUnits 0: as metres the vehicle would stand still (1e-5 m/s),
    as degrees it moves at 1 m/s: read as degrees, with one warning."""
    data = bytearray(SAMPLE.read_bytes())
    data[pyxtf.XTFFileHeader.NavUnits.offset] = 0  # metres
    path = tmp_path / "metres.xtf"
    path.write_bytes(bytes(data))
    _, nav = read_xtf(path)
    clean_nav = clean[1]
    assert clean_nav.units == "degrees" and nav.units == "degrees"
    np.testing.assert_array_equal(nav.x, clean_nav.x)
    assert nav.rejected == clean_nav.rejected
    lines = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(lines) == 1 and "longitudes and latitudes" in lines[0], lines


def test_a_damaged_frame_in_a_copy_with_new_samples(tmp_path, clean):
    from sonar_raster.insert.xtf_patch import patch_xtf

    data = SAMPLE.read_bytes()
    at = packet_offsets(data)
    path = tmp_path / "damaged.xtf"
    path.write_bytes(data[: at[3]] + b"\0" + data[at[3] + 1 :])  # ping 3 lost
    new = clean[0].sides["port"][10] * 0.5
    patch_xtf(path, tmp_path / "out.xtf", {10: {"port": new}})  # reads its copy back itself
    image, _ = read_xtf(tmp_path / "out.xtf")
    rows = [i for i in range(461) if i != 3]
    changed = np.flatnonzero(np.any(image.sides["port"] != clean[0].sides["port"][rows], axis=1))
    assert [rows[i] for i in changed] == [10]  # the ping the reader calls 10, not the 10th read
    assert np.max(np.abs(image.sides["port"][rows.index(10)] - new)) <= 0.5


def test_cli_track_reads_a_truncated_recording(tmp_path, capsys, caplog):
    if not SAMPLE.is_file():
        pytest.skip(f"{SAMPLE} not present")
    data = SAMPLE.read_bytes()
    path = tmp_path / "cut.xtf"
    path.write_bytes(data[: packet_offsets(data)[400] + 3000])
    out = tmp_path / "alt.csv"
    assert main(["track", str(path), "-o", str(out)]) == 0
    assert capsys.readouterr().err == ""
    reports(caplog, 400, "truncated")
    assert len(out.read_text().splitlines()) == 400 + 1


@pytest.mark.parametrize("fault", [f for f in FAULTS if FAULTS[f][4] == "skipped"])
def test_iter_pings_skips_the_bad_ping(tmp_path, caplog, fault):
    if not SAMPLE.is_file():
        pytest.skip(f"{SAMPLE} not present")
    path, k = corrupted(tmp_path, fault)
    assert [p.index for p in iter_pings(path)] == [i for i in range(461) if i != k]
    reports(caplog, k, FAULTS[fault][5])


@pytest.mark.parametrize("fault", FAULTS)
def test_cli_track_works_on_the_other_pings(tmp_path, capsys, caplog, fault):
    if not SAMPLE.is_file():
        pytest.skip(f"{SAMPLE} not present")
    path, k = corrupted(tmp_path, fault)
    out = tmp_path / "alt.csv"
    assert main(["track", str(path), "--pings", "0:60", "-o", str(out)]) == 0
    captured = capsys.readouterr()
    assert captured.err == "" and "Traceback" not in captured.out
    reports(caplog, k, FAULTS[fault][5])
    pings = 59 if FAULTS[fault][4] == "skipped" else 60
    assert f"{pings} pings" in captured.out
    assert len(out.read_text().splitlines()) == pings + 1


def test_track_csv_numbers_rows_by_file_ping(tmp_path, caplog):
    from sonar_raster.inversion.bottom import track_bottom
    from sonar_raster.inversion.track_io import write_track_csv

    if not SAMPLE.is_file():
        pytest.skip(f"{SAMPLE} not present")
    path, k = corrupted(tmp_path, "day 40")
    image, nav = read_xtf(path, slice(0, 20))
    track = track_bottom(image.sides, image.sonar.range_bin)
    out = tmp_path / "track.csv"
    write_track_csv(out, track, nav.altitude, pings=image.metadata["ping_indices"])
    first = [int(row.split(",")[0]) for row in out.read_text().splitlines()[1:]]
    assert first == [i for i in range(20) if i != k]


@pytest.mark.parametrize("fault", FAULTS)
def test_cli_invert_works_on_the_other_pings(tmp_path, capsys, caplog, fault):
    import rasterio

    if not SAMPLE.is_file():
        pytest.skip(f"{SAMPLE} not present")
    path, k = corrupted(tmp_path, fault)
    out = tmp_path / "inv"
    status = main(
        ["invert", str(path), "-o", str(out), "--max-iter", "2", "--no-previews", "--no-mesh",
         "--pings", "0:60", "--quiet"]
    )  # fmt: skip
    captured = capsys.readouterr()
    assert status == 0 and captured.err == "", captured.err
    reports(caplog, k, FAULTS[fault][5])
    pings = 59 if FAULTS[fault][4] == "skipped" else 60
    assert len((out / "bottom_track.csv").read_text().splitlines()) == pings + 1
    with rasterio.open(out / "elevation.tif") as src:
        # 60 pings at 0.12 m and 30 m each side: tens of metres, not the fix's 1.1 km
        assert src.width * src.res[0] < 80.0 and src.height * src.res[1] < 80.0
        assert src.crs.to_epsg() == 32619


# ---------------------------------------------------------------- more than a glitch


def _rewrite(tmp_path: Path, pings: range, edits: list[tuple[int, type, str, object]]) -> Path:
    """The sample with ``(channel or -1 for the ping header, struct, field, value)`` edits
    applied to each of ``pings``."""
    data = bytearray(SAMPLE.read_bytes())
    offsets = packet_offsets(data)
    for k in pings:
        for chan, struct, name, value in edits:
            at = offsets[k] + (ctypes.sizeof(PING) + CHAN_BYTES * chan if chan >= 0 else 0)
            put(data, at, struct, name, value)
    path = tmp_path / "rewritten.xtf"
    path.write_bytes(bytes(data))
    return path


def test_a_changed_setting_is_an_error_not_a_glitch(tmp_path, clean):
    both_sides = [(0, CHAN, "SlantRange", 50.0), (1, CHAN, "SlantRange", 50.0)]
    # 50 pings recorded at another range: the setting changed, pings are not skipped
    path = _rewrite(tmp_path, range(100, 150), both_sides)
    with pytest.raises(
        SonarRasterError, match="changes at ping 100 .* --pings 0:100 or --pings 100:150"
    ):
        read_xtf(path)
    image, _ = read_xtf(path, slice(100, 150))  # one setting: fine
    assert image.sonar.max_range == pytest.approx(50.0)
    # one such ping is a glitch: skipped
    image, _ = read_xtf(_rewrite(tmp_path, range(100, 101), both_sides))
    assert image.metadata["skipped_pings"] == [
        {"index": 100, "reason": "layout: sample spacing 0.048828 m where the others have "
         "0.029281 m"}
    ]  # fmt: skip
    assert image.shape == (460, 1024)


def test_no_usable_ping_is_one_error_line(tmp_path, capsys, clean):
    path = _rewrite(tmp_path, range(461), [(-1, PING, "Month", 0)])
    with pytest.raises(SonarRasterError) as err:
        read_xtf(path)
    message = str(err.value)
    assert "no usable side-scan ping" in message and "skipped 461 of 461" in message
    assert "458 more" in message and "\n" not in message
    assert main(["track", str(path)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("sonar-raster: error:")
    # the bad pings are outside the range asked for: nothing to report
    path = _rewrite(tmp_path, range(300, 461), [(-1, PING, "Month", 0)])
    image, _ = read_xtf(path, slice(0, 100))
    assert image.shape[0] == 100 and image.metadata["skipped_pings"] == []


# ---------------------------------------------------------------- georeferencing


def _straight_track(pings: int, jump_at: int | None = None) -> XtfNavigation:
    """Metres, heading north at 1 m/s, 0.1 s between pings; one fix 800 m east if asked."""
    t = 1e9 + 0.1 * np.arange(pings)
    x = np.full(pings, 500000.0)
    if jump_at is not None:
        x[jump_at] += 800.0
    zero = np.zeros(pings)
    return XtfNavigation(
        t, x, 5e6 + 0.1 * np.arange(pings), "metres", zero, zero, zero, np.full(pings, 8.0),
        np.full(pings, 20.0), np.ones(pings, dtype=bool),
    )  # fmt: skip


def _result(nav: XtfNavigation, cells: int = 20) -> SimpleNamespace:
    pings = len(nav.time)
    x = 2.0 + 0.5 * np.arange(cells)
    maps = np.full((pings, cells), -8.0)
    side = SimpleNamespace(x=x, elevation=maps, reflectivity=maps * 0 + 0.5, ground=maps * 0 + 1)
    return SimpleNamespace(navigation=nav, sides={"port": side, "starboard": side})


def test_georeference_sizes_the_raster_from_the_track_not_a_stray_fix():
    """A navigation that skipped read_xtf's filter, with one fix 800 m off: the raster spans
    the track (6 m x 12 m plus the swath), not the stray fix."""
    from sonar_raster.inversion.xtf import georeference

    raster = georeference(_result(_straight_track(60, jump_at=30)), pixel=0.5)
    width, height = (s * raster.pixel for s in raster.layers["elevation"].shape[::-1])
    assert width < 30.0 and height < 10.0
    reference = georeference(_result(_straight_track(60)), pixel=0.5)
    assert raster.layers["elevation"].shape == reference.layers["elevation"].shape
    np.testing.assert_array_equal(raster.layers["mosaic"], reference.layers["mosaic"])


def test_a_blank_record_without_navigation_takes_its_neighbours_attitude_and_depth():
    """The sample file's first ping: no fix, and depth, pitch and roll all 0 while the vehicle
    is at 14 m and pitched 20 degrees; its zeros would put that ping's seabed 0.9 m off
    (world elevation ``Z cos p - depth``). Gaps are interpolated from pings with navigation."""
    from sonar_raster.inversion.xtf import world_elevation

    nav = replace(
        _straight_track(10),  # (whose heading, roll and pitch share one array)
        pitch=np.full(10, np.radians(-20.0)),
        roll=np.full(10, 0.05),
        depth=np.full(10, 14.0),
    )
    nav.valid[0] = False
    nav.pitch[0] = nav.roll[0] = nav.depth[0] = 0.0
    assert nav.filled("pitch")[0] == pytest.approx(np.radians(-20.0))
    assert nav.filled("roll")[0] == pytest.approx(0.05)
    assert nav.filled("depth")[0] == pytest.approx(14.0)
    level = world_elevation(_result(nav))["port"]
    np.testing.assert_allclose(level, level[1, 0])  # every ping, the first too, at one level
    nav.valid[:] = False  # no ping has a fix: the file's own values
    assert nav.filled("depth")[0] == 0.0 and nav.filled("depth")[1] == 14.0


def test_grid_refuses_a_huge_raster_with_one_line():
    from sonar_raster.inversion.xtf import grid

    e = np.array([[0.0, 1.0], [5e5, 5e5 + 1.0]])
    n = np.array([[0.0, 0.0], [5e5, 5e5]])
    layers = {"elevation": np.zeros((2, 2)), "reflectivity": np.ones((2, 2))}
    with pytest.raises(SonarRasterError, match=r"pixels of 0\.05 m.*grid fewer pings") as err:
        grid([(e, n, layers)], 0.05, None)
    assert "\n" not in str(err.value)
    # non-finite positions are left out, not a crash in the extent
    e[1, 1], n[0, 1] = np.nan, np.inf
    raster = grid([(e[:1], n[:1], {k: v[:1] for k, v in layers.items()})], 0.5, None)
    assert raster.layers["reflectivity"].shape == (1, 1)
