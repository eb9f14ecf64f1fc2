"""Scene description files (TOML): seabed, objects with poses, sonar and trajectory.

A description is turned into plain data: a :class:`Scene`, a :class:`Sonar` and a
:class:`Trajectory`. A bare model file (glTF, OBJ, PLY, STL, VRML) gets a default flat sandy
seabed and a track that passes it in the middle of the starboard swath. The format is
documented in docs/scene-files.md.
"""

from __future__ import annotations

import errno
import logging
import math
import os
import stat
import sys
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from .._checks import positive
from ..errors import SonarRasterError
from ..scene import MeshPart, Scene, build_scene
from ..sonar import SIDES, BeamPattern, Sonar
from ..trajectory import Trajectory
from .seabed import Heightfield, level_of_detail, make_seabed, reflectivity_map

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

log = logging.getLogger(__name__)

MODEL_SUFFIXES = (".wrl", ".vrml", ".gltf", ".glb", ".obj", ".ply", ".stl", ".off")
_Y_UP_SUFFIXES = (".gltf", ".glb", ".wrl", ".vrml")  # y-up by their specifications
DEFAULT_SEABED_REFLECTIVITY = 0.3  # sand, relative to a rigid object's ~0.9


@dataclass(frozen=True)
class SceneSetup:
    """Everything a render needs, as loaded from a description or a bare model."""

    scene: Scene
    sonar: Sonar
    trajectory: Trajectory
    source: str
    altitude: float
    pulse: Any = None  # coherent.Pulse from [pulse]; None: the default for the sonar
    coherent: dict = field(default_factory=dict)  # render_coherent options from [coherent]
    effects: Any = None  # effects.Effects from [effects]; None: no sensor effects
    notes: dict = field(
        default_factory=dict
    )  # what loading changed (level of detail), for metadata


@dataclass(frozen=True)
class Overrides:
    """Command-line overrides; None keeps the description's value."""

    max_range: float | None = None
    range_bin: float | None = None
    altitude: float | None = None
    pings: int | None = None
    sides: tuple[str, ...] | None = None


def load_scene_file(path: str | Path, overrides: Overrides | None = None) -> SceneSetup:
    """Load a ``.toml`` scene description or a bare model file.

    Parameters
    ----------
    path : str or Path
        The description or model file.
    overrides : Overrides, optional
        Values that replace the file's sonar and trajectory settings.

    Raises
    ------
    SonarRasterError
        On a missing file, an unknown extension, or any invalid entry (the message names it).
    """
    path = Path(path)
    ov = overrides or Overrides()
    _check_regular_file(path)
    suffix = path.suffix.lower()
    if suffix == ".toml":
        return _from_description(path, ov)
    if suffix in MODEL_SUFFIXES:
        return _from_model(path, ov)
    raise SonarRasterError(
        f"{path}: unknown scene extension {suffix or '(none)'!r}; use .toml or a model file "
        f"({', '.join(MODEL_SUFFIXES)})"
    )


def load_scene(source: str | Path, overrides: Overrides | None = None) -> SceneSetup:
    """Load a bundled scene by name (``"default"``, ``"barrel_on_sand"``, ...) or a file.

    Parameters
    ----------
    source : str or Path
        A bundled scene's name (see :func:`~sonar_raster.scenes.list_bundled`), or the path of
        a ``.toml`` description or a model file (anything that exists or has an extension).
    overrides : Overrides, optional
        Values that replace the scene's sonar and trajectory settings.
    """
    path = Path(source)
    if not (path.exists() or path.is_symlink() or path.suffix):
        from .bundled import bundled_scene

        path = bundled_scene(str(source))
    return load_scene_file(path, overrides)


def _check_regular_file(path: Path) -> None:
    """Raise naming what ``path`` is when it is not a readable regular file."""
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        if path.is_symlink():
            raise SonarRasterError(
                f"scene file {path} is a broken symbolic link (to {os.readlink(path)})"
            ) from None
        raise SonarRasterError(f"scene file {path} does not exist") from None
    except OSError as exc:  # ELOOP, EACCES, ENAMETOOLONG, ...
        what = "a symbolic link loop" if exc.errno == errno.ELOOP else exc.strerror or str(exc)
        raise SonarRasterError(f"cannot read scene file {path}: {what}") from None
    if stat.S_ISDIR(mode):
        raise SonarRasterError(f"scene {path} is a directory; give a .toml or model file in it")
    if not stat.S_ISREG(mode):
        kind = "a FIFO (named pipe)" if stat.S_ISFIFO(mode) else "not a regular file"
        raise SonarRasterError(f"scene {path} is {kind}; give a .toml or model file")


