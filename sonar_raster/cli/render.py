"""``sonar-raster render``: a scene (description, model file or bundled name) to images."""

from __future__ import annotations

import argparse
import math
import warnings
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

from .._checks import cli_positive, cli_seed
from ..errors import DeprecatedOptionWarning, SonarRasterError
from ..meshio.formats import MODEL_SUFFIXES
from .effects_options import (
    add_effect_options,
    apply_sensor_option,
    display_from_args,
    effects_from_args,
    ideal_requested,
)
from .track import add_xtf_frequency, parse_xtf_frequency

_SIDE_CHOICES = {"port": ("port",), "starboard": ("starboard",), "both": ("port", "starboard")}
_OUTPUT_SUFFIXES = (".png", ".exr", ".xtf")

#: Cells (pings × bins × sides) above which a GL render streams in blocks by default.
_STREAM_CELLS = 1 << 26


def add_parser(sub: Any) -> None:
    """Add the ``render`` subcommand to an argparse subparsers object."""
    render = sub.add_parser(
        "render",
        help="render a scene to PNG and/or EXR",
        description="Render a scene description (.toml), a bare model file "
        f"({' '.join(MODEL_SUFFIXES)}) or a bundled scene by name "
        "(see 'sonar-raster scenes') to sonar images.",
    )
    render.add_argument("scene", help="scene file, model file, or bundled scene name")
    render.add_argument(
        "-o",
        "--output",
        action="append",
        required=True,
        metavar="OUT",
        help="output .png (display image), .exr (linear float) or .xtf (sonar records); repeatable",
    )
    render.add_argument(
        "--range",
        dest="max_range",
        type=cli_positive(float),
        metavar="METRES",
        help="maximum slant range",
    )
    render.add_argument(
        "--range-bin", type=cli_positive(float), metavar="METRES", help="slant-range bin size"
    )
    render.add_argument(
        "--altitude",
        type=cli_positive(float),
        metavar="METRES",
        help="sonar altitude above the seabed",
    )
    render.add_argument("--pings", type=cli_positive(int), metavar="N", help="number of pings")
    render.add_argument("--side", choices=sorted(_SIDE_CHOICES), help="sides to image")
    render.add_argument(
        "--renderer",
        choices=("gl", "reference"),
        default="gl",
        help="gl: OpenGL rasteriser (default); reference: slow numpy oracle",
    )
    render.add_argument(
        "--model",
        choices=("raster", "coherent"),
        default="raster",
        help="raster: Lambertian intensity (Eq. 11) by --renderer (default); coherent: point "
        "scatterers, chirp and matched filter (Eq. 10), with speckle; slow",
    )
    render.add_argument(
        "--scatterer-spacing",
        type=cli_positive(float),
        default=None,
        metavar="WAVELENGTHS",
        help="coherent model: distance between point scatterers in wavelengths (default 0.25; "
        "run time grows as 1/spacing^2)",
    )
    render.add_argument(
        "--spacing",
        dest="old_spacing",
        type=cli_positive(float),
        default=None,
        help=argparse.SUPPRESS,  # deprecated name of --scatterer-spacing
    )
    render.add_argument(
        "--seed",
        type=cli_seed,
        default=0,
        help="seed of the coherent model's scatterer jitter and of the speckle and noise effects "
        "(default 0: the same command gives the same image)",
    )
    render.add_argument(
        "--gl",
        choices=("egl", "osmesa"),
        default=None,
        help="headless GL backend (default: $SONAR_RASTER_GL, else EGL then OSMesa)",
    )
    render.add_argument(
        "--oversample",
        type=cli_positive(float),
        default=None,
        help="look-angle samples per range bin (GL renderer, default 2)",
    )
    render.add_argument(
        "--along-samples",
        type=cli_positive(int),
        default=None,
        metavar="N",
        help="rays per ping along track (GL renderer, default 2)",
    )
    render.add_argument(
        "--chunk-pings",
        type=cli_positive(int),
        default=None,
        metavar="N",
        help="render the track in blocks of N pings streamed to disk, so memory does not grow "
        "with the track (GL renderer; default: whole track at once, or blocks of 512 when it "
        "would exceed 64 M cells)",
    )
    render.add_argument("--bits", type=int, choices=(8, 16), default=8, help="PNG bit depth")
    render.add_argument(
        "--dynamic-range",
        type=cli_positive(float),
        default=None,
        metavar="DB",
        help="PNG display range in dB below the reference level (default: the image's span, "
        "6 to 60 dB)",
    )
    render.add_argument(
        "--force",
        action="store_true",
        help="render even when the job's estimate exceeds this machine's memory, the free "
        "disk of an output's folder, or an hour",
    )
    render.add_argument(
        "--no-micro-relief",
        action="store_true",
        help="leave out the seabed's micro_relief (its sediment's roughness; --ideal does too)",
    )
    render.add_argument("-q", "--quiet", action="store_true", help="no progress or summary")
    _add_sonar_options(render)
    _add_placement_options(render)
    add_effect_options(render)


