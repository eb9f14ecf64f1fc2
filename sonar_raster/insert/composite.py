"""Composite rendered objects into a recording: highlight with its speckle, shadow with its noise.

Per side, over the rows the objects reach, with the renders B (seabed alone), F (seabed and
objects) and V (seabed with dark objects) of :mod:`.scene`:

- the object's own return is ``O = F − V`` and the fraction of the seabed echo it leaves is
  ``v = V / B`` (1 where the rendered seabed sends nothing);
- the recording's gain per unit rendered seabed is ``g = (⟨I⟩ − N) / ⟨B⟩``, local means over
  :data:`GAIN_PINGS` pings × :data:`GAIN_BINS` bins of the recording's intensity I and of B,
  N the noise floor. It carries the recording's beam pattern, losses, TVG and seabed
  reflectivity, so an object gets the gain of the seabed at its slant range in its ping, and
  its return relative to the seabed is the render's (object over seabed reflectivity, and
  their geometry). Where B is (nearly) 0 the gain of the nearest bin in range is used;
- the composite is ``v I + (1 − v) n + g O s``: the seabed echo removed where the object hides
  it, replaced by noise ``n`` drawn from the recording's own water-column cells (so a full
  shadow keeps the recording's noise floor, its level and its distribution), and the object's
  return with speckle ``s`` ~ Gamma(L, 1/L) of the recording's equivalent number of looks L
  (:func:`sonar_raster.inversion.priors.estimate_looks`; no speckle for a clean recording).

Not modelled: the recording's along-track beam blur (objects are as sharp along track as
the render), multipath, and the recording's seabed relief under the object (flat across track).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ..dataset.labels import instances_from_labels, shadow_owners
from ..inversion.bottom import blanking_bins
from ..inversion.priors import estimate_looks

__all__ = ["SideStats", "composite_side", "side_stats"]

#: Local means for the gain: pings along track, bins along range.
GAIN_PINGS = 15
GAIN_BINS = 7
#: Water-column cells end this fraction of the first return's range before it.
WATER_FRACTION = 0.9
#: More looks than this count as a clean (speckle-free) recording.
MAX_LOOKS = 1000.0
#: Bins after the first return left out of the looks estimate (the nadir edge changes fast).
_EDGE_BINS = 4


@dataclass(frozen=True)
class SideStats:
    """What one side of a recording says about its noise and speckle.

    Attributes
    ----------
    water : ndarray, float64
        Intensities of the water-column cells (between the transmit pulse and the first
        return), the noise pool shadows draw from; may be empty.
    noise : float
        Their mean, the noise floor N.
    looks : float
        Equivalent number of looks of the seabed's speckle (inf: clean).
    """

    water: np.ndarray
    noise: float
    looks: float

    def record(self) -> dict:
        """JSON-able summary."""
        return {
            "noise_floor": float(self.noise),
            "water_cells": int(self.water.size),
            "looks": None if math.isinf(self.looks) else float(self.looks),
        }


def side_stats(intensity: np.ndarray, altitude: np.ndarray, range_bin: float) -> SideStats:
    """Noise pool, noise floor and speckle looks of one side.

    Parameters
    ----------
    intensity : ndarray, shape (pings, bins)
        Linear intensity, bins from range 0 outward.
    altitude : ndarray, shape (pings,)
        First-return distance per ping, metres.
    range_bin : float
        Slant-range bin, metres.

    Returns
    -------
    SideStats
    """
    pings, bins = intensity.shape
    lo = blanking_bins(intensity) + 1
    first = np.clip(np.floor(altitude / range_bin).astype(np.int64), 0, bins)
    cols = np.arange(bins)[None, :]
    water_mask = (cols >= lo) & (cols < np.floor(WATER_FRACTION * first)[:, None])
    water = intensity[water_mask]
    seabed = (cols >= first[:, None] + _EDGE_BINS).astype(np.float64)
    looks = estimate_looks(intensity, seabed) if pings > 1 else math.inf
    if not math.isfinite(looks) or looks > MAX_LOOKS:
        looks = math.inf
    noise = float(water.mean()) if water.size else 0.0
    return SideStats(np.ascontiguousarray(water, dtype=np.float64), noise, float(looks))


def _runs(rows: np.ndarray) -> list[slice]:
    """Slices of ``rows`` (sorted) over runs of consecutive values."""
    breaks = np.flatnonzero(np.diff(rows) != 1) + 1
    edges = np.concatenate([[0], breaks, [len(rows)]])
    return [slice(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:], strict=True)]


def _local_mean(values: np.ndarray, rows: np.ndarray) -> np.ndarray:
    out = np.empty_like(values)
    for run in _runs(rows):
        out[run] = ndimage.uniform_filter(
            values[run], size=(min(GAIN_PINGS, run.stop - run.start), GAIN_BINS), mode="nearest"
        )
    return out


def _fill_along_range(values: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """Each row's values where ``ok``, the nearest ``ok`` bin's value elsewhere (0 if none)."""
    out = np.zeros_like(values)
    cols = np.arange(values.shape[1])
    for i in range(values.shape[0]):
        good = np.flatnonzero(ok[i])
        if good.size:
            nearest = good[np.clip(np.searchsorted(good, cols), 0, good.size - 1)]
            left = good[np.clip(np.searchsorted(good, cols) - 1, 0, good.size - 1)]
            pick = np.where(np.abs(left - cols) < np.abs(nearest - cols), left, nearest)
            out[i] = values[i, pick]
    return out


def gain_map(
    recorded: np.ndarray, seabed: np.ndarray, rows: np.ndarray, noise: float
) -> np.ndarray:
    """``g = (⟨I⟩ − N) / ⟨B⟩`` per cell of the rendered rows (see the module docstring).

    Parameters
    ----------
    recorded, seabed : ndarray, shape (rows, bins)
        The recording's intensity and the rendered seabed alone on the same rows.
    rows : ndarray of int
        The rows' indices in the recording (runs of consecutive rows are smoothed apart).
    noise : float
        Noise floor N.

    Returns
    -------
    ndarray, shape (rows, bins), float64
    """
    mean_i = np.maximum(_local_mean(recorded, rows) - noise, 0.0)
    mean_b = _local_mean(seabed, rows)
    positive = mean_b[mean_b > 0]
    floor = 1e-2 * float(np.median(positive)) if positive.size else np.inf
    ok = mean_b > floor
    ratio = np.divide(mean_i, mean_b, out=np.zeros_like(mean_i), where=ok)
    return _fill_along_range(ratio, ok)


def composite_side(
    recorded: np.ndarray,
    seabed: np.ndarray,
    full: np.ndarray,
    visible: np.ndarray,
    labels: np.ndarray,
    rows: np.ndarray,
    stats: SideStats,
    rng: np.random.Generator,
    shadow_ratio: float = 0.5,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Composite one side's rendered objects into its recorded rows.

    Parameters
    ----------
    recorded : ndarray, shape (rows, bins)
        The recording's intensity on the rendered rows.
    seabed, full, visible : ndarray, shape (rows, bins)
        Renders B, F and V.
    labels : ndarray, shape (rows, bins), uint16
        The renderer's labels of F.
    rows : ndarray of int
        The rows' indices in the recording.
    stats : SideStats
        Noise pool, floor and looks of the side.
    rng : numpy.random.Generator
        Draws the noise and speckle.
    shadow_ratio : float
        A cell is shadow where F < ratio × B (as the dataset's labels).

    Returns
    -------
    intensity : ndarray, shape (rows, bins), float64
    instance : ndarray, shape (rows, bins), uint16
        Instance k on object k's highlight and shadow, 0 elsewhere.
    classes : ndarray, shape (rows, bins), uint8
        0 background, 1 highlight, 2 shadow.
    """
    obj = np.maximum(full - visible, 0.0)
    lit = seabed > 0
    keep = np.ones_like(seabed)
    np.divide(visible, seabed, out=keep, where=lit)
    keep = np.clip(keep, 0.0, 1.0)
    gain = gain_map(recorded, seabed, rows, stats.noise)
    hidden = keep < 1.0
    noise = np.zeros_like(recorded)
    if stats.water.size and hidden.any():
        noise[hidden] = stats.water[rng.integers(stats.water.size, size=int(hidden.sum()))]
    echo = gain * obj
    has = echo > 0
    if math.isfinite(stats.looks) and has.any():
        echo[has] *= rng.gamma(stats.looks, 1.0 / stats.looks, size=int(has.sum()))
    out = keep * recorded + (1.0 - keep) * noise + echo
    highlight = instances_from_labels(labels)
    shadow = shadow_owners(full, seabed, highlight, shadow_ratio)
    classes = np.zeros(out.shape, dtype=np.uint8)
    classes[highlight > 0] = 1
    classes[shadow > 0] = 2
    return out, (highlight + shadow).astype(np.uint16), classes
