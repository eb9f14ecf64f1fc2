"""``sonar-raster invert``: reflectivity, beam profile and elevation from an image or XTF file."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

from .._checks import cli_positive
from ..errors import SonarRasterError
from .track import add_xtf_frequency, parse_pings, parse_xtf_frequency


def _looks(text: str) -> float | str | None:
    """``--looks``: a number > 0, ``auto`` or ``none``."""
    if text.lower() in ("auto", "none"):
        return None if text.lower() == "none" else "auto"
    try:
        return cli_positive(float)(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(
            f"must be a number > 0, auto or none, got {text}"
        ) from None


_looks.__name__ = "looks"


def add_parser(sub: Any) -> None:
    """Add the ``invert`` subcommand to an argparse subparsers object."""
    inv = sub.add_parser(
        "invert",
        help="recover reflectivity, beam profile and elevation from one image side",
        description="Invert IMAGE (.npy, .exr, .tif or .png; rows = pings, columns = slant-range "
        "bins from range 0; the renderer's EXR as is or another tool's one-channel or grey "
        "EXR, its display PNG mapped back to intensity; the per-ping profiles take one side, "
        "--side) into DIR/elevation.exr, "
        "reflectivity.exr, beam.exr (rows = pings, columns = ground-range cells, NaN = no "
        "estimate), ground.exr (the image in ground range at the recovered elevation), "
        "even.exr (evenly illuminated, seed Eq. 22), beam_profile.json, seabed.glb/.ply "
        "(textured mesh), preview_az*.png (four views) and DIR/inversion.json; an image of "
        "both sides fitted as one surface (--method surface, which auto picks for a speckled "
        "image) puts each side's into DIR/port/ and DIR/starboard/, with elevation_std.exr. "
        "An XTF file "
        "(.xtf) is inverted on both sides (or --side) with its bottom track as altitude, into "
        "DIR/port/ and DIR/starboard/ (with PNG quick-looks elevation.png, reflectivity.png), "
        "plus DIR/bottom_track.csv, DIR/waterfall.png and, with navigation, GeoTIFFs "
        "DIR/elevation.tif, reflectivity.tif and mosaic.tif and their quick-looks "
        "DIR/elevation.png (hillshaded), reflectivity.png and mosaic.png. Several XTF files "
        "(or one with --lines) are survey lines: each is inverted and all are gridded together "
        "into DIR/elevation.tif (+ elevation_std.tif with --method surface), reflectivity.tif, "
        "mosaic.tif and their quick-looks, each line's own products in DIR/line_N/.",
    )
    inv.add_argument("image", nargs="+", help="input image, or .xtf files (several: survey lines)")
    inv.add_argument(
        "--lines",
        action="store_true",
        help="XTF input: each file holds several survey lines, split at its turns (heading "
        "change over 10 m of track above 20 degrees; turn pings dropped), gridded together",
    )
    inv.add_argument(
        "--line-pings",
        metavar="A:B,C:D",
        help="XTF input: the survey lines of the one file given, as ping ranges (stop "
        "excluded), gridded together (instead of finding its turns)",
    )
    inv.add_argument("-o", "--output", required=True, metavar="DIR", help="output directory")
    inv.add_argument(
        "--range-bin",
        type=cli_positive(float),
        metavar="METRES",
        help="slant-range bin size (default: from the renderer's EXR or PNG metadata, "
        "sonar:range_bin_m)",
    )
    inv.add_argument(
        "--altitude",
        type=cli_positive(float),
        metavar="METRES",
        help="sonar altitude (default: first bottom return of each ping)",
    )
    inv.add_argument(
        "--side",
        choices=("port", "starboard"),
        help="which side to invert: of an EXR (default starboard), of a renderer's two-sided "
        "display PNG (required there: port is flipped back to near range first), of an XTF "
        "file (default both)",
    )
    inv.add_argument(
        "--method",
        choices=("auto", "profiles", "surface"),
        default="auto",
        help="auto (default): surface for a speckled image (every real recording; estimated "
        "looks below 40) where this machine can afford it, else profiles, saying which and why; "
        "profiles: one elevation profile per ping from one side; surface: one smooth surface "
        "fitted to every ping of both sides (where the image has both) with a speckle "
        "likelihood, into DIR/port/ and DIR/starboard/ with elevation_std.exr (and "
        "DIR/elevation_std.tif for XTF input); see docs/inversion.md",
    )
    inv.add_argument(
        "--max-iter",
        type=cli_positive(int),
        default=300,
        metavar="N",
        help="most iterations per pyramid level and start (default 300; fewer is faster, coarser)",
    )
    inv.add_argument(
        "--ping-spacing",
        type=cli_positive(float),
        metavar="METRES",
        help="along-track distance between pings, for the along-track slope (default: the "
        "image's own, ping_spacing_m in its header as render writes it, else the ground cell "
        "size)",
    )
    inv.add_argument(
        "--levels",
        type=cli_positive(int),
        metavar="N",
        help="profiles: pyramid levels (default 3)",
    )
    inv.add_argument(
        "--coarsen",
        type=cli_positive(int),
        default=1,
        metavar="N",
        help="--method surface: fit the images pooled N x N at the finest level (knots N times "
        "wider), about N^2 times faster; products still at every ping and bin (default 1; 2 "
        "scores as well on smooth speckled seabeds, blurs objects' edges)",
    )
    inv.add_argument(
        "--tol",
        type=cli_positive(float),
        help="profiles: stop a level when E falls by less than TOL x E in an iteration "
        "(default 1e-2)",
    )
    inv.add_argument(
        "--beam",
        metavar="PATH",
        help="calibrated mode: fix the beam profile from a beam_profile.json of an earlier run "
        "(--method surface: its shape, for every side; or an earlier run's output folder, "
        "one per side)",
    )
    inv.add_argument(
        "--flat-prior",
        type=cli_positive(float),
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
        type=cli_positive(float),
        metavar="METRES",
        help="profiles: relief about the flat seabed assumed on speckled images (default 0.1)",
    )
    inv.add_argument(
        "--slope-std",
        type=cli_positive(float),
        metavar="S",
        help="profiles: seabed slope (rise over run) assumed on speckled images (default 0.2)",
    )
    inv.add_argument(
        "--law",
        metavar="NAME",
        help="the seabed's scattering law the surface fit models: lambert (default) or a "
        "sediment (sand, mud, clay, gravel, rock or a TR 9407 name such as 'fine sand'), "
        "whose APL-UW law at the sonar's frequency is taken; picks --method surface",
    )
    inv.add_argument(
        "--frequency",
        type=cli_positive(float),
        metavar="KHZ",
        help="--law: the sonar's centre frequency in kHz (default: the image's header as "
        "render writes it, or the XTF file's channels)",
    )
    inv.add_argument("--no-mesh", action="store_true", help="skip seabed.glb and seabed.ply")
    inv.add_argument("--no-previews", action="store_true", help="skip the preview renders")
    inv.add_argument(
        "--pings", metavar="A:B", help="XTF input: ping range to invert (indices, stop excluded)"
    )
    add_xtf_frequency(inv)
    inv.add_argument(
        "--force",
        action="store_true",
        help="invert even when the job is estimated over an hour or over this machine's memory",
    )
    inv.add_argument("-q", "--quiet", action="store_true", help="no progress bar or summary")


def run(args: argparse.Namespace) -> int:
    """Run ``sonar-raster invert``: one side of an image, or both sides of an XTF file."""
    images = list(args.image) if isinstance(args.image, (list, tuple)) else [args.image]
    xtf = [Path(p).suffix.lower() == ".xtf" for p in images]
    _check_law(args)
    if args.beam:  # read before anything is estimated or loaded: a bad path is the first error
        from ..inversion.solver import load_beams

        load_beams(args.beam)
    if len(images) > 1 or args.lines or args.line_pings:
        if not all(xtf):
            raise SonarRasterError(
                "several inputs, --lines and --line-pings are for XTF files (survey lines); "
                "invert an image on its own"
            )
        args.image = images
        _check_output_dir(Path(args.output), ())
        return _invert_lines(args)
    args.image = images[0]
    if xtf[0]:
        _check_output_dir(Path(args.output), ("port", "starboard"))
        return _invert_xtf(args)
    _check_output_dir(Path(args.output), ())
    pixels = _check_image_size(Path(args.image), args.force)
    loaded = None  # the sides read to choose, handed on
    if args.method == "auto":
        loaded = _image_sides(args)
        _choose_method(args, [loaded[0]])
    if pixels:
        check_cost(pixels, f"inverting {Path(args.image).name}", "crop the image (fewer pings or "
                   "range bins) and invert it in parts", args)  # fmt: skip
    if args.method == "surface":
        return _invert_surface(args, loaded)
    _refuse_coarsen(args)
    _refuse_law(args)
    from ..inversion.method import SPECKLED_LOOKS
    from ..inversion.solver import BeamProfile, invert
    from ..inversion.write import energy_summary, write_products

    if loaded is None:
        image, side, range_bin = load_side(Path(args.image), args.side, args.range_bin)
    else:  # the side load_side took comes first
        (side, image), range_bin = next(iter(loaded[0].items())), loaded[1]
    beam = BeamProfile.load(args.beam) if args.beam else None
    result = invert(
        image,
        float(range_bin),
        altitude=args.altitude,
        ping_spacing=_ping_spacing(args),
        max_iter=args.max_iter,
        beam=beam,
        looks=args.looks,
        **_given(args, PROFILE_OPTIONS),  # the others at the solver's defaults
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
        looks = result.settings.get("looks")
        if looks is not None and looks < SPECKLED_LOOKS:  # --method profiles on speckle
            print(
                f"note: a speckled image (about {looks:.3g} looks): per-ping profiles recover "
                "little relief beyond the first return; --method surface fits one surface to "
                "every ping (docs/inversion.md)"
            )
        for path in written:
            print(f"wrote {path}")
    return 0


#: Options of the per-ping profiles alone (None unless given): ``--method auto`` takes them as
#: a choice of the profiles, ``--method surface`` refuses them.
PROFILE_OPTIONS = ("flat_prior", "levels", "tol", "relief_std", "slope_std")


def _given(args: argparse.Namespace, names: tuple[str, ...]) -> dict[str, Any]:
    """The options among ``names`` the user gave (not None)."""
    return {name: getattr(args, name) for name in names if getattr(args, name) is not None}


def _profile_flags(args: argparse.Namespace) -> list[str]:
    """The :data:`PROFILE_OPTIONS` given, as their flags."""
    return [f"--{name.replace('_', '-')}" for name in _given(args, PROFILE_OPTIONS)]


def _refuse_profile_options(args: argparse.Namespace) -> None:
    """Refuse :data:`PROFILE_OPTIONS` for the surface fit: they are the profiles' alone."""
    given = _profile_flags(args)
    if given:
        raise SonarRasterError(
            f"{', '.join(given)}: not used by --method surface (the profiles' options); "
            "leave them out, or give --method profiles"
        )


