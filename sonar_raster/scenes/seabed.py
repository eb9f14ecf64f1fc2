"""Seabeds as heightfields on a regular grid, and their triangle meshes.

World: metres, z up. A :class:`Heightfield` holds ``z[j, i]``, the height of the node at
``(x0 + i * dx, y0 + j * dy)``: rows run along +y, columns along +x. Generators (:func:`flat`,
:func:`rough`, :func:`ripples`, :func:`bumpy`) draw from a seeded numpy ``Generator``, so the same
parameters and seed give the same seabed bit for bit, and set the mean height to ``depth``
exactly (so a scene's nominal ground level equals ``depth``). :func:`make_seabed` is the entry
point of a scene file's ``[seabed]`` table.
"""

from __future__ import annotations

import inspect
import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._checks import fraction, number, positive
from ..errors import SonarRasterError
from ..scene import MeshPart

#: Largest grid a generator builds (nodes); a typo such as ``resolution = 0.001`` fails fast.
MAX_NODES = 50_000_000

#: Default cell size of textured seabeds, metres: about one sonar range bin (5-10 cm).
DEFAULT_RESOLUTION = 0.1

#: Default largest cell edge of a flat seabed, metres: the renderer wants small triangles.
DEFAULT_MAX_CELL = 2.0

Size = tuple[float, float] | float
Pair = tuple[float, float]


# --------------------------------------------------------------------------- the mesh


def heightfield_mesh(
    z: np.ndarray,
    x0: float,
    y0: float,
    dx: float,
    dy: float,
    reflectivity: float | np.ndarray = 0.5,
    name: str = "seabed",
) -> MeshPart:
    """Triangulate a heightfield, two triangles per grid cell.

    Vertex ``j * nx + i`` is the node ``(x0 + i * dx, y0 + j * dy, z[j, i])``. Cell ``(j, i)``
    (corners ``a = (j, i)``, ``b = (j, i + 1)``, ``c = (j + 1, i + 1)``, ``d = (j + 1, i)``) gives
    faces ``2 * (j * (nx - 1) + i)`` = ``(a, b, c)`` and ``2 * (j * (nx - 1) + i) + 1`` =
    ``(a, c, d)``: cells in row-major order, both split along the same diagonal, both
    counter-clockwise seen from above (a flat grid has normals +z).

    Parameters
    ----------
    z : ndarray, shape (ny, nx)
        Node heights in metres; ``ny, nx >= 2``, all finite.
    x0, y0 : float
        Position of node ``z[0, 0]``, metres.
    dx, dy : float
        Node spacing along x (columns) and y (rows), metres, > 0.
    reflectivity : float or ndarray, shape (ny, nx)
        Reflectivity R >= 0, one value or a map sampled at the nodes; a face takes the mean of
        its cell's four corners (both faces of a cell share it).
    name : str
        Object name.

    Returns
    -------
    MeshPart
        ``vertices`` (ny * nx, 3) float64, ``faces`` (2 * (ny - 1) * (nx - 1), 3) int64,
        ``reflectivity`` float or (n_faces,) float64, ``is_seabed=True``.

    Raises
    ------
    SonarRasterError
        If the grid, spacing or reflectivity is invalid.
    """
    z = _check_grid(z)
    dx, dy = positive("seabed 'dx'", dx), positive("seabed 'dy'", dy)
    x0, y0 = number("seabed 'x0'", x0), number("seabed 'y0'", y0)
    ny, nx = z.shape
    vertices = np.empty((ny * nx, 3), dtype=np.float64)
    vertices[:, 0] = np.tile(x0 + dx * np.arange(nx), ny)
    vertices[:, 1] = np.repeat(y0 + dy * np.arange(ny), nx)
    vertices[:, 2] = z.ravel()
    return MeshPart(
        vertices=vertices,
        faces=_grid_faces(ny, nx),
        reflectivity=_face_reflectivity(reflectivity, z.shape),
        name=name,
        is_seabed=True,
    )


def _grid_faces(ny: int, nx: int) -> np.ndarray:
    """Faces of an (ny, nx) node grid in the order documented in :func:`heightfield_mesh`."""
    idx = np.arange(ny * nx, dtype=np.int64).reshape(ny, nx)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]
    faces = np.empty((ny - 1, nx - 1, 2, 3), dtype=np.int64)
    faces[:, :, 0, 0] = a
    faces[:, :, 0, 1] = b
    faces[:, :, 0, 2] = c
    faces[:, :, 1, 0] = a
    faces[:, :, 1, 1] = c
    faces[:, :, 1, 2] = d
    return faces.reshape(-1, 3)


def _face_reflectivity(reflectivity: float | np.ndarray, shape: tuple[int, int]) -> Any:
    """Scalar reflectivity as a float, or a node map as per-face values (cell corner means)."""
    r = np.asarray(reflectivity, dtype=np.float64)
    if not (np.all(np.isfinite(r)) and np.all(r >= 0)):
        raise SonarRasterError("seabed reflectivity must be finite and >= 0; fix the value or map")
    if r.ndim == 0:
        return float(r)
    if r.shape != shape:
        raise SonarRasterError(
            f"seabed reflectivity map has shape {r.shape} but the grid is {shape}; "
            "give one value per grid node"
        )
    cell = 0.25 * (r[:-1, :-1] + r[:-1, 1:] + r[1:, 1:] + r[1:, :-1])
    return np.repeat(cell.ravel(), 2)


