"""The GL renderer against closed forms, the numpy reference, and itself moved or re-run."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import box, plane

from sonar_raster.rendering.analytic import flat_seabed_profile, shadow_length
from sonar_raster.rendering.gl.raster import RasterSettings
from sonar_raster.scene import MeshPart, build_scene
from sonar_raster.sonar import BeamPattern, Sonar
from sonar_raster.trajectory import Trajectory


def rel_l1(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a.astype(np.float64) - b).sum() / np.abs(b).sum())


@pytest.mark.parametrize("beam", [BeamPattern.uniform(), BeamPattern.gaussian(30.0)])
@pytest.mark.parametrize("split", ["footprint"])
def test_flat_seabed_follows_closed_form(gl, flat_scene, beam, split):
    sonar = Sonar(max_range=40.0, range_bin=0.05, beam=beam, tilt=math.radians(15))
    altitude, spacing = 8.0, 0.2
    traj = Trajectory.straight((0.0, -2.0, altitude), 0.0, spacing, 12)
    gl.settings = RasterSettings(split=split)
    image = gl.render(flat_scene, sonar, traj)
    first = int(math.ceil(altitude / sonar.range_bin)) + 1  # bins fully beyond nadir
    for side in ("port", "starboard"):
        expected = flat_seabed_profile(sonar, altitude, 0.5, spacing, side=side)
        got = image.sides[side].astype(np.float64)
        assert np.all(got[:, : first - 2] == 0.0), "water column must be empty"
        err = np.abs(got[:, first:] / expected[first:] - 1.0)
        assert err.max() < 0.01, f"{side}: worst bin off by {err.max():.4f}"


def test_nearest_split_is_worse_than_footprint(gl, flat_scene):
    """The footprint deposit removes the bin aliasing of point samples (measured, not assumed)."""
    sonar = Sonar(max_range=30.0, range_bin=0.05, sides=("starboard",))
    traj = Trajectory.straight((0.0, 0.0, 10.0), 0.0, 0.2, 4)
    expected = flat_seabed_profile(sonar, 10.0, 0.5, 0.2)[210:]
    errors = {}
    for split in ("nearest", "footprint"):
        gl.settings = RasterSettings(split=split)
        got = gl.render(flat_scene, sonar, traj).sides["starboard"].mean(axis=0)[210:]
        errors[split] = rel_l1(got, expected)
    gl.settings = RasterSettings()
    assert errors["footprint"] < 0.002
    assert errors["nearest"] > 5 * errors["footprint"]


@pytest.mark.parametrize(
    "height,ground_range,altitude", [(1.0, 20.0, 10.0), (2.0, 15.0, 6.0), (0.5, 30.0, 12.0)]
)
def test_shadow_length(gl, height, ground_range, altitude):
    """Ground shadow of a box behind its far top edge is H x / (h - H) within one bin."""
    depth = 0.6
    near = ground_range - depth
    scene = build_scene(
        [plane(300.0), box((near + depth / 2, 0.0, height / 2), (depth, 6.0, height))]
    )
    sonar = Sonar(max_range=60.0, range_bin=0.05, sides=("starboard",))
    traj = Trajectory.straight((0.0, -0.5, altitude), 0.0, 0.1, 11)
    row = gl.render(scene, sonar, traj).sides["starboard"][5].astype(np.float64)
    expected = shadow_length(height, ground_range, altitude)
    # The shadow is the last run of empty bins before the seabed lights up again; search from
    # the box's top far edge to well past the expected end (the box's front face may lay over
    # into bins beyond its top edge, so the run does not always start right at the edge).
    k0 = int(math.hypot(ground_range, altitude - height) / sonar.range_bin)
    k1 = int(math.hypot(ground_range + expected, altitude) / sonar.range_bin) + 40
    dark = np.nonzero(row[k0:k1] == 0.0)[0]
    assert len(dark) > 0, "no shadow"
    r_end = (k0 + dark[-1] + 1) * sonar.range_bin  # first lit bin after the shadow
    assert np.all(row[k0 + dark[-1] + 1 : k1] > 0)
    measured = math.sqrt(r_end**2 - altitude**2) - ground_range
    ground_per_bin = sonar.range_bin * r_end / math.sqrt(r_end**2 - altitude**2)
    assert abs(measured - expected) <= ground_per_bin, (measured, expected)


def test_survey_coordinates_keep_precision(gl):
    """The same scene 500 km from the origin renders the same image (float64 shift on the CPU)."""
    parts = [plane(120.0), box((25.0, 0.0, 0.5), (1.0, 2.0, 1.0))]
    sonar = Sonar(max_range=40.0, range_bin=0.05)
    traj = Trajectory.straight((0.0, -3.0, 9.0), 30.0, 0.1, 60)
    near = gl.render(build_scene(parts), sonar, traj)
    offset = np.array([500_000.0, 4_500_000.0, 0.0])
    far_parts = [
        MeshPart(p.vertices + offset, p.faces, p.reflectivity, p.name, p.is_seabed) for p in parts
    ]
    far_traj = Trajectory(traj.positions + offset, traj.headings, traj.roll)
    far = gl.render(build_scene(far_parts), sonar, far_traj)
    for side in sonar.sides:
        assert rel_l1(far.sides[side], near.sides[side]) < 1e-4


def test_egl_and_osmesa_agree(gl, osmesa_renderer, flat_scene):
    sonar = Sonar(max_range=30.0, range_bin=0.05)
    traj = Trajectory.straight((0.0, 0.0, 10.0), 0.0, 0.2, 8)
    parts = build_scene([plane(120.0), box((15.0, 0.5, 0.5), (1.0, 1.0, 1.0))])
    a = gl.render(parts, sonar, traj)
    b = osmesa_renderer.render(parts, sonar, traj)
    assert osmesa_renderer.backend == "osmesa" and gl.backend == "egl"
    for side in sonar.sides:
        np.testing.assert_allclose(a.sides[side], b.sides[side], rtol=1e-6, atol=0)


def test_deterministic(gl):
    scene = build_scene([plane(120.0), box((15.0, 0.5, 0.5), (1.0, 1.0, 1.0))])
    sonar = Sonar(max_range=30.0, range_bin=0.05)
    traj = Trajectory.straight((0.0, 0.0, 10.0), 0.0, 0.2, 8)
    a = gl.render(scene, sonar, traj)
    b = gl.render(scene, sonar, traj)
    for side in sonar.sides:
        assert np.array_equal(a.sides[side], b.sides[side])


def test_stationary_sonar_repeats_one_row(gl, flat_scene):
    sonar = Sonar(max_range=30.0, range_bin=0.1)
    traj = Trajectory(np.tile([0.0, 0.0, 10.0], (5, 1)), np.zeros(5), np.zeros(5))
    image = gl.render(flat_scene, sonar, traj)
    rows = image.sides["starboard"]
    assert rows[0].sum() > 0 and np.all(rows == rows[0])
    # A stationary ping integrates 1 m along track (no motion to set a width).
    expected = flat_seabed_profile(sonar, 10.0, 0.5, 1.0)
    np.testing.assert_allclose(rows[0][110:], expected[110:], rtol=0.01)


def test_degenerate_triangles_are_dropped(gl, caplog):
    base = plane(120.0)
    v = np.vstack([base.vertices, [[5.0, 5.0, 0.0], [6.0, 6.0, 0.0], [7.0, 7.0, 0.0]]])
    f = np.vstack([base.faces, [[4, 5, 6], [0, 0, 1], [4, 4, 4]]])  # collinear, repeated
    with caplog.at_level("WARNING"):
        dirty = build_scene([MeshPart(v, f, 0.5, "seabed", True)])
    assert dirty.n_triangles == 2 and "dropped 3" in caplog.text
    sonar = Sonar(max_range=30.0, range_bin=0.1)
    traj = Trajectory.straight((0.0, 0.0, 10.0), 0.0, 0.2, 4)
    a = gl.render(dirty, sonar, traj)
    b = gl.render(build_scene([base]), sonar, traj)
    assert np.array_equal(a.sides["port"], b.sides["port"])
    assert np.all(np.isfinite(a.sides["port"]))


def test_curved_track_matches_straight_segments(gl, flat_scene):
    """A track split into segments renders each ping as a straight pass would."""
    sonar = Sonar(max_range=30.0, range_bin=0.1, sides=("starboard",))
    heading = np.radians(np.r_[np.zeros(10), np.full(10, 40.0)])
    steps = np.stack([np.sin(heading), np.cos(heading), np.zeros(20)], axis=1) * 0.2
    pos = np.cumsum(steps, axis=0) + [0.0, 0.0, 10.0]
    traj = Trajectory(pos, heading, np.zeros(20))
    assert len(traj.segments(0.025)) >= 2
    image = gl.render(flat_scene, sonar, traj).sides["starboard"]
    expected = flat_seabed_profile(sonar, 10.0, 0.5, 0.2)
    np.testing.assert_allclose(image[2:8, 120:], np.tile(expected[120:], (6, 1)), rtol=0.01)
    np.testing.assert_allclose(image[12:18, 120:], np.tile(expected[120:], (6, 1)), rtol=0.01)


def test_along_track_slope_is_integrated_over_the_ping_width(gl):
    """On a seabed sloping along track, one ray per ping still integrates the ping's slab.

    Range changes along the slab; the footprint deposit spreads each sample over the range
    interval its (angle × along-track) patch covers, so a single row matches the slab
    integral of the numpy reference as closely as many rows do.
    """
    from sonar_raster.rendering.reference import render_reference

    slope = math.radians(15.0)
    base = plane(120.0)
    v = base.vertices.copy()
    v[:, 2] = v[:, 1] * math.tan(slope)
    scene = build_scene([MeshPart(v, base.faces, 0.5, "seabed", True)])
    sonar = Sonar(max_range=30.0, range_bin=0.05, sides=("starboard",))
    traj = Trajectory.straight((0.0, 0.0, 10.0), 0.0, 0.5, 4)
    ref = render_reference(scene, sonar, traj).sides["starboard"]
    errors = {}
    for along in (1, 8):
        gl.settings = RasterSettings(along_samples=along)
        errors[along] = rel_l1(gl.render(scene, sonar, traj).sides["starboard"], ref)
    gl.settings = RasterSettings()
    assert errors[1] < 0.005 and errors[8] < 0.005, errors


def test_reused_renderer_matches_a_fresh_one(gl):
    """Targets are reused between renders (depth-only clears): nothing stale leaks through."""
    from sonar_raster.rendering.gl.raster import RasterRenderer

    busy = build_scene([plane(120.0), box((12.0, 1.0, 1.0), (1.0, 3.0, 2.0))])
    sparse = build_scene([plane(30.0, center=(0.0, 0.0))])
    sonar = Sonar(max_range=30.0, range_bin=0.05)
    traj = Trajectory.straight((0.0, 0.0, 10.0), 0.0, 0.2, 12)
    gl.render(busy, sonar, traj)
    again = gl.render(sparse, sonar, traj)
    with RasterRenderer("egl") as fresh:
        first = fresh.render(sparse, sonar, traj)
    for side in sonar.sides:
        assert np.array_equal(again.sides[side], first.sides[side])
