"""``sonar-raster insert``: rendered objects, their shadows and labels in a real recording."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

from .._checks import cli_seed
from ..errors import SonarRasterError
from .track import add_xtf_frequency, parse_xtf_frequency


def _at(text: str) -> tuple[int, float]:
    """``PING,RANGE``: a ping row and a signed ground range in metres (negative: port)."""
    parts = text.split(",")
    try:
        if len(parts) != 2:
            raise ValueError
        ping, ground = int(parts[0]), float(parts[1])
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r}: use PING,RANGE, e.g. 120,12.5 (range in metres, negative to port)"
        ) from None
    if ping < 0 or not math.isfinite(ground) or ground == 0:
        raise argparse.ArgumentTypeError(f"{text!r}: PING >= 0 and RANGE != 0 metres")
    return ping, ground


def add_parser(sub: Any) -> None:
    """Add the ``insert`` subcommand to an argparse subparsers object."""
    p = sub.add_parser(
        "insert",
        help="insert rendered objects, their shadows and labels into a recording (XTF)",
        description="Stand objects on the bottom-tracked seabed of RECORDING (.xtf), render "
        "them with its per-ping geometry and composite them with its gain, speckle and noise "
        "floor. Writes OUT.xtf (the recording with the objects; all else as recorded), OUT.png "
        "and OUT.json, and labels as the dataset command makes them: OUT.instances.png, "
        "OUT.classes.png (0 background, 1 highlight, 2 shadow), OUT.txt (YOLO), OUT.coco.json, "
        "and OUT.objects.json. Objects without --at are drawn from --seed where they fit.",
    )
    p.add_argument("recording", help="side-scan recording, .xtf with navigation")
    p.add_argument("-o", "--output", required=True, metavar="OUT", help="output stem or OUT.xtf")
    p.add_argument(
        "--object",
        dest="objects",
        action="append",
        metavar="SPEC",
        help="object to insert (repeat): a primitive (box, cylinder, barrel, truncated_cone, "
        "tyre, rock) or a model file, with :key=value options, e.g. box:size=2,1,0.8:yaw=30, "
        "wreck.glb:scale=0.01:up=y; keys yaw (deg), reflectivity (default 0.9), class "
        "(default: box)",
    )
    p.add_argument(
        "--at",
        action="append",
        type=_at,
        metavar="PING,RANGE",
        help="where the n-th --object stands: ping row and signed ground range in metres "
        "from the track (negative: port); objects without one are drawn",
    )
    p.add_argument("--seed", type=cli_seed, default=0, help="seed of drawn places, noise, speckle")
    p.add_argument(
        "--samples",
        choices=("auto", "amplitude", "intensity"),
        default="auto",
        help="what the file's samples are (auto: intensity in files sonar-raster wrote, "
        "else amplitude)",
    )
    add_xtf_frequency(
        p,
        "; the objects go into that pair, the other stays as recorded; all: into every pair, "
        "each rendered at its own frequency, range and bins, with labels per pair "
        "(OUT.445kHz.png, ...)",
    )
    p.add_argument(
        "--seabed-reflectivity",
        type=float,
        default=None,
        metavar="R",
        help="reflectivity the recording's seabed is taken to have (default 0.3); objects' "
        "reflectivities are relative to it",
    )
    p.add_argument(
        "--box",
        choices=("highlight", "highlight+shadow"),
        default="highlight",
        help="what YOLO and COCO boxes cover",
    )
    p.add_argument("--gl", choices=("egl", "osmesa"), default=None, help="OpenGL backend")


def run(args: argparse.Namespace) -> int:
    """Run ``sonar-raster insert``."""
    from ..insert.outputs import output_paths
    from ..insert.scene import DEFAULT_SEABED_REFLECTIVITY
    from ..io.commit import check_writable, commit

    if args.seed < 0:
        raise SonarRasterError(f"--seed must be >= 0, got {args.seed}")
    reflectivity = args.seabed_reflectivity
    if reflectivity is None:
        reflectivity = DEFAULT_SEABED_REFLECTIVITY
    if not (math.isfinite(reflectivity) and reflectivity > 0):
        raise SonarRasterError(f"--seabed-reflectivity must be > 0, got {reflectivity}")
    source = Path(args.recording)
    frequencies = _frequencies(args.xtf_frequency, source)
    paths = output_paths(args.output)
    if len(frequencies) > 1:
        paths = {"xtf": paths["xtf"]}
        for f in frequencies:
            paths.update(output_paths(_pair_stem(args.output, f), xtf=False))
    for path in paths.values():
        check_writable(path)
        if path.resolve() == source.resolve():
            raise SonarRasterError(f"output {path} would overwrite the recording; choose another")
    inserted = _insert(args, source, frequencies, reflectivity)
    written = commit(_jobs(args, inserted, frequencies))
    if not args.quiet:
        for k, o in enumerate(inserted[0].objects, start=1):
            r = o.record()
            print(
                f"object {k} ({r['class']}): ping {r['ping']}, {r['side']} ground range "
                f"{abs(r['ground_range_m']):.3g} m, size "
                + " x ".join(f"{v:.3g}" for v in r["size_m"])
                + " m"
            )
        if len(inserted) > 1:
            khz = ", ".join(f"{ins.recording.image.sonar.frequency_hz / 1e3:g}" for ins in inserted)
            print(f"into {len(inserted)} channel pairs: {khz} kHz")
        for path in written:
            print(f"wrote {path}")
    return 0


def _frequencies(text: str | None, source: Path) -> list[float | str | None]:
    """The pairs ``--xtf-frequency`` names: one, or with ``all`` every pair of the file."""
    if text != "all":
        return [parse_xtf_frequency(text)]
    from ..io.xtf import xtf_frequencies

    found = xtf_frequencies(source)
    if len(found) == 1:
        return [None]
    if not all(found):
        raise SonarRasterError(
            f"{source} does not record its channel pairs' frequencies: insert into one pair at "
            "a time (leave out --xtf-frequency for the first)"
        )
    return list(found)


def _pair_stem(out: str, frequency: float | str | None) -> str:
    """The label files' stem of one pair: ``OUT.445kHz``."""
    path = Path(out)
    stem = path.with_suffix("") if path.suffix.lower() == ".xtf" else path
    return str(stem.with_name(f"{stem.name}.{float(frequency or 0) / 1e3:g}kHz"))


