"""tools/compare_real.py with a texture below the micro-relief's grid (issue 16 experiment).

Each recorder sub-sample's intensity is multiplied by ``T = exp(s ξ − s²/2)`` (``TEX_LAW=gamma``:
a gamma texture of the same variance), ξ a unit Gaussian field correlated like the speckle
(the range cell, the along-track footprint), ``s² = TEX_SCALE · D(g)² · I(r)``: ``D`` the
slope of the sand's APL-UW ln σ at the ping's grazing angle, ``I`` the variance of the
across-track slope averaged over the resolution cell (1.25 cm × the 0.3° beam) from the sand
spectrum's wavenumbers outside the relief grid's (|Kx| or |Ky| > π / 1.5 bins). Arguments are
compare_real's. Run from the repository root:
``TEX_SCALE=1 python docs/notes/2026-12-02-sub-cell-texture/texture_exp.py``.
"""

import math
import os
import sys

import numpy as np
from scipy import ndimage, special

sys.path.insert(0, "tools")
import compare_real as cr  # noqa: E402

import sonar_raster.effects.speckle as sp  # noqa: E402
from sonar_raster.scenes.backscatter import backscattering_cross_section  # noqa: E402
from sonar_raster.scenes.seabed import MICRO_RESOLUTION_BINS, micro_relief_spectrum  # noqa: E402
from sonar_raster.scenes.sediments import sediment  # noqa: E402

SCALE = float(os.environ.get("TEX_SCALE", "1"))
LAW = os.environ.get("TEX_LAW", "lognormal")
BIN, CELL, BEAM = 0.0293, 0.0125, math.radians(0.3)  # the file's bin, the preset's cell, beam
GRID = MICRO_RESOLUTION_BINS * BIN

spectrum = micro_relief_spectrum("sand")
grazing = np.radians(np.linspace(1, 89, 300))
slope_ln_sigma = np.gradient(
    np.log(backscattering_cross_section(sediment("sand").parameters, grazing, 600e3)), grazing
)
k = np.linspace(-2500, 2500, 1001)
kx, ky = np.meshgrid(k, k)
outside = (abs(kx) > math.pi / GRID) | (abs(ky) > math.pi / GRID)
across_slope = kx**2 * spectrum(np.hypot(kx, ky))
ranges = np.arange(1.0, 32.0, 1.0)
unresolved = []
for r in ranges:  # ground-range cell at the median altitude's grazing angle
    ground = CELL / max(math.cos(math.asin(min(1.0, 5.2 / r))), 0.2)
    cell = np.sinc(kx * ground / (2 * np.pi)) ** 2 * np.sinc(ky * BEAM * r / (2 * np.pi)) ** 2
    unresolved.append((across_slope * cell)[outside].sum() * (k[1] - k[0]) ** 2)
unresolved = np.array(unresolved)

altitudes = {}
simulate = cr.simulate


def simulate_keeping_altitudes(real, alt, *args, **kwargs):
    """compare_real's simulation, its per-ping altitudes kept for the texture."""
    altitudes["h"] = np.asarray(alt)
    return simulate(real, alt, *args, **kwargs)


fine_field = sp._fine_field


def textured(entropy, pings, cols, n, sigma_along, sigma_fine, k_shape=None, looks=1.0):
    """The recorder's sub-sample intensity times the texture below the relief grid."""
    out = fine_field(entropy, pings, cols, n, sigma_along, sigma_fine, k_shape, looks)
    h = altitudes.get("h")
    if h is None or pings != len(h):  # the recorder's mean (Monte Carlo) stays untextured
        return out
    lo, hi = cols
    r = (np.arange(lo * n, hi * n) + 0.5) * BIN / n
    g = np.arcsin(np.clip(h[:, None] / np.maximum(r[None, :], 1e-3), 0, 1))
    s2 = SCALE * np.interp(g, grazing, slope_ln_sigma) ** 2 * np.interp(r, ranges, unresolved)
    rng = np.random.default_rng([lo, hi, int(entropy.entropy % 2**32)])
    z = ndimage.correlate1d(
        rng.standard_normal(out.shape), sp._range_taps(math.sqrt(2) * sigma_fine), 1, mode="wrap"
    )
    amp_along = np.repeat(math.sqrt(2.0) * np.asarray(sigma_along[lo:hi], np.float64), n)
    if np.any(amp_along > 0):
        z = sp.filter_columns(z, amp_along, circular=True)
        z = z / np.sqrt(sp._filter_gain(pings, amp_along))
    if LAW == "gamma":
        nu = np.minimum(1.0 / np.maximum(np.expm1(s2), 1e-6), 1e6)
        t = special.gammaincinv(nu, np.clip(special.ndtr(z), 1e-15, 1 - 1e-15)) / nu
    else:
        t = np.exp(np.sqrt(s2) * z - 0.5 * s2)
    return np.where(r[None, :] > h[:, None], out * t, out)


cr.simulate = simulate_keeping_altitudes
sp._fine_field = textured
sys.exit(cr.main(sys.argv[1:]))
