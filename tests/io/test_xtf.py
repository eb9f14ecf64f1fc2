"""XTF in and out: the OpenSidescan sample, simulated round trips, bad files, the CLI."""

from __future__ import annotations

import ctypes
import gc
import logging
import math
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import SHARED_DATA, plane

from sonar_raster import render_raster
from sonar_raster.cli.app import main
from sonar_raster.errors import SonarRasterError
from sonar_raster.io.xtf import XtfReader, _sound_speed, iter_pings, read_xtf, write_xtf
from sonar_raster.scene import build_scene
from sonar_raster.sonar import BeamPattern, Sonar
from sonar_raster.trajectory import Trajectory

pyxtf = pytest.importorskip("pyxtf")

SAMPLE = SHARED_DATA / "xtf" / "scotsman-iver2.xtf"
needs_sample = pytest.mark.skipif(not SAMPLE.is_file(), reason=f"{SAMPLE} not present")


@pytest.fixture(scope="module")
def sample():
    if not SAMPLE.is_file():
        pytest.skip(f"{SAMPLE} not present")
    return read_xtf(SAMPLE)


# ---------------------------------------------------------------- the real sample file


def test_sample_sizes_and_range(sample):
    image, nav = sample
    assert set(image.sides) == {"port", "starboard"}
    assert image.shape == (461, 1024)
    assert image.sonar.max_range == pytest.approx(30.0, abs=0.05)
    assert image.sonar.range_bin == pytest.approx(image.sonar.max_range / 1024)
    assert image.sonar.frequency_hz == pytest.approx(600e3)
    # the file stores 750 m/s, half the speed: 2 * SlantRange / TimeDuration says 1500
    assert image.sonar.sound_speed == pytest.approx(1500.0, rel=1e-3)


def test_sample_waterfall_matches_pyxtf(sample):
    image, _ = sample
    header, packets = pyxtf.xtf_read(str(SAMPLE))
    pings = packets[pyxtf.XTFHeaderType.sonar]
    port = pyxtf.concatenate_channel(pings, header, 0, weighted=True)
    starboard = pyxtf.concatenate_channel(pings, header, 1, weighted=True)
    # pyxtf stacks the latest ping first, port as stored (far range first)
    expected = np.hstack([port, starboard])[::-1].astype(np.float32)
    np.testing.assert_array_equal(image.display(), expected)
    # port as stored runs far -> near: the transmit pulse (saturated) is at its end
    assert np.all(image.sides["port"][:, :4] == 32767)
    assert np.all(image.sides["starboard"][:, :4] == 32767)


def test_sample_navigation(sample):
    image, nav = sample
    assert nav.units == "degrees"
    assert not nav.valid[0] and nav.valid[1:].all()  # the first ping has no fix
    assert np.all((nav.x[1:] > -69) & (nav.x[1:] < -68)) and np.all(np.abs(nav.y[1:] - 48.4) < 0.1)
    assert nav.crs == "EPSG:32619"  # UTM zone of longitude -68.8, north
    track = nav.to_trajectory()
    assert np.all(np.isfinite(track.positions))
    # speed over ground from the fixes agrees with the recorded speed, 2 knots
    header, packets = pyxtf.xtf_read(str(SAMPLE))
    knots = np.median([p.SensorSpeed for p in packets[pyxtf.XTFHeaderType.sonar][1:]])
    east, north = nav.projected()
    idx = np.flatnonzero(nav.fresh())
    path = np.sum(np.hypot(np.diff(east[idx]), np.diff(north[idx])))
    speed = path / (nav.time[idx[-1]] - nav.time[idx[0]])
    assert speed == pytest.approx(knots * 1852 / 3600, rel=0.1)
    assert nav.along_track_spacing() == pytest.approx(
        path / (idx[-1] - idx[0]), rel=1e-12
    )  # by definition; positive and finite
    assert np.all(np.isfinite(nav.altitude[1:])) and np.isnan(nav.altitude[0])


