"""Draw one dataset sample's parameters from a config and build its scene, sonar and track.

Every random draw comes from ``numpy.random.default_rng([seed, index])``, in a fixed order, so
a sample is a function of (config, seed, index) alone. Geometry is built in a track frame (the
track runs along +y through the origin, x to starboard, seabed mean level z = 0), then the whole
scene and the track are turned to the drawn compass heading.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..effects.presets import preset
from ..errors import SonarRasterError
from ..scene import MeshPart, Scene, build_scene
from ..scenes.objects import build_primitive
from ..scenes.seabed import MICRO_RESOLUTION_BINS, Heightfield, make_seabed, micro_relief
from ..scenes.sediments import material_index, material_reflectivity, sediment
from ..sonar import BeamPattern, Sonar
from ..trajectory import Trajectory
from .config import REACH_PAST_ALTITUDE, DatasetConfig, ObjectSpec, allowed, rule

#: Metres of seabed beyond the swath and the track ends.
SEABED_MARGIN = 2.0
_PLACEMENT_TRIES = 20
_MERGE_GAP = 48  # pings
_MESH_CACHE: dict[tuple[str, float], list[MeshPart]] = {}


@dataclass(frozen=True)
class SampleScene:
    """A drawn sample, ready to render.

    Attributes
    ----------
    scene : Scene
        Seabed (object id 0) then the object instances (object id k = instance k, 1-based).
    seabed : Scene
        The seabed alone (for shadows).
    sonar : Sonar
    trajectory : Trajectory
    instances : list of dict
        Per instance, in id order: class, category id, drawn parameters, placement.
    params : dict
        Everything drawn (JSON-able): sonar, track, seabed, effects seed.
    object_pings : ndarray of int or None
        Sorted ping rows that objects can reach (with a margin); None without any.
    effects_seed : int
        Seed for the realism effects.
    """

    scene: Scene
    seabed: Scene
    sonar: Sonar
    trajectory: Trajectory
    instances: list[dict]
    params: dict
    object_pings: np.ndarray | None
    effects_seed: int


def _rotation(yaw: float, pitch: float, roll: float) -> np.ndarray:
    """Rotation about x (roll), then y (pitch), then z (yaw); radians."""
    cx, sx, cy, sy, cz, sz = (
        math.cos(roll),
        math.sin(roll),
        math.cos(pitch),
        math.sin(pitch),
        math.cos(yaw),
        math.sin(yaw),
    )
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def _user_mesh(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A user model merged into one part: vertices, faces, per-face reflectivity (cached)."""
    from ..meshio.load import load_model

    key = (str(path), path.stat().st_mtime if path.exists() else -1.0)
    if key not in _MESH_CACHE:
        _MESH_CACHE[key] = load_model(path)
    parts = _MESH_CACHE[key]
    verts, faces, refl, offset = [], [], [], 0
    for p in parts:
        f = np.asarray(p.faces, dtype=np.int64).reshape(-1, 3)
        verts.append(np.asarray(p.vertices, dtype=np.float64).reshape(-1, 3))
        faces.append(f + offset)
        refl.append(np.broadcast_to(np.asarray(p.reflectivity, dtype=np.float64), (len(f),)))
        offset += len(verts[-1])
    return np.concatenate(verts), np.concatenate(faces), np.concatenate(refl)


def draw_object_params(spec: ObjectSpec, rng: np.random.Generator) -> dict[str, Any]:
    """Draw an object entry's own parameters (a rock's seed too).

    Parameters
    ----------
    spec : ObjectSpec
    rng : numpy.random.Generator
    """
    params = {key: dist.draw(rng) for key, dist in spec.params}
    if spec.primitive == "rock" and "seed" not in params:
        params["seed"] = int(rng.integers(2**31))
    return params