def _choose_method(args: argparse.Namespace, lines: list[dict[str, Any]]) -> None:
    """Resolve ``--method auto`` in ``args`` for these lines' sides, and say which and why.

    :data:`PROFILE_OPTIONS` and ``--looks none`` pick the profiles, ``--coarsen`` the surface
    fit; otherwise :func:`..inversion.method.choose_method` decides from the images' speckle
    and this machine's means.
    """
    from ..inversion.method import choose_method

    given = _profile_flags(args)
    if given or args.looks is None:
        args.method = "profiles"
        reason = f"method: profiles ({', '.join(given) or '--looks none'}: the profiles' options)"
    elif args.coarsen != 1:
        args.method = "surface"
        reason = "method: surface (--coarsen is the surface fit's)"
    elif _law_given(args):
        args.method = "surface"
        reason = "method: surface (--law is the surface fit's)"
    else:
        looks = args.looks if isinstance(args.looks, float) else None
        choice = choose_method(lines, looks, args.coarsen)
        args.method, reason = choice.method, choice.reason
    if not args.quiet:
        print(reason, flush=True)


def _image_sides(args: argparse.Namespace) -> tuple[dict[str, Any], float]:
    """The sides the surface fit takes (``--side``, else all; load_side's first) and the bin."""
    from ..inversion.write import exr_sides

    path = Path(args.image)
    image, got, range_bin = load_side(path, args.side, args.range_bin)
    sides = {got: image}
    other = "port" if got == "starboard" else "starboard"
    if args.side is None and other in exr_sides(path):  # the renderer's EXR holds both
        sides[other] = load_side(path, other, range_bin)[0]
    return sides, range_bin