def _finite(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be finite, got {text}")
    return value


_finite.__name__ = "number"


def _tilt(text: str) -> float:
    value = _finite(text)
    if not -90.0 <= value <= 90.0:
        raise argparse.ArgumentTypeError(f"must be between -90 and 90 degrees, got {text}")
    return value


_tilt.__name__ = "tilt"


def _position(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) not in (2, 3) or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"use X,Y or X,Y,Z in metres, e.g. 20,0 (got {text!r})")
    return values


_position.__name__ = "position"


def _add_sonar_options(parser: argparse.ArgumentParser) -> None:
    """Sonar and track options, named as sonar users name them (override the scene's)."""
    group = parser.add_argument_group(
        "sonar and track (override the scene's [sonar] and [trajectory])"
    )
    add = group.add_argument
    add(
        "--frequency",
        type=cli_positive(float),
        metavar="KHZ",
        help="centre frequency in kHz (default 400): sets the wavelength of the coherent "
        "model, the absorption of --absorption and a sinc beam's width, and is written to "
        "the outputs; the raster model's intensities do not depend on it",
    )
    add(
        "--tilt",
        type=_tilt,
        metavar="DEG",
        help="depression of the beam axis below the horizontal (default 20); it shapes the "
        "image through the vertical beam (give --beamwidth, or a scene with a beam)",
    )
    add(
        "--beamwidth",
        type=cli_positive(float),
        metavar="DEG",
        help="vertical beam: a Gaussian two-way beam of this full width at half power, about "
        "the --tilt axis (default: the scene's beam; a bare model has a uniform beam)",
    )
    add(
        "--sound-speed",
        type=cli_positive(float),
        metavar="M/S",
        help="speed of sound (default 1500): sets the wavelength, the ping period for "
        "--speed, and the sample timing written to .xtf",
    )
    add(
        "--heading",
        type=_finite,
        metavar="DEG",
        help="compass heading of the straight track (0 = north, +y; 90 = east); a bare model "
        "stays at --position and the track passes it on this heading",
    )
    add(
        "--ping-spacing",
        type=cli_positive(float),
        metavar="METRES",
        help="distance between pings along the track (scene default: its [trajectory] "
        "spacing; a bare model: the automatic track's length over --pings)",
    )
    add(
        "--speed",
        type=cli_positive(float),
        metavar="M/S",
        help="vehicle speed (1 knot = 0.514 m/s): pings are the distance run in one ping "
        "period, 2 x range / sound speed, apart",
    )
    add(
        "--track",
        metavar="FILE.xtf",
        help="reuse a recording's track: its positions, headings, roll, pitch and altitude "
        "(the file's, else its bottom track), moved so its middle ping lies over the middle "
        "of the scene's own track (a bare model: passed at mid-swath to starboard there)",
    )
    add_xtf_frequency(group, " of --track's file (its bottom track, where it has no altitude)")