#: Peak bytes per ping of a straight track (poses, attitude and their temporaries).
TRACK_BYTES_PER_PING = 128


def _check_track_size(pings: int) -> None:
    """Refuse a track whose poses alone would not fit in memory, before making it."""
    from .._budget import check_memory

    check_memory(
        pings * TRACK_BYTES_PER_PING,
        f"a track of {pings} pings",
        "lower 'pings' in [trajectory] or --pings",
    )


# -- tables ------------------------------------------------------------------------------------
def _table(data: dict, key: str, where: str) -> dict:
    value = data.get(key, {})
    if not isinstance(value, dict):
        raise SonarRasterError(f"{where}: [{key}] must be a table")
    return dict(value)


def _take(table: dict, key: str, default: Any, kind: type | tuple, where: str) -> Any:
    value = table.pop(key, default)
    if value is not None and not isinstance(value, kind):
        raise SonarRasterError(f"{where}: '{key}' has the wrong type ({type(value).__name__})")
    return value


def _no_leftovers(table: dict, where: str) -> None:
    if table:
        raise SonarRasterError(f"{where}: unknown key(s) {', '.join(sorted(table))}")


def _vector(value: Any, n: tuple[int, ...], key: str, where: str) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64) if isinstance(value, (list, tuple)) else None
    if arr is None or arr.ndim != 1 or len(arr) not in n or not np.all(np.isfinite(arr)):
        sizes = " or ".join(str(k) for k in n)
        raise SonarRasterError(f"{where}: '{key}' must be a list of {sizes} finite numbers")
    return arr


# -- sonar -------------------------------------------------------------------------------------
def _beam(spec: Any, frequency: float, sound_speed: float, base: Path, where: str) -> BeamPattern:
    if spec is None:
        return BeamPattern.uniform()
    if not isinstance(spec, dict):
        raise SonarRasterError(f"{where}: 'beam' must be a table like {{ kind = \"gaussian\" }}")
    spec = dict(spec)
    kind = spec.pop("kind", "uniform")
    number = (int, float)
    if kind == "uniform":
        beam = BeamPattern.uniform()
    elif kind == "gaussian":
        beam = BeamPattern.gaussian(float(_take(spec, "beamwidth_deg", 40.0, number, where)))
    elif kind == "sinc":
        aperture = float(_take(spec, "aperture_m", 0.02, number, where))
        beam = BeamPattern.sinc(aperture, frequency, sound_speed)
    elif kind == "table":
        beam = BeamPattern.from_csv(str(base / _take(spec, "path", "", str, where)))
    else:
        raise SonarRasterError(
            f"{where}: unknown beam kind {kind!r}; use uniform, gaussian, sinc or table"
        )
    _no_leftovers(spec, f"{where} beam")
    return beam


def _sonar(table: dict, base: Path, ov: Overrides, where: str) -> Sonar:
    number = (int, float)
    frequency = float(_take(table, "frequency_hz", 400e3, number, where))
    sides = _take(table, "sides", list(SIDES), list, where)
    sound_speed = float(_take(table, "sound_speed", 1500.0, number, where))
    if not (math.isfinite(sound_speed) and sound_speed > 0):
        raise SonarRasterError(f"{where}: sound_speed must be > 0 m/s, got {sound_speed}")
    sonar = Sonar(
        frequency_hz=frequency,
        max_range=float(_take(table, "max_range", 50.0, number, where)),
        range_bin=float(_take(table, "range_bin", 0.05, number, where)),
        tilt=math.radians(float(_take(table, "tilt_deg", 20.0, number, where))),
        beam=_beam(table.pop("beam", None), frequency, sound_speed, base, where),
        sides=tuple(sides),
        sound_speed=sound_speed,
    )
    _no_leftovers(table, f"{where} [sonar]")
    changes: dict[str, Any] = {}
    if ov.max_range is not None:
        changes["max_range"] = ov.max_range
    if ov.range_bin is not None:
        changes["range_bin"] = ov.range_bin
    if ov.sides is not None:
        changes["sides"] = ov.sides
    return replace(sonar, **changes) if changes else sonar


