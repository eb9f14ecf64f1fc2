"""Mosaic coverage: footprint splatting against point gridding on a real recording.

Inverts FILE.xtf once (``invert_xtf``), then grids its maps both ways in one process
(``georeference(..., method="points")``, the earlier gridding, and ``method="footprint"``) and
prints, per method, the share of NaN pixels inside the swath, the gridding time, and the
mosaic's nadir contrast (median of the mosaic within 1 m of the track over the median 3-6 m
out, dB; the per-metre ground image it replaced is printed too). The swath is independent of
both methods: per ping interval, the quadrilateral between the two pings' outermost cells with
a value on each side, rasterised at pixel centres and eroded by one pixel. Writes
before/after quick-looks (``sonar_raster.inversion.quicklook.mosaic_png``) of the whole
mosaic and of a far-range crop into ``--out``.

    python tools/bench_mosaic.py [FILE.xtf] [--max-iter 40] [--out docs/notes/2026-11-24-mosaic]
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from _common import DOCS, REAL_XTF, parser


def swath_mask(result, raster) -> np.ndarray:
    """Pixels (rows, cols) whose centre lies between the outermost valued cells of each ping
    interval, eroded by one pixel."""
    from scipy.ndimage import binary_erosion
    from skimage.draw import polygon

    from sonar_raster.inversion.xtf import ground_positions, robust_track

    nav = result.navigation
    east, north = robust_track(nav)
    heading, pitch = nav.filled_heading(), nav.filled("pitch")
    far = {}
    for side, inv in result.sides.items():
        e, n = ground_positions(east, north, heading, pitch, inv.x, inv.elevation, side)
        valued = np.isfinite(inv.ground)
        last = np.where(valued.any(axis=1), valued.shape[1] - 1 - np.argmax(valued[:, ::-1], 1), 0)
        rows = np.arange(len(last))
        far[side] = (e[rows, last], n[rows, last])
    shape = raster.layers["mosaic"].shape
    mask = np.zeros(shape, dtype=bool)
    (pe, pn), (se, sn) = far["port"], far["starboard"]
    for i in range(len(pe) - 1):
        xs = np.array([pe[i], pe[i + 1], se[i + 1], se[i]])
        ys = np.array([pn[i], pn[i + 1], sn[i + 1], sn[i]])
        r, c = polygon((raster.north - ys) / raster.pixel - 0.5,
                       (xs - raster.west) / raster.pixel - 0.5, shape)  # fmt: skip
        mask[r, c] = True
    return binary_erosion(mask)


def nadir_contrast(result, raster, layer: np.ndarray) -> float:
    """Median of ``layer`` within 1 m of the track over its median 3-6 m out, dB."""
    from sonar_raster.inversion.xtf import robust_track

    east, north = robust_track(result.navigation)
    rows, cols = np.nonzero(np.isfinite(layer) & (layer > 0))
    e = raster.west + (cols + 0.5) * raster.pixel
    n = raster.north - (rows + 0.5) * raster.pixel
    step = max(1, len(east) // 400)
    track = np.stack([east[::step], north[::step]], axis=1)
    from scipy.spatial import cKDTree

    dist = cKDTree(track).query(np.stack([e, n], axis=1))[0]
    values = layer[rows, cols]
    near, off = values[dist < 1.0], values[(dist > 3.0) & (dist < 6.0)]
    return float(10 * np.log10(np.median(near) / np.median(off)))


def per_metre(result, pixel: float, crs, method: str):
    """The values the mosaic showed before (the per-metre ground image), gridded by ``method``."""
    from sonar_raster.inversion.xtf import grid, ground_positions, robust_track

    nav = result.navigation
    east, north = robust_track(nav)
    samples = []
    for side, inv in result.sides.items():
        e, n = ground_positions(east, north, nav.filled_heading(), nav.filled("pitch"), inv.x,
                                inv.elevation, side)  # fmt: skip
        samples.append((e, n, {"mosaic": inv.ground}))
    step = float(np.max(np.hypot(np.diff(east), np.diff(north))))
    factor = max(1, int(np.ceil(2.0 * step / pixel)))
    return grid(samples, pixel, crs, factor, method=method)


def load(path: Path, max_iter: int, cache: Path | None):
    """``invert_xtf(path)``, or its pickle from an earlier run (``--cache``)."""
    import pickle

    from sonar_raster.inversion.xtf import invert_xtf

    if cache is not None and cache.is_file():
        with open(cache, "rb") as fh:
            return pickle.load(fh)
    start = time.perf_counter()
    result = invert_xtf(path, max_iter=max_iter)
    print(f"inversion {time.perf_counter() - start:.1f} s")
    if cache is not None:
        with open(cache, "wb") as fh:
            pickle.dump(result, fh)
    return result


def main() -> None:
    ap = parser(__doc__, DOCS / "notes" / "2026-11-24-mosaic")
    ap.add_argument("xtf", nargs="?", type=Path, default=REAL_XTF)
    ap.add_argument("--max-iter", type=int, default=40)
    ap.add_argument("--cache", type=Path, help="pickle of the inversion, made when missing")
    args = ap.parse_args()
    from sonar_raster.inversion.quicklook import mosaic_png, shrink
    from sonar_raster.inversion.xtf import georeference

    result = load(args.xtf, args.max_iter, args.cache)
    args.out.mkdir(parents=True, exist_ok=True)
    print(
        "| values | gridding | s | NaN in the raster | NaN inside the swath | nadir / 3-6 m out |"
    )
    print("|---|---|---|---|---|---|")
    rasters = {}
    for values in ("per metre of ground (before)", "evenly illuminated (after)"):
        for method in ("points", "footprint"):
            start = time.perf_counter()
            if values.startswith("per metre"):
                pixel, crs = rasters["pixel"] if "pixel" in rasters else (None, None)
                if pixel is None:
                    ref = georeference(result, method="points")
                    pixel, crs = rasters["pixel"] = (ref.pixel, ref.crs)
                    start = time.perf_counter()
                raster = per_metre(result, pixel, crs, method)
            else:
                raster = georeference(result, method=method)
            seconds = time.perf_counter() - start
            mosaic = raster.layers["mosaic"]
            rasters[(values, method)] = raster
            mask = swath_mask(result, raster)
            holes = int(np.isnan(mosaic[mask]).sum())
            contrast = nadir_contrast(result, raster, mosaic)
            print(f"| {values} | {method} | {seconds:.2f} | {100 * np.isnan(mosaic).mean():.1f} % "
                  f"| {100 * holes / mask.sum():.2f} % ({holes} of {mask.sum()}) | "
                  f"{contrast:+.1f} dB |")  # fmt: skip
    before = rasters[("per metre of ground (before)", "points")]
    after = rasters[("evenly illuminated (after)", "footprint")]
    rows, cols = before.layers["mosaic"].shape
    crop = (slice(int(0.33 * rows), int(0.63 * rows)), slice(int(0.05 * cols), int(0.35 * cols)))
    for name, raster, title in (
        ("before", before, "before: point gridding, per metre of ground range"),
        ("after", after, "after: footprints splatted, evenly illuminated"),
    ):
        small, k = shrink(raster.layers["mosaic"], 500)  # keeps the note's pictures small
        mosaic_png(args.out / f"{name}.png", small, raster.pixel * k, title=title)
        mosaic_png(args.out / f"{name}_crop.png", raster.layers["mosaic"][crop], raster.pixel,
                   title=f"{name}: far port range (crop)")  # fmt: skip
    print(f"wrote {args.out}/before.png, after.png, before_crop.png, after_crop.png")


if __name__ == "__main__":
    main()
