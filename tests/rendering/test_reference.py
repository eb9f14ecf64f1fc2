"""The patch reference renderer against closed forms and its own symmetries."""

import math

import numpy as np
import pytest
from conftest import box_from_bounds as box
from conftest import rect_seabed as seabed

from sonar_raster.errors import SonarRasterError
from sonar_raster.rendering.analytic import flat_seabed_profile, shadow_length
from sonar_raster.rendering.reference import render_reference
from sonar_raster.scene import MeshPart, build_scene
from sonar_raster.sonar import BeamPattern, Sonar
from sonar_raster.trajectory import Trajectory

ALTITUDE = 10.0
BIN = 0.1


pytestmark = pytest.mark.usefixtures("strict_float")


def plate(centre, normal, size, reflectivity=0.7):
    """Square of side ``size`` centred at ``centre`` with unit normal ``normal`` (two triangles)."""
    n = np.asarray(normal, dtype=float)
    n /= np.linalg.norm(n)
    e1 = np.cross([0.0, 1.0, 0.0], n)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    h = 0.5 * size
    c = np.asarray(centre, dtype=float)
    v = np.array(
        [c - h * e1 - h * e2, c + h * e1 - h * e2, c + h * e1 + h * e2, c - h * e1 + h * e2]
    )
    return MeshPart(v, np.array([[0, 1, 2], [0, 2, 3]]), reflectivity, "plate")


def mirrored(part):
    """Reflect x -> -x and reverse the winding so normals stay outward."""
    v = part.vertices * np.array([-1.0, 1.0, 1.0])
    return MeshPart(v, part.faces[:, ::-1], part.reflectivity, part.name, part.is_seabed)


def ground(r, h=ALTITUDE):
    return math.sqrt(max(r * r - h * h, 0.0))


@pytest.mark.parametrize(
    ("side", "beam", "roll"),
    [("starboard", BeamPattern.uniform(), 0.0), ("port", BeamPattern.gaussian(50.0), 0.05)],
)
def test_flat_seabed_matches_closed_form(side, beam, roll):
    # the track runs at 30 degrees to the seabed's triangle edges: a patch grid aligned with
    # the track puts whole columns of patch centres on bin edges (aliasing of ~8 % per bin)
    sonar = Sonar(max_range=30.0, range_bin=BIN, beam=beam, sides=(side,))
    heading = math.radians(30.0)
    along = np.array([math.sin(heading), math.cos(heading), 0.0])
    pos = np.array([0.0, -2.0, ALTITUDE]) + np.arange(20)[:, None] * 0.2 * along
    traj = Trajectory(pos, np.full(20, heading), np.full(20, roll))
    scene = build_scene([seabed(-40, 40, -40, 40)])
    image = render_reference(scene, sonar, traj)
    rows = image.sides[side].astype(np.float64)
    assert rows.shape == (20, sonar.n_bins) and image.sides[side].dtype == np.float32
    expected = flat_seabed_profile(sonar, ALTITUDE, 0.5, 0.2, side=side, roll=roll)
    nadir = int(ALTITUDE / BIN)
    interior = slice(nadir + 2, sonar.n_bins)
    np.testing.assert_allclose(rows.mean(axis=0)[interior], expected[interior], rtol=0.01)
    # single pings carry the patch sampling noise of point-sampled patches (a few per cent)
    np.testing.assert_allclose(rows[:, interior], np.tile(expected[interior], (20, 1)), rtol=0.05)
    assert np.all(rows[:, :nadir] == 0.0)
    assert image.metadata["renderer"] == "reference"
    assert image.metadata["patch_size"] == pytest.approx(BIN / 4)