def _ping_spacing(args: argparse.Namespace) -> float | None:
    """The pings' spacing: ``--ping-spacing``, else the image's own, or None (said).

    The image's own is ``ping_spacing_m`` in its header (as ``render`` writes it), else its
    effects' ``ping_spacing_m``.
    """
    if args.ping_spacing:
        return float(args.ping_spacing)
    from ..io.images import read_spec

    spec = read_spec(args.image)
    attrs = {} if spec is None else {a.name: a.value for a in spec.extra_attribs}
    for name in ("sonar_raster:ping_spacing_m", "sonar_raster:effects.ping_spacing_m"):
        value = _header_float(attrs, name)
        if value is not None and value > 0:
            return value
    if not args.quiet:
        print(
            f"note: {Path(args.image).name} does not say its ping spacing; the along-track "
            "geometry takes the ground cell (give --ping-spacing METRES)"
        )
    return None


def _xtf_sides(recording: tuple, side: str | None) -> dict[str, Any]:
    """A read XTF file's sides as intensities (samples squared), as ``invert_xtf`` takes them."""
    import numpy as np

    image = recording[0]
    chosen = (side,) if side else tuple(image.sides)
    return {s: np.square(image.sides[s].astype(np.float64)) for s in chosen if s in image.sides}


def _invert_surface(args: argparse.Namespace, loaded: tuple | None = None) -> int:
    """``invert --method surface``: both sides (or ``--side``) in one fit; ``loaded``: read."""
    import numpy as np

    from ..inversion.law import resolve_law
    from ..inversion.solver import load_beams
    from ..inversion.surface import invert_line
    from ..inversion.write import product_jobs
    from ..io.commit import commit

    _refuse_profile_options(args)
    sides, range_bin = loaded or _image_sides(args)
    pings = next(iter(sides.values())).shape[0]
    spacing = _ping_spacing(args) or float(range_bin)
    altitude = None if args.altitude is None else np.full(pings, float(args.altitude))
    results = invert_line(
        sides,
        float(range_bin),
        ping_spacing=spacing,
        altitude=altitude,
        looks="auto" if args.looks in ("auto", None) else args.looks,
        max_iter=args.max_iter,
        finest=args.coarsen,
        beam=load_beams(args.beam) if args.beam else None,
        law=resolve_law(_law(args), _image_frequency(Path(args.image))),
        progress=None if args.quiet else print,
    )
    out = Path(args.output)
    jobs = []
    for name, result in results.items():
        folder = out / name if len(results) > 1 else out
        jobs += product_jobs(
            result, folder, name, float(range_bin), mesh=not args.no_mesh,
            previews=not args.no_previews,
        )  # fmt: skip
    for folder in {p.parent for p, _ in jobs}:
        folder.mkdir(parents=True, exist_ok=True)
    written = commit(jobs)
    if not args.quiet:
        for written_path in written:
            print(f"wrote {written_path}")
    return 0


