"""Files of the ``invert`` command: the input image and the R, Φ, Z products."""

from __future__ import annotations

import os
from collections.abc import Callable
from functools import partial
from pathlib import Path

import numpy as np

from ..errors import SonarRasterError
from .solver import Inversion

INPUT_SUFFIXES = (".npy", ".exr", ".png", ".tif", ".tiff")


def read_side(path: Path, side: str | None) -> tuple[np.ndarray, str, dict]:
    """One side of an image file as float64 (pings, bins), the side's name and header fields.

    ``.npy`` and ``.png`` hold one side (PNG grey levels are taken as linear intensity);
    ``.exr`` is the renderer's output (``port``/``starboard`` channels), or one side from
    another tool (one channel of any name, or equal R, G, B); its ``sonar:range_bin_m`` is
    given back in the header dict. ``.tif`` is one side too (float values as they are,
    integers scaled to [0, 1]).
    """
    suffix = path.suffix.lower()
    if suffix not in INPUT_SUFFIXES:
        raise SonarRasterError(f"{path}: unknown image type; use .npy, .exr, .png or .tif")
    if not path.is_file():
        raise SonarRasterError(f"{path}: no such file")
    if suffix == ".exr":
        from ..io.images import read_pixels
        from ..sonar import SIDES

        pixels, spec = read_pixels(path)
        names = list(spec.channelnames)
        attrs = {attr.name: attr.value for attr in spec.extra_attribs}
        if not (names and all(n in SIDES for n in names)):  # another tool's EXR: one side
            return _one_side(pixels, names, path), side or "starboard", attrs
        sides = {n: pixels[:, :, i] for i, n in enumerate(names)}
        name = side or ("starboard" if "starboard" in sides else next(iter(sides)))
        if name not in sides:
            raise SonarRasterError(f"{path}: no {name} channel (has {', '.join(sides)})")
        return sides[name].astype(np.float64), name, attrs
    if suffix in (".tif", ".tiff"):  # another tool's image: float values as they are
        from ..io.images import read_pixels

        pixels, spec = read_pixels(path)
        return _one_side(pixels, list(spec.channelnames), path), side or "starboard", {}
    if suffix == ".npy":
        try:
            data = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise SonarRasterError(f"cannot read {path}: {exc}") from None
    else:
        data = _read_png(path)
    if data.ndim != 2:
        raise SonarRasterError(f"{path}: expected a 2-D image (pings x bins), got {data.shape}")
    if np.iscomplexobj(data):
        raise SonarRasterError(
            f"{path}: complex values (amplitudes?); give intensities, e.g. np.abs(a) ** 2"
        )
    if not (np.issubdtype(data.dtype, np.number) or data.dtype == np.bool_):
        raise SonarRasterError(f"{path}: expected numbers, got dtype {data.dtype}")
    return np.asarray(data, dtype=np.float64), side or "starboard", {}


def exr_sides(path: Path) -> list[str]:
    """The sides ("port", "starboard") an EXR holds as the renderer writes them; [] otherwise."""
    from ..io.images import read_spec
    from ..sonar import SIDES

    spec = read_spec(path) if path.suffix.lower() == ".exr" else None
    names = list(spec.channelnames) if spec is not None else []
    return names if names and all(n in SIDES for n in names) else []


def _one_side(pixels: np.ndarray, names: list[str], path: Path) -> np.ndarray:
    """The one side an EXR without port/starboard channels, or a TIFF, holds.

    Its only channel, or its R, G and B when they are equal (a grey image; alpha ignored).
    """
    if len(names) == 1:
        return pixels[:, :, 0].astype(np.float64)
    colour = [names.index(c) for c in ("R", "G", "B") if c in names]
    if len(colour) == 3 and all(
        np.array_equal(pixels[:, :, colour[0]], pixels[:, :, k], equal_nan=True) for k in colour
    ):
        return pixels[:, :, colour[0]].astype(np.float64)
    raise SonarRasterError(
        f"{path}: channels {', '.join(names)} are not one side: give the renderer's port/"
        "starboard EXR, a one-channel or grey EXR or TIFF, or the side as .npy"
    )


def _read_png(path: Path) -> np.ndarray:
    from ..io.images import read_pixels

    return read_pixels(path)[0][:, :, 0].astype(np.float64)


def _write_map(tmp: Path, values: np.ndarray, name: str) -> None:
    import OpenImageIO as oiio

    from ..io.commit import write_oiio

    pixels = np.ascontiguousarray(values, dtype=np.float32)[:, :, np.newaxis]
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], 1, oiio.FLOAT)
    spec.channelnames = (name,)
    spec.attribute("compression", "zip")
    write_oiio(tmp, pixels, spec)