# --------------------------------------------------------------------------- the heightfield


@dataclass(frozen=True, eq=False)
class Heightfield:
    """Heights on a regular grid.

    Attributes
    ----------
    z : ndarray, shape (ny, nx), float64
        Node heights in metres (read-only copy); ``z[j, i]`` is at ``(x0 + i*dx, y0 + j*dy)``.
    x0, y0 : float
        Position of node ``z[0, 0]``, metres (the grid's minimum x and y).
    dx, dy : float
        Node spacing along x (columns) and y (rows), metres.
    """

    z: np.ndarray
    x0: float
    y0: float
    dx: float
    dy: float

    def __post_init__(self) -> None:
        z = np.array(_check_grid(self.z), dtype=np.float64, copy=True)
        z.setflags(write=False)
        object.__setattr__(self, "z", z)
        object.__setattr__(self, "x0", number("seabed 'x0'", self.x0))
        object.__setattr__(self, "y0", number("seabed 'y0'", self.y0))
        object.__setattr__(self, "dx", positive("seabed 'dx'", self.dx))
        object.__setattr__(self, "dy", positive("seabed 'dy'", self.dy))

    @property
    def shape(self) -> tuple[int, int]:
        """Grid shape ``(ny, nx)``."""
        return (int(self.z.shape[0]), int(self.z.shape[1]))

    @property
    def x(self) -> np.ndarray:
        """Node x coordinates, shape (nx,), metres."""
        return self.x0 + self.dx * np.arange(self.shape[1])

    @property
    def y(self) -> np.ndarray:
        """Node y coordinates, shape (ny,), metres."""
        return self.y0 + self.dy * np.arange(self.shape[0])

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """``(xmin, xmax, ymin, ymax)`` of the nodes, metres."""
        ny, nx = self.shape
        return (self.x0, self.x0 + (nx - 1) * self.dx, self.y0, self.y0 + (ny - 1) * self.dy)

    def mesh(self, reflectivity: float | np.ndarray = 0.5, name: str = "seabed") -> MeshPart:
        """Triangle mesh of the seabed; see :func:`heightfield_mesh` for the layout."""
        return heightfield_mesh(self.z, self.x0, self.y0, self.dx, self.dy, reflectivity, name)

    def height_at(self, x: np.ndarray | float, y: np.ndarray | float) -> np.ndarray:
        """Interpolate the heights bilinearly.

        Points outside the grid take the height of the nearest edge. Inside a cell the bilinear
        surface differs from the two triangles of :meth:`mesh` by at most a quarter of the
        cell's twist ``|z00 - z10 - z01 + z11|`` (zero on planar cells).

        Parameters
        ----------
        x, y : array_like
            Query coordinates in metres, broadcast against each other.

        Returns
        -------
        ndarray, float64
            Heights in metres, with the broadcast shape of ``x`` and ``y`` (0-d for scalars).
        """
        xq, yq = np.broadcast_arrays(np.asarray(x, np.float64), np.asarray(y, np.float64))
        if not (np.all(np.isfinite(xq)) and np.all(np.isfinite(yq))):
            raise SonarRasterError("height_at needs finite x and y coordinates")
        ny, nx = self.shape
        i, tx = _cell_and_fraction((xq - self.x0) / self.dx, nx)
        j, ty = _cell_and_fraction((yq - self.y0) / self.dy, ny)
        z = self.z
        bottom = z[j, i] * (1.0 - tx) + z[j, i + 1] * tx
        top = z[j + 1, i] * (1.0 - tx) + z[j + 1, i + 1] * tx
        return np.asarray(bottom * (1.0 - ty) + top * ty)

    def resampled(self, resolution: float) -> Heightfield:
        """Resample bilinearly onto the same extent with cells of at most ``resolution`` metres.

        The spacing is the largest one not above ``resolution`` that divides the extent
        exactly, on each axis.
        """
        xmin, xmax, ymin, ymax = self.extent
        res = positive("seabed 'resolution'", resolution)
        nx, dx = _cells(xmax - xmin, res)
        ny, dy = _cells(ymax - ymin, res)
        _check_node_count(nx + 1, ny + 1)
        xs = xmin + dx * np.arange(nx + 1)
        ys = ymin + dy * np.arange(ny + 1)
        return Heightfield(self.height_at(xs[None, :], ys[:, None]), xmin, ymin, dx, dy)


def reflectivity_map(path: str | Path, field: Heightfield) -> np.ndarray:
    """Read a reflectivity map and sample it at a seabed's grid nodes.

    The map is stretched over the seabed's extent. ``.npy``: a 2-D array of reflectivities,
    row 0 at the smallest y (like elevation grids). Images (PNG, TIFF, EXR, ... read by
    OpenImageIO): the mean of the colour channels, scaled to [0, 1] for integer formats, row 0
    at the largest y (the top of the picture is north). Sampling is bilinear.

    Parameters
    ----------
    path : str or Path
        The map file.
    field : Heightfield
        The seabed whose nodes it is sampled at.

    Returns
    -------
    ndarray, shape (ny, nx), float64
        Reflectivity at each node, finite and >= 0 (ready for :meth:`Heightfield.mesh`).
    """
    from scipy.ndimage import map_coordinates

    path = Path(path)
    if not path.is_file():
        raise SonarRasterError(f"reflectivity map {path} does not exist; check the path")
    if path.suffix.lower() == ".npy":
        values = _read_npy(path).astype(np.float64)
    else:
        from ..io.images import read_pixels

        pixels, spec = read_pixels(path)
        values = pixels[:, :, : min(3, pixels.shape[2])].mean(axis=2)[::-1].astype(np.float64)
    if values.ndim != 2 or min(values.shape) < 1:
        raise SonarRasterError(f"reflectivity map {path.name} must be a 2-D grid")
    if not (np.all(np.isfinite(values)) and values.min() >= 0):
        raise SonarRasterError(f"reflectivity map {path.name} must hold finite values >= 0")
    ny, nx = field.shape
    rows = np.linspace(0.0, values.shape[0] - 1, ny)
    cols = np.linspace(0.0, values.shape[1] - 1, nx)
    grid = np.meshgrid(rows, cols, indexing="ij")
    return map_coordinates(values, grid, order=1, mode="nearest")


