"""Several survey lines: XTF files written by the project, inverted and gridded together in
world coordinates; the overlap's inverse-variance mean; the line splitter; bad inputs."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from sonar_raster.cli.app import main
from sonar_raster.errors import SonarRasterError
from sonar_raster.image import SonarImage
from sonar_raster.inversion.lines import combine, grid_lines, split_lines
from sonar_raster.io.xtf import write_xtf
from sonar_raster.sonar import BeamPattern, Sonar
from sonar_raster.trajectory import Trajectory

#: Projected origin of the local scene (UTM-like metres), seabed depth, altitude, geometry.
ORIGIN = (500_000.0, 6_100_000.0)
SEABED, ALT, BIN, RANGE, SPACING, PINGS = -20.0, 6.0, 0.05, 12.0, 0.2, 60
#: Lines at these local eastings (m), north then south then north (a lawnmower).
LINES_X = (-7.0, 0.0, 7.0)
#: The mound: local (east, north), height, std (m).
MOUND = (3.0, 6.0, 0.8, 0.8)
SONAR = Sonar(
    max_range=RANGE,
    range_bin=BIN,
    beam=BeamPattern.gaussian(50.0),
    tilt=math.radians(20.0),
    sides=("port", "starboard"),
)


def _seabed(length: float = PINGS * SPACING):
    from sonar_raster.scene import build_scene
    from sonar_raster.scenes.seabed import from_grid

    cell = 0.05
    x = np.arange(-22.0, 22.0 + cell / 2, cell)
    y = np.arange(-6.0, length + 6.0 + cell / 2, cell)
    xx, yy = np.meshgrid(x, y)
    mx, my, h, s = MOUND
    z = SEABED + h * np.exp(-((xx - mx) ** 2 + (yy - my) ** 2) / (2 * s * s))
    field = from_grid(z, cell, cell, x0=-22.0, y0=-6.0)
    return build_scene([field.mesh(np.full(xx.shape, 0.5))])


def _track(k: int) -> Trajectory:
    """Line k: north along x = LINES_X[k] for even k, south for odd k, over the same stretch."""
    length = (PINGS - 1) * SPACING
    if k % 2 == 0:
        return Trajectory.straight((LINES_X[k], 0.0, SEABED + ALT), 0.0, SPACING, PINGS)
    return Trajectory.straight((LINES_X[k], length, SEABED + ALT), 180.0, SPACING, PINGS)


def _write(path: Path, image: SonarImage, track: Trajectory, origin=ORIGIN) -> Path:
    """As amplitude samples (the XTF inversion squares them back into intensity)."""
    amp = {k: np.sqrt(np.maximum(v, 0.0)).astype(np.float32) for k, v in image.sides.items()}
    return write_xtf(path, SonarImage(amp, image.sonar, {}), track, altitude=ALT, origin=origin)


@pytest.fixture(scope="module")
def survey(tmp_path_factory, gl_renderer):
    """Three overlapping lines over a mound as three XTF files."""
    folder = tmp_path_factory.mktemp("survey")
    scene = _seabed()
    paths = []
    for k in range(len(LINES_X)):
        image = gl_renderer.render(scene, SONAR, _track(k))
        paths.append(_write(folder / f"line{k}.xtf", image, _track(k)))
    return paths


def _read_tif(path: Path):
    import rasterio

    with rasterio.open(path) as src:
        return src.read(1), src.transform, src.crs, src.tags()


def _grid(z: np.ndarray, transform) -> tuple[np.ndarray, np.ndarray]:
    """Local easting and northing of each pixel centre of a GeoTIFF."""
    rows, cols = np.indices(z.shape)
    east = transform.c + (cols + 0.5) * transform.a - ORIGIN[0]
    north = transform.f + (rows + 0.5) * transform.e - ORIGIN[1]
    return east, north


def _mound_peak(path: Path) -> tuple[float, float, float, float]:
    """(east, north) of the centroid of the rise within 2.5 m of the mound, the level and the
    mean rise within 1 m of the mound's centre."""
    z, transform, _, _ = _read_tif(path)
    east, north = _grid(z, transform)
    r = np.hypot(east - MOUND[0], north - MOUND[1])
    level = float(np.median(z[np.isfinite(z) & (r > 3.0)]))
    rise = np.where(np.isfinite(z) & (r < 2.5), np.maximum(z - level, 0.0), 0.0)
    top = float(np.nanmean(z[r < 1.0])) - level
    return (float((rise * east).sum() / rise.sum()), float((rise * north).sum() / rise.sum()),
            level, top)  # fmt: skip