def load_side(path: Path, side: str | None, range_bin: float | None) -> tuple[Any, str, float]:
    """One side of an image to invert, its name and its range bin.

    A display PNG the renderer wrote (it carries ``sonar:display_*`` text chunks) has its
    display mapping undone (codes back to linear intensity, code 0 to 0) and its geometry read
    from ``sonar:range_bin_m``; a two-sided one holds port (flipped, on the left) and
    starboard side by side, so ``side`` is required and that half is taken, near range first.
    Other PNGs are taken as one side of linear grey levels. ``.npy`` and ``.exr`` go through
    :func:`sonar_raster.inversion.write.read_side`.

    Parameters
    ----------
    path : Path
        ``.png``, ``.exr`` or ``.npy`` image.
    side : str, optional
        "port" or "starboard"; default: starboard where there is one.
    range_bin : float, optional
        Slant-range bin, metres; default: the file's ``sonar:range_bin_m``.

    Returns
    -------
    image : ndarray, shape (pings, bins), float64
        Linear intensity, columns from range 0 outward.
    side : str
        The side taken.
    range_bin : float
        The range bin used, metres.
    """
    if path.suffix.lower() == ".png" and path.is_file():
        image, side, attrs = _read_png_side(path, side)
    else:
        from ..inversion.write import read_side

        image, side, attrs = read_side(path, side)
    found = _header_float(attrs, "sonar:range_bin_m")
    range_bin = range_bin or found
    if not range_bin:
        raise SonarRasterError(
            f"{path.name} does not say its range bin (no sonar:range_bin_m); give --range-bin"
        )
    _check_level(image, path)
    return image, side, float(range_bin)


def _check_level(image: Any, path: Path) -> None:
    """Refuse values at :data:`..image.NO_DATA_LEVEL` or above before the work.

    The products are float32 files, which overflow near them once the fit is done (the Python
    API keeps float64 and takes any level).
    """
    import numpy as np

    from ..image import NO_DATA_LEVEL

    a = np.asarray(image)
    if not np.issubdtype(a.dtype, np.number) or np.iscomplexobj(a) or a.size == 0:
        return  # the inversion's own checks say what is wrong
    top = float(np.nanmax(a)) if not np.all(np.isnan(a)) else 0.0
    if top >= NO_DATA_LEVEL:
        raise SonarRasterError(
            f"{path.name}: values reach {top:.3g}, a no-data marker rather than an echo (the "
            "float32 products would overflow); set such samples to 0 or rescale the image"
        )


def _header_float(attrs: dict, name: str) -> float | None:
    """A numeric header field (EXR numbers, PNG text), None when absent or not a number."""
    import math

    try:
        value = float(attrs[name])
    except (KeyError, TypeError, ValueError):
        return None
    return value if math.isfinite(value) and value > 0 else None