# -- coherent model ----------------------------------------------------------------------------
def _pulse(table: dict, sonar: Sonar, where: str) -> Any:
    """[pulse]: kind (lfm | cw), bandwidth_hz (lfm), duration_s, window; None when absent."""
    if not table:
        return None
    from ..rendering.coherent.model import Pulse

    number = (int, float)
    kind = _take(table, "kind", "lfm", str, where)
    duration = _take(table, "duration_s", None, number, where)
    if kind == "cw":
        window = _take(table, "window", "none", str, where)
        length = 2.0 * sonar.range_bin / sonar.sound_speed if duration is None else duration
        pulse = Pulse.cw(float(length), window)
    elif kind == "lfm":
        window = _take(table, "window", "taylor", str, where)
        default_band = sonar.sound_speed / (2.0 * sonar.range_bin)
        band = float(_take(table, "bandwidth_hz", default_band, number, where))
        pulse = Pulse.lfm(band, None if duration is None else float(duration), window)
    else:
        raise SonarRasterError(f"{where}: unknown pulse kind {kind!r}; use lfm or cw")
    _no_leftovers(table, f"{where} [pulse]")
    return pulse


def _coherent(table: dict, where: str) -> dict:
    """[coherent]: keyword options of ``render_coherent``."""
    number = (int, float)
    out: dict[str, Any] = {}
    for key in ("spacing_wavelengths", "jitter_wavelengths"):
        if key in table:
            out[key] = float(_take(table, key, None, number, where))
    if "seed" in table:
        out["seed"] = _take(table, "seed", 0, int, where)
    if "scattering" in table:
        out["scattering"] = _take(table, "scattering", "lambert", str, where)
    beam = table.pop("horizontal_beam", None)
    if beam is not None:
        if not isinstance(beam, dict) or "width_deg" not in beam:
            raise SonarRasterError(
                f"{where}: horizontal_beam must be a table like {{ width_deg = 0.5 }}"
            )
        from ..rendering.coherent.model import HorizontalBeam

        beam = dict(beam)
        width = math.radians(float(_take(beam, "width_deg", None, number, where)))
        out["horizontal_beam"] = HorizontalBeam(width, _take(beam, "kind", "gaussian", str, where))
        _no_leftovers(beam, f"{where} [coherent] horizontal_beam")
    _no_leftovers(table, f"{where} [coherent]")
    return out


# -- sensor effects and materials --------------------------------------------------------------
def _reflectivity(table: dict, default: Any, where: str) -> Any:
    """'reflectivity' (a number) or 'material' (a sediment name, see sediments.py)."""
    material = _take(table, "material", None, str, where)
    value = _take(table, "reflectivity", None, (int, float), where)
    if material is None:
        return default if value is None else value
    if value is not None:
        raise SonarRasterError(f"{where}: give 'reflectivity' or 'material', not both")
    from .sediments import material_reflectivity

    return material_reflectivity(material)


def _effects(table: dict, base: Path, where: str) -> Any:
    """[effects]: fields of effects.Effects (None when absent); tvg_curve may name a CSV file."""
    if not table:
        return None
    from ..effects.chain import Effects

    return Effects.from_table(table, base=base, where=f"{where} [effects]")


# -- seabed and objects ------------------------------------------------------------------------
#: Default level of detail: seabed grids finer than this many range bins are drawn coarser.
DEFAULT_LOD_BINS = 0.5


def _seabed(
    table: dict, base: Path, where: str, sonar: Sonar, notes: dict
) -> tuple[Heightfield, MeshPart] | None:
    if not table:
        return None
    kind = table.pop("kind", "flat")
    map_file = table.pop("reflectivity_map", None)
    default = DEFAULT_SEABED_REFLECTIVITY if map_file is None else 1.0
    reflectivity = _reflectivity(table, default, f"{where} [seabed]")
    lod = table.pop("lod", True)
    if isinstance(lod, bool):
        lod_bins = DEFAULT_LOD_BINS if lod else 0.0
    elif isinstance(lod, (int, float)) and math.isfinite(lod) and lod > 0:
        lod_bins = float(lod)
    else:
        raise SonarRasterError(
            f"{where} [seabed]: lod must be true, false or a cell size in range bins (> 0)"
        )
    if "path" in table:
        table["path"] = str(base / str(table["path"]))
    field = make_seabed(str(kind), **table)
    if lod_bins > 0:
        field, report = level_of_detail(field, lod_bins * sonar.range_bin)
        if report:
            notes["seabed_lod"] = report
            log.info("seabed level of detail: %s", report)
    if map_file is not None:
        node_map = float(reflectivity) * reflectivity_map(base / str(map_file), field)
        return field, field.mesh(reflectivity=node_map, name="seabed")
    return field, field.mesh(reflectivity=float(reflectivity), name="seabed")