def summary(inv: Inversion, side: str, range_bin: float, extra: dict | None = None) -> dict:
    """The ``inversion.json`` document (``extra`` entries are added at the top level)."""
    doc = {
        "side": side,
        "range_bin_m": range_bin,
        "ground_axis": {
            "first_centre_m": float(inv.x[0]),
            "spacing_m": float(inv.x[1] - inv.x[0]),
            "cells": len(inv.x),
        },
        "ping_spacing_m": float(inv.ping_spacing) if np.isfinite(inv.ping_spacing) else None,
        "altitude_m": [float(a) for a in inv.altitude],
        "energy_per_iteration": [[float(e) for e in level] for level in inv.energies],
        "iterations": inv.iterations,
        "iterations_per_level": [len(level) - 1 for level in inv.energies],
        "levels": [_level_doc(run) for run in inv.runs],
        "settings": dict(inv.settings),
        "elevation": "metres relative to the transducer, negative below; NaN = no estimate",
    }
    doc.update(extra or {})
    return doc


def _level_doc(run: dict) -> dict:
    if "starts" not in run:  # the surface fit: one start per level
        return {k: float(v) if isinstance(v, np.floating) else v for k, v in run.items()}
    starts = [{**s, "energy": float(s["energy"])} for s in run["starts"]]
    return {**run, "starts": starts}


PRODUCTS = {
    "elevation.exr": "Z, metres relative to the transducer, negative below",
    "reflectivity.exr": "R",
    "beam.exr": "Φ per cell (intensity per metre of ground range per unit R)",
    "ground.exr": "the image in ground range at the recovered Z, intensity per metre of ground "
    "range: I(ρ)/Δr · x/ρ with ρ = sqrt(x² + Z²)",
    "even.exr": "evenly illuminated ground-range image (seed Eq. 22): ground / (Φ cos⟨θ⟩), "
    "cos⟨θ⟩ = −Z / sqrt(x² + Z²); equals R on a level seabed",
    "elevation_std.exr": "standard deviation of Z per cell, metres (Laplace approximation; "
    "surface fit only)",
    "beam_profile.json": "Φ against depression angle, for calibrated mode (--beam)",
    "seabed.glb": "textured mesh: X across track (+ starboard), Y along track, Z elevation, metres",
    "seabed.ply": "the same mesh with vertex colours",
    "elevation.png": "quick-look of elevation.exr: hillshaded, coloured by Z, pings downward",
    "reflectivity.png": "quick-look of reflectivity.exr, pings downward",
}


def write_products(
    inv: Inversion,
    directory: str | os.PathLike,
    side: str,
    range_bin: float,
    *,
    mesh: bool = True,
    previews: bool = True,
    preview_size: tuple[int, int] = (640, 480),
    backend: str | None = None,
) -> list[Path]:
    """Write the inversion's products into ``directory`` atomically (temp names, then renames).

    Always ``elevation.exr``, ``reflectivity.exr``, ``beam.exr``, ``beam_profile.json`` and
    ``inversion.json``; ``ground.exr`` and ``even.exr`` when the result carries them; with
    ``mesh`` ``seabed.glb`` and ``seabed.ply``; with ``previews`` four
    ``preview_az{045,135,225,315}.png`` renders of the mesh (``preview_size`` = width, height
    in pixels; GL ``backend`` as :func:`.gl.create_context`). Every file is
    made before any is renamed into place, so a failure leaves no product behind.

    Parameters
    ----------
    inv : Inversion
        The result of :func:`~sonar_raster.invert`.
    directory : str or path-like
        Output folder; created if missing.
    side : {"port", "starboard"}
        The side that was inverted (recorded in ``inversion.json``).
    range_bin : float
        Slant-range bin of the inverted image, metres (recorded in ``inversion.json``).

    Returns
    -------
    list of Path
        The files written.
    """
    from .._checks import integer, positive
    from ..image import SIDE_NAMES
    from ..io.commit import commit

    if side not in SIDE_NAMES:
        raise SonarRasterError(f"side must be 'port' or 'starboard', got {side!r}")
    positive("range_bin (metres)", range_bin)
    if previews:
        for n in preview_size:
            integer("preview_size (pixels)", n)
    directory = Path(directory)
    if directory.exists() and not directory.is_dir():
        raise SonarRasterError(f"{directory} is a file; give a folder for the products")
    jobs = product_jobs(
        inv, directory, side, range_bin, mesh=mesh, previews=previews,
        preview_size=preview_size, backend=backend,
    )  # fmt: skip
    directory.mkdir(parents=True, exist_ok=True)
    return commit(jobs)