def test_sample_streams_ping_by_ping():
    if not SAMPLE.is_file():
        pytest.skip(f"{SAMPLE} not present")
    with XtfReader(SAMPLE) as reader:
        pings = iter(reader)
        first = next(pings)
        assert reader._fh is not None and reader._fh.tell() < 2 * 4480 + 1024  # one packet read
        assert first.index == 0 and not first.has_navigation
        second = next(pings)
        assert second.has_navigation and second.sides["starboard"].dtype == np.float32
    assert sum(1 for _ in iter_pings(SAMPLE)) == 461


def test_sample_ping_range(sample):
    image, nav = sample
    part, part_nav = read_xtf(SAMPLE, pings=slice(100, 140))
    assert part.shape == (40, 1024)
    np.testing.assert_array_equal(part.sides["port"], image.sides["port"][100:140])
    np.testing.assert_array_equal(part_nav.time, nav.time[100:140])


@pytest.mark.parametrize(
    "field, timing, expected",
    [(750.0, True, 1500.0), (1500.0, True, 1500.0), (750.0, False, 1500.0)]
    + [(1480.0, False, 1480.0)],
)
def test_sound_speed_stored_whole_or_halved(field, timing, expected):
    chan = SimpleNamespace(SlantRange=30.0, TimeDuration=2 * 30.0 / 1500.0 if timing else 0.0)
    assert _sound_speed(field, chan) == pytest.approx(expected)


# ---------------------------------------------------------------- simulated round trips


@pytest.fixture(scope="module")
def simulated():
    sonar = Sonar(
        frequency_hz=450e3,
        max_range=15.0,
        range_bin=0.05,
        beam=BeamPattern.gaussian(50.0),
        tilt=math.radians(15.0),
    )
    n = 40
    t = np.linspace(0.0, 1.0, n)
    pos = np.stack([3.0 * t, -4.0 + 8.0 * t + 0.5 * t**2, 8.0 + 0.2 * t], axis=1)
    track = Trajectory(
        pos, np.radians(20.0 + 10.0 * t), np.radians(-2.0 + 4.0 * t), np.radians(3.0 - 2.0 * t)
    )
    image = render_raster(build_scene([plane(200.0)]), sonar, track)
    return image, track


@pytest.mark.parametrize("origin", [(0.0, 0.0), (512000.0, 5365000.0)])
def test_simulated_round_trip_is_exact_in_float32(tmp_path, simulated, origin):
    image, track = simulated
    altitude = 8.0 + np.linspace(0, 0.2, track.n_pings)
    path = write_xtf(tmp_path / "sim.xtf", image, track, altitude=altitude, origin=origin)
    back, nav = read_xtf(path)
    for side in image.sides:
        np.testing.assert_array_equal(back.sides[side], image.sides[side])
    assert back.sonar.range_bin == pytest.approx(image.sonar.range_bin, rel=1e-6)
    assert back.sonar.max_range == pytest.approx(image.sonar.max_range, rel=1e-6)
    assert back.sonar.frequency_hz == image.sonar.frequency_hz
    assert back.sonar.tilt == pytest.approx(image.sonar.tilt, rel=1e-6)
    assert back.sonar.sound_speed == image.sonar.sound_speed
    assert nav.units == "metres" and nav.valid.all() and nav.crs is None
    again = nav.to_trajectory(origin=origin)
    np.testing.assert_allclose(again.positions[:, :2], track.positions[:, :2], atol=1e-6)
    np.testing.assert_allclose(again.positions[:, 2], track.positions[:, 2], atol=1e-5)
    np.testing.assert_allclose(again.headings, track.headings, atol=1e-6)  # float32 degrees
    np.testing.assert_allclose(again.roll, track.roll, atol=1e-7)
    np.testing.assert_allclose(again.pitch, track.pitch, atol=1e-7)
    np.testing.assert_allclose(nav.altitude, altitude, rtol=1e-6)