def _rotation(angles_deg: np.ndarray) -> np.ndarray:
    """Rotation matrix for rotations about x, then y, then z (degrees)."""
    ax, ay, az = np.radians(angles_deg)
    rx = np.array([[1, 0, 0], [0, math.cos(ax), -math.sin(ax)], [0, math.sin(ax), math.cos(ax)]])
    ry = np.array([[math.cos(ay), 0, math.sin(ay)], [0, 1, 0], [-math.sin(ay), 0, math.cos(ay)]])
    rz = np.array([[math.cos(az), -math.sin(az), 0], [math.sin(az), math.cos(az), 0], [0, 0, 1]])
    return rz @ ry @ rx


def _primitive(spec: dict, where: str) -> list[MeshPart]:
    import trimesh

    kind = spec.pop("primitive")
    number = (int, float)
    if kind == "box":
        size = _vector(_take(spec, "size", [1.0, 1.0, 1.0], list, where), (3,), "size", where)
        if np.any(size <= 0):
            raise SonarRasterError(f"{where}: 'size' must be > 0 in every axis, got {list(size)}")
        mesh = trimesh.creation.box(extents=size)
    elif kind == "cylinder":
        radius = positive(f"{where}: 'radius'", _take(spec, "radius", 0.5, number, where))
        length = positive(f"{where}: 'length'", _take(spec, "length", 2.0, number, where))
        mesh = trimesh.creation.cylinder(radius=radius, height=length, sections=64)
    elif kind == "sphere":
        radius = positive(f"{where}: 'radius'", _take(spec, "radius", 0.5, number, where))
        mesh = trimesh.creation.icosphere(subdivisions=4, radius=radius)
    else:
        raise SonarRasterError(f"{where}: unknown primitive {kind!r}; use box, cylinder or sphere")
    return [MeshPart(np.asarray(mesh.vertices), np.asarray(mesh.faces), 0.9, str(kind))]


def _object(spec: dict, base: Path, seabed: Heightfield | None, k: int) -> list[MeshPart]:
    where = f"object {k + 1}"
    spec = dict(spec)
    if "primitive" in spec:
        parts = _primitive(spec, where)
        up = "z"
    elif "file" in spec:
        from ..meshio.load import load_model

        model = base / str(spec.pop("file"))
        parts = load_model(model)
        up = "y" if model.suffix.lower() in _Y_UP_SUFFIXES else "z"
    else:
        raise SonarRasterError(
            f"{where}: give 'file' (a model) or 'primitive' (box, cylinder, sphere)"
        )
    number = (int, float)
    up = _take(spec, "up", up, str, where)
    if up not in ("y", "z"):
        raise SonarRasterError(f'{where}: \'up\' must be "y" or "z"')
    position = _vector(_take(spec, "position", [0.0, 0.0], list, where), (2, 3), "position", where)
    rotation = _rotation(
        _vector(
            _take(spec, "rotation_deg", [0.0, 0.0, 0.0], list, where), (3,), "rotation_deg", where
        )
    )
    if up == "y":
        rotation = rotation @ _rotation(np.array([90.0, 0.0, 0.0]))
    scale = float(_take(spec, "scale", 1.0, number, where))
    sink = float(_take(spec, "sink", 0.0, number, where))
    reflectivity = _reflectivity(spec, None, where)
    name = _take(spec, "name", None, str, where)
    _no_leftovers(spec, where)
    if not scale > 0:
        raise SonarRasterError(f"{where}: 'scale' must be > 0")
    moved = [(p.vertices @ rotation.T) * scale for p in parts]
    lowest = min(float(v[:, 2].min()) for v in moved)
    if len(position) == 2:  # stand it on the seabed (or on z = 0 without one)
        ground = float(seabed.height_at(position[0], position[1])) if seabed is not None else 0.0
        offset = np.array([position[0], position[1], ground - lowest - sink])
    else:
        offset = position
    out = []
    for j, (part, v) in enumerate(zip(parts, moved, strict=True)):
        label = name if name and len(parts) == 1 else (f"{name}/{part.name}" if name else part.name)
        out.append(
            MeshPart(
                v + offset,
                part.faces,
                part.reflectivity if reflectivity is None else float(reflectivity),
                label or f"object{k}_{j}",
            )
        )
    return out


