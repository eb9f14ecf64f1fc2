"""The renderer's object-label pass: which object each (ping, range bin) cell came from."""

from __future__ import annotations

import math

import numpy as np
from conftest import box_from_bounds, rect_seabed

from sonar_raster.scene import build_scene
from sonar_raster.sonar import Sonar
from sonar_raster.trajectory import Trajectory

SEABED, BOX = 1, 2  # labels are object id + 1, in the order the parts were given


def _box_scene(x0=19.4, x1=20.0, y0=-3.0, y1=3.0, height=1.0):
    return build_scene(
        [
            rect_seabed(-60.0, 60.0, -40.0, 40.0),
            box_from_bounds([[x0, y0, 0.0], [x1, y1, height]], name="box"),
        ]
    )


def _slant_interval(bounds, ping_y: float, altitude: float) -> tuple[float, float]:
    """Smallest and largest slant range from a ping to a box's corners and its nearest point."""
    lo, hi = np.asarray(bounds, dtype=float)
    corners = np.array(np.meshgrid(*zip(lo, hi, strict=True))).reshape(3, -1).T
    sonar = np.array([0.0, ping_y, altitude])
    nearest = np.clip(sonar, lo, hi)
    d = np.linalg.norm(corners - sonar, axis=1)
    return float(np.linalg.norm(nearest - sonar)), float(d.max())


def test_labels_do_not_change_the_image_and_cover_returns(gl):
    scene = _box_scene()
    sonar = Sonar(max_range=40.0, range_bin=0.05)
    traj = Trajectory.straight((0.0, -6.0, 8.0), 0.0, 0.2, 60)
    plain = gl.render(scene, sonar, traj)
    labelled = gl.render(scene, sonar, traj, labels=True)
    assert plain.labels is None
    assert labelled.metadata["label_names"] == ["(no return)", "seabed", "box"]
    for side in sonar.sides:
        assert np.array_equal(plain.sides[side], labelled.sides[side])
        lab = labelled.labels[side]
        assert lab.dtype == np.uint16 and lab.shape == plain.sides[side].shape
        # Every cell that holds energy has a label; the water column has none.
        assert np.all(lab[plain.sides[side] > 0] > 0)
        first_bottom = int(8.0 / sonar.range_bin) - 1
        assert np.all(lab[:, :first_bottom] == 0)
    assert not np.any(labelled.labels["port"] == BOX), "the box is on the starboard side"


def test_box_label_lies_in_the_box_range_interval_and_its_pings(gl):
    bounds = [[19.4, -3.0, 0.0], [20.0, 3.0, 1.0]]
    scene = _box_scene(*(bounds[0][0], bounds[1][0], bounds[0][1], bounds[1][1], bounds[1][2]))
    sonar = Sonar(max_range=40.0, range_bin=0.05, sides=("starboard",))
    spacing, altitude = 0.2, 8.0
    traj = Trajectory.straight((0.0, -8.0, altitude), 0.0, spacing, 80)
    lab = gl.render(scene, sonar, traj, labels=True).labels["starboard"]
    ping_y = traj.positions[:, 1]
    for ping in range(traj.n_pings):
        bins = np.flatnonzero(lab[ping] == BOX)
        inside = -3.0 + spacing < ping_y[ping] < 3.0 - spacing
        outside = ping_y[ping] < -3.0 - spacing or ping_y[ping] > 3.0 + spacing
        if outside:
            assert len(bins) == 0, f"ping {ping} at y={ping_y[ping]:.1f} sees the box"
        if inside:
            assert len(bins) > 0, f"ping {ping} at y={ping_y[ping]:.1f} misses the box"
            r_lo, r_hi = _slant_interval(bounds, ping_y[ping], altitude)
            assert bins.min() >= math.floor(r_lo / sonar.range_bin) - 1
            assert bins.max() <= math.ceil(r_hi / sonar.range_bin) + 1
            # Beyond the box: its shadow (no label), then the seabed again.
            after = lab[ping, bins.max() + 1 :]
            assert after[0] == 0 and np.any(after == SEABED)


def test_labels_follow_objects_on_a_dogleg_track_with_culling(gl):
    """Two boxes, one per leg; culled draws upload only nearby faces and their labels."""
    parts = [
        rect_seabed(-150.0, 150.0, -150.0, 150.0),
        box_from_bounds([[15.0, -1.0, 0.0], [16.0, 1.0, 1.0]], name="north"),
        box_from_bounds([[-1.0, 95.0, 0.0], [1.0, 96.0, 1.0]], name="east"),
    ]
    scene = build_scene(parts)
    sonar = Sonar(max_range=30.0, range_bin=0.1, sides=("starboard",))
    leg1 = Trajectory.straight((0.0, -20.0, 8.0), 0.0, 0.5, 81)  # north along x = 0
    leg2 = Trajectory.straight((0.0, 110.0, 8.0), 90.0, 0.5, 81)  # east along y = 110
    traj = Trajectory(
        np.concatenate([leg1.positions, leg2.positions]),
        np.concatenate([leg1.headings, leg2.headings]),
        np.zeros(162),
    )
    gl.settings = type(gl.settings)(max_edge=2.0)  # many small triangles: culling pays
    try:
        image = gl.render(scene, sonar, traj, labels=True)
    finally:
        gl.settings = type(gl.settings)()
    lab = image.labels["starboard"]
    # Leg 1 (heading north) has the "north" box to starboard; leg 2 (heading east) has
    # starboard to the south, where the "east" box (y = 95..96) lies, 14 m off the track.
    assert np.any(lab[:81] == 2) and not np.any(lab[:81] == 3)
    assert np.any(lab[81:] == 3) and not np.any(lab[81:] == 2)
    assert np.all(lab[image.sides["starboard"] > 0] > 0)


def test_stationary_sonar_repeats_the_labels(gl):
    scene = _box_scene()
    sonar = Sonar(max_range=30.0, range_bin=0.05, sides=("starboard",))
    traj = Trajectory(np.tile([0.0, 0.0, 8.0], (5, 1)), np.zeros(5), np.zeros(5))
    lab = gl.render(scene, sonar, traj, labels=True).labels["starboard"]
    assert np.any(lab[0] == BOX)
    assert all(np.array_equal(lab[0], lab[k]) for k in range(1, 5))


def test_no_label_work_when_labels_are_off():
    """Labels off: the label programs are never built, no label target or buffer exists."""
    from sonar_raster.rendering.gl.raster import RasterRenderer

    scene = _box_scene()
    sonar = Sonar(max_range=30.0, range_bin=0.1)
    traj = Trajectory.straight((0.0, -2.0, 8.0), 0.0, 0.2, 10)
    with RasterRenderer("egl") as r:
        r.render(scene, sonar, traj)
        live = r.live_objects()
        assert any(name.startswith("program") for name in live)
        assert not any("labels" in name for name in live), live
        r.render(scene, sonar, traj, labels=True)
        live = r.live_objects()
        assert "program samples labels" in live and "target labels" in live, live
