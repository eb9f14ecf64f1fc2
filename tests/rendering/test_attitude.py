"""Crab (heading off the course) and pitch tilt the fans: raster, reference and geometry agree."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import box_from_bounds, rect_seabed

from sonar_raster.errors import SonarRasterError
from sonar_raster.rendering.analytic import flat_seabed_profile
from sonar_raster.rendering.reference import render_reference
from sonar_raster.scene import build_scene
from sonar_raster.sonar import Sonar
from sonar_raster.trajectory import Trajectory

ALTITUDE, SPACING = 8.0, 0.2


def _track(n: int, crab_deg: float = 0.0, pitch_deg: float = 0.0, y0: float = -4.0) -> Trajectory:
    """Northbound pings at x = 0; the vehicle points ``crab_deg`` right of north."""
    pos = np.column_stack([np.zeros(n), y0 + SPACING * np.arange(n), np.full(n, ALTITUDE)])
    return Trajectory(pos, np.full(n, math.radians(crab_deg)), 0.0, math.radians(pitch_deg))


def _pole_scene(x: float):
    """A thin, tall box: a point-like target along track, at across-track distance x."""
    return build_scene(
        [
            rect_seabed(-40.0, 40.0, -40.0, 60.0),
            box_from_bounds([[x, -0.1, 0.0], [x + 0.3, 0.1, 3.0]]),
        ]
    )


@pytest.mark.parametrize("crab,pitch", [(10.0, 0.0), (-8.0, -5.0)])
def test_raster_matches_reference_with_crab_and_pitch(gl, crab, pitch):
    scene = build_scene(
        [
            rect_seabed(-20.0, 20.0, -20.0, 20.0),
            box_from_bounds([[6.0, -1.0, 0.0], [7.0, 1.0, 1.5]]),
        ]
    )
    sonar = Sonar(max_range=12.0, range_bin=0.06)
    traj = _track(6, crab, pitch, y0=-0.5)
    got = gl.render(scene, sonar, traj)
    ref = render_reference(scene, sonar, traj)
    for side in sonar.sides:
        a, b = got.sides[side].astype(np.float64), ref.sides[side].astype(np.float64)
        err = np.abs(a - b).sum() / b.sum()
        assert err <= 0.02, f"{side}: relative L1 {err:.4f}"


@pytest.mark.parametrize(
    "crab,pitch,x",
    [(10.0, 0.0, 15.0), (-10.0, 0.0, 15.0), (0.0, 8.0, 15.0), (0.0, 0.0, 15.0)],
)
def test_a_target_is_seen_by_the_ping_whose_fan_passes_through_it(gl, crab, pitch, x):
    """The fan of the ping at travel u holds points with d·f = u (v·f): a target at across
    track x and height z is seen at u = y + x tan(crab) − (altitude − z) tan(pitch)."""
    sonar = Sonar(max_range=25.0, range_bin=0.05, sides=("starboard",))
    traj = _track(200, crab, pitch, y0=-20.0)
    image = gl.render(_pole_scene(x), sonar, traj).sides["starboard"].astype(np.float64)
    # The pole's top (z = 3 m) returns beyond the seabed's pings' near part: use the bins of
    # its near face at the top, where nothing else is as bright.
    z_top = 3.0
    r_top = math.hypot(x, ALTITUDE - z_top)
    k = int(r_top / sonar.range_bin)
    window = image[:, k - 8 : k + 8].sum(axis=1)
    window -= np.median(window)
    measured = traj.positions[int(np.argmax(window)), 1]
    expected = x * math.tan(math.radians(crab)) - (ALTITUDE - z_top) * math.tan(math.radians(pitch))
    assert abs(measured - expected) <= 2 * SPACING, (measured, expected)


def test_crab_keeps_a_flat_seabed_profile(gl):
    """Fans perpendicular to the heading still sweep the same area: the profile is unchanged
    up to the cos(crab) of the fans' spacing (the spacing of fans is u cos(crab))."""
    scene = build_scene([rect_seabed(-60.0, 60.0, -60.0, 60.0)])
    sonar = Sonar(max_range=20.0, range_bin=0.05, sides=("starboard",))
    crab = 12.0
    image = gl.render(scene, sonar, _track(10, crab)).sides["starboard"].astype(np.float64)
    expected = flat_seabed_profile(sonar, ALTITUDE, 0.5, SPACING) * math.cos(math.radians(crab))
    first = int(ALTITUDE / sonar.range_bin) + 2
    np.testing.assert_allclose(image[:, first:], np.tile(expected[first:], (10, 1)), rtol=0.01)