def _read_png_side(path: Path, side: str | None) -> tuple[Any, str, dict]:
    """One side of a PNG: a renderer's display image mapped back to intensity, or grey levels."""
    import numpy as np

    from ..io.images import read_pixels

    pixels, spec = read_pixels(path)
    attrs = {a.name: a.value for a in spec.extra_attribs}
    codes = pixels[:, :, 0].astype(np.float64)
    ref = _header_float(attrs, "sonar:display_ref_level_m2")
    span = _header_float(attrs, "sonar:display_dynamic_range_db")
    if ref is None or span is None:  # not ours: grey levels as linear intensity
        return codes, side or "starboard", attrs
    sides = [s for s in str(attrs.get("sonar:sides", "starboard")).split(",") if s]
    if len(sides) == 2 and side is None:
        raise SonarRasterError(
            f"{path.name} is a two-sided display image (port on the left, starboard on the "
            "right); pass --side port or --side starboard"
        )
    side = side or sides[0]
    if side not in sides:
        raise SonarRasterError(f"{path.name} has no {side} side (it has {', '.join(sides)})")
    if len(sides) == 2:
        half = codes.shape[1] // 2
        codes = codes[:, :half][:, ::-1] if side == "port" else codes[:, half:]
    elif side == "port":
        codes = codes[:, ::-1]
    # read_pixels gives codes / max_code in [0, 1]; code 0 is zero intensity (shadow, water).
    intensity = ref * 10.0 ** (span / 10.0 * (codes - 1.0))
    return np.where(codes > 0, intensity, 0.0), side, attrs


#: Peak bytes per input pixel of an inversion (float64 copies, pyramid, ground-range grids).
_PIXEL_BYTES = 64


#: Seconds per input pixel of an inversion at the default settings (3 levels, --max-iter 300):
#: ``sonar-raster invert`` of a 200 x 600 render took 5.7 s in ``tools/bench_costs.py`` and
#: 10.7-21.8 s as a command (start-up included), and of 150 pings of the OpenSidescan XTF
#: (2 x 153 600 samples, both sides, GeoTIFFs) 36.0 s, on 2 cores shared with three other
#: engineers (load 4-5): 4.7e-5 to 1.8e-4 s per pixel; upper-middle.
_PIXEL_SECONDS = 1e-4
#: Bytes per sample of an XTF file (16-bit samples; headers make the count an upper bound).
_XTF_SAMPLE_BYTES = 2


def check_cost(pixels: int, what: str, lower: str, args: argparse.Namespace) -> None:
    """Estimate an inversion's time and memory from its pixels; refuse it before the solve.

    Refused (one line naming what lowers it) when over an hour or over the machine's
    memory, unless ``--force``; the estimate is printed when it is over
    :data:`sonar_raster._progress.ANNOUNCE_S` and not ``--quiet``.

    Parameters
    ----------
    pixels : int
        Input pixels (pings x bins, both sides of an XTF file).
    what : str
        The job as the user would name it.
    lower : str
        What lowers it, naming options.
    args : argparse.Namespace
        ``force`` and ``quiet``.
    """
    from .._progress import ANNOUNCE_S, Estimate, announce, check_job
    from ..inversion import method

    # --method auto is checked as profiles (the cheaper) and not announced until it is resolved
    chosen = getattr(args, "method", "profiles")
    if chosen == "surface":
        estimate = method.surface_estimate(pixels, what, getattr(args, "coarsen", 1))
    else:
        estimate = Estimate(
            what, {"pixels": float(pixels)}, seconds=_PIXEL_SECONDS * pixels,
            memory=float(_PIXEL_BYTES) * pixels,
        )  # fmt: skip
    check_job(estimate, lower, force=args.force)
    if not args.quiet and estimate.seconds >= ANNOUNCE_S and chosen != "auto":
        announce(estimate)


