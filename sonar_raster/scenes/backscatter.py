"""Seabed backscattering strength by sediment and grazing angle: the APL-UW high-frequency model.

Sources
-------
- APL-UW, "High-Frequency Ocean Environmental Acoustic Models Handbook", Applied Physics
  Laboratory, University of Washington, Technical Report APL-UW TR 9407 (October 1994),
  section IV (bottom). Table 2 (p. IV-6), "Model inputs in terms of sediment name", gives per
  sediment its mean grain size Mz (φ units), the density ratio ρ, the sound-speed ratio ν, the
  loss parameter δ, the volume parameter σ₂, the spectral exponent γ and the spectral strength
  w₂; the grain-size regressions of section IV.A (ρ, ν, δ and w₂ from Mz) reproduce that table
  (``tests/scenes/test_backscatter.py`` checks them row by row).
- The monostatic roughness cross section is the Kirchhoff term joined to the small-roughness
  perturbation term as in the APL-UW bistatic model (K. L. Williams and D. R. Jackson, "Bistatic
  bottom scattering: Model, experiments, and model/data comparison", J. Acoust. Soc. Am. 103,
  169-181 (1998); D. R. Jackson and M. D. Richardson, "High-Frequency Seafloor Acoustics",
  Springer (2007), ch. 13), evaluated at backscatter (incident = scattered grazing angle,
  azimuth π): ``σ_r = (σ_kr^-2 + σ_pr^-2)^(-1/2)``.
- The sediment-volume term is TR 9407 section IV.C's flat-interface volume cross section,
  Eq. (66): ``σ_v = 5 δ σ₂ |1 - V²|² sin²θ / (ν ln10 |P|² Im P)``, with σ₂ the ratio of the
  sediment volume-scattering coefficient to its attenuation coefficient (dB/m). The module
  evaluates the equal form ``(5 / ln10) δ σ₂ |1 + V|⁴ / (ν ρ² Im P)`` (substitute
  ``1 + V = 2ρ sinθ / (ρ sinθ + P)`` and ``1 - V = 2P / (ρ sinθ + P)``), first derived here
  by radiative transfer, then checked against the printed equation as transcribed, with its
  equation numbers, in the public ``uacpy`` port of the report (github.com/ErVuL/uacpy,
  ``uacpy/sonar/bottom_scattering.py``, Eqs. 65-66), and against the report's Table 3
  (pp. IV-23..25; silt, Mz 6, 30 kHz, σ₂ = 0.001 and 0.0003, as transcribed in uacpy's
  tests): the volume term those two columns imply agrees with this one to 0.1 dB from 5° to
  80° grazing (``tests/scenes/test_backscatter.py``). The report itself (DTIC ADB199453) was
  not readable here.
- Not implemented: TR 9407 Eq. (65) multiplies Eq. (66) by the shadowing function S(θ)
  (Eqs. 43-45) and averages it over the large-scale bottom slope (three-point Gauss-Hermite,
  Eqs. 46-49), as it does the roughness term. Like the roughness term above, the volume term
  here is the unaveraged one; the difference is under 0.1 dB above 5° for silt at 30 kHz
  (Table 3 is 4.1 dB above this model at 1°), but grows with the rms slope, i.e. with
  frequency and roughness: for medium sand at 5° it is +1.6 dB in S_b at 30 kHz, +4.7 dB at
  600 kHz.

Notation: grazing angle θ (radians, from the mean seabed plane), water wavenumber k,
``κ = (1 + iδ)/ν``, ``P(θ) = sqrt(κ² - cos²θ)`` (Im P ≥ 0), the fluid reflection coefficient
``V(θ) = (ρ sinθ - P)/(ρ sinθ + P)``, and the two-dimensional roughness spectrum
``W(K) = w₂ / (h₀ K)^γ`` with w₂ in cm⁴ and h₀ = 1 cm. The backscattering strength is
``S_b = 10 log10(σ_r + σ_v)`` in dB re 1 m²/(m² sr).

TR 9407 states the model for 10-100 kHz; side-scans at 300 kHz-1 MHz use it extrapolated (the
roughness term grows as k^(4-γ) = k^0.75; the volume term does not depend on frequency).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import SonarRasterError

#: Reference water sound speed of the model, m/s.
WATER_SOUND_SPEED = 1500.0


@dataclass(frozen=True)
class SedimentParameters:
    """Inputs of the APL-UW bottom model for one sediment (TR 9407 Table 2 notation).

    Attributes
    ----------
    name : str
        Sediment name as in TR 9407 Table 2.
    mz : float
        Mean grain size, φ units (-log2 of the diameter in mm).
    rho : float
        Density ratio ρ (sediment / water).
    nu : float
        Sound-speed ratio ν (sediment / water).
    delta : float
        Loss parameter δ (imaginary / real part of the sediment wavenumber).
    sigma2 : float
        Volume parameter σ₂ (volume-scattering coefficient / attenuation coefficient).
    gamma : float
        Spectral exponent γ of the roughness spectrum.
    w2 : float
        Spectral strength w₂ of the roughness spectrum, cm⁴ (reference wavenumber 1 cm⁻¹).
    """

    name: str
    mz: float
    rho: float
    nu: float
    delta: float
    sigma2: float
    gamma: float
    w2: float


def grain_size_parameters(mz: float, name: str = "") -> SedimentParameters:
    """Model inputs from the mean grain size by the TR 9407 section IV regressions.

    Valid for -1 ≤ Mz ≤ 9 (sandy gravel to clay); coarser beds (cobble, rock) are tabulated
    only, see :data:`TABLE_2`.

    Parameters
    ----------
    mz : float
        Mean grain size, φ units.
    name : str
        Name to give the result.

    Returns
    -------
    SedimentParameters

    Raises
    ------
    SonarRasterError
        If ``mz`` is outside [-1, 9].
    """
    if not (isinstance(mz, (int, float)) and -1.0 <= mz <= 9.0):
        raise SonarRasterError(
            f"grain size Mz = {mz!r} φ is outside the regressions' range -1..9; "
            "use a tabulated sediment (rock, cobble) for coarser beds"
        )
    m = float(mz)
    if m < 1.0:
        rho = 2.3139 + m * (-0.17057 + m * 0.007797)
        nu = 1.2778 + m * (-0.056452 + m * 0.002709)
    elif m < 5.3:
        rho = 3.0455 + m * (-1.1069031 + m * (0.2290201 - m * 0.0165406))
        nu = 1.3425 + m * (-0.1382798 + m * (0.0213937 - m * 0.0014881))
    else:
        rho = 1.1565 - m * 0.0012973
        nu = 1.0019 - m * 0.0024324
    # Attenuation: k_h (dB/m/kHz) by grain size, then δ = k_h ν c ln10 / (40000 π).
    if m < 0.0:
        kh = 0.4556
    elif m < 2.6:
        kh = 0.4556 + 0.0245 * m
    elif m < 4.5:
        kh = 0.1978 + 0.1245 * m
    elif m < 6.0:
        kh = 8.0399 - 2.5228 * m + 0.20098 * m * m
    else:
        kh = 0.9431 - 0.2041 * m + 0.0117 * m * m
    delta = kh * nu * 1528.0 * math.log(10.0) / (40000.0 * math.pi)
    ratio = (2.03846 - 0.26923 * m) / (1.0 + 0.076923 * m) if m < 5.0 else 0.5
    w2 = 0.00207 * ratio * ratio
    sigma2 = 0.002 if m < 5.5 else 0.001
    return SedimentParameters(name or f"Mz {m:g}", m, rho, nu, delta, sigma2, 3.25, w2)


def _row(name: str, mz: float, rho: float, nu: float, delta: float, sigma2: float, w2: float):
    return SedimentParameters(name, mz, rho, nu, delta, sigma2, 3.25, w2)


#: TR 9407 Table 2 (p. IV-6): name -> model inputs. ρ, ν, δ as printed; w₂ and σ₂ of the
#: rock and cobble rows as printed, the others from the section IV regressions (Table 2 prints
#: them to 4-6 digits; the test compares).
TABLE_2: dict[str, SedimentParameters] = {
    p.name: p
    for p in (
        _row("rough rock", -9.9999, 2.5, 2.5, 0.01374, 0.002, 0.20693),
        _row("rock", -9.9999, 2.5, 2.5, 0.01374, 0.002, 0.01862),
        _row("cobble", -7.0, 2.5, 1.8, 0.01374, 0.002, 0.016),
        _row("sandy gravel", -1.0, 2.492, 1.337, 0.01705, 0.002, 0.012937),
        _row("coarse sand", 0.5, 2.231, 1.2503, 0.01638, 0.002, 0.006957),
        _row("medium sand", 1.5, 1.845, 1.1782, 0.01624, 0.002, 0.004446),
        _row("fine sand", 2.5, 1.451, 1.1073, 0.01602, 0.002, 0.002715),
        _row("very fine sand", 3.5, 1.268, 1.0568, 0.01875, 0.002, 0.001544),
        _row("clayey sand", 4.0, 1.224, 1.0364, 0.02019, 0.002, 0.001119),
        _row("coarse silt", 4.5, 1.195, 1.0179, 0.02158, 0.002, 0.000781),
        _row("sandy silt", 5.0, 1.169, 0.9999, 0.01261, 0.002, 0.000518),
        _row("silt", 6.0, 1.149, 0.9873, 0.00386, 0.001, 0.000518),
        _row("fine silt", 6.5, 1.148, 0.9861, 0.00306, 0.001, 0.000518),
        _row("clayey silt", 7.0, 1.147, 0.9849, 0.00242, 0.001, 0.000518),
        _row("silty clay", 8.0, 1.146, 0.9824, 0.00163, 0.001, 0.000518),
        _row("clay", 9.0, 1.145, 0.98, 0.00148, 0.001, 0.000518),
    )
}


def _reflection(p: SedimentParameters, sin_t: np.ndarray, cos_t: np.ndarray):
    """(V, P): fluid reflection coefficient and the sediment's vertical-wavenumber ratio."""
    kappa = (1.0 + 1j * p.delta) / p.nu
    big_p = np.sqrt(kappa * kappa - cos_t * cos_t + 0j)
    big_p = np.where(big_p.imag < 0, -big_p, big_p)
    v = (p.rho * sin_t - big_p) / (p.rho * sin_t + big_p)
    return v, big_p


