"""The ``sonar-raster`` command line: ``render``, ``invert``, ``scenes`` and ``doctor``.

Heavy modules (moderngl, trimesh, OpenImageIO) load inside the commands, so ``--help``
answers at once. Bad input ends with one line on stderr and exit status 2, with no traceback
and no output file left behind.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from ..errors import SonarRasterError

EXIT_BAD_INPUT = 2
_SIDE_CHOICES = {"port": ("port",), "starboard": ("starboard",), "both": ("port", "starboard")}
_OUTPUT_SUFFIXES = (".png", ".exr", ".xtf")


def _positive(kind: type):
    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        if not (0 < value < float("inf")):
            raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
        return value

    parse.__name__ = f"positive {kind.__name__}"
    return parse


def _looks(text: str) -> float | str | None:
    """``--looks``: a number > 0, ``auto`` or ``none``."""
    if text.lower() in ("auto", "none"):
        return None if text.lower() == "none" else "auto"
    try:
        return _positive(float)(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(
            f"must be a number > 0, auto or none, got {text}"
        ) from None


_looks.__name__ = "looks"


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: ``sonar-raster: error: ... (see --help)``, exit 2."""

    def error(self, message: str):  # type: ignore[override]
        print(f"sonar-raster: error: {message} (see '{self.prog} --help')", file=sys.stderr)
        sys.exit(EXIT_BAD_INPUT)


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="sonar-raster",
        description="Side-scan sonar images from 3D scenes, rendered with headless OpenGL.",
    )
    sub = parser.add_subparsers(
        dest="command", required=True, metavar="COMMAND", parser_class=_Parser
    )

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
        type=_positive(float),
        metavar="METRES",
        help="maximum slant range",
    )
    render.add_argument(
        "--range-bin", type=_positive(float), metavar="METRES", help="slant-range bin size"
    )
    render.add_argument(
        "--altitude",
        type=_positive(float),
        metavar="METRES",
        help="sonar altitude above the seabed",
    )
    render.add_argument("--pings", type=_positive(int), metavar="N", help="number of pings")
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
        type=_positive(float),
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
        type=_positive(float),
        default=None,
        help="look-angle samples per range bin (GL renderer, default 2)",
    )
    render.add_argument(
        "--along-samples",
        type=_positive(int),
        default=None,
        metavar="N",
        help="rays per ping along track (GL renderer, default 2)",
    )
    render.add_argument(
        "--chunk-pings",
        type=_positive(int),
        default=None,
        metavar="N",
        help="render the track in blocks of N pings streamed to disk, so memory does not grow "
        "with the track (GL renderer; default: whole track at once, or blocks of 512 when it "
        "would exceed 64 M cells)",
    )
    render.add_argument("--bits", type=int, choices=(8, 16), default=8, help="PNG bit depth")
    render.add_argument(
        "--dynamic-range",
        type=_positive(float),
        default=None,
        metavar="DB",
        help="PNG display range in dB below the reference level (default: the image's span, "
        "6 to 60 dB)",
    )
    render.add_argument("-q", "--quiet", action="store_true", help="no progress or summary")

    from .effects_options import add_effect_options

    add_effect_options(render)
    _add_invert(sub)
    _add_dataset(sub)
    from .track import add_track_parser

    add_track_parser(sub)
    sub.add_parser("scenes", help="list the bundled scenes")
    sub.add_parser("doctor", help="show which GL backends start and the package versions")
    return parser


def _add_dataset(sub) -> None:
    ds = sub.add_parser(
        "dataset",
        help="generate a labelled dataset (images, masks, YOLO, COCO) from a config",
        description="Render N randomised, labelled samples from a dataset config (.toml, or a "
        "bundled one such as 'dataset_default') into DIR; rerunning resumes a stopped run.",
    )
    ds.add_argument("config", help="dataset config file or bundled name")
    ds.add_argument("-o", "--output", required=True, metavar="DIR", help="output directory")
    ds.add_argument(
        "-n", dest="count", type=_positive(int), metavar="N", help="samples (default: config)"
    )
    ds.add_argument("--workers", type=_positive(int), default=1, help="worker processes")
    ds.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler tcp://... or 'local'")
    ds.add_argument("--seed", type=int, default=None, help="global seed (default: config)")
    ds.add_argument("-q", "--quiet", action="store_true", help="no progress bar or summary")


