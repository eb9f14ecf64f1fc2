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
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from .._checks import integer, positive
from .._checks import number as finite
from ..errors import InputWarning, SonarRasterError
from ..meshio.formats import MODEL_SUFFIXES, Y_UP_SUFFIXES, model_suffix
from ..scene import MeshPart, Scene, build_scene
from ..sonar import SIDES, BeamPattern, Sonar
from ..trajectory import Trajectory
from .seabed import (
    MICRO_OUTER_SCALE,
    MICRO_RESOLUTION_BINS,
    Heightfield,
    level_of_detail,
    make_seabed,
    micro_relief,
    reflectivity_map,
)

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

log = logging.getLogger(__name__)

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


#: Length units of model files, metres per unit (``units`` key, ``--units``).
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "km": 1000.0, "in": 0.0254, "ft": 0.3048}
#: The file axis that points up (``up`` key, ``--up``): rotation angles (x, y, z) in degrees
#: that turn it to +z (right-handed, so the other two axes stay a right-handed pair).
UP_AXES = {
    "z": (0.0, 0.0, 0.0),
    "y": (90.0, 0.0, 0.0),
    "x": (0.0, -90.0, 0.0),
    "-z": (180.0, 0.0, 0.0),
    "-y": (-90.0, 0.0, 0.0),
    "-x": (0.0, 90.0, 0.0),
}
#: A bare model larger or smaller than this (largest extent, metres) is probably in other
#: units than the ones it is read in: the load warns, naming --units/--scale.
PLAUSIBLE_SIZE_M = (0.05, 50.0)
#: Fewer range bins than this per side image almost nothing: the load warns.
FEW_BINS = 32


@dataclass(frozen=True)
class Placement:
    """How a bare model file is put into the world (``--up``, ``--units``, ``--scale``, ...).

    Attributes
    ----------
    up : str, optional
        The file's axis that points up: one of :data:`UP_AXES`; None: by format (glTF and
        VRML "y", others "z").
    units : str
        Length unit of the file's coordinates, a key of :data:`UNITS`.
    scale : float
        Extra factor on top of the units, > 0.
    position : tuple of float, optional
        ``(x, y)`` or ``(x, y, z)`` in metres: the centre of the model's footprint, and the
        height of its lowest point above the seabed (default 0: resting on it; negative
        buries it). None: mid-swath to starboard of the middle of the automatic track.
    """

    up: str | None = None
    units: str = "m"
    scale: float = 1.0
    position: tuple[float, ...] | None = None

    @property
    def is_default(self) -> bool:
        """True when nothing was asked for (the format's defaults apply)."""
        return self == Placement()


@dataclass(frozen=True)
class RecordedTrack:
    """A track taken from a recording (``render --track FILE.xtf``), in local metres.

    Attributes
    ----------
    positions : ndarray, shape (n, 2), float64
        Horizontal positions, metres east and north of an arbitrary local origin.
    altitude : ndarray, shape (n,), float64
        Altitude above the seabed per ping, metres, > 0.
    headings, roll, pitch : ndarray, shape (n,), float64
        Radians, as in :class:`Trajectory`.
    source : str
        Where it came from, for messages and metadata.
    """

    positions: np.ndarray
    altitude: np.ndarray
    headings: np.ndarray
    roll: np.ndarray
    pitch: np.ndarray
    source: str = ""

    def placed(self, middle: np.ndarray, ground_z: float) -> Trajectory:
        """The track moved so its middle ping is over ``middle`` (x, y), seabed at ground_z."""
        mid = len(self.positions) // 2
        xy = self.positions - self.positions[mid] + np.asarray(middle, dtype=np.float64)[:2]
        pos = np.column_stack([xy, ground_z + self.altitude])
        return Trajectory(pos, self.headings, self.roll, self.pitch)


