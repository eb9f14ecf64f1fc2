"""``sonar-raster render``: a scene (description, model file or bundled name) to images."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

from .._checks import cli_positive
from ..errors import SonarRasterError
from .effects_options import add_effect_options, effects_from_args

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
        "(.wrl .gltf .glb .obj .ply .stl) or a bundled scene by name "
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
        "--spacing",
        type=cli_positive(float),
        default=None,
        metavar="WAVELENGTHS",
        help="coherent model: scatterer spacing (default 0.25; run time grows as 1/spacing^2)",
    )
    render.add_argument(
        "--seed",
        type=int,
        default=None,
        help="seed of the coherent model's scatterer jitter and of the speckle and noise effects",
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
        help="render even when the job's memory estimate exceeds this machine's memory",
    )
    render.add_argument("-q", "--quiet", action="store_true", help="no progress or summary")
    add_effect_options(render)


def run(args: argparse.Namespace) -> int:
    """Run ``sonar-raster render``."""
    outputs = _check_outputs(args.output)
    from ..scenes.description import Overrides, load_scene

    overrides = Overrides(
        max_range=args.max_range,
        range_bin=args.range_bin,
        altitude=args.altitude,
        pings=args.pings,
        sides=_SIDE_CHOICES[args.side] if args.side else None,
    )
    setup = load_scene(args.scene, overrides)
    _check_in_range(setup)
    _check_size(args, setup, _streamed(args, setup))
    if _streamed(args, setup):
        return _render_survey(args, setup, outputs)
    image = _render_image(args, setup)
    image.metadata.update(
        {"scene": setup.source, "altitude_m": setup.altitude, "pings": setup.trajectory.n_pings}
    )
    image.metadata.update(setup.notes)
    effects = effects_from_args(args, setup.effects)
    if effects is not None:  # no effects: the renderer's image is written as is
        from ..effects.chain import apply_effects

        image = apply_effects(image, effects, seed=args.seed, trajectory=setup.trajectory)
    written = _write(args, setup, image, outputs)
    if not args.quiet:
        pings, bins = image.shape
        print(
            f"rendered {setup.source}: {setup.scene.n_triangles} triangles, {pings} pings x "
            f"{bins} bins per side ({', '.join(image.sides)})"
        )
        for path in dict.fromkeys(written):
            print(f"wrote {path}")
    return 0


def _check_outputs(outputs: list[str]) -> list[Path]:
    """Check every output (and its JSON sidecar) can be written, before any work starts."""
    from ..io.commit import check_writable

    paths = [Path(o) for o in outputs]
    for p in paths:
        if p.suffix.lower() not in _OUTPUT_SUFFIXES:
            raise SonarRasterError(f"output {p}: unknown extension; use .png, .exr or .xtf")
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


def _check_size(args: argparse.Namespace, setup: Any, streamed: bool) -> None:
    """Estimate the render's peak memory from its settings; refuse it before allocating."""
    import math

    from .._budget import check_memory

    sonar, pings = setup.sonar, setup.trajectory.n_pings
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
    if args.spacing is not None:
        options["spacing_wavelengths"] = args.spacing
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
    )


def _write(args: argparse.Namespace, setup: Any, image: Any, outputs: list[Path]) -> list[Path]:
    """Write every output in one all-or-nothing commit: all files replaced, or none."""
    from ..io.commit import commit
    from ..io.images import image_jobs

    jobs: dict[Path, Callable[[Path], None]] = {}  # a sidecar named twice: the last one wins
    for path in outputs:
        if path.suffix.lower() == ".xtf":
            jobs[path] = partial(_write_xtf, image=image, setup=setup)
            continue
        for final, writer in image_jobs(
            image, path, bit_depth=args.bits, dynamic_range_db=args.dynamic_range
        ):
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


def _render_survey(args: argparse.Namespace, setup: Any, outputs: list[Path]) -> int:
    from ..rendering.survey import render_survey

    if effects_from_args(args, setup.effects) is not None:
        raise SonarRasterError(
            "sensor effects are not applied to surveys streamed in blocks (--chunk-pings, or "
            "over 64 M cells) yet; render fewer pings at a time, or add --no-effects"
        )
    meta = {"scene": setup.source, "altitude_m": setup.altitude, "pings": setup.trajectory.n_pings}
    meta.update(setup.notes)
    written, summary = render_survey(
        setup.scene,
        setup.sonar,
        setup.trajectory,
        list(outputs),
        chunk_pings=args.chunk_pings or 512,
        backend=args.gl,
        settings=_settings(args),
        bit_depth=args.bits,
        dynamic_range_db=args.dynamic_range,
        metadata=meta,
        progress=not args.quiet,
    )
    if not args.quiet:
        print(
            f"rendered {setup.source}: {setup.trajectory.n_pings} pings x {setup.sonar.n_bins} "
            f"bins per side in {summary['blocks']} blocks; {summary['draws']} draws, "
            f"{summary['draws_skipped_empty']} skipped as empty"
        )
        for path in written:
            print(f"wrote {path}")
    return 0
