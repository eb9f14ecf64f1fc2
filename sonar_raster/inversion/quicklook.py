"""PNG quick-looks of sonar images and recovered maps, each with a colour bar and a scale bar.

For a survey engineer's first look (the EXR and GeoTIFF products hold the numbers): a
waterfall of the recorded image, a mosaic, a hillshaded elevation and a reflectivity map. Each
function draws one map with matplotlib's Agg canvas (no pyplot, no global state, so it is safe
in worker processes), shrinks it first to at most :data:`MAX_PIXELS` on its longer side (NaN-
aware block means) so a large raster stays quick, and writes one small PNG:

- a colour bar naming the quantity and its unit (dB re the image's 99.5th percentile,
  metres, R);
- a scale bar of a round length (1, 2 or 5 × 10ⁿ metres, about a fifth of the map's width);
- north up with an "N" arrow for georeferenced rasters; pings downward, in time order, for
  maps in (ping, cell) order;
- NaN (no data) transparent over a light grey background.

Every function takes the path to write (a temporary name from
:func:`sonar_raster.io.commit.commit` works: the format is always PNG).
"""

from __future__ import annotations

import math
import os
import warnings

import numpy as np

__all__ = [
    "MAX_PIXELS",
    "decibels",
    "hillshade_png",
    "map_png",
    "mosaic_png",
    "reflectivity_png",
    "scale_length",
    "shrink",
    "waterfall_png",
]

#: Longest side of a map in a quick-look, pixels (larger maps are block-averaged first).
MAX_PIXELS = 1000
#: Figure resolution, dots per inch.
DPI = 100
#: Background behind no-data (NaN) pixels.
NO_DATA_COLOUR = "#d9d9d9"


def shrink(values: np.ndarray, max_pixels: int = MAX_PIXELS) -> tuple[np.ndarray, int]:
    """Block means of ``values`` so that its longer side is at most ``max_pixels``.

    Parameters
    ----------
    values : ndarray, shape (rows, cols)
        A map; NaN marks no data and is left out of the means (a block of NaN stays NaN).
    max_pixels : int
        Longest side wanted.

    Returns
    -------
    shrunk : ndarray, shape (ceil(rows / k), ceil(cols / k)), float64
        Means of k × k blocks (the last blocks may be partial).
    k : int
        The block size (1: unchanged, as float64).
    """
    a = np.asarray(values, dtype=np.float64)
    if a.ndim != 2 or a.size == 0:
        raise ValueError(f"a quick-look needs a non-empty 2-D map, got shape {a.shape}")
    if max_pixels < 1:
        raise ValueError(f"max_pixels must be at least 1, got {max_pixels}")
    k = max(1, math.ceil(max(a.shape) / max_pixels))
    if k == 1:
        return a, 1
    rows, cols = math.ceil(a.shape[0] / k), math.ceil(a.shape[1] / k)
    padded = np.full((rows * k, cols * k), np.nan)
    padded[: a.shape[0], : a.shape[1]] = a
    blocks = padded.reshape(rows, k, cols, k)
    finite = np.isfinite(blocks)
    count = finite.sum(axis=(1, 3))
    total = np.where(finite, blocks, 0.0).sum(axis=(1, 3))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, total / np.maximum(count, 1), np.nan), k


def decibels(values: np.ndarray) -> np.ndarray:
    """``10 log10(values)`` where values are positive and finite, NaN elsewhere.

    Parameters
    ----------
    values : ndarray
        Intensities (linear, ≥ 0).
    """
    a = np.asarray(values, dtype=np.float64)
    ok = np.isfinite(a) & (a > 0)
    out = np.full(a.shape, np.nan)
    out[ok] = 10.0 * np.log10(a[ok])
    return out