def test_three_xtf_lines_are_gridded_in_world_coordinates(survey, tmp_path, capsys):
    """Real inversions (profiles) of three lines: the level in the sea-surface datum and the
    mound at its easting/northing. Each line alone puts the mound's rise 0.5-0.8 m towards its
    own track (the inversion's bias, not the placement); the two lines that look at it from
    opposite sides (line 2 from the west, line 3 from the east) straddle it."""
    out = tmp_path / "inv"
    args = ["invert", *map(str, survey), "-o", str(out), "--levels", "1", "--max-iter", "20"]
    assert main([*args, "--no-mesh", "--no-previews"]) == 0, capsys.readouterr().err
    printed = capsys.readouterr().out
    assert "3 lines: line0.xtf pings 0:60, line1.xtf pings 0:60" in printed
    assert "elevation datum: sea surface" in printed
    tags = _read_tif(out / "elevation.tif")[3]
    assert "sea surface" in tags["description"]
    pixel = _read_tif(out / "elevation.tif")[1].a
    for name in ("elevation", "reflectivity", "mosaic"):
        assert (out / f"{name}.tif").is_file() and (out / f"{name}.png").is_file()
    assert not (out / "elevation_std.tif").exists()  # the profiles have no std
    for k in (1, 2, 3):
        doc = json.loads((out / f"line_{k}" / "line.json").read_text())
        assert doc["pings"] == [0, 60] and doc["source"].endswith(f"line{k - 1}.xtf")
        assert (out / f"line_{k}" / "port" / "elevation.exr").is_file()
    east, north, level, top = _mound_peak(out / "elevation.tif")
    assert abs(level - SEABED) < 0.1, level  # the sensor depth (14 m) + the inverted 6 m
    assert top > 0.08, top  # the mound is there (0.16 m; truth 0.58 m: the fit is shallow)
    assert abs(north - MOUND[1]) < pixel, north  # along track: ping positions
    west_look, east_look = (_mound_peak(out / f"line_{k}" / "elevation.tif") for k in (2, 3))
    assert min(west_look[3], east_look[3]) > 0.08, (west_look, east_look)  # 0.16, 0.12
    assert west_look[0] < MOUND[0] < east_look[0]  # each pulled towards its own track
    middle = 0.5 * (west_look[0] + east_look[0])
    assert abs(middle - MOUND[0]) < 2 * pixel, (west_look, east_look)


def _truth_line(calls: list, stds=(0.1, 0.2, 0.1)):
    """A stand-in for the surface fit: line k's true elevation below the transducer at its
    ground cells (from the known track), with a constant std per line."""
    from sonar_raster.inversion.solver import BeamProfile, Inversion

    def fake(sides, range_bin, *, ping_spacing, altitude=None, **kwargs):
        k = len(calls)
        calls.append(kwargs)
        track = _track(k)
        x = (np.arange(200) + 0.5) * 0.05
        mx, my, h, s = MOUND
        out = {}
        for side in sides:
            sign = 1.0 if side == "starboard" else -1.0
            right = np.stack([np.cos(track.headings), -np.sin(track.headings)], axis=1)
            e = track.positions[:, :1] + sign * right[:, :1] * x
            n = track.positions[:, 1:2] + sign * right[:, 1:] * x
            z = SEABED + h * np.exp(-((e - mx) ** 2 + (n - my) ** 2) / (2 * s * s))
            z = z - track.positions[:, 2:3]
            ones = np.ones_like(z)
            out[side] = Inversion(
                x, np.full(len(z), ALT), ones, (k + 1) * ones, ones, z,
                BeamProfile(np.array([0.1, 1.0]), np.ones(2)), ping_spacing=ping_spacing,
                even=(k + 1) * ones, elevation_std=np.full_like(z, stds[k]),
            )  # fmt: skip
        return out

    def fake_lines(lines, **kwargs):  # the joint fit: one call, the lines in order
        return [fake(line.sides, line.range_bin, ping_spacing=0.1, **kwargs) for line in lines]

    return fake_lines


