"""Scene description files: every table, overrides, and errors that name the problem."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sonar_raster.errors import SonarRasterError
from sonar_raster.rendering.gl.context import create_context, requested_backends
from sonar_raster.scenes.description import Overrides, load_scene_file


def write(tmp_path, text: str, name: str = "scene.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_full_description(tmp_path):
    (tmp_path / "beam.csv").write_text("angle_deg,value\n-90,0.1\n0,1.0\n90,0.1\n")
    (tmp_path / "track.csv").write_text("x,y,z,heading_deg,roll_deg\n0,0,12,90,0\n0.2,0,12,90,1\n")
    np.save(tmp_path / "depth.npy", np.full((11, 21), -2.0))
    path = write(
        tmp_path,
        """
[sonar]
frequency_hz = 200e3
max_range = 25.0
range_bin = 0.1
tilt_deg = 10.0
beam = { kind = "table", path = "beam.csv" }
sides = ["port"]

[seabed]
kind = "grid"
path = "depth.npy"
resolution = 1.0
reflectivity = 0.4

[[objects]]
primitive = "box"
size = [2.0, 1.0, 0.5]
position = [5.0, 5.0]
reflectivity = 0.8
name = "crate"

[[objects]]
primitive = "sphere"
radius = 0.5
position = [15.0, 5.0, 3.0]

[trajectory]
csv = "track.csv"
""",
    )
    setup = load_scene_file(path)
    assert setup.sonar.sides == ("port",) and setup.sonar.n_bins == 250
    assert setup.sonar.tilt == pytest.approx(math.radians(10))
    assert setup.sonar.beam(0.0) == pytest.approx(1.0)
    assert setup.sonar.beam(math.radians(45)) == pytest.approx(0.55)
    scene = setup.scene
    assert scene.names == ("seabed", "crate", "sphere")
    assert scene.ground_z == pytest.approx(-2.0)
    crate = scene.vertices[np.unique(scene.faces[scene.object_id == 1])]
    assert crate[:, 2].min() == pytest.approx(-2.0) and crate[:, 2].max() == pytest.approx(-1.5)
    assert np.allclose(crate[:, :2].mean(axis=0), [5.0, 5.0])
    sphere = scene.vertices[np.unique(scene.faces[scene.object_id == 2])]
    assert np.allclose(sphere.mean(axis=0), [15.0, 5.0, 3.0], atol=1e-6)
    refl = {
        n: float(scene.reflectivity[scene.object_id == k][0]) for k, n in enumerate(scene.names)
    }
    assert refl == {"seabed": 0.4, "crate": 0.8, "sphere": 0.9}
    traj = setup.trajectory
    assert traj.n_pings == 2 and traj.roll[1] == pytest.approx(math.radians(1))
    assert setup.altitude == pytest.approx(14.0)


def test_overrides_and_straight_track(tmp_path):
    path = write(
        tmp_path,
        """
[sonar]
max_range = 30.0
[seabed]
kind = "flat"
size = [80.0, 20.0]
depth = -5.0
[trajectory]
altitude = 7.0
heading_deg = 90.0
spacing = 0.5
pings = 10
""",
    )
    setup = load_scene_file(
        path, Overrides(max_range=40.0, range_bin=0.2, altitude=9.0, pings=4, sides=("starboard",))
    )
    assert setup.sonar.max_range == 40.0 and setup.sonar.n_bins == 200
    assert setup.sonar.sides == ("starboard",)
    pos = setup.trajectory.positions
    assert len(pos) == 4 and np.allclose(pos[:, 2], 4.0)  # -5 + 9
    assert np.allclose(np.diff(pos[:, 0]), 0.5) and np.allclose(pos[:, 1], 0.0)  # heading east


def test_y_up_models_are_turned_to_z_up(tmp_path):
    (tmp_path / "pole.wrl").write_text(
        "#VRML V2.0 utf8\nShape { geometry Box { size 0.2 3.0 0.2 } }\n"
    )
    setup = load_scene_file(
        write(
            tmp_path,
            """
