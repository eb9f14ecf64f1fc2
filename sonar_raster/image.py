"""SonarImage: the raw intensity images a renderer returns, with what made them."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from .errors import SonarRasterError
from .sonar import Sonar

#: Intensities at or above this are no-data markers (float32's largest, 3.4e38; 9.99e37), not
#: echoes in any unit: the XTF reader blanks them like NaN, ``sonar-raster invert`` refuses
#: them (its float32 products overflow near them).
NO_DATA_LEVEL = 1e30
#: The sides an image may have.
SIDE_NAMES = ("port", "starboard")


@dataclass(frozen=True)
class SonarImage:
    """Raw intensity per side.

    Attributes
    ----------
    sides : dict of str to ndarray, shape (pings, bins), float32
        Keys are "port" and/or "starboard". Rows are pings in time order, columns are slant
        range bins from near to far; bin k covers ``[k, k + 1) * sonar.range_bin`` metres.
        Values are the beam-weighted backscattering area ``Σ Φ R max(0, cos θ) dA`` in m²
        (K = 1) over the visible surface in the bin's range ring and the ping's along-track width.
    sonar : Sonar
        The sonar that made the image.
    metadata : dict
        Anything needed to reproduce the image (scene, trajectory, renderer settings).
    labels : dict of str to ndarray, shape (pings, bins), uint16, or None
        Per side, which object each cell's largest share of weight came from: 0 where nothing
        returned, else the scene's ``object_id + 1`` (``metadata["label_names"]`` names them).
        None unless the renderer was asked for labels.
    """

    sides: dict[str, np.ndarray]
    sonar: Sonar
    metadata: dict = field(default_factory=dict)
    labels: dict[str, np.ndarray] | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.sides, Mapping):
            raise SonarRasterError(
                "SonarImage sides must be a dict such as {'starboard': array of (pings, bins)}"
            )
        wrong = [k for k in self.sides if k not in SIDE_NAMES]
        if wrong:
            raise SonarRasterError(
                f"SonarImage side(s) {', '.join(map(repr, wrong))}: name them 'port' or "
                "'starboard' (lower case)"
            )
        for name, values in self.sides.items():
            if np.ndim(values) != 2:
                raise SonarRasterError(
                    f"SonarImage side {name!r} must be 2-D (pings, bins), got shape "
                    f"{np.shape(values)}"
                )

    @property
    def shape(self) -> tuple[int, int]:
        """(pings, bins) of each side."""
        first = next(iter(self.sides.values()))
        return (int(first.shape[0]), int(first.shape[1]))

    def display(self) -> np.ndarray:
        """Both sides in one array as viewers show them, shape (pings, 2 * bins) or (pings, bins).

        Port is on the left with range increasing to the left; starboard on the right with
        range increasing to the right. A missing side is left out.
        """
        parts = []
        if "port" in self.sides:
            parts.append(self.sides["port"][:, ::-1])
        if "starboard" in self.sides:
            parts.append(self.sides["starboard"])
        return np.concatenate(parts, axis=1)
