"""Sonar: frequency, range sampling, vertical beam pattern, mounting tilt and sides."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .errors import SonarRasterError

SIDES = ("port", "starboard")


@dataclass(frozen=True)
class BeamPattern:
    """Two-way vertical beam pattern Φ as a function of the angle off the beam axis.

    Stored as a table (linear interpolation, held constant outside the table), so analytic
    patterns and measured ones take the same path.

    Attributes
    ----------
    angles : ndarray, shape (k,), float64
        Angles off the beam axis in radians, increasing; positive is further below the axis.
    values : ndarray, shape (k,), float64
        Φ at those angles, dimensionless, >= 0.
    kind : str
        How the table was made ("uniform", "gaussian", "sinc", "table"), for metadata.
    """

    angles: np.ndarray
    values: np.ndarray
    kind: str = "table"

    def __post_init__(self) -> None:
        a = np.asarray(self.angles, dtype=np.float64)
        v = np.asarray(self.values, dtype=np.float64)
        if a.ndim != 1 or a.shape != v.shape or len(a) < 2:
            raise SonarRasterError("a beam pattern table needs two equal-length columns, >= 2 rows")
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(v))):
            raise SonarRasterError("the beam pattern table has NaN or infinite entries")
        if np.any(np.diff(a) <= 0) or np.any(v < 0):
            raise SonarRasterError("beam pattern angles must increase and values must be >= 0")
        object.__setattr__(self, "angles", a)
        object.__setattr__(self, "values", v)

    def __call__(self, off_axis: np.ndarray | float) -> np.ndarray:
        """Φ at angles off the axis (radians), any shape."""
        return np.interp(off_axis, self.angles, self.values)

    @property
    def is_uniform(self) -> bool:
        """True when Φ is 1 everywhere (the renderer then skips it)."""
        return bool(np.all(self.values == 1.0))

    @classmethod
    def uniform(cls) -> BeamPattern:
        """Φ = 1 at every angle."""
        return cls(np.array([-math.pi, math.pi]), np.ones(2), "uniform")

    @classmethod
    def gaussian(cls, beamwidth_deg: float, sidelobe_db: float | None = None) -> BeamPattern:
        """Gaussian two-way pattern whose full width at half power is ``beamwidth_deg``.

        ``sidelobe_db`` (< 0, two-way, relative to the peak) floors it: a transducer's
        sidelobes, which a Gaussian main lobe lacks, so that the nadir far off the axis still
        returns (the first bottom return every side-scan record shows). None: no floor.
        """
        if not beamwidth_deg > 0:
            raise SonarRasterError("beam width must be > 0 degrees")
        if sidelobe_db is not None and not (math.isfinite(sidelobe_db) and sidelobe_db < 0):
            raise SonarRasterError(f"sidelobe level must be < 0 dB, got {sidelobe_db!r}")
        a = np.linspace(-math.pi, math.pi, 3601)
        sigma = math.radians(beamwidth_deg) / (2.0 * math.sqrt(2.0 * math.log(2.0)))
        values = np.exp(-0.5 * (a / sigma) ** 2)
        if sidelobe_db is not None:
            values = np.maximum(values, 10.0 ** (sidelobe_db / 10.0))
        return cls(a, values, "gaussian")

    @classmethod
    def sinc(
        cls, aperture_m: float, frequency_hz: float, sound_speed: float = 1500.0
    ) -> BeamPattern:
        """Two-way pattern of a uniform line aperture: ``sinc(L sin(a) / λ) ** 4``."""
        if not (aperture_m > 0 and frequency_hz > 0):
            raise SonarRasterError("aperture and frequency must be > 0")
        a = np.linspace(-math.pi / 2, math.pi / 2, 7201)
        u = aperture_m * np.sin(a) * frequency_hz / sound_speed
        return cls(a, np.sinc(u) ** 4, "sinc")

    @classmethod
    def from_csv(cls, path: str) -> BeamPattern:
        """Read a table of ``angle_deg, value`` rows (header line allowed)."""
        try:
            data = np.loadtxt(
                path, delimiter=",", ndmin=2, comments="#", skiprows=_header_rows(path)
            )
        except (OSError, ValueError) as exc:
            raise SonarRasterError(f"cannot read beam pattern table {path}: {exc}") from None
        if data.shape[1] != 2:
            raise SonarRasterError(f"{path}: a beam pattern table has two columns, angle_deg,value")
        return cls(np.radians(data[:, 0]), data[:, 1], "table")


def _header_rows(path: str) -> int:
    with open(path, encoding="utf-8") as fh:
        first = fh.readline()
    try:
        [float(x) for x in first.split(",")]
    except ValueError:
        return 1
    return 0


@dataclass(frozen=True)
class Sonar:
    """A side-looking sonar.

    Attributes
    ----------
    frequency_hz : float
        Centre frequency in Hz.
    max_range : float
        Largest slant range recorded, metres.
    range_bin : float
        Slant-range size of one image column, metres; bin k covers [k, k+1) * range_bin.
    beam : BeamPattern
        Two-way vertical pattern as a function of the angle below the beam axis.
    tilt : float
        Depression of the beam axis below the horizontal, radians.
    sides : tuple of str
        Which sides are imaged, a subset of ("port", "starboard").
    sound_speed : float
        Speed of sound, m/s.
    """

    frequency_hz: float = 400e3
    max_range: float = 50.0
    range_bin: float = 0.05
    beam: BeamPattern = field(default_factory=BeamPattern.uniform)
    tilt: float = math.radians(20.0)
    sides: tuple[str, ...] = SIDES
    sound_speed: float = 1500.0

    def __post_init__(self) -> None:
        for name in ("frequency_hz", "max_range", "range_bin", "sound_speed"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise SonarRasterError(f"sonar {name} must be a positive number, got {value!r}")
        if self.range_bin > self.max_range:
            raise SonarRasterError("range bin is larger than the maximum range: no bins to image")
        if self.n_bins > 1_000_000:
            raise SonarRasterError(f"{self.n_bins} range bins is too many; use a larger range bin")
        if (
            not self.sides
            or any(s not in SIDES for s in self.sides)
            or len(set(self.sides)) < len(self.sides)
        ):
            raise SonarRasterError(
                f"sides must be port, starboard or both, each once, got {self.sides!r}"
            )
        if not math.isfinite(self.tilt):
            raise SonarRasterError("tilt must be a finite angle")
        if abs(self.tilt) > math.pi / 2:
            raise SonarRasterError(
                f"tilt is in radians, between -pi/2 and pi/2; got {self.tilt!r} (for degrees "
                f"use math.radians({self.tilt!r}))"
            )

    @property
    def n_bins(self) -> int:
        """Number of range bins (image columns)."""
        return max(1, int(round(self.max_range / self.range_bin)))

    @property
    def wavelength(self) -> float:
        """Wavelength in metres."""
        return self.sound_speed / self.frequency_hz

    def gain(self, depression: np.ndarray | float) -> np.ndarray:
        """Two-way beam gain Φ at depression angles below the horizontal (radians)."""
        return self.beam(np.asarray(depression, dtype=np.float64) - self.tilt)

    def to_dict(self) -> dict:
        """Plain description for metadata sidecars."""
        return {
            "frequency_hz": self.frequency_hz,
            "max_range_m": self.max_range,
            "range_bin_m": self.range_bin,
            "n_bins": self.n_bins,
            "tilt_deg": math.degrees(self.tilt),
            "beam": self.beam.kind,
            "sides": list(self.sides),
            "sound_speed_m_s": self.sound_speed,
        }