def _check_image_size(path: Path, force: bool = False) -> int | None:
    """Read only the image's header; refuse an image too large to invert on this machine.

    Returns its pixels (None when the header cannot be read: the reader reports why).
    """
    import math

    from .._budget import check_memory

    shape: tuple[int, ...] | None = None
    if path.suffix.lower() == ".npy" and path.is_file():
        import numpy as np

        try:
            with open(path, "rb") as fh:
                version = np.lib.format.read_magic(fh)
                read = {
                    (1, 0): np.lib.format.read_array_header_1_0,
                    (2, 0): np.lib.format.read_array_header_2_0,
                }.get(version)
                if read is None:
                    return None
                shape = read(fh)[0]
        except (OSError, ValueError):
            return None  # read_side names what is wrong with the file
    elif path.is_file():
        from ..io.images import read_spec

        spec = read_spec(path)
        if spec is None:
            return None
        shape = (spec.height, spec.width)
    if shape is None:
        return None
    pixels = math.prod(int(n) for n in shape[:2])
    check_memory(
        pixels * _PIXEL_BYTES,
        f"inverting an image of {' x '.join(str(n) for n in shape)} pixels",
        "crop the image (fewer pings or range bins) and invert it in parts",
        force=force,
    )
    return pixels


def _check_output_dir(out: Path, subdirs: tuple[str, ...]) -> None:
    """Check, before any work, that ``out`` (and ``out/<sub>``) can be made and written."""
    from ..io.commit import check_can_create

    for folder in (out, *(out / sub for sub in subdirs)):
        if folder.exists() and not folder.is_dir():
            raise SonarRasterError(
                f"cannot write into {folder}: it exists and is not a directory; "
                "give a directory for -o"
            )
    existing = out
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if existing.exists() and not existing.is_dir():
        raise SonarRasterError(f"cannot make {out}: {existing} is not a directory")
    check_can_create(existing)