def _add_invert(sub) -> None:
    inv = sub.add_parser(
        "invert",
        help="recover reflectivity, beam profile and elevation from one image side",
        description="Invert IMAGE (.npy, .exr or .png; rows = pings, columns = slant-range "
        "bins from range 0; the renderer's EXR as is) into DIR/elevation.exr, "
        "reflectivity.exr, beam.exr (rows = pings, columns = ground-range cells, NaN = no "
        "estimate), ground.exr (the image in ground range at the recovered elevation), "
        "even.exr (evenly illuminated, seed Eq. 22), beam_profile.json, seabed.glb/.ply "
        "(textured mesh), preview_az*.png (four views) and DIR/inversion.json. An XTF file "
        "(.xtf) is inverted on both sides (or --side) with its bottom track as altitude, into "
        "DIR/port/ and DIR/starboard/, plus DIR/bottom_track.csv and, with navigation, "
        "GeoTIFFs DIR/elevation.tif, reflectivity.tif and mosaic.tif.",
    )
    inv.add_argument("image", help="input image, or an .xtf file")
    inv.add_argument("-o", "--output", required=True, metavar="DIR", help="output directory")
    inv.add_argument(
        "--range-bin",
        type=_positive(float),
        metavar="METRES",
        help="slant-range bin size (read from a renderer EXR when omitted)",
    )
    inv.add_argument(
        "--altitude",
        type=_positive(float),
        metavar="METRES",
        help="sonar altitude (default: first bottom return of each ping)",
    )
    inv.add_argument("--side", choices=("port", "starboard"), help="which side of an EXR")
    inv.add_argument(
        "--max-iter",
        type=_positive(int),
        default=300,
        metavar="N",
        help="most iterations per pyramid level and start (default 300; fewer is faster, coarser)",
    )
    inv.add_argument(
        "--ping-spacing",
        type=_positive(float),
        metavar="METRES",
        help="along-track distance between pings, for the along-track slope (default: the "
        "ground cell size)",
    )
    inv.add_argument(
        "--levels", type=_positive(int), default=3, metavar="N", help="pyramid levels (default 3)"
    )
    inv.add_argument(
        "--tol",
        type=_positive(float),
        default=1e-2,
        help="stop a level when E falls by less than TOL x E in an iteration (default 1e-2)",
    )
    inv.add_argument(
        "--beam",
        metavar="FILE",
        help="calibrated mode: fix the beam profile from a beam_profile.json of an earlier run",
    )
    inv.add_argument(
        "--flat-prior",
        type=_positive(float),
        metavar="W",
        help="prior that the seabed is flat at the altitude on scales above 0.2 x altitude "
        "(weight W, try 0.25): for broadly flat seabeds with small relief and a trusted "
        "--altitude; it flattens broad mounds and trenches",
    )
    inv.add_argument(
        "--looks",
        type=_looks,
        default="auto",
        metavar="L|auto|none",
        help="speckle looks of the image, which weigh priors on the relief and slopes against "
        "the image noise (default auto: estimated from neighbouring pings; none: no priors, "
        "for noise-free images)",
    )
    inv.add_argument(
        "--relief-std",
        type=_positive(float),
        default=0.1,
        metavar="METRES",
        help="relief about the flat seabed assumed on speckled images (default 0.1)",
    )
    inv.add_argument(
        "--slope-std",
        type=_positive(float),
        default=0.2,
        metavar="S",
        help="seabed slope (rise over run) assumed on speckled images (default 0.2)",
    )
    inv.add_argument("--no-mesh", action="store_true", help="skip seabed.glb and seabed.ply")
    inv.add_argument("--no-previews", action="store_true", help="skip the preview renders")
    inv.add_argument(
        "--pings", metavar="A:B", help="XTF input: ping range to invert (indices, stop excluded)"
    )
    inv.add_argument("--quiet", action="store_true", help="no progress bar or summary")


