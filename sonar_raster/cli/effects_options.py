"""``sonar-raster render`` options for the sensor effects, merged over a scene's [effects]."""

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
    "speckle": "speckle",
    "k_shape": "k_shape",
    "range_resolution_m": "range_resolution",
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


def add_effect_options(parser: argparse.ArgumentParser) -> None:
    """Add the effect options to the ``render`` parser (all default to the scene's values)."""
    group = parser.add_argument_group(
        "sensor effects (override the scene's [effects]; see docs/effects.md)"
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

    The options become an ``[effects]`` table of the fields they set, read by
    :meth:`~sonar_raster.effects.chain.Effects.from_table` over the scene's effects. Returns
    None when nothing is enabled, so the caller skips the effects step entirely.
    """
    from ..effects.chain import Effects

    base = Effects() if args.no_effects or scene_effects is None else scene_effects
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
    return effects if effects.stages else None
