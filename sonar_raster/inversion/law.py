"""The seabed's scattering law as the inversion's model sees it.

The model's ground cell returns ``R · f(θ) dA`` (θ the incidence angle from the facet's normal).
Lambert's law is ``f = cos θ``; another law is Lambert's times a factor
``L(c) = f(θ) / cos θ`` of ``c = cos θ``, which is what the renderers multiply a face's Lambert
weight by (:func:`sonar_raster.scenes.sediments.law_factor`). The inversion needs ``L`` and its
derivative at every cell for every trial Z, so a law here is a smooth curve: ``ln L`` is a
monotone cubic (PCHIP, continuous first derivative) through the renderers' table of 1° steps,
taken over ``c``; the model's gradients are exact for that curve. Within a table step it
differs from the renderers' linear interpolation by a fraction of the step's change
(``tests/inversion/test_law.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import SonarRasterError


@dataclass(frozen=True, eq=False)
class ScatteringLaw:
    """A smooth factor ``L(cos θ) = f(θ) / cos θ`` over Lambert's law.

    Attributes
    ----------
    name : str
        What the law is (e.g. ``"sand at 400 kHz"``), for messages and metadata.
    cos_nodes : ndarray, shape (n,)
        Increasing ``cos θ`` in [0, 1] at which ``log_factor`` is given.
    log_factor : ndarray, shape (n,)
        ``ln L`` at the nodes.
    """

    name: str
    cos_nodes: np.ndarray
    log_factor: np.ndarray

    def __post_init__(self) -> None:
        c = np.asarray(self.cos_nodes, np.float64)
        v = np.asarray(self.log_factor, np.float64)
        if c.ndim != 1 or c.shape != v.shape or c.size < 2:
            raise SonarRasterError("a scattering law needs as many values as nodes, at least two")
        if not (np.all(np.isfinite(c)) and np.all(np.isfinite(v)) and np.all(np.diff(c) > 0)):
            raise SonarRasterError("a scattering law's nodes must be finite and increasing")
        from scipy.interpolate import PchipInterpolator  # only where a law is used

        curve = PchipInterpolator(c, v, extrapolate=True)
        object.__setattr__(self, "_curve", curve)
        object.__setattr__(self, "_slope", curve.derivative())

    def log_factor_at(self, cos_incidence: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``ln L`` and ``d ln L / d cos θ`` at ``cos_incidence`` (clipped to the nodes)."""
        c = np.clip(cos_incidence, self.cos_nodes[0], self.cos_nodes[-1])
        slope = self._slope(c)  # type: ignore[attr-defined]
        inside = (cos_incidence >= self.cos_nodes[0]) & (cos_incidence <= self.cos_nodes[-1])
        value = self._curve(c)  # type: ignore[attr-defined]
        return value, np.where(inside, slope, 0.0)

    @classmethod
    def from_table(cls, name: str, table: np.ndarray) -> ScatteringLaw:
        """A law from a renderer table row: ``L`` at incidence ``j π / (2 (n − 1))``.

        The grazing end (θ = 90°, whose value repeats the one before it) is left out.
        """
        table = np.asarray(table, np.float64)
        theta = np.linspace(0.0, 0.5 * math.pi, table.size)[:-1]
        values = table[:-1]
        if np.any(~np.isfinite(values)) or np.any(values <= 0):
            raise SonarRasterError(f"the scattering law {name!r} has values that are not > 0")
        c = np.cos(theta)[::-1]
        return cls(name, c, np.log(values[::-1]))


#: What ``--law`` accepts besides a material name.
LAMBERT = "lambert"


def law_index(name: str) -> int | None:
    """The renderers' law index of ``name`` (None for ``"lambert"``); one line if unknown."""
    from ..scenes.sediments import material_index

    key = name.strip().lower()
    if key == LAMBERT:
        return None
    try:
        return material_index(key)
    except SonarRasterError as err:
        raise SonarRasterError(f"--law: {err}") from None


def scattering_law(
    name: str, frequency: float | None, sound_speed: float = 1500.0
) -> ScatteringLaw | None:
    """The law a seabed of material ``name`` has at ``frequency`` (None for Lambert's).

    Parameters
    ----------
    name : str
        ``"lambert"`` or a material of :mod:`sonar_raster.scenes.sediments` (``"sand"``,
        ``"fine sand"``, ...): its APL-UW law, as the renderers draw it.
    frequency : float or None
        Sonar frequency, Hz; needed for a material.
    sound_speed : float
        Water sound speed, m/s.

    Raises
    ------
    SonarRasterError
        An unknown name, or a material without a frequency.
    """
    from ..scenes.sediments import law_tables

    index = law_index(name)
    if index is None:
        return None
    key = name.strip().lower()
    if frequency is None or not (math.isfinite(frequency) and frequency > 0):
        raise SonarRasterError(
            f"--law {name}: the law depends on the sonar's frequency, which the input does not "
            "record: give it with --frequency KHZ (Python: scattering_law(name, hz))"
        )
    table = law_tables(float(frequency), sound_speed)[index]
    return ScatteringLaw.from_table(f"{key} at {frequency / 1e3:g} kHz", table)


def resolve_law(
    law: str | ScatteringLaw | None, frequency_hz: float | None
) -> ScatteringLaw | None:
    """``law`` as the model takes it: a name at this frequency, a law as it is, None Lambert's.

    ``frequency_hz`` (a line's recorded frequency; 0 or None where unknown) is used only for a
    name other than ``"lambert"``.
    """
    if law is None or isinstance(law, ScatteringLaw):
        return law
    known = frequency_hz if frequency_hz and frequency_hz > 0 else None
    return scattering_law(str(law), known)
