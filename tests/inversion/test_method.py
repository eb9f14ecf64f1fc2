"""``--method auto``'s choice: the surface fit for speckled images this machine can afford."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sonar_raster.inversion import method


def _sides(looks: float, seed: int = 0) -> dict[str, np.ndarray]:
    """Both sides of a line over a seabed whose mean falls with range, times L-look speckle."""
    rng = np.random.default_rng(seed)
    k = np.arange(300)
    mean = np.where(k >= 40, 50.0 / np.maximum(k - 10.0, 1.0), 0.0) * np.ones((80, 1))
    return {s: mean * rng.gamma(looks, 1.0 / looks, mean.shape) for s in ("port", "starboard")}


@pytest.mark.parametrize("looks", [1.0, 2.0, 8.0, 200.0])
def test_the_looks_are_estimated_from_neighbouring_pings(looks):
    assert method.image_looks(_sides(looks)) == pytest.approx(looks, rel=0.1)


def test_a_single_look_line_gets_the_surface_fit_a_multi_look_one_the_profiles():
    speckled = method.choose_method([_sides(1.0)])
    assert speckled.method == "surface" and speckled.looks == pytest.approx(1.0, rel=0.1)
    assert "--method profiles" in speckled.reason
    assert method.choose_method([_sides(30.0)]).method == "surface"
    smooth = method.choose_method([_sides(200.0)])
    assert smooth.method == "profiles" and "--method surface" in smooth.reason
    # the fewest looks over several lines decide; looks given are taken as they are
    assert method.choose_method([_sides(200.0), _sides(1.0, 1)]).method == "surface"
    assert method.choose_method([_sides(1.0)], looks=100.0).method == "profiles"
    assert method.choose_method([_sides(200.0)], looks=1.5).method == "surface"


def test_identical_pings_have_no_speckle():
    flat = {"starboard": np.ones((10, 50))}
    assert math.isinf(method.image_looks(flat))
    assert method.choose_method([flat]).method == "profiles"


@pytest.mark.parametrize("rate", ["SURFACE_PIXEL_SECONDS", "SURFACE_PIXEL_BYTES"])
def test_a_surface_fit_this_machine_cannot_afford_falls_back_to_the_profiles(monkeypatch, rate):
    monkeypatch.setattr(method, rate, 1e9)  # days, or petabytes, for 48 000 pixels
    choice = method.choose_method([_sides(1.0)])
    assert choice.method == "profiles"
    assert "4.8e+04 pixels" in choice.reason and "--pings" in choice.reason
    # a coarser fit divides the time, not the memory
    if rate == "SURFACE_PIXEL_SECONDS":
        monkeypatch.setattr(method, rate, 0.3)  # 4 h at full resolution, 14 min pooled 4 x 4
        assert method.choose_method([_sides(1.0)]).method == "profiles"
        assert method.choose_method([_sides(1.0)], finest=4).method == "surface"


def test_speckle_correlated_between_pings_is_still_speckle():
    """A footprint wider than the ping spacing shares speckle between neighbouring pings, which
    reads as more looks between pings; between bins it does not (the default render: 6.5
    against 3.0)."""
    from scipy import ndimage

    from sonar_raster.inversion.priors import estimate_looks

    rng = np.random.default_rng(2)
    speckle = ndimage.uniform_filter1d(rng.exponential(size=(160, 300)), 3, axis=0)
    image = speckle * np.linspace(2.0, 1.0, 300)  # 3 looks, each shared by 3 pings
    assert estimate_looks(image, image > 0) > 6.0
    assert method.image_looks({"starboard": image}) == pytest.approx(3.0, rel=0.1)
    assert method.choose_method([{"starboard": image}]).method == "surface"
