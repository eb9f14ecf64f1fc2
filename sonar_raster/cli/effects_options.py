"""``sonar-raster render`` options for the sensor and its effects, merged over a scene's [effects].

Which effects a render gets, from the lowest layer up: the sensor's (``--sensor NAME``, else the
scene's ``[sonar] preset``, else the default sensor :data:`~sonar_raster.effects.presets.
DEFAULT_SENSOR`), replaced by the scene's ``[effects]`` table when it has one and names no
sensor; then the effect options given on the command line. ``--ideal`` starts from no effects at
all (the raw Lambertian image, as the renderer gives it), with the options on top.
"""

from __future__ import annotations

import argparse
import math
from typing import Any

_ALONG_MODES = ("along_beam_deg", "array_length_m", "sas_resolution_m")
#: Effects field -> the render option (its ``dest``) that sets it as it is; None: not given.
_FIELDS = {
    "along_beam_deg": "along_beam_deg",
    "array_length_m": "array_length",
    "sas_resolution_m": "sas_resolution",
    "nadir_gap_deg": "nadir_gap_deg",
    "water_column_db": "water_column_db",
    "volume_db": "water_column_sv",
    "speckle": "speckle",
    "k_shape": "k_shape",
    "speckle_looks": "speckle_looks",
    "range_resolution_m": "range_resolution",
    "downsample": "downsample",
    "sample_spacing_m": "sample_spacing",
    "spreading": "spreading",
    "absorption": "absorption",
    "noise_db": "noise",
    "tvg_log_coefficient": "tvg_log",
    "gain_db": "gain_db",
    "saturation": "saturation",
    "bits": "quantise_bits",  # not "bits": that is render's PNG bit depth
}