def _add_placement_options(parser: argparse.ArgumentParser) -> None:
    """Bare model placement: axis, units, scale, position."""
    from ..scenes.description import UNITS, UP_AXES

    group = parser.add_argument_group(
        "bare model files (a scene .toml sets these per [[objects]] entry)"
    )
    add = group.add_argument
    add(
        "--up",
        choices=tuple(UP_AXES),
        help="the file's axis that points up (default: y for glTF and VRML, as their "
        "specifications say; z for OBJ, PLY, STL, OFF); robotics VRML (choreonoid, OpenHRP) "
        "is often z-up",
    )
    add(
        "--units",
        choices=tuple(UNITS),
        default="m",
        help="length unit of the file's coordinates (default m); CAD exports are often mm",
    )
    add("--scale", type=cli_positive(float), default=1.0, help="extra scale factor (default 1)")
    add(
        "--position",
        type=_position,
        metavar="X,Y[,Z]",
        help="where the model's footprint centre goes, metres east and north; Z lifts its "
        "lowest point above the seabed (default 0: resting on it; < 0 buries it). Default: "
        "mid-swath to starboard of the middle of the track",
    )


def load_setup(args: argparse.Namespace) -> Any:
    """The scene of ``render``'s arguments, with the sonar, track and placement options.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed ``render`` options.
    """
    from ..scenes.description import Overrides, Placement, load_scene

    if args.old_spacing is not None:
        warnings.warn(
            "--spacing is deprecated (it reads like ping spacing); use --scatterer-spacing",
            DeprecatedOptionWarning,
            stacklevel=2,
        )
        if args.scatterer_spacing is None:
            args.scatterer_spacing = args.old_spacing
    overrides = Overrides(
        max_range=args.max_range,
        range_bin=args.range_bin,
        altitude=args.altitude,
        pings=args.pings,
        sides=_SIDE_CHOICES[args.side] if args.side else None,
        frequency_hz=None if args.frequency is None else 1e3 * args.frequency,
        tilt_deg=args.tilt,
        beamwidth_deg=args.beamwidth,
        sound_speed=args.sound_speed,
        heading_deg=args.heading,
        ping_spacing=args.ping_spacing,
        speed=args.speed,
        track=_recorded_track(args.track, args.xtf_frequency),
        placement=Placement(args.up, args.units, args.scale, args.position),
        micro_relief=False if args.no_micro_relief or ideal_requested(args) else None,
    )
    return load_scene(args.scene, overrides)


def _recorded_track(path: str | None, xtf_frequency: str | None) -> Any:
    """A recording's track for ``--track``: altitude from the file, else its bottom track."""
    import numpy as np

    from ..io.xtf import read_xtf_track
    from ..scenes.description import RecordedTrack

    if path is None:
        if xtf_frequency is not None:
            raise SonarRasterError(
                "--xtf-frequency chooses the channels of --track's file; give --track"
            )
        return None
    frequency = parse_xtf_frequency(xtf_frequency)
    if Path(path).suffix.lower() != ".xtf":
        raise SonarRasterError(f"--track {path}: give a recording (.xtf)")
    traj, altitude, image = read_xtf_track(path, frequency=frequency)
    known = np.isfinite(altitude) & (altitude > 0)
    if not known.all():
        from ..inversion.bottom import track_bottom

        bottom = track_bottom(image.sides, image.sonar.range_bin)
        tracked = np.where(bottom.valid, bottom.altitude, np.nan)
        altitude = np.where(known, altitude, tracked)
        known = np.isfinite(altitude) & (altitude > 0)
    if not known.any():
        raise SonarRasterError(
            f"--track {path}: no ping has an altitude, in the file or from its bottom track"
        )
    rows = np.arange(len(altitude))
    altitude = np.interp(rows, rows[known], altitude[known])
    return RecordedTrack(
        traj.positions[:, :2], altitude, traj.headings, traj.roll, traj.pitch, source=path
    )


def placement_lines(setup: Any) -> list[str]:
    """One line saying what was placed where, for a bare model (none for a description).

    Parameters
    ----------
    setup : SceneSetup
        A loaded scene; bare models carry ``notes["placement"]``.
    """
    placed = setup.notes.get("placement")
    if not placed:
        return []
    size = " x ".join(f"{v:.3g}" for v in placed["size_m"])
    x, y, z = placed["position_m"]
    track = placed["track"]
    how = f"up {placed['up']}, units {placed['units']}" + (
        f", scale {placed['scale']:g}" if placed["scale"] != 1 else ""
    )
    base = "on the seabed" if z == 0 else f"base {z:g} m above the seabed"
    return [
        f"placed {placed['model']}: {size} m ({how}) at x {x:.4g} m, y {y:.4g} m, {base}; "
        f"track ({track['source']}): {track['pings']} pings {track['spacing_m']:.3g} m apart, "
        f"heading {track['heading_deg']:.4g} deg, altitude {track['altitude_m']:.3g} m, "
        f"passing it {track['passing_m']:.3g} m to starboard"
    ]