def spectral_strength_si(p: SedimentParameters) -> float:
    """w₂ in SI units (m^(4-γ)): W(K) = w2_si K^-γ."""
    return p.w2 * 1e-8 * 0.01 ** (-p.gamma)


def roughness_cross_section(
    p: SedimentParameters, grazing: np.ndarray, frequency: float, sound_speed: float
) -> tuple[np.ndarray, np.ndarray]:
    """Kirchhoff and small-roughness perturbation backscattering cross sections (linear).

    Parameters
    ----------
    p : SedimentParameters
        The sediment.
    grazing : ndarray
        Grazing angles, radians, in (0, π/2].
    frequency : float
        Hz.
    sound_speed : float
        Water sound speed, m/s.

    Returns
    -------
    sigma_kr, sigma_pr : ndarray
        Per unit area and steradian, the shape of ``grazing``.
    """
    t = np.asarray(grazing, dtype=np.float64)
    s, c = np.sin(t), np.cos(t)
    k = 2.0 * math.pi * frequency / sound_speed
    w2 = spectral_strength_si(p)
    alpha = p.gamma / 2.0 - 1.0
    g = math.gamma
    ch2 = 2.0 * math.pi * w2 * g(2.0 - alpha) * 2.0 ** (-2.0 * alpha)
    ch2 /= alpha * (1.0 - alpha) * g(1.0 + alpha)
    q0 = ch2 * 2.0 ** (1.0 - 2.0 * alpha) * k ** (2.0 * (1.0 - alpha))
    a = (
        8.0
        * alpha**2
        * g((1.0 + alpha) / (2.0 * alpha))
        / (g(0.5) * g(1.0 / alpha) * g(1.0 / (2.0 * alpha)))
    ) ** (2.0 * alpha)
    b = a ** ((1.0 + alpha) / (2.0 * alpha)) * g(1.0 / alpha) / (2.0 * alpha)
    v90, _ = _reflection(p, np.ones(1), np.zeros(1))
    denom = (c ** (4.0 * alpha) + a * q0 * q0 * s**4) ** ((1.0 + alpha) / (2.0 * alpha))
    sigma_kr = np.abs(v90[0]) ** 2 / (8.0 * math.pi) * b * q0 * (1.0 + 100.0 * c**4) / denom
    v, big_p = _reflection(p, s, c)
    y = ((p.rho - 1.0) ** 2 * c * c + p.rho**2 - ((1.0 + 1j * p.delta) / p.nu) ** 2) / (
        p.rho * s + big_p
    ) ** 2
    big_k = 2.0 * k * (c + 1e-4)  # the Bragg wavenumber (offset as in the APL-UW code)
    sigma_pr = 4.0 * k**4 * s**4 * np.abs(y) ** 2 * w2 * big_k ** (-p.gamma)
    return sigma_kr, sigma_pr