def _xtf_samples(path: Path) -> int | None:
    """Samples of an XTF file from its size (an upper bound), None if it cannot be read.

    16-bit samples are assumed and the headers are counted as samples.
    """
    try:
        size = path.stat().st_size
    except OSError:
        return None  # read_xtf names what is wrong with the file
    return max(1, size // _XTF_SAMPLE_BYTES)


def _parse_lines(text: str) -> list[tuple[int, int]]:
    """``--line-pings``: ranges ``A:B,C:D`` (stop excluded)."""
    ranges = []
    for part in text.split(","):
        a, sep, b = part.strip().partition(":")
        try:
            lo, hi = int(a), int(b)
        except ValueError:
            lo = hi = -1
        if not sep or lo < 0 or hi <= lo:
            raise SonarRasterError(
                f"--line-pings: {part!r} is not a ping range A:B with 0 <= A < B; e.g. "
                "--line-pings 0:800,840:1650"
            )
        ranges.append((lo, hi))
    return ranges


def _invert_lines(args: argparse.Namespace) -> int:
    """``sonar-raster invert A.xtf B.xtf ... -o DIR`` (or one file ``--lines``): survey lines."""
    from ..inversion import lines as ml
    from ..inversion.solver import BeamProfile
    from ..io.commit import commit

    out = Path(args.output)
    if args.lines and args.line_pings:
        raise SonarRasterError("give --lines (find the turns) or --line-pings A:B,C:D, not both")
    split: bool | list[tuple[int, int]] = (
        _parse_lines(args.line_pings) if args.line_pings else bool(args.lines)
    )
    if args.pings and len(args.image) > 1:
        raise SonarRasterError("--pings applies to one file; give the lines' files whole")
    if args.side:
        raise SonarRasterError("--side is for one file; survey lines are inverted on both sides")
    sizes = [_xtf_samples(Path(p)) for p in args.image]
    # sized from the files before reading them, unless pings are chosen (then once read)
    early = not args.pings and not args.line_pings and all(sizes)
    if early:
        files = f"{len(args.image)} XTF file" + ("s" if len(args.image) > 1 else "")
        check_cost(
            sum(s for s in sizes if s),
            f"inverting {files}",
            "invert fewer files or pings at a time",
            args,
        )
    lines, notes = ml.read_lines(
        args.image,
        split=split,
        pings=parse_pings(args.pings),
        frequency=parse_xtf_frequency(args.xtf_frequency),
    )
    if not args.quiet:
        for note in notes or [ml.describe_lines(lines)]:
            print(note)
    if len(lines) < 2:
        raise SonarRasterError(
            f"{ml.describe_lines(lines)}: several lines need two or more; invert a single "
            "line without --lines or --line-pings"
        )
    auto = args.method == "auto"
    if auto:
        _choose_method(args, [line.sides for line in lines])
    if auto or not early:  # the chosen method's cost, on the pings read
        pixels = sum(v.size for line in lines for v in line.sides.values())
        check_cost(pixels, f"inverting {len(lines)} lines", "invert fewer lines or pings "
                   "at a time", args)  # fmt: skip
    options = _line_options(args, BeamProfile)
    results = ml.invert_lines(
        lines, method=args.method, altitude=args.altitude, progress=not args.quiet, **options
    )
    datum = ml.vertical_datum(lines)
    samples = [ml.line_samples(line, res, datum) for line, res in zip(lines, results, strict=True)]
    gridded = ml.grid_lines(
        samples, ml.default_pixel(lines, results), lines[0].crs, align=datum == "first line"
    )
    jobs = _line_jobs(args, out, lines, results, gridded, datum)
    made = [
        d for d in sorted({p.parent for p, _ in jobs}, key=lambda p: len(p.parts)) if not d.exists()
    ]
    for folder in made:
        folder.mkdir(parents=True, exist_ok=True)
    try:
        written = commit(jobs)  # every line's products and the combined ones, or none
    except BaseException:
        for folder in reversed(made):
            if folder.is_dir() and not any(folder.iterdir()):
                folder.rmdir()
        raise
    if not args.quiet:
        crs = gridded.combined.crs or "none (file coordinates)"
        print(f"elevation datum: {datum}; pixel {gridded.combined.pixel:.3f} m; CRS {crs}")
        if datum == "first line":
            shifts = ", ".join(f"{o:+.3f}" for o in gridded.offsets[1:])
            print(f"line elevation offsets to line 1 (from overlaps), m: {shifts}")
        for path in written:
            print(f"wrote {path}")
    return 0


def _line_options(args: argparse.Namespace, beam_profile: Any) -> dict[str, Any]:
    """The inversion options of an XTF line.

    Profiles: the solver's; surface: looks, max_iter and the calibrated beam of ``--beam``.
    """
    if args.method == "surface":
        from ..inversion.solver import load_beams

        _refuse_profile_options(args)
        beam = load_beams(args.beam) if args.beam else None
        return {
            "max_iter": args.max_iter,
            "looks": args.looks,
            "beam": beam,
            "finest": args.coarsen,
            "law": _law(args),
        }
    _refuse_coarsen(args)
    _refuse_law(args)
    options: dict[str, Any] = {"max_iter": args.max_iter, "looks": args.looks}
    options.update(_given(args, PROFILE_OPTIONS))
    if args.beam:
        options["beam"] = beam_profile.load(args.beam)
    return options


def _law_given(args: argparse.Namespace) -> bool:
    """Whether ``--law`` names a law other than Lambert's (an unknown name is refused first)."""
    from ..inversion.law import LAMBERT

    return args.law is not None and args.law.strip().lower() != LAMBERT


def _check_law(args: argparse.Namespace) -> None:
    """Refuse an unknown ``--law`` and a ``--frequency`` without one, before any work."""
    from ..inversion.law import law_index

    if args.frequency is not None and not _law_given(args):
        raise SonarRasterError("--frequency is for --law (a sediment's law); leave it out")
    if args.law is not None:
        law_index(args.law)


def _law(args: argparse.Namespace) -> Any:
    """``--law`` for the fit: None (Lambert), a law at ``--frequency``, or the name alone.

    A name alone is taken at each line's recorded frequency (:func:`..inversion.law.resolve_law`).
    """
    from ..inversion.law import scattering_law

    if not _law_given(args):
        return None
    if args.frequency is not None:
        return scattering_law(args.law, args.frequency * 1e3)
    return args.law


def _image_frequency(path: Path) -> float | None:
    """The sonar frequency an image's header records (``sonar:frequency_hz``), Hz, or None."""
    from ..io.images import read_spec

    spec = None if path.suffix.lower() == ".npy" else read_spec(path)
    attrs = {} if spec is None else {a.name: a.value for a in spec.extra_attribs}
    return _header_float(attrs, "sonar:frequency_hz")


def _refuse_law(args: argparse.Namespace) -> None:
    """``--law`` is the surface fit's; the per-ping profiles model Lambert's law."""
    if _law_given(args):
        raise SonarRasterError(
            "--law is for --method surface; the per-ping profiles model Lambert's law"
        )


def _refuse_coarsen(args: argparse.Namespace) -> None:
    """``--coarsen`` is the surface fit's; the profile method has ``--levels``."""
    if args.coarsen != 1:
        raise SonarRasterError(
            "--coarsen is for --method surface; the profile method's pyramid is --levels"
        )


def _line_jobs(args, out: Path, lines, results, gridded, datum: str) -> list:
    """Every file of a multi-line inversion: combined GeoTIFFs and PNGs, then per line."""
    from ..inversion import lines as ml
    from ..inversion.track_io import write_track_csv
    from ..inversion.write import product_jobs
    from ..inversion.xtf import geotiff_jobs
    from ..io.commit import write_json

    descriptions = ml.geotiff_descriptions(datum)
    jobs = geotiff_jobs(out, gridded.combined, descriptions)
    jobs += ml.quicklook_jobs(out, gridded.combined)
    for k, (line, res, raster) in enumerate(zip(lines, results, gridded.lines, strict=True)):
        folder = out / f"line_{k + 1}"
        jobs += geotiff_jobs(folder, raster, descriptions)
        csv = partial(
            write_track_csv,
            track=line.track,
            recorded=line.recorded_altitude,
            pings=[int(p) for p in line.pings],
        )
        doc = {
            "source": line.source,
            "pings": [int(line.pings[0]), int(line.pings[-1]) + 1],
            "datum": datum,
            "elevation_offset_m": gridded.offsets[k],
            "method": args.method,
            "ping_spacing_m": line.ping_spacing,
        }
        jobs += [
            (folder / "bottom_track.csv", csv),
            (folder / "line.json", partial(write_json, doc=doc)),
        ]
        for side, inv in res.items():
            jobs += product_jobs(
                inv,
                folder / side,
                side,
                line.range_bin,
                mesh=not args.no_mesh,
                previews=not args.no_previews,
                quicklooks=True,
            )
    return jobs


def _invert_xtf(args: argparse.Namespace) -> int:
    """``sonar-raster invert FILE.xtf -o DIR``: both sides, bottom-tracked, with GeoTIFFs."""
    from ..inversion.solver import BeamProfile
    from ..inversion.track_io import summary_lines, write_track_csv
    from ..inversion.write import energy_summary, product_jobs
    from ..inversion.xtf import georeference, geotiff_jobs, invert_xtf, quicklook_jobs
    from ..io.commit import commit

    out = Path(args.output)
    frequency = parse_xtf_frequency(args.xtf_frequency)
    samples = None if args.pings else _xtf_samples(Path(args.image))  # a crop: not sized
    if samples:
        check_cost(samples, f"inverting {Path(args.image).name} (samples from its size)",
                   "invert fewer pings at a time (--pings A:B)", args)  # fmt: skip
    recording = None
    if args.method == "auto":  # read here to choose, and handed on
        from ..io.xtf import read_xtf

        recording = read_xtf(args.image, parse_pings(args.pings), frequency)
        sides = _xtf_sides(recording, args.side)
        _choose_method(args, [sides])
        pixels = sum(v.size for v in sides.values())  # the chosen method's estimate, said
        check_cost(pixels, f"inverting {Path(args.image).name}", "invert fewer pings at a "
                   "time (--pings A:B)", args)  # fmt: skip
    result = invert_xtf(
        args.image,
        pings=parse_pings(args.pings),
        sides=(args.side,) if args.side else None,
        altitude=args.altitude,
        ping_spacing=args.ping_spacing,
        progress=not args.quiet,
        method=args.method,
        recording=recording,
        frequency=frequency,
        **_line_options(args, BeamProfile),
    )
    image, nav = result.image, result.navigation
    raster = georeference(result) if nav.valid.any() else None
    csv = partial(
        write_track_csv,
        track=result.track,
        recorded=nav.altitude,
        pings=image.metadata.get("ping_indices"),
    )
    extra: list[tuple[Path, Callable[[Path], None]]] = [(out / "bottom_track.csv", csv)]
    if raster is not None:
        extra += geotiff_jobs(out, raster)
    extra += quicklook_jobs(out, result, raster)  # PNGs with colour and scale bars
    jobs = []
    for side, inv in result.sides.items():
        jobs += product_jobs(
            inv, out / side, side, image.sonar.range_bin,
            mesh=not args.no_mesh, previews=not args.no_previews, quicklooks=True,
        )  # fmt: skip
    made = [d for d in [out, *(out / side for side in result.sides)] if not d.exists()]
    for folder in made:
        folder.mkdir(parents=True, exist_ok=True)
    try:
        written = commit(jobs + extra)  # every side's products and the track/GeoTIFFs, or none
    except BaseException:
        for folder in reversed(made):  # leave no empty folders behind either
            if folder.is_dir() and not any(folder.iterdir()):
                folder.rmdir()
        raise
    if not args.quiet:
        for line in summary_lines(result.track, nav.altitude, image.sonar.range_bin):
            print(line)
        for side, inv in result.sides.items():
            for line in energy_summary(inv) if args.method == "profiles" else []:
                print(f"{side}: {line}")
        if raster is None:
            print("no navigation in the file: no GeoTIFF written")
        else:
            print(f"GeoTIFFs: CRS {raster.crs or 'none (file coordinates)'}, pixel "
                  f"{raster.pixel:.3f} m")  # fmt: skip
        for path in written:
            print(f"wrote {path}")
    return 0
