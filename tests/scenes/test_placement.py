"""Bare model placement (up axis, units, scale, position, heading) and sonar/track overrides."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from sonar_raster.errors import InputWarning, SonarRasterError
from sonar_raster.scenes.description import (
    FEW_BINS,
    UNITS,
    UP_AXES,
    Overrides,
    Placement,
    RecordedTrack,
    _rotation,
    load_scene,
)

#: A wedge authored z-up: 2 m along x, 1 m along y, 0.5 m tall, its apex edge at x = 0 on top.
WEDGE_OBJ = """v 0 0 0\nv 2 0 0\nv 2 1 0\nv 0 1 0\nv 0 0 0.5\nv 0 1 0.5
f 1 3 2\nf 1 4 3\nf 1 2 5\nf 4 6 3\nf 1 5 6\nf 1 6 4\nf 2 3 6\nf 2 6 5
"""
#: A box 2 x 1 x 0.5 authored z-up (as choreonoid's table.wrl is) in VRML, y-up by the spec.
ZUP_VRML = "#VRML V2.0 utf8\nShape { geometry Box { size 2 1 0.5 } }\n"


def model_vertices(setup) -> np.ndarray:
    """Vertices of the faces that are not the seabed's (object id 0 is the seabed)."""
    scene = setup.scene
    seabed = scene.names.index("seabed") if "seabed" in scene.names else -1
    faces = scene.faces[scene.object_id != seabed]
    return scene.vertices[np.unique(faces)]


def load(path, **placement) -> object:
    extra = {k: placement.pop(k) for k in list(placement) if k in Overrides.__dataclass_fields__}
    return load_scene(path, Overrides(placement=Placement(**placement), **extra))


@pytest.mark.parametrize("up", list(UP_AXES))
def test_each_up_axis_turns_that_file_axis_to_plus_z_without_mirroring(up):
    axis = np.zeros(3)
    axis["xyz".index(up[-1])] = -1.0 if up.startswith("-") else 1.0
    rotation = _rotation(np.array(UP_AXES[up]))
    np.testing.assert_allclose(rotation @ axis, [0.0, 0.0, 1.0], atol=1e-12)
    assert np.linalg.det(rotation) == pytest.approx(1.0)


def test_vrml_is_y_up_by_default_and_up_z_stands_a_z_up_model(tmp_path):
    model = tmp_path / "table.wrl"
    model.write_text(ZUP_VRML)
    lying = np.ptp(model_vertices(load(model)), axis=0)
    standing = np.ptp(model_vertices(load(model, up="z")), axis=0)
    np.testing.assert_allclose(lying, [2.0, 0.5, 1.0], atol=1e-9)  # y-up: its 1 m axis stands
    np.testing.assert_allclose(standing, [2.0, 1.0, 0.5], atol=1e-9)
    assert model_vertices(load(model, up="z"))[:, 2].min() == pytest.approx(0.0)  # on the seabed


def test_up_minus_z_turns_the_wedge_upside_down(tmp_path):
    model = tmp_path / "wedge.obj"
    model.write_text(WEDGE_OBJ)
    for up, apex_on_top in (("z", True), ("-z", False)):
        v = model_vertices(load(model, up=up))
        low, high = v[:, 2].min(), v[:, 2].max()
        thin_end = v[np.isclose(v[:, 0], v[:, 0].max())]  # file x = 2: the wedge's sharp edge
        assert np.allclose(thin_end[:, 2], low if apex_on_top else high)
        assert high - low == pytest.approx(0.5)


def test_units_scale_the_model_and_the_automatic_track_follows(tmp_path):
    model = tmp_path / "tray.obj"
    model.write_text(WEDGE_OBJ.replace("v 2 ", "v 355 ").replace(" 0.5\n", " 50\n"))  # mm-ish
    with pytest.warns(InputWarning, match=r"tray\.obj is 355 m across .* pass --units mm"):
        metres = load(model)
    track = np.ptp(metres.trajectory.positions[:, 1])
    assert track == pytest.approx(6 * 355.0)  # six model sizes: 2.1 km, as the issue saw
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a plausible size warns nothing
        mm = load(model, units="mm")
    size = np.ptp(model_vertices(mm), axis=0)
    assert size.max() == pytest.approx(0.355)
    assert np.ptp(mm.trajectory.positions[:, 1]) == pytest.approx(20.0)  # the 20 m minimum
    both = load(model, units="cm", scale=0.1)
    np.testing.assert_allclose(np.ptp(model_vertices(both), axis=0), size, rtol=1e-12)
    assert UNITS["in"] == 0.0254 and UNITS["ft"] == 0.3048