def test_simulated_uint16_error_within_stated_bound(tmp_path, simulated):
    image, track = simulated
    path = write_xtf(tmp_path / "sim16.xtf", image, track, sample_format="uint16")
    back, _ = read_xtf(path)
    header, packets = pyxtf.xtf_read(str(path))
    for k, side in enumerate(image.sides):
        err = np.abs(back.sides[side].astype(np.float64) - image.sides[side])
        bound = image.sides[side].max(axis=1, keepdims=True) / 65535.0
        assert np.all(err <= bound)
        assert np.all(image.sides[side].max(axis=1) > 0)
        # pyxtf reads the same integer codes; the Weight N gives value = code * 2**-N
        pings = packets[pyxtf.XTFHeaderType.sonar]
        codes = pyxtf.concatenate_channel(pings, header, k)[::-1].astype(np.float64)
        weights = np.array([p.ping_chan_headers[k].Weight for p in pings])  # time order
        decoded = codes * 2.0 ** -weights[:, None]
        if side == "port":
            decoded = decoded[:, ::-1]
        np.testing.assert_array_equal(decoded.astype(np.float32), back.sides[side])


def test_simulated_file_is_read_by_pyxtf_with_port_reversed(tmp_path, simulated):
    image, track = simulated
    path = write_xtf(tmp_path / "sim.xtf", image, track)
    header, packets = pyxtf.xtf_read(str(path))
    assert header.NumberOfSonarChannels == 2 and header.NavUnits == 0
    assert [header.ChanInfo[k].TypeOfChannel for k in range(2)] == [1, 2]
    ping = packets[pyxtf.XTFHeaderType.sonar][5]
    np.testing.assert_array_equal(ping.data[0][::-1], image.sides["port"][5])
    np.testing.assert_array_equal(ping.data[1], image.sides["starboard"][5])
    assert ping.SoundVelocity == pytest.approx(750.0)  # half, as readers expect
    chan = ping.ping_chan_headers[1]
    assert chan.SlantRange == pytest.approx(15.0) and chan.NumSamples == 300
    assert 2 * chan.SlantRange / chan.TimeDuration == pytest.approx(1500.0, rel=1e-6)
    assert ping.NumBytesThisRecord == len(ping.to_bytes())


def test_projected_positions_marked_as_degrees_are_read_as_metres(tmp_path, simulated, caplog):
    """UTM-sized eastings and northings in a file whose NavUnits says degrees are no place on
    Earth in degrees: read as metres (as written), with one warning, not rejected as wild."""
    image, track = simulated
    path = write_xtf(tmp_path / "utm.xtf", image, track, origin=(500_000.0, 5_400_000.0))
    _, nav = read_xtf(path)
    data = bytearray(path.read_bytes())
    data[pyxtf.XTFFileHeader.NavUnits.offset] = 3  # degrees
    marked = tmp_path / "marked.xtf"
    marked.write_bytes(bytes(data))
    caplog.clear()
    _, back = read_xtf(marked)
    assert back.units == "metres" and back.valid.all() and not back.rejected
    np.testing.assert_array_equal(back.x, nav.x)
    np.testing.assert_array_equal(back.y, nav.y)
    lines = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(lines) == 1 and "no place on Earth in degrees" in lines[0], lines


def test_write_rejects_bad_input_and_leaves_nothing(tmp_path, simulated):
    image, track = simulated
    short = Trajectory(track.positions[:5], track.headings[:5], track.roll[:5])
    with pytest.raises(SonarRasterError, match="poses"):
        write_xtf(tmp_path / "a.xtf", image, short)
    with pytest.raises(SonarRasterError, match="sample_format"):
        write_xtf(tmp_path / "a.xtf", image, track, sample_format="int8")
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------- bad files


def _bad_files(tmp: Path) -> dict[str, tuple[Path, str]]:
    data = SAMPLE.read_bytes() if SAMPLE.is_file() else None
    files = {}
    (tmp / "empty.xtf").write_bytes(b"")
    files["empty"] = (tmp / "empty.xtf", "empty")
    (tmp / "text.xtf").write_bytes(b"not sonar at all\n" * 200)
    files["text"] = (tmp / "text.xtf", "not an XTF file")
    (tmp / "tiny.xtf").write_bytes(b"\x7b" + b"\0" * 99)
    files["tiny"] = (tmp / "tiny.xtf", "shorter than")
    if data is not None:
        (tmp / "header_only.xtf").write_bytes(data[:1024])
        files["header only"] = (tmp / "header_only.xtf", "no side-scan pings")
        (tmp / "cut_first.xtf").write_bytes(data[: 1024 + 100])
        files["cut in first ping"] = (tmp / "cut_first.xtf", "truncated")
        broken = bytearray(data[: 1024 + 4480])
        broken[1024] = 0  # the packet marker of the only ping
        (tmp / "broken.xtf").write_bytes(bytes(broken))
        files["no packet marker"] = (tmp / "broken.xtf", "corrupt or not XTF: no packet marker")
    return files  # damage after a good ping loses a ping, not the file: test_xtf_faults.py


