"""Compare a simulated side-scan image with the real XTF pass, with the numbers an engineer checks.

Reads ``../shared/data/xtf/scotsman-iver2.xtf`` (Marine Sonic HDS, 600 kHz, Iver2 AUV) with
pyxtf directly, then renders a flat seabed of medium sand (``--sediment``) at the same slant
range, bin size and ping spacing, along a track whose altitude follows the real first bottom
return ping by ping (the vehicle dives through the file, from about 11 m to 3 m altitude,
pitched 20° nose down for half of it: each ping is pitched and rolled as the file records,
``--level`` for level fans), applies the sensor effects,
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

It also scores the real file against itself, its starboard side as if it were a simulation of
its port side over the same pings (``stbd/port`` rows): a left-right symmetric sensor over one
seabed that matched one side exactly would score that on the other.

Usage: ``python tools/compare_real.py [--xtf PATH] [--level] [--downsample off|max|mean]
[--k-shape NU] [--law lambert] [--sediment 'fine sand'] [--along-beam-deg 0.5] [--png out.png]
[--json out.json]``.
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

from sonar_raster.effects.presets import DEFAULT_SENSOR

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
    pitch_deg: np.ndarray | None = None  # per ping, positive nose up (XTF SensorPitch)
    roll_deg: np.ndarray | None = None  # per ping, positive starboard down (XTF SensorRoll)


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
    pitch = np.array([p.SensorPitch for p in pings], dtype=np.float64)
    roll = np.array([p.SensorRoll for p in pings], dtype=np.float64)
    return RealPass(sides, samples, max_range / n, max_range, freq, spacing, hits, pitch, roll)


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


#: The real wreck's shadow (starboard rows and bins holding its core) and the seabed beside it.
SHADOW_ROWS = (190, 340)
SHADOW_BINS = (380, 600)
BESIDE_BINS = (650, 900)
#: A wreck-like hull for the simulation: along-track rows, slant bin of its near side, beam
#: and height (m). The height is the real wreck's from its shadow (1.17 m,
#: ``tools/report_real.py``); the length spans the rows where the file shows it.
WRECK_HULL = {"rows": (195, 335), "near_bin": 390, "beam_m": 4.0, "height_m": 1.2}


def wreck_hull(real: RealPass, altitudes: np.ndarray):
    """An upright hull standing where the real wreck stands (starboard): the upper half of an
    ellipsoid (length, beam, twice the height), its lower half pressed just under the seabed."""
    import trimesh

    from sonar_raster.scene import MeshPart

    rows, hull = WRECK_HULL["rows"], WRECK_HULL
    h = float(np.median(altitudes[rows[0] : rows[1]]))
    r = (hull["near_bin"] + 0.5) * real.range_bin
    x0 = math.sqrt(max(r**2 - h**2, 1.0))
    length = (rows[1] - rows[0]) * real.ping_spacing
    sphere = trimesh.creation.icosphere(subdivisions=4)
    v = np.asarray(sphere.vertices) * [hull["beam_m"] / 2, length / 2, hull["height_m"]]
    v[:, 2] = np.maximum(v[:, 2], -0.05)  # the buried half: under the seabed, hidden by it
    v += [x0 + hull["beam_m"] / 2, (rows[0] + rows[1]) / 2 * real.ping_spacing, 0.0]
    return MeshPart(v, np.asarray(sphere.faces), 0.9, "wreck hull")


def simulate(real: RealPass, altitudes: np.ndarray, args: argparse.Namespace, beam, tilt):
    """Render a flat seabed of ``--sediment`` (and a wreck-like hull) along the real altitudes
    with the Marine Sonic preset's sonar at the file's range and bins, then apply the preset's
    effects (``--along-beam-deg``/``--range-resolution``/``--noise-db`` replace its figures)."""
    from sonar_raster import Trajectory, apply_effects, build_scene
    from sonar_raster.effects.presets import preset
    from sonar_raster.rendering.gl.raster import render_raster
    from sonar_raster.scenes.seabed import MICRO_RESOLUTION_BINS, Heightfield, micro_relief
    from sonar_raster.scenes.sediments import material_index, material_reflectivity
    from sonar_raster.sonar import BeamPattern

    p = preset(args.sensor)
    n_pings = len(altitudes)
    length = n_pings * real.ping_spacing
    half = real.max_range + 5.0
    field = Heightfield(np.zeros((2, 2)), -half, -5.0, 2.0 * half, length + 10.0)  # a plane
    if args.micro_relief == "on":  # the sand's own roughness spectrum, at the image's scales
        cell = args.relief_cell or MICRO_RESOLUTION_BINS * real.range_bin
        field = micro_relief(field, args.sediment, resolution=cell, seed=args.seed)
    law = material_index(args.sediment) if args.law == "apl" else 0
    seabed = replace(field.mesh(material_reflectivity(args.sediment)), is_seabed=True, law=law)
    sonar = p.sonar(real.max_range, real.range_bin)
    if beam is not None:
        sonar = replace(sonar, beam=BeamPattern.gaussian(beam), tilt=math.radians(tilt))
    pitch = roll = np.zeros(n_pings)
    heights = altitudes
    if args.attitude and real.pitch_deg is not None and real.roll_deg is not None:
        # The fan is a plane: its nearest seabed point is h / cos(pitch) away whatever the roll.
        pitch = np.radians(ndimage.median_filter(real.pitch_deg, 5, mode="nearest"))
        roll = np.radians(ndimage.median_filter(real.roll_deg, 5, mode="nearest"))
        heights = altitudes * np.cos(pitch)
    positions = np.stack(
        [np.zeros(n_pings), np.arange(n_pings) * real.ping_spacing, heights], axis=1
    )
    traj = Trajectory(positions, np.zeros(n_pings), roll, pitch)
    scene = build_scene([seabed, wreck_hull(real, altitudes)])
    raw = render_raster(scene, sonar, traj)  # pitched and rolled fans unless --level
    fx = replace(p.effects(), ping_spacing_m=real.ping_spacing)
    for name, value in (
        ("along_beam_deg", args.along_beam_deg),
        ("range_resolution_m", args.range_resolution),
        ("noise_db", args.noise_db),
        ("speckle_looks", args.speckle_looks),
    ):
        if value is not None:
            fx = replace(fx, **{name: value})
    if args.downsample == "off":  # the recorder keeps one sample per bin
        fx = replace(fx, downsample="off", sample_spacing_m=None)
    elif args.downsample != "preset":  # MAX or mean of sub-samples at half the resolution cell
        cell = fx.range_resolution_m or real.range_bin
        fx = replace(fx, downsample=args.downsample, sample_spacing_m=cell / 2.0)
    if args.k_shape is not None:  # K-distributed: a patchy seabed's texture under the speckle
        fx = replace(fx, speckle="k", k_shape=args.k_shape)
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


def corr_length(norm: np.ndarray, mask: np.ndarray, axis: int, step: float) -> float:
    """Speckle correlation length, metres: the std of the Gaussian cell whose lag-1 intensity
    correlation is the image's, ``σ = 1 / (2 √(−ln ρ(1)))`` pixels times the pixel size."""
    rho = min(max(lag1(norm, mask, axis), 1e-6), 0.999)
    return step / (2.0 * math.sqrt(-math.log(rho)))