def run(args: argparse.Namespace) -> int:
    """Run ``sonar-raster render``: one sensor, or several over one track (``--sensor A,B``).

    Several presets render one image each; a PNG or EXR output is written once per preset, its
    name before the suffix (``out.png`` → ``out.klein-3900-445.png``), and their channels share
    the XTF. The first preset's effects take ``--seed``, the others seeds spawned from it, so
    the first image equals a render of that preset alone. Every check runs before any render.
    """
    import copy

    sensors = _sensor_list(args)
    several = len(sensors) > 1
    if several:
        _check_several(args)
    outputs = _check_outputs(args.output)
    runs: list[tuple] = []
    for name, seed in zip(sensors, _seeds(args.seed, len(sensors)), strict=True):
        one = copy.copy(args)
        one.sensor, one.seed = name, seed
        _check_long_track(one, outputs)  # a long --pings is sized before its track is made
        setup = apply_sensor_option(one, load_setup(one))  # issue 16: --sensor sets the sonar
        if not args.quiet and not runs:
            for line in placement_lines(setup):
                print(line)
        _check_in_range(setup)
        effects = effects_from_args(one, setup.effects)  # bad options fail before the render
        runs.append((name if several else None, one, setup, effects))
    streamed = any(_streamed(one, setup) for _, one, setup, _ in runs)  # one XTF: all or none
    for _, one, setup, _ in runs:
        _check_size(one, setup, streamed, outputs)
    if streamed:
        return _render_survey(args, runs, outputs)
    renders = []
    for name, one, setup, effects in runs:
        image = _rendered(one, setup, effects)
        renders.append((name, one, setup, image))
        if not args.quiet:
            pings, bins = image.shape
            what = setup.source if name is None else f"{setup.source} as {name}"
            print(
                f"rendered {what}: {setup.scene.n_triangles} triangles, {pings} pings x "
                f"{bins} bins per side ({', '.join(image.sides)})"
            )
    written = _write(args, renders, outputs)
    if not args.quiet:
        for path in dict.fromkeys(written):
            print(f"wrote {path}")
    return 0


def _rendered(args: argparse.Namespace, setup: Any, effects: Any) -> Any:
    """The scene's image with its track's metadata, and the effects unless there are none."""
    import numpy as np

    image = _render_image(args, setup)
    image.metadata.update(_track_metadata(setup))
    image.metadata.update(setup.notes)
    echoes = any(np.any(side) for side in image.sides.values())  # else render() said so
    if effects is not None:  # no effects: the renderer's image is written as is
        from ..effects.chain import apply_effects

        image = apply_effects(image, effects, seed=args.seed, trajectory=setup.trajectory)
    if echoes:
        _warn_blank(image, effects)
    return image


def _sensor_list(args: argparse.Namespace) -> list[str | None]:
    """``--sensor``'s names: one (or None), or several comma-separated (a dual-frequency set)."""
    text = getattr(args, "sensor", None)
    if text is None or "," not in text:
        return [text]
    names = [name.strip() for name in text.split(",")]
    if "" in names or len(set(names)) < len(names) or "ideal" in names:
        raise SonarRasterError(
            f"--sensor {text!r}: give different presets once each, comma-separated, e.g. "
            "klein-3900-445,klein-3900-900"
        )
    return names


def _check_several(args: argparse.Namespace) -> None:
    """Options that one preset of several cannot share: each has its own."""
    for option in ("frequency", "tilt", "beamwidth"):
        if getattr(args, option, None) is not None:
            raise SonarRasterError(
                f"--{option} with several --sensor presets: each has its own; render them one "
                "at a time to change it"
            )
    if getattr(args, "ideal", False):
        raise SonarRasterError("--ideal takes one --sensor preset at a time")


def _seeds(seed: int | None, count: int) -> list[int | None]:
    """``--seed`` for the first preset, seeds spawned from it for the others (None: none)."""
    if seed is None or count == 1:
        return [seed] * count
    import numpy as np

    children = np.random.SeedSequence(seed).spawn(count)
    return [seed, *(int(c.generate_state(1)[0]) for c in children[1:])]


