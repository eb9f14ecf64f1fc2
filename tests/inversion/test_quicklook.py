"""Quick-look PNGs: block means, round scale bars, dB, and what the pictures hold."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sonar_raster.inversion import quicklook as ql
from sonar_raster.io.images import read_pixels


def test_shrink_is_the_nan_mean_of_each_block():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(2503, 1207))
    a[rng.random(a.shape) < 0.3] = np.nan
    a[:5, :5] = np.nan  # one whole block without data
    small, k = ql.shrink(a, 1000)
    assert k == 3 and small.shape == (835, 403) and max(small.shape) <= 1000
    assert np.isnan(small[0, 0])
    for i, j in [(1, 1), (400, 200), (834, 402), (834, 0)]:  # last blocks are partial
        block = a[i * k : (i + 1) * k, j * k : (j + 1) * k]
        assert small[i, j] == pytest.approx(np.nanmean(block), rel=1e-12)
    same, k = ql.shrink(a[:100, :100], 1000)
    assert k == 1 and np.array_equal(same, a[:100, :100], equal_nan=True)


@pytest.mark.parametrize("width", [0.37, 3.0, 17.0, 60.0, 1234.0, 9.99e4])
def test_scale_bar_is_round_and_about_a_fifth_of_the_width(width):
    length = ql.scale_length(width)
    mantissa = length / 10 ** math.floor(math.log10(length))
    assert round(mantissa, 9) in (1.0, 2.0, 5.0)
    assert width / 12.5 < length <= width / 5  # the next round length would exceed a fifth


def test_decibels_of_nonpositive_values_are_nan():
    db = ql.decibels(np.array([100.0, 1.0, 0.0, -3.0, np.nan, np.inf]))
    np.testing.assert_array_equal(db[:2], [20.0, 0.0])
    assert np.isnan(db[2:]).all()


def _no_data_share(path) -> float:
    pixels = read_pixels(path)[0][:, :, :3]
    grey = np.array([0xD9, 0xD9, 0xD9]) / 255.0
    return float(np.all(np.abs(pixels - grey) < 1.5 / 255, axis=-1).mean())


def test_no_data_shows_as_the_background_and_the_map_as_colours(tmp_path):
    """A map whose left half is NaN shows far more of the no-data grey than a full one, in
    each kind of quick-look; the picture stays small."""
    rng = np.random.default_rng(1)
    full = 1.0 + rng.random((300, 400))
    half = full.copy()
    half[:, :200] = np.nan
    writers = {
        "mosaic": lambda p, v: ql.mosaic_png(p, v, 0.1),
        "hillshade": lambda p, v: ql.hillshade_png(p, v, 0.1, exaggeration=5.0),
        "reflectivity": lambda p, v: ql.reflectivity_png(p, v, 0.1, along_m=0.2, north_up=False),
    }
    for name, write in writers.items():
        write(tmp_path / f"{name}_full.png", full)
        write(tmp_path / f"{name}_half.png", half)
        a, b = (
            _no_data_share(tmp_path / f"{name}_full.png"),
            _no_data_share(tmp_path / f"{name}_half.png"),
        )
        assert b > a + 0.1, (name, a, b)
        assert (tmp_path / f"{name}_half.png").stat().st_size < 300_000


def test_waterfall_puts_port_on_the_left(tmp_path):
    """Port bright, starboard dark: the left half of the picture's map is the brighter."""
    port, starboard = np.full((200, 300), 100.0), np.full((200, 300), 1.0)
    ql.waterfall_png(tmp_path / "w.png", {"port": port, "starboard": starboard}, 0.1,
                     dynamic_range_db=40.0)  # fmt: skip
    pixels = read_pixels(tmp_path / "w.png")[0][:, :, 0]
    row = pixels[pixels.shape[0] // 2]
    white = np.flatnonzero(row > 0.95)
    dark = np.flatnonzero(row < 0.55)  # 20 dB down in 40 dB: mid grey at most
    assert white.size > 50 and dark.size > 50
    assert np.median(white) < np.median(dark)


def test_bad_maps_are_refused():
    with pytest.raises(ValueError, match="2-D"):
        ql.shrink(np.zeros(5))
    with pytest.raises(ValueError, match="cell_m"):
        ql.map_png("x.png", np.zeros((3, 3)), 0.0)
    with pytest.raises(ValueError, match="sides"):
        ql.waterfall_png("x.png", {"left": np.zeros((3, 3))}, 0.1)