def product_jobs(
    inv: Inversion,
    directory: Path,
    side: str,
    range_bin: float,
    *,
    mesh: bool = True,
    previews: bool = True,
    preview_size: tuple[int, int] = (640, 480),
    backend: str | None = None,
    quicklooks: bool = False,
) -> list[tuple[Path, Callable[[Path], None]]]:
    """The (path, writer) jobs of :func:`write_products`; nothing is written.

    For a caller that commits them together with other files in one
    :func:`sonar_raster.io.commit.commit`.

    Parameters
    ----------
    inv, directory, side, range_bin, mesh, previews, preview_size, backend
        As for :func:`write_products`.
    quicklooks : bool
        Also PNG quick-looks ``elevation.png`` (hillshaded) and ``reflectivity.png`` of the
        maps, with colour and scale bars (:mod:`sonar_raster.inversion.quicklook`).
    """
    from ..io.commit import write_json

    maps = {"elevation": inv.elevation, "reflectivity": inv.reflectivity, "beam": inv.beam}
    if inv.reprojected is not None:
        maps["ground"] = inv.reprojected
    if inv.even is not None:
        maps["even"] = inv.even
    if inv.elevation_std is not None:
        maps["elevation_std"] = inv.elevation_std
    jobs: list[tuple[Path, Callable[[Path], None]]] = [
        (directory / f"{k}.exr", partial(_write_map, values=v, name=k)) for k, v in maps.items()
    ]
    jobs.append((directory / "beam_profile.json", inv.profile.save))
    if quicklooks:
        jobs += _quicklook_jobs(inv, directory, side)
    extra: dict = {}
    if mesh or previews:
        extra.update(_mesh_jobs(inv, directory, side, jobs, mesh, previews, preview_size, backend))
    extra["products"] = {
        path.name: PRODUCTS.get(path.name, "preview render of seabed.glb") for path, _ in jobs
    }
    jobs.append(
        (
            directory / "inversion.json",
            partial(write_json, doc=summary(inv, side, range_bin, extra)),
        )
    )
    return jobs


def _quicklook_jobs(
    inv: Inversion, directory: Path, side: str
) -> list[tuple[Path, Callable[[Path], None]]]:
    """Hillshaded elevation and reflectivity quick-looks of one side, rows = pings."""
    from . import quicklook as ql

    dx = float(inv.x[1] - inv.x[0])
    dy = float(inv.ping_spacing) if np.isfinite(inv.ping_spacing) else None
    return [
        (directory / "elevation.png", partial(ql.hillshade_png, elevation=inv.elevation, cell_m=dx,
                                              along_m=dy, title=f"{side}: elevation Z",
                                              label="Z, m (re the transducer)", north_up=False)),
        (directory / "reflectivity.png", partial(ql.reflectivity_png, values=inv.reflectivity,
                                                 cell_m=dx, along_m=dy,
                                                 title=f"{side}: reflectivity", north_up=False)),
    ]  # fmt: skip


def _mesh_jobs(inv, directory, side, jobs, mesh, previews, size, backend) -> dict:
    """Append the mesh and preview writers to ``jobs``; return their inversion.json entries."""
    from ..meshio.export import export, seabed_mesh
    from ..rendering.gl.preview import AZIMUTHS, ELEVATION, exaggeration, render_previews

    texture = inv.even if inv.even is not None else inv.reflectivity
    dy = inv.ping_spacing if np.isfinite(inv.ping_spacing) else float(inv.x[1] - inv.x[0])
    doc: dict = {"texture": "even.exr" if inv.even is not None else "reflectivity.exr"}
    coloured = seabed_mesh(inv.x, inv.elevation, texture, dy, side, textured=False)
    doc["mesh"] = {"vertices": len(coloured.vertices), "faces": len(coloured.faces)}
    if mesh:
        textured = seabed_mesh(inv.x, inv.elevation, texture, dy, side, textured=True)
        for name, mesh_obj, kind in (
            ("seabed.glb", textured, "glb"),
            ("seabed.ply", coloured, "ply"),
        ):
            jobs.append((directory / name, partial(_write_bytes, data=export(mesh_obj, kind))))
    if previews:
        images = render_previews(coloured, size, backend)
        for az, image in zip(AZIMUTHS, images, strict=True):
            jobs.append(
                (directory / f"preview_az{az:03.0f}.png", partial(_write_png, pixels=image))
            )
        doc["previews"] = {
            "renderer": "moderngl (EGL, else OSMesa, via sonar_raster.rendering.gl.context)",
            "azimuth_deg": list(AZIMUTHS),
            "elevation_deg": ELEVATION,
            "vertical_exaggeration": exaggeration(np.asarray(coloured.vertices)),
            "size_px": list(size),
        }
    return doc


def _write_bytes(tmp: Path, data: bytes) -> None:
    tmp.write_bytes(data)


def _write_png(tmp: Path, pixels: np.ndarray) -> None:
    import OpenImageIO as oiio

    from ..io.commit import write_oiio

    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], oiio.UINT8)
    write_oiio(tmp, np.ascontiguousarray(pixels, dtype=np.uint8), spec)


def energy_summary(inv: Inversion) -> list[str]:
    """One line per level: iterations and E of every start, which start was kept, E trend."""
    lines = []
    for k, (energies, run) in enumerate(zip(inv.energies, inv.runs, strict=False)):
        starts = ", ".join(
            f"{s['start']}: {s['iterations']} it ({s['stopped']}), E {s['energy']:.4g}"
            for s in run["starts"]
        )
        lines.append(
            f"level {k + 1} (1/{run['factor']} res.): E {energies[0]:.4g} -> {energies[-1]:.4g}; "
            f"kept {run['kept']}; {starts}"
        )
    return lines
