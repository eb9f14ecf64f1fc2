"""Trajectory: ping poses, and their split into near-straight segments.

Heading is a compass angle: 0 points along +y (north), 90 degrees along +x (east); pitch is
positive nose up; roll positive starboard down. The sonar's fan of beams is the plane through
the transducer perpendicular to the vehicle's fore axis (heading and pitch), so a vehicle that
crabs (heading differs from its course over ground) or pitches sweeps tilted fans along its
track. Across-track is positive to starboard.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .errors import SonarRasterError


def heading_axes(heading: float) -> tuple[np.ndarray, np.ndarray]:
    """Along-track and starboard unit vectors for a compass heading in radians."""
    along = np.array([math.sin(heading), math.cos(heading), 0.0])
    starboard = np.array([math.cos(heading), -math.sin(heading), 0.0])
    return along, starboard


def fore_axis(heading: float, pitch: float) -> np.ndarray:
    """The vehicle's fore axis (unit) for a compass heading and a nose-up pitch, radians."""
    c = math.cos(pitch)
    return np.array([math.sin(heading) * c, math.cos(heading) * c, math.sin(pitch)])


#: Largest angle between the fan's normal (fore axis) and the direction of travel.
MAX_CRAB_DEG = 60.0


@dataclass(frozen=True)
class Segment:
    """Pings on one straight line at equal spacing, rendered by one draw per side.

    Attributes
    ----------
    first, count : int
        Ping indices ``first .. first + count - 1`` of the trajectory.
    origin : ndarray, shape (3,), float64
        Position of the first ping, world metres.
    along : ndarray, shape (3,), float64
        Unit direction of travel (the heading's direction for a stationary sonar).
    fore, starboard, up : ndarray, shape (3,), float64
        The fan's orthonormal frame: the fore axis (normal of the fan plane, from the mean
        heading and pitch), to starboard (horizontal) and up, both in the fan plane. Without
        crab or pitch on a level track, ``fore == along``.
    spacing : float
        Distance between consecutive pings along ``along``, metres; 0 when the pings coincide
        (a stationary sonar: every ping gives the same row).
    width : float
        Along-track width each ping integrates over, metres (``spacing``, or the trajectory's
        typical spacing for a lone or stationary ping, or 1 m when nothing moves).
    """

    first: int
    count: int
    origin: np.ndarray
    along: np.ndarray
    starboard: np.ndarray
    up: np.ndarray
    spacing: float
    width: float
    fore: np.ndarray

    @property
    def shear(self) -> np.ndarray:
        """Map from world offsets to (travel, starboard, up) fan coordinates, shape (3, 3).

        A point ``d`` (relative to the origin) lies in the fan of the ping at travel
        ``u = d·fore / along·fore`` metres; its offset from that ping, ``d − u along``, lies in
        the fan plane with components ``starboard`` and ``up``. The rows of the matrix give
        ``(u, (d − u along)·starboard, (d − u along)·up)``.
        """
        k = self.fore / float(self.along @ self.fore)
        return np.stack(
            [
                k,
                self.starboard - float(self.along @ self.starboard) * k,
                self.up - float(self.along @ self.up) * k,
            ]
        )


