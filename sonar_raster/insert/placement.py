"""Where inserted objects stand: on the recording's seabed, in a ping's fan, inside the swath.

An object placed at ``(ping, x)`` has its footprint centred at signed ground range ``x``
(metres across the track, negative to port) from the seabed point below that ping in its fan
(:meth:`Recording.nadir`), its lowest point on that seabed, so its highlight falls in that
ping's row. The seabed is taken flat across the track at the tracked depth of each ping.

Checks, each one line naming the object: the ping must be in the recording and have a bottom
track of its own nearby (half of the pings within :data:`TRACK_PINGS`), the object must not
cross the track, its far edge must lie within the maximum slant range, its top below the
transducer, and its along-track extent inside the recording.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import SonarRasterError
from ..trajectory import heading_axes
from .objects import ObjectMesh
from .recording import Recording

__all__ = ["PlacedObject", "draw_placement", "place_object", "track_frame"]

#: A placement needs a bottom track on half of the pings within this many pings of it.
TRACK_PINGS = 5
#: Drawn objects keep this much clear ground between their footprints, metres.
CLEARANCE_M = 1.0
#: Drawn ground ranges, as fractions of the swath's ground width at the ping.
DRAW_RANGE = (0.15, 0.85)
_DRAW_TRIES = 50


@dataclass(frozen=True)
class PlacedObject:
    """An object stood on the recording's seabed.

    Attributes
    ----------
    mesh : ObjectMesh
    ping : int
        Row of the recording whose fan holds the object's centre.
    ground_range : float
        Signed ground range of the footprint's centre, metres (negative: port).
    side : str
        "port" or "starboard".
    vertices : ndarray, shape (n, 3), float64
        World metres (the recording's local frame).
    rows : ndarray of int
        Rows of the recording the object and its shadow can reach.
    """

    mesh: ObjectMesh
    ping: int
    ground_range: float
    side: str
    vertices: np.ndarray
    rows: np.ndarray

    def record(self) -> dict:
        """A JSON-able description."""
        return {
            "class": self.mesh.label,
            "source": self.mesh.source,
            "params": self.mesh.params,
            "reflectivity": self.mesh.reflectivity,
            "ping": int(self.ping),
            "ground_range_m": float(self.ground_range),
            "side": self.side,
            "size_m": [float(v) for v in self.mesh.size],
            "position_m": [float(v) for v in self.vertices.mean(axis=0)],
            "base_z_m": float(self.vertices[:, 2].min()),
        }


def _smooth_headings(headings: np.ndarray, half: int = 10) -> np.ndarray:
    """Running circular mean of the headings over ±half pings."""
    z = np.exp(1j * headings)
    k = np.ones(2 * half + 1)
    num = np.convolve(np.pad(z, half, mode="edge"), k, mode="valid")
    return np.angle(num)


def track_frame(rec: Recording) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per ping: the seabed point in its fan, and horizontal along-track and starboard axes.

    Parameters
    ----------
    rec : Recording

    Returns
    -------
    nadir, along, starboard : ndarray, shape (pings, 3)
        The axes come from the headings smoothed over ±10 pings (the fan's own jitter would
        tilt the seabed's cross lines into each other).
    """
    heading = _smooth_headings(rec.trajectory.headings)
    axes = [heading_axes(float(h)) for h in heading]
    along = np.array([a for a, _ in axes])
    starboard = np.array([s for _, s in axes])
    return rec.nadir(), along, starboard


def _name(k: int, mesh: ObjectMesh) -> str:
    return f"object {k + 1} ({mesh.label})"


def place_object(
    rec: Recording, mesh: ObjectMesh, ping: int, ground_range: float, k: int = 0
) -> PlacedObject:
    """Stand ``mesh`` on the seabed at ``(ping, ground_range)``, checking it fits the swath.

    Parameters
    ----------
    rec : Recording
    mesh : ObjectMesh
    ping : int
        Row of the recording.
    ground_range : float
        Signed ground range of the footprint's centre, metres (negative: port).
    k : int
        The object's position in the request, for messages (0-based).

    Returns
    -------
    PlacedObject

    Raises
    ------
    SonarRasterError
        When the object would stand outside the swath or the recording, or where the
        recording has no bottom track.
    """
    name = _name(k, mesh)
    pings, bins = rec.shape
    if not (isinstance(ping, (int, np.integer)) and 0 <= ping < pings):
        raise SonarRasterError(f"{name}: ping {ping} is outside the recording (0 to {pings - 1})")
    if not math.isfinite(ground_range) or ground_range == 0:
        raise SonarRasterError(f"{name}: give a ground range != 0 (negative: port)")
    side = "starboard" if ground_range > 0 else "port"
    if side not in rec.sides:
        raise SonarRasterError(f"{name}: the recording has no {side} side")
    lo, hi = max(0, ping - TRACK_PINGS), min(pings, ping + TRACK_PINGS + 1)
    if rec.valid[lo:hi].mean() < 0.5:
        raise SonarRasterError(
            f"{name}: ping {ping} has no bottom track (no clear first seabed return within "
            f"{TRACK_PINGS} pings); choose a ping where the seabed shows"
        )
    nadir, along, starboard = track_frame(rec)
    sign = 1.0 if side == "starboard" else -1.0
    v = mesh.vertices
    across = ground_range + sign * v[:, 0]  # a port object is turned 180 degrees (not mirrored)
    along_off = sign * v[:, 1]
    height = float(v[:, 2].max())
    h = float(rec.vertical_altitude()[ping])
    near, far = float(np.min(np.abs(across))), float(np.max(np.abs(across)))
    if np.any(np.sign(across) != sign) or near <= 0:
        raise SonarRasterError(
            f"{name} at ping {ping}, ground range {ground_range:g} m crosses the track (its "
            f"footprint reaches {-sign * near:.3g} m); move it further out"
        )
    reach = math.hypot(far, h)
    if reach > rec.image.sonar.max_range:
        ground_max = math.sqrt(max(rec.image.sonar.max_range**2 - h * h, 0.0))
        raise SonarRasterError(
            f"{name} at ping {ping}, ground range {ground_range:g} m stands outside the swath: "
            f"its far edge is at {far:.3g} m, the swath ends at {ground_max:.3g} m (altitude "
            f"{h:.3g} m, range {rec.image.sonar.max_range:.3g} m)"
        )
    if height >= 0.9 * h:
        raise SonarRasterError(
            f"{name} is {height:.3g} m tall, too close to the sonar {h:.3g} m above the seabed "
            f"at ping {ping}; use a smaller object or another ping"
        )
    world = (
        nadir[ping]
        + across[:, None] * starboard[ping]
        + along_off[:, None] * along[ping]
        + v[:, 2:3] * np.array([0.0, 0.0, 1.0])
    )
    d = (nadir - nadir[ping]) @ along[ping]
    y0, y1 = float(along_off.min()), float(along_off.max())
    if d.min() > y0 or d.max() < y1:
        raise SonarRasterError(
            f"{name} at ping {ping} reaches past the {'start' if d.min() > y0 else 'end'} of "
            "the recording; choose a ping further inside"
        )
    margin = max(0.5, 3.0 * rec.trajectory.typical_spacing)
    rows = np.flatnonzero((d >= y0 - margin) & (d <= y1 + margin))
    rows = np.union1d(rows, [ping])
    return PlacedObject(mesh, int(ping), float(ground_range), side, world, rows)


def _footprint_radius(mesh: ObjectMesh) -> float:
    return 0.5 * float(np.hypot(*mesh.size[:2]))


def draw_placement(
    rec: Recording,
    mesh: ObjectMesh,
    rng: np.random.Generator,
    placed: list[PlacedObject],
    k: int = 0,
    sides: tuple[str, ...] | None = None,
) -> PlacedObject:
    """Draw a ping, side and ground range for ``mesh`` where it fits, clear of ``placed``.

    Parameters
    ----------
    rec : Recording
    mesh : ObjectMesh
    rng : numpy.random.Generator
    placed : list of PlacedObject
        Objects already placed; the new one keeps :data:`CLEARANCE_M` from them.
    k : int
        The object's position in the request, for messages.
    sides : tuple of str, optional
        Sides to draw from (default: the recording's).

    Returns
    -------
    PlacedObject

    Raises
    ------
    SonarRasterError
        When no fitting place was drawn in 50 tries.
    """
    pings, _ = rec.shape
    sides = sides or rec.sides
    h_all = rec.vertical_altitude()
    radius = _footprint_radius(mesh)
    span = max(1, int(math.ceil(mesh.size[1] / max(rec.trajectory.typical_spacing, 1e-3))))
    last = None
    for _ in range(_DRAW_TRIES):
        side = sides[int(rng.integers(len(sides)))]
        lo, hi = min(span + 2, pings - 1), max(span + 3, pings - span - 2)
        ping = int(rng.integers(lo, hi)) if hi > lo else pings // 2
        h = float(h_all[min(ping, pings - 1)])
        ground_max = math.sqrt(max(rec.image.sonar.max_range**2 - h * h, 0.0))
        x = float(rng.uniform(*DRAW_RANGE)) * ground_max
        sign = 1.0 if side == "starboard" else -1.0
        try:
            obj = place_object(rec, mesh, ping, sign * x, k)
        except SonarRasterError as exc:
            last = exc
            continue
        centre = obj.vertices[:, :2].mean(axis=0)
        clear = all(
            np.hypot(*(centre - p.vertices[:, :2].mean(axis=0)))
            >= radius + _footprint_radius(p.mesh) + CLEARANCE_M
            for p in placed
        )
        if clear:
            return obj
    why = f" (last: {last})" if last is not None else ""
    raise SonarRasterError(
        f"{_name(k, mesh)}: found no free place in the swath in {_DRAW_TRIES} tries{why}; "
        "use fewer or smaller objects, or give --at"
    )
