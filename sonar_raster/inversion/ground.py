"""Slant-range images of one side: their check and the slant-range ↔ ground-range conversion.

Slant bin k covers ``[k, k + 1) * range_bin``; ground cell j has centre
``x_j = (j + 1/2) * ground_bin``. Slant intensities are areas per bin (as the renderer's);
ground intensities are densities per metre of ground range, so the conversion carries the
flat-seabed Jacobian ``dr/dx = x / r``: ``G(x) = I(r) / range_bin * x / r``. Over a flat
seabed rendered by the GL raster, ``G = w Φ R cos θ`` with ``w`` the ping width.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import SonarRasterError


def check_slant(slant: np.ndarray, range_bin: float, min_pings: int = 1) -> np.ndarray:
    """A slant-range image (pings x bins, linear, finite, >= 0) as float64, or one clear error."""
    a = np.asarray(slant)
    if a.ndim != 2 or a.shape[0] < min_pings or a.shape[1] < 4:
        raise SonarRasterError(
            f"image must be 2-D with >= {min_pings} ping(s) and >= 4 range bins, got {a.shape}"
        )
    if np.iscomplexobj(a):
        raise SonarRasterError("image is complex (amplitudes?); give intensities, |a|²")
    if not np.issubdtype(a.dtype, np.number) or not np.all(np.isfinite(a)):
        raise SonarRasterError("image must hold finite numbers")
    if np.any(a < 0):
        raise SonarRasterError("image intensities must be >= 0 (linear, not dB)")
    if not (math.isfinite(range_bin) and range_bin > 0):
        raise SonarRasterError(f"range bin must be > 0 metres, got {range_bin!r}")
    return a.astype(np.float64)


def ground_axis(altitude: np.ndarray, range_bin: float, bins: int, ground_bin: float) -> np.ndarray:
    """Ground cell centres reaching the farthest ground range any ping sees, shape (cells,)."""
    reach = np.sqrt(max((bins * range_bin) ** 2 - float(np.min(altitude)) ** 2, 0.0))
    cells = int(reach // ground_bin)
    if cells < 2:
        raise SonarRasterError(
            f"altitude {np.min(altitude):g} m leaves fewer than 2 ground cells in "
            f"{bins * range_bin:g} m of range"
        )
    return (np.arange(cells) + 0.5) * ground_bin


def slant_to_ground(
    slant: np.ndarray, range_bin: float, altitude: np.ndarray, x: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Resample a slant-range image onto ground cells over a flat seabed at the altitude.

    Parameters
    ----------
    slant : ndarray, shape (pings, bins)
        Intensity per slant bin.
    range_bin : float
        Slant bin size, metres.
    altitude : ndarray, shape (pings,)
        Sonar altitude per ping, metres.
    x : ndarray, shape (cells,)
        Ground cell centres, evenly spaced, metres.

    Returns
    -------
    ground : ndarray, shape (pings, cells), float64
        Intensity per metre of ground range (0 where invalid).
    valid : ndarray, shape (pings, cells), bool
        Cells whose slant range lies inside the image.
    """
    return sample_ground(
        slant, range_bin, np.broadcast_to(altitude[:, None], (len(altitude), len(x))), x
    )


def sample_ground(
    slant: np.ndarray, range_bin: float, depth: np.ndarray, x: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Resample a slant-range image onto ground cells that lie ``depth`` below the sonar.

    Cell (i, j) takes the slant image at range ``r = sqrt(x_j² + depth_ij²)`` (linear
    interpolation between bin centres) per metre of ground range with the flat-seabed Jacobian
    ``x / r``; :func:`slant_to_ground` is the case of one depth per ping.

    Parameters
    ----------
    slant : ndarray, shape (pings, bins)
        Intensity per slant bin.
    range_bin : float
        Slant bin size, metres.
    depth : ndarray, shape (pings, cells)
        Depth of each ground cell below the transducer, metres (finite).
    x : ndarray, shape (cells,)
        Ground cell centres, metres.

    Returns
    -------
    ground : ndarray, shape (pings, cells), float64
        Intensity per metre of ground range (0 where invalid).
    valid : ndarray, shape (pings, cells), bool
        Cells whose slant range lies inside the image.
    """
    r = np.sqrt(x[None, :] ** 2 + depth**2)
    pos = r / range_bin - 0.5
    bins = slant.shape[1]
    valid = r < bins * range_bin
    k0 = np.clip(np.floor(pos).astype(np.int64), 0, bins - 1)
    k1 = np.minimum(k0 + 1, bins - 1)
    t = np.clip(pos - k0, 0.0, 1.0)
    rows = np.arange(slant.shape[0])[:, None]
    values = (1.0 - t) * slant[rows, k0] + t * slant[rows, k1]
    ground = values / range_bin * (x[None, :] / r)
    return np.where(valid, ground, 0.0), valid


def ground_to_slant(
    ground: np.ndarray, x: np.ndarray, altitude: np.ndarray, range_bin: float, bins: int
) -> np.ndarray:
    """Inverse of :func:`slant_to_ground`: intensity per slant bin, shape (pings, bins).

    Bins nearer than the altitude (water column) and beyond the ground axis are 0. The
    Jacobian ``r / x`` is evaluated at ``x >= dx / 2`` so nadir stays finite.
    """
    dx = float(x[1] - x[0])
    r = (np.arange(bins) + 0.5) * range_bin
    xs = np.sqrt(np.maximum(r[None, :] ** 2 - altitude[:, None] ** 2, 0.0))
    out = np.empty((ground.shape[0], bins))
    for i, row in enumerate(ground):
        out[i] = np.interp(xs[i], x, row, left=row[0], right=0.0)
    xs_safe = np.maximum(xs, 0.5 * dx)
    out *= range_bin * (r[None, :] / xs_safe)
    inside = (r[None, :] >= altitude[:, None]) & (xs <= x[-1] + 0.5 * dx)
    return np.where(inside, out, 0.0)