@pytest.mark.parametrize(
    ("height", "x", "h"), [(1.0, 12.0, 10.0), (2.0, 8.0, 10.0), (3.0, 15.0, 12.0)]
)
def test_shadow_length_behind_box(height, x, h):
    depth = 0.3  # box extent across track; its top's far edge is at ground range x
    x0 = x - depth
    # the box's top and front face return nearer than the seabed at its foot
    assert math.hypot(x, h - height) < math.hypot(x0, h)
    sonar = Sonar(max_range=30.0, range_bin=BIN, sides=("starboard",))
    traj = Trajectory.straight((0.0, 0.0, h), 0.0, 0.2, 5)
    scene = build_scene([seabed(-1, 29, -4, 5), box([[x0, -5.0, 0.0], [x, 6.0, height]])])
    row = render_reference(scene, sonar, traj).sides["starboard"].mean(axis=0)
    lit = np.flatnonzero(row > 0)
    gaps = np.flatnonzero(np.diff(lit) > 1)
    assert len(gaps) == 1, "expected exactly one shadow"
    last_lit, next_lit = lit[gaps[0]], lit[gaps[0] + 1]
    measured = ground((next_lit + 0.5) * BIN, h) - ground((last_lit + 0.5) * BIN, h)
    expected = shadow_length(height, x, h) + depth
    x_end = x + shadow_length(height, x, h)
    one_bin = BIN * math.hypot(x_end, h) / x_end  # a range bin on the seabed at the shadow end
    assert abs(measured - expected) <= one_bin


def test_tilted_plate_energy():
    # a plate facing the sonar, alone: the image holds the whole Σ Φ R cos θ A
    beam = BeamPattern.gaussian(40.0)
    roll = 0.05
    sonar = Sonar(max_range=30.0, range_bin=BIN, beam=beam, sides=("starboard",))
    traj = Trajectory(
        np.column_stack([np.zeros(20), np.arange(20) * 0.2, np.full(20, ALTITUDE)]),
        np.zeros(20),
        np.full(20, roll),
    )
    centre, normal, size, refl = np.array([12.0, 2.0, 4.0]), [-1.0, 0.3, 0.8], 1.0, 0.7
    scene = build_scene([plate(centre, normal, size, refl)])
    image = render_reference(scene, sonar, traj)
    total = float(image.sides["starboard"].astype(np.float64).sum())
    # independent: tensor Gauss-Legendre over the plate, thin fan seen from (0, y, altitude)
    v, f = scene.vertices, scene.faces
    e1, e2 = v[1] - v[0], v[3] - v[0]
    n = np.cross(e1, e2)
    n /= np.linalg.norm(n)
    g, w = np.polynomial.legendre.leggauss(40)
    s, t = np.meshgrid(0.5 * (g + 1), 0.5 * (g + 1), indexing="ij")
    pts = v[0] + s[..., None] * e1 + t[..., None] * e2
    q = np.stack([np.zeros_like(s), pts[..., 1], np.full_like(s, ALTITUDE)], axis=-1)
    d = q - pts
    r = np.linalg.norm(d, axis=-1)
    cos = (d @ n) / r
    alpha = np.arctan2(ALTITUDE - pts[..., 2], pts[..., 0])
    integrand = beam(alpha - (sonar.tilt + roll)) * refl * cos
    area = np.linalg.norm(np.cross(e1, e2))
    expected = float(np.einsum("i,j,ij->", w, w, integrand)) * area / 4.0
    assert len(f) == 2 and np.all(cos > 0) and r.max() < sonar.max_range
    assert total == pytest.approx(expected, rel=1e-3)


def test_an_open_sheet_returns_from_its_back_and_occludes():
    """An open plate wound away from the sonar returns as the plate wound towards it (a sheet
    scatters from either side; before 2026-12-02 its back returned nothing); dark, it still
    casts its shadow."""
    sonar = Sonar(max_range=30.0, range_bin=BIN, sides=("starboard",))
    traj = Trajectory.straight((0.0, 0.0, ALTITUDE), 0.0, 0.2, 5)
    front = plate([8.0, 0.4, 6.0], [-1.0, 0.0, 1.0], 2.0)
    back = MeshPart(front.vertices, front.faces[:, ::-1], front.reflectivity, "back")
    seen = render_reference(build_scene([front]), sonar, traj).sides["starboard"]
    alone = render_reference(build_scene([back]), sonar, traj).sides["starboard"]
    assert seen.sum() > 0
    np.testing.assert_allclose(alone, seen, rtol=1e-6, atol=1e-12)
    bed = seabed(-1, 29, -4, 5)
    dark = MeshPart(front.vertices, front.faces[:, ::-1], 0.0, "dark back")
    open_bed = render_reference(build_scene([bed]), sonar, traj).sides["starboard"]
    shaded = render_reference(build_scene([bed, dark]), sonar, traj).sides["starboard"]
    assert shaded.sum() < 0.95 * open_bed.sum()
    assert np.all(shaded <= open_bed + 1e-7)