@pytest.mark.parametrize(
    "case",
    ["empty", "text", "tiny", "header only", "cut in first ping", "no packet marker"],
)
def test_bad_files_raise_one_clear_error(tmp_path, case):
    files = _bad_files(tmp_path)
    if case not in files:
        pytest.skip(f"{SAMPLE} not present")
    path, message = files[case]
    with pytest.raises(SonarRasterError, match=message):
        read_xtf(path)


@pytest.mark.parametrize("case", ["empty", "text", "cut in first ping"])
@pytest.mark.parametrize("command", ["track", "invert"])
def test_cli_bad_files_exit_2_and_write_nothing(tmp_path, capsys, case, command):
    (tmp_path / "in").mkdir()
    files = _bad_files(tmp_path / "in")
    if case not in files:
        pytest.skip(f"{SAMPLE} not present")
    out = tmp_path / "out"
    out.mkdir()
    target = ["-o", str(out / "alt.csv")] if command == "track" else ["-o", str(out / "inv")]
    status = main([command, str(files[case][0]), *target, "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2
    assert len(err) == 1 and err[0].startswith("sonar-raster: error:")
    assert list(out.iterdir()) == []


@needs_sample
def test_header_without_side_scan_channel_raises_and_closes_the_file(tmp_path):
    data = bytearray(SAMPLE.read_bytes()[: 1024 + 4480])
    info = pyxtf.XTFFileHeader.ChanInfo.offset
    for k in range(2):  # TypeOfChannel 0: neither port nor starboard
        data[info + k * ctypes.sizeof(pyxtf.XTFChanInfo)] = 0
    path = tmp_path / "no_sides.xtf"
    path.write_bytes(bytes(data))
    with pytest.raises(SonarRasterError, match="no port or starboard side-scan channel"):
        read_xtf(path)
    gc.collect()  # an unclosed file would warn now (ResourceWarning: an error in these tests)


def test_missing_file():
    with pytest.raises(SonarRasterError, match="no such file"):
        read_xtf("/nonexistent/file.xtf")


# ---------------------------------------------------------------- the CLI


@needs_sample
def test_cli_track_writes_csv(tmp_path, capsys):
    out = tmp_path / "alt.csv"
    assert main(["track", str(SAMPLE), "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "461 pings" in text and "SensorPrimaryAltitude" in text
    rows = out.read_text().strip().splitlines()
    assert rows[0].startswith("ping,altitude_m,valid")
    assert len(rows) == 462
    alt = np.array([float(r.split(",")[1]) for r in rows[1:]])
    assert np.all((alt > 1.0) & (alt < 20.0))


@needs_sample
def test_cli_track_png(tmp_path):
    out = tmp_path / "alt.png"
    assert main(["track", str(SAMPLE), "-o", str(out), "--quiet", "--pings", "0:100"]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in tmp_path.iterdir()] == ["alt.png"]


# ---------------------------------------------------------------- georeferencing and inversion


def test_ground_positions_analytic():
    from sonar_raster.inversion.xtf import ground_positions

    east, north = np.array([100.0, 100.0]), np.array([200.0, 200.0])
    heading = np.radians([90.0, 0.0])  # east, north
    pitch = np.radians([0.0, -20.0])  # level; nose down
    x = np.array([1.0, 5.0])
    z = np.full((2, 2), -4.0)
    e, n = ground_positions(east, north, heading, pitch, x, z, "starboard")
    # heading east: starboard is south
    np.testing.assert_allclose(e[0], [100.0, 100.0], atol=1e-12)
    np.testing.assert_allclose(n[0], [199.0, 195.0], atol=1e-12)
    # heading north: starboard is east; nose down 20 deg tilts the fan: 4 m down the fan
    # is 4 sin 20 behind (and 4 cos 20 below)
    np.testing.assert_allclose(e[1], [101.0, 105.0], atol=1e-12)
    np.testing.assert_allclose(n[1], 200.0 - 4.0 * math.sin(math.radians(20.0)), atol=1e-12)
    e, n = ground_positions(east, north, heading, pitch, x, z, "port")
    np.testing.assert_allclose(n[0], [201.0, 205.0], atol=1e-12)


def test_geotiff_places_values_at_their_coordinates(tmp_path):
    """Grid a layer whose value is its own easting (and one its northing): read back through
    rasterio, each pixel's value (a mean of samples inside it) must lie within one pixel of
    its centre's coordinates."""
    import rasterio

    from sonar_raster.inversion.xtf import geotiff_jobs, grid, ground_positions
    from sonar_raster.io.commit import commit

    pings = 60
    heading = np.full(pings, math.radians(30.0))
    along = np.arange(pings) * 0.2
    east = 512000.0 + along * math.sin(heading[0])
    north = 5365000.0 + along * math.cos(heading[0])
    x = (np.arange(200) + 0.5) * 0.05
    z = np.full((pings, len(x)), -5.0)
    samples = []
    for side in ("port", "starboard"):
        e, n = ground_positions(east, north, heading, np.zeros(pings), x, z, side)
        # float32 rasters: store the coordinates relative to the first ping
        layers = {"elevation": e - east[0], "reflectivity": n - north[0], "mosaic": 0 * e}
        samples.append((e, n, layers))
    raster = grid(samples, 0.1, "EPSG:32619", along_factor=3)
    commit(geotiff_jobs(tmp_path, raster))
    with rasterio.open(tmp_path / "elevation.tif") as src:
        assert src.crs.to_epsg() == 32619
        values = src.read(1)
        rows, cols = np.nonzero(np.isfinite(values))
        t = src.transform  # pixel centres, north up (affine's `*` warns in rasterio's xy)
        assert t.b == 0 and t.d == 0 and t.e == -t.a
        xs, ys = t.c + (cols + 0.5) * t.a, t.f + (rows + 0.5) * t.e
        assert len(rows) > 0.3 * values.size
        assert np.max(np.abs(values[rows, cols] - (xs - east[0]))) <= 0.1
    with rasterio.open(tmp_path / "reflectivity.tif") as src:
        values = src.read(1)
        assert np.max(np.abs(values[rows, cols] - (ys - north[0]))) <= 0.1


@needs_sample
def test_invert_real_file(tmp_path, capsys):
    """Both sides of a crop of the sample file across the wreck: finite R, Φ, Z on every
    covered cell, E never rising, products per side and GeoTIFFs in UTM zone 19N."""
    import json

    import OpenImageIO as oiio
    import rasterio

    out = tmp_path / "inv"
    status = main(
        ["invert", str(SAMPLE), "-o", str(out), "--pings", "288:312", "--max-iter", "15",
         "--levels", "2", "--no-mesh", "--no-previews", "--quiet"]
    )  # fmt: skip
    assert status == 0, capsys.readouterr().err
    for side in ("port", "starboard"):
        doc = json.loads((out / side / "inversion.json").read_text())
        for level in doc["energy_per_iteration"]:
            assert len(level) > 1 and np.all(np.diff(level) <= 1e-12 * level[0])
        maps = {}
        for name in ("elevation", "reflectivity", "beam", "ground"):
            buf = oiio.ImageBuf(str(out / side / f"{name}.exr"))
            maps[name] = buf.get_pixels(oiio.FLOAT)[:, :, 0]
        covered = np.isfinite(maps["ground"])
        assert covered.mean() > 0.95
        for name in ("elevation", "reflectivity", "beam"):
            assert np.all(np.isfinite(maps[name][covered])), name
        assert np.all(maps["elevation"][covered] < 0)  # below the transducer
    csv = (out / "bottom_track.csv").read_text().splitlines()
    assert len(csv) == 25
    with rasterio.open(out / "elevation.tif") as src:
        assert src.crs.to_epsg() == 32619
        z = src.read(1)
        z = z[np.isfinite(z)]
        # sensor depth ~21.5 m + altitude ~4.2 m: the seabed lies ~26 m down
        assert 20.0 < -np.median(z) < 32.0
    for name in ("reflectivity.tif", "mosaic.tif"):
        assert (out / name).is_file()
    _wreck_stands_above_seabed(out / "starboard")


def _wreck_stands_above_seabed(directory: Path) -> None:
    """The wreck, found by its acoustic shadow in the starboard image (cells from the start
    of the highlight to the start of the shadow, in ground range), rises above the open
    seabed beyond the shadow: the top tenth of its recovered Z lies above the seabed's 99th
    percentile."""
    import json

    import OpenImageIO as oiio

    from sonar_raster.inversion.shadows import find_shadows, object_pings

    image, _ = read_xtf(SAMPLE, pings=slice(288, 312))
    doc = json.loads((directory / "inversion.json").read_text())
    alt, dr = np.array(doc["altitude_m"]), image.sonar.range_bin
    axis = doc["ground_axis"]
    x = axis["first_centre_m"] + axis["spacing_m"] * np.arange(axis["cells"])
    z = oiio.ImageBuf(str(directory / "elevation.exr")).get_pixels(oiio.FLOAT)[:, :, 0]
    found = find_shadows(image.sides["starboard"].astype(np.float64) ** 2, dr, alt)
    wreck = object_pings(found.height)
    assert wreck.sum() >= 20  # the hull's shadow is on every ping of this crop

    def ground(k, h):
        return np.sqrt(np.maximum((k * dr) ** 2 - h * h, 0.0))

    on, off = [], []
    for i in np.flatnonzero(wreck):
        lo, hi = ground(found.highlight[i], alt[i]), ground(found.start[i], alt[i])
        on.append(z[i][(x >= lo) & (x <= hi)])
        off.append(z[i][x >= ground(found.end[i], alt[i]) + 2.0])
    on, off = np.concatenate(on), np.concatenate(off)
    on, off = on[np.isfinite(on)], off[np.isfinite(off)]  # cells with an estimate
    assert on.size > 20 and off.size > 100
    assert np.percentile(on, 90) > np.percentile(off, 99)


def test_invert_xtf_writes_every_product_or_none(tmp_path, monkeypatch, capsys):
    """A failure while writing the last file (a GeoTIFF) leaves no side's products behind."""
    if not SAMPLE.is_file():
        pytest.skip(f"{SAMPLE} not present")
    import sonar_raster.inversion.xtf as inv_xtf

    def broken(directory, raster):
        def fail(tmp):
            raise OSError(28, "No space left on device")

        return [(directory / "mosaic.tif", fail)]

    monkeypatch.setattr(inv_xtf, "geotiff_jobs", broken)
    out = tmp_path / "inv"
    status = main(
        ["invert", str(SAMPLE), "-o", str(out), "--pings", "288:312", "--max-iter", "2",
         "--levels", "1", "--no-mesh", "--no-previews", "--quiet"]
    )  # fmt: skip
    assert status == 2 and "No space left" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize("marker", [float("nan"), float(np.finfo(np.float32).max), -1e35])
def test_a_few_no_data_samples_of_a_float_file_become_zero_and_are_counted(
    tmp_path, simulated, caplog, marker
):
    """NaN or a huge no-data marker (float32's largest, as processing programs write it)."""
    import struct

    image, track = simulated
    marked = {s: v.astype(np.float32).copy() for s, v in image.sides.items()}
    marked["starboard"][5, 100] = marked["port"][7, 3] = 12345.678  # found again in the bytes
    marked["starboard"][9, :40] = 23456.789  # 40 of 300 samples: over MAX_BLANKED, skipped
    path = write_xtf(tmp_path / "sim.xtf", replace(image, sides=marked), track)
    data = path.read_bytes()
    for value in (12345.678, 23456.789):
        data = data.replace(struct.pack("<f", value), struct.pack("<f", marker))
    path.write_bytes(data)
    back, _ = read_xtf(path)
    assert back.metadata["ping_indices"] == [k for k in range(40) if k != 9]
    assert back.metadata["blanked_samples"] == 2
    assert back.sides["starboard"][5, 100] == 0.0 and back.sides["port"][7, 3] == 0.0
    assert np.all(np.isfinite(back.sides["starboard"]))
    assert "set 2 non-finite or no-data samples to 0 (no echo) in 2 pings" in caplog.text
