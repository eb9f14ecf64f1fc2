"""Ground-range images made from an inversion: the reprojected and the evenly lit image.

Reprojected image (seed Fig. 8a): ground cell (i, j) takes the slant-range image at the
range of the *recovered* seabed, ``ρ = sqrt(x_j² + Z_ij²)``, linearly interpolated between
bin centres, per metre of ground range with the flat-seabed Jacobian ``x / ρ``:
``G = I(ρ) / Δr · x / ρ``. Over a flat seabed this is the flat-seabed conversion of
:func:`.ground.slant_to_ground`, and for the renderer's images ``G = Φ R cos θ``
in the units of the recovered Φ. Relief still shades it (slopes facing the sonar are bright).

Evenly illuminated image (seed Eq. 22, Fig. 8c): the reprojected image divided by the recovered
beam profile and by the *average* incidence cosine of Eq. 22, that of a level patch at the
recovered depth, ``cos⟨θ⟩ = −Z / sqrt(x² + Z²)``:
``G_even = G / (Φ(α) · cos⟨θ⟩)``. On a level seabed it equals the reflectivity (in the scale
the inversion fixes between Φ and R); relief keeps its shading, which is why the seed uses it as
the texture of the 3D views. NaN where there is no estimate or ``Φ cos⟨θ⟩`` is below
``1e-6`` of its median.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .ground import sample_ground

if TYPE_CHECKING:
    from .law import ScatteringLaw

#: ``Φ cos⟨θ⟩`` below this fraction of its median leaves an evenly lit cell undefined (NaN).
EVEN_FLOOR = 1e-6


def reproject(
    slant: np.ndarray, range_bin: float, x: np.ndarray, elevation: np.ndarray
) -> np.ndarray:
    """The slant-range image in ground range at the recovered elevation.

    Parameters
    ----------
    slant : ndarray, shape (pings, bins)
        Linear intensity per slant bin, bins from range 0 outward.
    range_bin : float
        Slant bin size, metres.
    x : ndarray, shape (cells,)
        Ground-range cell centres, metres.
    elevation : ndarray, shape (pings, cells)
        Z relative to the transducer, metres, negative below; NaN where unknown.

    Returns
    -------
    ndarray, shape (pings, cells), float64
        Intensity per metre of ground range; NaN where Z is NaN or the range lies beyond the
        image.
    """
    known = np.isfinite(elevation)
    depth = np.where(known, elevation, 0.0)
    ground, valid = sample_ground(np.asarray(slant, np.float64), range_bin, depth, x)
    return np.where(known & valid, ground, np.nan)


def mean_incidence_cos(x: np.ndarray, elevation: np.ndarray) -> np.ndarray:
    """``cos⟨θ⟩ = −Z / sqrt(x² + Z²)`` of Eq. 22, shape of ``elevation`` (NaN stays NaN)."""
    z = np.asarray(elevation, np.float64)
    return -z / np.sqrt(x[None, :] ** 2 + z * z)


def even_illumination(
    reprojected: np.ndarray,
    beam: np.ndarray,
    x: np.ndarray,
    elevation: np.ndarray,
    law: ScatteringLaw | None = None,
) -> np.ndarray:
    """The evenly illuminated ground-range image of Eq. 22 (see the module notes).

    Parameters
    ----------
    reprojected : ndarray, shape (pings, cells)
        Output of :func:`reproject`.
    beam : ndarray, shape (pings, cells)
        Recovered Φ per cell (``Inversion.beam``).
    x : ndarray, shape (cells,)
        Ground-range cell centres, metres.
    elevation : ndarray, shape (pings, cells)
        Recovered Z, metres.
    law : ScatteringLaw, optional
        The seabed's law the fit modelled: the gain is then ``Φ cos⟨θ⟩ L(cos⟨θ⟩)``.

    Returns
    -------
    ndarray, shape (pings, cells), float64
        ``G / (Φ cos⟨θ⟩)``, reflectivity-like; NaN where undefined.
    """
    cos = mean_incidence_cos(x, elevation)
    gain = beam * cos
    if law is not None:
        with np.errstate(invalid="ignore"):
            gain = gain * np.exp(law.log_factor_at(np.nan_to_num(cos, nan=0.0))[0])
    ok = np.isfinite(gain) & np.isfinite(reprojected)
    positive = gain[ok & (gain > 0)]
    floor = EVEN_FLOOR * float(np.median(positive)) if positive.size else np.inf
    ok &= gain > floor
    with np.errstate(over="ignore"):  # a gain near the float floor: no estimate, not an error
        even = np.where(ok, reprojected / np.where(ok, gain, 1.0), np.nan)
    return np.where(np.isfinite(even), even, np.nan)
