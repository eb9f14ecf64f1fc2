"""The surface fit's results as the package's per-side :class:`Inversion` products."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from .layout import Line
from .solve import EDGE_BINS, SurfaceFit, fit_lines

if TYPE_CHECKING:
    from ..law import ScatteringLaw
    from ..solver import BeamProfile, Inversion


def invert_lines(
    lines: Sequence[Line],
    *,
    looks: float | str = "auto",
    levels: int = 2,
    finest: int = 1,
    max_iter: int = 150,
    uncertainty: bool = True,
    beam: BeamProfile | Mapping[str, BeamProfile] | None = None,
    progress=None,
) -> list[dict[str, Inversion]]:
    """One surface fitted to every side of every line, returned per line and side.

    The per-side results carry the same products as :func:`sonar_raster.invert`'s (ground-range,
    reprojected and evenly lit images), so :func:`sonar_raster.write_products` writes them.

    Parameters
    ----------
    lines : sequence of Line
        The lines (:class:`.layout.Line`).
    looks, levels, finest, max_iter, uncertainty, beam, progress
        As for :func:`.solve.fit_lines`.

    Returns
    -------
    list of dict of str to Inversion
        Per line, per side.
    """
    fits = fit_lines(
        lines,
        looks=looks,
        levels=levels,
        finest=finest,
        max_iter=max_iter,
        uncertainty=uncertainty,
        beam=beam,
        progress=progress,
    )
    given = [line.altitude is not None for line in lines]
    options = {
        "levels": levels,
        "finest": finest,
        "max_iter": max_iter,
        "calibrated": beam is not None,
    }
    return [
        {
            name: _inversion(fit, name, image, line.range_bin, line, options, known)
            for name, image in line.sides.items()
        }
        for line, fit, known in zip(lines, fits, given, strict=True)
    ]


def invert_line(
    sides: Mapping[str, np.ndarray],
    range_bin: float,
    *,
    ping_spacing: float,
    altitude: np.ndarray | None = None,
    law: ScatteringLaw | None = None,
    **options,
) -> dict[str, Inversion]:
    """:func:`invert_lines` of one straight line, pings ``ping_spacing`` apart.

    Parameters
    ----------
    sides : mapping of str to ndarray, each shape (pings, bins)
        ``"port"`` and/or ``"starboard"`` linear intensity, bins from range 0.
    range_bin : float
        Slant-range bin, metres.
    ping_spacing : float
        Along-track distance between pings, metres.
    altitude : ndarray, shape (pings,), optional
        Altitude per ping (default: the first bottom return).
    law : ScatteringLaw, optional
        The seabed's scattering law (default Lambert's; :func:`..law.scattering_law`).
    **options
        As for :func:`invert_lines`.

    Returns
    -------
    dict of str to Inversion
    """
    line = Line.straight(sides, range_bin, ping_spacing, altitude, law)
    return invert_lines([line], **options)[0]


def _inversion(
    fit: SurfaceFit,
    name: str,
    image: np.ndarray,
    range_bin: float,
    line: Line,
    options: dict,
    altitude_given: bool,
) -> Inversion:
    from ..ground import slant_to_ground
    from ..products import even_illumination, reproject
    from ..solver import BeamProfile, Inversion

    slant = np.asarray(image, np.float64)
    alt = fit.altitude
    ground, _ = slant_to_ground(slant, range_bin, alt, fit.x)
    # the edge in the finest level's bins: its knots are ``finest`` times wider
    reach = (slant.shape[1] - EDGE_BINS * int(options.get("finest", 1))) * range_bin
    known = np.sqrt(fit.x[None, :] ** 2 + alt[:, None] ** 2) < reach
    refl, beam, elev = (
        np.where(known, v[name], np.nan) for v in (fit.reflectivity, fit.beam, fit.elevation)
    )
    depression, gain = fit.profile[name]
    settings = {
        "method": "surface",
        **options,
        "looks": fit.looks[name],
        "altitude": "given" if altitude_given else "first return",
        "law": "lambert" if line.law is None else line.law.name,
    }
    inv = Inversion(
        fit.x,
        alt,
        ground,
        refl,
        beam,
        elev,
        BeamProfile(depression, gain),
        energies=[[e] for e in fit.energies],
        ping_spacing=line.spacing,
        runs=[
            {"evaluations": n, "energy": float(e)}
            for n, e in zip(fit.evaluations, fit.energies, strict=True)
        ],
        settings=settings,
    )
    reprojected = reproject(slant, range_bin, fit.x, inv.elevation)
    even = even_illumination(reprojected, inv.beam, fit.x, inv.elevation, line.law)
    std = fit.elevation_std.get(name)
    if std is not None:
        std = np.where(known, std, np.nan)
    return replace(inv, reprojected=reprojected, even=even, elevation_std=std)