def test_a_model_the_track_runs_inside_warns(tmp_path):
    model = tmp_path / "hall.obj"  # 400 m x 200 m, 25 m tall: the 10 m track runs through it
    vertices, faces = WEDGE_OBJ.split("f", 1)
    big = np.loadtxt(vertices.replace("v", "").splitlines()) * [200.0, 200.0, 50.0]
    model.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in big) + "f" + faces)
    with pytest.warns(InputWarning) as seen:
        load(model)
    inside = [str(w.message) for w in seen if "runs inside" in str(w.message)]
    assert len(inside) == 1 and "hall.obj's bounding box" in inside[0] and "25 m tall" in inside[0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load(model, units="cm")  # 4 m across: beside the track, nothing to say


def test_a_speck_warns_with_the_scale_that_makes_it_a_metre(tmp_path):
    model = tmp_path / "valve.obj"
    model.write_text(WEDGE_OBJ)
    with pytest.warns(InputWarning, match=r"under 5 cm.*--scale 50 makes it 1 m"):
        load(model, scale=0.01)  # 2 cm


@pytest.mark.parametrize("heading", [0.0, 37.0, 270.0])
def test_position_and_heading_place_model_and_track(tmp_path, heading):
    model = tmp_path / "wedge.obj"
    model.write_text(WEDGE_OBJ)
    setup = load(model, position=(30.0, -12.0, 0.25), heading_deg=heading, pings=11)
    v = model_vertices(setup)
    centre = 0.5 * (v.min(axis=0) + v.max(axis=0))
    np.testing.assert_allclose(centre[:2], [30.0, -12.0], atol=1e-9)
    assert v[:, 2].min() == pytest.approx(0.25)
    traj = setup.trajectory
    mid = traj.positions[5]
    h = math.radians(heading)
    along, starboard = np.array([math.sin(h), math.cos(h)]), np.array([math.cos(h), -math.sin(h)])
    offset = centre[:2] - mid[:2]
    passing = setup.notes["placement"]["track"]["passing_m"]
    assert offset @ along == pytest.approx(0.0, abs=1e-9)
    assert offset @ starboard == pytest.approx(passing)  # mid-swath to starboard
    assert math.hypot(passing, setup.altitude) == pytest.approx(25.0)  # half the 50 m range
    np.testing.assert_allclose(traj.headings, h)


def test_ping_spacing_and_speed_set_the_track(tmp_path):
    model = tmp_path / "wedge.obj"
    model.write_text(WEDGE_OBJ)
    spaced = load(model, ping_spacing=0.25)
    assert spaced.trajectory.typical_spacing == pytest.approx(0.25)
    assert spaced.trajectory.n_pings == 81  # 20 m at 0.25 m
    fast = load(model, speed=2.0, sound_speed=1500.0, max_range=75.0, pings=7)
    assert fast.trajectory.typical_spacing == pytest.approx(2.0 * 2 * 75.0 / 1500.0)
    assert fast.trajectory.n_pings == 7
    with pytest.raises(SonarRasterError, match="--ping-spacing or --speed, not both"):
        load(model, ping_spacing=0.1, speed=1.0)


def test_sonar_overrides_on_a_description(tmp_path):
    ov = Overrides(frequency_hz=100e3, tilt_deg=12.0, beamwidth_deg=30.0, sound_speed=1480.0)
    setup = load_scene("flat_calibration", ov)
    sonar = setup.sonar
    assert (sonar.frequency_hz, sonar.sound_speed) == (100e3, 1480.0)
    assert math.degrees(sonar.tilt) == pytest.approx(12.0)
    assert sonar.beam.kind == "gaussian"
    half = np.radians([12.0 - 15.0, 12.0, 12.0 + 15.0])  # half power at ±beamwidth/2
    np.testing.assert_allclose(sonar.gain(half), [0.5, 1.0, 0.5], rtol=1e-3)


def test_heading_and_spacing_override_a_straight_track_not_a_csv(tmp_path):
    setup = load_scene("flat_calibration", Overrides(heading_deg=90.0, ping_spacing=0.3))
    step = np.diff(setup.trajectory.positions, axis=0)
    np.testing.assert_allclose(step[:, :2], np.tile([0.3, 0.0], (len(step), 1)), atol=1e-12)
    (tmp_path / "t.csv").write_text("x,y,z,heading_deg\n0,0,10,0\n0,1,10,0\n")
    (tmp_path / "s.toml").write_text('[seabed]\nkind = "flat"\n[trajectory]\ncsv = "t.csv"\n')
    with pytest.raises(SonarRasterError, match=r"track comes from t\.csv; --heading apply"):
        load_scene(tmp_path / "s.toml", Overrides(heading_deg=90.0))


def test_description_objects_take_units_and_any_up_axis(tmp_path):
    (tmp_path / "w.obj").write_text(WEDGE_OBJ)
    (tmp_path / "s.toml").write_text(
        '[[objects]]\nfile = "w.obj"\nunits = "cm"\nup = "x"\nposition = [0, 0]\n'
    )
    v = model_vertices(load_scene(tmp_path / "s.toml"))
    np.testing.assert_allclose(np.ptp(v, axis=0), [0.005, 0.01, 0.02], atol=1e-12)
    with pytest.raises(SonarRasterError, match=r"in a scene description give 'up', 'units'"):
        load_scene(tmp_path / "s.toml", Overrides(placement=Placement(units="mm")))
    (tmp_path / "s.toml").write_text('[[objects]]\nfile = "w.obj"\nunits = "yards"\n')
    with pytest.raises(SonarRasterError, match=r"'units' must be one of m, cm, mm"):
        load_scene(tmp_path / "s.toml")


def test_few_bins_and_a_tilt_without_a_beam_warn(tmp_path):
    with pytest.warns(InputWarning, match=r"leaves 4 range bins per side"):
        setup = load_scene("flat_calibration", Overrides(max_range=40.0, range_bin=10.0))
    assert setup.sonar.n_bins == 4 < FEW_BINS
    model = tmp_path / "w.obj"
    model.write_text(WEDGE_OBJ)
    with pytest.warns(InputWarning, match=r"--tilt 30 changes nothing with a uniform"):
        load(model, tilt_deg=30.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load(model, tilt_deg=30.0, beamwidth_deg=40.0)


def test_a_recorded_track_replaces_the_track_keeping_its_shape(tmp_path):
    n = 9
    xy = np.column_stack([np.linspace(100.0, 104.0, n), np.linspace(50.0, 58.0, n) ** 1.01])
    altitude = np.linspace(4.0, 6.0, n)
    headings = np.full(n, math.atan2(4.0, 8.0))
    track = RecordedTrack(xy, altitude, headings, np.zeros(n), np.zeros(n), "rec.xtf")
    setup = load_scene("flat_calibration", Overrides(track=track))
    pos = setup.trajectory.positions
    np.testing.assert_allclose(np.diff(pos[:, :2], axis=0), np.diff(xy, axis=0), atol=1e-9)
    np.testing.assert_allclose(pos[:, 2] - setup.scene.ground_z, altitude, atol=1e-9)
    own = load_scene("flat_calibration").trajectory.positions
    np.testing.assert_allclose(pos[n // 2, :2], own[len(own) // 2, :2], atol=1e-9)
    with pytest.raises(SonarRasterError, match="--heading cannot be combined with --track"):
        load_scene("flat_calibration", Overrides(track=track, heading_deg=3.0))
    model = tmp_path / "w.obj"
    model.write_text(WEDGE_OBJ)
    placed = load_scene(model, Overrides(track=track))
    v = model_vertices(placed)
    centre = 0.5 * (v.min(axis=0) + v.max(axis=0))
    h = headings[n // 2]
    offset = centre[:2] - placed.trajectory.positions[n // 2, :2]
    assert offset @ np.array([math.cos(h), -math.sin(h)]) == pytest.approx(
        placed.notes["placement"]["track"]["passing_m"]
    )