def volume_cross_section(p: SedimentParameters, grazing: np.ndarray) -> np.ndarray:
    """Sediment-volume backscattering cross section (linear): TR 9407 Eq. (66), see module doc.

    ``σ_v = 5 δ σ₂ |1 - V²|² sin²θ / (ν ln10 |P|² Im P)``, evaluated in the equivalent form
    ``(5 / ln10) δ σ₂ |1 + V|⁴ / (ν ρ² Im P)``; independent of frequency. Without the
    slope averaging and shadowing of Eq. (65).

    Parameters
    ----------
    p : SedimentParameters
        The sediment.
    grazing : ndarray
        Grazing angles, radians, in (0, π/2].

    Returns
    -------
    ndarray
        Per unit area and steradian, the shape of ``grazing``.
    """
    t = np.asarray(grazing, dtype=np.float64)
    v, big_p = _reflection(p, np.sin(t), np.cos(t))
    # Radiative transfer: σ_v2 = σ₂ α_dB with α_dB = 20 log10(e) k δ / ν, depth integral
    # 1 / (4 k Im P), power transmission |1 + V|⁴ / ρ² down and up; 20 log10(e) / 4 = 5 / ln10.
    num = 5.0 / math.log(10.0) * p.delta * p.sigma2 * np.abs(1.0 + v) ** 4
    return num / (p.nu * p.rho**2 * big_p.imag)


