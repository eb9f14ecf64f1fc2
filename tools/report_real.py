"""A report on a real side-scan XTF pass: waterfall, altitude, inversion, wreck height.

Usage: ``python tools/report_real.py FILE.xtf -o DIR [--pings A:B] [--max-iter N]
[--levels N] [--side starboard] [--method auto|profiles|surface] [--law NAME]`` (``auto``,
the default, chooses as ``sonar-raster invert`` does: the surface fit for a speckled file it
can afford)

Writes into DIR:

- ``waterfall.png``: both channels, port on the left (range increasing to the left), in dB,
  with the tracked altitude;
- ``altitude.png``: the bottom track (``sonar_raster.track_bottom``) against the file's
  own altitude field;
- ``inversion.png``: recovered elevation Z and reflectivity R of both sides (pings × ground
  range, port on the left), and the georeferenced elevation (``elevation.tif``, UTM);
- ``SIDE/``: the inversion products of each side (``write_products``), with the 3D previews
  of the recovered seabed (``preview_az*.png``) when OpenGL is available, else
  ``hillshade.png`` of the elevation;
- ``shadow.png``: the object side normalised by its seabed level, the detected highlight and
  shadow per ping, and the height from each ping's shadow;
- ``bands.png``: the open seabed's level per ping (world vertical) and its along-track bands;
- ``report.md`` / ``report.json``: every number below.

Along-track bands on the open seabed: per ping and side, the median of the world elevation
(``Z cos p`` minus the sensor depth, as in ``elevation.tif``) over the cells from 2 m ground
range to the swath's end (on the object side without the wreck's cells, highlight to 2 m past
its shadow); a band is that level minus a robust local straight line (LOWESS) over
``--band-window`` metres of track (the seabed's own slope along track is not a band; a sharp
change of slope reads as a small band). Reported: the bands' std and the deepest and highest,
and, for comparison, the same per-ping levels relative to the transducer, which follow the
vehicle's altitude.

Wreck height, two ways, on the object side (``--side``, starboard for the sample file):

1. From the acoustic shadow (``inversion.shadows``): per ping, a shadow directly behind
   a highlight gives ``H = Ls h / (R + Ls)`` (slant ranges, h the tracked altitude). This
   holds in the side-scan fan, which a pitch p tilts from the vertical, so the vertical
   height is that times ``cos p``. The longest run of pings with a shadow is the wreck; its
   height is the 90th percentile of H over them (the median and the maximum are reported
   too). Shadows running to the end of the range within 20 pings of the wreck give only a
   lower bound, reported separately.
2. From the recovered elevation. The same pings' cells from the highlight's start to the
   shadow's start (converted to ground range over a flat seabed at the tracked altitude) are
   the wreck; the seabed is the same pings' cells from 2 m beyond the shadow's end. The
   height is the 90th percentile of Z cos p on the wreck minus the median of Z cos p on
   the seabed.
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import numpy as np
from _common import parser

from sonar_raster.cli.track import draw_waterfall, parse_pings
from sonar_raster.errors import SonarRasterError
from sonar_raster.inversion.shadows import find_shadows, object_pings
from sonar_raster.inversion.xtf import georeference, geotiff_jobs, invert_xtf, world_elevation
from sonar_raster.io.commit import commit

SEABED_BEYOND_M = 2.0
#: Open seabed for the bands: from this ground range to the swath's end, metres.
BAND_NEAR_M = 2.0


def local_line(level: np.ndarray, half: int, rounds: int = 3) -> np.ndarray:
    """LOWESS of ``level`` (NaN = missing): a robust local straight line over ±``half`` samples.

    Tricube weights by distance, bisquare weights by residual (6 median absolute residuals)
    refitted ``rounds`` times; exact for a straight line, at the ends too. A band narrower than
    the window is left in the residual; the seabed's slope is not.
    """
    n = len(level)
    ok = np.isfinite(level)
    fit = np.full(n, np.nan)
    robust = np.ones(n)
    for _ in range(rounds + 1):
        for i in range(n):
            j = np.arange(max(0, i - half), min(n, i + half + 1))
            j = j[ok[j]]
            if len(j) < 3:
                continue
            w = (1.0 - (np.abs(j - i) / (half + 1.0)) ** 3) ** 3 * robust[j]
            if w.sum() <= 0:
                continue
            a = np.polyfit(j - i, level[j], 1, w=np.sqrt(w))
            fit[i] = a[1]
        resid = np.where(ok, level - fit, np.nan)
        scale = 6.0 * np.nanmedian(np.abs(resid))
        if not scale > 0:
            break
        robust = np.where(ok, np.clip(1.0 - (resid / scale) ** 2, 0.0, 1.0) ** 2, 0.0)
    return fit


def open_seabed_level(levels: np.ndarray, x: np.ndarray, exclude: np.ndarray) -> np.ndarray:
    """Per ping, the median of ``levels`` (pings, cells) from ``BAND_NEAR_M`` ground range on,
    ``exclude``'s cells left out (the wreck); NaN where a ping has none."""
    z = np.where((x >= BAND_NEAR_M)[None, :] & ~exclude, levels, np.nan)
    has = np.isfinite(z).any(axis=1)
    level = np.full(len(z), np.nan)
    level[has] = np.nanmedian(z[has], axis=1)
    return level


