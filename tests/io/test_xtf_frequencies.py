"""Dual-frequency XTF files: several images written as one file, one pair of channels read."""

from __future__ import annotations

import json
import logging
import math
from dataclasses import replace

import numpy as np
import pytest

from sonar_raster.cli.app import main
from sonar_raster.errors import SonarRasterError
from sonar_raster.image import SonarImage
from sonar_raster.io.images import read_exr
from sonar_raster.io.xtf import XtfReader, read_xtf, read_xtf_track, write_xtf, xtf_frequencies
from sonar_raster.sonar import Sonar
from sonar_raster.trajectory import Trajectory

pyxtf = pytest.importorskip("pyxtf")

PINGS = 30


def _band(khz: float, bins: int, range_bin: float, seed: int, pings: int = PINGS) -> SonarImage:
    """Two sides of distinct random intensities (no two bands share a value), a seabed from
    12 m of slant range on."""
    sonar = Sonar(
        frequency_hz=khz * 1e3, max_range=bins * range_bin, range_bin=range_bin,
        tilt=math.radians(10.0),
    )  # fmt: skip
    rng = np.random.default_rng(seed)
    water = (np.arange(bins) + 0.5) * range_bin < 12.0
    sides = {
        s: np.where(water, 0.0, rng.exponential(1.0 + seed, (pings, bins))).astype(np.float32)
        for s in sonar.sides
    }
    return SonarImage(sides, sonar, {})


@pytest.fixture(scope="module")
def dual(tmp_path_factory):
    """A 445 / 900 kHz file (low pair first, as Klein and EdgeTech record them) and its bands."""
    low, high = _band(445.0, 300, 0.1, 1), _band(900.0, 500, 0.03, 2)
    track = Trajectory.straight((50.0, 80.0, -20.0), 30.0, 0.2, PINGS)
    path = write_xtf(tmp_path_factory.mktemp("dual") / "dual.xtf", [low, high], track)
    return path, low, high


def _same(image: SonarImage, band: SonarImage) -> None:
    for side in band.sides:
        np.testing.assert_array_equal(image.sides[side], band.sides[side])
    assert image.sonar.frequency_hz == band.sonar.frequency_hz
    assert image.sonar.range_bin == pytest.approx(band.sonar.range_bin, rel=1e-6)


def test_the_file_holds_four_channels_each_with_its_frequency(dual):
    path, low, high = dual
    header, packets = pyxtf.xtf_read(str(path))
    assert header.NumberOfSonarChannels == 4
    assert [header.ChanInfo[k].Frequency for k in range(4)] == [445.0, 445.0, 900.0, 900.0]
    ping = packets[pyxtf.XTFHeaderType.sonar][0]
    assert [c.NumSamples for c in ping.ping_chan_headers] == [300, 300, 500, 500]


def test_the_first_pair_is_read_by_default_and_the_others_are_named(dual, caplog):
    path, low, _ = dual
    with caplog.at_level(logging.WARNING, logger="sonar_raster.io.xtf"):
        image, _ = read_xtf(path)
    _same(image, low)
    assert image.metadata["channels"] == {"port": 0, "starboard": 1}
    said = " ".join(r.getMessage() for r in caplog.records)
    assert "445 kHz, 900 kHz" in said and "--xtf-frequency" in said


@pytest.mark.parametrize("choice", ["high", 900e3, 880e3])
def test_the_high_pair_is_read_when_asked(dual, choice, caplog):
    path, _, high = dual
    with caplog.at_level(logging.WARNING, logger="sonar_raster.io.xtf"):
        image, nav = read_xtf(path, frequency=choice)
    _same(image, high)
    assert image.metadata["channels"] == {"port": 2, "starboard": 3}
    assert nav.valid.all() and not caplog.records  # a choice made: nothing to say
    track, _, again = read_xtf_track(path, slice(5, 10), frequency=choice)
    assert track.n_pings == 5 and again.shape == (5, 500)


@pytest.mark.parametrize("choice", ["low", 445e3])
def test_the_low_pair_is_read_when_asked(dual, choice):
    path, low, _ = dual
    _same(read_xtf(path, frequency=choice)[0], low)


