"""Which inversion suits an image: one surface for speckled images, per-ping profiles otherwise.

On the bathymetry bench's one-line seabeds with speckle of 1, 4, 10 and 30 looks the per-ping
profiles score about the first return's flat seabed, the surface fit recovers relief on sand
waves, mounds, trenches and the box (docs/notes/2026-11-28-auto-method.md). On clean images
neither wins throughout (the surface five of the bench's six seabeds, two of the independent
model's four, whose mean favours the profiles; docs/inversion.md), and the profiles cost a
fraction of the time and memory. So a speckled image gets the surface fit where this machine
can afford it, anything else the profiles.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .._progress import Estimate

#: Estimated looks below which an image counts as speckled: above the most the surface fit
#: trusts (``surface.solve.MAX_LOOKS``, 30; the bench at 30 looks reads 19-30), below the
#: fewest a clean render read (the bench's boulders 50 on one side, a test's ripples 50; the
#: real 600 kHz file 2.7-3.0, the default render 3.1-3.2; docs/notes/2026-11-28-auto-method.md).
SPECKLED_LOOKS = 40.0
#: Seconds per input pixel of the surface fit (two levels, 8 Gauss-Newton steps, the
#: uncertainty): unloaded on 2 cores, ``python tools/bench_fit_speed.py --pings 200 --bins 600
#: --finest 1 --seabed mounds`` (2 x 120 000 pixels) took 41.8-51.5 s on 2026-11-28 (61.0-75.8
#: s before that day's changes; the host's speed varies), 1.7e-4 to 2.1e-4 s per pixel; about
#: twice that, for a loaded machine (earlier, at load 4-6 and before the faster uncertainty,
#: 2.2e-4 to 9e-4).
SURFACE_PIXEL_SECONDS = 4e-4
#: Peak bytes per input pixel of the surface fit: 1.07 GB resident for one of those lines
#: (240 000 pixels, 4.5 kB each: Jacobians of Z and log R, normal matrices, LU factors, the
#: model's caches); with a margin.
SURFACE_PIXEL_BYTES = 6_000


@dataclass(frozen=True)
class MethodChoice:
    """The method :func:`choose_method` picked and why.

    Attributes
    ----------
    method : {"surface", "profiles"}
    looks : float
        The images' speckle looks (estimated, or as given).
    reason : str
        One line for the user: what was chosen, why, and how to choose otherwise.
    """

    method: str
    looks: float
    reason: str


def image_looks(sides: Mapping[str, np.ndarray]) -> float:
    """Speckle looks of one line's sides: the median of each side's estimate, at least 1.

    Each side's estimate is the smaller of two that a clean image reads high and speckle reads
    at its looks (:func:`.priors.looks_between`): between pings two apart, since an along-track
    footprint wider than the ping spacing shares speckle between neighbouring pings (the
    default render reads 6.5 between neighbours, 3.1 two apart); and each bin against the mean
    of its two neighbours, which passes a range trend or shading but not speckle.
    """
    from .priors import looks_between

    found = []
    for image in sides.values():
        a = np.nan_to_num(np.asarray(image, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0)
        if a.ndim == 2 and a.shape[0] >= 3 and a.shape[1] >= 3:
            lit = (a[:-2] > 0) & (a[2:] > 0)
            pings = looks_between(a[:-2][lit], a[2:][lit])
            left, centre, right = a[:, :-2], a[:, 1:-1], a[:, 2:]
            lit = (left > 0) & (centre > 0) & (right > 0)
            bins = looks_between(centre[lit], 0.5 * (left + right)[lit], 1.5)
            found.append(min(pings, bins))
    finite = [v for v in found if math.isfinite(v)]
    if not finite:
        return math.inf  # identical pings, or too few: nothing speckles
    return max(float(np.median(finite)), 1.0)


def surface_estimate(pixels: int, what: str, finest: int = 1) -> Estimate:
    """The surface fit's time and memory over ``pixels`` input pixels.

    ``finest`` (its pooling) divides the time; the products are still at every pixel.
    """
    from .._progress import Estimate

    return Estimate(
        what,
        {"pixels": float(pixels)},
        seconds=SURFACE_PIXEL_SECONDS / max(finest, 1) ** 2 * pixels,
        memory=float(SURFACE_PIXEL_BYTES) * pixels,
    )


def choose_method(
    lines: Sequence[Mapping[str, np.ndarray]], looks: float | None = None, finest: int = 1
) -> MethodChoice:
    """The surface fit for speckled images it can afford here, the per-ping profiles otherwise.

    Parameters
    ----------
    lines : sequence of mapping of str to ndarray
        Each line's sides, (pings, bins) linear intensity (an image is one line).
    looks : float, optional
        The images' looks if known (the user's ``--looks``); default: estimated from
        neighbouring pings (:func:`image_looks`, the fewest over the lines).
    finest : int
        The surface fit's finest pooling (``--coarsen``), which divides its time.

    Returns
    -------
    MethodChoice
    """
    from .._progress import check_job
    from ..errors import SonarRasterError

    if looks is None:
        looks = min((image_looks(sides) for sides in lines), default=math.inf)
    shown = "many" if not math.isfinite(looks) else f"{looks:.3g}"
    if looks >= SPECKLED_LOOKS:
        return MethodChoice(
            "profiles",
            looks,
            f"method: profiles (an image without strong speckle, about {shown} looks: one "
            "elevation profile per ping; --method surface fits one surface instead)",
        )
    pixels = sum(int(np.asarray(a).size) for sides in lines for a in sides.values())
    estimate = surface_estimate(pixels, "one surface", finest)
    try:
        check_job(estimate, "")  # the limits every job is held to
    except SonarRasterError:
        return MethodChoice(
            "profiles",
            looks,
            f"method: profiles (a speckled image, about {shown} looks, but {estimate.line()}, "
            "more than this machine allows; invert fewer pings at a time, e.g. --pings A:B, "
            "for the surface fit, which recovers more relief from speckle)",
        )
    return MethodChoice(
        "surface",
        looks,
        f"method: surface (a speckled image, about {shown} looks: one surface fitted to every "
        "ping of both sides, which recovers relief the per-ping profiles cannot; --method "
        "profiles for those: faster, and a hundredth of the memory)",
    )