def test_surface_lines_land_in_place_and_combine_by_inverse_variance(
    survey, tmp_path, capsys, monkeypatch
):
    """``--method surface`` through invert_lines (here a stand-in returning the truth with a
    std of 0.1, 0.2, 0.1 m per line): every pixel holds the true seabed at its centre, the
    std where two or three lines overlap is 1 / sqrt(sum 1/σ²), and each line's products and
    elevation_std.tif are written."""
    from sonar_raster.inversion import surface

    calls: list = []
    monkeypatch.setattr(surface, "invert_lines", _truth_line(calls))
    out = tmp_path / "inv"
    args = ["invert", *map(str, survey), "-o", str(out), "--method", "surface", "-q"]
    assert main([*args, "--no-mesh", "--no-previews", "--max-iter", "7"]) == 0
    assert len(calls) == 3 and calls[0]["max_iter"] == 7
    z, transform, _, _ = _read_tif(out / "elevation.tif")
    east, north = _grid(z, transform)
    mx, my, h, s = MOUND
    truth = SEABED + h * np.exp(-((east - mx) ** 2 + (north - my) ** 2) / (2 * s * s))
    inside = np.isfinite(z)
    assert inside.mean() > 0.5
    # the footprints grid a smooth field to within its curvature over a pixel
    assert np.abs(z - truth)[inside].max() < 0.02, np.abs(z - truth)[inside].max()
    peak = np.unravel_index(np.nanargmax(z), z.shape)
    assert math.hypot(east[peak] - mx, north[peak] - my) < transform.a
    std = _read_tif(out / "elevation_std.tif")[0]
    seen = np.stack([np.isfinite(_read_tif(out / f"line_{k}" / "elevation.tif")[0])
                     for k in (1, 2, 3)])  # fmt: skip
    w = np.array([1 / 0.1**2, 1 / 0.2**2, 1 / 0.1**2])[:, None, None]
    covered = seen.any(axis=0)
    expected = 1.0 / np.sqrt((w * seen).sum(axis=0)[covered])
    np.testing.assert_allclose(std[covered], expected, rtol=1e-5)
    assert set(np.round(np.unique(expected), 4)) >= {0.1, 0.0894, 0.0667}  # line 2 is never alone
    refl = _read_tif(out / "reflectivity.tif")[0]  # R = line number: the plain mean
    plain = (seen * np.array([1.0, 2.0, 3.0])[:, None, None]).sum(0)[covered] / seen.sum(0)[covered]
    np.testing.assert_allclose(refl[covered], plain, rtol=1e-5)
    assert (out / "elevation_std.png").is_file()
    assert (out / "line_2" / "starboard" / "elevation_std.exr").is_file()


def test_one_xtf_with_method_surface_grids_its_std(survey, tmp_path, capsys, monkeypatch):
    """One file with ``--method surface`` (it used to run the profiles silently; ``--coarsen``
    passed on): the fit's elevation and std (here the stand-in's truth and 0.1 m) are gridded
    beside the others."""
    from sonar_raster.inversion import surface

    calls: list = []
    monkeypatch.setattr(surface, "invert_lines", _truth_line(calls))
    out = tmp_path / "one"
    argv = ["invert", str(survey[0]), "-o", str(out), "--method", "surface", "--no-mesh"]
    assert main([*argv, "--no-previews", "--coarsen", "2", "-q"]) == 0, capsys.readouterr().err
    assert len(calls) == 1
    assert calls[0]["finest"] == 2  # --coarsen reaches the fit of an XTF line
    z, transform, _, _ = _read_tif(out / "elevation.tif")
    east, north = _grid(z, transform)
    mx, my, h, s = MOUND
    truth = SEABED + h * np.exp(-((east - mx) ** 2 + (north - my) ** 2) / (2 * s * s))
    assert np.nanmax(np.abs(z - truth)) < 0.02
    std = _read_tif(out / "elevation_std.tif")[0]
    np.testing.assert_allclose(std[np.isfinite(std)], 0.1, rtol=1e-5)
    assert (out / "elevation_std.png").is_file() and (out / "port" / "elevation_std.exr").is_file()