def scale_length(width_m: float) -> float:
    """A round scale-bar length (1, 2 or 5 × 10ⁿ metres) near a fifth of ``width_m``.

    Parameters
    ----------
    width_m : float
        Width of the map, metres (> 0).
    """
    if not (math.isfinite(width_m) and width_m > 0):
        raise ValueError(f"the map width must be a positive number of metres, got {width_m}")
    target = width_m / 5.0
    power = 10.0 ** math.floor(math.log10(target))
    return max(m * power for m in (1.0, 2.0, 5.0) if m * power <= target)


def _limits(values: np.ndarray, low: float, high: float) -> tuple[float, float]:
    """Percentile limits of the finite values (0, 1 when there are none; widened if equal)."""
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return 0.0, 1.0
    lo, hi = (float(v) for v in np.percentile(finite, [low, high]))
    if hi <= lo:
        pad = max(abs(hi), 1.0) * 1e-3
        lo, hi = lo - pad, hi + pad
    return lo, hi


def _metres_text(length: float) -> str:
    return f"{length:g} m" if length >= 1 else f"{100 * length:g} cm"


def map_png(
    path: str | os.PathLike,
    values: np.ndarray,
    cell_m: float,
    *,
    along_m: float | None = None,
    cmap: str = "gray",
    vmin: float | None = None,
    vmax: float | None = None,
    label: str = "",
    title: str = "",
    north_up: bool = False,
    rgba: np.ndarray | None = None,
    x_range_m: tuple[float, float] | None = None,
    ylabel: str | None = None,
) -> None:
    """Write one map as a PNG with a colour bar and a scale bar (the other functions' core).

    Parameters
    ----------
    path : str or path-like
        PNG to write.
    values : ndarray, shape (rows, cols)
        The map (NaN = no data), row 0 at the top.
    cell_m : float
        Width of a column, metres.
    along_m : float, optional
        Height of a row, metres (default ``cell_m``: square pixels).
    cmap : str
        Matplotlib colour map of the values and the colour bar.
    vmin, vmax : float, optional
        Colour limits (default: the 1st and 99th percentiles of the finite values).
    label : str
        Colour-bar label: the quantity and its unit.
    title : str
        Figure title.
    north_up : bool
        Draw an "N" arrow (georeferenced rasters); otherwise the vertical axis is labelled
        as pings in time order.
    rgba : ndarray, shape (rows, cols, 4), optional
        Colours to show instead of ``values`` mapped through ``cmap`` (a hillshade); the
        colour bar still shows ``cmap`` between ``vmin`` and ``vmax``.
    x_range_m : (float, float), optional
        Horizontal coordinates of the left and right edges, metres: the axes are drawn with
        ticks (a waterfall: across-track range, port < 0). Default: no axes, the scale bar
        alone.
    ylabel : str, optional
        Label of the vertical axis when ``x_range_m`` is given (default "along track, m");
        "…(not to scale)" hides its ticks.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure
    from mpl_toolkits.axes_grid1 import make_axes_locatable
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    values = np.asarray(values, dtype=np.float64)
    if values.ndim != 2 or values.size == 0:
        raise ValueError(f"a quick-look needs a non-empty 2-D map, got shape {values.shape}")
    if not (math.isfinite(cell_m) and cell_m > 0):
        raise ValueError(f"cell_m must be a positive number of metres, got {cell_m}")
    along = float(along_m) if along_m else float(cell_m)
    rows, cols = values.shape
    width_m, height_m = cols * cell_m, rows * along
    if vmin is None or vmax is None:
        lo, hi = _limits(values, 1.0, 99.0)
        vmin = lo if vmin is None else vmin
        vmax = hi if vmax is None else vmax
    norm = Normalize(vmin=vmin, vmax=vmax)
    left, right = x_range_m if x_range_m is not None else (0.0, width_m)
    aspect = min(max(height_m / width_m, 0.25), 4.0)  # figure shape, within reason
    fig_w = 7.0 if aspect <= 1.0 else max(4.0, 7.0 / aspect + 1.5)
    fig = Figure(figsize=(fig_w, max(3.0, min(fig_w * aspect, 9.0)) + 0.6), dpi=DPI)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    ax.set_facecolor(NO_DATA_COLOUR)
    shown = rgba if rgba is not None else np.ma.masked_invalid(values)
    ax.imshow(shown, cmap=cmap, norm=norm, extent=(left, right, height_m, 0.0),
              interpolation="nearest", aspect="equal")  # fmt: skip
    cax = make_axes_locatable(ax).append_axes("right", size="3%", pad=0.08)
    fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), cax=cax, label=label)
    length = scale_length(width_m)
    ax.add_artist(
        AnchoredSizeBar(ax.transData, length, _metres_text(length), "lower right", pad=0.4,
                        color="black", frameon=True, size_vertical=height_m / 150.0)
    )  # fmt: skip
    if x_range_m is None:
        ax.set_xticks([])
        ax.set_yticks([])
        if not north_up:
            ax.set_ylabel("pings, in time order ↓")
    else:
        ax.set_xlabel("across track, m (port < 0 < starboard)")
        ax.set_ylabel(ylabel or "along track, m")
        if ylabel and ylabel.endswith("(not to scale)"):
            ax.set_yticks([])
    if north_up:
        ax.annotate("N", xy=(0.06, 0.96), xytext=(0.06, 0.84), xycoords="axes fraction",
                    ha="center", va="center", fontsize=11, fontweight="bold",
                    arrowprops={"arrowstyle": "-|>", "color": "black"})  # fmt: skip
    if title:
        ax.set_title(title, fontsize=10)
    fig.savefig(os.fspath(path), format="png", dpi=DPI, bbox_inches="tight",
                metadata={"Software": None})  # fmt: skip


def waterfall_png(
    path: str | os.PathLike,
    sides: dict[str, np.ndarray],
    range_bin: float,
    *,
    ping_spacing: float | None = None,
    dynamic_range_db: float = 40.0,
    title: str = "waterfall",
) -> None:
    """The recorded image as side-scan viewers show it: port on the left, in dB.

    Parameters
    ----------
    path : str or path-like
        PNG to write.
    sides : dict of str to ndarray, shape (pings, bins)
        Linear intensity per side ("port", "starboard"), columns from range 0 outward.
    range_bin : float
        Slant-range bin, metres (the horizontal axis and scale bar are slant range).
    ping_spacing : float, optional
        Along-track distance between pings, metres: rows are drawn to scale. Default: one
        row per ping, stretched to the figure.
    dynamic_range_db : float
        dB shown below the reference level (the 99.5th percentile of the positive samples).
    title : str
        Figure title.
    """
    if not sides or not all(s in ("port", "starboard") for s in sides):
        raise ValueError(f"sides must be 'port' and/or 'starboard', got {list(sides)}")
    parts = []
    if "port" in sides:
        parts.append(np.asarray(sides["port"], dtype=np.float64)[:, ::-1])
    if "starboard" in sides:
        parts.append(np.asarray(sides["starboard"], dtype=np.float64))
    both = np.concatenate(parts, axis=1)
    linear, k = shrink(both)
    db = decibels(linear)
    bins = next(iter(sides.values())).shape[1]
    left = -bins * range_bin if "port" in sides else 0.0
    right = bins * range_bin if "starboard" in sides else 0.0
    top = _limits(db, 0.0, 99.5)[1]
    if ping_spacing:
        along, ylabel = ping_spacing * k, "along track, m"
    else:  # rows stretched to a square map
        along, ylabel = (right - left) / db.shape[0], "pings, in time order (not to scale)"
    map_png(
        path,
        db,
        range_bin * k,
        along_m=along,
        vmin=top - dynamic_range_db,
        vmax=top,
        label=f"dB re {top:.1f} dB",
        title=title,
        x_range_m=(left, right),
        ylabel=ylabel,
    )


def mosaic_png(
    path: str | os.PathLike,
    values: np.ndarray,
    pixel: float,
    *,
    dynamic_range_db: float = 40.0,
    title: str = "mosaic",
    north_up: bool = True,
) -> None:
    """A georeferenced image (linear intensity) in dB, grey, north up.

    Parameters
    ----------
    path : str or path-like
        PNG to write.
    values : ndarray, shape (rows, cols)
        Linear intensity, NaN = no data; row 0 is the northern edge.
    pixel : float
        Pixel size, metres.
    dynamic_range_db : float
        dB shown below the reference level (the 99.5th percentile of the positive values).
    title : str
        Figure title.
    north_up : bool
        Rows run north to south (draws the "N" arrow).
    """
    linear, k = shrink(values)
    db = decibels(linear)
    top = _limits(db, 0.0, 99.5)[1]
    map_png(path, db, pixel * k, vmin=top - dynamic_range_db, vmax=top,
            label=f"dB re {top:.1f} dB", title=title, north_up=north_up)  # fmt: skip


def hillshade_png(
    path: str | os.PathLike,
    elevation: np.ndarray,
    cell_m: float,
    *,
    along_m: float | None = None,
    azimuth_deg: float = 315.0,
    altitude_deg: float = 45.0,
    exaggeration: float = 1.0,
    cmap: str = "viridis",
    title: str = "elevation",
    label: str = "elevation, m",
    north_up: bool = True,
) -> None:
    """Elevation coloured by height and shaded by a light from ``azimuth_deg``.

    Parameters
    ----------
    path : str or path-like
        PNG to write.
    elevation : ndarray, shape (rows, cols)
        Heights, metres (NaN = no data; shaded as the median and left transparent).
    cell_m : float
        Width of a column, metres.
    along_m : float, optional
        Height of a row, metres (default ``cell_m``).
    azimuth_deg, altitude_deg : float
        Direction the light comes from, degrees clockwise from the top of the map, and its
        height above the horizon (matplotlib's ``LightSource``).
    exaggeration : float
        Vertical exaggeration of the shading (the colours are true heights).
    cmap : str
        Colour map of the heights.
    title, label : str
        Figure title and colour-bar label.
    north_up : bool
        The map is georeferenced, north up; False: rows are pings in time order.
    """
    from matplotlib import colormaps
    from matplotlib.colors import LightSource, Normalize

    z, k = shrink(elevation)
    dx = cell_m * k
    dy = (along_m or cell_m) * k
    lo, hi = _limits(z, 1.0, 99.0)
    finite = np.isfinite(z)
    filled = np.where(finite, z, np.median(z[finite]) if finite.any() else 0.0)
    light = LightSource(azdeg=azimuth_deg, altdeg=altitude_deg)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a flat map: zero-range intensity
        rgba = light.shade(filled, cmap=colormaps[cmap], norm=Normalize(lo, hi), blend_mode="soft",
                           vert_exag=exaggeration, dx=dx, dy=dy)  # fmt: skip
    rgba[..., 3] = np.where(finite, 1.0, 0.0)
    map_png(path, z, dx, along_m=None if along_m is None else dy, cmap=cmap, vmin=lo, vmax=hi,
            label=label, title=title, north_up=north_up, rgba=rgba)  # fmt: skip


def reflectivity_png(
    path: str | os.PathLike,
    values: np.ndarray,
    cell_m: float,
    *,
    along_m: float | None = None,
    cmap: str = "cividis",
    title: str = "reflectivity",
    north_up: bool = True,
) -> None:
    """Recovered reflectivity R between its 1st and 99th percentiles.

    Parameters
    ----------
    path : str or path-like
        PNG to write.
    values : ndarray, shape (rows, cols)
        R (NaN = no data).
    cell_m : float
        Width of a column, metres.
    along_m : float, optional
        Height of a row, metres (default ``cell_m``).
    cmap : str
        Colour map.
    title : str
        Figure title.
    north_up : bool
        The map is georeferenced, north up; False: rows are pings in time order.
    """
    r, k = shrink(values)
    map_png(path, r, cell_m * k, along_m=None if along_m is None else along_m * k, cmap=cmap,
            label="reflectivity R", title=title, north_up=north_up)  # fmt: skip
