"""Compare a simulated side-scan image with the real XTF pass, with the numbers an engineer checks.

Reads ``../shared/data/xtf/scotsman-iver2.xtf`` (Marine Sonic HDS, 600 kHz, Iver2 AUV) with
pyxtf directly, then renders a flat sandy seabed at the same slant range, bin size and ping
spacing, along a track whose altitude follows the real first bottom return ping by ping (the
vehicle dives through the file, from about 11 m to 3 m altitude), applies the sensor effects,
and prints, per side:

* mean intensity against slant range (real and simulated, each normalised to its own mean over
  the range window every ping sees as seabed), in dB, and the RMS difference;
* speckle contrast (std / mean of intensity) in homogeneous 16 × 16 patches: median and
  quartiles, and how many patches passed the homogeneity test;
* lag-1 correlation of normalised intensity along track and along range (the speckle cell);
* distances between the histograms of normalised intensity (intensity over its local mean):
  Kolmogorov-Smirnov statistic and Bhattacharyya distance.

The real samples are taken as amplitudes (intensity = sample²): the squared samples have the
contrast near 1 of fully developed speckle, the samples themselves near 0.52 (Rayleigh). The
HDS's vertical beam is not in the file: a Gaussian beam's width and tilt are fitted to the real
mean profile with a thin-fan closed form (``--beam-deg``/``--tilt-deg`` fix them instead). The
starboard wreck (OpenSidescan hit at ping 138; rows 98-377 hold it and its shadow) is masked
out of the statistics.

Usage: ``python tools/compare_real.py [--xtf PATH] [--along-beam-deg 0.5] [--png out.png]``.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from _common import REAL_XTF, parser
from scipy import ndimage, stats

DEFAULT_XTF = REAL_XTF
SKIP_PINGS = 8  # the first pings have no navigation and a settling altitude
PATCH = 16
WRECK_ROWS = (-40, 240)  # rows around the annotated hit ping holding the wreck and its shadow


@dataclass
class RealPass:
    sides: dict[str, np.ndarray]  # intensity (sample²), (pings, bins), near to far
    samples: dict[str, np.ndarray]  # raw uint16 samples as float, near to far
    range_bin: float
    max_range: float
    frequency_hz: float
    ping_spacing: float
    hits: list[tuple[int, int]]  # (ping, sample) targets


def read_real(path: Path) -> RealPass:
    """Read both channels near-to-far with pyxtf; port is stored far-to-near in this file."""
    import pyxtf

    header, packets = pyxtf.xtf_read(str(path))
    pings = packets[pyxtf.XTFHeaderType.sonar]
    port = np.array([p.data[0] for p in pings], dtype=np.float64)[:, ::-1]
    star = np.array([p.data[1] for p in pings], dtype=np.float64)
    chan = pings[1].ping_chan_headers[0]
    max_range = float(chan.SlantRange)
    n = port.shape[1]
    times = np.array([p.Hour * 3600 + p.Minute * 60 + p.Second + p.HSeconds / 100 for p in pings])
    period = float((times[-1] - times[1]) / (len(times) - 2))
    knots = float(np.median([p.SensorSpeed for p in pings[1:]]))
    spacing = knots * 1852.0 / 3600.0 * period  # XTF speed is in knots
    hits = []
    hits_file = path.with_name(path.name + ".hits")
    if hits_file.is_file():
        for line in hits_file.read_text().splitlines():
            parts = line.split()
            if len(parts) >= 3:
                hits.append((int(parts[1]), int(parts[2])))
    sides = {"port": port**2, "starboard": star**2}
    samples = {"port": port, "starboard": star}
    freq = float(chan.Frequency) * 1e3
    return RealPass(sides, samples, max_range / n, max_range, freq, spacing, hits)


def first_returns(samples: np.ndarray, skip: int = 16) -> np.ndarray:
    """First bottom return per ping (bin index, median-filtered over 31 pings): where the
    range-smoothed amplitude first exceeds 3 times the water column just after the transmit."""
    smooth = ndimage.uniform_filter1d(samples, 7, axis=1)
    smooth[:, :skip] = 0.0
    water = np.median(smooth[:, skip : 3 * skip], axis=1)
    first = np.argmax(smooth > 3.0 * water[:, None], axis=1).astype(np.float64)
    return ndimage.median_filter(first, size=31, mode="nearest")


def altimeter(path: Path) -> np.ndarray:
    """The file's altimeter over cos(pitch): the slant range to the seabed in the fan plane."""
    import pyxtf

    _, packets = pyxtf.xtf_read(str(path))
    pings = packets[pyxtf.XTFHeaderType.sonar]
    alt = np.array([p.SensorPrimaryAltitude for p in pings])
    pitch = np.radians([p.SensorPitch for p in pings])
    return alt / np.cos(pitch)


