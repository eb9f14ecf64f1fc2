"""The seabed's micro-relief: the sediment's APL-UW roughness spectrum as heights, in scenes."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate

from sonar_raster.errors import SonarRasterError
from sonar_raster.scene import build_scene
from sonar_raster.scenes import seabed
from sonar_raster.scenes.backscatter import spectral_strength_si
from sonar_raster.scenes.description import Overrides, load_scene_file
from sonar_raster.scenes.sediments import sediment
from sonar_raster.sonar import BeamPattern, Sonar
from sonar_raster.trajectory import Trajectory


def _flat(size=(40.0, 20.0)):
    return seabed.flat(size=size, center=(0.0, 0.0))


@pytest.mark.parametrize("name", ["sand", "rock", "mud"])
def test_relief_variance_is_the_spectrum_integrated_over_the_grid(name):
    """Height variance = ∫∫ w₂ (K² + 1/L²)^(-γ/2) dKx dKy over the grid's wavenumber box.

    The integral is done by scipy over the box from the sediment's Table 2 numbers directly
    (not through the module's spectrum function); 4 seeds of a 40 m × 20 m grid at 10 cm.
    """
    p = sediment(name).parameters
    w2, g, inv = spectral_strength_si(p), p.gamma, 1.0 / seabed.MICRO_OUTER_SCALE
    field = _flat()
    got = [seabed.micro_relief(field, name, resolution=0.1, seed=s).z.var() for s in range(4)]
    kx, ky = math.pi / 0.1, math.pi / 0.1  # Nyquist on each axis

    def density(y, x):
        return w2 * (x * x + y * y + inv * inv) ** (-0.5 * g)

    # the spectrum is peaked at K = 0: integrate the inner square apart
    core, _ = integrate.dblquad(density, -1.0, 1.0, -1.0, 1.0, epsabs=0, epsrel=1e-6)
    total, _ = integrate.dblquad(density, -kx, kx, -ky, ky, epsabs=0, epsrel=1e-6)
    assert np.mean(got) == pytest.approx(total, rel=0.10)
    assert core < total


def test_relief_spectrum_follows_the_power_law_with_the_published_level():
    """The periodogram, averaged over rings, is W(K) = w₂ K^-γ for K ≫ 1/L, to 10 %."""
    p = sediment("sand").parameters
    field = seabed.micro_relief(_flat((25.6, 25.6)), "sand", resolution=0.05, seed=3)
    z = field.z - field.z.mean()  # 513 × 513 nodes, periodic over the nodes
    n = z.shape[0]
    dk = 2.0 * math.pi / (n * field.dx)
    power = np.abs(np.fft.fft2(z)) ** 2 / float(n * n) ** 2 / (dk * dk)  # Σ power dk² = var
    k = 2.0 * math.pi * np.fft.fftfreq(n, field.dx)
    kk = np.hypot(k[:, None], k[None, :])
    for lo in (5.0, 10.0, 20.0, 40.0):
        ring = (kk >= lo) & (kk < 1.25 * lo)
        expected = spectral_strength_si(p) * np.mean(kk[ring] ** -p.gamma)
        assert power[ring].mean() == pytest.approx(expected, rel=0.10), lo


def test_relief_is_reproducible_and_keeps_the_seabed_under_it():
    base = seabed.ripples(size=(20.0, 10.0), resolution=0.2, amplitude=0.05, seed=1)
    a = seabed.micro_relief(base, "gravel", resolution=0.05, seed=4)
    b = seabed.micro_relief(base, "gravel", resolution=0.05, seed=4)
    c = seabed.micro_relief(base, "gravel", resolution=0.05, seed=5)
    assert np.array_equal(a.z, b.z) and not np.array_equal(a.z, c.z)
    assert a.dx <= 0.05 and a.dy <= 0.05 and a.extent == base.extent
    under = base.height_at(a.x[None, :], a.y[:, None])
    assert abs(float(np.mean(a.z - under))) < 0.01  # zero-mean relief on the ripples
    # rougher sediments have more relief: rock > gravel > sand > clay (TR 9407 w₂)
    relief = [
        np.std(seabed.micro_relief(base, s, resolution=0.05, seed=4).z - under)
        for s in ("rock", "gravel", "sand", "clay")
    ]
    assert relief == sorted(relief, reverse=True) and relief[0] > 3 * relief[-1]


def test_relief_rejects_bad_arguments():
    with pytest.raises(SonarRasterError, match="unknown material"):
        seabed.micro_relief(_flat(), "cheese", resolution=0.1)
    with pytest.raises(SonarRasterError, match="resolution"):
        seabed.micro_relief(_flat(), "sand", resolution=0.0)
    with pytest.raises(SonarRasterError, match="seed"):
        seabed.micro_relief(_flat(), "sand", resolution=0.1, seed=-1)
    with pytest.raises(SonarRasterError, match="coarser resolution") as info:
        seabed.micro_relief(_flat((5000.0, 500.0)), "sand", resolution=0.05)  # 1e9 nodes
    assert "\n" not in str(info.value)


# -- in an image ---------------------------------------------------------------------------


def test_texture_grows_as_the_grazing_angle_falls(gl):
    """Over a flat seabed the raw image is the same in every ping; with the sand's relief each
    range's along-track contrast is the relief's slopes seen through the backscatter law, which
    steepens as grazing falls (Lambert: d ln σ / dg = 2 cot g), so it grows with range."""
    sonar = Sonar(
        max_range=30.0, range_bin=0.05, beam=BeamPattern.gaussian(60.0), tilt=math.radians(20)
    )
    pings = 200
    pos = np.stack([np.zeros(pings), np.linspace(-10, 10, pings), np.full(pings, 6.0)], axis=1)
    track = Trajectory(pos, np.zeros(pings), np.zeros(pings))
    flat = seabed.flat(size=(70.0, 30.0), center=(0.0, 0.0))
    contrast = {}
    for label, field in (
        ("flat", flat),
        ("relief", seabed.micro_relief(flat, "sand", resolution=0.075, seed=2)),
    ):
        part = field.mesh(reflectivity=0.3)
        img = gl.render(build_scene([part]), sonar, track).sides["starboard"].astype(float)
        bands = [(10.0, 14.0), (16.0, 20.0), (24.0, 28.0)]  # grazing 25-37°, 17-22°, 12-14°
        contrast[label] = [
            float(np.median(cut.std(axis=0) / cut.mean(axis=0)))
            for cut in (img[:, round(a / 0.05) : round(b / 0.05)] for a, b in bands)
        ]
    assert max(contrast["flat"]) < 0.01
    c = contrast["relief"]
    assert 0.05 < c[0] < c[1] < c[2], c


# -- scene files ---------------------------------------------------------------------------


def _scene(tmp_path, seabed_lines: str):
    text = (
        '[sonar]\nmax_range = 20.0\nrange_bin = 0.05\n\n[seabed]\nkind = "flat"\n'
        f"size = [30.0, 12.0]\n{seabed_lines}\n\n[trajectory]\naltitude = 5.0\npings = 8\n"
    )
    path = tmp_path / "s.toml"
    path.write_text(text, encoding="utf-8")
    return path


def _seabed_z(setup):
    scene = setup.scene
    return scene.vertices[np.unique(scene.faces[scene.object_id == 0]), 2]


def test_scene_file_micro_relief(tmp_path):
    on = load_scene_file(_scene(tmp_path, 'material = "sand"\nmicro_relief = true'))
    assert np.ptp(_seabed_z(on)) > 0.02
    note = on.notes["seabed_micro_relief"]
    assert note["sediment"] == "sand" and note["cell_m"][0] <= 1.5 * 0.05 + 1e-12
    # the ideal image's scene leaves it out
    off = load_scene_file(
        _scene(tmp_path, 'material = "sand"\nmicro_relief = true'), Overrides(micro_relief=False)
    )
    assert np.ptp(_seabed_z(off)) == 0.0 and "seabed_micro_relief" not in off.notes
    # a Lambert seabed names its sediment; a table sets cell, outer scale and seed
    lines = 'reflectivity = 0.3\nmicro_relief = { sediment = "rock", resolution = 0.1, seed = 3 }'
    rock = load_scene_file(_scene(tmp_path, lines))
    assert rock.notes["seabed_micro_relief"]["cell_m"][0] <= 0.1
    assert np.ptp(_seabed_z(rock)) > np.ptp(_seabed_z(on))


@pytest.mark.parametrize(
    ("lines", "match"),
    [
        ("reflectivity = 0.3\nmicro_relief = true", "micro_relief needs a sediment"),
        ('material = "sand"\nmicro_relief = 2', "micro_relief must be true, false or a table"),
        ('material = "sand"\nmicro_relief = { cell = 0.1 }', "unknown"),
        ('material = "sand"\nmicro_relief = { resolution = "fine" }', "wrong type"),
        ('reflectivity = 0.3\nmicro_relief = { sediment = "cheese" }', "unknown material"),
    ],
)
def test_scene_file_micro_relief_errors(tmp_path, lines, match):
    with pytest.raises(SonarRasterError, match=match) as info:
        load_scene_file(_scene(tmp_path, lines))
    assert "\n" not in str(info.value)


# -- bare model files -------------------------------------------------------------------------

WEDGE_OBJ = """v 0 0 0\nv 2 0 0\nv 2 1 0\nv 0 1 0\nv 0 0 0.5\nv 0 1 0.5
f 1 3 2\nf 1 4 3\nf 1 2 5\nf 4 6 3\nf 1 5 6\nf 1 6 4\nf 2 3 6\nf 2 6 5
"""


def test_a_bare_model_stands_on_sand_with_its_relief_over_the_swath(tmp_path):
    from sonar_raster.scenes.description import load_scene

    model = tmp_path / "wedge.obj"
    model.write_text(WEDGE_OBJ, encoding="utf-8")
    ov = {"max_range": 20.0, "range_bin": 0.05, "altitude": 5.0}
    setup = load_scene(model, Overrides(**ov))
    z = _seabed_z(setup)
    assert 0.01 < np.std(z) < 0.05  # sand's relief, 2-3 cm rms
    note = setup.notes["seabed_micro_relief"]
    x0, y0, x1, y1 = note["extent_m"]
    ground = math.sqrt(20.0**2 - 5.0**2) + 2.0
    ys = setup.trajectory.positions[:, 1]
    assert x0 == pytest.approx(-ground) and x1 == pytest.approx(ground)  # heading 0: x across
    assert y0 == pytest.approx(ys.min() - 3.0) and y1 == pytest.approx(ys.max() + 3.0)
    plane = load_scene(model, Overrides(**ov, micro_relief=False))
    assert np.ptp(_seabed_z(plane)) == 0.0 and "seabed_micro_relief" not in plane.notes
    huge = load_scene(model, Overrides(max_range=400.0, range_bin=0.02, altitude=5.0))
    assert np.ptp(_seabed_z(huge)) == 0.0  # 16 M nodes: the plane, and the note says why
    assert "a plane instead" in huge.notes["seabed_micro_relief"]["skipped"]


def test_the_render_options_leave_the_relief_out():
    """``--no-micro-relief`` and ``--ideal`` render the default scene's seabed as a plane."""
    from sonar_raster.cli.app import _parser
    from sonar_raster.cli.render import load_setup

    def seabed_std(*options):
        args = _parser().parse_args(["render", "default", "-o", "x.png", *options])
        return float(np.std(_seabed_z(load_setup(args))))

    assert seabed_std() > 0.01  # sand's relief, 2-3 cm
    assert seabed_std("--no-micro-relief") == 0.0
    assert seabed_std("--ideal") == 0.0