def backscattering_strength(
    p: SedimentParameters,
    grazing: np.ndarray,
    frequency: float,
    sound_speed: float = WATER_SOUND_SPEED,
) -> np.ndarray:
    """Bottom backscattering strength S_b(θ) = 10 log10(σ_r + σ_v), dB re 1 m²/(m² sr).

    Parameters
    ----------
    p : SedimentParameters
        The sediment.
    grazing : ndarray
        Grazing angles, radians, in (0, π/2].
    frequency : float
        Hz (TR 9407 states 10-100 kHz).
    sound_speed : float
        Water sound speed, m/s.

    Returns
    -------
    ndarray
        dB, the shape of ``grazing``.
    """
    return 10.0 * np.log10(backscattering_cross_section(p, grazing, frequency, sound_speed))


def backscattering_cross_section(
    p: SedimentParameters,
    grazing: np.ndarray,
    frequency: float,
    sound_speed: float = WATER_SOUND_SPEED,
) -> np.ndarray:
    """Linear σ_r + σ_v per unit area and steradian (see :func:`backscattering_strength`).

    Parameters
    ----------
    p : SedimentParameters
        The sediment.
    grazing : ndarray
        Grazing angles, radians; clipped to [1e-4, π/2].
    frequency : float
        Hz.
    sound_speed : float
        Water sound speed, m/s.

    Returns
    -------
    ndarray
        The shape of ``grazing``.
    """
    if not (math.isfinite(frequency) and frequency > 0):
        raise SonarRasterError(f"frequency must be a positive number of Hz, got {frequency!r}")
    t = np.clip(np.asarray(grazing, dtype=np.float64), 1e-4, 0.5 * math.pi)
    kr, pr = roughness_cross_section(p, t, frequency, sound_speed)
    rough = (kr**-2.0 + pr**-2.0) ** -0.5
    return rough + volume_cross_section(p, t)


#: Incidence-angle samples of a law table (0 = normal incidence .. π/2 = grazing).
TABLE_SAMPLES = 91


def angular_table(
    p: SedimentParameters,
    frequency: float,
    reference: float,
    samples: int = TABLE_SAMPLES,
    sound_speed: float = WATER_SOUND_SPEED,
) -> np.ndarray:
    """The renderer's angular law of a sediment, sampled uniformly in incidence angle.

    The renderer weighs a face by ``R · f(θ) · area`` where θ is the incidence angle (from the
    normal) and Lambert's law is ``f = cos θ``. For a sediment, ``f(θ) = σ(90° - θ) / σ_ref``
    with ``σ_ref = reference / cos 45°``, so that with R = the sediment's reflectivity
    (``reference`` = its σ at 45° grazing, see :mod:`sonar_raster.scenes.sediments`) the
    rendered seabed has the model's σ at every angle. The table holds ``f(θ) / cos θ``: the
    factor by which the raster's weight (area ∝ 1/cos θ) differs from Lambert's.

    Parameters
    ----------
    p : SedimentParameters
        The sediment.
    frequency : float
        Hz.
    reference : float
        σ at 45° grazing that R was made from (linear).
    samples : int
        Samples from θ = 0 to π/2 inclusive.
    sound_speed : float
        Water sound speed, m/s.

    Returns
    -------
    ndarray, shape (samples,), float64
        ``f(θ_j) / cos θ_j`` at ``θ_j = j π / (2 (samples - 1))``; the last (grazing) sample
        repeats the one before it (cos θ = 0 there).
    """
    theta = np.linspace(0.0, 0.5 * math.pi, samples)
    sigma = backscattering_cross_section(p, 0.5 * math.pi - theta, frequency, sound_speed)
    f = sigma * math.cos(math.radians(45.0)) / reference
    out = np.empty(samples)
    out[:-1] = f[:-1] / np.cos(theta[:-1])
    out[-1] = out[-2]
    return out