@dataclass(frozen=True)
class Overrides:
    """Command-line overrides; None keeps the description's value.

    ``frequency_hz``, ``tilt_deg``, ``sound_speed`` replace the ``[sonar]`` values;
    ``beamwidth_deg`` replaces its beam by a Gaussian two-way vertical beam of that full width
    at half power; ``heading_deg`` and ``ping_spacing`` (metres) the straight track's;
    ``speed`` (m/s) sets the ping spacing to the distance run in one ping period (two-way
    travel time to the maximum range); ``track`` replaces the track by a recorded one;
    ``placement`` places a bare model file (a description places its objects itself);
    ``micro_relief = False`` leaves out a seabed's ``micro_relief`` (the ideal image).
    Numbers are checked when made: finite, and > 0 except the tilt and heading.
    """

    max_range: float | None = None
    range_bin: float | None = None
    altitude: float | None = None
    pings: int | None = None
    sides: tuple[str, ...] | None = None
    frequency_hz: float | None = None
    tilt_deg: float | None = None
    beamwidth_deg: float | None = None
    sound_speed: float | None = None
    heading_deg: float | None = None
    ping_spacing: float | None = None
    speed: float | None = None
    track: RecordedTrack | None = None
    placement: Placement | None = None
    micro_relief: bool | None = None

    def __post_init__(self) -> None:
        for name, unit in _POSITIVE_OVERRIDES.items():
            if getattr(self, name) is not None:
                positive(f"{name} ({unit})", getattr(self, name))
        for name in ("tilt_deg", "heading_deg"):  # any sign; the tilt's range is checked at load
            if getattr(self, name) is not None:
                finite(f"{name} (degrees)", getattr(self, name))
        if self.pings is not None:
            integer("pings", self.pings)


#: Fields of :class:`Overrides` that are None or a finite number > 0, with their units.
_POSITIVE_OVERRIDES = {
    "max_range": "metres",
    "range_bin": "metres",
    "altitude": "metres",
    "frequency_hz": "Hz",
    "beamwidth_deg": "degrees",
    "sound_speed": "m/s",
    "ping_spacing": "metres",
    "speed": "m/s",
}


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
    _check_overrides(ov)
    if suffix == ".toml":
        if ov.placement is not None and not ov.placement.is_default:
            raise SonarRasterError(
                f"{path.name}: --up, --units, --scale and --position place a bare model file; "
                "in a scene description give 'up', 'units', 'scale' and 'position' per "
                "[[objects]] entry"
            )
        return _checked_setup(_from_description(path, ov), ov)
    if model_suffix(path) is not None:
        return _checked_setup(_from_model(path, ov), ov)
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


def _check_overrides(ov: Overrides) -> None:
    """Refuse overrides that contradict each other, naming the options."""
    if ov.ping_spacing is not None and ov.speed is not None:
        raise SonarRasterError("give --ping-spacing or --speed, not both")
    if ov.track is not None:
        clash = [
            name
            for name, value in (
                ("--heading", ov.heading_deg),
                ("--ping-spacing", ov.ping_spacing),
                ("--speed", ov.speed),
                ("--altitude", ov.altitude),
            )
            if value is not None
        ]
        if clash:
            raise SonarRasterError(
                f"{', '.join(clash)} cannot be combined with --track: the recorded track "
                "sets the headings, the spacing and the altitude"
            )


def _checked_setup(setup: SceneSetup, ov: Overrides) -> SceneSetup:
    """Warn about sonar settings that image little (few bins, a tilt with no beam)."""
    sonar = setup.sonar
    if sonar.n_bins < FEW_BINS:
        warnings.warn(
            f"range bin {sonar.range_bin:g} m over the {sonar.max_range:g} m range leaves "
            f"{sonar.n_bins} range bin{'s' if sonar.n_bins != 1 else ''} per side: the image "
            f"is {sonar.n_bins} pixel{'s' if sonar.n_bins != 1 else ''} wide; lower "
            "--range-bin (e.g. 0.05) or raise --range",
            InputWarning,
            stacklevel=3,
        )
    if ov.tilt_deg is not None and sonar.beam.is_uniform:
        warnings.warn(
            f"--tilt {ov.tilt_deg:g} changes nothing with a uniform vertical beam; give "
            "--beamwidth (or a beam in the scene's [sonar]) for the tilt to shape the image",
            InputWarning,
            stacklevel=3,
        )
    return setup


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
    kinds = kind if isinstance(kind, tuple) else (kind,)
    wrong = value is not None and not isinstance(value, kind)
    if wrong or (isinstance(value, bool) and bool not in kinds):  # TOML true is no number
        raise SonarRasterError(f"{where}: '{key}' has the wrong type ({type(value).__name__})")
    return value


