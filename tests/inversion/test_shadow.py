"""Object heights from acoustic shadows: rendered boxes of known height on a flat seabed."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import box_from_bounds, plane

from sonar_raster import render_raster
from sonar_raster.errors import SonarRasterError
from sonar_raster.inversion.shadows import find_shadows, object_pings
from sonar_raster.scene import build_scene
from sonar_raster.sonar import BeamPattern, Sonar
from sonar_raster.trajectory import Trajectory

ALT = 6.0
BIN = 0.05
SONAR = Sonar(
    max_range=20.0,
    range_bin=BIN,
    beam=BeamPattern.gaussian(60.0),
    tilt=math.radians(20.0),
    sides=("starboard",),
)


def _render(height: float, x0: float, x1: float) -> np.ndarray:
    track = Trajectory.straight((0.0, -10.0, ALT), 0.0, 0.1, 200)
    box = box_from_bounds([[x0, -4.0, 0.0], [x1, 4.0, height]])
    image = render_raster(build_scene([plane(200.0), box]), SONAR, track)
    return image.sides["starboard"].astype(np.float64)


@pytest.mark.parametrize("height, x0, x1", [(1.5, 8.0, 10.0), (0.8, 5.0, 6.0)])
@pytest.mark.parametrize("speckle", [False, True])
def test_box_height_from_its_shadow(height, x0, x1, speckle):
    image = _render(height, x0, x1)
    if speckle:
        image = image * np.random.default_rng(2).exponential(size=image.shape)
    found = find_shadows(image, BIN, np.full(len(image), ALT))
    box = object_pings(found.height)
    assert 70 <= box.sum() <= 85  # 8 m of box at 0.1 m per ping
    # the shadow starts where the ray over the box's far top edge leaves it
    r_top = math.hypot(x1, ALT - height)
    assert np.median(found.start[box]) * BIN == pytest.approx(r_top, abs=2 * BIN)
    # and ends where that ray meets the seabed
    x_end = x1 * ALT / (ALT - height)
    assert np.median(found.end[box]) * BIN == pytest.approx(math.hypot(x_end, ALT), abs=2 * BIN)
    # H = Ls h / (R + Ls) within 3 % (two bins of shadow length at most)
    assert np.median(found.height[box]) == pytest.approx(height, rel=0.03)
    assert not np.isfinite(found.bound).any()


def test_shadow_past_the_range_gives_a_lower_bound():
    height, x1 = 2.5, 13.0  # the ray over the top meets the seabed at 31 m, beyond 20 m
    found = find_shadows(_render(height, 12.0, x1), BIN, np.full(200, ALT))
    cut = np.isfinite(found.bound)
    assert cut.sum() >= 70 and not np.isfinite(found.height[cut]).any()
    r_top = math.hypot(x1, ALT - height)
    expected = (SONAR.max_range - r_top) * ALT / SONAR.max_range
    assert np.median(found.bound[cut]) == pytest.approx(expected, abs=ALT * 2 * BIN / 20.0)
    assert np.all(found.bound[cut] < height)


def test_flat_seabed_has_no_shadow():
    track = Trajectory.straight((0.0, -10.0, ALT), 0.0, 0.1, 200)
    image = render_raster(build_scene([plane(200.0)]), SONAR, track).sides["starboard"]
    found = find_shadows(image, BIN, np.full(200, ALT))
    assert not np.isfinite(found.height).any() and not object_pings(found.height).any()


def test_bad_input():
    with pytest.raises(SonarRasterError):
        find_shadows(-np.ones((4, 40)), BIN, np.full(4, ALT))
    with pytest.raises(SonarRasterError):
        find_shadows(np.ones((4, 40)), BIN, np.zeros(4))


@pytest.mark.parametrize("dark, found", [(0.02, True), (0.2, False)])
def test_a_shadow_holds_the_noise_floor_not_a_dark_seabed(dark, found):
    """A run after a highlight whose mean is a fifth of the seabed's (a back slope that a
    steep scattering law darkens; single-look speckle under the median filter reads it below
    the shadow level) is no shadow; one 17 dB down (the real file's wreck) is."""
    rng = np.random.default_rng(4)
    bins, pings = 400, 60
    mean = np.ones((pings, bins))
    mean[:, : int(ALT / BIN)] = 0.0  # water column
    mean[:, 200:220] = 4.0  # highlight
    mean[:, 220:260] = dark  # 2 m dark run
    image = mean * rng.exponential(size=mean.shape)
    # the median filter's test alone takes both
    loose = find_shadows(image, BIN, np.full(pings, ALT), shadow_mean=None)
    assert np.isfinite(loose.height).mean() > 0.5
    share = np.isfinite(find_shadows(image, BIN, np.full(pings, ALT)).height).mean()
    assert share > 0.75 if found else share < 0.05


def test_a_shadow_on_a_seabed_near_the_noise_floor_holds_that_floor():
    """Where the seabed is only 6 dB above the noise floor (a far range, a weak echo), a cast
    shadow is at the floor, not 10 dB under the seabed: it is still a shadow."""
    rng = np.random.default_rng(5)
    bins, pings = 400, 60
    mean = np.ones((pings, bins))
    mean[:, 200:220] = 4.0  # highlight
    mean[:, 220:260] = 0.0  # cast shadow
    mean += 0.25  # the noise floor everywhere, water column included
    image = mean * rng.exponential(size=mean.shape)
    share = np.isfinite(find_shadows(image, BIN, np.full(pings, ALT)).height).mean()
    loose = find_shadows(image, BIN, np.full(pings, ALT), shadow_mean=None)
    assert share > 0.5 and share == np.isfinite(loose.height).mean()
    # measured against the seabed alone it would not be one
    floorless = image.copy()
    floorless[:, : int(ALT / BIN)] = 0.0
    assert np.isfinite(find_shadows(floorless, BIN, np.full(pings, ALT)).height).mean() < 0.05