def shadow_contrast(image: np.ndarray) -> float:
    """Seabed beside the wreck over its shadow, dB: the median of the 9 × 9 local mean over
    :data:`BESIDE_BINS` over the 5th percentile of it in the shadow window (same rows)."""
    local = ndimage.uniform_filter(image.astype(np.float64), 9)
    rows = slice(*SHADOW_ROWS)
    shadow = np.percentile(local[rows, slice(*SHADOW_BINS)], 5)
    beside = np.median(local[rows, slice(*BESIDE_BINS)])
    return float(10 * np.log10(beside / max(shadow, 1e-30)))


def first_return_db(image: np.ndarray, first: np.ndarray) -> float:
    """The first bottom return's level below mid-swath, dB: medians over pings of the mean of
    bins 2-11 after each ping's first return over the mean of bins 150-249 after it (no target
    in the issue; the beam's sidelobe floor sets it in the simulation)."""
    near, mid = [], []
    for i in range(SKIP_PINGS, image.shape[0]):
        f = int(first[i])
        near.append(image[i, f + 2 : f + 12].mean())
        mid.append(image[i, f + 150 : f + 250].mean())
    return float(10 * np.log10(np.median(near) / np.median(mid)))


TARGETS = {"profile": 1.0, "contrast": 0.05, "ks": 0.05, "length": 0.20, "shadow": 3.0}


def band_stats(a, b, band: slice, real: RealPass, rng) -> dict:
    """Every per-band statistic of two images, ``a`` as the reference: each is (intensity,
    seabed mask, mean profile in dB over the window); the profile RMS uses bins ``band``."""
    (img_a, mask_a, prof_a), (img_b, mask_b, prof_b) = a, b
    cols = np.zeros(img_a.shape[1], bool)
    cols[band] = True
    row = pixel_stats(img_a, mask_a & cols, img_b, mask_b & cols, real, rng)
    return {"profile": float(np.sqrt(np.mean((prof_a[band] - prof_b[band]) ** 2)))} | row


