"""Georeferenced gridding by footprints: no holes inside the swath, linear fields exact, and the
XTF quick-looks written with the other products, all or none."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from skimage.draw import polygon

from sonar_raster.cli.app import main
from sonar_raster.inversion.xtf import grid, ground_positions, join_sides

SAMPLE = Path(__file__).resolve().parents[3] / "shared" / "data" / "xtf" / "scotsman-iver2.xtf"


def _swath(heading_deg: float = 30.0, pings: int = 40, cells: int = 120, spacing: float = 0.2):
    """Both sides of a straight track: 5 cm ground cells (as dense as the pixels), pings
    ``spacing`` apart; layers: a linear field of position and a constant."""
    heading = np.full(pings, math.radians(heading_deg))
    along = np.arange(pings) * spacing
    east = 1000.0 + along * math.sin(heading[0])
    north = 2000.0 + along * math.cos(heading[0])
    x = (np.arange(cells) + 0.5) * 0.05
    z = np.full((pings, cells), -5.0)
    samples = []
    for side in ("port", "starboard"):
        e, n = ground_positions(east, north, heading, np.zeros(pings), x, z, side)
        layers = {"linear": 0.3 * (e - 1000.0) - 0.7 * (n - 2000.0), "one": np.ones_like(e)}
        samples.append((e, n, layers))  # port, starboard
    # the outline: far port at the first and last ping, far starboard at the last and first
    order = [(0, 0), (0, -1), (1, -1), (1, 0)]
    hull = tuple(np.array([samples[s][axis][p, -1] for s, p in order]) for axis in (0, 1))
    return samples, hull


def _inside(raster, hull) -> np.ndarray:
    """Pixels whose centre lies at least one pixel inside the swath's outline."""
    from scipy.ndimage import binary_erosion

    shape = raster.layers["one"].shape
    mask = np.zeros(shape, dtype=bool)
    r, c = polygon((raster.north - hull[1]) / raster.pixel - 0.5,
                   (hull[0] - raster.west) / raster.pixel - 0.5, shape)  # fmt: skip
    mask[r, c] = True
    return binary_erosion(mask, iterations=2)


@pytest.mark.parametrize("heading", [0.0, 30.0, 77.0])
def test_footprints_leave_no_hole_inside_the_swath(heading):
    """Cells as dense as the pixels, on a rotated track, leave holes when point-gridded; the
    footprints cover every pixel inside the swath."""
    samples, hull = _swath(heading)
    points = grid(samples, 0.05, None, along_factor=4, method="points")
    inside = _inside(points, hull)
    assert inside.sum() > 1000
    if heading != 0.0:  # the baseline does leave holes: the test can see them
        assert np.isnan(points.layers["one"][inside]).mean() > 0.01
    splat = grid(join_sides(dict(zip(("port", "starboard"), samples, strict=True))), 0.05, None)
    assert not np.isnan(splat.layers["one"][_inside(splat, hull)]).any()
    ones = splat.layers["one"][np.isfinite(splat.layers["one"])]
    np.testing.assert_allclose(ones, 1.0, rtol=1e-6)  # a weighted mean of ones is one


def test_a_linear_field_is_gridded_at_pixel_centres():
    """Bilinear footprints reproduce a linear field: each pixel inside the swath holds the
    field at its centre (within 1/8 of the field's change across a pixel)."""
    samples, hull = _swath(30.0)
    raster = grid(join_sides(dict(zip(("port", "starboard"), samples, strict=True))), 0.05, None)
    inside = _inside(raster, hull)
    rows, cols = np.nonzero(inside)
    e = raster.west + (cols + 0.5) * raster.pixel
    n = raster.north - (rows + 0.5) * raster.pixel
    truth = 0.3 * (e - 1000.0) - 0.7 * (n - 2000.0)
    change = math.hypot(0.3, 0.7) * raster.pixel
    error = np.abs(raster.layers["linear"][rows, cols] - truth)
    assert error.max() < change / 8, error.max() / change


def test_nan_values_are_left_out_of_their_layer_only():
    samples, hull = _swath(30.0)
    e, n, layers = samples[1]
    layers = dict(layers)
    layers["one"] = layers["one"].copy()
    layers["one"][:, 60:] = np.nan  # starboard's far half has no value in this layer
    raster = grid([samples[0], (e, n, layers)], 0.05, None)
    far = np.isnan(raster.layers["one"]) & np.isfinite(raster.layers["linear"])
    assert far.sum() > 500  # the linear layer still covers it
    finite = raster.layers["one"][np.isfinite(raster.layers["one"])]
    np.testing.assert_allclose(finite, 1.0, rtol=1e-6)  # renormalised, not pulled towards 0


def test_mosaic_values_are_the_evenly_illuminated_image():
    from types import SimpleNamespace

    from sonar_raster.inversion.xtf import mosaic_values

    ground, even = np.full((2, 3), 5.0), np.full((2, 3), 0.3)
    assert np.all(mosaic_values(SimpleNamespace(ground=ground, even=even)) == 0.3)
    assert np.all(mosaic_values(SimpleNamespace(ground=ground, even=None)) == 5.0)


def _invert(out: Path, *extra: str) -> int:
    return main(
        ["invert", str(SAMPLE), "-o", str(out), "--pings", "288:312", "--max-iter", "3",
         "--levels", "1", "--no-mesh", "--no-previews", "-q", *extra]
    )  # fmt: skip


QUICKLOOKS = ["waterfall.png", "mosaic.png", "elevation.png", "reflectivity.png"]


def test_invert_xtf_writes_quicklooks_of_every_product(tmp_path, capsys):
    import json

    from sonar_raster.io.images import read_pixels

    if not SAMPLE.is_file():
        pytest.fail(f"{SAMPLE} is missing: the shared data must sit beside the clone")
    out = tmp_path / "inv"
    assert _invert(out) == 0, capsys.readouterr().err
    for name in QUICKLOOKS + [f"{s}/{p}" for s in ("port", "starboard")
                              for p in ("elevation.png", "reflectivity.png")]:  # fmt: skip
        pixels, spec = read_pixels(out / name)
        assert 300 < spec.width < 1400 and 100 < spec.height < 1400, name
        assert pixels.std() > 0.05, name  # a picture, not a blank
        assert (out / name).stat().st_size < 400_000, name
    doc = json.loads((out / "port" / "inversion.json").read_text())
    assert "elevation.png" in doc["products"] and "reflectivity.png" in doc["products"]


def test_a_failing_quicklook_leaves_no_product(tmp_path, capsys, monkeypatch):
    from sonar_raster.inversion import quicklook

    if not SAMPLE.is_file():
        pytest.fail(f"{SAMPLE} is missing: the shared data must sit beside the clone")

    def full(path, *args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(quicklook, "mosaic_png", full)
    out = tmp_path / "inv"
    assert _invert(out) == 2
    assert "No space left" in capsys.readouterr().err
    assert not out.exists()