def fan_profile(r: np.ndarray, altitude: float, width_deg: float, tilt_deg: float) -> np.ndarray:
    """Thin-fan flat-seabed density ``Φ(asin(h/r) − tilt) h / sqrt(r² − h²)`` (per metre)."""
    out = np.zeros_like(r)
    ok = r > altitude * 1.0005
    alpha = np.arcsin(altitude / r[ok])
    sigma = math.radians(width_deg) / (2.0 * math.sqrt(2.0 * math.log(2.0)))
    beam = np.exp(-0.5 * ((alpha - math.radians(tilt_deg)) / sigma) ** 2)
    out[ok] = beam * altitude / np.sqrt(r[ok] ** 2 - altitude**2)
    return out


def range_gain(r: np.ndarray, alpha: float, footprint: bool) -> np.ndarray:
    """Spreading, absorption, 30 log r + 2αr TVG, and the side-scan footprint (∝ r) together."""
    return r**-4.0 * r**3.0 * (r if footprint else 1.0)  # absorption and its TVG cancel


def normalised_profile(image: np.ndarray, window: slice) -> np.ndarray:
    profile = image.mean(axis=0)
    return profile / profile[window].mean()


def fit_beam(real: RealPass, altitudes: np.ndarray, window: slice, footprint: bool):
    """Grid-fit a Gaussian vertical beam (width, tilt) to both sides' mean profiles, in dB."""
    r = (np.arange(real.sides["port"].shape[1]) + 0.5) * real.range_bin
    target = np.concatenate(
        [
            10 * np.log10(normalised_profile(real.sides[s][SKIP_PINGS:], window)[window])
            for s in ("port", "starboard")
        ]
    )
    sample = altitudes[SKIP_PINGS:][:: max(1, len(altitudes) // 40)]
    best = (math.inf, 0.0, 0.0)
    for width in np.arange(20.0, 91.0, 5.0):
        for tilt in np.arange(0.0, 61.0, 2.5):
            prof = np.mean([fan_profile(r, h, width, tilt) for h in sample], axis=0)
            prof = prof * range_gain(r, 0.0, footprint)
            model = prof / prof[window].mean()
            if np.any(model[window] <= 0):
                continue
            model_db = 10 * np.log10(model[window])
            err = float(np.sqrt(np.mean((np.concatenate([model_db, model_db]) - target) ** 2)))
            if err < best[0]:
                best = (err, float(width), float(tilt))
    return best


def simulate(real: RealPass, altitudes: np.ndarray, args: argparse.Namespace, beam, tilt):
    """Render the flat seabed along the real altitudes, then apply the effects."""
    water_ratio = water_column_ratio(real)
    from sonar_raster import Effects, Sonar, Trajectory, apply_effects, build_scene
    from sonar_raster.rendering.gl.raster import render_raster
    from sonar_raster.scene import MeshPart
    from sonar_raster.scenes.sediments import material_reflectivity
    from sonar_raster.sonar import BeamPattern

    n_pings = len(altitudes)
    length = n_pings * real.ping_spacing
    half = real.max_range + 5.0
    v = np.array(
        [[-half, -5.0, 0.0], [half, -5.0, 0.0], [half, length + 5, 0.0], [-half, length + 5, 0.0]]
    )
    seabed = MeshPart(
        v, np.array([[0, 1, 2], [0, 2, 3]]), material_reflectivity("sand"), "seabed", is_seabed=True
    )
    sonar = Sonar(
        frequency_hz=real.frequency_hz,
        max_range=real.max_range,
        range_bin=real.range_bin,
        beam=BeamPattern.gaussian(beam),
        tilt=math.radians(tilt),
    )
    positions = np.stack(
        [np.zeros(n_pings), np.arange(n_pings) * real.ping_spacing, altitudes], axis=1
    )
    traj = Trajectory(positions, np.zeros(n_pings), np.zeros(n_pings))
    raw = render_raster(build_scene([seabed]), sonar, traj)  # level fans: pitch is not modelled
    fx = Effects(
        along_beam_deg=args.along_beam_deg,
        speckle="exponential",
        range_resolution_m=args.range_resolution,
        spreading=True,
        absorption=True,
        tvg="log",
        tvg_log_coefficient=30.0,
    )
    quiet = apply_effects(raw, fx, seed=args.seed, trajectory=traj)
    noise_db = noise_to_match(real, quiet, fx, water_ratio)
    fx = replace(fx, noise_db=noise_db, bits=16)
    return raw, apply_effects(raw, fx, seed=args.seed, trajectory=traj)


def noise_to_match(real: RealPass, sim, fx, water_ratio: float) -> float:
    """Receiver noise level (dB, before TVG) giving the simulation the real water column's
    level relative to the seabed: mean over water-column bins of N0 G(r) = ratio x seabed mean."""
    from sonar_raster.effects.chain import tvg_db

    n_bins = real.sides["port"].shape[1]
    r = (np.arange(n_bins) + 0.5) * real.range_bin
    gain = 10 ** (tvg_db(fx, r, sim.metadata["effects"]["alpha_db_m"]) / 10)
    seabed, water = [], []
    for side in real.sides:
        first = first_returns(real.samples[side])
        k = np.arange(n_bins)
        wc = (k[None, :] >= 20) & (k[None, :] < first[:, None] - 10)
        wc[:SKIP_PINGS] = False
        water.append(np.broadcast_to(gain, wc.shape)[wc].mean())
        seabed.append(sim.sides[side].astype(np.float64)[SKIP_PINGS:].mean())
    return float(10 * np.log10(water_ratio * np.mean(seabed) / np.mean(water)))


def water_column_ratio(real: RealPass) -> float:
    """Mean real intensity in the water column over its mean over the whole seabed."""
    n_bins = real.sides["port"].shape[1]
    k = np.arange(n_bins)
    ratios = []
    for side in real.sides:
        first = first_returns(real.samples[side])
        wc = (k[None, :] >= 20) & (k[None, :] < first[:, None] - 10)
        sea = k[None, :] > first[:, None] + 10
        wc[:SKIP_PINGS] = sea[:SKIP_PINGS] = False
        ratios.append(real.sides[side][wc].mean() / real.sides[side][sea].mean())
    return float(np.mean(ratios))


def seabed_mask(first: np.ndarray, shape: tuple[int, int], hits, side: str) -> np.ndarray:
    """Pixels well past the first bottom return, not near the end, not on the wreck."""
    k = np.arange(shape[1])
    mask = (k[None, :] > first[:, None] + 20) & (k[None, :] < shape[1] - 8)
    mask[:SKIP_PINGS] = False
    if side == "starboard":
        for ping, _ in hits:
            mask[max(0, ping + WRECK_ROWS[0]) : ping + WRECK_ROWS[1]] = False
    return mask


def local_mean(image: np.ndarray) -> np.ndarray:
    return ndimage.uniform_filter(image, size=(15, 41), mode="nearest")


def patch_contrasts(image: np.ndarray, mask: np.ndarray) -> np.ndarray:
    out = []
    for i in range(0, image.shape[0] - PATCH + 1, PATCH):
        for j in range(0, image.shape[1] - PATCH + 1, PATCH):
            if not mask[i : i + PATCH, j : j + PATCH].all():
                continue
            p = image[i : i + PATCH, j : j + PATCH]
            h = PATCH // 2
            quads = [p[:h, :h].mean(), p[:h, h:].mean(), p[h:, :h].mean(), p[h:, h:].mean()]
            if np.std(quads) / np.mean(quads) > 0.35:  # a trend or an edge: not homogeneous
                continue
            out.append(p.std() / p.mean())
    return np.array(out)


def lag1(norm: np.ndarray, mask: np.ndarray, axis: int) -> float:
    x = np.where(mask, norm - 1.0, 0.0)
    m = mask.astype(np.float64)
    if axis == 0:
        num, both = (x[1:] * x[:-1]).sum(), (m[1:] * m[:-1]).sum()
    else:
        num, both = (x[:, 1:] * x[:, :-1]).sum(), (m[:, 1:] * m[:, :-1]).sum()
    var = (x * x).sum() / m.sum()
    return float(num / both / var)


def speckle_cells(real: RealPass, first: np.ndarray) -> tuple[float, float]:
    """Horizontal beam width (deg) and range resolution (m) whose speckle has the real image's
    lag-1 intensity correlations: ``ρ(1) = exp(-1 / (4 σ²))`` for a Gaussian cell of
    standard deviation σ (pings or bins); along track σ = β r / (√2 · 2.355 · Δy)."""
    image = real.sides["port"]
    mask = seabed_mask(first, image.shape, [], "port")
    norm = image / np.maximum(local_mean(image), 1e-30)
    fwhm = 2.0 * math.sqrt(2.0 * math.log(2.0))
    sigmas = [1.0 / (2.0 * math.sqrt(-math.log(max(lag1(norm, mask, a), 1e-3)))) for a in (0, 1)]
    r_mean = float(((np.nonzero(mask)[1] + 0.5) * real.range_bin).mean())
    beam = math.degrees(sigmas[0] * fwhm * real.ping_spacing * math.sqrt(2.0) / r_mean)
    return beam, sigmas[1] * fwhm * real.range_bin


def bhattacharyya(a: np.ndarray, b: np.ndarray) -> float:
    edges = np.logspace(-3, 2, 101)
    p, _ = np.histogram(np.clip(a, 1e-3, 99), edges)
    q, _ = np.histogram(np.clip(b, 1e-3, 99), edges)
    p, q = p / p.sum(), q / q.sum()
    return float(-math.log(np.sum(np.sqrt(p * q))))


def statistics(image: np.ndarray, mask: np.ndarray):
    norm = image / np.maximum(local_mean(image), 1e-30)
    contrasts = patch_contrasts(image, mask)
    return {
        "norm": norm[mask],
        "contrast": contrasts,
        "lag_along": lag1(norm, mask, 0),
        "lag_range": lag1(norm, mask, 1),
    }


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--xtf", type=Path, default=DEFAULT_XTF)
    ap.add_argument("--along-beam-deg", type=float, default=None, help="default: from data")
    ap.add_argument(
        "--range-resolution",
        type=float,
        default=None,
        metavar="M",
        help="speckle range cell (default: from the data)",
    )
    ap.add_argument("--beam-deg", type=float, default=None)
    ap.add_argument("--tilt-deg", type=float, default=None)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--png", type=Path, default=None, help="write real | simulated here")
    args = ap.parse_args(argv)
    if not args.xtf.is_file():
        print(f"no XTF file at {args.xtf}", file=sys.stderr)
        return 2
    real = read_real(args.xtf)
    firsts = {s: first_returns(real.samples[s]) for s in real.sides}
    detected = np.minimum(firsts["port"], firsts["starboard"]) * real.range_bin
    # Smooth: the steps of a bin between pings would make a steeply climbing or diving track.
    altitudes = ndimage.gaussian_filter1d(detected, 10.0, mode="nearest")
    n_bins = real.sides["port"].shape[1]
    r = (np.arange(n_bins) + 0.5) * real.range_bin
    lo = int(math.ceil((altitudes[SKIP_PINGS:].max() + 1.5) / real.range_bin))
    window = slice(lo, n_bins - 8)
    print(
        f"real pass: {args.xtf.name}, {real.sides['port'].shape[0]} pings x {n_bins} bins, "
        f"range {real.max_range:.2f} m, bin {100 * real.range_bin:.2f} cm, "
        f"{real.frequency_hz / 1e3:.0f} kHz, ping spacing {real.ping_spacing:.3f} m"
    )
    print(
        f"altitude from the first bottom return: {altitudes[SKIP_PINGS:].min():.2f} to "
        f"{altitudes[SKIP_PINGS:].max():.2f} m (median {np.median(altitudes):.2f} m)"
    )
    ratio = detected[SKIP_PINGS:] / altimeter(args.xtf)[SKIP_PINGS:]
    print(
        f"first return / (altimeter field / cos pitch): median {np.median(ratio):.3f}, "
        f"5-95% {np.percentile(ratio, 5):.3f}-{np.percentile(ratio, 95):.3f}"
    )
    if args.beam_deg is None or args.tilt_deg is None:
        err, beam, tilt = fit_beam(real, altitudes, window, footprint=True)
        print(
            f"fitted Gaussian vertical beam: {beam:.0f} deg wide, tilt {tilt:.1f} deg "
            f"(thin-fan fit, RMS {err:.2f} dB)"
        )
    else:
        beam, tilt = args.beam_deg, args.tilt_deg
    if args.along_beam_deg is None or args.range_resolution is None:
        beam_deg, cell = speckle_cells(real, firsts["port"])
        args.along_beam_deg = args.along_beam_deg or beam_deg
        args.range_resolution = args.range_resolution or cell
        print(
            f"speckle cells from the real port side's lag-1 correlations: horizontal beam "
            f"{beam_deg:.2f} deg, range resolution {100 * cell:.1f} cm"
        )
    raw, sim = simulate(real, altitudes, args, beam, tilt)
    fx = sim.metadata["effects"]
    print(
        f"simulation effects: {', '.join(fx['stages'])}; alpha {fx['alpha_db_m']:.3f} dB/m, "
        f"receiver noise {fx['settings']['noise_db']:.1f} dB (matches the real water column, "
        f"{10 * np.log10(water_column_ratio(real)):.1f} dB re the seabed)"
    )
    empty = sum(int((raw.sides[s].sum(axis=1) == 0).sum()) for s in raw.sides)
    if empty:
        print(f"warning: the raw render has {empty} empty ping rows")
    print()
    print(
        f"mean intensity against slant range, dB re each image's mean over "
        f"{r[window.start]:.1f}-{r[window.stop - 1]:.1f} m"
    )
    print(
        f"{'range m':>8s} {'port real':>10s} {'port sim':>9s} {'stbd real':>10s} {'stbd sim':>9s}"
    )
    profiles = {}
    for side in ("port", "starboard"):
        for name, img in (("real", real.sides[side]), ("sim", sim.sides[side])):
            a = img[SKIP_PINGS:].astype(np.float64)
            if side == "starboard":
                keep = np.ones(len(a), bool)
                for ping, _ in real.hits:
                    lo, hi = ping + WRECK_ROWS[0] - SKIP_PINGS, ping + WRECK_ROWS[1] - SKIP_PINGS
                    keep[max(0, lo) : hi] = False
                a = a[keep]
            profiles[side, name] = 10 * np.log10(np.maximum(normalised_profile(a, window), 1e-12))
    step = int(round(2.0 / real.range_bin))
    for k in range(int(round(1.0 / real.range_bin)), n_bins, step):
        row = [profiles[s, n][k] for s in ("port", "starboard") for n in ("real", "sim")]
        print(f"{r[k]:8.1f} " + " ".join(f"{v:9.1f}" for v in row))
    for side in ("port", "starboard"):
        diff = profiles[side, "real"][window] - profiles[side, "sim"][window]
        print(f"{side}: RMS difference over the window {np.sqrt(np.mean(diff**2)):.2f} dB")
    print()
    print(f"{'statistic':32s} {'side':9s} {'real':>8s} {'sim':>8s} {'sim raw':>8s}")
    for side in ("port", "starboard"):
        mask = seabed_mask(firsts[side], real.sides[side].shape, real.hits, side)
        st = {
            "real": statistics(real.sides[side], mask),
            "sim": statistics(sim.sides[side].astype(np.float64), mask),
            "raw": statistics(raw.sides[side].astype(np.float64), mask),
        }
        rows = [
            ("speckle contrast, median", lambda s: np.median(s["contrast"])),
            ("speckle contrast, 25th pct", lambda s: np.percentile(s["contrast"], 25)),
            ("speckle contrast, 75th pct", lambda s: np.percentile(s["contrast"], 75)),
            ("homogeneous patches", lambda s: len(s["contrast"])),
            ("lag-1 correlation along track", lambda s: s["lag_along"]),
            ("lag-1 correlation along range", lambda s: s["lag_range"]),
        ]
        for label, get in rows:
            vals = [get(st[k]) for k in ("real", "sim", "raw")]
            print(f"{label:32s} {side:9s} " + " ".join(f"{v:8.3f}" for v in vals))
        rng = np.random.default_rng(0)
        a = rng.choice(st["real"]["norm"], 200_000)
        for key, label in (("sim", "sim"), ("raw", "sim raw")):
            b = rng.choice(st[key]["norm"], 200_000)
            ks = stats.ks_2samp(a, b).statistic
            distance = bhattacharyya(a, b)
            print(f"{'KS / Bhattacharyya vs ' + label:32s} {side:9s} {ks:8.3f} {distance:8.3f}")
    if args.png:
        write_png(args.png, real, sim)
    return 0


def write_png(path: Path, real: RealPass, sim) -> None:
    """Real (top) over simulated (bottom), port | starboard, 40 dB display, greyscale, every
    2nd ping and 4th bin (a small picture for the README)."""
    from PIL import Image

    from sonar_raster.io.images import display_mapping

    def panel(sides):
        both = np.concatenate([sides["port"][:, ::-1], sides["starboard"]], axis=1)
        codes, _ = display_mapping(both.astype(np.float64), 40.0)
        return np.round(255 * codes[::2, ::4]).astype(np.uint8)

    top, bottom = panel(real.sides), panel(sim.sides)
    gap = np.full((4, top.shape[1]), 255, np.uint8)
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.concatenate([top, gap, bottom])).save(path, optimize=True)
    print(f"wrote {path}")


if __name__ == "__main__":
    sys.exit(main())