def test_pitch_and_heading_come_from_the_csv(tmp_path):
    path = tmp_path / "track.csv"
    path.write_text("x,y,z,heading_deg,roll_deg,pitch_deg\n0,0,8,5,1,2\n0,1,8,5,1,2\n")
    traj = Trajectory.from_csv(str(path))
    assert traj.pitch == pytest.approx(np.radians([2.0, 2.0]))
    seg = traj.segments(0.01)[0]
    assert seg.fore == pytest.approx(
        [
            math.sin(math.radians(5)) * math.cos(math.radians(2)),
            math.cos(math.radians(5)) * math.cos(math.radians(2)),
            math.sin(math.radians(2)),
        ]
    )
    # A point in the fan of the ping at travel u maps to (u, side, up) with side, up in the fan.
    u, side, up = 0.7, 3.0, -2.0
    point = seg.origin + u * seg.along + side * seg.starboard + up * seg.up
    assert seg.shear @ (point - seg.origin) == pytest.approx([u, side, up])


def test_subset_keeps_every_pose_field():
    traj = _track(10, crab_deg=4.0, pitch_deg=3.0)
    part = traj.subset(slice(2, 6))
    for name in ("positions", "headings", "roll", "pitch"):
        np.testing.assert_array_equal(getattr(part, name), getattr(traj, name)[2:6])


def test_heading_far_off_the_course_is_refused():
    traj = _track(5, crab_deg=75.0)
    with pytest.raises(SonarRasterError, match="off the direction of travel"):
        traj.segments(0.01)


def test_a_ping_repeating_its_neighbours_fix_at_another_depth_is_its_own_segment():
    """The sample XTF's first record has no fix: it takes the next ping's position, and its
    own altitude puts it 2.5 m higher. With the same attitude as the next ping, the two made a
    vertical segment, which has no fan plane and stopped the render."""
    traj = _track(8)
    pos = traj.positions.copy()
    pos[0, :2] = pos[1, :2]
    pos[0, 2] += 2.5
    moved = Trajectory(pos, traj.headings, traj.roll, traj.pitch)
    segments = moved.segments(0.01)
    assert segments[0].count == 1 and sum(s.count for s in segments) == 8


def test_scene_file_sets_crab_pitch_and_roll(tmp_path):
    from sonar_raster.scenes.description import load_scene_file

    path = tmp_path / "crab.toml"
    path.write_text(
        '[sonar]\nmax_range = 20.0\n[seabed]\nkind = "flat"\nsize = [60.0, 60.0]\n'
        "[trajectory]\nheading_deg = 90.0\ncrab_deg = 7.0\npitch_deg = -3.0\nroll_deg = 2.0\n"
        "pings = 5\nspacing = 0.2\n"
    )
    traj = load_scene_file(path).trajectory
    assert traj.headings == pytest.approx(np.radians(np.full(5, 97.0)))
    assert traj.pitch == pytest.approx(np.radians(np.full(5, -3.0)))
    assert traj.roll == pytest.approx(np.radians(np.full(5, 2.0)))
    # The course stays east (heading_deg); the vehicle points 7 degrees right of it.
    assert np.diff(traj.positions[:, 0]) == pytest.approx(np.full(4, 0.2))


def test_a_diving_track_leaves_no_empty_rows(gl):
    """Regression: a straight track descending 0.09 m per 0.12 m ping once left a quarter of
    its rows empty (the fan was tilted with the track but the rows were not)."""
    scene = build_scene([rect_seabed(-40.0, 40.0, -40.0, 40.0)])
    sonar = Sonar(max_range=20.0, range_bin=0.05)
    n = 40
    pos = np.column_stack([np.zeros(n), 0.12 * np.arange(n), 12.0 - 0.09 * np.arange(n)])
    image = gl.render(scene, sonar, Trajectory(pos, np.zeros(n), 0.0))
    for side in sonar.sides:
        assert np.all(image.sides[side].sum(axis=1) > 0), f"{side}: empty rows"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("x,y,z,heading_deg\n0,0,5,0\n0,0.1,5\n", r"Line #3 \(got 3 columns instead of 4\)$"),
        ("x,y,z,heading_deg\n0,0,5,0\n0,abc,5,0\n", r"line 3 has an empty or non-numeric cell"),
        ("x,y,z,heading_deg\n", "has a header but no rows"),
        ("", "trajectory CSV is empty"),
    ],
    ids=["short row", "text cell", "header only", "empty"],
)
def test_a_bad_track_csv_is_one_line_naming_the_line(tmp_path, text, message):
    from sonar_raster.errors import SonarRasterError

    path = tmp_path / "track.csv"
    path.write_text(text)
    with pytest.raises(SonarRasterError, match=message) as info:
        Trajectory.from_csv(str(path))
    assert "\n" not in str(info.value)


def test_a_track_csv_with_a_byte_order_mark_reads(tmp_path):
    path = tmp_path / "track.csv"
    path.write_bytes("\ufeffx,y,z,heading_deg\n0,0,5,0\n0,0.1,5,0\n".encode())
    assert Trajectory.from_csv(str(path)).n_pings == 2