def along_track_bands(level: np.ndarray, spacing: float, window_m: float) -> dict:
    """Bands of one side: its open-seabed level per ping minus a robust local line."""
    half = max(2, int(round(0.5 * window_m / max(spacing, 1e-9))))
    band = level - local_line(level, half)
    ok = np.isfinite(band)
    if not ok.any():
        return {"pings": 0}
    return {
        "pings": int(ok.sum()),
        "window_pings": 2 * half + 1,
        "std_m": float(np.std(band[ok])),
        "deepest_m": float(np.min(band[ok])),
        "highest_m": float(np.max(band[ok])),
        "level_min_max_m": [float(np.min(level[ok])), float(np.max(level[ok]))],
        "level": level,
        "band": band,
    }


def elevation_height(
    inv, shadow: dict, range_bin: float, wreck: np.ndarray, pitch: np.ndarray
) -> dict:
    """Wreck height from the recovered Z: 90th percentile on the wreck minus seabed median."""
    x = inv.x
    on, off = [], []
    for i in np.flatnonzero(wreck):
        h = inv.altitude[i]

        def ground(k, h=h):
            return math.sqrt(max((k * range_bin) ** 2 - h * h, 0.0))

        x0, x1 = ground(shadow["highlight"][i]), ground(shadow["start"][i])
        x2 = ground(shadow["end"][i]) + SEABED_BEYOND_M
        z = inv.elevation[i] * math.cos(pitch[i])
        on.append(z[(x >= x0) & (x <= x1) & np.isfinite(z)])
        off.append(z[(x >= x2) & np.isfinite(z)])
    z_on, z_off = np.concatenate(on or [[]]), np.concatenate(off or [[]])
    if z_on.size == 0 or z_off.size == 0:
        return {"height_m": math.nan}
    seabed = float(np.median(z_off))
    return {
        "height_m": float(np.percentile(z_on, 90) - seabed),
        "max_m": float(np.max(z_on) - seabed),
        "median_on_wreck_m": float(np.median(z_on) - seabed),
        "seabed_z_m": seabed,
        "wreck_cells": int(z_on.size),
        "seabed_cells": int(z_off.size),
    }


def _bound_note(doc: dict) -> str:
    if doc["truncated_lower_bound_m"] is None:
        return ""
    rows = doc["truncated_pings"]
    return (
        f" Shadows running to the end of the range on {len(rows)} ping(s) ({rows[0]}–{rows[-1]})"
        f" give only a lower bound there: H >= {doc['truncated_lower_bound_m']:.2f} m."
    )


