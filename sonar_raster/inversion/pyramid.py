"""Multi-resolution pyramid of an image (slant and ground range) and upsampling between levels."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy import ndimage

from .model import Geometry


@dataclass(frozen=True)
class Level:
    """One pyramid level: data at a resolution ``factor`` times coarser than the input.

    Attributes
    ----------
    image : ndarray, shape (pings, cells)
        Ground-range image: mean intensity per metre over each block of input cells.
    weight : ndarray, shape (pings, cells)
        1 where every input cell of the block is valid, else 0.
    slant : ndarray, shape (pings, bins)
        Slant-range image: mean intensity per metre of slant range over each block of bins.
    slant_weight : ndarray, shape (pings, bins)
        1 where the ground axis covers the bin at the level's altitude, else 0.
    altitude : ndarray, shape (pings,)
        Mean altitude of the block's pings, metres.
    geom : Geometry
    factor : int
    """

    image: np.ndarray
    weight: np.ndarray
    slant: np.ndarray
    slant_weight: np.ndarray
    altitude: np.ndarray
    geom: Geometry
    factor: int


def _pool(a: np.ndarray, f: int) -> np.ndarray:
    p, n = a.shape[0] // f, a.shape[1] // f
    return a[: p * f, : n * f].reshape(p, f, n, f).mean(axis=(1, 3))


def build(
    image: np.ndarray,
    valid: np.ndarray,
    slant: np.ndarray,
    altitude: np.ndarray,
    geom: Geometry,
    levels: int,
) -> list[Level]:
    """Levels from coarsest to finest; a level needs at least 2 pings and 2 cells.

    ``image``/``valid`` are the ground-range image and its mask, ``slant`` the image per metre
    of slant range (pings, bins) and ``geom`` the finest grid.
    """
    out = []
    for k in range(levels):
        f = 2**k
        if image.shape[0] // f < 2 or image.shape[1] // f < 2:
            break
        cells, bins = image.shape[1] // f, slant.shape[1] // f
        x = (np.arange(cells) + 0.5) * geom.dx * f
        pings = image.shape[0] // f
        alt = altitude[: pings * f].reshape(pings, f).mean(axis=1)
        weight = (_pool(valid.astype(np.float64), f) >= 1.0).astype(np.float64)
        rb = geom.range_bin * f
        reach = np.sqrt((x[-1] - geom.dx * f) ** 2 + alt[:, None] ** 2)
        centres = (np.arange(bins) + 0.5) * rb
        slant_weight = (centres[None, :] <= reach).astype(np.float64)
        grid = replace(geom, x=x, dx=geom.dx * f, dy=geom.dy * f, range_bin=rb, bins=bins)
        out.append(Level(_pool(image, f), weight, _pool(slant, f), slant_weight, alt, grid, f))
    return out[::-1]


def upsample(values: np.ndarray, coarse: Level, fine: Level) -> np.ndarray:
    """Bilinear resampling of a coarse (pings, cells) map onto the fine level's cells."""
    ratio = coarse.factor // fine.factor
    rows = (np.arange(fine.image.shape[0]) + 0.5) / ratio - 0.5
    cols = (np.arange(fine.image.shape[1]) + 0.5) / ratio - 0.5
    grid = np.meshgrid(rows, cols, indexing="ij")
    return ndimage.map_coordinates(values, grid, order=1, mode="nearest")