def level_of_detail(field: Heightfield, cell: float) -> tuple[Heightfield, dict]:
    """A coarser grid for a seabed finer than the image can resolve, and the error it costs.

    Each axis whose spacing is below ``cell`` is resampled (bilinearly, on the same extent) to
    the largest spacing not above ``cell`` that divides the extent; an axis already coarser is
    kept. A side-scan image resolves at best one range bin in ground range (finer still only
    along track, at the ping spacing), so heights finer than half a bin mostly add triangles:
    the error of the coarse surface at the fine nodes is returned so it can be reported.

    Parameters
    ----------
    field : Heightfield
    cell : float
        Finest spacing worth drawing, metres (> 0).

    Returns
    -------
    coarse : Heightfield
        ``field`` itself when no axis is finer than ``cell``.
    report : dict
        Empty when nothing changed; else ``from_m`` and ``to_m`` (dx, dy), ``triangles_from``,
        ``triangles_to``, and ``rms_m`` / ``max_m``: the RMS and largest height difference
        between the coarse surface and the fine grid at the fine nodes, metres.
    """
    cell = positive("seabed 'cell'", cell)
    if field.dx >= cell and field.dy >= cell:
        return field, {}
    xmin, xmax, ymin, ymax = field.extent
    nx, dx = _cells(xmax - xmin, cell) if field.dx < cell else (field.shape[1] - 1, field.dx)
    ny, dy = _cells(ymax - ymin, cell) if field.dy < cell else (field.shape[0] - 1, field.dy)
    xs, ys = xmin + dx * np.arange(nx + 1), ymin + dy * np.arange(ny + 1)
    coarse = Heightfield(field.height_at(xs[None, :], ys[:, None]), xmin, ymin, dx, dy)
    sq, worst = 0.0, 0.0
    step = max(1, (1 << 20) // field.shape[1])  # fine rows per block
    for j in range(0, field.shape[0], step):
        rows = field.y[j : j + step]
        diff = coarse.height_at(field.x[None, :], rows[:, None]) - field.z[j : j + step]
        sq += float(np.sum(diff * diff))
        worst = max(worst, float(np.abs(diff).max()))
    report = {
        "from_m": [field.dx, field.dy],
        "to_m": [dx, dy],
        "triangles_from": 2 * (field.shape[0] - 1) * (field.shape[1] - 1),
        "triangles_to": 2 * ny * nx,
        "rms_m": math.sqrt(sq / field.z.size),
        "max_m": worst,
    }
    return coarse, report


def _cell_and_fraction(f: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Cell index in ``[0, n - 2]`` and fraction in ``[0, 1]`` of fractional node positions."""
    f = np.clip(f, 0.0, n - 1.0)
    i = np.minimum(np.floor(f).astype(np.intp), n - 2)
    return i, f - i


# --------------------------------------------------------------------------- validation


def _pair(name: str, value: Any, lengths: bool) -> Pair:
    """A number or a pair of numbers as a pair of floats; ``lengths``: each > 0, one allowed."""
    label = f"seabed '{name}'"
    check = positive if lengths else number
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value.item()
    if isinstance(value, (list, tuple, np.ndarray)):
        if len(value) != 2:
            raise SonarRasterError(f"{label} must be two numbers (x, y), got {value!r}")
        return (check(label, value[0]), check(label, value[1]))
    if not lengths:
        raise SonarRasterError(f"{label} must be two numbers (x, y), got {value!r}")
    v = check(label, value)
    return (v, v)


def _seed(value: Any) -> int:
    """Check that a seed is an int >= 0 and return it."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise SonarRasterError(f"seabed 'seed' must be an integer >= 0, got {value!r}")
    return int(value)


def _check_grid(z: Any) -> np.ndarray:
    """Return ``z`` as a finite float64 grid of at least 2 x 2 nodes, or raise."""
    try:
        arr = np.asarray(z, dtype=np.float64)
    except (TypeError, ValueError):
        raise SonarRasterError(
            "the elevation grid is not numeric; give a 2-D float array"
        ) from None
    if arr.ndim != 2:
        raise SonarRasterError(
            f"the elevation grid has {arr.ndim} dimension(s); give a 2-D array (ny, nx)"
        )
    if arr.shape[0] < 2 or arr.shape[1] < 2:
        raise SonarRasterError(
            f"the elevation grid has shape {arr.shape}; it needs at least 2 x 2 nodes"
        )
    bad = int(np.count_nonzero(~np.isfinite(arr)))
    if bad:
        raise SonarRasterError(
            f"the elevation grid has {bad} NaN or infinite value(s); fill or crop them first"
        )
    return arr


def _check_node_count(nx: int, ny: int) -> None:
    if nx * ny > MAX_NODES:
        raise SonarRasterError(
            f"a seabed grid of {ny} x {nx} nodes exceeds {MAX_NODES} nodes; "
            "use a coarser resolution or a smaller size"
        )


def _cells(length: float, resolution: float) -> tuple[int, float]:
    """Return the number and size of the largest cells <= ``resolution`` dividing ``length``."""
    n = max(1, math.ceil(length / resolution - 1e-9))
    return n, length / n


@dataclass(frozen=True)
class _Grid:
    """Node layout of a generated seabed."""

    nx: int
    ny: int
    x0: float
    y0: float
    dx: float
    dy: float

    def coords(self) -> tuple[np.ndarray, np.ndarray]:
        """Node coordinates ``x`` (1, nx) and ``y`` (ny, 1), metres, for broadcasting."""
        x = self.x0 + self.dx * np.arange(self.nx)
        y = self.y0 + self.dy * np.arange(self.ny)
        return x[None, :], y[:, None]

    def heightfield(self, relief: np.ndarray, depth: float) -> Heightfield:
        """Heightfield of ``relief`` shifted so that its mean is exactly ``depth``."""
        z = relief - relief.mean() + depth
        return Heightfield(z, self.x0, self.y0, self.dx, self.dy)


def _layout(size: Any, center: Any, resolution: Any) -> _Grid:
    """Grid covering ``size`` metres around ``center`` with cells no larger than resolution."""
    lx, ly = _pair("size", size, lengths=True)
    cx, cy = _pair("center", center, lengths=False)
    res = positive("seabed 'resolution'", resolution)
    ncx, dx = _cells(lx, res)
    ncy, dy = _cells(ly, res)
    _check_node_count(ncx + 1, ncy + 1)
    return _Grid(ncx + 1, ncy + 1, cx - 0.5 * lx, cy - 0.5 * ly, dx, dy)


# --------------------------------------------------------------------------- random fields


def _spectral_field(
    rng: np.random.Generator,
    grid: _Grid,
    spectrum: Callable[[np.ndarray], np.ndarray],
) -> np.ndarray:
    """Gaussian random field with power spectrum ``spectrum(k)``, zero mean, unit std.

    White noise on the nodes is filtered in the Fourier domain by ``sqrt(spectrum(k))``,
    ``k`` the angular wavenumber magnitude in rad/m; the field is periodic over the grid.
    Returns shape (ny, nx), float64.
    """
    shape = (grid.ny, grid.nx)
    noise_hat = np.fft.rfft2(rng.standard_normal(shape))
    ky = 2.0 * np.pi * np.fft.fftfreq(grid.ny, grid.dy)
    kx = 2.0 * np.pi * np.fft.rfftfreq(grid.nx, grid.dx)
    k = np.hypot(ky[:, None], kx[None, :])
    gain = np.sqrt(spectrum(k))
    gain[0, 0] = 0.0
    field = np.fft.irfft2(noise_hat * gain, s=shape)
    field -= field.mean()
    std = float(field.std())
    return field / std if std > 0 else field


def _power_law(exponent: float, correlation_length: float) -> Callable[[np.ndarray], np.ndarray]:
    """Spectrum ``(1 + (k L)^2)^(-exponent/2)``: flat below ``1/L``, ``k^-exponent`` above."""
    return lambda k: (1.0 + (k * correlation_length) ** 2) ** (-0.5 * exponent)


#: Outer scale of the micro-relief, metres: its spectrum is the sediment's power law above
#: ``1/outer_scale`` and flat below (larger relief is the scene's own seabed kind).
MICRO_OUTER_SCALE = 1.0

#: Default cell of the micro-relief, in range bins.
MICRO_RESOLUTION_BINS = 1.5

#: Most nodes of a micro-relief grid (20 M: about 4 GB while its mesh is built).
MICRO_MAX_NODES = 20_000_000


def micro_relief_spectrum(
    sediment: str, outer_scale: float = MICRO_OUTER_SCALE
) -> Callable[[np.ndarray], np.ndarray]:
    """The sediment's roughness spectrum ``W(K) = w₂ (K² + 1/L²)^(-γ/2)``, SI units.

    ``w₂`` and ``γ`` are the APL-UW TR 9407 Table 2 values of the sediment (the same numbers
    that set its backscattering law); ``W`` is the 2-D spectral density of heights, so that
    the height variance is ``∫ W d²K`` (K in rad/m, W in m⁴).

    Parameters
    ----------
    sediment : str
        A sediment class or Table 2 name (see :func:`..sediments.sediment`).
    outer_scale : float
        ``L``, metres (> 0).

    Returns
    -------
    callable
        ``W(K)`` for an array of angular wavenumbers (rad/m).
    """
    from .backscatter import spectral_strength_si
    from .sediments import sediment as find

    p = find(sediment).parameters
    w2, gamma = spectral_strength_si(p), p.gamma
    inv = 1.0 / positive("micro_relief 'outer_scale'", outer_scale)
    return lambda k: w2 * (k * k + inv * inv) ** (-0.5 * gamma)


def micro_relief(
    field: Heightfield,
    sediment: str,
    *,
    resolution: float,
    outer_scale: float = MICRO_OUTER_SCALE,
    seed: int = 0,
) -> Heightfield:
    """The seabed with its sediment's roughness added at scales the image resolves.

    A rough seabed's texture in a side-scan image comes from its relief at scales from the
    resolution cell up: each facet's slope changes its grazing angle, so its backscatter, by
    more the lower the grazing angle, and the troughs behind crests fall in shadow. The relief
    is a Gaussian random field with :func:`micro_relief_spectrum` (the sediment's published
    APL-UW spectrum, not a fitted level), made by spectral synthesis (as :func:`rough`) on a
    grid of cells no larger than ``resolution``, its variance the spectrum integrated over that
    grid's wavenumbers, and added to ``field`` resampled bilinearly onto that grid.

    Parameters
    ----------
    field : Heightfield
        The seabed (any kind).
    sediment : str
        Its material: a sediment class or TR 9407 Table 2 name.
    resolution : float
        Largest cell of the result, metres (about one to two range bins).
    outer_scale : float
        Largest scale of the added relief, metres.
    seed : int
        Seed of the random field (the same seed gives the same relief bit for bit).

    Returns
    -------
    Heightfield
    """
    cell = positive("micro_relief 'resolution'", resolution)
    xmin, xmax, ymin, ymax = field.extent
    nodes = (_cells(xmax - xmin, cell)[0] + 1) * (_cells(ymax - ymin, cell)[0] + 1)
    if nodes > MICRO_MAX_NODES:
        raise SonarRasterError(
            f"micro_relief at {cell:g} m over {xmax - xmin:g} m x {ymax - ymin:g} m needs "
            f"{nodes:,} nodes (at most {MICRO_MAX_NODES:,}): give it a coarser resolution, or "
            "a smaller seabed"
        )
    fine = field.resampled(cell)
    ny, nx = fine.shape
    grid = _Grid(nx, ny, fine.x0, fine.y0, fine.dx, fine.dy)
    spectrum = micro_relief_spectrum(sediment, outer_scale)
    # the field's variance is W integrated over the grid's wavenumbers (the mean left out)
    ky = 2.0 * np.pi * np.fft.fftfreq(ny, fine.dy)
    kx = 2.0 * np.pi * np.fft.fftfreq(nx, fine.dx)
    density = spectrum(np.hypot(ky[:, None], kx[None, :]))
    density[0, 0] = 0.0
    variance = float(density.sum()) * (2.0 * np.pi) ** 2 / (nx * fine.dx * ny * fine.dy)
    rng = np.random.default_rng(_seed(seed))
    relief = math.sqrt(variance) * _spectral_field(rng, grid, spectrum)
    return Heightfield(fine.z + relief, fine.x0, fine.y0, fine.dx, fine.dy)


# --------------------------------------------------------------------------- generators


def flat(
    *,
    size: Size = (100.0, 100.0),
    center: Pair = (0.0, 0.0),
    resolution: float | None = None,
    depth: float = 0.0,
    seed: int = 0,
    max_cell: float = DEFAULT_MAX_CELL,
) -> Heightfield:
    """Make a flat seabed at height ``depth``.

    A flat seabed needs few cells, but the renderer interpolates linearly in its projected
    space and wants small triangles, so cells are never larger than ``max_cell``.

    Parameters
    ----------
    size : float or (float, float)
        Extent ``(Lx, Ly)`` in metres (one number: a square).
    center : (float, float)
        Centre ``(cx, cy)`` in metres.
    resolution : float or None
        Cell size in metres; ``None`` or anything above ``max_cell`` gives ``max_cell``. The
        actual spacing is the largest one not above it that divides the size exactly.
    depth : float
        Height z of the seabed, metres.
    seed : int
        Unused; accepted so that every kind takes the same keys.
    max_cell : float
        Largest cell edge in metres (the longest triangle edge is ``sqrt(2) * max_cell``).

    Returns
    -------
    Heightfield
    """
    _seed(seed)
    cell = positive("seabed 'max_cell'", max_cell)
    res = cell if resolution is None else min(positive("seabed 'resolution'", resolution), cell)
    grid = _layout(size, center, res)
    return grid.heightfield(np.zeros((grid.ny, grid.nx)), number("seabed 'depth'", depth))


def rough(
    *,
    size: Size = (100.0, 100.0),
    center: Pair = (0.0, 0.0),
    resolution: float = DEFAULT_RESOLUTION,
    depth: float = 0.0,
    seed: int = 0,
    rms_height: float = 0.05,
    spectral_exponent: float = 3.25,
    correlation_length: float = 10.0,
) -> Heightfield:
    """Make a fractal (power-law) rough seabed by spectral synthesis.

    The 2-D power spectral density is ``W(k) ~ (1 + (k L)^2)^(-gamma/2)`` with ``k`` the
    angular wavenumber (rad/m), ``gamma`` the spectral exponent and ``L`` the correlation
    length: a ``k^-gamma`` power law above ``1/L``, flat (no larger relief) below it. The relief
    is then scaled to exactly ``rms_height`` and its mean set to exactly ``depth``.

    Parameters
    ----------
    size, center, resolution, depth, seed
        As for :func:`flat`; ``resolution`` is the cell size in metres.
    rms_height : float
        Root-mean-square height about the mean, metres (default 5 cm, a sandy bed).
    spectral_exponent : float
        ``gamma`` of the 2-D spectrum, in (0, 8]; in (2, 4) for a fractal surface of
        dimension ``(8 - gamma) / 2``; the default 3.25 is the APL-UW model's typical value.
    correlation_length : float
        Outer scale ``L`` of the relief, metres.

    Returns
    -------
    Heightfield
    """
    grid = _layout(size, center, resolution)
    rng = np.random.default_rng(_seed(seed))
    rms = positive("seabed 'rms_height'", rms_height)
    exponent = positive("seabed 'spectral_exponent'", spectral_exponent)
    if exponent > 8.0:
        raise SonarRasterError(
            f"seabed 'spectral_exponent' must be in (0, 8], got {spectral_exponent!r}; "
            "natural seabeds have 2 to 4"
        )
    spectrum = _power_law(exponent, positive("seabed 'correlation_length'", correlation_length))
    return grid.heightfield(
        rms * _spectral_field(rng, grid, spectrum), number("seabed 'depth'", depth)
    )


def ripples(
    *,
    size: Size = (100.0, 100.0),
    center: Pair = (0.0, 0.0),
    resolution: float = DEFAULT_RESOLUTION,
    depth: float = 0.0,
    seed: int = 0,
    wavelength: float = 1.0,
    amplitude: float = 0.05,
    direction_deg: float = 0.0,
    irregularity: float = 0.3,
    asymmetry: float = 0.4,
    roughness: float | None = None,
) -> Heightfield:
    """Make sand ripples: sharp crests, rounded troughs, a gentle stoss and a steep lee side.

    One period, from trough to trough, is two parabolic arcs meeting at a sharp crest: the stoss
    side takes ``(1 + asymmetry) / 2`` of the wavelength, the lee side the rest. The phase is
    ``s / wavelength + irregularity / 2 * psi(x, y)`` cycles, ``s`` the distance along
    ``direction_deg`` and ``psi`` a smooth unit-std random field correlated over five
    wavelengths, so crests wander by about ``irregularity / 2`` wavelengths and the local
    wavelength changes slowly. Fine roughness is added (:func:`rough`'s spectrum with exponent
    3.25 and correlation length one wavelength).

    Parameters
    ----------
    size, center, resolution, depth, seed
        As for :func:`flat`; ``resolution`` must be at most a quarter of ``wavelength``.
    wavelength : float
        Crest spacing, metres.
    amplitude : float
        Half the crest-to-trough height, metres (default: height 10 cm over 1 m, steepness 0.1).
    direction_deg : float
        Compass direction the ripples face and migrate toward, degrees (0 = +y, 90 = +x, as
        trajectory headings); crests run across it and the steep lee faces point along it.
    irregularity : float
        0 for straight, regular crests, up to 1 for strongly sinuous ones.
    asymmetry : float
        0 for symmetric ripples, up to 0.95 (lee side 2.5 % of the wavelength). The default
        0.4 with the default amplitude gives a 34 degree lee face, about sand's angle of repose.
    roughness : float or None
        RMS of the added small-scale roughness, metres; ``None`` gives ``amplitude / 10``.

    Returns
    -------
    Heightfield
    """
    grid = _layout(size, center, resolution)
    rng = np.random.default_rng(_seed(seed))
    lam = positive("seabed 'wavelength'", wavelength)
    amp = positive("seabed 'amplitude'", amplitude)
    if lam < 4.0 * max(grid.dx, grid.dy):
        raise SonarRasterError(
            f"ripple wavelength {lam:g} m spans fewer than 4 cells; use resolution <= {lam / 4:g}"
        )
    lee = 0.5 * (1.0 - fraction("seabed 'asymmetry'", asymmetry, upper=0.95))
    irr = fraction("seabed 'irregularity'", irregularity)
    rough_rms = 0.1 * amp if roughness is None else number("seabed 'roughness'", roughness)
    if rough_rms < 0:
        raise SonarRasterError(f"seabed 'roughness' must be >= 0, got {roughness!r}")
    heading = math.radians(number("seabed 'direction_deg'", direction_deg))
    x, y = grid.coords()
    wander = _spectral_field(rng, grid, lambda k: _gauss(k * 5.0 * lam * math.sqrt(2.0)))
    phase = (x * math.sin(heading) + y * math.cos(heading)) / lam + 0.5 * irr * wander
    relief = amp * _ripple_profile(phase - np.floor(phase), 1.0 - lee)
    if rough_rms > 0:
        relief += rough_rms * _spectral_field(rng, grid, _power_law(3.25, lam))
    return grid.heightfield(relief, number("seabed 'depth'", depth))


def _ripple_profile(u: np.ndarray, stoss: float) -> np.ndarray:
    """Zero-mean ripple shape of crest-to-trough height 2 at cycle fraction ``u`` in [0, 1).

    Trough at ``u = 0``, crest at ``u = stoss``; each side is a parabola with zero slope at the
    trough, so crests are sharp and troughs rounded.
    """
    t = np.where(u < stoss, u / stoss, (1.0 - u) / (1.0 - stoss))
    return 2.0 * t * t - 2.0 / 3.0


def bumpy(
    *,
    size: Size = (100.0, 100.0),
    center: Pair = (0.0, 0.0),
    resolution: float = DEFAULT_RESOLUTION,
    depth: float = 0.0,
    seed: int = 0,
    bump_height: float = 0.3,
    bump_width: float = 1.5,
    density: float = 0.02,
    hollow_fraction: float = 0.5,
) -> Heightfield:
    """Make a bumpy clay seabed: smooth Gaussian mounds and hollows at random places.

    Bump centres form a Poisson process of ``density`` per m² over the area widened by three
    widths (so the edges are bumpy too). Each bump is ``h * exp(-r² / (2 s²))`` with ``|h|``
    uniform in ``[0.5, 1.5] * bump_height``, ``s`` uniform in ``[0.7, 1.3] * bump_width``, and
    ``h < 0`` (a hollow) with probability ``hollow_fraction``.

    Parameters
    ----------
    size, center, resolution, depth, seed
        As for :func:`flat`; ``resolution`` is the cell size in metres.
    bump_height : float
        Typical bump height, metres.
    bump_width : float
        Typical Gaussian standard deviation ``s`` of a bump, metres (its radius is about 2 s).
    density : float
        Bumps per square metre.
    hollow_fraction : float
        Probability that a bump is a hollow, in [0, 1].

    Returns
    -------
    Heightfield
    """
    grid = _layout(size, center, resolution)
    rng = np.random.default_rng(_seed(seed))
    height = positive("seabed 'bump_height'", bump_height)
    width = positive("seabed 'bump_width'", bump_width)
    rate = positive("seabed 'density'", density)
    hollow = fraction("seabed 'hollow_fraction'", hollow_fraction)
    if width < max(grid.dx, grid.dy):
        raise SonarRasterError(
            f"bump_width {width:g} m is narrower than a cell; use resolution <= {width:g}"
        )
    margin = 3.0 * 1.3 * width
    xmin, ymin = grid.x0 - margin, grid.y0 - margin
    wx = (grid.nx - 1) * grid.dx + 2 * margin
    wy = (grid.ny - 1) * grid.dy + 2 * margin
    count = int(rng.poisson(rate * wx * wy))
    cx = xmin + wx * rng.random(count)
    cy = ymin + wy * rng.random(count)
    sign = np.where(rng.random(count) < hollow, -1.0, 1.0)
    h = sign * height * rng.uniform(0.5, 1.5, count)
    s = width * rng.uniform(0.7, 1.3, count)
    relief = np.zeros((grid.ny, grid.nx))
    for k in range(count):
        _add_bump(relief, grid, cx[k], cy[k], h[k], s[k])
    return grid.heightfield(relief, number("seabed 'depth'", depth))


def _add_bump(relief: np.ndarray, grid: _Grid, cx: float, cy: float, h: float, s: float) -> None:
    """Add ``h * exp(-r²/(2 s²))`` around ``(cx, cy)`` to ``relief``, within 4 s (in place)."""
    i0 = max(0, math.floor((cx - 4 * s - grid.x0) / grid.dx))
    i1 = min(grid.nx, math.ceil((cx + 4 * s - grid.x0) / grid.dx) + 1)
    j0 = max(0, math.floor((cy - 4 * s - grid.y0) / grid.dy))
    j1 = min(grid.ny, math.ceil((cy + 4 * s - grid.y0) / grid.dy) + 1)
    if i0 >= i1 or j0 >= j1:
        return
    gx = _gauss((grid.x0 + grid.dx * np.arange(i0, i1) - cx) / s)
    gy = _gauss((grid.y0 + grid.dy * np.arange(j0, j1) - cy) / s)
    relief[j0:j1, i0:i1] += h * np.outer(gy, gx)


def _gauss(t: np.ndarray) -> np.ndarray:
    """Return ``exp(-t² / 2)``, held at ``exp(-700)`` (1e-304) beyond ``|t| = 37.4``.

    The floor keeps the result a normal float: no underflow under ``np.errstate(all="raise")``.
    """
    return np.exp(-0.5 * np.minimum(t * t, 1400.0))


# --------------------------------------------------------------------------- grids and files


def from_grid(
    z: np.ndarray, dx: float, dy: float | None = None, x0: float = 0.0, y0: float = 0.0
) -> Heightfield:
    """Wrap a height grid ``z[j, i]`` at ``(x0 + i * dx, y0 + j * dy)``.

    Parameters
    ----------
    z : array_like, shape (ny, nx)
        Heights in metres, finite, at least 2 x 2.
    dx : float
        Column spacing (along x), metres.
    dy : float or None
        Row spacing (along y), metres; ``None`` means ``dx``.
    x0, y0 : float
        Position of ``z[0, 0]``, metres.

    Returns
    -------
    Heightfield
    """
    return Heightfield(z, x0, y0, dx, dx if dy is None else dy)


def load_elevation(
    path: str | Path,
    resolution: float | Pair | None = None,
    *,
    origin: Pair | None = None,
) -> Heightfield:
    """Read an elevation grid (metres, z up) from ``.npy`` or a GDAL raster such as GeoTIFF.

    ``.npy``: a 2-D array ``z[j, i]`` at ``(x0 + i * dx, y0 + j * dy)``; the file holds no
    spacing, so ``resolution`` (``d`` or ``(dx, dy)``) is required, and ``origin = (x0, y0)``
    defaults to ``(0, 0)``.

    Raster (GeoTIFF, BAG, ...; read with rasterio, band 1): nodes are the pixel centres of the
    geotransform, rows flipped when needed so that y increases with the row index (columns
    likewise for x). Nodata or NaN pixels raise: fill or crop them before loading. A rotated
    geotransform raises. ``resolution``, if given, resamples (bilinearly) to that cell size; a
    raster without a geotransform is treated like ``.npy``.

    Parameters
    ----------
    path : str or Path
        The file.
    resolution : float or (float, float) or None
        Grid spacing in metres (see above).
    origin : (float, float) or None
        Position of the first node for files without georeferencing, metres.

    Returns
    -------
    Heightfield

    Raises
    ------
    SonarRasterError
        If the file is missing or unreadable, or its grid or the arguments are invalid.
    """
    path = Path(path)
    if not path.is_file():
        raise SonarRasterError(f"elevation file {path} does not exist; check the path")
    if path.suffix.lower() == ".npy":
        return _from_plain_grid(_read_npy(path), path, resolution, origin)
    z, geo = _read_raster(path)
    if geo is None:
        return _from_plain_grid(z, path, resolution, origin)
    if origin is not None:
        raise SonarRasterError(
            f"{path} is georeferenced, so its origin comes from the file; drop 'origin'"
        )
    field = Heightfield(z, *geo)
    if resolution is None:
        return field
    return field.resampled(positive("seabed 'resolution'", resolution))


def _from_plain_grid(
    z: np.ndarray, path: Path, resolution: Any, origin: Pair | None
) -> Heightfield:
    """Heightfield of a grid from a file that holds no spacing."""
    if resolution is None:
        raise SonarRasterError(f"{path} holds no grid spacing; give 'resolution' (metres per cell)")
    dx, dy = _pair("resolution", resolution, lengths=True)
    x0, y0 = (0.0, 0.0) if origin is None else _pair("origin", origin, lengths=False)
    try:
        return Heightfield(z, x0, y0, dx, dy)
    except SonarRasterError as exc:
        raise SonarRasterError(f"{path}: {exc}") from None


def _read_npy(path: Path) -> np.ndarray:
    try:
        return np.load(path, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise SonarRasterError(f"cannot read {path} as a .npy array: {exc}") from None


def _read_raster(path: Path) -> tuple[np.ndarray, tuple[float, float, float, float] | None]:
    """Band 1 oriented with y (and x) increasing with the index, and ``(x0, y0, dx, dy)``.

    The georeferencing is ``None`` for a raster with no geotransform (rows kept as stored).
    """
    import rasterio
    from rasterio.errors import NotGeoreferencedWarning, RasterioIOError

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            with rasterio.open(path) as ds:
                band = ds.read(1, masked=True)
                t = ds.transform
                georeferenced = not (t.is_identity and ds.crs is None)
    except RasterioIOError as exc:
        raise SonarRasterError(f"cannot read {path} as a raster: {exc}") from None
    missing = int(np.ma.count_masked(band))
    if missing:
        raise SonarRasterError(
            f"{path} has {missing} nodata pixel(s); fill them (e.g. gdal_fillnodata) or crop"
        )
    z = np.asarray(band.filled(np.nan), dtype=np.float64)
    if not georeferenced:
        return z, None
    if t.b != 0 or t.d != 0:
        raise SonarRasterError(f"{path} has a rotated geotransform; warp it north-up first")
    z, x0, dx = _orient(z, t.c, t.a, axis=1)
    z, y0, dy = _orient(z, t.f, t.e, axis=0)
    return z, (x0, y0, dx, dy)


def _orient(z: np.ndarray, edge: float, step: float, axis: int) -> tuple[np.ndarray, float, float]:
    """Flip ``z`` along ``axis`` if ``step < 0``; first pixel-centre coordinate and spacing."""
    n = z.shape[axis]
    if step < 0:
        return np.flip(z, axis=axis), edge + step * (n - 0.5), -step
    return z, edge + 0.5 * step, step


# --------------------------------------------------------------------------- dispatch


def _grid_file(
    *,
    path: str | Path,
    resolution: float | Pair | None = None,
    origin: Pair | None = None,
) -> Heightfield:
    """Seabed kind ``grid``: :func:`load_elevation` with keyword arguments."""
    return load_elevation(path, resolution, origin=origin)


_KINDS: dict[str, Callable[..., Heightfield]] = {
    "flat": flat,
    "rough": rough,
    "ripples": ripples,
    "bumpy": bumpy,
    "grid": _grid_file,
}


def make_seabed(kind: str, **params: Any) -> Heightfield:
    """Build a seabed by kind name, as a scene file's ``[seabed]`` table does.

    Parameters
    ----------
    kind : str
        ``"flat"``, ``"rough"``, ``"ripples"``, ``"bumpy"`` (see those functions) or ``"grid"``
        (``path=``, ``resolution=``, ``origin=``; see :func:`load_elevation`).
    **params
        Keyword arguments of that kind.

    Returns
    -------
    Heightfield

    Raises
    ------
    SonarRasterError
        If the kind or a parameter name is unknown, a required one is missing, or a value is
        invalid.
    """
    func = _KINDS.get(kind)
    if func is None:
        raise SonarRasterError(
            f"unknown seabed kind {kind!r}; use one of {', '.join(sorted(_KINDS))}"
        )
    sig = inspect.signature(func)
    valid = list(sig.parameters)
    unknown = sorted(set(params) - set(valid))
    if unknown:
        raise SonarRasterError(
            f"unknown parameter(s) {', '.join(unknown)} for seabed kind '{kind}'; "
            f"valid: {', '.join(valid)}"
        )
    required = [n for n, p in sig.parameters.items() if p.default is p.empty and n not in params]
    if required:
        raise SonarRasterError(f"seabed kind '{kind}' needs parameter(s) {', '.join(required)}")
    return func(**params)