def _maps_figure(path: Path, result, raster) -> None:
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(18, 7))
    sides = result.sides
    for ax, name, cmap in ((axes[0], "elevation", "viridis"), (axes[1], "reflectivity", "gray")):
        parts, extent_l, extent_r = [], 0.0, 0.0
        if "port" in sides:
            parts.append(getattr(sides["port"], name)[:, ::-1])
            extent_l = -float(sides["port"].x[-1])
        if "starboard" in sides:
            parts.append(getattr(sides["starboard"], name))
            extent_r = float(sides["starboard"].x[-1])
        values = np.hstack(parts)
        lo, hi = np.nanpercentile(values, [1, 99])
        im = ax.imshow(values, aspect="auto", cmap=cmap, vmin=lo, vmax=hi,
                       extent=(extent_l, extent_r, values.shape[0] - 0.5, -0.5))  # fmt: skip
        fig.colorbar(im, ax=ax, shrink=0.8, label="Z, m (rel. transducer)" if name == "elevation"
                     else "R")  # fmt: skip
        ax.set_title(f"recovered {name}")
        ax.set_xlabel("ground range, m (port < 0 < starboard)")
        ax.set_ylabel("ping")
    ax = axes[2]
    if raster is not None:
        z = raster.layers["elevation"]
        lo, hi = np.nanpercentile(z, [1, 99])
        extent = (0, z.shape[1] * raster.pixel, 0, z.shape[0] * raster.pixel)
        im = ax.imshow(z, cmap="viridis", vmin=lo, vmax=hi, extent=extent)
        fig.colorbar(im, ax=ax, shrink=0.8, label="seabed elevation, m")
        ax.set_title(f"elevation.tif ({raster.crs}), origin E {raster.west:.1f} N "
                     f"{raster.north - z.shape[0] * raster.pixel:.1f}")  # fmt: skip
        ax.set_xlabel("east, m")
        ax.set_ylabel("north, m")
    else:
        ax.set_axis_off()
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _hillshade(path: Path, z: np.ndarray, dx: float, dy: float) -> None:
    import matplotlib.pyplot as plt

    zz = np.where(np.isfinite(z), z, np.nanmedian(z))
    gy, gx = np.gradient(zz, dy, dx)
    az, alt = math.radians(315.0), math.radians(35.0)
    slope = np.arctan(np.hypot(gx, gy))
    aspect = np.arctan2(-gx, gy)
    shade = np.sin(alt) * np.cos(slope) + np.cos(alt) * np.sin(slope) * np.cos(az - aspect)
    fig, ax = plt.subplots(figsize=(10, 6))
    ax.imshow(shade, cmap="gray", aspect="auto")
    ax.set_title("hillshade of the recovered elevation")
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _shadow_figure(path: Path, shadow: dict, wreck: np.ndarray, dr: float, side: str) -> None:
    import matplotlib.pyplot as plt

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(16, 7), width_ratios=(2, 1))
    ratio = shadow["ratio"]
    extent = (0, ratio.shape[1] * dr, ratio.shape[0] - 0.5, -0.5)
    db = 10 * np.log10(np.maximum(ratio, 1e-3))
    ax.imshow(db, cmap="gray", vmin=-15, vmax=6, aspect="auto", extent=extent)
    rows = np.flatnonzero(wreck)
    for key, colour in (("highlight", "y"), ("start", "r"), ("end", "c")):
        ax.plot(shadow[key][rows] * dr, rows, ".", color=colour, ms=2, label=key)
    ax.legend(loc="lower right")
    ax.set_xlabel(f"{side} slant range, m")
    ax.set_ylabel("ping")
    ax.set_title("intensity / seabed level (dB); highlight start, shadow start and end")
    bx.plot(shadow["height"], np.arange(len(ratio)), "k.", ms=3, label="shadow inside range")
    bx.plot(shadow["bound"], np.arange(len(ratio)), "r>", ms=3, label="lower bound (cut)")
    bx.legend(loc="lower right")
    bx.invert_yaxis()
    bx.set_xlabel("H = Ls h / (R + Ls), m")
    bx.set_title("height from each ping's shadow")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _bands(result, shadow: dict, wreck: np.ndarray, dr: float, window: float, png: Path) -> dict:
    """:func:`along_track_bands` of each side, world vertical and relative to the transducer."""
    import matplotlib.pyplot as plt

    world = world_elevation(result)
    spacing = result.navigation.along_track_spacing()
    bands = {}
    fig, axes = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for side, inv in result.sides.items():
        exclude = np.zeros(inv.elevation.shape, dtype=bool)
        for i in np.flatnonzero(wreck) if side == shadow["side"] else []:
            h = inv.altitude[i]
            x0 = math.sqrt(max((shadow["highlight"][i] * dr) ** 2 - h * h, 0.0))
            x1 = math.sqrt(max((shadow["end"][i] * dr) ** 2 - h * h, 0.0)) + SEABED_BEYOND_M
            exclude[i] = (inv.x >= x0) & (inv.x <= x1)
        b = along_track_bands(open_seabed_level(world[side], inv.x, exclude), spacing, window)
        about = open_seabed_level(inv.elevation, inv.x, exclude)  # relative to the transducer
        about -= np.nanmedian(about)
        b["transducer_frame_std_m"] = float(np.nanstd(about))
        b["transducer_frame_deepest_m"] = float(np.nanmin(about))
        bands[side] = b
        axes[0].plot(b["level"], label=side)
        axes[1].plot(b["band"], label=side)
    axes[0].set_ylabel("open-seabed level, m")
    axes[1].set_ylabel(f"band (minus a {window:g} m local line), m")
    axes[1].set_xlabel("ping")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend()
    fig.savefig(png, dpi=90)
    plt.close(fig)
    return bands


