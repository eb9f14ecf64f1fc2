"""Which inversion suits an image: one surface for speckled images, per-ping profiles otherwise.

On the bathymetry bench's one-line seabeds with speckle of 1, 4, 10 and 30 looks the per-ping
profiles score about the first return's flat seabed, the surface fit recovers relief on sand
waves, mounds, trenches and the box (docs/notes/2026-11-28-auto-method.md); on clean images
each wins on half the seabeds, and the profiles cost a fraction of the memory. So a speckled
image gets the surface fit where this machine can afford it, anything else the profiles.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

#: Estimated looks below which an image counts as speckled: above the most the surface fit
#: trusts (``surface.solve.MAX_LOOKS``, 30), below the fewest a clean bench render gave (156;
#: real recordings and the default render 2.9-4.0).
SPECKLED_LOOKS = 60.0
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

    Each side's estimate is the smaller of :func:`.priors.estimate_looks` between neighbouring
    pings and between neighbouring bins, over the lit bins (> 0). Speckle correlated along
    one axis reads as more looks along it: the default render's (its along-track footprint)
    gives 6.4-6.6 between pings and 3.0 between bins, the real 600 kHz file's squared samples
    2.9 / 3.2 (port) and 3.8 / 4.0 (starboard); the bench's clean renders 200 or more both ways.
    """
    from .priors import estimate_looks

    found = []
    for image in sides.values():
        a = np.nan_to_num(np.asarray(image, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0)
        if a.ndim == 2 and min(a.shape) >= 2:
            found.append(min(estimate_looks(a, a > 0), estimate_looks(a.T, a.T > 0)))
    finite = [v for v in found if math.isfinite(v)]
    if not finite:
        return math.inf  # identical pings, or a single one: nothing speckles
    return max(float(np.median(finite)), 1.0)


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
    from .._budget import SHARE, physical_memory, size_text
    from .._progress import TIME_LIMIT_S, duration_text

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
    seconds = SURFACE_PIXEL_SECONDS / max(finest, 1) ** 2 * pixels
    memory = float(SURFACE_PIXEL_BYTES) * pixels
    have = physical_memory()
    if seconds > TIME_LIMIT_S or memory > SHARE * have:
        return MethodChoice(
            "profiles",
            looks,
            f"method: profiles (a speckled image, about {shown} looks, but one surface over "
            f"{pixels:,} pixels would take about {duration_text(seconds)} and "
            f"{size_text(memory)} of this machine's {size_text(have)}; invert fewer pings at "
            "a time, e.g. --pings A:B, for the surface fit, which recovers more relief from "
            "speckle)",
        )
    return MethodChoice(
        "surface",
        looks,
        f"method: surface (a speckled image, about {shown} looks: one surface fitted to every "
        "ping of both sides, which recovers relief the per-ping profiles cannot; --method "
        "profiles for those: faster, and a hundredth of the memory)",
    )