def _invert(args: argparse.Namespace) -> int:
    from ..inversion.solver import BeamProfile, invert
    from ..inversion.write import energy_summary, read_side, write_products

    if Path(args.image).suffix.lower() == ".xtf":
        from ..inversion.xtf import invert_xtf_command

        return invert_xtf_command(args)
    image, side, attrs = read_side(Path(args.image), args.side)
    range_bin = args.range_bin or attrs.get("sonar:range_bin_m")
    if not range_bin:
        raise SonarRasterError("--range-bin is required for this image")
    beam = BeamProfile.load(args.beam) if args.beam else None
    result = invert(
        image,
        float(range_bin),
        altitude=args.altitude,
        ping_spacing=args.ping_spacing,
        max_iter=args.max_iter,
        levels=args.levels,
        tol=args.tol,
        beam=beam,
        flat_prior=args.flat_prior or 0.0,
        looks=args.looks,
        relief_std=args.relief_std,
        slope_std=args.slope_std,
        progress=not args.quiet,
    )
    written = write_products(
        result,
        Path(args.output),
        side,
        float(range_bin),
        mesh=not args.no_mesh,
        previews=not args.no_previews,
    )
    if not args.quiet:
        for line in energy_summary(result):
            print(line)
        for path in written:
            print(f"wrote {path}")
    return 0


def _resolve_scene(name: str) -> Path:
    path = Path(name)
    if path.exists() or path.suffix:
        return path
    from ..scenes.bundled import bundled_scene

    return bundled_scene(name)


def _check_outputs(outputs: list[str]) -> list[Path]:
    paths = [Path(o) for o in outputs]
    for p in paths:
        if p.suffix.lower() not in _OUTPUT_SUFFIXES:
            raise SonarRasterError(f"output {p}: unknown extension; use .png, .exr or .xtf")
        if not p.parent.is_dir():
            raise SonarRasterError(
                f"cannot write {p}: directory {p.parent} does not exist; create it first"
            )
    return paths


def _render(args: argparse.Namespace) -> int:
    outputs = _check_outputs(args.output)
    from ..scenes.description import Overrides, load_scene_file

    overrides = Overrides(
        max_range=args.max_range,
        range_bin=args.range_bin,
        altitude=args.altitude,
        pings=args.pings,
        sides=_SIDE_CHOICES[args.side] if args.side else None,
    )
    setup = load_scene_file(_resolve_scene(args.scene), overrides)
    if _streamed(args, setup):
        return _render_survey(args, setup, outputs)
    if args.model == "coherent":
        from ..rendering.coherent.model import render_coherent, to_raster_units

        options = dict(setup.coherent)
        if args.spacing is not None:
            options["spacing_wavelengths"] = args.spacing
        if args.seed is not None:
            options["seed"] = args.seed
        image = render_coherent(
            setup.scene,
            setup.sonar,
            setup.trajectory,
            pulse=setup.pulse,
            progress=not args.quiet,
            **options,
        )
        if image.metadata["facet_area_m2"] > 0:  # written in the raster's units (m², no 1/r⁴)
            image = to_raster_units(image)
    elif args.renderer == "reference":
        from ..rendering.reference import render_reference

        image = render_reference(setup.scene, setup.sonar, setup.trajectory)
    else:
        from ..rendering.gl.raster import RasterSettings, render_raster

        settings = RasterSettings(
            oversample=args.oversample or RasterSettings.oversample,
            along_samples=args.along_samples or RasterSettings.along_samples,
        )
        image = render_raster(
            setup.scene,
            setup.sonar,
            setup.trajectory,
            backend=args.gl,
            settings=settings,
            progress=not args.quiet,
        )
    image.metadata.update(
        {"scene": setup.source, "altitude_m": setup.altitude, "pings": setup.trajectory.n_pings}
    )
    image.metadata.update(setup.notes)
    from .effects_options import effects_from_args

    effects = effects_from_args(args, setup.effects)
    if effects is not None:  # no effects: the renderer's image is written as is
        from ..effects.chain import apply_effects

        image = apply_effects(image, effects, seed=args.seed, trajectory=setup.trajectory)
    from ..io.images import write_image

    written = []
    for path in outputs:
        if path.suffix.lower() == ".xtf":
            from ..io.xtf import write_xtf

            traj = setup.trajectory
            altitude = traj.positions[:, 2] - setup.scene.ground_z
            written.append(write_xtf(path, image, traj, altitude=altitude))
            continue
        written += write_image(
            image, path, bit_depth=args.bits, dynamic_range_db=args.dynamic_range
        )
    if not args.quiet:
        pings, bins = image.shape
        print(
            f"rendered {setup.source}: {setup.scene.n_triangles} triangles, {pings} pings x "
            f"{bins} bins per side ({', '.join(image.sides)})"
        )
        for path in dict.fromkeys(written):
            print(f"wrote {path}")
    return 0


