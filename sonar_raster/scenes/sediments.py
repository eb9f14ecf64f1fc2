"""Sediment table: typical high-frequency seabed backscatter per sediment class.

Each class carries a backscattering strength ``BS45`` (dB re 1 m² per m² per steradian) at 45°
grazing angle for frequencies of roughly 100-500 kHz, a representative mid value of the
spread of measurements and model predictions summarised in:

- APL-UW, "High-Frequency Ocean Environmental Acoustic Models Handbook", Applied Physics
  Laboratory, University of Washington, Technical Report APL-UW TR 9407 (1994), section on
  bottom backscattering (sediment classes from rough rock to clay);
- D. R. Jackson and M. D. Richardson, "High-Frequency Seafloor Acoustics", Springer (2007);
- X. Lurton, "An Introduction to Underwater Acoustics", 2nd ed., Springer (2010), seafloor
  backscatter chapter.

Real seabeds scatter within about ±5 dB of these values depending on roughness, shell content
and frequency: they set realistic contrasts between materials, not a calibrated level. The
grain-size range of each class is the Wentworth scale in φ = -log2(grain diameter / mm).

The renderer's scattering law is ``R cos θ`` per unit area (θ from the normal), so a material's
:attr:`Sediment.reflectivity` is ``10^(BS45 / 10) / cos 45°``: the rendered seabed then has the
tabulated backscatter at 45° grazing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..errors import SonarRasterError


@dataclass(frozen=True)
class Sediment:
    """One sediment class.

    Attributes
    ----------
    name : str
    phi_range : (float, float)
        Grain size range, φ units (Wentworth); ±inf for open ends.
    bs45_db : float
        Backscattering strength at 45° grazing, dB re 1 m²/(m² sr).
    description : str
    """

    name: str
    phi_range: tuple[float, float]
    bs45_db: float
    description: str

    @property
    def lambert_db(self) -> float:
        """Lambert parameter ``10 log10 μ`` for ``BS = μ sin² (grazing)``, dB."""
        return self.bs45_db - 10.0 * math.log10(0.5)

    @property
    def reflectivity(self) -> float:
        """Renderer reflectivity R, so that ``R cos θ`` equals BS45 at 45° (linear)."""
        return 10.0 ** (self.bs45_db / 10.0) / math.cos(math.radians(45.0))


SEDIMENTS: dict[str, Sediment] = {
    s.name: s
    for s in (
        Sediment("rock", (-math.inf, -8.0), -15.0, "bedrock and boulders (φ < -8)"),
        Sediment("gravel", (-8.0, -1.0), -20.0, "pebbles and granules (-8 ≤ φ < -1)"),
        Sediment("sand", (-1.0, 4.0), -27.0, "very coarse to very fine sand (-1 ≤ φ < 4)"),
        Sediment("mud", (4.0, 8.0), -32.0, "silt and sandy or clayey silt (4 ≤ φ < 8)"),
        Sediment("clay", (8.0, math.inf), -37.0, "clay and silty clay (φ ≥ 8)"),
    )
}


def sediment(name: str) -> Sediment:
    """The sediment class called ``name`` (case-insensitive).

    Raises
    ------
    SonarRasterError
        If the name is not in the table (the message lists the known ones).
    """
    key = str(name).strip().lower()
    if key not in SEDIMENTS:
        raise SonarRasterError(
            f"unknown material {name!r}; use one of {', '.join(SEDIMENTS)} or a number"
        )
    return SEDIMENTS[key]


def material_reflectivity(name: str) -> float:
    """Renderer reflectivity of a sediment by name (see :attr:`Sediment.reflectivity`)."""
    return sediment(name).reflectivity