def _warn_blank(image: Any, effects: Any) -> None:
    """Warn when every pixel of the image is zero (it is still written: it may be meant)."""
    import numpy as np

    from ..errors import InputWarning

    if any(np.any(side) for side in image.sides.values()):
        return
    why = (
        "the effects took it all (a very strong absorption, a nadir gap near 90 degrees, "
        "a K shape near 0?)"
        if effects is not None
        else "nothing in the swath returned an echo"
    )
    warnings.warn(f"the image is zero everywhere: {why}", InputWarning, stacklevel=2)


def _check_outputs(outputs: list[str]) -> list[Path]:
    """Check every output (and its JSON sidecar) can be written, before any work starts."""
    from ..io.commit import check_writable

    paths = [Path(o) for o in outputs]
    for p in paths:
        if p.suffix.lower() not in _OUTPUT_SUFFIXES:
            raise SonarRasterError(f"output {p}: unknown extension; use .png, .exr or .xtf")
    seen: dict[Path, Path] = {}
    for p in paths:
        same = seen.setdefault(p.resolve(), p)
        if same is not p:
            also = "" if str(same) == str(p) else f" (also as {same})"
            raise SonarRasterError(f"output {p} is given twice{also}; give it once")
    for p in paths:
        check_writable(p)
        if p.suffix.lower() != ".xtf":
            check_writable(p.with_suffix(".json"))
    return paths


def _check_in_range(setup: Any) -> None:
    """Refuse a track from which nothing in the scene is within the maximum range (black image)."""
    import numpy as np

    vertices = setup.scene.vertices
    if len(vertices) == 0:
        return
    positions = setup.trajectory.positions
    nearest = np.clip(positions, vertices.min(axis=0), vertices.max(axis=0))
    gap = float(np.sqrt(((nearest - positions) ** 2).sum(axis=1)).min())
    max_range = setup.sonar.max_range
    if gap <= max_range:
        return
    if setup.altitude >= max_range:
        raise SonarRasterError(
            f"altitude {setup.altitude:g} m is above the maximum range {max_range:g} m: the "
            "seabed is out of range and the image would be black; lower --altitude or raise "
            "--range"
        )
    raise SonarRasterError(
        f"nothing in the scene comes within the maximum range {max_range:g} m of the track "
        f"(nearest {gap:.4g} m): the image would be black; raise --range or move the track"
    )


#: Peak bytes per image cell (ping x bin x side): the GL accumulator (u64) and its read-back,
#: the float32 image, its display image and the float64 display mapping.
_CELL_BYTES = 40
#: Bytes per texel of the GL targets: RGBA float32 colour, depth, labels.
_TEXEL_BYTES = 24
#: Bytes per cell of the tile index over the scene's plane (offsets and their search keys).
_TILE_BYTES = 16


#: Seconds per ray of the GL raster (pass 1 and 2 together): ``tools/bench_costs.py`` fits
#: 2.7e-8 on the 2-core CI machine shared with three other engineers; 1.5x that, upper-end.
_RAY_SECONDS = 4e-8
#: Seconds per image cell (ping x bin x side) besides the rays: with sensor effects (measured
#: 2.5e-7) and without (1e-8 fitted; encoding included), with the same margin or more.
_CELL_SECONDS = (4e-7, 5e-8)
#: Seconds per scene triangle: upload, tiling and shader set-up (3.0 s for 2 M triangles,
#: docs/performance.md).
_TRIANGLE_SECONDS = 1.5e-6


#: A ``--pings`` above this is sized from a two-ping load of the scene before the track (about
#: 100 bytes a ping) is made: 10^8 pings take 18 s and 10 GB just to make.
_PRECHECK_PINGS = 1_000_000