#: Cells (pings × bins × sides) above which a GL render streams in blocks by default.
_STREAM_CELLS = 1 << 26


def _streamed(args: argparse.Namespace, setup) -> bool:
    if args.model != "raster" or args.renderer != "gl":
        if args.chunk_pings is not None:
            raise SonarRasterError("--chunk-pings needs the GL raster renderer")
        return False
    cells = setup.trajectory.n_pings * setup.sonar.n_bins * len(setup.sonar.sides)
    return args.chunk_pings is not None or cells > _STREAM_CELLS


def _render_survey(args: argparse.Namespace, setup, outputs: list[Path]) -> int:
    from ..rendering.gl.raster import RasterSettings
    from ..rendering.survey import render_survey
    from .effects_options import effects_from_args

    if effects_from_args(args, setup.effects) is not None:
        raise SonarRasterError(
            "sensor effects are not applied to surveys streamed in blocks (--chunk-pings, or "
            "over 64 M cells) yet; render fewer pings at a time, or add --no-effects"
        )

    settings = RasterSettings(
        oversample=args.oversample or RasterSettings.oversample,
        along_samples=args.along_samples or RasterSettings.along_samples,
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
        settings=settings,
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


def _scenes() -> int:
    from ..scenes.bundled import list_bundled

    for name, description in list_bundled():
        print(f"{name:24s} {description}")
    return 0


def _doctor() -> int:
    import os
    from importlib import metadata

    from ..rendering.gl.context import BACKENDS, ENV_VAR, probe

    print(f"{ENV_VAR}={os.environ.get(ENV_VAR, '(unset)')}")
    ok = False
    for backend in BACKENDS:
        info = probe(backend)
        if info["ok"] == "yes":
            ok = True
            print(
                f"{backend:7s} ok   {info['renderer']} | OpenGL {info['version']} | "
                f"max texture {info['max_texture_size']}"
            )
        else:
            print(f"{backend:7s} FAIL {info['error']}")
    print(f"python  {sys.version.split()[0]}")
    for pkg in (
        "sonar_raster",
        "moderngl",
        "glcontext",
        "numpy",
        "scipy",
        "trimesh",
        "OpenImageIO",
        "scikit-image",
        "rasterio",
        "embreex",
    ):
        try:
            version = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            version = "not installed"
        print(f"{pkg:13s} {version}")
    return 0 if ok else 1


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    args = _parser().parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="sonar-raster: %(message)s")
    try:
        if args.command == "render":
            return _render(args)
        if args.command == "dataset":
            from ..dataset.generate import run_cli

            return run_cli(args)
        if args.command == "invert":
            return _invert(args)
        if args.command == "track":
            from .track import track_command

            return track_command(args)
        if args.command == "scenes":
            return _scenes()
        return _doctor()
    except SonarRasterError as exc:
        print(f"sonar-raster: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("sonar-raster: interrupted; nothing was written", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
