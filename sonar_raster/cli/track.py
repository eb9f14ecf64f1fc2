"""``sonar-raster track``: the altitude per ping of an XTF file, as a summary, plot or table."""

from __future__ import annotations

import argparse
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import SonarRasterError

if TYPE_CHECKING:  # bottom imports scipy: keep it out of `sonar-raster --help`
    from ..inversion.bottom import BottomTrack

TRACK_SUFFIXES = (".png", ".csv")


def parse_pings(text: str | None) -> slice | None:
    """``"A:B"`` (either end may be empty) as a slice of ping indices; None for None."""
    if text is None:
        return None
    parts = text.split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        start, stop = (int(p) if p.strip() else None for p in parts)
    except ValueError:
        raise SonarRasterError(f"--pings {text!r}: use FIRST:STOP, e.g. 100:200") from None
    if (start is not None and start < 0) or (stop is not None and stop < 0):
        raise SonarRasterError(f"--pings {text!r}: ping indices are >= 0")
    return slice(start, stop)


def parse_xtf_frequency(text: str | None) -> float | str | None:
    """``--xtf-frequency``: "low", "high" or a frequency in kHz, as ``read_xtf`` takes it."""
    if text is None or text in ("low", "high"):
        return text
    try:
        khz = float(text)
    except ValueError:
        khz = float("nan")
    if not (np.isfinite(khz) and khz > 0):
        raise SonarRasterError(
            f"--xtf-frequency {text!r}: use low, high or the channels' frequency in kHz, e.g. 900"
        )
    return khz * 1e3


def add_xtf_frequency(parser: Any, more: str = "") -> None:
    """Add ``--xtf-frequency`` (which pair of a dual-frequency file's channels to read)."""
    parser.add_argument(
        "--xtf-frequency",
        metavar="F",
        help="XTF input with several frequencies: low, high or kHz (default: the first pair)"
        + more,
    )


def add_parser(sub: Any) -> None:
    """Add the ``track`` subcommand to an argparse subparsers object."""
    track = sub.add_parser(
        "track",
        help="bottom-track an XTF file: altitude per ping from the first bottom return",
        description="Track the first bottom return of each ping in FILE.xtf (both sides), "
        "print a summary, and write the altitude per ping as a plot (.png, needs matplotlib) "
        "or a table (.csv).",
    )
    track.add_argument("file", help="XTF file")
    track.add_argument("-o", "--output", metavar="OUT", help="output .png or .csv")
    track.add_argument("--pings", metavar="A:B", help="ping range (indices, stop excluded)")
    add_xtf_frequency(track)
    track.add_argument("-q", "--quiet", action="store_true", help="no summary")


def run(args: argparse.Namespace) -> int:
    """Run ``sonar-raster track``."""
    from ..inversion.track_io import summary_lines
    from ..io.commit import check_writable
    from ..io.xtf import read_xtf

    out = Path(args.output) if args.output else None
    if out is not None:
        if out.suffix.lower() not in TRACK_SUFFIXES:
            raise SonarRasterError(f"output {out}: unknown extension; use .png or .csv")
        check_writable(out)
    frequency = parse_xtf_frequency(args.xtf_frequency)
    image, nav = read_xtf(args.file, parse_pings(args.pings), frequency)
    from ..inversion.bottom import track_bottom

    track = track_bottom(image.sides, image.sonar.range_bin)
    if not args.quiet:
        for line in summary_lines(track, nav.altitude, image.sonar.range_bin):
            print(line)
    if out is not None:
        written = write_track(out, track, nav.altitude, image)
        if not args.quiet:
            print(f"wrote {written}")
    return 0


def write_track(out: Path, track: BottomTrack, recorded: np.ndarray, image) -> Path:
    """Write the track as a .csv table or a .png plot (with the waterfall), all-or-nothing."""
    from ..inversion.track_io import write_track_csv
    from ..io.commit import commit

    if out.suffix.lower() == ".csv":
        pings = image.metadata.get("ping_indices")  # file ping numbers (bad pings skipped)
        commit([(out, partial(write_track_csv, track=track, recorded=recorded, pings=pings))])
    else:
        commit([(out, partial(_plot_track, track=track, recorded=recorded, image=image))])
    return out


def _plot_track(tmp: Path, track: BottomTrack, recorded: np.ndarray, image) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (wf, ax) = plt.subplots(1, 2, figsize=(12, 6), width_ratios=(1.4, 1))
    try:
        draw_waterfall(wf, image, track.altitude)
        pings = np.arange(len(track.altitude))
        ax.plot(pings, track.altitude, "k-", lw=1.2, label="tracked (first return)")
        bad = ~track.valid
        ax.plot(pings[bad], track.altitude[bad], "rx", ms=4, label="no clear return")
        if np.isfinite(recorded).any():
            ax.plot(pings, recorded, "c-", lw=0.8, label="file (SensorPrimaryAltitude)")
        ax.set_xlabel("ping")
        ax.set_ylabel("altitude, m")
        ax.legend(loc="best", fontsize=8)
        ax.grid(alpha=0.3)
        fig.tight_layout()
        fig.savefig(tmp, format="png", dpi=110)
    finally:
        plt.close(fig)


def draw_waterfall(ax, image, altitude: np.ndarray | None = None) -> None:
    """Waterfall on a matplotlib axis: port on the left (range increasing to the left), dB."""
    display = image.display().astype(np.float64)
    positive = display[display > 0]
    floor = float(np.percentile(positive, 1)) if positive.size else 1.0
    db = 10.0 * np.log10(np.maximum(display, floor))
    top = float(np.percentile(db, 99.5))
    reach = image.sonar.range_bin * image.shape[1]
    left = -reach if "port" in image.sides else 0.0
    right = reach if "starboard" in image.sides else 0.0
    pings = image.shape[0]
    ax.imshow(
        db, cmap="copper", aspect="auto", vmin=top - 40.0, vmax=top,
        extent=(left, right, pings - 0.5, -0.5), interpolation="nearest",
    )  # fmt: skip
    if altitude is not None:
        rows = np.arange(pings)
        for sign, side in ((-1.0, "port"), (1.0, "starboard")):
            if side in image.sides:
                ax.plot(sign * altitude, rows, "c-", lw=0.6)
    ax.set_xlabel("slant range, m (port < 0 < starboard)")
    ax.set_ylabel("ping")