def _check_long_track(args: argparse.Namespace, outputs: list[Path]) -> None:
    """Size a long ``--pings`` job from a two-ping load of the scene; refuse it before loading."""
    if not args.pings or args.pings <= _PRECHECK_PINGS:
        return
    from .._budget import check_memory
    from ..scenes.description import TRACK_BYTES_PER_PING

    check_memory(  # the poses alone first, as loading the scene would
        args.pings * TRACK_BYTES_PER_PING,
        f"a track of {args.pings} pings",
        "lower 'pings' in [trajectory] or --pings",
    )
    probe = argparse.Namespace(**{**vars(args), "pings": 2, "quiet": True})
    setup = apply_sensor_option(probe, load_setup(probe))
    cells = args.pings * setup.sonar.n_bins * len(setup.sonar.sides)
    raster = _model(args) == "raster"
    streamed = raster and (args.chunk_pings is not None or cells > _STREAM_CELLS)
    _check_size(args, setup, streamed, outputs, pings=args.pings, announce_it=False)


def _check_size(
    args: argparse.Namespace,
    setup: Any,
    streamed: bool,
    outputs: list[Path] | None = None,
    *,
    pings: int | None = None,
    announce_it: bool = True,
) -> None:
    """Estimate the render's peak memory, time and output size; refuse it before allocating.

    Refused when over the machine's memory, the free disk of an output's folder, or an hour
    (``--force`` skips the three); the estimate is printed when it is long.
    """
    pings = pings or setup.trajectory.n_pings
    _check_memory(args, setup, streamed, pings)
    if _model(args) != "raster":  # the reference and coherent models size their own jobs
        return
    from .._budget import check_disk
    from .._progress import ANNOUNCE_S, announce, check_job

    estimate = raster_estimate(args, setup, streamed, outputs or [], pings)
    check_disk(
        _output_sizes(args, setup, streamed, outputs or [], pings),
        estimate.what,
        "lower --pings or --range, or raise --range-bin",
        force=args.force,
    )
    check_job(estimate, "lower --pings, --oversample or --along-samples", force=args.force)
    if announce_it and not args.quiet and estimate.seconds >= ANNOUNCE_S:
        announce(estimate)


def raster_estimate(
    args: argparse.Namespace,
    setup: Any,
    streamed: bool,
    outputs: list[Path],
    pings: int | None = None,
) -> Any:
    """The GL raster render's size (rays, cells), time and output bytes, from its settings.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed ``render`` options (``--oversample``, ``--along-samples``, effects).
    setup : SceneSetup
        The loaded scene, sonar and track.
    streamed : bool
        The render goes block by block (no sensor effects).
    outputs : list of Path
        The files to write.
    pings : int, optional
        Pings of the track (default: the setup's).

    Returns
    -------
    sonar_raster._progress.Estimate
    """
    from .._progress import Estimate

    sonar, pings = setup.sonar, pings or setup.trajectory.n_pings
    sides, bins = len(sonar.sides), sonar.n_bins
    settings = _settings(args)
    rays = float(pings) * settings.along_samples * math.ceil(settings.oversample * bins * 1.2)
    rays *= sides
    cells = float(pings) * bins * sides
    effects = effects_from_args(args, setup.effects) is not None
    triangles = float(setup.scene.n_triangles)
    seconds = (
        _RAY_SECONDS * rays
        + _CELL_SECONDS[0 if effects else 1] * cells
        + _TRIANGLE_SECONDS * triangles
    )
    disk = sum(size for _, size in _output_sizes(args, setup, streamed, outputs, pings))
    return Estimate(
        f"rendering {pings} pings x {bins} bins x {sides} sides",
        {"rays": rays, "cells": cells, "triangles": triangles},
        seconds=seconds,
        disk=disk,
    )