def pixel_stats(img_a, mask_a, img_b, mask_b, real: RealPass, rng) -> dict:
    """Speckle contrast, correlation lengths and the KS distance of two images' masked pixels."""
    row: dict = {}
    samples = []
    for key, img, m in (("real", img_a, mask_a), ("sim", img_b, mask_b)):
        norm = img / np.maximum(local_mean(img), 1e-30)
        c = patch_contrasts(img, m)
        row[f"contrast_{key}"] = float(np.median(c)) if len(c) else math.nan
        row[f"along_{key}"] = corr_length(norm, m, 0, real.ping_spacing)
        row[f"across_{key}"] = corr_length(norm, m, 1, real.range_bin)
        samples.append(rng.choice(norm[m], min(100_000, int(m.sum()))))
    row["ks"] = float(stats.ks_2samp(*samples).statistic)
    return row


#: Grazing-angle bands of :func:`grazing_rows`, degrees.
GRAZING_EDGES = (4.0, 7.0, 10.0, 14.0, 20.0, 30.0)


def grazing_rows(real: RealPass, sim, firsts, altitudes: np.ndarray, window: slice):
    """Per side and grazing-angle band (not range band): the same statistics, no target.

    The track dives from about 12 m to 3 m altitude, so one range band mixes grazing angles;
    each pixel's grazing angle is ``asin(h / r)`` with the ping's tracked altitude ``h`` (the
    seabed taken flat), the same for the file and its simulation.
    """
    out = []
    rng = np.random.default_rng(0)
    r = (np.arange(real.sides["port"].shape[1]) + 0.5) * real.range_bin
    grazing = np.degrees(np.arcsin(np.clip(altitudes[:, None] / r[None, :], 0.0, 1.0)))
    cols = np.zeros(len(r), bool)
    cols[window] = True
    for side in ("port", "starboard"):
        mask = seabed_mask(firsts[side], real.sides[side].shape, real.hits, side) & cols
        sim_img = sim.sides[side].astype(np.float64)
        for lo, hi in zip(GRAZING_EDGES[:-1], GRAZING_EDGES[1:], strict=True):
            m = mask & (grazing >= lo) & (grazing < hi)
            if m.sum() < 10_000:
                continue
            row = {"side": side, "grazing_deg": (lo, hi), "pixels": int(m.sum())}
            out.append(row | pixel_stats(real.sides[side], m, sim_img, m, real, rng))
    return out


def band_edges(window: slice, n_bands: int) -> list[tuple[int, int]]:
    edges = np.linspace(window.start, window.stop, n_bands + 1).astype(int)
    return list(zip(edges[:-1].tolist(), edges[1:].tolist(), strict=True))


def band_rows(real: RealPass, sim, firsts, profiles, window: slice, n_bands: int):
    """Per side and range band: every statistic, real and simulated."""
    out = []
    rng = np.random.default_rng(0)
    for side in ("port", "starboard"):
        mask = seabed_mask(firsts[side], real.sides[side].shape, real.hits, side)
        a = (real.sides[side], mask, profiles[side, "real"])
        b = (sim.sides[side].astype(np.float64), mask, profiles[side, "sim"])
        for lo, hi in band_edges(window, n_bands):
            row = {"side": side, "band_m": (lo * real.range_bin, hi * real.range_bin)}
            out.append(row | band_stats(a, b, slice(lo, hi), real, rng))
    return out


def side_rows(real: RealPass, firsts, window: slice, n_bands: int):
    """The file against itself: per range band, its starboard side scored as if it were a
    simulation of its port side, over the same pings (the wreck's rows left out of both). A
    left-right symmetric sensor over one seabed that matched one side exactly would score this
    on the other."""
    keep = np.ones(real.sides["port"].shape[0], bool)
    keep[:SKIP_PINGS] = False
    for ping, _ in real.hits:
        keep[max(0, ping + WRECK_ROWS[0]) : ping + WRECK_ROWS[1]] = False
    a, b = (
        (
            real.sides[side],
            seabed_mask(firsts[side], real.sides[side].shape, real.hits, "starboard"),
            10 * np.log10(np.maximum(normalised_profile(real.sides[side][keep], window), 1e-12)),
        )
        for side in ("port", "starboard")
    )
    rng = np.random.default_rng(0)
    return [
        {"side": "stbd/port", "band_m": (lo * real.range_bin, hi * real.range_bin)}
        | band_stats(a, b, slice(lo, hi), real, rng)
        for lo, hi in band_edges(window, n_bands)
    ]