def _no_leftovers(table: dict, where: str) -> None:
    if table:
        raise SonarRasterError(f"{where}: unknown key(s) {', '.join(sorted(table))}")


def _vector(value: Any, n: tuple[int, ...], key: str, where: str) -> np.ndarray:
    numbers = isinstance(value, (list, tuple)) and all(
        isinstance(v, (int, float)) and not isinstance(v, bool) for v in value
    )
    arr = np.asarray(value, dtype=np.float64) if numbers else None
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
        width = float(_take(spec, "beamwidth_deg", 40.0, number, where))
        floor = _take(spec, "sidelobe_db", None, number, where)
        beam = BeamPattern.gaussian(width, None if floor is None else float(floor))
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
    tilt_deg = float(_take(table, "tilt_deg", 20.0, number, where))
    frequency = frequency if ov.frequency_hz is None else ov.frequency_hz
    sound_speed = sound_speed if ov.sound_speed is None else ov.sound_speed
    tilt_deg = tilt_deg if ov.tilt_deg is None else ov.tilt_deg
    if not (math.isfinite(sound_speed) and sound_speed > 0):
        raise SonarRasterError(f"{where}: sound_speed must be > 0 m/s, got {sound_speed}")
    if not -90.0 <= tilt_deg <= 90.0:
        raise SonarRasterError(
            f"{where}: tilt_deg must be between -90 and 90 degrees below the horizontal, got "
            f"{tilt_deg:g}"
        )
    beam_spec = table.pop("beam", None)
    if ov.beamwidth_deg is not None:
        beam_spec = {"kind": "gaussian", "beamwidth_deg": ov.beamwidth_deg}
    sonar = Sonar(
        frequency_hz=frequency,
        max_range=float(_take(table, "max_range", 50.0, number, where)),
        range_bin=float(_take(table, "range_bin", 0.05, number, where)),
        tilt=math.radians(tilt_deg),
        beam=_beam(beam_spec, frequency, sound_speed, base, where),
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


def _sensor_preset(data: dict, where: str) -> dict:
    """Issue 16 hook: expand ``[sonar] preset`` (see effects.presets.apply_sensor_preset)."""
    from ..effects.presets import apply_sensor_preset

    return apply_sensor_preset(data, where)


# -- sensor effects and materials --------------------------------------------------------------
def _reflectivity(table: dict, default: Any, where: str) -> tuple[Any, int]:
    """'reflectivity' or 'material' (see sediments.py), and the law ('scattering' = apl|lambert)."""
    material = _take(table, "material", None, str, where)
    value = _take(table, "reflectivity", None, (int, float), where)
    law = _take(table, "scattering", None, str, where)
    if material is None:
        if law not in (None, "lambert"):
            raise SonarRasterError(f"{where}: scattering = {law!r} needs a 'material'")
        return (default if value is None else value), 0
    if value is not None:
        raise SonarRasterError(f"{where}: give 'reflectivity' or 'material', not both")
    from .sediments import LAWS, material_index, material_reflectivity

    if law not in (None, *LAWS):
        raise SonarRasterError(f"{where}: scattering must be one of {', '.join(LAWS)}")
    index = 0 if law == "lambert" else material_index(material)
    return material_reflectivity(material), index


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
    table: dict, base: Path, where: str, sonar: Sonar, notes: dict, with_relief: bool = True
) -> tuple[Heightfield, MeshPart] | None:
    if not table:
        return None
    kind = table.pop("kind", "flat")
    map_file = table.pop("reflectivity_map", None)
    relief = _micro_relief(table, sonar, f"{where} [seabed]")
    default = DEFAULT_SEABED_REFLECTIVITY if map_file is None else 1.0
    reflectivity, law = _reflectivity(table, default, f"{where} [seabed]")
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
    if relief is not None and with_relief:
        field = micro_relief(field, **relief)
        notes["seabed_micro_relief"] = {**relief, "cell_m": [field.dx, field.dy]}
    if map_file is not None:
        node_map = float(reflectivity) * reflectivity_map(base / str(map_file), field)
        return field, replace(field.mesh(reflectivity=node_map, name="seabed"), law=law)
    return field, replace(field.mesh(reflectivity=float(reflectivity), name="seabed"), law=law)