def test_a_failing_product_leaves_no_file_of_any_line(survey, tmp_path, capsys, monkeypatch):
    from sonar_raster.inversion import quicklook, surface

    def full(path, *args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(surface, "invert_lines", _truth_line([]))
    monkeypatch.setattr(quicklook, "mosaic_png", full)
    out = tmp_path / "inv"
    argv = ["invert", *map(str, survey), "-o", str(out), "--method", "surface", "--no-mesh"]
    assert main([*argv, "--no-previews", "-q"]) == 2
    assert "No space left" in capsys.readouterr().err
    assert not out.exists()


def _strip(east0: float, east1: float, z: float, std: float | None, refl: float):
    """A tiny starboard swath over east0..east1, north 0..2 m: constant layers."""
    pings, cells = 21, int(round((east1 - east0) / 0.1)) + 1
    north = np.repeat(np.linspace(0.0, 2.0, pings)[:, None], cells, axis=1)
    east = np.repeat(np.linspace(east0, east1, cells)[None, :], pings, axis=0)
    layers = {"elevation": np.full(east.shape, z), "reflectivity": np.full(east.shape, refl),
              "mosaic": np.full(east.shape, refl)}  # fmt: skip
    if std is not None:
        layers["elevation_var"] = np.full(east.shape, std * std)
    return {"starboard": (east, north, layers)}


def test_overlap_is_the_inverse_variance_mean_by_hand():
    """Two lines of constant layers overlapping over east 1-2 m: there z = (-10/0.01 - 11/0.04)
    / (1/0.01 + 1/0.04) = -10.2 m, std = 1/sqrt(125) = 0.0894 m, R the plain mean 2; elsewhere
    each line's own values."""
    out = grid_lines([_strip(0.0, 2.0, -10.0, 0.1, 1.0), _strip(1.0, 3.0, -11.0, 0.2, 3.0)],
                     0.1, None).combined  # fmt: skip
    east = out.west + (np.arange(out.layers["elevation"].shape[1]) + 0.5) * out.pixel
    row = out.layers["elevation"].shape[0] // 2
    both, only_a, only_b = (east > 1.2) & (east < 1.8), east < 0.8, east > 2.2
    z, std, refl = (out.layers[k][row] for k in ("elevation", "elevation_std", "reflectivity"))
    np.testing.assert_allclose(z[both], -10.2, atol=1e-5)
    np.testing.assert_allclose(std[both], 1 / math.sqrt(125.0), rtol=1e-5)
    np.testing.assert_allclose(refl[both], 2.0, rtol=1e-6)
    np.testing.assert_allclose(z[only_a], -10.0, atol=1e-5)
    np.testing.assert_allclose(std[only_b], 0.2, rtol=1e-5)
    # without a std the elevation is the plain mean too
    plain = grid_lines([_strip(0.0, 2.0, -10.0, None, 1.0), _strip(1.0, 3.0, -11.0, None, 3.0)],
                       0.1, None).combined  # fmt: skip
    assert "elevation_std" not in plain.layers
    np.testing.assert_allclose(plain.layers["elevation"][row][both], -10.5, atol=1e-5)


def test_lines_without_depth_are_aligned_on_the_first():
    """The "first line" datum: line 2 lies 0.7 m below line 1 where they overlap (its
    transducer was higher), so it is shifted up by 0.7 m and the overlap agrees."""
    lines = [_strip(0.0, 2.0, -6.0, None, 1.0), _strip(1.0, 3.0, -6.7, None, 1.0)]
    gridded = grid_lines(lines, 0.1, None, align=True)
    assert gridded.offsets == pytest.approx([0.0, 0.7], abs=1e-5)
    z = gridded.combined.layers["elevation"]
    np.testing.assert_allclose(z[np.isfinite(z)], -6.0, atol=1e-5)


def test_too_many_line_pixels_are_refused(monkeypatch):
    from sonar_raster.inversion import xtf

    lines = [_strip(0.0, 2.0, -6.0, None, 1.0), _strip(1.0, 3.0, -6.7, None, 1.0)]
    monkeypatch.setattr(xtf, "MAX_GRID_CELLS", 1000)  # one line's frame (651) still fits
    with pytest.raises(SonarRasterError, match="grid fewer lines"):
        grid_lines(lines, 0.1, None)


def test_lines_without_sensor_depth_are_levelled_on_the_first(gl_renderer, tmp_path, capsys):
    """Files with no sensor depth, line 2 flown 1 m higher: its elevation below its own
    transducer is 1 m deeper, so it is shifted up by the overlap's median difference and the
    gridded seabed is level, relative to the first line's transducer."""
    scene, paths = _seabed(), []
    for k, lift in enumerate((0.0, 1.0, 0.0)):
        line = _track(k)
        flown = Trajectory(line.positions + [0.0, 0.0, lift], line.headings, line.roll)
        image = gl_renderer.render(scene, SONAR, flown)
        recorded = flown.positions.copy()
        recorded[:, 2] = lift  # sensor depth -lift <= 0: the files record no depth
        track = Trajectory(recorded, line.headings, line.roll)
        paths.append(_write(tmp_path / f"l{k}.xtf", image, track))
    out = tmp_path / "inv"
    args = ["invert", *map(str, paths), "-o", str(out), "--levels", "1", "--max-iter", "20"]
    assert main([*args, "--no-mesh", "--no-previews"]) == 0, capsys.readouterr().err
    printed = capsys.readouterr().out
    assert "elevation datum: first line" in printed
    offsets = [json.loads((out / f"line_{k}" / "line.json").read_text())["elevation_offset_m"]
               for k in (1, 2, 3)]  # fmt: skip
    assert offsets[0] == 0.0 and abs(offsets[1] - 1.0) < 0.05 and abs(offsets[2]) < 0.05, offsets
    z, _, _, tags = _read_tif(out / "elevation.tif")
    assert "first line's mean transducer level" in tags["description"]
    assert abs(float(np.nanmedian(z)) + ALT) < 0.1  # 6 m below line 1's transducer


def test_combine_refuses_rasters_on_different_frames():
    a = grid_lines([_strip(0.0, 2.0, -6.0, None, 1.0)], 0.1, None).combined
    b = grid_lines([_strip(5.0, 7.0, -6.0, None, 1.0)], 0.1, None).combined
    with pytest.raises(SonarRasterError, match="one frame"):
        combine([a, b])


def _lawnmower(jitter_deg: float = 0.0, seed: int = 0):
    """Three 30 m legs 8 m apart joined by half-circle turns, pings 0.25 m apart.

    Returns east, north, heading and the legs' (start, stop) rows.
    """
    step, leg, radius = 0.25, 30.0, 4.0
    e, n, h, legs = [], [], [], []
    x0 = 0.0
    for k in range(3):
        up = k % 2 == 0
        count = int(leg / step)
        legs.append((len(e), len(e) + count))
        along = np.arange(count) * step
        e += [x0] * count
        n += list(along if up else leg - along)
        h += [0.0 if up else math.pi] * count
        if k < 2:  # turn east by a half circle
            arc = np.arange(1, int(math.pi * radius / step)) * step / radius
            cy = leg if up else 0.0
            e += list(x0 + radius - radius * np.cos(arc))
            n += list(cy + (radius * np.sin(arc) if up else -radius * np.sin(arc)))
            h += list(arc if up else math.pi - arc)
            x0 += 2 * radius
    heading = np.mod(np.array(h), 2 * math.pi)
    heading += np.random.default_rng(seed).normal(0.0, math.radians(jitter_deg), len(h))
    return np.array(e), np.array(n), heading, legs


@pytest.mark.parametrize("jitter", [0.0, 3.0])
def test_split_lines_finds_the_legs_of_a_lawnmower(jitter):
    """The runs between turns are the legs, less at most half the window (5 m) plus the
    heading filter at each end; yaw jitter of 3° is not a turn."""
    east, north, heading, legs = _lawnmower(jitter)
    found = split_lines(east, north, heading)
    assert len(found) == 3, found
    trim = int(5.0 / 0.25) + 5
    for (a, b), (la, lb) in zip(found, legs, strict=True):
        assert la <= a <= la + trim and lb - trim <= b <= lb, ((a, b), (la, lb))
    # a turn too gentle for the rule (16° over 10 m: radius 36 m) leaves one line
    n = 200
    gentle = np.cumsum(np.full(n, math.radians(0.4)))
    e, nn = np.cumsum(0.25 * np.sin(gentle)), np.cumsum(0.25 * np.cos(gentle))
    assert split_lines(e, nn, gentle) == [(0, n)]


def _turning_track(leg_pings: int) -> tuple[Trajectory, list[tuple[int, int]]]:
    """The three lines of ``leg_pings`` pings joined by half-circle turns (radius 3.5 m), as
    one track; and each line's rows."""
    length = (leg_pings - 1) * SPACING
    arc = np.arange(1, int(math.pi * 3.5 / SPACING)) * SPACING / 3.5
    legs, pos, head = [], [], []

    def add(p, h):
        pos.append(np.asarray(p, dtype=float))
        head.append(np.asarray(h, dtype=float))

    for k in range(3):
        along = np.arange(leg_pings) * SPACING
        y = along if k % 2 == 0 else length - along
        start = sum(len(h) for h in head)
        legs.append((start, start + leg_pings))
        add(np.stack([np.full(leg_pings, LINES_X[k]), y], 1), np.full(leg_pings, k % 2 * math.pi))
        if k == 0:  # over the top, east: heading 0 -> pi
            add(np.stack([-3.5 - 3.5 * np.cos(arc), length + 3.5 * np.sin(arc)], 1), arc)
        elif k == 1:  # under the bottom, east: heading pi -> 2 pi
            add(np.stack([3.5 - 3.5 * np.cos(arc), -3.5 * np.sin(arc)], 1), math.pi - arc)
    xy = np.concatenate(pos)
    z = np.full((len(xy), 1), SEABED + ALT)
    headings = np.mod(np.concatenate(head), 2 * math.pi)
    return Trajectory(np.hstack([xy, z]), headings, np.zeros(len(xy))), legs


def test_one_xtf_with_turns_is_split_into_lines(gl_renderer, tmp_path, capsys):
    """One file holding three 24 m lines and two turns: ``--lines`` finds the three lines (the
    turn pings and up to 5 m of line beside each turn dropped) and grids them together."""
    leg = 120
    track, legs = _turning_track(leg)
    image = gl_renderer.render(_seabed(length=leg * SPACING), SONAR, track)
    path = _write(tmp_path / "turns.xtf", image, track)
    out = tmp_path / "inv"
    args = ["invert", str(path), "--lines", "-o", str(out), "--levels", "1", "--max-iter", "5"]
    assert main([*args, "--no-mesh", "--no-previews"]) == 0, capsys.readouterr().err
    first = capsys.readouterr().out.splitlines()[0]
    assert first.startswith("3 lines: turns.xtf pings ") and "turn pings dropped" in first
    spans = [tuple(map(int, s.split(":"))) for s in
             first.split("pings ", 1)[1].split(" (")[0].split(", ")]  # fmt: skip
    trim = int(5.0 / SPACING) + 5
    for (a, b), (la, lb) in zip(spans, legs, strict=True):
        assert la <= a <= la + trim and lb - trim <= b <= lb, (spans, legs)
    assert spans[0][0] == 0  # no turn before the first line
    z = _read_tif(out / "elevation.tif")[0]
    assert abs(float(np.nanmedian(z)) - SEABED) < 0.1
    assert (out / "line_3" / "bottom_track.csv").is_file()


def _small(path: Path, sonar: Sonar = SONAR, navigation: bool = True, pings: int = 60) -> Path:
    """A quick XTF of speckle on a straight line (no rendering)."""
    rng = np.random.default_rng(1)
    bins = int(round(sonar.max_range / sonar.range_bin))
    sides = {s: rng.exponential(1.0, (pings, bins)).astype(np.float32) for s in sonar.sides}
    track = Trajectory.straight((0.0, 0.0, -14.0), 0.0, SPACING, pings)
    if not navigation:  # every fix at (0, 0): no position
        track = Trajectory(np.tile([0.0, 0.0, -14.0], (pings, 1)), track.headings, track.roll)
    origin = ORIGIN if navigation else (0.0, 0.0)
    return write_xtf(path, SonarImage(sides, sonar, {}), track, altitude=ALT, origin=origin)


def _bad(argv: list[str], capsys) -> str:
    assert main([*argv, "-q"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return err


@pytest.mark.parametrize(
    "other, message",
    [
        ({"max_range": 10.0}, "has range port 10 m, starboard 10 m, not port 12 m"),
        ({"range_bin": 0.04}, "has range bin 0.04 m, not 0.05 m"),
        ({"frequency_hz": 900e3}, "has frequency 900 kHz, not"),
    ],
)
def test_lines_of_different_sonar_settings_are_refused(tmp_path, capsys, other, message):
    import dataclasses

    a = _small(tmp_path / "a.xtf")
    b = _small(tmp_path / "b.xtf", dataclasses.replace(SONAR, **other))
    err = _bad(["invert", str(a), str(b), "-o", str(tmp_path / "o")], capsys)
    assert message in err and "one sonar setting" in err, err
    assert not (tmp_path / "o").exists()


def test_bad_line_inputs_give_one_line_errors(tmp_path, capsys):
    a, nowhere = _small(tmp_path / "a.xtf"), _small(tmp_path / "n.xtf", navigation=False)
    out = str(tmp_path / "o")
    assert "has no navigation" in _bad(["invert", str(a), str(nowhere), "-o", out], capsys)
    err = _bad(["invert", str(a), "--lines", "-o", out], capsys)
    assert "1 line: a.xtf pings 0:60: several lines need two or more" in err, err
    assert "--side is for one file" in _bad(["invert", str(a), str(a), "--side", "port", "-o",
                                             out], capsys)  # fmt: skip
    assert "not a ping range" in _bad(["invert", str(a), "--line-pings", "5:2", "-o", out], capsys)
    err = _bad(["invert", str(a), "--line-pings", "0:30,100:200", "-o", out], capsys)
    assert "the line 100:200 has fewer than 2 pings" in err, err
    err = _bad(["invert", str(a), "--lines", "--line-pings", "0:30,30:60", "-o", out], capsys)
    assert "not both" in err, err
    np.save(tmp_path / "i.npy", np.ones((4, 4)))
    assert "for XTF files" in _bad(["invert", str(tmp_path / "i.npy"), str(a), "-o", out], capsys)
    assert not (tmp_path / "o").exists()


def test_the_real_recording_is_one_line(tmp_path, capsys):
    """The OpenSidescan sample's course corrections (up to 12.7° over 10 m) are not turns, so
    ``--lines`` finds one line and says several lines need two."""
    sample = Path(__file__).resolve().parents[3] / "shared" / "data" / "xtf" / "scotsman-iver2.xtf"
    if not sample.is_file():
        pytest.fail(f"{sample} is missing: the shared data must sit beside the clone")
    err = _bad(["invert", str(sample), "--lines", "-o", str(tmp_path / "o")], capsys)
    assert "1 line: scotsman-iver2.xtf pings 0:" in err and "two or more" in err, err


def test_line_pings_name_the_lines_of_one_file(tmp_path):
    from sonar_raster.inversion.lines import describe_lines, read_lines

    path = _small(tmp_path / "a.xtf")
    lines, notes = read_lines([path], split=[(0, 25), (35, 60)])
    assert [list(line.pings[[0, -1]]) for line in lines] == [[0, 24], [35, 59]]
    assert notes == ["2 lines: a.xtf pings 0:25, 35:60 (10 pings outside the lines dropped)"]
    assert describe_lines(lines) == "2 lines: a.xtf pings 0:25, 35:60"
    np.testing.assert_allclose(lines[1].north - ORIGIN[1], np.arange(35, 60) * SPACING)
    np.testing.assert_allclose(lines[1].depth, 14.0)
    side = lines[0].sides["port"]
    raw = _small(tmp_path / "b.xtf")
    from sonar_raster.io.xtf import read_xtf

    amplitude = read_xtf(raw)[0].sides["port"][:25].astype(np.float64)
    blank = int(np.argmax(side[0] > 0))
    np.testing.assert_allclose(side[:, blank:], amplitude[:, blank:] ** 2, rtol=1e-6)
    assert not side[:, :blank].any()  # the transmit pulse zeroed


@pytest.mark.slow
def test_two_lines_through_the_real_surface_fit(survey, tmp_path, capsys):
    """The real joint surface fit (few iterations): its per-side results carry what the gridding
    needs; the combined std is below every line's where they overlap, the level is the sea
    surface datum's and the mound is there."""
    out = tmp_path / "inv"
    args = ["invert", *map(str, survey[:2]), "-o", str(out), "--method", "surface", "-q"]
    assert main([*args, "--max-iter", "10", "--no-mesh", "--no-previews"]) == 0
    std = _read_tif(out / "elevation_std.tif")[0]
    per_line = np.stack([_read_tif(out / f"line_{k}" / "elevation_std.tif")[0] for k in (1, 2)])
    two = np.isfinite(per_line).all(axis=0)
    assert two.sum() > 1000 and np.all(std[two] > 0)
    assert np.all(std[two] < per_line[:, two].min(axis=0))  # 1/sqrt(Σ 1/σ²) < each σ
    east, north, level, top = _mound_peak(out / "elevation.tif")
    assert abs(level - SEABED) < 0.1 and top > 0.08, (level, top)


def _nav_degrees(lon0: float, pings: int = 30):
    from sonar_raster.io.xtf import XtfNavigation

    lon = lon0 + np.arange(pings) * 2e-6
    nan = np.full(pings, np.nan)
    return XtfNavigation(
        np.arange(pings, dtype=float), lon, np.full(pings, 52.0), "degrees", np.zeros(pings),
        np.zeros(pings), np.zeros(pings), nan, np.full(pings, 10.0), np.ones(pings, bool),
    )  # fmt: skip


def test_a_file_in_the_next_utm_zone_is_placed_in_the_first_files_zone():
    """A line starting east of 6° E (zone 32) joins a survey in zone 31: its positions are the
    zone-31 coordinates of its fixes, as a direct projection of the degrees gives them."""
    from rasterio.warp import transform

    from sonar_raster.inversion.lines import _file_track

    nav = _nav_degrees(6.0005)
    assert nav.crs == "EPSG:32632"
    track = _file_track(nav, "EPSG:32631", "b.xtf")
    e, n = transform("EPSG:4326", "EPSG:32631", nav.x.tolist(), nav.y.tolist())
    np.testing.assert_allclose(track["east"], e, atol=1e-3)
    np.testing.assert_allclose(track["north"], n, atol=1e-3)
    assert track["crs"] == "EPSG:32631"
    with pytest.raises(SonarRasterError, match="in degrees and in metres"):
        _file_track(nav, None, "b.xtf")