def reached(rows) -> dict[str, list[bool]]:
    """Each band's pass or fail of every per-band target."""
    t = TARGETS
    return {
        "mean profile <= 1 dB RMS": [r["profile"] <= t["profile"] for r in rows],
        "speckle contrast within 0.05": [
            abs(r["contrast_real"] - r["contrast_sim"]) <= t["contrast"] for r in rows
        ],
        "KS <= 0.05": [r["ks"] <= t["ks"] for r in rows],
        "along-track length within 20 %": [
            abs(r["along_sim"] / r["along_real"] - 1) <= t["length"] for r in rows
        ],
        "across-track length within 20 %": [
            abs(r["across_sim"] / r["across_real"] - 1) <= t["length"] for r in rows
        ],
    }


def _sediment_name(name: str) -> str:
    """``--sediment``'s value if the sediment table knows it (argparse's one-line error if not)."""
    from sonar_raster.errors import SonarRasterError
    from sonar_raster.scenes.sediments import sediment

    try:
        sediment(name)
    except SonarRasterError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return name


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--xtf", type=Path, default=DEFAULT_XTF)
    ap.add_argument("--sensor", default=DEFAULT_SENSOR, help="sensor preset simulated")
    ap.add_argument("--along-beam-deg", type=float, default=None, help="default: the preset's")
    ap.add_argument("--range-resolution", type=float, default=None, metavar="M")
    ap.add_argument("--noise-db", type=float, default=None, help="default: the preset's")
    ap.add_argument(
        "--speckle-looks", type=float, default=None, help="looks per sample (default: preset's)"
    )
    ap.add_argument("--k-shape", type=float, default=None, help="K texture shape ν (default: none)")
    ap.add_argument(
        "--downsample",
        choices=("preset", "off", "max", "mean"),
        default="preset",
        help="recorder's reduction of sub-samples to bins (default: the preset's)",
    )
    ap.add_argument(
        "--law",
        choices=("apl", "lambert"),
        default="apl",
        help="seabed scattering law: the APL-UW sand law (default) or Lambert",
    )
    ap.add_argument(
        "--sediment",
        type=_sediment_name,
        default="sand",
        help="the seabed's sediment: its APL-UW law, roughness and reflectivity (a class or a "
        "TR 9407 Table 2 name, e.g. 'fine sand'; default sand, i.e. medium sand)",
    )
    ap.add_argument(
        "--micro-relief",
        choices=("on", "off"),
        default="on",
        help="the sand's APL-UW roughness as relief on the seabed (seabed.micro_relief; "
        "default on), or a flat plane",
    )
    ap.add_argument(
        "--relief-cell", type=float, default=None, metavar="M", help="its cell (default 1.5 bins)"
    )
    ap.add_argument(
        "--fit-beam", action="store_true", help="fit the vertical beam to the real mean profile"
    )
    ap.add_argument("--beam-deg", type=float, default=None)
    ap.add_argument("--tilt-deg", type=float, default=None)
    ap.add_argument(
        "--level",
        dest="attitude",
        action="store_false",
        help="level fans (default: each ping pitched and rolled as the file records)",
    )
    ap.add_argument("--bands", type=int, default=3, help="range bands (default 3)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--png", type=Path, default=None, help="write real | simulated here")
    ap.add_argument("--json", type=Path, default=None, help="write the numbers here")
    args = ap.parse_args(argv)
    if not args.xtf.is_file():
        print(f"no XTF file at {args.xtf}", file=sys.stderr)
        return 2
    try:
        real = read_real(args.xtf)
    except Exception as exc:  # pyxtf reads a damaged file in many ways
        detail = " ".join(str(exc).split())[:160]
        print(
            f"compare_real: error: cannot read {args.xtf} as a clean two-channel XTF pass "
            f"({type(exc).__name__}: {detail}); it compares files like the sample",
            file=sys.stderr,
        )
        return 2
    firsts = {s: first_returns(real.samples[s]) for s in real.sides}
    detected = np.minimum(firsts["port"], firsts["starboard"]) * real.range_bin
    # Smooth: the steps of a bin between pings would make a steeply climbing or diving track.
    altitudes = ndimage.gaussian_filter1d(detected, 10.0, mode="nearest")
    n_bins = real.sides["port"].shape[1]
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
    beam = tilt = None
    if args.beam_deg is not None and args.tilt_deg is not None:
        beam, tilt = args.beam_deg, args.tilt_deg
    elif args.fit_beam:
        err, beam, tilt = fit_beam(real, altitudes, window, footprint=True)
        print(f"fitted Gaussian vertical beam: {beam:.0f} deg, tilt {tilt:.1f} deg ({err:.2f} dB)")
    raw, sim = simulate(real, altitudes, args, beam, tilt)
    fx = sim.metadata["effects"]
    print(
        f"simulated: preset {args.sensor}, vertical beam "
        f"{'preset' if beam is None else f'{beam:g} deg, tilt {tilt:g} deg'}; effects "
        f"{', '.join(fx['stages'])}; noise {fx['settings'].get('noise_db')} dB"
    )
    profiles = {}
    for side in ("port", "starboard"):
        for name, img in (("real", real.sides[side]), ("sim", sim.sides[side])):
            a = img[SKIP_PINGS:].astype(np.float64)
            if side == "starboard":
                keep = np.ones(len(a), bool)
                for ping, _ in real.hits:
                    lo_, hi_ = ping + WRECK_ROWS[0] - SKIP_PINGS, ping + WRECK_ROWS[1] - SKIP_PINGS
                    keep[max(0, lo_) : hi_] = False
                a = a[keep]
            profiles[side, name] = 10 * np.log10(np.maximum(normalised_profile(a, window), 1e-12))
    rows = band_rows(real, sim, firsts, profiles, window, args.bands)
    itself = side_rows(real, firsts, window, args.bands)
    print()
    print(
        f"{'side':9s} {'band m':>11s} {'profile dB':>10s} {'contrast r/s':>13s} "
        f"{'KS':>6s} {'along cm r/s':>13s} {'across cm r/s':>14s}"
    )
    for row in rows + itself:
        print(
            f"{row['side']:9s} {row['band_m'][0]:5.1f}-{row['band_m'][1]:4.1f} "
            f"{row['profile']:10.2f} {row['contrast_real']:6.3f}/{row['contrast_sim']:.3f} "
            f"{row['ks']:6.3f} {100 * row['along_real']:6.2f}/{100 * row['along_sim']:<6.2f} "
            f"{100 * row['across_real']:6.2f}/{100 * row['across_sim']:.2f}"
        )
    print(
        "(stbd/port: the real starboard side scored as a simulation of the real port side, "
        "same pings; a left-right symmetric sensor over one seabed gives the same on both)"
    )
    shadow = {"real": shadow_contrast(real.sides["starboard"])}
    shadow["sim"] = shadow_contrast(sim.sides["starboard"])
    print(
        f"wreck shadow contrast (starboard): real {shadow['real']:.1f} dB, "
        f"sim {shadow['sim']:.1f} dB"
    )
    sim_first = np.round(altitudes / real.range_bin).astype(int)
    nadir = {
        side: (
            first_return_db(real.sides[side].astype(np.float64), firsts[side]),
            first_return_db(sim.sides[side].astype(np.float64), sim_first),
        )
        for side in ("port", "starboard")
    }
    print(
        "first bottom return below mid-swath (real / sim): "
        + ", ".join(f"{s} {r:.1f} / {m:.1f} dB" for s, (r, m) in nadir.items())
    )
    by_grazing = grazing_rows(real, sim, firsts, altitudes, window)
    print()
    print("per grazing band (each pixel's asin(h / r); no target):")
    print(
        f"{'side':9s} {'grazing':>9s} {'pixels':>8s} {'contrast r/s':>13s} {'KS':>6s} "
        f"{'along cm r/s':>13s} {'across cm r/s':>14s}"
    )
    for row in by_grazing:
        print(
            f"{row['side']:9s} {row['grazing_deg'][0]:4.0f}-{row['grazing_deg'][1]:<4.0f} "
            f"{row['pixels']:8d} {row['contrast_real']:6.3f}/{row['contrast_sim']:.3f} "
            f"{row['ks']:6.3f} {100 * row['along_real']:6.2f}/{100 * row['along_sim']:<6.2f} "
            f"{100 * row['across_real']:6.2f}/{100 * row['across_sim']:.2f}"
        )
    checks = reached(rows)
    checks["shadow contrast within 3 dB"] = [
        abs(shadow["real"] - shadow["sim"]) <= TARGETS["shadow"]
    ]
    own = reached(itself)
    print()
    print(f"{'':34s} simulated   the file's starboard as its port's")
    for name, ok in checks.items():
        mine = f"{sum(own[name])} of {len(own[name])}" if name in own else "-"
        print(f"{name:34s} {sum(ok)} of {len(ok)} reached {mine:>9s}")
    if args.json:
        args.json.write_text(
            __import__("json").dumps(
                {
                    "bands": rows,
                    "shadow_db": shadow,
                    "real_starboard_vs_port": itself,
                    "by_grazing": by_grazing,
                    "first_return_db": nadir,
                },
                indent=1,
            )
        )
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