def _micro_relief(table: dict, sonar: Sonar, where: str) -> dict | None:
    """The arguments of :func:`.seabed.micro_relief` from a ``[seabed]`` table, or None.

    ``micro_relief = true`` or ``{ sediment, resolution, outer_scale, seed }``; the sediment
    defaults to the seabed's ``material``, the resolution to ``MICRO_RESOLUTION_BINS`` bins.
    """
    spec = table.pop("micro_relief", False)
    if spec is False:
        return None
    if spec is True:
        spec = {}
    if not isinstance(spec, dict):
        raise SonarRasterError(
            f"{where}: micro_relief must be true, false or a table "
            f"{{ sediment = NAME, resolution = M, outer_scale = M, seed = N }}, got {spec!r}"
        )
    spec = dict(spec)
    sediment = spec.pop("sediment", table.get("material"))
    if not isinstance(sediment, str):
        raise SonarRasterError(
            f"{where}: micro_relief needs a sediment (its roughness spectrum): give the seabed a "
            "'material' or write micro_relief = { sediment = \"sand\" }"
        )
    out = {
        "sediment": sediment,
        "resolution": _take(
            spec, "resolution", MICRO_RESOLUTION_BINS * sonar.range_bin, (int, float), where
        ),
        "outer_scale": _take(spec, "outer_scale", MICRO_OUTER_SCALE, (int, float), where),
        "seed": _take(spec, "seed", 0, int, where),
    }
    _no_leftovers(spec, f"{where} micro_relief")
    return out


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
        up = "y" if model_suffix(model) in Y_UP_SUFFIXES else "z"
    else:
        raise SonarRasterError(
            f"{where}: give 'file' (a model) or 'primitive' (box, cylinder, sphere)"
        )
    number = (int, float)
    up = _take(spec, "up", up, str, where)
    if up not in UP_AXES:
        raise SonarRasterError(f"{where}: 'up' must be one of {', '.join(UP_AXES)}, got {up!r}")
    units = _take(spec, "units", "m", str, where)
    if units not in UNITS:
        raise SonarRasterError(f"{where}: 'units' must be one of {', '.join(UNITS)}, got {units!r}")
    position = _vector(_take(spec, "position", [0.0, 0.0], list, where), (2, 3), "position", where)
    rotation = _rotation(
        _vector(
            _take(spec, "rotation_deg", [0.0, 0.0, 0.0], list, where), (3,), "rotation_deg", where
        )
    )
    rotation = rotation @ _rotation(np.array(UP_AXES[up]))
    scale = float(_take(spec, "scale", 1.0, number, where))
    sink = float(_take(spec, "sink", 0.0, number, where))
    reflectivity, law = _reflectivity(spec, None, where)
    name = _take(spec, "name", None, str, where)
    _no_leftovers(spec, where)
    if not (math.isfinite(scale) and scale > 0):
        raise SonarRasterError(f"{where}: 'scale' must be > 0")
    scale *= UNITS[units]
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
                law=law,
            )
        )
    return out


