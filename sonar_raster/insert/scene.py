"""The scene of an insertion: the recording's seabed as a surface, the objects on it, three renders.

The seabed is a ribbon along the track: one cross line per ping (horizontal, along the
smoothed starboard axis, as wide as the swath plus a margin) at the depth of that ping's
seabed point, so every ping's fan finds the seabed at its tracked first-return distance. The
depths are taken along the track's arc length at each seabed point (which a pitched fan puts
ahead of or behind its ping) and read back at the pings' own arc lengths, so the ribbon never
folds back on itself.

Three renders of the rows the objects reach, with the recording's geometry (per-ping
positions, headings, roll, pitch, range bins) and its beam pattern when known, else a uniform
beam (the recording's own gain comes in through the composite): the seabed alone (B), the
seabed with the objects and their labels (F), and the same with the objects' reflectivity set
to 0 (V: the seabed they leave visible).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..scene import MeshPart, Scene, build_scene
from ..sonar import BeamPattern
from .placement import PlacedObject, track_frame
from .recording import Recording

__all__ = ["DEFAULT_SEABED_REFLECTIVITY", "Renders", "build_insert_scene", "render_passes"]

#: Reflectivity of the rendered seabed; an object's return is relative to it.
DEFAULT_SEABED_REFLECTIVITY = 0.3
#: Seabed rows rendered beyond the objects' rows (a pitched fan meets the seabed ahead).
PAD_PINGS = 40
_RIBBON_COLUMNS = 9


@dataclass(frozen=True)
class Renders:
    """Raw renders (float64, rows × bins) of one side's rows that objects reach.

    Attributes
    ----------
    rows : ndarray of int
        Rows of the recording rendered, increasing.
    seabed, full, visible : dict of str to ndarray
        B, F and V of the module docstring.
    labels : dict of str to ndarray, uint16
        The renderer's labels of F (0 none, 1 seabed, k + 1 object k).
    """

    rows: np.ndarray
    seabed: dict[str, np.ndarray]
    full: dict[str, np.ndarray]
    visible: dict[str, np.ndarray]
    labels: dict[str, np.ndarray]


def _arc(points: np.ndarray) -> np.ndarray:
    step = np.hypot(*np.diff(points[:, :2], axis=0).T)
    return np.concatenate([[0.0], np.cumsum(step)])


def _seabed_part(rec: Recording, rows: np.ndarray, reflectivity: float, side: str) -> MeshPart:
    nadir, along, starboard = track_frame(rec)
    pos = rec.trajectory.positions
    arc = _arc(pos)
    seabed_arc = arc + np.einsum("ij,ij->i", (nadir - pos)[:, :2], along[:, :2])
    order = np.argsort(seabed_arc, kind="stable")
    lo = max(0, int(rows.min()) - PAD_PINGS)
    hi = min(len(pos), int(rows.max()) + PAD_PINGS + 1)
    keep = [lo]
    for i in range(lo + 1, hi):  # pings that moved: a stationary ping adds no cross line
        if arc[i] - arc[keep[-1]] > 1e-2:
            keep.append(i)
    k = np.asarray(keep)
    z = np.interp(arc[k], seabed_arc[order], nadir[order, 2])
    width = rec.image.sonar.max_range + 5.0
    cols = np.linspace(-2.0, width, _RIBBON_COLUMNS)  # the side's swath and a little beyond
    if side == "port":
        cols = -cols[::-1]
    centre = pos[k, :2]
    ends = 5.0 + float(np.max(np.linalg.norm(nadir[k, :2] - centre, axis=1)))
    first, last = centre[0] - ends * along[k[0], :2], centre[-1] + ends * along[k[-1], :2]
    centre = np.vstack([first, centre, last])
    across = np.vstack([starboard[k[0], :2], starboard[k, :2], starboard[k[-1], :2]])
    z = np.concatenate([[z[0]], z, [z[-1]]])
    xy = centre[:, None, :] + cols[None, :, None] * across[:, None, :]
    verts = np.concatenate([xy, np.broadcast_to(z[:, None, None], (*xy.shape[:2], 1))], axis=2)
    n_rows, n_cols = xy.shape[:2]
    idx = np.arange(n_rows * n_cols).reshape(n_rows, n_cols)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return MeshPart(verts.reshape(-1, 3), faces, reflectivity, "seabed", is_seabed=True)


def build_insert_scene(
    rec: Recording,
    objects: list[PlacedObject],
    side: str,
    seabed_reflectivity: float = DEFAULT_SEABED_REFLECTIVITY,
) -> tuple[Scene, Scene, Scene, np.ndarray]:
    """The seabed alone, seabed and objects, and the same with dark objects; the rows to render.

    Parameters
    ----------
    rec : Recording
    objects : list of PlacedObject
        The objects of one side; object j (0-based) becomes scene object j + 1 (label j + 2).
    side : str
        The side rendered: the seabed covers its swath only.
    seabed_reflectivity : float
        Reflectivity of the rendered seabed.

    Returns
    -------
    seabed, full, dark : Scene
    rows : ndarray of int
        Rows of the recording the objects reach.
    """
    rows = np.unique(np.concatenate([o.rows for o in objects]))
    seabed = _seabed_part(rec, rows, seabed_reflectivity, side)
    parts = [seabed] + [
        MeshPart(o.vertices, o.mesh.faces, o.mesh.reflectivity, f"{o.mesh.label}#{k + 1}")
        for k, o in enumerate(objects)
    ]
    full = build_scene(parts)
    dark = replace(full, reflectivity=np.where(full.object_id == 0, full.reflectivity, 0.0))
    own = full.object_id == 0
    alone = Scene(
        full.vertices, full.faces[own], full.reflectivity[own], full.object_id[own],
        full.names[:1], full.ground_z, two_sided=full.two_sided_faces()[own],
    )  # fmt: skip
    return alone, full, dark, rows


def render_passes(
    renderer: object,
    rec: Recording,
    scenes: tuple,
    rows: np.ndarray,
    side: str,
    beam: tuple[BeamPattern, float] | None = None,
) -> Renders:
    """Render B, F (with labels) and V of one side over ``rows`` with the recording's geometry.

    Parameters
    ----------
    renderer : RasterRenderer
        A GL renderer with the object-id pass, owned by the caller.
    rec : Recording
    scenes : (Scene, Scene, Scene)
        The seabed alone, the full scene and the dark-object scene.
    rows : ndarray of int
        Rows of the recording to render.
    side : str
        "port" or "starboard".
    beam : (BeamPattern, float), optional
        The recording's vertical beam pattern and its tilt (radians), when known; default a
        uniform beam (the gain measured on the seabed then stands for the beam at the
        seabed's depression angle, also for an object's higher points at the same range).

    Returns
    -------
    Renders
    """
    alone, full, dark = scenes
    pattern, tilt = beam if beam is not None else (BeamPattern.uniform(), rec.image.sonar.tilt)
    sonar = replace(rec.image.sonar, beam=pattern, tilt=tilt, sides=(side,))
    track = rec.trajectory.subset(rows)
    b = renderer.render(alone, sonar, track)  # type: ignore[attr-defined]
    f = renderer.render(full, sonar, track, labels=True)  # type: ignore[attr-defined]
    v = renderer.render(dark, sonar, track)  # type: ignore[attr-defined]

    def f64(image: object) -> dict[str, np.ndarray]:
        return {s: np.asarray(a, dtype=np.float64) for s, a in image.sides.items()}  # type: ignore[attr-defined]

    return Renders(rows, f64(b), f64(f), f64(v), dict(f.labels))