def _output_sizes(
    args: argparse.Namespace,
    setup: Any,
    streamed: bool,
    outputs: list[Path],
    pings: int | None = None,
) -> list[tuple[Path, float]]:
    """Upper-end bytes of each output: uncompressed pixels plus headers."""
    sonar, pings = setup.sonar, pings or setup.trajectory.n_pings
    sides, bins = len(sonar.sides), sonar.n_bins
    cells = float(pings) * bins * sides
    exr = 4.0 * cells + 65536.0
    sizes: list[tuple[Path, float]] = []
    for path in outputs:
        kind = path.suffix.lower()
        if kind == ".xtf":
            sizes.append((path, pings * (256.0 + sides * (64.0 + 4.0 * bins))))
            continue
        sizes.append((path.with_suffix(".json"), 65536.0 + 64.0 * pings))
        if kind == ".exr":
            sizes.append((path, exr))
            continue
        rows = 1.0
        if getattr(args, "square_pixels", False):
            rows = max(1.0, setup.trajectory.typical_spacing / sonar.range_bin)
        sizes.append((path, cells * rows * (args.bits // 8) * 3.0 + 65536.0))  # RGB at most
        if streamed and not any(o.suffix.lower() == ".exr" for o in outputs):
            sizes.append((path, exr))  # the streamed PNG is made from a temporary EXR
    return sizes


def _check_memory(args: argparse.Namespace, setup: Any, streamed: bool, pings: int) -> None:
    """Estimate the render's peak memory from its settings; refuse it before allocating."""
    from .._budget import check_memory

    sonar = setup.sonar
    sides, bins = len(sonar.sides), sonar.n_bins
    model = _model(args)
    if model != "raster":
        per_cell = _CELL_BYTES + 8 * sides  # the model's float64 accumulator
        check_memory(
            pings * bins * sides * per_cell,
            f"the {model} model's image of {pings} pings x {bins} bins x {sides} sides",
            "lower --pings or --range, or raise --range-bin",
            force=args.force,
        )
        return
    from ..rendering.gl.raster import MAX_TEXELS, MAX_TEXTURE
    from ..rendering.survey import STAT_ROWS

    settings = _settings(args)
    columns = min(MAX_TEXTURE, math.ceil(settings.oversample * bins * 1.2) + 1)
    texels = min(MAX_TEXELS, columns * min(pings, MAX_TEXTURE) * settings.along_samples)
    targets = texels * _TEXEL_BYTES
    if streamed:
        block = min(pings, args.chunk_pings or 512)
        stats = min(pings, STAT_ROWS) * bins * sides * 24
        check_memory(
            block * bins * sides * _CELL_BYTES + stats + targets,
            f"rendering blocks of {block} pings x {bins} bins x {sides} sides",
            "lower --chunk-pings or --range, or raise --range-bin",
            force=args.force,
        )
    else:
        check_memory(
            pings * bins * sides * _CELL_BYTES + targets,
            f"rendering {pings} pings x {bins} bins x {sides} sides",
            "lower --pings, or use --chunk-pings to stream the track in blocks",
            force=args.force,
        )
    vertices = setup.scene.vertices
    if len(vertices):
        tile = 0.25 * (sonar.max_range + 8.0 * sonar.range_bin)
        span = vertices[:, :2].max(axis=0) - vertices[:, :2].min(axis=0)
        nx, ny = (float(s) // tile + 1 for s in span)
        check_memory(
            nx * ny * _TILE_BYTES,
            f"the tile index of a scene {span[0]:.4g} m x {span[1]:.4g} m wide",
            "check the objects' positions (one far from the rest?) or raise --range",
            force=args.force,
        )


def _model(args: argparse.Namespace) -> str:
    """The forward model of ``rendering.entry.render`` that --model and --renderer select."""
    if args.model == "coherent":
        return "coherent"
    return "reference" if args.renderer == "reference" else "raster"


def _settings(args: argparse.Namespace) -> Any:
    from ..rendering.gl.raster import RasterSettings

    return RasterSettings(
        oversample=args.oversample or RasterSettings.oversample,
        along_samples=args.along_samples or RasterSettings.along_samples,
    )


def _render_image(args: argparse.Namespace, setup: Any) -> Any:
    from ..rendering.entry import render

    model = _model(args)
    options = dict(setup.coherent)
    if args.scatterer_spacing is not None:
        options["spacing_wavelengths"] = args.scatterer_spacing
    if args.seed is not None:
        options["seed"] = args.seed
    return render(
        setup.scene,
        setup.sonar,
        setup.trajectory,
        model=model,
        settings=_settings(args) if model == "raster" else None,
        backend=args.gl,
        pulse=setup.pulse,
        coherent=options,
        progress=not args.quiet,
        force=args.force,
    )


def _write(args: argparse.Namespace, renders: list[tuple], outputs: list[Path]) -> list[Path]:
    """Write every output in one all-or-nothing commit: all files replaced, or none.

    ``renders`` are ``(preset, args, setup, image)``: one with preset None, or several presets
    (:func:`run`), whose images share an XTF and get a PNG or EXR each, named
    ``out.PRESET.png``.
    """
    from ..io.commit import commit
    from ..io.images import image_jobs

    jobs: dict[Path, Callable[[Path], None]] = {}  # a sidecar named twice: the last one wins
    for path in outputs:
        if path.suffix.lower() == ".xtf":
            images = [image for *_, image in renders]
            jobs[path] = partial(_write_xtf, image=images, setup=renders[0][2])
            continue
        for name, one, setup, image in renders:
            named = path if name is None else _named([path], name)[0]
            display = display_from_args(one, setup)  # issue 16: level, palette, geometry
            for final, writer in image_jobs(
                image, named, bit_depth=args.bits, dynamic_range_db=args.dynamic_range,
                display=display,
            ):  # fmt: skip
                jobs[final] = writer
    return commit(list(jobs.items()))


def _write_xtf(tmp: Path, image: Any, setup: Any) -> None:
    from ..io.xtf import write_xtf

    traj = setup.trajectory
    write_xtf(tmp, image, traj, altitude=traj.positions[:, 2] - setup.scene.ground_z)


def _streamed(args: argparse.Namespace, setup: Any) -> bool:
    if _model(args) != "raster":
        if args.chunk_pings is not None:
            raise SonarRasterError("--chunk-pings needs the GL raster renderer")
        return False
    cells = setup.trajectory.n_pings * setup.sonar.n_bins * len(setup.sonar.sides)
    return args.chunk_pings is not None or cells > _STREAM_CELLS


def _track_metadata(setup: Any) -> dict[str, Any]:
    """The scene, altitude, pings and the pings' spacing for an image's metadata.

    The spacing (metres; left out when the sonar does not move) is what ``invert`` reads back
    as the image's along-track geometry.
    """
    import numpy as np

    track = setup.trajectory
    meta = {"scene": setup.source, "altitude_m": setup.altitude, "pings": track.n_pings}
    if track.n_pings >= 2 and np.any(np.diff(track.positions, axis=0)):
        meta["ping_spacing_m"] = track.typical_spacing
    return meta


def _render_survey(args: argparse.Namespace, runs: list[tuple], outputs: list[Path]) -> int:
    """Stream the track to its files block by block.

    ``runs`` are ``(preset, args, setup, effects)``: one with preset None, or several presets
    (their PNG/EXR named as :func:`_write` names them, one XTF of all).
    """
    from ..rendering.survey import SurveyBand, render_bands

    xtfs = [p for p in outputs if p.suffix.lower() == ".xtf"]
    images = [p for p in outputs if p.suffix.lower() != ".xtf"]
    bands = []
    for name, one, setup, effects in runs:
        meta = _track_metadata(setup)
        meta.update(setup.notes)
        files = images if name is None else _named(images, name)
        display = display_from_args(one, setup)
        band = SurveyBand(setup.sonar, tuple(files), effects, one.seed, meta, display, name)
        bands.append(band)
    setup = runs[0][2]
    written, summaries = render_bands(
        setup.scene,
        bands,
        setup.trajectory,
        xtfs,
        chunk_pings=args.chunk_pings or 512,
        backend=args.gl,
        settings=_settings(args),
        bit_depth=args.bits,
        dynamic_range_db=args.dynamic_range,
        progress=not args.quiet,
    )
    if not args.quiet:
        for (name, _, band_setup, _), summary in zip(runs, summaries, strict=True):
            what = setup.source if name is None else f"{setup.source} as {name}"
            print(
                f"rendered {what}: {setup.trajectory.n_pings} pings x {band_setup.sonar.n_bins} "
                f"bins per side in {summary['blocks']} blocks; {summary['draws']} draws, "
                f"{summary['draws_skipped_empty']} skipped as empty"
            )
        for path in dict.fromkeys(written):  # a sidecar shared by a PNG and an EXR: once
            print(f"wrote {path}")
    return 0


def _named(paths: list[Path], preset: str) -> list[Path]:
    """A preset's own image files: ``out.png`` → ``out.PRESET.png``."""
    return [path.with_name(f"{path.stem}.{preset}{path.suffix}") for path in paths]