[[objects]]
file = "pole.wrl"
position = [0.0, 0.0]
""",
        )
    )
    ext = np.ptp(setup.scene.vertices, axis=0)
    assert ext[2] == pytest.approx(3.0) and ext[1] == pytest.approx(0.2)


@pytest.mark.parametrize(
    "text,needle",
    [
        ("[sonar]\nmax_rnage = 3\n[seabed]\nkind='flat'\n", "max_rnage"),
        ("[seabed]\nkind = 'lava'\n", "lava"),
        ("[seabed]\nkind = 'flat'\nwidth = 3\n", "width"),
        ("[[objects]]\nprimitive = 'torus'\n", "torus"),
        ("[[objects]]\nposition = [1, 2]\n", "file"),
        ("[[objects]]\nprimitive = 'box'\nposition = [1]\n", "position"),
        ("[seabed]\nkind='flat'\n[trajectory]\naltitude = -3\n", "altitude"),
        ("[seabed]\nkind='flat'\n[trajectory]\npings = 0\n", "ping"),
        ("[sonar]\nbeam = { kind = 'laser' }\n", "laser"),
        ("[sonar\n", "TOML"),
        ("colour = 'red'\n[seabed]\nkind='flat'\n", "colour"),
    ],
)
def test_errors_name_the_problem(tmp_path, text, needle):
    with pytest.raises(SonarRasterError) as info:
        load_scene_file(write(tmp_path, text))
    assert needle in str(info.value)
    assert "\n" not in str(info.value)


def test_unknown_backend_and_missing_libraries(monkeypatch):
    with pytest.raises(SonarRasterError, match="unknown GL backend"):
        requested_backends("vulkan")
    monkeypatch.setenv("SONAR_RASTER_GL", "osmesa")
    assert requested_backends(None) == ("osmesa",)
    assert requested_backends("egl") == ("egl",)

    def fail(name):
        raise RuntimeError(f"{name} library not found")

    monkeypatch.setattr("sonar_raster.rendering.gl.context._create", fail)
    with pytest.raises(SonarRasterError) as info:
        create_context(None)
    message = str(info.value)
    assert "libegl1" in message and "libosmesa6" in message and "osmesa library" in message


def test_pulse_and_coherent_tables(tmp_path):
    base = '[sonar]\nrange_bin = 0.05\n[seabed]\nkind = "flat"\nsize = 20.0\n'
    setup = load_scene_file(write(tmp_path, base))
    assert setup.pulse is None and setup.coherent == {}
    text = base + (
        '[pulse]\nkind = "lfm"\nduration_s = 0.004\nwindow = "hann"\n'
        "[coherent]\nspacing_wavelengths = 2\nseed = 4\n"
        'horizontal_beam = { width_deg = 0.5, kind = "sinc" }\n'
    )
    setup = load_scene_file(write(tmp_path, text))
    assert setup.pulse.bandwidth_hz == pytest.approx(15e3)  # c / (2 range_bin)
    assert (setup.pulse.duration_s, setup.pulse.window) == (0.004, "hann")
    assert setup.coherent["spacing_wavelengths"] == 2.0 and setup.coherent["seed"] == 4
    assert setup.coherent["horizontal_beam"].width == pytest.approx(math.radians(0.5))
    cw = load_scene_file(write(tmp_path, base + '[pulse]\nkind = "cw"\n'))
    assert cw.pulse.kind == "cw" and cw.pulse.resolution() == pytest.approx(0.05)
    for bad in ('[pulse]\nkind = "fm"\n', "[coherent]\nspacing = 1\n", '[pulse]\nwindow = "x"\n'):
        with pytest.raises(SonarRasterError):
            load_scene_file(write(tmp_path, base + bad))


def test_sinc_beam_uses_the_scene_sound_speed(tmp_path):
    """λ = c / f: a faster sound speed widens the aperture's beam (first null at sin a = λ/L)."""
    widths = {}
    for c in (1450.0, 1550.0):
        path = tmp_path / f"c{int(c)}.toml"
        path.write_text(
            f"[sonar]\nfrequency_hz = 300000.0\nsound_speed = {c}\n"
            'beam = { kind = "sinc", aperture_m = 0.05 }\n[seabed]\nkind = "flat"\n'
            "[trajectory]\npings = 2\n"
        )
        beam = load_scene_file(path).sonar.beam
        a = np.radians(np.linspace(0.0, 8.0, 8001))  # first null only: sin a < 1.35 λ/L
        widths[c] = a[np.argmin(beam(a))]
        assert math.sin(widths[c]) == pytest.approx(c / 300e3 / 0.05, rel=2e-3)
    assert widths[1550.0] > widths[1450.0]


def test_a_gaussian_beam_takes_a_sidelobe_floor(tmp_path):
    """``sidelobe_db`` floors a scene's Gaussian beam two-way; a level that is not below the
    peak is one line naming it."""
    beams = {}
    for floor in ("", ", sidelobe_db = -30.0", ", sidelobe_db = 5.0"):
        path = tmp_path / f"b{len(floor)}.toml"
        path.write_text(
            f'[sonar]\nbeam = {{ kind = "gaussian", beamwidth_deg = 30.0{floor} }}\n'
            '[seabed]\nkind = "flat"\n[trajectory]\npings = 2\n'
        )
        if "5.0" in floor:
            with pytest.raises(SonarRasterError, match="sidelobe level must be < 0 dB, got 5.0"):
                load_scene_file(path)
            continue
        beams[floor] = load_scene_file(path).sonar.beam(np.radians([0.0, 80.0]))
    assert beams[""][1] < 1e-8 and beams[", sidelobe_db = -30.0"][1] == pytest.approx(1e-3)
    assert beams[""][0] == beams[", sidelobe_db = -30.0"][0] == 1.0
