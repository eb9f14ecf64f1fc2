"""Sound absorption in sea water, Francois & Garrison (1982).

R. E. Francois and G. R. Garrison, "Sound absorption based on ocean measurements. Part II:
Boric acid contribution and equation for total absorption", J. Acoust. Soc. Am. 72(6),
1879-1890 (1982); Part I (pure water and MgSO4), JASA 72(3), 896-907 (1982).

``α = A1 P1 f1 f² / (f1² + f²) + A2 P2 f2 f² / (f2² + f²) + A3 P3 f²`` in dB/km with f in kHz:
boric acid relaxation (dominant below ~10 kHz), magnesium sulphate relaxation (10-500 kHz) and
pure-water viscosity (above ~500 kHz). Temperatures are taken as given (IPTS-68 in the paper;
the difference to ITS-90 is 0.024 % and ignored).
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import SonarRasterError


def _check(name: str, value: float, lo: float, hi: float) -> float:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and lo <= value <= hi):
        raise SonarRasterError(f"{name} must be a number in [{lo}, {hi}], got {value!r}")
    return float(value)


def francois_garrison(
    frequency_hz: float | np.ndarray,
    temperature_c: float = 10.0,
    salinity_psu: float = 35.0,
    depth_m: float = 10.0,
    ph: float = 8.0,
) -> np.ndarray:
    """Absorption coefficient of sea water, dB per metre (one way).

    Parameters
    ----------
    frequency_hz : float or ndarray
        Frequency in Hz, > 0 (the fit covers 200 Hz to 1 MHz).
    temperature_c : float
        Water temperature, °C, in [-2, 40].
    salinity_psu : float
        Salinity, PSU (‰), in [0, 45].
    depth_m : float
        Depth of the path, metres, in [0, 11000].
    ph : float
        pH, in [6, 9].

    Returns
    -------
    ndarray, shape of ``frequency_hz``, float64
        α in dB/m; a two-way path of slant range r loses ``2 α r`` dB.

    Raises
    ------
    SonarRasterError
        If a parameter is outside its range.
    """
    f = np.asarray(frequency_hz, dtype=np.float64) / 1e3  # kHz
    if f.size == 0 or not np.all(np.isfinite(f)) or np.any(f <= 0):
        raise SonarRasterError("absorption frequency must be a positive number of Hz")
    t = _check("water temperature (°C)", temperature_c, -2.0, 40.0)
    s = _check("salinity (PSU)", salinity_psu, 0.0, 45.0)
    z = _check("water depth (m)", depth_m, 0.0, 11000.0)
    ph = _check("pH", ph, 6.0, 9.0)
    kelvin = t + 273.0
    c = 1412.0 + 3.21 * t + 1.19 * s + 0.0167 * z
    # Boric acid.
    a1 = 8.86 / c * 10.0 ** (0.78 * ph - 5.0)
    f1 = 2.8 * math.sqrt(s / 35.0) * 10.0 ** (4.0 - 1245.0 / kelvin)
    # Magnesium sulphate.
    a2 = 21.44 * s / c * (1.0 + 0.025 * t)
    p2 = 1.0 - 1.37e-4 * z + 6.2e-9 * z**2
    f2 = 8.17 * 10.0 ** (8.0 - 1990.0 / kelvin) / (1.0 + 0.0018 * (s - 35.0))
    # Pure water.
    if t <= 20.0:
        a3 = 4.937e-4 - 2.59e-5 * t + 9.11e-7 * t**2 - 1.50e-8 * t**3
    else:
        a3 = 3.964e-4 - 1.146e-5 * t + 1.45e-7 * t**2 - 6.5e-10 * t**3
    p3 = 1.0 - 3.83e-5 * z + 4.9e-10 * z**2
    f_sq = f * f
    alpha_km = (
        a1 * f1 * f_sq / (f1 * f1 + f_sq) + a2 * p2 * f2 * f_sq / (f2 * f2 + f_sq) + a3 * p3 * f_sq
    )
    return alpha_km / 1000.0