def _insert(
    args: argparse.Namespace,
    source: Path,
    frequencies: list[float | str | None],
    reflectivity: float,
) -> list[Any]:
    """The insertion into each pair, in the order given.

    With several pairs the objects are placed in the pair of the shortest swath (drawn places
    then fit every pair) and stand at the same ping and ground range in the others.
    """
    from ..insert.insertion import insert_objects
    from ..insert.recording import read_recording
    from ..rendering.gl.raster import RasterRenderer

    objects = args.objects or ["box"]
    recordings = [read_recording(source, samples=args.samples, frequency=f) for f in frequencies]
    pings = {rec.shape[0] for rec in recordings}
    if len(pings) > 1:
        raise SonarRasterError(
            f"{source}: its channel pairs hold different pings ({sorted(pings)}); insert into "
            "one pair at a time (--xtf-frequency low or high)"
        )
    order = sorted(range(len(recordings)), key=lambda k: recordings[k].image.sonar.max_range)
    out: dict[int, Any] = {}
    at = args.at
    with RasterRenderer(args.gl) as renderer:
        for k in order:
            out[k] = insert_objects(
                recordings[k], objects, at=at, seed=args.seed, renderer=renderer,
                seabed_reflectivity=reflectivity,
            )  # fmt: skip
            at = [(o.ping, o.ground_range) for o in out[k].objects]
    return [out[k] for k in range(len(recordings))]


def _jobs(
    args: argparse.Namespace, inserted: list[Any], frequencies: list[float | str | None]
) -> list[tuple[Path, Any]]:
    """The files of one insertion, or of one per pair (labels per pair, one XTF of all)."""
    from ..insert.outputs import insertion_jobs, xtf_job

    if len(inserted) == 1:
        return insertion_jobs(inserted[0], args.output, box=args.box, seed=args.seed)
    jobs = [xtf_job(inserted, args.output)]
    for ins, frequency in zip(inserted, frequencies, strict=True):
        stem = _pair_stem(args.output, frequency)
        jobs += insertion_jobs(ins, stem, box=args.box, seed=args.seed, xtf=False)
    return jobs