# -- trajectory --------------------------------------------------------------------------------
def _trajectory(
    table: dict, ground_z: float, base: Path, ov: Overrides, where: str, sonar: Sonar
) -> tuple[Trajectory, float]:
    number = (int, float)
    if "csv" in table:
        path = base / str(table.pop("csv"))
        _no_leftovers(table, f"{where} [trajectory]")
        if ov.track is not None:
            return _recorded(ov.track, Trajectory.from_csv(str(path)), ground_z)
        given = [
            name
            for name, value in (
                ("--heading", ov.heading_deg),
                ("--ping-spacing", ov.ping_spacing),
                ("--speed", ov.speed),
            )
            if value is not None
        ]
        if given:
            raise SonarRasterError(
                f"{where}: the track comes from {path.name}; {', '.join(given)} apply to "
                "straight tracks (start, heading_deg, spacing in [trajectory])"
            )
        traj = Trajectory.from_csv(str(path))
        below = traj.positions[:, 2] <= ground_z
        if below.all():
            raise SonarRasterError(
                f"{where}: every ping of {path.name} is at or below the seabed's level "
                f"(z {traj.positions[:, 2].max():g} m, seabed at {ground_z:g} m): z is up, "
                "the sonar's height; check its sign or the seabed's depth"
            )
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
    if ov.heading_deg is not None:
        heading = ov.heading_deg
    override = _spacing(ov, sonar)
    if override is not None:
        spacing = override
    if not (math.isfinite(altitude) and altitude > 0):
        raise SonarRasterError(f"altitude must be > 0 metres, got {altitude}")
    z = ground_z + altitude
    _check_track_size(pings)
    line = Trajectory.straight((start[0], start[1], z), heading, spacing, pings)
    if ov.track is not None:
        return _recorded(ov.track, line, ground_z)
    # Crab turns the vehicle (and its fans) off the course; pitch tilts the fans forward.
    attitude = np.radians([crab, roll, pitch])
    traj = Trajectory(line.positions, line.headings + attitude[0], attitude[1], attitude[2])
    return traj, altitude