@pytest.mark.parametrize(
    ("choice", "says"),
    [(600e3, "no side-scan channels at 600 kHz (it has 445 kHz, 900 kHz)"),
     ("middle", "'low', 'high' or a number"), (-1.0, "positive number")],
)  # fmt: skip
def test_a_choice_the_file_cannot_meet_is_one_clear_error(dual, choice, says):
    with pytest.raises(SonarRasterError, match=r".*") as err:
        XtfReader(dual[0], frequency=choice)
    assert says in str(err.value) and "\n" not in str(err.value)


def test_pairs_without_recorded_frequencies_go_by_order(dual, tmp_path, caplog):
    path, low, high = dual
    raw = bytearray(path.read_bytes())
    header = pyxtf.XTFFileHeader.create_from_buffer(bytes(raw[:1024]))
    for k in range(4):
        header.ChanInfo[k].Frequency = 0.0
    raw[:1024] = header.to_bytes()[:1024]
    blind = tmp_path / "blind.xtf"
    blind.write_bytes(bytes(raw))
    with caplog.at_level(logging.WARNING, logger="sonar_raster.io.xtf"):
        image, _ = read_xtf(blind)
    np.testing.assert_array_equal(image.sides["port"], low.sides["port"])
    assert "ChanInfo [0, 1]" in caplog.text and "channels [2, 3]" in caplog.text
    with pytest.raises(SonarRasterError, match="cannot be told apart"):
        read_xtf(blind, frequency="high")


def test_a_pair_recorded_a_little_apart_stays_one_pair(dual, tmp_path):
    """445 / 446 kHz on the two sides of one pair (a header's rounding) is one pair."""
    path, low, high = dual
    raw = bytearray(path.read_bytes())
    header = pyxtf.XTFFileHeader.create_from_buffer(bytes(raw[:1024]))
    header.ChanInfo[1].Frequency = 446.0
    raw[:1024] = header.to_bytes()[:1024]
    near = tmp_path / "near.xtf"
    near.write_bytes(bytes(raw))
    image, _ = read_xtf(near, frequency="low")
    _same(image, low)
    assert image.metadata["channels"] == {"port": 0, "starboard": 1}
    _same(read_xtf(near, frequency="high")[0], high)


def test_a_single_frequency_file_reads_as_before(tmp_path, caplog):
    band = _band(600.0, 200, 0.05, 3)
    track = Trajectory.straight((0.0, 0.0, -10.0), 0.0, 0.2, PINGS)
    path = write_xtf(tmp_path / "one.xtf", band, track)
    with caplog.at_level(logging.WARNING, logger="sonar_raster.io.xtf"):
        for choice in (None, "low", "high", 600e3):
            _same(read_xtf(path, frequency=choice)[0], band)
    assert not caplog.records
    with pytest.raises(SonarRasterError, match="it has 600 kHz"):
        read_xtf(path, frequency=900e3)


def test_images_of_unequal_pings_are_not_written(tmp_path):
    low, high = _band(445.0, 100, 0.1, 1), _band(900.0, 100, 0.03, 2)
    short = replace(high, sides={s: v[:-1] for s, v in high.sides.items()})
    track = Trajectory.straight((0.0, 0.0, -20.0), 0.0, 0.2, PINGS)
    with pytest.raises(SonarRasterError, match="30, 29 pings"):
        write_xtf(tmp_path / "bad.xtf", [low, short], track)
    assert not list(tmp_path.iterdir())


