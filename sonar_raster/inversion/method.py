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
    at its looks (:func:`speckle_looks`): between pings two apart, since an along-track
    footprint wider than the ping spacing shares speckle between neighbouring pings (the
    default render reads 6.5 between neighbours, 3.1 two apart); and each bin against the mean
    of its two neighbours, which passes a range trend or shading but not speckle.
    """
    found = []
    for image in sides.values():
        a = np.nan_to_num(np.asarray(image, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0)
        if a.ndim == 2 and a.shape[0] >= 3 and a.shape[1] >= 3:
            pings = speckle_looks(a[:-2], a[2:])
            left, right = a[:, :-2], a[:, 2:]
            beside = np.where((left > 0) & (right > 0), 0.5 * (left + right), 0.0)  # both lit
            bins = speckle_looks(a[:, 1:-1], beside, 1.5)
            found.append(min(pings, bins))
    finite = [v for v in found if math.isfinite(v)]
    if not finite:
        return math.inf  # identical pings, or too few: nothing speckles
    return max(float(np.median(finite)), 1.0)


def speckle_looks(a: np.ndarray, b: np.ndarray, spread: float = 2.0) -> float:
    """Looks L of independent L-look speckle on ``a`` and ``b`` (samples of one mean, > 0).

    ``E[a b] = μ²`` and ``E[(a − b)²] = spread μ² / L`` (2 for two samples, 1.5 for one
    against the mean of two), so ``L = spread Σ a b / Σ (a − b)²``; ``inf`` where they agree.
    """
    keep = (a > 0) & (b > 0)
    x, y = a[keep], b[keep]
    diff = float(np.sum((x - y) ** 2))
    return math.inf if diff <= 0.0 else spread * float(np.sum(x * y)) / diff


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