def _recorded(track: RecordedTrack, own: Trajectory, ground_z: float) -> tuple[Trajectory, float]:
    """The recorded track, its middle ping over the middle of the scene's own track."""
    middle = own.positions[own.n_pings // 2, :2]
    return track.placed(middle, ground_z), float(np.median(track.altitude))


def _from_description(path: Path, ov: Overrides) -> SceneSetup:
    where = path.name
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8-sig"))  # a BOM from Windows editors
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise SonarRasterError(f"{where}: not valid TOML ({exc})") from None
    base = path.parent
    data = _sensor_preset(data, where)  # issue 16: [sonar] preset = "NAME" (effects/presets.py)
    sonar = _sonar(_table(data, "sonar", where), base, ov, where)
    notes: dict = {}
    relief = ov.micro_relief is not False
    sea = _seabed(_table(data, "seabed", where), base, where, sonar, notes, relief)
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
    traj, altitude = _trajectory(_table(data, "trajectory", where), ground, base, ov, where, sonar)
    pulse = _pulse(_table(data, "pulse", where), sonar, where)
    coherent = _coherent(_table(data, "coherent", where), where)
    effects = _effects(_table(data, "effects", where), base, where)
    return SceneSetup(scene, sonar, traj, str(path), altitude, pulse, coherent, effects, notes)


def _from_model(path: Path, ov: Overrides) -> SceneSetup:
    """A bare model on a sandy seabed, mid-swath to starboard of a track passing it.

    The seabed has sand's micro-relief over the swath (unless ``ov.micro_relief`` is False,
    or the swath is too large: then a plane).

    The model is turned and scaled by ``ov.placement``, its footprint centred at the placement's
    position (default: mid-swath to starboard of the track's middle ping); the automatic
    straight track (heading ``ov.heading_deg``, default 0) is about six model sizes long and
    passes it at half the maximum slant range. A recorded track (``ov.track``) passes it the
    same way at its middle ping.
    """
    sonar = _sonar({}, path.parent, ov, path.name)
    place = ov.placement or Placement()
    spec: dict[str, Any] = {"file": path.name, "position": [0.0, 0.0, 0.0], "units": place.units}
    spec["scale"] = place.scale
    if place.up is not None:
        spec["up"] = place.up
    parts = _object(spec, path.parent, None, 0)
    corners = np.concatenate([p.vertices for p in parts])
    low, high = corners.min(axis=0), corners.max(axis=0)
    extent = high - low
    size = float(extent.max())
    up = place.up or ("y" if model_suffix(path) in Y_UP_SUFFIXES else "z")
    _warn_size(path.name, size, place)
    track = ov.track
    if track is not None:
        heading = float(track.headings[len(track.headings) // 2])
        altitude = float(np.median(track.altitude))
    else:
        heading = math.radians(ov.heading_deg or 0.0)
        altitude = ov.altitude if ov.altitude is not None else 10.0
    if not (math.isfinite(altitude) and altitude > 0):
        raise SonarRasterError(f"altitude must be > 0 metres, got {altitude}")
    r_mid = 0.5 * sonar.max_range
    ground_range = math.sqrt(max(r_mid**2 - altitude**2, (0.25 * sonar.max_range) ** 2))
    along = np.array([math.sin(heading), math.cos(heading)])
    starboard = np.array([math.cos(heading), -math.sin(heading)])
    if place.position is not None:
        target = np.asarray(place.position[:2], dtype=np.float64)
        middle = target - ground_range * starboard
    else:
        middle = np.zeros(2)
        target = middle + ground_range * starboard
    base = place.position[2] if place.position is not None and len(place.position) > 2 else 0.0
    shift = np.array([*(target - 0.5 * (low[:2] + high[:2])), base - low[2]])
    objects = [replace(p, vertices=p.vertices + shift) for p in parts]
    if track is not None:
        traj = track.placed(middle, 0.0)
    else:
        traj = _auto_track(ov, sonar, middle, along, heading, altitude, size)
    _warn_inside(path.name, low + shift, high + shift, traj)
    xy = np.vstack([traj.positions[:, :2], target])
    reach = sonar.max_range + 10.0
    lo, hi = xy.min(axis=0) - reach, xy.max(axis=0) + reach
    seabed = make_seabed("flat", size=tuple(hi - lo), center=tuple(0.5 * (lo + hi)), depth=0.0)
    notes: dict[str, Any] = {}
    if ov.micro_relief is not False:  # sand's texture over what the swath sees
        seabed = _bare_relief(seabed, traj, sonar, altitude, notes)
    scene = build_scene([seabed.mesh(DEFAULT_SEABED_REFLECTIVITY, "seabed"), *objects])
    placed = {
        "model": path.name,
        "size_m": [float(v) for v in extent],
        "up": up,
        "units": place.units,
        "scale": place.scale,
        "position_m": [float(v) for v in (*target, base)],
        "track": {
            "source": track.source if track is not None else "automatic",
            "pings": traj.n_pings,
            "spacing_m": traj.typical_spacing,
            "heading_deg": math.degrees(heading) % 360.0,
            "altitude_m": altitude,
            "middle_m": [float(v) for v in middle],
            "passing_m": ground_range,
        },
    }
    return SceneSetup(scene, sonar, traj, str(path), altitude, notes={"placement": placed, **notes})


#: Most nodes of a bare model's micro-relief; a larger swath keeps the plane (noted).
BARE_RELIEF_MAX_NODES = 4_000_000


def _bare_relief(
    plane: Heightfield, traj: Trajectory, sonar: Sonar, altitude: float, notes: dict
) -> Heightfield:
    """Sand's micro-relief on the part of the seabed the swath sees, or the plane if too big.

    The patch covers each ping's swath (its ground range on both sides plus 2 m) and 3 m
    beyond the track's ends; outside it the fans see no seabed anyway.
    """
    ground = math.sqrt(max(sonar.max_range**2 - altitude**2, 0.0)) + 2.0
    h = traj.headings
    starboard = np.stack([np.cos(h), -np.sin(h)], axis=1)
    along = np.stack([np.sin(h), np.cos(h)], axis=1)
    xy = traj.positions[:, :2]
    ends = np.concatenate([xy[:1] - 3.0 * along[:1], xy[-1:] + 3.0 * along[-1:]])
    corners = np.concatenate([xy + ground * starboard, xy - ground * starboard, ends])
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    cell = MICRO_RESOLUTION_BINS * sonar.range_bin
    nodes = math.prod(math.ceil(float(d) / cell) + 1 for d in hi - lo)
    if nodes > BARE_RELIEF_MAX_NODES:  # noted, not warned: a huge swath is the user's choice
        notes["seabed_micro_relief"] = {
            "skipped": f"the swath needs {nodes} nodes at {cell:g} m (most "
            f"{BARE_RELIEF_MAX_NODES}); a plane instead (a scene file sets the relief's extent)"
        }
        log.info("seabed micro-relief skipped: %s nodes", nodes)
        return plane
    patch = make_seabed("flat", size=tuple(hi - lo), center=tuple(0.5 * (lo + hi)), depth=0.0)
    relief: dict[str, Any] = {
        "sediment": "sand",
        "resolution": cell,
        "outer_scale": MICRO_OUTER_SCALE,
        "seed": 0,
    }
    field = micro_relief(patch, **relief)
    notes["seabed_micro_relief"] = {
        **relief,
        "cell_m": [field.dx, field.dy],
        "extent_m": [float(v) for v in (*lo, *hi)],
    }
    return field


def _auto_track(
    ov: Overrides,
    sonar: Sonar,
    middle: np.ndarray,
    along: np.ndarray,
    heading: float,
    altitude: float,
    size: float,
) -> Trajectory:
    """The straight track past a bare model: about six model sizes (at least 20 m) long."""
    spacing = _spacing(ov, sonar)
    length = max(20.0, 6.0 * size)
    if spacing is None:
        pings = ov.pings if ov.pings is not None else 200
        spacing = length / max(pings - 1, 1)
    else:
        pings = ov.pings if ov.pings is not None else int(math.ceil(length / spacing)) + 1
    _check_track_size(pings)
    start = middle - 0.5 * spacing * (pings - 1) * along
    return Trajectory.straight(
        (start[0], start[1], altitude), math.degrees(heading), spacing, pings
    )


def _spacing(ov: Overrides, sonar: Sonar) -> float | None:
    """Ping spacing from --ping-spacing, or --speed times the ping period (2 R / c)."""
    if ov.speed is not None:
        return ov.speed * 2.0 * sonar.max_range / sonar.sound_speed
    return ov.ping_spacing


def _warn_inside(name: str, low: np.ndarray, high: np.ndarray, traj: Trajectory) -> None:
    """Warn when the track runs inside the model's bounding box (it images from within)."""
    inside = np.all((traj.positions >= low) & (traj.positions <= high), axis=1)
    if inside.any():
        altitude = float(np.median(traj.positions[inside, 2]))
        warnings.warn(
            f"the track runs inside {name}'s bounding box on {int(inside.sum())} of "
            f"{traj.n_pings} pings (the model is {high[2] - low[2]:.4g} m tall, the sonar "
            f"{altitude:.3g} m up): pass --units or --scale if it is too large, or a higher "
            "--altitude",
            InputWarning,
            stacklevel=3,
        )


def _warn_size(name: str, size: float, place: Placement) -> None:
    """Warn when a model is implausibly large or small for a seabed object, naming fixes."""
    small, large = PLAUSIBLE_SIZE_M
    read = f"read in {place.units}" + (f" with scale {place.scale:g}" if place.scale != 1 else "")
    if size > large:
        hints = []
        for unit in ("mm", "cm", "in"):
            factor = UNITS[unit] / UNITS[place.units]
            if factor < 1 and small <= size * factor <= large:
                hints.append(f"--units {unit} ({size * factor:.3g} m)")
        fix = " or ".join(hints[:2]) if hints else f"--scale {10.0 / size:.3g} (10 m)"
        warnings.warn(
            f"{name} is {size:.4g} m across ({read}), over {large:g} m: if the file is not in "
            f"{place.units}, pass {fix}; or --scale to size it",
            InputWarning,
            stacklevel=3,
        )
    elif size < small:
        warnings.warn(
            f"{name} is {size:.3g} m across ({read}), under {small * 100:g} cm: it will show as "
            f"a speck; if the file is in other units pass --units, or enlarge it with "
            f"--scale (--scale {1.0 / max(size, 1e-12):.3g} makes it 1 m)",
            InputWarning,
            stacklevel=3,
        )