# -- trajectory --------------------------------------------------------------------------------
def _trajectory(
    table: dict, ground_z: float, base: Path, ov: Overrides, where: str
) -> tuple[Trajectory, float]:
    number = (int, float)
    if "csv" in table:
        path = base / str(table.pop("csv"))
        _no_leftovers(table, f"{where} [trajectory]")
        traj = Trajectory.from_csv(str(path))
        return traj, float(traj.positions[0, 2] - ground_z)
    start = _vector(_take(table, "start", [0.0, 0.0], list, where), (2,), "start", where)
    altitude = float(_take(table, "altitude", 10.0, number, where))
    heading = float(_take(table, "heading_deg", 0.0, number, where))
    spacing = float(_take(table, "spacing", 0.1, number, where))
    pings = _take(table, "pings", 200, int, where)
    crab = float(_take(table, "crab_deg", 0.0, number, where))
    pitch = float(_take(table, "pitch_deg", 0.0, number, where))
    roll = float(_take(table, "roll_deg", 0.0, number, where))
    _no_leftovers(table, f"{where} [trajectory]")
    if ov.altitude is not None:
        altitude = ov.altitude
    if ov.pings is not None:
        pings = ov.pings
    if not (math.isfinite(altitude) and altitude > 0):
        raise SonarRasterError(f"altitude must be > 0 metres, got {altitude}")
    z = ground_z + altitude
    _check_track_size(pings)
    line = Trajectory.straight((start[0], start[1], z), heading, spacing, pings)
    # Crab turns the vehicle (and its fans) off the course; pitch tilts the fans forward.
    attitude = np.radians([crab, roll, pitch])
    traj = Trajectory(line.positions, line.headings + attitude[0], attitude[1], attitude[2])
    return traj, altitude


def _from_description(path: Path, ov: Overrides) -> SceneSetup:
    where = path.name
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise SonarRasterError(f"{where}: not valid TOML ({exc})") from None
    base = path.parent
    sonar = _sonar(_table(data, "sonar", where), base, ov, where)
    notes: dict = {}
    sea = _seabed(_table(data, "seabed", where), base, where, sonar, notes)
    objects = data.get("objects", [])
    if not isinstance(objects, list) or not all(isinstance(o, dict) for o in objects):
        raise SonarRasterError(f"{where}: objects must be [[objects]] tables")
    parts = [sea[1]] if sea else []
    for k, spec in enumerate(objects):
        parts.extend(_object(spec, base, sea[0] if sea else None, k))
    known = {"name", "description", "sonar", "seabed", "objects", "trajectory", "pulse"}
    known |= {"coherent", "effects"}
    unknown = set(data) - known
    if unknown:
        raise SonarRasterError(f"{where}: unknown top-level key(s) {', '.join(sorted(unknown))}")
    scene = build_scene(parts)
    ground = scene.ground_z if sea else 0.0
    traj, altitude = _trajectory(_table(data, "trajectory", where), ground, base, ov, where)
    pulse = _pulse(_table(data, "pulse", where), sonar, where)
    coherent = _coherent(_table(data, "coherent", where), where)
    effects = _effects(_table(data, "effects", where), base, where)
    return SceneSetup(scene, sonar, traj, str(path), altitude, pulse, coherent, effects, notes)


def _from_model(path: Path, ov: Overrides) -> SceneSetup:
    """A bare model on a flat sandy seabed, mid-swath to starboard of a track passing it."""
    sonar = _sonar({}, path.parent, ov, path.name)
    altitude = ov.altitude if ov.altitude is not None else 10.0
    if not (math.isfinite(altitude) and altitude > 0):
        raise SonarRasterError(f"altitude must be > 0 metres, got {altitude}")
    r_mid = 0.5 * sonar.max_range
    ground_range = math.sqrt(max(r_mid**2 - altitude**2, (0.25 * sonar.max_range) ** 2))
    placed = _object({"file": path.name, "position": [0.0, 0.0]}, path.parent, None, 0)
    corners = np.concatenate([p.vertices for p in placed])
    # Centre the model's footprint (not its file origin) at mid-swath, abeam of mid-track.
    shift = np.array([ground_range, 0.0, 0.0])
    shift[:2] -= 0.5 * (corners[:, :2].min(axis=0) + corners[:, :2].max(axis=0))
    objects = [replace(p, vertices=p.vertices + shift) for p in placed]
    size = max(float(np.ptp(corners, axis=0).max()), 0.1)
    length = max(20.0, 6.0 * size)
    pings = ov.pings if ov.pings is not None else 200
    _check_track_size(pings)
    seabed = make_seabed(
        "flat", size=(2.2 * sonar.max_range, length + 20.0), center=(0.0, 0.0), depth=0.0
    )
    parts = [seabed.mesh(DEFAULT_SEABED_REFLECTIVITY, "seabed"), *objects]
    scene = build_scene(parts)
    traj = Trajectory.straight(
        (0.0, -0.5 * length, altitude), 0.0, length / max(pings - 1, 1), pings
    )
    return SceneSetup(scene, sonar, traj, str(path), altitude)