def test_halving_patch_size_keeps_total():
    sonar = Sonar(max_range=25.0, range_bin=BIN, beam=BeamPattern.gaussian(50.0))
    traj = Trajectory.straight((0.0, 0.0, ALTITUDE), 0.0, 0.2, 4)
    scene = build_scene(
        [
            seabed(-22, 22, -2, 3),
            box([[6.0, -3.0, 0.0], [7.5, 4.0, 2.0]]),
            plate([-9, 0.3, 2], [1, 0, 1], 1.5),
        ]
    )
    coarse = render_reference(scene, sonar, traj)
    fine = render_reference(scene, sonar, traj, patch_size=BIN / 8)
    for side in sonar.sides:
        a = coarse.sides[side].astype(np.float64).sum()
        b = fine.sides[side].astype(np.float64).sum()
        assert a > 0 and abs(a / b - 1) < 0.005


def test_mirrored_scene_gives_mirrored_image():
    sonar = Sonar(max_range=20.0, range_bin=BIN)
    traj = Trajectory.straight((0.0, 0.0, ALTITUDE), 0.0, 0.25, 4)
    parts = [
        seabed(-18, 18, -2, 3),
        box([[5.0, -3.0, 0.0], [6.0, 4.0, 1.5]]),
        plate([-7.0, 0.4, 3.0], [1.0, 0.2, 1.0], 1.2),
    ]
    image = render_reference(build_scene(parts), sonar, traj)
    mirror = render_reference(build_scene([mirrored(p) for p in parts]), sonar, traj)
    assert image.sides["port"].sum() > 0 and image.sides["starboard"].sum() > 0
    assert not np.allclose(image.sides["port"], image.sides["starboard"])
    for a, b in (("port", "starboard"), ("starboard", "port")):
        np.testing.assert_allclose(mirror.sides[a], image.sides[b], rtol=1e-5, atol=1e-9)


def test_stationary_pings_give_identical_rows():
    sonar = Sonar(max_range=20.0, range_bin=BIN, sides=("starboard",))
    traj = Trajectory(np.tile([0.0, 0.0, ALTITUDE], (6, 1)), np.zeros(6), np.zeros(6))
    (segment,) = traj.segments(BIN / 4)
    assert segment.spacing == 0.0 and segment.width == 1.0
    scene = build_scene([seabed(-1, 19, -3, 3), box([[8.0, -2.0, 0.0], [9.0, 2.0, 1.0]])])
    rows = render_reference(scene, sonar, traj).sides["starboard"]
    assert rows[0].sum() > 0
    assert np.array_equal(rows, np.broadcast_to(rows[0], rows.shape))


def test_rejects_bad_patch_size_and_types():
    sonar = Sonar(max_range=5.0, range_bin=BIN)
    traj = Trajectory.straight((0.0, 0.0, 2.0), 0.0, 0.2, 2)
    scene = build_scene([seabed(-3, 3, -1, 1)])
    with pytest.raises(SonarRasterError, match="patch_size"):
        render_reference(scene, sonar, traj, patch_size=0.0)
    with pytest.raises(TypeError, match="scene"):
        render_reference("scene.wrl", sonar, traj)