def _bands_text(bands: dict, window: float) -> str:
    lines = []
    for side, b in bands.items():
        if not b.get("pings"):
            lines.append(f"- {side}: no open seabed")
            continue
        lo, hi = b["level_min_max_m"]
        lines.append(
            f"- {side}: bands std **{b['std_m']:.3f} m**, deepest {b['deepest_m']:+.3f} m, "
            f"highest {b['highest_m']:+.3f} m ({b['pings']} pings, against a robust local line "
            f"over {b['window_pings']} pings ≈ {window:g} m); the level itself runs from "
            f"{lo:.2f} to {hi:.2f} m. Relative to the transducer the same levels have std "
            f"{b['transducer_frame_std_m']:.3f} m, deepest "
            f"{b['transducer_frame_deepest_m']:+.3f} m (the vehicle's altitude changes)."
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    try:
        return _report(argv)
    except SonarRasterError as exc:
        print(f"report_real: error: {exc}", file=sys.stderr)
        return 2


def _report(argv: list[str] | None) -> int:
    ap = parser(__doc__)
    ap.add_argument("xtf")
    ap.add_argument("-o", "--output", required=True)
    ap.add_argument("--pings", help="ping range A:B (default: all)")
    ap.add_argument("--max-iter", type=int, default=40)
    ap.add_argument("--levels", type=int, default=3)
    ap.add_argument(
        "--method",
        default="auto",
        choices=("auto", "profiles", "surface"),
        help="the inversion (surface: one surface for both sides, its own levels; auto, the "
        "default: as sonar-raster invert chooses)",
    )
    ap.add_argument("--side", default="starboard", choices=("port", "starboard"),
                        help="the side with the object")  # fmt: skip
    ap.add_argument("--band-window", type=float, default=5.0,
                    help="metres of track: the seabed's own level (5)")  # fmt: skip
    ap.add_argument("--law", help="surface fit: the seabed's scattering law (a sediment's "
                    "name, taken at the file's frequency; default Lambert's)")  # fmt: skip
    args = ap.parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sonar_raster.inversion.write import write_products

    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    recording = None
    if args.method == "auto":  # as sonar-raster invert chooses, the file read once
        from sonar_raster.inversion.method import choose_method
        from sonar_raster.io.xtf import read_xtf

        recording = read_xtf(args.xtf, parse_pings(args.pings))
        sides = recording[0].sides  # amplitudes: their squares, as invert_xtf takes them
        choice = choose_method([{s: np.square(v.astype(np.float64)) for s, v in sides.items()}])
        args.method = choice.method
        print(choice.reason, flush=True)
    options = {"max_iter": args.max_iter}
    if args.method == "profiles":
        options["levels"] = args.levels
    if args.law:
        options["law"] = args.law
    result = invert_xtf(args.xtf, pings=parse_pings(args.pings), method=args.method,
                        recording=recording, **options)  # fmt: skip
    seconds = time.perf_counter() - t0
    image, nav, track = result.image, result.navigation, result.track
    dr = image.sonar.range_bin
    if args.side not in image.sides:
        raise SonarRasterError(
            f"{args.xtf} has no {args.side} side (it has {', '.join(image.sides)}); give --side"
        )

    fig, ax = plt.subplots(figsize=(10, 9))
    draw_waterfall(ax, image, track.altitude)
    ax.set_title(f"{Path(args.xtf).name}: waterfall (port left), tracked altitude in cyan")
    fig.savefig(out / "waterfall.png", dpi=90)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(9, 4))
    ax.plot(track.altitude, "k-", label="tracked (first return, both sides)")
    if np.isfinite(nav.altitude).any():
        ax.plot(nav.altitude, "c-", lw=0.8, label="file: SensorPrimaryAltitude")
    ax.set_xlabel("ping")
    ax.set_ylabel("altitude, m")
    ax.legend()
    ax.grid(alpha=0.3)
    fig.savefig(out / "altitude.png", dpi=90)
    plt.close(fig)

    raster = georeference(result) if nav.valid.any() else None
    if raster is not None:
        commit(geotiff_jobs(out, raster))
    _maps_figure(out / "inversion.png", result, raster)
    preview = "preview_az*.png"
    for side, inv in result.sides.items():
        try:
            write_products(inv, out / side, side, dr)
        except SonarRasterError as exc:  # no OpenGL: no preview renders
            print(f"{side}: previews unavailable ({exc}); writing hillshade.png", file=sys.stderr)
            write_products(inv, out / side, side, dr, previews=False)
            _hillshade(out / side / "hillshade.png", inv.elevation, float(inv.x[1] - inv.x[0]),
                       nav.along_track_spacing())  # fmt: skip
            preview = "hillshade.png"

    side = args.side
    slant = image.sides[side].astype(np.float64) ** 2  # intensity, as inverted
    found = find_shadows(slant, dr, track.altitude)
    pitch = nav.filled("pitch")
    shadow = {
        "side": side,
        "highlight": found.highlight,
        "start": found.start,
        "end": found.end,
        "ratio": found.ratio,
        "height": found.height * np.cos(pitch),  # in the fan -> vertical
        "bound": found.bound * np.cos(pitch),
    }
    wreck = object_pings(shadow["height"])
    h = shadow["height"][wreck]
    near = np.zeros_like(wreck)
    if wreck.any():  # truncated shadows within 20 pings of the wreck
        rows = np.flatnonzero(wreck)
        near[max(0, rows[0] - 20) : rows[-1] + 21] = True
    bounds = shadow["bound"][near & np.isfinite(shadow["bound"])]
    _shadow_figure(out / "shadow.png", shadow, wreck, dr, side)
    from_shadow = {
        "height_m": float(np.percentile(h, 90)) if h.size else math.nan,
        "median_m": float(np.median(h)) if h.size else math.nan,
        "max_m": float(np.max(h)) if h.size else math.nan,
        "pings": [int(np.flatnonzero(wreck)[0]), int(np.flatnonzero(wreck)[-1])] if h.size else [],
        "pings_with_shadow": int(h.size),
        "truncated_lower_bound_m": float(np.max(bounds)) if bounds.size else None,
        "truncated_pings": [int(i) for i in np.flatnonzero(near & np.isfinite(shadow["bound"]))],
    }
    from_z = (
        elevation_height(result.sides[side], shadow, dr, wreck, pitch)
        if side in result.sides and h.size
        else {"height_m": math.nan}
    )
    bands = _bands(result, shadow, wreck, dr, args.band_window, out / "bands.png")
    first = int(image.metadata["first_ping_index"])
    doc = {
        "file": str(args.xtf),
        "pings": [first, first + image.shape[0]],
        "bins": image.shape[1],
        "range_bin_m": dr,
        "slant_range_m": dr * image.shape[1],
        "sound_speed_m_s": image.sonar.sound_speed,
        "navigation": {
            "units": nav.units,
            "crs": raster.crs if raster else None,
            "pings_with_fix": int(nav.valid.sum()),
            "along_track_spacing_m": nav.along_track_spacing(),
        },  # fmt: skip
        "altitude": {
            "tracked_min_median_max_m": [
                float(track.altitude.min()),
                float(np.median(track.altitude)),
                float(track.altitude.max()),
            ],  # fmt: skip
            "valid_pings": int(track.valid.sum()),
            "tracked_minus_file_median_m": float(np.nanmedian(track.altitude - nav.altitude)),
        },
        "inversion": {
            "method": args.method,
            "law": args.law or "lambert",
            "max_iter": args.max_iter,
            "levels": args.levels,
            "seconds": seconds,
            "energy": {
                s: [[e[0], e[-1], len(e) - 1] for e in inv.energies]
                for s, inv in result.sides.items()
            },  # fmt: skip
        },
        "wreck_side": side,
        "wreck_height_from_shadow": from_shadow,
        "wreck_height_from_elevation": from_z,
        "bands": {
            s: {k: v for k, v in b.items() if k not in ("level", "band")} for s, b in bands.items()
        },
        "preview": f"{side}/{preview}",
    }
    (out / "report.json").write_text(json.dumps(doc, indent=1))
    md = f"""# Real-data report: {Path(args.xtf).name}

Pings {doc["pings"][0]}–{doc["pings"][1]}, {image.shape[1]} samples per side,
slant range {doc["slant_range_m"]:.2f} m (bin {dr * 100:.2f} cm), sound speed
{image.sonar.sound_speed:.0f} m/s. Navigation: {nav.units}, {doc["navigation"]["pings_with_fix"]}
pings with a fix, GeoTIFFs in {doc["navigation"]["crs"]}, {nav.along_track_spacing():.3f} m per
ping.

![waterfall](waterfall.png)

Altitude (bottom track, both sides): min {doc["altitude"]["tracked_min_median_max_m"][0]:.2f},
median {doc["altitude"]["tracked_min_median_max_m"][1]:.2f}, max
{doc["altitude"]["tracked_min_median_max_m"][2]:.2f} m; {track.valid.sum()} of
{len(track.valid)} pings with a clear return; tracked − file altitude, median
{doc["altitude"]["tracked_minus_file_median_m"]:+.2f} m.

![altitude](altitude.png)

Inversion ({args.method}; {args.levels} levels for the profiles, at most {args.max_iter}
iterations per level and start): {seconds:.0f} s for {len(result.sides)} side(s).

![inversion](inversion.png)

3D preview / hillshade: `{doc["preview"]}`.

![shadow](shadow.png)

## Wreck height ({side})

- From the acoustic shadow, H = Ls·h/(R + Ls): **{from_shadow["height_m"]:.2f} m** (90th
  percentile over {from_shadow["pings_with_shadow"]} pings {from_shadow["pings"]}; median
  {from_shadow["median_m"]:.2f} m, max {from_shadow["max_m"]:.2f} m).{_bound_note(from_shadow)}
- From the recovered elevation map: **{from_z["height_m"]:.2f} m** (90th percentile of Z on the
  wreck minus the median of the seabed beyond its shadow).

## Along-track bands on the open seabed

{_bands_text(doc["bands"], args.band_window)}

![bands](bands.png)
"""
    (out / "report.md").write_text(md)
    print(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
