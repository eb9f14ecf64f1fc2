"""The surface fit's relief shrunk where its noise could explain it (inversion.surface.shrink)."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from sonar_raster.inversion.surface.shrink import shrink_relief

KNOT, DX, DY = 0.2, 0.05, 0.1  # the bench's Z knots, ground cells and pings, metres
SHAPE = (400, 600)


def _noise(sigma: float, seed: int) -> np.ndarray:
    """Noise of std ``sigma`` correlated over about one knot, as the fit's is."""
    white = np.random.default_rng(seed).standard_normal(SHAPE)
    smooth = ndimage.gaussian_filter(white, (KNOT / DY, KNOT / DX))
    return sigma * smooth / smooth.std()


def test_relief_within_its_noise_goes_to_the_trend():
    y, x = np.mgrid[: SHAPE[0], : SHAPE[1]] * np.array([DY, DX])[:, None, None]
    trend = -12.0 + 0.02 * x  # a gentle slope: kept
    noisy = trend + _noise(0.03, 1)
    out = shrink_relief(noisy, np.full(SHAPE, 0.03), KNOT, DX, DY)
    inner = (slice(50, -50), slice(80, -80))
    before = np.sqrt(np.mean((noisy - trend)[inner] ** 2))
    after = np.sqrt(np.mean((out - trend)[inner] ** 2))
    assert after < 0.4 * before, (before, after)  # 0.36 (GAIN_SCALE 1.5; the plain Wiener 0.25)


def test_relief_well_above_its_noise_stays():
    y, x = np.mgrid[: SHAPE[0], : SHAPE[1]] * np.array([DY, DX])[:, None, None]
    relief = 0.15 * np.sin(2 * np.pi * (x * 0.87 + y * 0.5) / 3.0)  # the bench's sand waves
    truth = -12.0 + relief
    fitted = truth + _noise(0.02, 2)
    out = shrink_relief(fitted, np.full(SHAPE, 0.02), KNOT, DX, DY)
    inner = (slice(50, -50), slice(80, -80))
    before = np.sqrt(np.mean((fitted - truth)[inner] ** 2))
    after = np.sqrt(np.mean((out - truth)[inner] ** 2))
    assert after < 1.05 * before, (before, after)
    amplitude = np.polyfit(relief[inner].ravel(), (out - truth + relief)[inner].ravel(), 1)[0]
    assert amplitude > 0.95  # the waves keep their height


def test_relief_shrinks_where_it_is_noise_and_stays_where_it_is_not():
    """A mound in one half, flat noise in the other: each half gets its own gain."""
    y, x = np.mgrid[: SHAPE[0], : SHAPE[1]] * np.array([DY, DX])[:, None, None]
    mound = 0.5 * np.exp(-((x - 7.5) ** 2 + (y - 10.0) ** 2) / (2 * 1.5**2))
    truth = -12.0 + mound
    fitted = truth + _noise(0.03, 3)
    out = shrink_relief(fitted, np.full(SHAPE, 0.03), KNOT, DX, DY)
    top = (slice(80, 120), slice(130, 170))
    bare = (slice(60, 340), slice(420, 560))
    assert abs((out - truth)[top].mean()) < 0.02  # the mound's top stays
    bare_before = np.sqrt(np.mean((fitted - truth)[bare] ** 2))
    bare_after = np.sqrt(np.mean((out - truth)[bare] ** 2))
    assert bare_after < 0.5 * bare_before, (bare_before, bare_after)


def test_cells_without_an_estimate_or_a_std_keep_their_value():
    z = np.full((60, 80), -12.0) + _noise(0.03, 4)[:60, :80]
    std = np.full_like(z, 0.03)
    z[:, :5] = np.nan
    std[10:20, 30:40] = np.nan
    out = shrink_relief(z, std, KNOT, DX, DY)
    assert np.all(np.isnan(out[:, :5]))
    np.testing.assert_array_equal(out[10:20, 30:40], z[10:20, 30:40])
    assert np.all(np.isfinite(out[:, 5:]))
