"""A recording to insert objects into: its intensities, per-ping geometry and bottom track.

XTF side-scan samples are envelope amplitudes in most files (their speckle contrast is that
of a Rayleigh amplitude), so the intensity composited is their square; files written by this
project's ``render`` (``SonarName`` "sonar_raster") hold intensities. ``samples="auto"`` picks
by that name; "amplitude" or "intensity" overrides it.

The seabed under each ping is placed from its first return. The tracked altitude
(:func:`sonar_raster.inversion.bottom.track_bottom`) is the slant distance to the nearest
seabed point *in the side-scan fan*, which a pitch p tilts from the vertical, so the seabed
point is ``position + h · down_fan`` with ``down_fan = (sin p along track, −cos p up)``: at a
vertical distance ``h cos p`` below the transducer and ``h sin p`` ahead of it.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..errors import SonarRasterError
from ..image import SonarImage
from ..trajectory import Trajectory, fore_axis, heading_axes

__all__ = ["SAMPLE_KINDS", "Recording", "read_recording", "recording_from_image"]

SAMPLE_KINDS = ("auto", "amplitude", "intensity")
#: A side whose largest sample holds at least this fraction of its samples is saturated there.
SATURATED_FRACTION = 1e-3
#: ``SonarName`` of the XTF files this project writes (their samples are intensities).
OWN_SONAR_NAME = "sonar_raster"


@dataclass(frozen=True)
class Recording:
    """A side-scan recording in intensity, with its geometry.

    Attributes
    ----------
    intensity : dict of str to ndarray, shape (pings, bins), float64
        Linear intensity per side (the samples, or their squares), bins from range 0 outward.
    image : SonarImage
        The recording as read (samples as stored, float32), with its sonar and metadata.
    trajectory : Trajectory
        Per-ping positions (metres, local), headings, roll and pitch.
    altitude : ndarray, shape (pings,), float64
        Tracked first-return distance per ping, metres (finite everywhere).
    valid : ndarray, shape (pings,), bool
        Pings with a clear first return of their own (not interpolated).
    amplitude : bool
        True when the stored samples are amplitudes (intensity = sample²).
    source : str
        Where it came from (a path, or "image").
    frequency : float or {"low", "high"}, optional
        Of a dual-frequency XTF source, the channels read (``read_xtf``'s ``frequency``); the
        same pair is the one rewritten. None: the file's first pair.
    full_scale : dict of str to float
        Per side, the sample value the recorder saturates at: its largest sample when at
        least :data:`SATURATED_FRACTION` of the samples sit there; absent when not saturated.
    """

    intensity: dict[str, np.ndarray]
    image: SonarImage
    trajectory: Trajectory
    altitude: np.ndarray
    valid: np.ndarray
    amplitude: bool
    source: str = "image"
    frequency: float | str | None = None
    full_scale: dict[str, float] = field(default_factory=dict)

    @property
    def range_bin(self) -> float:
        """Slant-range bin, metres."""
        return float(self.image.sonar.range_bin)

    @property
    def shape(self) -> tuple[int, int]:
        """(pings, bins) of each side."""
        return self.image.shape

    @property
    def sides(self) -> tuple[str, ...]:
        """The recorded sides, "port" and/or "starboard"."""
        return tuple(self.intensity)

    def down(self) -> np.ndarray:
        """Unit vector from each transducer to its nearest seabed point in its fan, (pings, 3)."""
        t = self.trajectory
        out = np.empty((t.n_pings, 3))
        for i in range(t.n_pings):
            fore = fore_axis(float(t.headings[i]), float(t.pitch[i]))
            _, starboard = heading_axes(float(t.headings[i]))
            out[i] = -np.cross(starboard, fore)
        return out

    def nadir(self) -> np.ndarray:
        """The seabed point below each ping in its fan (first return), world metres (pings, 3)."""
        return self.trajectory.positions + self.altitude[:, None] * self.down()

    def vertical_altitude(self) -> np.ndarray:
        """Height of each transducer above the seabed under it, metres (``h cos p``)."""
        return self.altitude * np.cos(self.trajectory.pitch)

    def samples_from_intensity(self, intensity: np.ndarray) -> np.ndarray:
        """Stored samples for intensities: their square root for amplitude files.

        Parameters
        ----------
        intensity : ndarray
            Linear intensity >= 0.
        """
        values = np.maximum(np.asarray(intensity, dtype=np.float64), 0.0)
        return np.sqrt(values) if self.amplitude else values

    def saturate(self, side: str, intensity: np.ndarray) -> np.ndarray:
        """Intensities clipped where the recorder's samples saturate (see ``full_scale``).

        Parameters
        ----------
        side : str
            "port" or "starboard".
        intensity : ndarray
            Linear intensity.
        """
        top = self.full_scale.get(side)
        if top is None:
            return intensity
        return np.minimum(intensity, top * top if self.amplitude else top)


def _amplitude(kind: str, image: SonarImage) -> bool:
    if kind not in SAMPLE_KINDS:
        raise SonarRasterError(f"samples must be one of {', '.join(SAMPLE_KINDS)}, got {kind!r}")
    if kind == "auto":
        return image.metadata.get("sonar_name", "").strip("\0 ") != OWN_SONAR_NAME
    return kind == "amplitude"


def recording_from_image(
    image: SonarImage,
    trajectory: Trajectory,
    *,
    amplitude: bool = False,
    source: str = "image",
) -> Recording:
    """A :class:`Recording` of an image and its track, bottom-tracked here.

    Parameters
    ----------
    image : SonarImage
        Samples per side (pings, bins), range bins from 0 outward.
    trajectory : Trajectory
        One pose per ping.
    amplitude : bool
        The samples are amplitudes (intensity = sample²).
    source : str
        A name for messages.

    Returns
    -------
    Recording

    Raises
    ------
    SonarRasterError
        When the track has another ping count, or no ping has a clear first return (no
        bottom track: objects cannot be stood on the seabed).
    """
    from ..inversion.bottom import track_bottom

    if trajectory.n_pings != image.shape[0]:
        raise SonarRasterError(
            f"{source}: the track has {trajectory.n_pings} poses for {image.shape[0]} pings"
        )
    intensity, full_scale = {}, {}
    for side, values in image.sides.items():
        v = np.asarray(values, dtype=np.float64)
        if not (np.all(np.isfinite(v)) and np.all(v >= 0)):
            raise SonarRasterError(f"{source}: the {side} side has negative or non-finite samples")
        intensity[side] = v * v if amplitude else v
        top = float(v.max()) if v.size else 0.0
        if top > 0 and np.count_nonzero(v == top) >= SATURATED_FRACTION * v.size:
            full_scale[side] = top
    try:
        track = track_bottom(intensity, image.sonar.range_bin)
    except SonarRasterError as exc:
        raise SonarRasterError(
            f"{source} has no bottom track ({exc}); objects cannot be stood on its seabed"
        ) from None
    return Recording(
        intensity=intensity,
        image=image,
        trajectory=trajectory,
        altitude=np.asarray(track.altitude, dtype=np.float64),
        valid=np.asarray(track.valid, dtype=bool),
        amplitude=amplitude,
        source=source,
        full_scale=full_scale,
    )


def read_recording(
    path: str | os.PathLike,
    *,
    samples: str = "auto",
    pings: slice | None = None,
    frequency: float | str | None = None,
) -> Recording:
    """Read an XTF recording, its track and its bottom track.

    Parameters
    ----------
    path : str or PathLike
        An ``.xtf`` file with navigation.
    samples : {"auto", "amplitude", "intensity"}
        What the samples are; "auto": intensities in files this project wrote, else amplitudes.
    pings : slice, optional
        Which pings to read (by index among the file's side-scan pings).
    frequency : float or {"low", "high"}, optional
        A dual-frequency file's channels (Hz, or "low" / "high"; ``read_xtf``'s); the objects
        go into that pair only, the other stays as recorded. None: the first pair.

    Returns
    -------
    Recording

    Raises
    ------
    SonarRasterError
        For a file that is not a readable XTF recording with navigation, or that has no
        bottom track.
    """
    from ..io.xtf import read_xtf_track

    p = Path(path)
    if p.suffix.lower() != ".xtf":
        raise SonarRasterError(f"{p}: give a side-scan recording (.xtf)")
    trajectory, _, image = read_xtf_track(p, pings, frequency)
    rec = recording_from_image(
        image, trajectory, amplitude=_amplitude(samples, image), source=str(p)
    )
    rec = replace(rec, frequency=frequency)
    if not math.isfinite(float(np.max(rec.altitude))):
        raise SonarRasterError(f"{p} has no bottom track; objects cannot be stood on its seabed")
    return rec
