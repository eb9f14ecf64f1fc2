"""Files of the ``invert`` command: the input image and the R, Φ, Z products."""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from pathlib import Path

import numpy as np

from .errors import SonarRasterError
from .invert import Inversion

INPUT_SUFFIXES = (".npy", ".exr", ".png")


def read_side(path: Path, side: str | None) -> tuple[np.ndarray, str, dict]:
    """One side of an image file as float64 (pings, bins), the side's name and header fields.

    ``.npy`` and ``.png`` hold one side (PNG grey levels are taken as linear intensity);
    ``.exr`` is the renderer's output, its ``sonar:range_bin_m`` given back in the header dict.
    """
    suffix = path.suffix.lower()
    if suffix not in INPUT_SUFFIXES:
        raise SonarRasterError(f"{path}: unknown image type; use .npy, .exr or .png")
    if not path.is_file():
        raise SonarRasterError(f"{path}: no such file")
    if suffix == ".exr":
        from .io import read_exr

        sides, attrs = read_exr(path)
        name = side or ("starboard" if "starboard" in sides else next(iter(sides)))
        if name not in sides:
            raise SonarRasterError(f"{path}: no {name} channel (has {', '.join(sides)})")
        return sides[name].astype(np.float64), name, attrs
    if suffix == ".npy":
        try:
            data = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise SonarRasterError(f"cannot read {path}: {exc}") from None
    else:
        data = _read_png(path)
    if data.ndim != 2:
        raise SonarRasterError(f"{path}: expected a 2-D image (pings x bins), got {data.shape}")
    return np.asarray(data, dtype=np.float64), side or "starboard", {}


def _read_png(path: Path) -> np.ndarray:
    from .io import read_pixels

    return read_pixels(path)[0][:, :, 0].astype(np.float64)


def _write_map(tmp: Path, values: np.ndarray, name: str) -> None:
    import OpenImageIO as oiio

    from .io import _write_oiio

    pixels = np.ascontiguousarray(values, dtype=np.float32)[:, :, np.newaxis]
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], 1, oiio.FLOAT)
    spec.channelnames = (name,)
    spec.attribute("compression", "zip")
    _write_oiio(tmp, pixels, spec)


def summary(inv: Inversion, side: str, range_bin: float) -> dict:
    """The ``inversion.json`` document."""
    return {
        "side": side,
        "range_bin_m": range_bin,
        "ground_axis": {
            "first_centre_m": float(inv.x[0]),
            "spacing_m": float(inv.x[1] - inv.x[0]),
            "cells": len(inv.x),
        },
        "altitude_m": [float(a) for a in inv.altitude],
        "energy_per_iteration": [[float(e) for e in level] for level in inv.energies],
        "iterations": inv.iterations,
        "elevation": "metres relative to the transducer, negative below; NaN = no estimate",
    }


def write_products(inv: Inversion, directory: Path, side: str, range_bin: float) -> list[Path]:
    """Write elevation.exr, reflectivity.exr, beam.exr and inversion.json atomically."""
    from .io import _commit, _write_json

    directory.mkdir(parents=True, exist_ok=True)
    maps = {"elevation": inv.elevation, "reflectivity": inv.reflectivity, "beam": inv.beam}
    jobs: list[tuple[Path, Callable[[Path], None]]] = [
        (directory / f"{k}.exr", partial(_write_map, values=v, name=k)) for k, v in maps.items()
    ]
    jobs.append(
        (directory / "inversion.json", partial(_write_json, doc=summary(inv, side, range_bin)))
    )
    return _commit(jobs)
