"""The display PNG: levelled mapping, copper palette, ground range and square pixels."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from sonar_raster.errors import SonarRasterError
from sonar_raster.image import SonarImage
from sonar_raster.io import images as io
from sonar_raster.sonar import Sonar


def slant_image(pings: int = 6, bins: int = 400, range_bin: float = 0.05, **meta) -> SonarImage:
    """Each bin holds its own slant range (metres): a resampling shows where it read."""
    r = (np.arange(bins) + 0.5) * range_bin
    data = np.tile(r, (pings, 1))
    sonar = Sonar(max_range=bins * range_bin, range_bin=range_bin)
    return SonarImage({"port": data.copy(), "starboard": data.copy()}, sonar, dict(meta))


def test_ground_range_reads_the_slant_range_of_each_ground_point():
    h = 4.0
    image = slant_image()
    sides, geometry = io.display_sides(
        image, io.checked_sides(image), io.Display(ground_range=True, altitude_m=h)
    )
    x = (np.arange(sides["starboard"].shape[1]) + 0.5) * 0.05
    expected = np.sqrt(x**2 + h**2)  # a linear ramp in r interpolates exactly
    inside = expected < 20.0 - 0.025
    np.testing.assert_allclose(sides["starboard"][0][inside], expected[inside], rtol=1e-6)
    assert sides["starboard"].shape[1] == math.ceil(math.sqrt(20.0**2 - h**2) / 0.05)
    assert geometry == {"columns": "ground range", "column_m": 0.05, "row_m": None, "altitude_m": h}
    with pytest.raises(SonarRasterError, match="altitude"):
        io.display_sides(image, io.checked_sides(image), io.Display(ground_range=True))


def test_square_pixels_resample_pings_to_the_bin_size():
    image = slant_image(pings=10, ping_spacing_m=0.1)
    rows = np.arange(10.0)[:, None] * np.ones((1, 400))  # row value = ping index
    image = SonarImage({"starboard": rows}, image.sonar, image.metadata)
    sides, geometry = io.display_sides(
        image, io.checked_sides(image), io.Display(square_pixels=True)
    )
    out = sides["starboard"]
    assert out.shape == (20, 400) and geometry["row_m"] == 0.05
    centres = np.clip((np.arange(20) + 0.5) * 0.5 - 0.5, 0, 9)  # ping index at each row centre
    np.testing.assert_allclose(out[:, 7], centres, atol=1e-12)


def test_levelled_png_puts_the_median_at_mid_grey_and_records_the_mapping(tmp_path):
    rng = np.random.default_rng(0)
    data = rng.exponential(1e-6, (50, 300))
    meta = {"effects": {"stages": ["speckle"]}}
    image = SonarImage(
        {"port": data, "starboard": data[::-1]}, Sonar(max_range=15.0, range_bin=0.05), meta
    )
    path = tmp_path / "a.png"
    io.write_image(image, path)
    doc = json.loads(path.with_suffix(".json").read_text())
    mapping = doc["display_mapping"]
    assert mapping["level"] == "median" and mapping["dynamic_range_db"] == io.LEVELLED_RANGE_DB
    pixels, spec = io.read_pixels(path)
    assert float(np.median(pixels)) == pytest.approx(0.5, abs=2 / 255)
    assert spec.getattribute("sonar:display_level") == "median"
    # the mapping inverts: I = ref 10^(DR/10 (code - 1)) gives back the median
    back = mapping["ref_level_m2"] * 10 ** (
        mapping["dynamic_range_db"] / 10 * (np.median(pixels) - 1)
    )
    assert back == pytest.approx(np.median(data), rel=0.05)


def test_copper_palette_inverts_from_green(tmp_path):
    image = slant_image()
    grey, copper = tmp_path / "g.png", tmp_path / "c.png"
    io.write_image(image, grey, bit_depth=16)
    io.write_image(image, copper, bit_depth=16, display=io.Display(palette="copper"))
    g, _ = io.read_pixels(grey)
    c, spec = io.read_pixels(copper)
    assert c.shape[2] == 3 and g.shape[2] == 1
    np.testing.assert_allclose(c[:, :, 1] / io.COPPER[1], g[:, :, 0], atol=2 / 65535)
    np.testing.assert_allclose(c[:, :, 0], np.minimum(1.0, 1.25 * g[:, :, 0]), atol=2 / 65535)
    assert "0.7812" in spec.getattribute("sonar:display_palette_formula")
    assert (
        json.loads(copper.with_suffix(".json").read_text())["display_mapping"]["palette"]
        == "copper"
    )


def test_raw_png_mapping_is_unchanged_by_default(tmp_path):
    image = slant_image()
    path = tmp_path / "r.png"
    io.write_image(image, path)
    mapping = json.loads(path.with_suffix(".json").read_text())["display_mapping"]
    assert set(mapping) == {"ref_level_m2", "dynamic_range_db", "formula"}
    display = SonarImage(io.checked_sides(image), image.sonar).display()
    expected, _ = io.display_mapping(display, io.auto_dynamic_range(display))
    pixels, _ = io.read_pixels(path)
    np.testing.assert_array_equal(np.rint(pixels[:, :, 0] * 255), np.rint(expected * 255))


def test_bad_display_settings_are_refused():
    with pytest.raises(SonarRasterError, match="palette"):
        io.Display(palette="jet")
    with pytest.raises(SonarRasterError, match="level"):
        io.Display(level="mean")
    with pytest.raises(SonarRasterError, match="altitude_m"):
        io.Display(altitude_m=-1.0)
