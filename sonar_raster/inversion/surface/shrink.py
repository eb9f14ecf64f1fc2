"""Relief the data cannot tell from noise, shrunk towards the fit's smooth trend.

The surface fit's Z holds the seabed's relief plus the speckle it could not average out; its
Laplace standard deviation σ (``solve.elevation_std``) says how large that noise is, cell by
cell. About a smooth trend (a near-Gaussian of σ ``TREND_KNOTS`` Z-knot spacings), each cell's
deviation ``d`` is multiplied by ``min(1, GAIN_SCALE · s² / (s² + σ²))`` (the local Wiener
gain, scaled), where the relief's own variance ``s² = max(0, mean d² − mean σ²)`` is taken over
a window of ``WINDOW_KNOTS`` knots: where the fitted relief is no larger than its noise it goes
towards the trend, where it stands well above its noise it stays. The standard deviation
written beside Z is the fit's σ, unchanged (the shrunk cells' errors lie within it more often,
not less; the shrunk estimate's own Gaussian variance, gain times σ², covered 4-51 %: its
error is the relief it shrank, not noise).

Measured on the bathymetry bench and the independent model's images
(docs/notes/2026-12-02-relief-shrinkage.md).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

#: σ of the Gaussian trend the relief is shrunk towards, in Z-knot spacings.
TREND_KNOTS = 20.0
#: Width of the window over which the relief's variance is estimated, in Z-knot spacings.
WINDOW_KNOTS = 10.0
#: The Wiener gain times this, at most 1: relief whose variance is at least twice its noise's
#: is kept whole (the plain Wiener gain, 1, cost sand waves 4 %: their fit's error is bias, not
#: noise; docs/notes/2026-12-02-relief-shrinkage.md).
GAIN_SCALE = 1.5


def shrink_relief(
    z: np.ndarray,
    std: np.ndarray,
    knot: float,
    dx: float,
    dy: float,
    gain_scale: float = GAIN_SCALE,
) -> np.ndarray:
    """Z with the relief its noise could explain shrunk towards the smooth trend.

    Parameters
    ----------
    z, std : ndarray, shape (pings, cells)
        Elevation and its standard deviation, metres; NaN where there is no estimate.
    knot : float
        The Z knots' spacing, metres.
    dx, dy : float
        Ground cell and ping spacing, metres.
    gain_scale : float
        The Wiener gain's factor (:data:`GAIN_SCALE`).

    Returns
    -------
    ndarray, shape (pings, cells)
        The shrunk elevation (``z`` itself where ``z`` or ``std`` is NaN).
    """
    ok = np.isfinite(z) & np.isfinite(std)
    if not ok.any():
        return z
    weight = ok.astype(np.float64)
    zf = np.where(ok, z, 0.0)
    sigma = (TREND_KNOTS * knot / dy, TREND_KNOTS * knot / dx)
    cover = _near_gaussian(weight, sigma)
    trend = _near_gaussian(zf, sigma) / np.maximum(cover, 1e-12)
    d = np.where(ok, zf - trend, 0.0)
    noise = np.where(ok, std, 0.0) ** 2
    size = (max(1, round(WINDOW_KNOTS * knot / dy)), max(1, round(WINDOW_KNOTS * knot / dx)))
    count = np.maximum(ndimage.uniform_filter(weight, size, mode="nearest"), 1e-12)
    power = ndimage.uniform_filter(d * d, size, mode="nearest") / count
    floor = ndimage.uniform_filter(noise, size, mode="nearest") / count
    relief = np.maximum(power - floor, 0.0)
    gain = np.minimum(1.0, gain_scale * relief / np.maximum(relief + noise, 1e-30))
    return np.where(ok, trend + gain * d, z)


def _near_gaussian(values: np.ndarray, sigma: tuple[float, float]) -> np.ndarray:
    """A Gaussian filter of std ``sigma`` (samples per axis) as three box filters.

    Three passes of an odd box of ``w`` samples have the variance ``(w² − 1) / 4``; each pass
    costs the same whatever its width, where ``ndimage.gaussian_filter`` costs its width (9 s a
    side for 1000 pings × 2000 cells at the coarsened fits' knots, against 0.3 s).
    """
    out = values
    for axis, s in enumerate(sigma):
        width = 2 * round((np.sqrt(4.0 * s * s + 1.0) - 1.0) / 2.0) + 1
        for _ in range(3):
            out = ndimage.uniform_filter1d(out, int(width), axis=axis, mode="nearest")
    return out