def object_mesh_of(spec: ObjectSpec, params: dict, base: Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of an object entry with drawn ``params`` (a model file turned z-up).

    Parameters
    ----------
    spec : ObjectSpec
    params : dict
        From :func:`draw_object_params`.
    base : Path
        Folder model files are resolved against.
    """
    if spec.primitive is not None:
        return build_primitive(spec.primitive, params)
    v, f, _ = _user_mesh(base / str(spec.file))
    if spec.up == "y":
        v = v @ _rotation(0.0, 0.0, math.pi / 2).T
    return v, f


def _seabed(
    config: DatasetConfig,
    rng: np.random.Generator,
    heading_deg: float,
    extent: tuple,
    range_bin: float,
):
    weights = np.array([s.weight for s in config.seabeds], dtype=np.float64)
    spec = config.seabeds[int(rng.choice(len(weights), p=weights / weights.sum()))]
    material, law = None, 0
    if spec.material is None:
        reflectivity = float(spec.reflectivity.draw(rng))
    else:  # the sediment's own level, and its APL-UW law unless Lambert is asked for
        material = sediment(str(spec.material.draw(rng))).name
        reflectivity = material_reflectivity(material)
        law = 0 if spec.scattering == "lambert" else material_index(material)
    params = {key: dist.draw(rng) for key, dist in spec.params}
    seed = int(rng.integers(2**31))
    record = {"kind": spec.kind, "reflectivity": reflectivity, "seed": seed, **params}
    if material is not None:
        record.update(material=material, scattering=spec.scattering)
    x0, x1, y0, y1 = extent
    build = dict(params)
    if spec.kind == "ripples":  # drawn as a world compass direction; built in the track frame
        world = float(build.get("direction_deg", 0.0))
        build["direction_deg"] = world - heading_deg
        record["direction_deg"] = world
    field = make_seabed(
        spec.kind,
        size=(x1 - x0, y1 - y0),
        center=(0.5 * (x0 + x1), 0.5 * (y0 + y1)),
        depth=0.0,
        seed=seed,
        **build,
    )
    if spec.micro_relief is not None:  # the sediment's roughness at the image's scales
        drawn = spec.micro_relief.draw(rng)
        rough = material if drawn is True else str(drawn)  # true: the material's roughness
        relief_seed = int(rng.integers(2**31))
        cell = MICRO_RESOLUTION_BINS * range_bin
        field = micro_relief(field, str(rough), resolution=cell, seed=relief_seed)
        record["micro_relief"] = {"sediment": rough, "seed": relief_seed, "cell_m": cell}
    return field, reflectivity, law, record


def _place(
    config: DatasetConfig,
    rng: np.random.Generator,
    placed: list[np.ndarray],
    ground_max: float,
    length: float,
) -> tuple[float, float, str]:
    """Draw (x, y) in the track frame and the side, avoiding earlier objects when possible."""
    x = y = 0.0
    side = config.sides[0]
    for _ in range(_PLACEMENT_TRIES):
        along = float(config.placement["along_track"].draw(rng))
        ground = float(config.placement["ground_range"].draw(rng))
        side = config.sides[int(rng.integers(len(config.sides)))] if len(config.sides) > 1 else side
        sign = 1.0 if side == "starboard" else -1.0
        x, y = sign * ground * ground_max, (along - 0.5) * length
        if all(math.hypot(x - p[0], y - p[1]) >= config.min_separation for p in placed):
            break
    return x, y, side


def draw_sample(config: DatasetConfig, seed: int, index: int) -> SampleScene:
    """Draw sample ``index`` of the dataset ``(config, seed)`` and build its geometry.

    Parameters
    ----------
    config : DatasetConfig
    seed : int
        Global dataset seed, >= 0.
    index : int
        Sample index, >= 0.

    Returns
    -------
    SampleScene

    Raises
    ------
    SonarRasterError
        If the drawn values are inconsistent (e.g. a maximum range below the altitude) or a
        user mesh cannot be read.
    """
    rng = np.random.default_rng([int(seed), int(index)])
    sensor = None if config.sensor is None else str(config.sensor.draw(rng))
    s = {key: dist.draw(rng) for key, dist in config.sonar.items()}
    t = {key: dist.draw(rng) for key, dist in config.track.items()}
    altitude, spacing, heading = float(t["altitude"]), float(t["spacing"]), float(t["heading_deg"])
    beam = None
    if sensor is not None:  # the preset's sonar where the config leaves a key out
        sensor_preset = preset(sensor)
        own = sensor_preset.sonar(s.get("max_range"))
        if "beamwidth_deg" not in s:  # the preset's beam, its sidelobe floor included
            beam = own.beam
        s = {
            "frequency_hz": own.frequency_hz,
            "max_range": own.max_range,
            "tilt_deg": math.degrees(own.tilt),
            "beamwidth_deg": sensor_preset.vertical_beamwidth_deg / math.sqrt(2.0),
            "sound_speed": own.sound_speed,
            **s,
        }
    max_range = float(s["max_range"])
    for key, value in (("altitude", altitude), ("spacing", spacing)):
        if not allowed(key, value):
            raise SonarRasterError(f"drawn {key} {value:g} m must be {rule(key)}")
    if max_range <= REACH_PAST_ALTITUDE * altitude:
        raise SonarRasterError(
            f"drawn max_range {max_range:g} m does not reach past the altitude {altitude:g} m"
        )
    sonar = Sonar(
        frequency_hz=float(s["frequency_hz"]),
        max_range=max_range,
        range_bin=max_range / config.bins,
        beam=BeamPattern.gaussian(float(s["beamwidth_deg"])) if beam is None else beam,
        tilt=math.radians(float(s["tilt_deg"])),
        sides=config.sides,
        sound_speed=float(s["sound_speed"]),
    )
    length = (config.pings - 1) * spacing
    ground_max = math.sqrt(max_range**2 - altitude**2)
    m = SEABED_MARGIN
    x0 = -ground_max - m if "port" in config.sides else -m
    x1 = ground_max + m if "starboard" in config.sides else m
    extent = (x0, x1, -0.5 * length - m, 0.5 * length + m)
    field, seabed_r, law, seabed_record = _seabed(config, rng, heading, extent, sonar.range_bin)
    parts = [replace(field.mesh(reflectivity=seabed_r, name="seabed"), law=law)]
    instances: list[dict] = []
    centres: list[np.ndarray] = []
    for spec in config.objects:
        for _ in range(int(spec.count.draw(rng))):
            inst = _draw_instance(config, spec, rng, field, centres, ground_max, length)
            parts.append(inst.pop("_part"))
            instances.append(inst)
    effects_seed = int(rng.integers(2**31))
    rot = _heading_rotation(math.radians(heading))
    parts = [replace(p, vertices=p.vertices @ rot.T) for p in parts]
    scene = build_scene(parts)
    own = scene.object_id == 0  # the seabed alone: the same cleaned faces, no second check
    seabed_scene = Scene(
        scene.vertices,
        scene.faces[own],
        scene.reflectivity[own],
        scene.object_id[own],
        scene.names[:1],
        scene.ground_z,
        law=None if scene.law is None else scene.law[own],
        two_sided=scene.two_sided_faces()[own],
    )
    start = rot @ np.array([0.0, -0.5 * length, altitude])
    trajectory = Trajectory.straight(tuple(start), heading, spacing, config.pings)
    params = {
        "index": int(index),
        "seed": int(seed),
        "sonar": {
            **sonar.to_dict(),
            "beamwidth_deg": float(s["beamwidth_deg"]),
            **({} if sensor is None else {"preset": sensor}),
        },
        "track": {
            "altitude_m": altitude,
            "heading_deg": heading,
            "spacing_m": spacing,
            "pings": config.pings,
            "start_m": [float(v) for v in start],
            "length_m": length,
        },
        "seabed": {**seabed_record, "extent_track_m": list(extent)},
        "effects_seed": effects_seed,
    }
    return SampleScene(
        scene=scene,
        seabed=seabed_scene,
        sonar=sonar,
        trajectory=trajectory,
        instances=instances,
        params=params,
        object_pings=_object_pings(instances, config.pings, spacing, length),
        effects_seed=effects_seed,
    )


def _draw_instance(
    config: DatasetConfig,
    spec: ObjectSpec,
    rng: np.random.Generator,
    field: Heightfield,
    centres: list[np.ndarray],
    ground_max: float,
    length: float,
) -> dict[str, Any]:
    params = draw_object_params(spec, rng)
    reflectivity = float(spec.reflectivity.draw(rng))
    scale = float(spec.scale.draw(rng))
    burial = float(spec.burial_fraction.draw(rng))
    yaw, pitch, roll = (float(d.draw(rng)) for d in (spec.yaw_deg, spec.pitch_deg, spec.roll_deg))
    x, y, side = _place(config, rng, centres, ground_max, length)
    drawn = {"scale": scale, "burial_fraction": burial, "reflectivity": reflectivity}
    for key, value in drawn.items():
        if not allowed(key, value):
            raise SonarRasterError(f"drawn {key} {value:g} of '{spec.label}' must be {rule(key)}")
    v, f = object_mesh_of(spec, params, Path(config.source).parent)
    rot = _rotation(math.radians(yaw), math.radians(pitch), math.radians(roll))
    v = (v @ rot.T) * scale
    height = float(np.ptp(v[:, 2]))
    z = float(field.height_at(x, y)) - float(v[:, 2].min()) - burial * height
    v = v + np.array([x, y, z])
    centres.append(np.array([x, y]))
    k = len(centres)
    refl: Any = reflectivity
    if spec.file is not None:  # per-face material reflectivity scaled to the drawn mean
        _, _, per_face = _user_mesh(Path(config.source).parent / str(spec.file))
        mean = float(per_face.mean()) if per_face.size else 0.0
        refl = per_face * (reflectivity / mean) if mean > 0 else reflectivity
    part = MeshPart(v, f, refl, f"{spec.label}#{k}")
    return {
        "instance": k,
        "class": spec.label,
        "category_id": config.categories.index(spec.label) + 1,
        "source": spec.primitive or spec.file,
        "params": params,
        "reflectivity": reflectivity,
        "scale": scale,
        "burial_fraction": burial,
        "yaw_deg": yaw,
        "pitch_deg": pitch,
        "roll_deg": roll,
        "side": side,
        "position_track_m": [x, y, z],
        "height_m": height,
        "bounds_track_m": [v.min(axis=0).tolist(), v.max(axis=0).tolist()],
        "_part": part,
    }


def _heading_rotation(heading: float) -> np.ndarray:
    """Track frame (x starboard, y along) to world for a compass heading (radians)."""
    c, s = math.cos(heading), math.sin(heading)
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])


def _object_pings(
    instances: list[dict], pings: int, spacing: float, length: float
) -> np.ndarray | None:
    """Sorted ping rows that objects' along-track extents reach, each widened by 2 pings."""
    rows = []
    for inst in instances:
        y0, y1 = inst["bounds_track_m"][0][1], inst["bounds_track_m"][1][1]
        first = max(0, int(math.floor((y0 + 0.5 * length) / spacing)) - 2)
        stop = min(pings, int(math.ceil((y1 + 0.5 * length) / spacing)) + 3)
        rows.append(np.arange(first, stop))
    out = np.unique(np.concatenate(rows)) if rows else np.zeros(0, dtype=np.int64)
    if out.size == 0:
        return None
    # Fill gaps shorter than _MERGE_GAP pings: each gap splits the track into another draw,
    # and a draw costs more than a few extra pings.
    gaps = np.flatnonzero(np.diff(out) > 1)
    fill = [np.arange(out[g] + 1, out[g + 1]) for g in gaps if out[g + 1] - out[g] <= _MERGE_GAP]
    return np.unique(np.concatenate([out, *fill])) if fill else out