@dataclass(frozen=True)
class Trajectory:
    """Ping poses in time order.

    Attributes
    ----------
    positions : ndarray, shape (n, 3), float64
        Transducer positions, world metres.
    headings : ndarray, shape (n,), float64
        Compass headings in radians.
    roll : ndarray, shape (n,), float64
        Roll in radians, positive starboard down; it tilts the beam on each side.
    pitch : ndarray, shape (n,), float64
        Pitch in radians, positive nose up; it tilts the fan forward (default 0: level).
    """

    positions: np.ndarray
    headings: np.ndarray
    roll: np.ndarray
    pitch: np.ndarray = field(default_factory=lambda: np.zeros(1))  # broadcast to every ping

    def __post_init__(self) -> None:
        p = np.asarray(self.positions, dtype=np.float64)
        if p.ndim == 1 and p.size == 3:
            p = p.reshape(1, 3)  # one pose
        if p.ndim != 2 or p.shape[1] != 3:
            raise SonarRasterError(
                f"trajectory positions must be (pings, 3) x, y, z rows, got shape {p.shape}; "
                "e.g. np.column_stack([x, y, z])"
            )
        h = np.asarray(self.headings, dtype=np.float64).reshape(-1)
        for name, angle in (("roll", self.roll), ("pitch", self.pitch)):
            size = np.size(angle)
            if size not in (1, len(h)):
                raise SonarRasterError(
                    f"trajectory {name} has {size} values for {len(h)} headings; give one per "
                    "ping or one for all"
                )
        r = np.broadcast_to(np.asarray(self.roll, dtype=np.float64).reshape(-1), h.shape).copy()
        t = np.broadcast_to(np.asarray(self.pitch, dtype=np.float64).reshape(-1), h.shape).copy()
        if len(p) == 0:
            raise SonarRasterError("the trajectory has no pings; use at least one ping")
        if len(h) != len(p):
            raise SonarRasterError("trajectory positions and headings differ in length")
        finite = np.all(np.isfinite(p)) and np.all(np.isfinite(h))
        if not (finite and np.all(np.isfinite(r)) and np.all(np.isfinite(t))):
            raise SonarRasterError("the trajectory has NaN or infinite positions or angles")
        if np.any(np.abs(t) >= math.radians(80.0)):
            raise SonarRasterError("pitch must be within ±80 degrees for a side-looking sonar")
        object.__setattr__(self, "positions", p)
        object.__setattr__(self, "headings", h)
        object.__setattr__(self, "roll", r)
        object.__setattr__(self, "pitch", t)

    @property
    def n_pings(self) -> int:
        """Number of pings."""
        return len(self.positions)

    @classmethod
    def straight(
        cls, start: tuple[float, float, float], heading_deg: float, spacing: float, count: int
    ) -> Trajectory:
        """A straight, level track of ``count`` pings ``spacing`` metres apart."""
        if not (isinstance(count, (int, np.integer)) and count >= 1):
            raise SonarRasterError(f"ping count must be a positive integer, got {count!r}")
        if not (math.isfinite(spacing) and spacing > 0):
            raise SonarRasterError(f"ping spacing must be > 0 metres, got {spacing!r}")
        heading = math.radians(heading_deg)
        along, _ = heading_axes(heading)
        pos = np.asarray(start, dtype=np.float64) + np.arange(count)[:, None] * spacing * along
        return cls(pos, np.full(count, heading), np.zeros(count))

    @classmethod
    def from_csv(cls, path: str) -> Trajectory:
        """Read poses from a CSV with a header naming ``x, y, z, heading_deg``.

        Optional columns ``roll_deg`` and ``pitch_deg`` (default 0). Headings that differ from
        the course over ground are crab: the fans follow the heading, not the course.
        """
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # "Empty input file": said below
                data: Any = np.genfromtxt(
                    path, delimiter=",", names=True, dtype=np.float64, ndmin=1, encoding="utf-8-sig"
                )
        except IndexError:  # numpy's way of saying there is no header line
            raise SonarRasterError(
                f"{path}: trajectory CSV is empty; it needs a header x,y,z,heading_deg and rows"
            ) from None
        except (OSError, ValueError, UnicodeDecodeError) as exc:
            detail = " ".join(str(exc).replace("Some errors were detected !", "").split())
            raise SonarRasterError(f"cannot read trajectory CSV {path}: {detail}") from None
        names = data.dtype.names or ()
        missing = [c for c in ("x", "y", "z", "heading_deg") if c not in names]
        if missing:
            raise SonarRasterError(f"{path}: trajectory CSV lacks column(s) {', '.join(missing)}")
        if len(data) == 0:
            raise SonarRasterError(f"{path}: trajectory CSV has a header but no rows")
        used = [c for c in ("x", "y", "z", "heading_deg", "roll_deg", "pitch_deg") if c in names]
        bad = ~np.all([np.isfinite(data[c]) for c in used], axis=0)
        if bad.any():
            row = int(np.flatnonzero(bad)[0])
            raise SonarRasterError(
                f"{path}: line {row + 2} has an empty or non-numeric cell (or inf/nan) in "
                f"{', '.join(used)}; {int(bad.sum())} row(s) like it"
            )
        roll = np.radians(data["roll_deg"]) if "roll_deg" in names else np.zeros(len(data))
        pitch = np.radians(data["pitch_deg"]) if "pitch_deg" in names else np.zeros(len(data))
        pos = np.stack([data["x"], data["y"], data["z"]], axis=1)
        return cls(pos, np.radians(data["heading_deg"]), roll, pitch)

    def subset(self, rows: slice | np.ndarray) -> Trajectory:
        """The pings ``rows`` (a slice, indices or a mask) with every pose field."""
        return Trajectory(
            self.positions[rows], self.headings[rows], self.roll[rows], self.pitch[rows]
        )

    @property
    def typical_spacing(self) -> float:
        """Median distance between consecutive pings, or 1 m if the sonar never moves."""
        if self.n_pings < 2:
            return 1.0
        d = np.linalg.norm(np.diff(self.positions, axis=0), axis=1)
        d = d[d > 1e-9]
        return float(np.median(d)) if len(d) else 1.0

    def segments(
        self, tolerance: float, max_count: int = 16384, angle_tolerance: float | None = None
    ) -> list[Segment]:
        """Split the pings into straight, evenly spaced runs with one fan orientation.

        A ping joins a segment while its position lies within ``tolerance`` metres of the
        segment's uniform line, its heading and pitch within ``angle_tolerance`` and its roll
        within 0.5 degrees of the others; a lone ping forms its own segment.

        Parameters
        ----------
        tolerance : float
            Largest allowed position error, metres (a fraction of the range bin is sensible).
        max_count : int
            Most pings per segment (the framebuffer height limit).
        angle_tolerance : float, optional
            Largest spread of heading and of pitch in a segment, radians (each segment's fans
            take the mean); default 0.5 degrees.
        """
        angle = math.radians(0.5) if angle_tolerance is None else float(angle_tolerance)
        out: list[Segment] = []
        start = 0
        n = self.n_pings
        while start < n:
            end = self._longest_run(start, tolerance, max_count, angle)
            out.append(self._make_segment(start, end))
            start = end
        return out

    def _fits(self, start: int, end: int, tolerance: float, angle: float) -> bool:
        p = self.positions[start:end]
        k = np.arange(end - start)[:, None] / max(end - start - 1, 1)
        delta = p[-1] - p[0]
        line = p[0] + k * delta
        if np.max(np.linalg.norm(p - line, axis=1)) > tolerance:
            return False
        dist = float(np.linalg.norm(delta))
        if dist > 1e-9 and math.hypot(delta[0], delta[1]) < 1e-6 * dist:
            return False  # a vertical run (a ping repeating its neighbour's fix): no fan plane
        dh = np.angle(np.exp(1j * (self.headings[start:end] - self.headings[start])))
        if np.ptp(dh) > angle or np.ptp(self.pitch[start:end]) > angle:
            return False
        roll = self.roll[start:end]
        return bool(np.ptp(roll) <= math.radians(0.5))

    def _longest_run(self, start: int, tolerance: float, max_count: int, angle: float) -> int:
        n = min(self.n_pings, start + max_count)
        good, step = start + 1, 1
        while good < n:
            trial = min(n, good + step)
            if not self._fits(start, trial, tolerance, angle):
                break
            good, step = trial, step * 2
        else:
            return good
        lo, hi = good, min(n, good + step)
        while hi - lo > 1:
            mid = (lo + hi) // 2
            lo, hi = (mid, hi) if self._fits(start, mid, tolerance, angle) else (lo, mid)
        return lo

    def _make_segment(self, start: int, end: int) -> Segment:
        p = self.positions[start:end]
        count = end - start
        delta = p[-1] - p[0]
        dist = float(np.linalg.norm(delta))
        if count > 1 and dist > 1e-9:
            along = delta / dist
            spacing = dist / (count - 1)
        else:
            along, _ = heading_axes(float(self.headings[start]))
            spacing = 0.0
        horiz = math.hypot(along[0], along[1])
        if horiz < 1e-6:
            raise SonarRasterError("a vertical trajectory segment has no side-looking geometry")
        heading = self.headings[start:end]
        mean_heading = float(np.angle(np.mean(np.exp(1j * heading))))
        fore = fore_axis(mean_heading, float(np.mean(self.pitch[start:end])))
        if spacing == 0.0:
            along = fore
        elif float(along @ fore) < math.cos(math.radians(MAX_CRAB_DEG)):
            raise SonarRasterError(
                f"pings {start}..{end - 1}: the heading is more than {MAX_CRAB_DEG:.0f} degrees "
                "off the direction of travel; check the headings (compass degrees, 0 = +y) "
                "and that the pings are in time order"
            )
        starboard = np.cross(fore, [0.0, 0.0, 1.0])
        starboard /= np.linalg.norm(starboard)
        up = np.cross(starboard, fore)
        width = spacing if spacing > 0 else self.typical_spacing
        return Segment(start, count, p[0].copy(), along, starboard, up, spacing, width, fore)
