"""Make the small README pictures of the sensor effects, one PNG per effect, in docs/effects/.

One small scene (a sandy flat seabed with four small rocks and a pipe, starboard side, 8 m
altitude, 30 m range) is rendered once on the GL path; each picture applies one effect (or a
short chain) to that raw image. Every picture uses the same display: 40 dB below its own
99.5th percentile, copper colour map, range increasing to the right, pings downwards.

Usage: ``python tools/effects_gallery.py [--out docs/effects] [--only NAME ...]``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from _common import DOCS, ROOT, parser, pyplot


def gallery(seabed_db: float, alpha: float) -> dict[str, tuple[dict, str]]:
    """Settings and caption per picture; levels are set from the raw seabed's median level
    (``seabed_db``, dB re 1 m²) so each effect shows at a sensible strength."""
    at_20m = seabed_db - 40.0 * math.log10(20.0) - 2.0 * alpha * 20.0  # after propagation
    return {
        "raw": ({}, "renderer output (no effects)"),
        "along_track": ({"along_beam_deg": 3.0}, "side-scan beam 3 deg: blur grows with range"),
        "sas": ({"sas_resolution_m": 0.5}, "SAS 50 cm: the same resolution at every range"),
        "spreading": (
            {"spreading": True, "absorption": True},
            "1/r^4 spreading and absorption, no TVG",
        ),
        "tvg": (
            {"spreading": True, "absorption": True, "tvg": "log", "tvg_log_coefficient": 30.0},
            "spreading and absorption with TVG 30 log r + 2 alpha r",
        ),
        "speckle": (
            {"speckle": "exponential", "range_resolution_m": 0.1},
            "exponential (fully developed) speckle",
        ),
        "speckle_k": (
            {"speckle": "k", "k_shape": 0.5, "range_resolution_m": 0.1},
            "K-distributed speckle, nu = 0.5 (patchy)",
        ),
        "recorder_max": (
            {
                "speckle": "exponential",
                "range_resolution_m": 0.0125,
                "downsample": "max",
                "sample_spacing_m": 0.00625,
            },
            "1.25 cm pulse, recorder keeps the largest of 8 samples per 5 cm bin (XTF MAX)",
        ),
        "noise": (
            {"water_column_db": seabed_db - 15.0, "noise_db": seabed_db - 12.0},
            "water-column returns and receiver noise",
        ),
        "nadir_gap": ({"nadir_gap_deg": 60.0}, "nadir gap of 60 deg"),
        "quantise": (
            {"gain_db": 3.0, "saturation": 10 ** ((seabed_db + 10.0) / 10), "bits": 8},
            "gain, saturation (objects clip) and 8-bit quantisation",
        ),
        "all": (
            {
                "along_beam_deg": 0.5,
                "speckle": "exponential",
                "range_resolution_m": 0.06,
                "spreading": True,
                "absorption": True,
                "noise_db": at_20m - 10.0,
                "tvg": "log",
                "tvg_log_coefficient": 30.0,
                "bits": 12,
            },
            "all of them: beam, speckle, losses, noise, TVG, 12 bits",
        ),
    }


def render_scene():
    import trimesh

    from sonar_raster import Sonar, Trajectory, build_scene
    from sonar_raster.rendering.gl.raster import render_raster
    from sonar_raster.scene import MeshPart
    from sonar_raster.scenes.sediments import material_reflectivity
    from sonar_raster.sonar import BeamPattern

    v = np.array([[-5.0, -5.0, 0.0], [40.0, -5.0, 0.0], [40.0, 30.0, 0.0], [-5.0, 30.0, 0.0]])
    seabed = MeshPart(
        v, np.array([[0, 1, 2], [0, 2, 3]]), material_reflectivity("sand"), "seabed", True
    )
    parts = [seabed]
    for x in (10.0, 16.0, 22.0, 28.0):  # small rocks at increasing range
        rock = trimesh.creation.box(bounds=[[x, 5.8, 0.0], [x + 0.3, 6.1, 0.3]])
        parts.append(MeshPart(np.asarray(rock.vertices), np.asarray(rock.faces), 0.9, "rock"))
    pipe = trimesh.creation.cylinder(radius=0.4, height=8.0, sections=32)
    pipe.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, [1, 0, 0]))
    pipe.apply_translation([18.0, 17.0, 0.4])
    parts.append(MeshPart(np.asarray(pipe.vertices), np.asarray(pipe.faces), 0.9, "pipe"))
    sonar = Sonar(
        frequency_hz=600e3,
        max_range=30.0,
        range_bin=0.05,
        beam=BeamPattern.sinc(0.004, 600e3),
        tilt=math.radians(25.0),
        sides=("starboard",),
    )
    traj = Trajectory.straight((0.0, 0.0, 8.0), 0.0, 0.1, 240)
    return render_raster(build_scene(parts), sonar, traj), traj


def save(path: Path, data: np.ndarray) -> None:
    from matplotlib import pyplot as plt

    from sonar_raster.io.images import display_mapping

    codes, _ = display_mapping(data.astype(np.float64), 40.0)
    small = codes[::2, ::3]  # 120 x 200 pixels
    plt.imsave(path, small, cmap="copper", vmin=0.0, vmax=1.0)


def main(argv: list[str] | None = None) -> int:
    pyplot()
    from sonar_raster.effects.chain import Effects, apply_effects

    ap = parser(__doc__, out=DOCS / "effects")
    ap.add_argument("--only", nargs="+", default=None, help="make only these pictures")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    raw, traj = render_scene()
    star = raw.sides["starboard"]
    seabed_db = 10.0 * math.log10(float(np.median(star[star > 0])))
    alpha = Effects(absorption=True).alpha_db_m(raw.sonar.frequency_hz)
    for name, (settings, caption) in gallery(seabed_db, alpha).items():
        if args.only and name not in args.only:
            continue
        if "bits" in settings and "saturation" not in settings:  # full scale 15 dB up
            unquantised = dict(settings, bits=None)
            level = apply_effects(raw, Effects(**unquantised), seed=1, trajectory=traj)
            settings = dict(settings, saturation=30.0 * float(np.median(level.sides["starboard"])))
        image = apply_effects(raw, Effects(**settings), seed=1, trajectory=traj)
        path = args.out / f"{name}.png"
        save(path, image.sides["starboard"])
        print(f"{path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}: {caption}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
