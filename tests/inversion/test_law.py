"""The inversion's scattering law: the renderers' table as a smooth curve, and its errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sonar_raster.errors import SonarRasterError
from sonar_raster.inversion.law import scattering_law
from sonar_raster.scenes.sediments import law_factor, material_index


@pytest.mark.parametrize(("name", "frequency"), [("sand", 400e3), ("clay", 100e3), ("rock", 9e5)])
def test_the_curve_is_the_renderers_table(name, frequency):
    law = scattering_law(name, frequency)
    assert law is not None
    index = material_index(name)
    theta = np.radians(np.arange(90))  # the table's nodes, grazing end left out
    cos = np.cos(theta)
    want = law_factor(np.full(cos.shape, index), cos, frequency)
    got = np.exp(law.log_factor_at(cos)[0])
    np.testing.assert_allclose(got, want, rtol=1e-12)
    # between nodes the curve stays between its neighbours (monotone cubic) and off the
    # renderers' linear interpolation by less than half the step's change (in log)
    mid = np.cos(np.radians(np.arange(89) + 0.5))
    between = np.exp(law.log_factor_at(mid)[0])
    low, high = np.minimum(want[:-1], want[1:]), np.maximum(want[:-1], want[1:])
    assert np.all(between >= low * (1 - 1e-12)) and np.all(between <= high * (1 + 1e-12))
    linear = law_factor(np.full(mid.shape, index), mid, frequency)
    step = np.abs(np.diff(np.log(want)))
    assert np.all(np.abs(np.log(between / linear)) <= 0.5 * step + 1e-9)


def test_the_slope_is_the_curves_derivative():
    law = scattering_law("sand", 400e3)
    assert law is not None
    c = np.linspace(0.03, 0.999, 997)
    h = 1e-7
    numeric = (law.log_factor_at(c + h)[0] - law.log_factor_at(c - h)[0]) / (2 * h)
    exact = law.log_factor_at(c)[1]
    np.testing.assert_allclose(exact, numeric, rtol=1e-5, atol=1e-5 * np.abs(numeric).max())
    assert np.ptp(exact) > 1.0  # a law that changes, not a constant


def test_lambert_is_no_law_and_bad_names_are_one_line():
    assert scattering_law("Lambert", None) is None
    with pytest.raises(SonarRasterError, match="--law: unknown material 'granite'"):
        scattering_law("granite", 400e3)
    with pytest.raises(SonarRasterError, match="--frequency"):
        scattering_law("sand", None)
    with pytest.raises(SonarRasterError, match="--frequency"):
        scattering_law("sand", math.nan)
