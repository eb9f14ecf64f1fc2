"""``sonar-raster sensors``: the sensor presets, with their main figures."""

from __future__ import annotations

import argparse
import json
from typing import Any


def add_parser(sub: Any) -> None:
    """Add the ``sensors`` subcommand to an argparse subparsers object."""
    sensors = sub.add_parser(
        "sensors",
        help='list the sensor presets (render --sensor NAME, [sonar] preset = "NAME")',
        description="List the sensor presets: frequency, range resolution, beams, tilt, default "
        "range and bins, bit depth. Figures marked * were chosen, not published (docs/sensors.md "
        "gives the sources and the reasons).",
    )
    sensors.add_argument("--json", action="store_true", help="every field of every preset, as JSON")


def _row(p: Any) -> list[str]:
    star = set(p.assumed)

    def mark(field: str, text: str) -> str:
        return text + ("*" if field in star else "")

    if p.kind == "sas":
        along = f"SAS {100 * p.sas_resolution_m:g} cm"
    else:
        along = mark("horizontal_beamwidth_deg", f"{p.horizontal_beamwidth_deg:g} deg")
    bins = p.sonar().n_bins
    return [
        p.name,
        mark("frequency_hz", f"{p.frequency_hz / 1e3:g} kHz"),
        f"{100 * p.range_resolution_m:.3g} cm",
        along,
        mark("vertical_beamwidth_deg", f"{p.vertical_beamwidth_deg:g} deg"),
        mark("tilt_deg", f"{p.tilt_deg:g} deg"),
        mark("max_ranges_m", f"{p.max_ranges_m[0]:.4g} m") + f" / {bins}",
        mark("bits", str(p.bits)),
    ]


def run(args: argparse.Namespace) -> int:
    """Run ``sonar-raster sensors``."""
    from ..effects.presets import DEFAULT_SENSOR, PRESETS, list_presets

    names = list_presets()
    if args.json:
        rows = {n: PRESETS[n].table_row() for n in names}
        print(json.dumps({"default": DEFAULT_SENSOR, "presets": rows}, indent=2))
        return 0
    head = ["preset", "frequency", "range res.", "along-track", "vertical", "tilt", "range / bins"]
    table = [[*head, "bits"]] + [_row(PRESETS[n]) for n in names]
    widths = [max(len(r[i]) for r in table) for i in range(len(head) + 1)]
    for k, row in enumerate(table):
        line = "  ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)).rstrip()
        print(line + ("   (default)" if k and row[0] == DEFAULT_SENSOR else ""))
    print("* chosen, not published: see docs/sensors.md")
    return 0
