"""Sediment table: seabed backscatter per sediment from the APL-UW high-frequency model.

Five classes by grain size (Wentworth scale, φ = -log2(grain diameter / mm)) — rock, gravel,
sand, mud, clay — each stand for one row of APL-UW TR 9407 Table 2 ("Model inputs in terms of
sediment name", p. IV-6): rock → rock, gravel → sandy gravel (Mz = -1), sand → medium sand
(Mz = 1.5), mud → silt (Mz = 6), clay → clay (Mz = 9). Every Table 2 row is also a material by
its own name ("fine sand", "clayey silt", ...). The backscattering strength by grazing angle
and frequency is :func:`sonar_raster.scenes.backscatter.backscattering_strength`.

Two scattering laws use this table:

- ``"apl"`` (default for a surface given by ``material``): the rendered surface has the APL-UW
  backscattering cross section σ(θ) at the sonar's frequency at every incidence angle
  (the renderers read :func:`law_tables`).
- ``"lambert"``: ``R cos θ`` per unit area (the seed's Eq. 11), with the same level at 45°
  grazing at the reference frequency.

:attr:`Sediment.reflectivity` is R = σ(45°, 100 kHz) / cos 45°: both laws give the tabulated
level at 45° grazing and 100 kHz (the top of TR 9407's frequency range).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache

import numpy as np

from ..errors import SonarRasterError
from .backscatter import TABLE_2, SedimentParameters, angular_table, backscattering_cross_section

#: Frequency at which :attr:`Sediment.bs45_db` and the reflectivity are evaluated, Hz.
REFERENCE_FREQUENCY = 100e3

#: Scattering laws a surface can have (index 0 in a scene's per-face law array is Lambert).
LAWS = ("lambert", "apl")


@dataclass(frozen=True)
class Sediment:
    """One sediment class.

    Attributes
    ----------
    name : str
    phi_range : (float, float)
        Grain size range, φ units (Wentworth); ±inf for open ends.
    parameters : SedimentParameters
        APL-UW model inputs (TR 9407 Table 2 row).
    description : str
    """

    name: str
    phi_range: tuple[float, float]
    parameters: SedimentParameters
    description: str

    @property
    def bs45_db(self) -> float:
        """APL-UW backscattering strength at 45° grazing and 100 kHz, dB re 1 m²/(m² sr)."""
        return 10.0 * math.log10(_sigma45(self.name))

    @property
    def lambert_db(self) -> float:
        """Lambert parameter ``10 log10 μ`` for ``BS = μ sin² (grazing)``, dB."""
        return self.bs45_db - 10.0 * math.log10(0.5)

    @property
    def reflectivity(self) -> float:
        """Renderer reflectivity R, so that ``R cos θ`` equals BS45 at 45° (linear)."""
        return _sigma45(self.name) / math.cos(math.radians(45.0))

    def strength_db(self, grazing: np.ndarray, frequency: float) -> np.ndarray:
        """APL-UW backscattering strength at grazing angles (radians) and ``frequency`` (Hz).

        Parameters
        ----------
        grazing : ndarray
            Grazing angles, radians.
        frequency : float
            Hz.

        Returns
        -------
        ndarray
            dB re 1 m²/(m² sr), the shape of ``grazing``.
        """
        return 10.0 * np.log10(backscattering_cross_section(self.parameters, grazing, frequency))


def _class(name: str, phi: tuple[float, float], row: str, description: str) -> Sediment:
    return Sediment(name, phi, TABLE_2[row], description)


SEDIMENTS: dict[str, Sediment] = {
    s.name: s
    for s in (
        _class("rock", (-math.inf, -8.0), "rock", "bedrock and boulders (φ < -8)"),
        _class("gravel", (-8.0, -1.0), "sandy gravel", "pebbles and granules (-8 ≤ φ < -1)"),
        _class("sand", (-1.0, 4.0), "medium sand", "very coarse to very fine sand (-1 ≤ φ < 4)"),
        _class("mud", (4.0, 8.0), "silt", "silt and sandy or clayey silt (4 ≤ φ < 8)"),
        _class("clay", (8.0, math.inf), "clay", "clay and silty clay (φ ≥ 8)"),
    )
}

#: Every TR 9407 Table 2 row by its own name, besides the five classes.
TABLE_MATERIALS: dict[str, Sediment] = {
    name: Sediment(name, (p.mz, p.mz), p, f"TR 9407 Table 2 row, Mz = {p.mz:g} φ")
    for name, p in TABLE_2.items()
    if name not in SEDIMENTS
}

#: All material names in law order: a face with material index i (1-based) uses MATERIALS[i-1].
MATERIALS: tuple[str, ...] = (*SEDIMENTS, *TABLE_MATERIALS)


def sediment(name: str) -> Sediment:
    """The sediment class or Table 2 row called ``name`` (case-insensitive).

    Parameters
    ----------
    name : str
        A class (rock, gravel, sand, mud, clay) or a TR 9407 Table 2 name (e.g. "fine sand").

    Raises
    ------
    SonarRasterError
        If the name is not in the table (the message lists the classes).
    """
    key = " ".join(str(name).strip().lower().replace("_", " ").split())
    if key in SEDIMENTS:
        return SEDIMENTS[key]
    if key in TABLE_MATERIALS:
        return TABLE_MATERIALS[key]
    raise SonarRasterError(
        f"unknown material {name!r}; use one of {', '.join(SEDIMENTS)}, a TR 9407 sediment "
        f"name ({', '.join(TABLE_MATERIALS)}) or a number"
    )


def material_index(name: str) -> int:
    """1-based index of a material in :data:`MATERIALS` (0 is reserved for Lambert).

    Parameters
    ----------
    name : str
        A material name accepted by :func:`sediment`.
    """
    return MATERIALS.index(sediment(name).name) + 1


def material_reflectivity(name: str) -> float:
    """Renderer reflectivity of a sediment by name (see :attr:`Sediment.reflectivity`).

    Parameters
    ----------
    name : str
        A material name accepted by :func:`sediment`.
    """
    return sediment(name).reflectivity


@cache
def _sigma45(name: str) -> float:
    s = SEDIMENTS.get(name) or TABLE_MATERIALS[name]
    grazing = np.array([math.radians(45.0)])
    return float(backscattering_cross_section(s.parameters, grazing, REFERENCE_FREQUENCY)[0])


@cache
def _table(frequency: float, sound_speed: float) -> np.ndarray:
    rows = [np.full(angular_table_samples(), 1.0)]  # unused row 0 (Lambert: f/cos = 1)
    for name in MATERIALS:
        s = sediment(name)
        rows.append(angular_table(s.parameters, frequency, _sigma45(name), sound_speed=sound_speed))
    out = np.stack(rows).astype(np.float64)
    out.setflags(write=False)
    return out


def angular_table_samples() -> int:
    """Incidence-angle samples per law row (uniform from 0 to π/2 inclusive)."""
    from .backscatter import TABLE_SAMPLES

    return TABLE_SAMPLES


def law_tables(frequency: float, sound_speed: float = 1500.0) -> np.ndarray:
    """Per-material angular laws the renderers multiply a face's Lambert weight by.

    Parameters
    ----------
    frequency : float
        Sonar frequency, Hz.
    sound_speed : float
        Water sound speed, m/s.

    Returns
    -------
    ndarray, shape (1 + len(MATERIALS), samples), float64, read-only
        Row 0 is Lambert (all ones); row i is ``f(θ) / cos θ`` of material ``MATERIALS[i-1]``
        (see :func:`sonar_raster.scenes.backscatter.angular_table`) at incidence angles
        ``θ_j = j π / (2 (samples - 1))``.
    """
    if not (isinstance(frequency, (int, float)) and math.isfinite(frequency) and frequency > 0):
        raise SonarRasterError(f"frequency must be a positive number of Hz, got {frequency!r}")
    return _table(float(frequency), float(sound_speed))


def law_factor(
    law: np.ndarray, cos_incidence: np.ndarray, frequency: float, sound_speed: float = 1500.0
) -> np.ndarray:
    """``f(θ) / cos θ`` per face law index, linearly interpolated in incidence angle.

    The CPU twin of the raster's texture lookup (same table, same interpolation): the
    reference renderer multiplies its Lambert weight ``R cos θ dA`` by this.

    Parameters
    ----------
    law : ndarray of int
        Law index per sample (0 = Lambert, i = ``MATERIALS[i-1]``).
    cos_incidence : ndarray
        cos θ per sample, in [0, 1].
    frequency : float
        Sonar frequency, Hz.
    sound_speed : float
        Water sound speed, m/s.

    Returns
    -------
    ndarray, float64
        The shape of ``law``.
    """
    table = law_tables(frequency, sound_speed)
    theta = np.arccos(np.clip(cos_incidence, 0.0, 1.0))
    x = theta / (0.5 * math.pi) * (table.shape[1] - 1)
    j = np.clip(np.floor(x).astype(np.int64), 0, table.shape[1] - 2)
    w = x - j
    return table[law, j] * (1.0 - w) + table[law, j + 1] * w
