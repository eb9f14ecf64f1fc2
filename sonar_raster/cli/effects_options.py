"""``sonar-raster render`` options for the sensor effects, merged over a scene's [effects]."""

from __future__ import annotations

import argparse
import math
from dataclasses import replace
from typing import Any

from ..errors import SonarRasterError

_ALONG_MODES = ("along_beam_deg", "array_length_m", "sas_resolution_m")


def _number(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be finite, got {text}")
    return value


def add_effect_options(parser: argparse.ArgumentParser) -> None:
    """Add the effect options to the ``render`` parser (all default to the scene's values)."""
    group = parser.add_argument_group(
        "sensor effects (override the scene's [effects]; see README 'Sensor effects')"
    )
    add = group.add_argument
    add("--along-beam-deg", type=_number, metavar="DEG", help="side-scan horizontal beam width")
    add("--array-length", type=_number, metavar="M", help="side-scan array length (beam λ/L)")
    add("--sas-resolution", type=_number, metavar="M", help="SAS along-track resolution")
    add("--nadir-gap-deg", type=_number, metavar="DEG", help="blind cone below the sonar")
    add("--water-column-db", type=_number, metavar="DB", help="water-column level, dB re 1 m²")
    add("--speckle", choices=("off", "exponential", "k"), help="multiplicative speckle")
    add("--k-shape", type=_number, metavar="NU", help="K-distribution shape (with --speckle k)")
    add("--range-resolution", type=_number, metavar="M", help="speckle range cell (default 1 bin)")
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
    add("--no-effects", action="store_true", help="ignore the scene's [effects] table")


def effects_from_args(args: argparse.Namespace, scene_effects: Any) -> Any:
    """The Effects to apply: the scene's (unless --no-effects) with the options given on top.

    Returns None when nothing is enabled, so the caller skips the effects step entirely.
    """
    from ..effects.chain import Effects, load_tvg_curve

    base = Effects() if args.no_effects or scene_effects is None else scene_effects
    simple = {
        "along_beam_deg": args.along_beam_deg,
        "array_length_m": args.array_length,
        "sas_resolution_m": args.sas_resolution,
        "nadir_gap_deg": args.nadir_gap_deg,
        "water_column_db": args.water_column_db,
        "speckle": args.speckle,
        "k_shape": args.k_shape,
        "range_resolution_m": args.range_resolution,
        "spreading": args.spreading,
        "absorption": args.absorption,
        "noise_db": args.noise,
        "tvg_log_coefficient": args.tvg_log,
        "gain_db": args.gain_db,
        "saturation": args.saturation,
        "bits": args.quantise_bits,
    }
    changes: dict[str, Any] = {k: v for k, v in simple.items() if v is not None}
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
        else:
            changes.update(tvg="curve", tvg_curve=load_tvg_curve(args.tvg))
    try:
        effects = replace(base, **changes) if changes else base
    except TypeError as exc:  # pragma: no cover - argparse types prevent this
        raise SonarRasterError(f"effects: {exc}") from None
    return effects if effects.stages else None