def test_cli_reads_the_pair_asked_for(dual, tmp_path, capsys):
    path = dual[0]
    out = tmp_path / "alt.csv"
    assert main(["track", str(path), "-o", str(out), "-q", "--xtf-frequency", "900"]) == 0
    assert len(out.read_text().strip().splitlines()) == PINGS + 1
    code = main(["track", str(path), "-o", str(tmp_path / "x.csv"), "--xtf-frequency", "600"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "445 kHz, 900 kHz" in err[0]
    assert main(["track", str(path), "-q", "--xtf-frequency", "abc"]) == 2
    assert "--xtf-frequency 'abc'" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["alt.csv"]


def test_pairs_are_matched_by_frequency_not_by_order(tmp_path):
    """Channels recorded port 900, starboard 445, port 445, starboard 900 kHz: each side is
    paired with its own frequency's other side (in order they would mix the frequencies)."""
    low, high = _band(445.0, 300, 0.1, 1), _band(900.0, 500, 0.03, 2)

    def one(band: SonarImage, side: str) -> SonarImage:
        sonar = replace(band.sonar, sides=(side,))
        return SonarImage({side: band.sides[side]}, sonar, {})

    track = Trajectory.straight((50.0, 80.0, -20.0), 30.0, 0.2, PINGS)
    order = [one(high, "port"), one(low, "starboard"), one(low, "port"), one(high, "starboard")]
    path = write_xtf(tmp_path / "mixed.xtf", order, track)
    image, _ = read_xtf(path, frequency="high")
    _same(image, high)
    assert image.metadata["channels"] == {"port": 0, "starboard": 3}
    image, _ = read_xtf(path, frequency="low")
    _same(image, low)
    assert image.metadata["channels"] == {"port": 2, "starboard": 1}


@pytest.fixture(scope="module")
def dual_line(tmp_path_factory):
    """A longer 445 / 900 kHz line with a seabed at 12 m of slant range, to insert into."""
    low, high = (
        _band(k, n, b, s, pings=120) for k, n, b, s in ((445, 300, 0.1, 1), (900, 500, 0.03, 2))
    )
    track = Trajectory.straight((0.0, 0.0, -12.0), 0.0, 0.2, 120)
    path = write_xtf(tmp_path_factory.mktemp("line") / "dual.xtf", [low, high], track)
    return path, low, high


@pytest.mark.parametrize("choice", [None, "high"])
def test_insert_changes_the_pair_asked_for_and_keeps_the_other(dual_line, tmp_path, choice):
    path, low, high = dual_line
    argv = ["insert", str(path), "-o", str(tmp_path / "out"), "-q", "--object", "box",
            "--at", "60,8"]  # fmt: skip
    assert main(argv + (["--xtf-frequency", choice] if choice else [])) == 0
    changed, kept = (high, low) if choice == "high" else (low, high)
    with_objects = {}
    for band in (low, high):
        image, _ = read_xtf(tmp_path / "out.xtf", frequency=band.sonar.frequency_hz)
        with_objects[band is changed] = image
    _same(with_objects[False], kept)
    image = with_objects[True]
    differs = np.abs(image.sides["starboard"] - changed.sides["starboard"]).max(axis=1) > 0
    assert 0 < differs.sum() < 120 and differs[60]  # the box's pings, from the changed pair
    np.testing.assert_array_equal(image.sides["port"], changed.sides["port"])


def test_render_reads_the_track_of_the_pair_asked_for(dual_line, tmp_path, capsys):
    path = str(dual_line[0])
    out = str(tmp_path / "x.png")
    code = main(["render", "default", "-o", out, "--xtf-frequency", "high"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "give --track" in err[0]
    code = main(["render", "default", "-o", out, "--track", path, "--xtf-frequency", "600"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "445 kHz, 900 kHz" in err[0]
    assert list(tmp_path.iterdir()) == []
    argv = ["render", "default", "-o", out, "--track", path, "--xtf-frequency", "high", "-q"]
    assert main(argv) == 0 and capsys.readouterr().err == ""  # no word on the other pair


def test_render_writes_two_presets_as_one_dual_frequency_file(tmp_path, capsys):
    """``--sensor A,B``: one image per preset over one track, their channels in one XTF and a
    PNG each; the first preset's image is the one a render of it alone makes (same seed)."""
    dual, alone = tmp_path / "dual", tmp_path / "alone"
    dual.mkdir()
    alone.mkdir()
    common = ["render", "default", "--pings", "30", "--seed", "3", "-q"]
    argv = [*common, "--sensor", "klein-3900-445,klein-3900-900"]
    assert main([*argv, "-o", str(dual / "out.xtf"), "-o", str(dual / "out.png")]) == 0
    assert main([*common, "--sensor", "klein-3900-445", "-o", str(alone / "out.xtf")]) == 0
    names = sorted(p.name for p in dual.iterdir())
    assert names == sorted(
        f"out{s}" for s in (".xtf", ".klein-3900-445.png", ".klein-3900-445.json",
                            ".klein-3900-900.png", ".klein-3900-900.json")
    )  # fmt: skip
    low, _ = read_xtf(dual / "out.xtf", frequency="low")
    high, _ = read_xtf(dual / "out.xtf", frequency="high")
    single, _ = read_xtf(alone / "out.xtf")
    assert (low.sonar.frequency_hz, high.sonar.frequency_hz) == (445e3, 900e3)
    assert low.shape == (30, 4000) and high.shape == (30, 5333)  # each preset's bins
    _same(low, single)
    assert not np.array_equal(high.sides["starboard"][:, :100], low.sides["starboard"][:, :100])


@pytest.mark.parametrize(
    ("sensor", "more", "says"),
    [
        ("klein-3900-445,klein-3900-445", [], "different presets once each"),
        ("klein-3900-445,nope", [], "nope"),
        ("klein-3900-445,klein-3900-900", ["--frequency", "400"], "--frequency with several"),
        ("klein-3900-445,klein-3900-900", ["--ideal"], "one --sensor preset at a time"),
    ],
)
def test_render_with_presets_it_cannot_combine_is_one_line(tmp_path, capsys, sensor, more, says):
    argv = ["render", "default", "--pings", "8", "--sensor", sensor, *more]
    assert main([*argv, "-o", str(tmp_path / "out.xtf")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and says in err[0], err
    assert list(tmp_path.iterdir()) == []


def test_two_presets_stream_a_long_track_block_by_block(tmp_path):
    """``--sensor A,B --chunk-pings N`` (a track too long to hold streams so too): each preset
    streamed to its own EXR and PNG, one XTF of both read back from them; the first preset's
    band is the one its streamed render alone makes, the second its own EXR."""
    dual, alone = tmp_path / "dual", tmp_path / "alone"
    dual.mkdir()
    alone.mkdir()
    common = ["render", "default", "--pings", "40", "--seed", "2", "-q", "--chunk-pings", "16"]
    argv = [*common, "--sensor", "klein-3900-445,klein-3900-900", "-o", str(dual / "d.xtf")]
    assert main([*argv, "-o", str(dual / "d.exr"), "-o", str(dual / "d.png")]) == 0
    assert main([*common, "--sensor", "klein-3900-445", "-o", str(alone / "one.xtf")]) == 0
    names = sorted(p.name for p in dual.iterdir())
    expected = [f"d.{k}.{e}" for k in ("klein-3900-445", "klein-3900-900")
                for e in ("exr", "json", "png")]  # fmt: skip
    assert names == sorted([*expected, "d.xtf"])
    low, _ = read_xtf(dual / "d.xtf", frequency="low")
    high, _ = read_xtf(dual / "d.xtf", frequency="high")
    assert low.shape == (40, 4000) and high.shape == (40, 5333)
    _same(low, read_xtf(alone / "one.xtf")[0])
    exr, attrs = read_exr(dual / "d.klein-3900-900.exr")
    assert attrs["sonar:frequency_hz"] == pytest.approx(900e3)
    for side, values in exr.items():
        np.testing.assert_array_equal(values, high.sides[side])


@pytest.mark.parametrize("at", [["--at", "60,8"], []])
def test_insert_into_every_pair_puts_one_object_in_each(dual_line, tmp_path, capsys, at):
    """``--xtf-frequency all``: the object in both pairs at one ping and ground range (a drawn
    place chosen where the shorter swath holds it), each pair's own labels, one XTF."""
    path, low, high = dual_line
    assert xtf_frequencies(path) == [445e3, 900e3]
    argv = ["insert", str(path), "-o", str(tmp_path / "out"), "--object", "box", *at]
    assert main([*argv, "--xtf-frequency", "all", "--seed", "5"]) == 0
    assert "into 2 channel pairs: 445, 900 kHz" in capsys.readouterr().out
    names = {p.name for p in tmp_path.iterdir()}
    for khz in ("445", "900"):
        assert {f"out.{khz}kHz.{e}" for e in ("png", "txt", "coco.json", "objects.json")} <= names
    assert "out.xtf" in names and "out.png" not in names
    places, rows = [], []
    for band, khz in ((low, "445"), (high, "900")):
        image, _ = read_xtf(tmp_path / "out.xtf", frequency=band.sonar.frequency_hz)
        np.testing.assert_array_equal(image.sides["port"], band.sides["port"])
        differs = np.abs(image.sides["starboard"] - band.sides["starboard"]).max(axis=1) > 0
        assert 0 < differs.sum() < 120
        rows.append(differs)
        doc = json.loads((tmp_path / f"out.{khz}kHz.objects.json").read_text())
        places.append([(o["ping"], o["ground_range_m"]) for o in doc["objects"]])
    assert places[0] == places[1] and len(places[0]) == 1
    ping, ground = places[0][0]
    assert rows[0][ping] and rows[1][ping]  # the object's own ping, in both pairs
    assert ground < 9.0  # inside the 900 kHz swath (15 m of slant range at 12 m)