def test_flat_profile_closed_form_and_table_agree():
    sonar = Sonar(max_range=30.0, range_bin=BIN)
    uniform = flat_seabed_profile(sonar, ALTITUDE, 0.5, 0.2)
    edges = np.arange(sonar.n_bins + 1) * BIN
    u = np.arccosh(np.maximum(edges, ALTITUDE) / ALTITUDE)
    np.testing.assert_allclose(uniform, 0.5 * 0.2 * ALTITUDE * np.diff(u), rtol=1e-12)
    flat_table = BeamPattern(np.array([-1.0, 1.0]), np.array([0.3, 0.3]))
    tabled = flat_seabed_profile(
        Sonar(max_range=30.0, range_bin=BIN, beam=flat_table), ALTITUDE, 0.5, 0.2
    )
    np.testing.assert_allclose(tabled, 0.3 * uniform, rtol=1e-9, atol=1e-15)
    # roll moves the beam axis: down to starboard, up to port
    gauss = Sonar(max_range=30.0, range_bin=BIN, beam=BeamPattern.gaussian(30.0))
    down = flat_seabed_profile(gauss, ALTITUDE, 0.5, 0.2, side="starboard", roll=0.1)
    up = flat_seabed_profile(gauss, ALTITUDE, 0.5, 0.2, side="port", roll=-0.1)
    np.testing.assert_allclose(down, up)
    assert np.argmax(down) < np.argmax(flat_seabed_profile(gauss, ALTITUDE, 0.5, 0.2))


def test_shadow_length_formula_and_checks():
    assert shadow_length(2.0, 8.0, 10.0) == pytest.approx(2.0)
    assert shadow_length(0.0, 8.0, 10.0) == 0.0
    with pytest.raises(SonarRasterError):
        shadow_length(10.0, 8.0, 10.0)
    with pytest.raises(SonarRasterError):
        flat_seabed_profile(Sonar(), -1.0, 0.5, 0.2)


def test_turning_track_renders_each_leg_as_alone():
    sonar = Sonar(max_range=15.0, range_bin=BIN, beam=BeamPattern.gaussian(50.0))
    leg1 = Trajectory.straight((0.0, 0.0, ALTITUDE), 0.0, 0.25, 4)
    corner = tuple(leg1.positions[-1] + [0.0, 0.25, 0.0])
    leg2 = Trajectory.straight(corner, 60.0, 0.25, 3)
    both = Trajectory(
        np.vstack([leg1.positions, leg2.positions]),
        np.concatenate([leg1.headings, leg2.headings]),
        np.concatenate([leg1.roll, leg2.roll]),
    )
    assert [s.count for s in both.segments(BIN / 4)] == [4, 3]
    scene = build_scene([seabed(-16, 16, -16, 16), box([[4.0, -1.0, 0.0], [5.0, 3.0, 1.5]])])
    whole = render_reference(scene, sonar, both)
    for rows, leg in ((slice(0, 4), leg1), (slice(4, 7), leg2)):
        alone = render_reference(scene, sonar, leg)
        for side in sonar.sides:
            np.testing.assert_array_equal(whole.sides[side][rows], alone.sides[side])


def test_survey_coordinates_keep_precision():
    # a scene and track at UTM-like eastings/northings render as they do near the origin
    sonar = Sonar(max_range=15.0, range_bin=BIN, sides=("starboard",))
    offset = np.array([512_345.37, 6_123_456.81, -40.3])
    traj = Trajectory.straight((0.0, 0.0, ALTITUDE), 20.0, 0.25, 4)
    parts = [seabed(-16, 16, -16, 16), box([[6.0, -2.0, 0.0], [7.0, 4.0, 2.0]])]
    near = render_reference(build_scene(parts), sonar, traj).sides["starboard"]
    far_traj = Trajectory(traj.positions + offset, traj.headings, traj.roll)
    far_scene = build_scene(parts).translated(offset)
    far = render_reference(far_scene, sonar, far_traj).sides["starboard"]
    assert near.sum() > 0
    assert np.abs(far - near).sum() <= 1e-4 * near.sum()