def _number(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be finite, got {text}")
    return value


def _positive(text: str) -> float:
    value = _number(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be a length > 0 in metres, got {text}")
    return value


def add_effect_options(parser: argparse.ArgumentParser) -> None:
    """Add the effect options to the ``render`` parser (all default to the scene's values)."""
    group = parser.add_argument_group(
        "sensor and effects (override the scene's [effects]; see docs/sensors.md, docs/effects.md)"
    )
    add = group.add_argument
    add(
        "--sensor",
        metavar="NAME",
        help="sensor preset: its sonar (frequency, beams, tilt, range, bins) and every effect it "
        "has (see 'sonar-raster sensors'); default: the scene's [sonar] preset, else the "
        f"effects of {_default_sensor()} on the scene's sonar. render: several comma-separated "
        "(e.g. a dual-frequency sonar's two) render one image each over one track, one .xtf",
    )
    add(
        "--ideal",
        action="store_true",
        help="no sensor effects and no seabed micro_relief: the raw Lambertian image of the "
        "scene's geometry (options below still apply)",
    )
    add("--along-beam-deg", type=_number, metavar="DEG", help="side-scan horizontal beam width")
    add("--array-length", type=_number, metavar="M", help="side-scan array length (beam λ/L)")
    add("--sas-resolution", type=_number, metavar="M", help="SAS along-track resolution")
    add("--nadir-gap-deg", type=_number, metavar="DEG", help="blind cone below the sonar")
    add("--water-column-db", type=_number, metavar="DB", help="water-column level, dB re 1 m²")
    add("--speckle", choices=("off", "exponential", "k"), help="multiplicative speckle")
    add("--k-shape", type=_number, metavar="NU", help="K-distribution shape (with --speckle k)")
    add(
        "--speckle-looks",
        type=_number,
        metavar="L",
        help="looks per sample (>= 1): speckle of L averaged looks, contrast 1/sqrt(L)",
    )
    add("--range-resolution", type=_number, metavar="M", help="speckle range cell (default 1 bin)")
    add(
        "--downsample",
        choices=("off", "max", "mean"),
        help="recorder keeps the max or mean intensity of its sub-samples per bin (needs "
        "--sample-spacing unless the sensor sets it)",
    )
    add(
        "--sample-spacing",
        type=_positive,
        metavar="M",
        help="recorder sample spacing before --downsample, m of slant range",
    )
    add("--spreading", action="store_true", default=None, help="two-way spreading, 1/r^4")
    add("--absorption", action="store_true", default=None, help="Francois-Garrison absorption")
    add("--noise", type=_number, metavar="DB", help="receiver noise level, dB in image units")
    add(
        "--tvg",
        metavar="LAW",
        help="time-varied gain: 'log' (N log r + 2 alpha r), 'off', or a CSV of range_m,gain_db",
    )
    add("--tvg-log", type=_number, metavar="N", help="N of the log TVG law (default 30)")
    add("--gain-db", type=_number, metavar="DB", help="fixed gain")
    add("--saturation", type=_number, metavar="LEVEL", help="full-scale level; above it clips")
    add("--quantise-bits", type=int, choices=(8, 12, 16), help="quantise to the sonar's bits")
    add("--water-column-sv", type=_number, metavar="DB", help="volume backscatter Sv, dB re 1/m")
    add("--no-effects", action="store_true", help="the same as --ideal")
    add_display_options(parser)


def _default_sensor() -> str:
    from ..effects.presets import DEFAULT_SENSOR

    return DEFAULT_SENSOR


def ideal_requested(args: argparse.Namespace) -> bool:
    """``--ideal``, ``--no-effects`` or ``--sensor ideal``: no effects, no seabed micro-relief."""
    flags = getattr(args, "ideal", False) or getattr(args, "no_effects", False)
    return bool(flags or getattr(args, "sensor", None) == "ideal")


def apply_sensor_option(args: argparse.Namespace, setup: Any) -> Any:
    """The scene setup with ``--sensor NAME``'s sonar; explicit sonar options win over it.

    ``--range``/``--range-bin`` choose the preset's range sampling; ``--frequency``, ``--tilt``,
    ``--beamwidth`` (a Gaussian two-way beam of that width) and ``--sound-speed``, where given,
    replace the preset's values (they were already applied to the scene's own sonar, which the
    preset replaces).

    Parameters
    ----------
    args : argparse.Namespace
        Parsed ``render`` options (``sensor``, ``max_range``, ``range_bin``, ``frequency``
        (kHz), ``tilt`` (degrees), ``beamwidth`` (degrees), ``sound_speed`` (m/s)).
    setup : SceneSetup
        The loaded scene; its sides are kept.

    Returns
    -------
    SceneSetup
        ``setup`` itself without ``--sensor``; else a copy whose sonar is the preset's with the
        explicit options applied (``notes["sensor_sonar_overrides"]`` lists them).
    """
    name = getattr(args, "sensor", None)
    if name is None or name == "ideal":  # --ideal with a preset: its sonar, no effects
        return setup
    import math
    from dataclasses import replace

    from ..effects.presets import preset
    from ..sonar import BeamPattern

    sonar = preset(name).sonar(args.max_range, args.range_bin, setup.sonar.sides)
    changes: dict[str, Any] = {}
    if getattr(args, "frequency", None) is not None:
        changes["frequency_hz"] = 1e3 * float(args.frequency)
    if getattr(args, "tilt", None) is not None:
        changes["tilt"] = math.radians(float(args.tilt))
    if getattr(args, "beamwidth", None) is not None:
        changes["beam"] = BeamPattern.gaussian(float(args.beamwidth))
    if getattr(args, "sound_speed", None) is not None:
        changes["sound_speed"] = float(args.sound_speed)
    notes = {**setup.notes, "sensor_sonar": name}
    if changes:
        sonar = replace(sonar, **changes)
        options = {"frequency_hz": "--frequency", "tilt": "--tilt", "beam": "--beamwidth"}
        notes["sensor_sonar_overrides"] = [options.get(k, "--sound-speed") for k in changes]
    return replace(setup, sonar=sonar, notes=notes)


def add_display_options(parser: argparse.ArgumentParser) -> None:
    """Add the PNG display options (level, palette, ground range, square pixels).

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The ``render`` parser.
    """
    group = parser.add_argument_group("PNG display (see docs/effects.md, 'The display image')")
    add = group.add_argument
    add(
        "--level",
        choices=("peak", "median"),
        default=None,
        help="peak: white at the 99.5th percentile; median: the median at mid-grey (default "
        "with effects; then --dynamic-range defaults to 45 dB)",
    )
    add("--palette", choices=("grey", "copper"), default="grey", help="PNG colours")
    add(
        "--ground-range",
        action="store_true",
        help="slant-range correction: columns in ground range over a flat seabed",
    )
    add("--square-pixels", action="store_true", help="resample pings so pixels are square")


def display_from_args(args: argparse.Namespace, setup: Any) -> Any:
    """The :class:`~sonar_raster.io.images.Display` the options ask for.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed ``render`` options.
    setup : SceneSetup
        The scene: its altitude and ping spacing place the ground range and square pixels.
    """
    from ..io.images import Display

    return Display(
        level=getattr(args, "level", None),
        palette=getattr(args, "palette", "grey"),
        ground_range=bool(getattr(args, "ground_range", False)),
        square_pixels=bool(getattr(args, "square_pixels", False)),
        altitude_m=float(setup.altitude) if setup.altitude > 0 else None,
        ping_spacing_m=float(setup.trajectory.typical_spacing) or None,
    )


def effects_from_args(args: argparse.Namespace, scene_effects: Any) -> Any:
    """The Effects to apply: the sensor's or the scene's, with the options given on top.

    The base is ``--sensor``'s effects, else the scene's (its ``[effects]`` table, or the
    effects of its ``[sonar] preset``), else those of the default sensor; ``--ideal`` (or
    ``--no-effects``) makes the base empty. The options become an ``[effects]`` table of the
    fields they set, read by
    :meth:`~sonar_raster.effects.chain.Effects.from_table` over the base. Returns None when
    nothing is enabled, so the caller skips the effects step entirely.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed ``render`` options.
    scene_effects : Effects or None
        The scene's effects (``SceneSetup.effects``).
    """
    from ..effects.chain import Effects
    from ..effects.presets import DEFAULT_SENSOR, preset

    if ideal_requested(args):
        base = Effects()
    elif getattr(args, "sensor", None) is not None:
        base = preset(args.sensor).effects()
    elif scene_effects is not None:
        base = scene_effects
    else:
        base = preset(DEFAULT_SENSOR).effects()
    given = {field: getattr(args, dest) for field, dest in _FIELDS.items()}
    changes: dict[str, Any] = {k: v for k, v in given.items() if v is not None}
    if any(k in changes for k in _ALONG_MODES):  # the command line picks the along-track mode
        for key in _ALONG_MODES:
            changes.setdefault(key, None)
    if args.k_shape is not None and "speckle" not in changes:
        changes["speckle"] = "k"  # --k-shape alone means K-distributed speckle
    if args.tvg_log is not None and args.tvg is None and base.tvg == "off":
        changes["tvg"] = "log"  # --tvg-log alone means the log law
    if args.tvg is not None:
        if args.tvg in ("off", "log"):
            changes.update(tvg=args.tvg, tvg_curve=())
        else:  # a CSV file, relative to the working folder
            changes.update(tvg="curve", tvg_curve=args.tvg)
    effects = Effects.from_table(changes, where="command line", defaults=base)
    _check_downsample(args, effects)
    return effects if effects.stages else None


def _check_downsample(args: argparse.Namespace, effects: Any) -> None:
    """Refuse --sample-spacing with downsampling off (Effects refuses the converse itself)."""
    from ..errors import SonarRasterError

    if args.sample_spacing is not None and effects.downsample == "off":
        raise SonarRasterError(
            "--sample-spacing does nothing while downsampling is off: add --downsample max or mean"
        )
