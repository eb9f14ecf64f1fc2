"""Where the surface fit's unknowns live: survey lines, the world grid and each view's bases.

A *line* is one pass of the sonar (its images and where each ping was); a *view* is one side of
one line at one resolution level. Z and log R are tensor cubic B-splines on one grid in a frame
whose y axis runs along the first line (origin at its first ping), X to its starboard; every
ground cell of every view is a point of that frame, so its value is a row of a sparse basis
matrix (16 coefficients) and overlapping lines share coefficients.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import sparse

from ...errors import SonarRasterError
from ..law import ScatteringLaw
from ..model import Geometry

SIDES = ("port", "starboard")


def bspline_basis(
    points: np.ndarray, start: float, stop: float, spacing: float
) -> sparse.csr_matrix:
    """Cubic B-spline basis with uniform knots ``spacing`` apart covering ``[start, stop]``.

    Parameters
    ----------
    points : ndarray, shape (n,)
        Where the basis is evaluated (clipped to the covered interval).
    start, stop : float
        Interval the basis must cover.
    spacing : float
        Knot spacing, > 0.

    Returns
    -------
    scipy.sparse.csr_matrix, shape (n, knots)
        Row i holds the weights of the coefficients at ``points[i]`` (they sum to 1).
    """
    cols, weights, count = cubic_rows(points, start, stop, spacing)
    n = cols.shape[0]
    indptr = np.arange(0, 4 * n + 1, 4)
    return sparse.csr_matrix((weights.ravel(), cols.ravel(), indptr), shape=(n, count))


def cubic_rows(
    points: np.ndarray, start: float, stop: float, spacing: float
) -> tuple[np.ndarray, np.ndarray, int]:
    """The rows of :func:`bspline_basis` as arrays: per point its 4 columns and weights.

    On uniform knots the 4 cubic B-splines that are non-zero on a span are fixed polynomials
    of the position ``s`` within it (de Boor's recursion, solved once): ``(1 − s)³/6``,
    ``(3s³ − 6s² + 4)/6``, ``(−3s³ + 3s² + 3s + 1)/6``, ``s³/6``; the last span holds the
    interval's end. Same values as ``scipy.interpolate.BSpline.design_matrix`` on the knots
    ``start + spacing · (−3 … spans + 3)`` (tests/inversion/test_surface.py), without its
    search and sort.

    Returns
    -------
    cols : ndarray of int64, shape (n, 4)
    weights : ndarray, shape (n, 4)
    count : int
        Basis functions (columns) in all.
    """
    spans = max(1, int(math.ceil((stop - start) / spacing - 1e-9)))
    u = np.clip((np.asarray(points, np.float64) - start) / spacing, 0.0, spans)
    span = np.minimum(np.floor(u), spans - 1)
    s = u - span
    s2 = s * s
    s3 = s2 * s
    weights = np.stack(
        [(1.0 - s) ** 3, 3.0 * s3 - 6.0 * s2 + 4.0, -3.0 * s3 + 3.0 * s2 + 3.0 * s + 1.0, s3],
        axis=-1,
    )
    weights /= 6.0
    cols = span.astype(np.int64)[:, None] + np.arange(4)
    return cols, weights, spans + 3


def knot_centres(start: float, stop: float, spacing: float) -> np.ndarray:
    """Where each basis function of :func:`bspline_basis` peaks (its Greville abscissa).

    Parameters
    ----------
    start, stop, spacing : float
        As for :func:`bspline_basis`.

    Returns
    -------
    ndarray, shape (knots,)
    """
    spans = max(1, int(math.ceil((stop - start) / spacing - 1e-9)))
    return start + spacing * (np.arange(spans + 3) - 1.0)


def tensor_basis(
    y: np.ndarray, x: np.ndarray, extent: tuple[float, float, float, float], spacing: float
) -> sparse.csr_matrix:
    """The tensor B-spline basis at scattered points.

    Row i holds the weights of the (ky, kx) coefficients (flattened, y major) at
    ``(y[i], x[i])``.

    Parameters
    ----------
    y, x : ndarray, shape (n,)
        Points in the frame, metres.
    extent : tuple of float
        ``(y0, y1, x0, x1)`` the grid covers.
    spacing : float
        Knot spacing on both axes, metres.

    Returns
    -------
    scipy.sparse.csr_matrix, shape (n, ky·kx)
    """
    y0, y1, x0, x1 = extent
    cy, vy, ky = cubic_rows(y, y0, y1, spacing)
    cx, vx, kx = cubic_rows(x, x0, x1, spacing)
    n = cy.shape[0]
    # built in scipy's index type, no int64 copy to narrow (2 M points: 1.1 → 0.7 s)
    index = np.int32 if 16 * n < 2**31 and ky * kx < 2**31 else np.int64
    cols = np.empty((n, 4, 4), index)
    np.multiply(cy[:, :, None], kx, out=cols, casting="unsafe")
    cols += cx[:, None, :].astype(index)
    vals = vy[:, :, None] * vx[:, None, :]
    indptr = np.arange(0, 16 * n + 1, 16, dtype=index)
    return sparse.csr_matrix((vals.ravel(), cols.ravel(), indptr), shape=(n, ky * kx))


@dataclass(frozen=True)
class Line:
    """One survey line: its images and where each ping was.

    Attributes
    ----------
    sides : mapping of str to ndarray, each shape (pings, bins)
        ``"port"`` and/or ``"starboard"`` linear intensity, bins from range 0.
    range_bin : float
        Slant-range bin, metres.
    position : ndarray, shape (pings, 2)
        Transducer position per ping in any plane metric frame (e.g. easting, northing), metres.
    heading : ndarray, shape (pings,)
        Heading per ping, radians clockwise from the frame's second axis (north).
    altitude : ndarray, shape (pings,), optional
        Altitude per ping, metres (default: the first bottom return).
    height : ndarray, shape (pings,), optional
        Transducer height in a datum common to every line (e.g. minus the sensor depth),
        metres (default 0: every line at one depth).
    law : ScatteringLaw, optional
        The seabed's scattering law at this line's frequency (default: Lambert's;
        :func:`..law.scattering_law`).
    """

    sides: Mapping[str, np.ndarray]
    range_bin: float
    position: np.ndarray
    heading: np.ndarray
    altitude: np.ndarray | None = None
    height: np.ndarray | None = None
    law: ScatteringLaw | None = None

    @classmethod
    def straight(
        cls,
        sides: Mapping[str, np.ndarray],
        range_bin: float,
        ping_spacing: float,
        altitude: np.ndarray | None = None,
        law: ScatteringLaw | None = None,
    ) -> Line:
        """A straight line along north from the origin, pings ``ping_spacing`` apart."""
        if not (math.isfinite(ping_spacing) and ping_spacing > 0):
            raise SonarRasterError(f"ping spacing must be > 0 metres, got {ping_spacing!r}")
        pings = next(iter(sides.values())).shape[0] if sides else 0
        position = np.zeros((pings, 2))
        position[:, 1] = np.arange(pings) * ping_spacing
        return cls(sides, range_bin, position, np.zeros(pings), altitude, law=law)

    @property
    def pings(self) -> int:
        """Number of pings."""
        return int(np.asarray(self.position).shape[0])

    @property
    def spacing(self) -> float:
        """Median distance between consecutive pings, metres (1 for a single ping)."""
        steps = np.linalg.norm(np.diff(np.asarray(self.position, float), axis=0), axis=1)
        return float(np.median(steps)) if steps.size else 1.0


@dataclass(frozen=True)
class Frame:
    """The fit's plane frame: origin and the heading of its y axis in the lines' frame."""

    origin: np.ndarray  # (2,)
    heading: float

    @classmethod
    def of(cls, lines: Sequence[Line]) -> Frame:
        """Y along the first line's mean heading, origin at its first ping."""
        h = np.asarray(lines[0].heading, np.float64)
        mean = math.atan2(float(np.mean(np.sin(h))), float(np.mean(np.cos(h))))
        return cls(np.asarray(lines[0].position, np.float64)[0].copy(), mean)

    def to_frame(self, position: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(y, X) in the frame of positions (…, 2) in the lines' frame."""
        d = np.asarray(position, np.float64) - self.origin
        s, c = math.sin(self.heading), math.cos(self.heading)
        return d[..., 0] * s + d[..., 1] * c, d[..., 0] * c - d[..., 1] * s

    def to_world(self, y: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Positions (…, 2) in the lines' frame of frame coordinates ``(y, X)``."""
        s, c = math.sin(self.heading), math.cos(self.heading)
        return np.stack([x * c + y * s, y * c - x * s], axis=-1) + self.origin


@dataclass
class View:
    """One side of one line at one level: its data and where its cells are.

    ``z`` of the view (relative to the transducer, (pings, cells)) is
    ``(bz @ Z knots) − height[:, None]``.
    """

    line: int
    side: str
    image: np.ndarray  # (pings, bins), intensity per metre of slant range
    mask: np.ndarray  # (pings, bins) bool
    floor: float
    looks: float
    geom: Geometry
    tau: np.ndarray  # (cells,)
    altitude: np.ndarray  # (pings,)
    height: np.ndarray  # (pings,)
    bz: sparse.csr_matrix  # (pings·cells, nz)
    br: sparse.csr_matrix  # (pings·cells, nr)
    nadir: sparse.csr_matrix  # (pings, nz): Z at each ping's nadir
    points: tuple[np.ndarray, np.ndarray]  # frame (y, X) of each cell, (pings, cells) each
    anchor_bin: float  # the bin the first-return anchor's σ counts in (Problem.anchor_std)
    anchor_looks: float = 1.0  # the images' own looks, by whose root that σ shrinks

    @property
    def shape(self) -> tuple[int, int]:
        """(pings, cells)."""
        return self.altitude.size, self.geom.x.size


def pool(values: np.ndarray, f: int) -> np.ndarray:
    """Mean over blocks of ``f`` pings (the first axis); other axes are kept."""
    if f == 1:
        return values
    p = values.shape[0] // f
    out = values[: p * f].reshape(p, f, *values.shape[1:]).mean(axis=1)
    return out


def pool_image(image: np.ndarray, f: int) -> np.ndarray:
    """Mean over f × f blocks of pings and bins."""
    if f == 1:
        return image
    p, b = image.shape[0] // f, image.shape[1] // f
    return image[: p * f, : b * f].reshape(p, f, b, f).mean(axis=(1, 3))


def pool_heading(heading: np.ndarray, f: int) -> np.ndarray:
    """Circular mean of headings over blocks of ``f`` pings."""
    if f == 1:
        return heading
    p = heading.size // f
    h = heading[: p * f].reshape(p, f)
    return np.arctan2(np.sin(h).mean(axis=1), np.cos(h).mean(axis=1))


def cell_points(
    frame: Frame, position: np.ndarray, heading: np.ndarray, side: str, x: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Frame (y, X) of every ground cell of one side, each (pings, cells)."""
    py, px = frame.to_frame(position)
    rel = np.asarray(heading, np.float64) - frame.heading
    sign = 1.0 if side == "starboard" else -1.0
    # starboard of a heading ψ (clockwise from the frame's y) is (cos ψ, −sin ψ) in (X, y)
    reach = sign * x[None, :]
    return py[:, None] - reach * np.sin(rel)[:, None], px[:, None] + reach * np.cos(rel)[:, None]


def check_lines(lines: Sequence[Line]) -> None:
    """One-line errors for lines the fit cannot take."""
    if isinstance(lines, Line) or not isinstance(lines, Sequence):
        raise SonarRasterError("give the lines as a list, e.g. fit_lines([line])")
    if not lines:
        raise SonarRasterError("no lines to fit")
    for k, line in enumerate(lines):
        where = f"line {k + 1}: " if len(lines) > 1 else ""
        if not line.sides or any(n not in SIDES for n in line.sides):
            raise SonarRasterError(f"{where}sides must be 'port' and/or 'starboard'")
        pings = {np.asarray(v).shape[0] for v in line.sides.values()}
        if len(pings) != 1:
            raise SonarRasterError(f"{where}both sides must have the same number of pings")
        n = pings.pop()
        if np.asarray(line.position).shape != (n, 2) or np.asarray(line.heading).shape != (n,):
            raise SonarRasterError(
                f"{where}position must be (pings, 2) and heading (pings,) for its {n} pings"
            )
        if not (np.all(np.isfinite(line.position)) and np.all(np.isfinite(line.heading))):
            raise SonarRasterError(f"{where}positions and headings must be finite")
