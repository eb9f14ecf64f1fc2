"""Seabed heightfields and meshes: numeric truths, spectra, file round trips, errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sonar_raster.errors import SonarRasterError
from sonar_raster.scene import build_scene
from sonar_raster.scenes import seabed
from sonar_raster.scenes.description import load_scene_file
from sonar_raster.scenes.seabed import Heightfield, heightfield_mesh


@pytest.fixture(autouse=True)
def _strict_float():
    with np.errstate(all="raise"):
        yield


def _areas_normals(part):
    tri = part.vertices[part.faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(cross, axis=1)
    return 0.5 * norm, cross / norm[:, None]


def _raises(func, *args, match=None, **kwargs):
    with pytest.raises(SonarRasterError, match=match) as info:
        func(*args, **kwargs)
    assert "\n" not in str(info.value)
    return str(info.value)


# --------------------------------------------------------------------------- mesh


def test_mesh_flat_grid_area_normals_count():
    ny, nx, dx, dy = 7, 11, 0.3, 0.7
    part = heightfield_mesh(np.full((ny, nx), -4.0), 5.0, -2.0, dx, dy)
    area, normal = _areas_normals(part)
    assert part.faces.shape == (2 * (nx - 1) * (ny - 1), 3)
    assert part.is_seabed and part.name == "seabed"
    assert area.sum() == pytest.approx((nx - 1) * dx * (ny - 1) * dy, rel=1e-13)
    np.testing.assert_allclose(normal, np.tile([0.0, 0.0, 1.0], (len(normal), 1)), atol=1e-15)


def test_mesh_vertices_at_grid_points_and_face_order():
    rng = np.random.default_rng(3)
    ny, nx, x0, y0, dx, dy = 4, 6, 10.0, 20.0, 0.5, 0.25
    z = rng.normal(size=(ny, nx))
    part = heightfield_mesh(z, x0, y0, dx, dy)
    j, i = np.mgrid[0:ny, 0:nx]
    expected = np.stack([x0 + i * dx, y0 + j * dy, z], axis=-1).reshape(-1, 3)
    np.testing.assert_array_equal(part.vertices, expected)
    # cell (j, i) = (2, 3): faces 2 * (2 * 5 + 3) and the next one
    a, b, c, d = 2 * nx + 3, 2 * nx + 4, 3 * nx + 4, 3 * nx + 3
    np.testing.assert_array_equal(part.faces[26], [a, b, c])
    np.testing.assert_array_equal(part.faces[27], [a, c, d])


def test_mesh_normals_point_up_on_relief():
    hf = seabed.rough(size=(10.0, 8.0), resolution=0.2, rms_height=0.05, seed=1)
    _, normal = _areas_normals(hf.mesh())
    assert np.all(normal[:, 2] > 0)


def test_mesh_reflectivity_map_is_cell_corner_mean():
    z = np.zeros((3, 4))
    r = np.arange(12, dtype=float).reshape(3, 4)
    part = heightfield_mesh(z, 0.0, 0.0, 1.0, 1.0, reflectivity=r)
    cell = 0.25 * (r[:-1, :-1] + r[:-1, 1:] + r[1:, 1:] + r[1:, :-1])
    np.testing.assert_array_equal(part.reflectivity, np.repeat(cell.ravel(), 2))
    assert heightfield_mesh(z, 0.0, 0.0, 1.0, 1.0, reflectivity=0.3).reflectivity == 0.3


def test_mesh_feeds_build_scene_with_ground_at_depth():
    hf = seabed.bumpy(size=(20.0, 10.0), resolution=0.25, depth=-20.0, seed=4)
    scene = build_scene([hf.mesh(reflectivity=0.7)])
    assert scene.n_triangles == 2 * 80 * 40
    assert scene.ground_z == pytest.approx(-20.0, abs=1e-12)
    assert np.all(scene.reflectivity == 0.7)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"z": np.zeros(5)}, "dimension"),
        ({"z": np.zeros((1, 5))}, "2 x 2"),
        ({"z": np.array([[0.0, np.nan], [0.0, 0.0]])}, "NaN"),
        ({"dx": 0.0}, "'dx'"),
        ({"dy": -1.0}, "'dy'"),
        ({"reflectivity": -0.1}, "reflectivity"),
        ({"reflectivity": np.ones((3, 3))}, "shape"),
    ],
)
def test_mesh_bad_input(kwargs, match):
    args = {"z": np.zeros((2, 3)), "x0": 0.0, "y0": 0.0, "dx": 1.0, "dy": 1.0}
    args.update(kwargs)
    _raises(heightfield_mesh, match=match, **args)


# --------------------------------------------------------------------------- flat


def test_flat_extent_area_and_cell_limit():
    hf = seabed.flat(size=(30.0, 12.0), center=(100.0, -50.0), resolution=5.0, depth=-20.0)
    assert hf.dx <= 2.0 and hf.dy <= 2.0  # clipped to max_cell
    assert hf.extent == pytest.approx((85.0, 115.0, -56.0, -44.0), abs=1e-12)
    assert np.all(hf.z == -20.0)
    area, normal = _areas_normals(hf.mesh())
    assert area.sum() == pytest.approx(30.0 * 12.0, rel=1e-13)
    assert np.all(normal[:, 2] == pytest.approx(1.0))


def test_flat_spacing_divides_size():
    hf = seabed.flat(size=(10.0, 7.0), resolution=0.3)
    assert hf.shape == (math.ceil(7.0 / 0.3) + 1, math.ceil(10.0 / 0.3) + 1)
    assert hf.dx == pytest.approx(10.0 / 34) and hf.dy == pytest.approx(7.0 / 24)
    assert seabed.flat(size=5.0, max_cell=5.0).shape == (2, 2)


# --------------------------------------------------------------------------- rough


def _radial_psd_slope(hf: Heightfield, kmin: float, kmax: float) -> float:
    """Log-log slope of the radially averaged 2-D periodogram between kmin and kmax (rad/m)."""
    p = np.abs(np.fft.rfft2(hf.z - hf.z.mean())) ** 2
    ky = 2 * np.pi * np.fft.fftfreq(hf.shape[0], hf.dy)
    kx = 2 * np.pi * np.fft.rfftfreq(hf.shape[1], hf.dx)
    k = np.hypot(ky[:, None], kx[None, :]).ravel()
    edges = np.geomspace(kmin, kmax, 15)
    which = np.digitize(k, edges)
    kc = [np.exp(np.log(k[which == b]).mean()) for b in range(1, len(edges))]
    pc = [p.ravel()[which == b].mean() for b in range(1, len(edges))]
    return float(np.polyfit(np.log(kc), np.log(pc), 1)[0])


def test_rough_rms_mean_and_seed():
    kw = {"size": (20.0, 15.0), "resolution": 0.1, "rms_height": 0.08, "depth": -12.0}
    a = seabed.rough(seed=7, **kw)
    assert np.std(a.z) == pytest.approx(0.08, rel=1e-12)
    assert np.mean(a.z) == pytest.approx(-12.0, abs=1e-12)
    np.testing.assert_array_equal(a.z, seabed.rough(seed=7, **kw).z)
    assert not np.array_equal(a.z, seabed.rough(seed=8, **kw).z)


@pytest.mark.parametrize("exponent", [2.5, 3.25, 3.8])
def test_rough_spectral_slope_matches_exponent(exponent):
    hf = seabed.rough(
        size=(51.2, 51.2),
        resolution=0.1,
        rms_height=0.1,
        spectral_exponent=exponent,
        correlation_length=20.0,
        seed=11,
    )
    # kL >= 20 over the fit range, so the roll-off changes the slope by < 0.01
    assert _radial_psd_slope(hf, 1.0, 20.0) == pytest.approx(-exponent, abs=0.08)


# --------------------------------------------------------------------------- ripples


def _dominant_wavelength(hf: Heightfield, axis: int) -> float:
    z = hf.z - hf.z.mean()
    spacing = hf.dx if axis == 1 else hf.dy
    power = (np.abs(np.fft.rfft(z, axis=axis)) ** 2).mean(axis=1 - axis)
    freq = np.fft.rfftfreq(z.shape[axis], spacing)
    return float(1.0 / freq[1 + np.argmax(power[1:])])


@pytest.mark.parametrize(("wavelength", "direction", "axis"), [(1.0, 90.0, 1), (1.3, 0.0, 0)])
def test_ripples_dominant_wavelength(wavelength, direction, axis):
    hf = seabed.ripples(
        size=(40.0, 40.0), resolution=0.1, wavelength=wavelength, direction_deg=direction, seed=5
    )
    assert abs(_dominant_wavelength(hf, axis) - wavelength) < 0.1


def test_ripples_direction_is_compass_bearing():
    hf = seabed.ripples(size=(40.0, 40.0), wavelength=1.0, direction_deg=30.0, seed=2)
    p = np.abs(np.fft.fft2(hf.z - hf.z.mean())) ** 2
    fy = np.fft.fftfreq(hf.shape[0], hf.dy)[:, None]
    fx = np.fft.fftfreq(hf.shape[1], hf.dx)[None, :]
    p[fy[:, 0] < 0, :] = 0.0  # keep one of the two symmetric peaks
    j, i = np.unravel_index(np.argmax(p), p.shape)
    bearing = math.degrees(math.atan2(fx[0, i], fy[j, 0]))
    assert bearing == pytest.approx(30.0, abs=2.0)
    assert math.hypot(fx[0, i], fy[j, 0]) == pytest.approx(1.0, abs=0.03)


def test_ripples_regular_profile_is_exact():
    amp, lam, asym = 0.05, 1.0, 0.4
    hf = seabed.ripples(
        size=(4.0, 10.0),
        resolution=0.05,
        wavelength=lam,
        amplitude=amp,
        direction_deg=0.0,
        irregularity=0.0,
        asymmetry=asym,
        roughness=0.0,
        depth=-3.0,
    )
    u = np.mod((hf.y - hf.y0) / lam, 1.0)  # y0 = -5 is a whole number of wavelengths
    stoss = 0.5 * (1 + asym)
    t = np.where(u < stoss, u / stoss, (1 - u) / (1 - stoss))
    profile = amp * (2 * t * t - 2 / 3)
    expected = profile - profile.mean() - 3.0
    np.testing.assert_allclose(hf.z, np.broadcast_to(expected[:, None], hf.shape), atol=1e-12)
    # the steep lee face points along +y (direction 0): descents steeper than ascents
    slope = np.diff(hf.z[:, 0]) / hf.dy
    assert -slope.min() > 2 * slope.max()


def test_ripples_too_coarse_grid_raises():
    _raises(seabed.ripples, size=10.0, resolution=0.5, wavelength=1.0, match="wavelength")


# --------------------------------------------------------------------------- bumpy


def test_bumpy_mean_seed_and_sign():
    kw = {"size": (30.0, 30.0), "resolution": 0.2, "depth": -8.0, "density": 0.05}
    a = seabed.bumpy(seed=1, **kw)
    assert np.mean(a.z) == pytest.approx(-8.0, abs=1e-12)
    np.testing.assert_array_equal(a.z, seabed.bumpy(seed=1, **kw).z)
    assert not np.array_equal(a.z, seabed.bumpy(seed=2, **kw).z)
    mounds = seabed.bumpy(seed=1, hollow_fraction=0.0, **kw).z
    hollows = seabed.bumpy(seed=1, hollow_fraction=1.0, **kw).z
    np.testing.assert_allclose(mounds - mounds.mean(), -(hollows - hollows.mean()), atol=1e-12)
    assert mounds.max() - np.median(mounds) > 2 * (np.median(mounds) - mounds.min())
    assert 0.3 < np.ptp(mounds) < 3 * 1.5 * 0.3


# --------------------------------------------------------------------------- height_at


def test_height_at_nodes_and_linear_between():
    rng = np.random.default_rng(0)
    hf = seabed.from_grid(rng.normal(size=(5, 7)), dx=0.5, dy=0.8, x0=-1.0, y0=2.0)
    xx, yy = np.meshgrid(hf.x, hf.y)
    np.testing.assert_allclose(hf.height_at(xx, yy), hf.z, atol=1e-12)
    t = np.linspace(0.0, 1.0, 9)
    x = hf.x[2] + t * hf.dx
    edge = (1 - t) * hf.z[3, 2] + t * hf.z[3, 3]
    np.testing.assert_allclose(hf.height_at(x, hf.y[3]), edge, atol=1e-12)


def test_height_at_plane_exact_and_clamped_outside():
    x = np.linspace(0.0, 6.0, 13)
    y = np.linspace(0.0, 4.0, 5)
    hf = seabed.from_grid(0.3 + 0.2 * x[None, :] - 0.1 * y[:, None], dx=0.5, dy=1.0)
    rng = np.random.default_rng(1)
    px, py = rng.uniform(0, 6, 50), rng.uniform(0, 4, 50)
    np.testing.assert_allclose(hf.height_at(px, py), 0.3 + 0.2 * px - 0.1 * py, atol=1e-12)
    assert float(hf.height_at(-5.0, 10.0)) == pytest.approx(hf.z[-1, 0])
    assert hf.height_at(1.0, 1.0).shape == ()
    _raises(hf.height_at, np.nan, 0.0, match="finite")


def test_resampled_keeps_extent_and_plane():
    hf = seabed.from_grid(np.add.outer(np.arange(4.0), np.arange(6.0)), dx=2.0, dy=2.0)
    fine = hf.resampled(0.3)
    assert fine.extent == pytest.approx(hf.extent)
    assert fine.dx <= 0.3 and fine.dy <= 0.3
    np.testing.assert_allclose(fine.z, hf.height_at(fine.x[None, :], fine.y[:, None]))


def test_heightfield_is_read_only_copy():
    z = np.zeros((3, 3))
    hf = seabed.from_grid(z, dx=1.0)
    z[0, 0] = 5.0
    assert hf.z[0, 0] == 0.0 and hf.dy == 1.0
    with pytest.raises(ValueError):
        hf.z[0, 0] = 1.0


# --------------------------------------------------------------------------- files


def test_load_npy_round_trip(tmp_path):
    z = np.random.default_rng(2).normal(size=(4, 5))
    path = tmp_path / "bed.npy"
    np.save(path, z)
    hf = seabed.load_elevation(path, resolution=(0.5, 0.25), origin=(3.0, 4.0))
    np.testing.assert_array_equal(hf.z, z)
    assert (hf.x0, hf.y0, hf.dx, hf.dy) == (3.0, 4.0, 0.5, 0.25)
    _raises(seabed.load_elevation, path, match="resolution")


def _north_up(west, north, sx, sy):
    """North-up geotransform (rasterio's from_origin warns under affine 3)."""
    from rasterio import Affine

    return Affine(sx, 0.0, west, 0.0, -sy, north)


def _write_geotiff(path, data, transform, nodata=None):
    import rasterio

    with rasterio.open(
        path,
        "w",
        driver="GTiff",
        height=data.shape[0],
        width=data.shape[1],
        count=1,
        dtype="float32",
        crs="EPSG:32631",
        transform=transform,
        nodata=nodata,
    ) as ds:
        ds.write(data.astype(np.float32), 1)


def test_geotiff_round_trip_origin_spacing_orientation(tmp_path):
    west, north, sx, sy = 500_000.0, 6_000_000.0, 2.0, 3.0
    data = np.arange(20, dtype=np.float32).reshape(4, 5) - 30.0  # row 0 is the north edge
    path = tmp_path / "dem.tif"
    _write_geotiff(path, data, _north_up(west, north, sx, sy))
    hf = seabed.load_elevation(path)
    assert (hf.dx, hf.dy) == (sx, sy)
    assert hf.x0 == west + 0.5 * sx
    assert hf.y0 == north - 4 * sy + 0.5 * sy
    np.testing.assert_array_equal(hf.z, data[::-1])
    row, col = 1, 3  # a pixel centre reads back that pixel's value
    x, y = west + (col + 0.5) * sx, north - (row + 0.5) * sy
    assert float(hf.height_at(x, y)) == pytest.approx(data[row, col])
    coarse = seabed.load_elevation(path, resolution=0.5)
    assert coarse.extent == pytest.approx(hf.extent) and coarse.dx <= 0.5


def test_geotiff_nodata_raises(tmp_path):
    data = np.zeros((3, 3), dtype=np.float32)
    data[1, 1] = -9999.0
    path = tmp_path / "holes.tif"
    _write_geotiff(path, data, _north_up(0.0, 3.0, 1.0, 1.0), nodata=-9999.0)
    _raises(seabed.load_elevation, path, match="nodata")
    _raises(seabed.load_elevation, path, origin=(0.0, 0.0), match="nodata")


def test_load_errors(tmp_path):
    _raises(seabed.load_elevation, tmp_path / "missing.tif", match="does not exist")
    junk = tmp_path / "junk.tif"
    junk.write_bytes(b"not a raster")
    _raises(seabed.load_elevation, junk, match="cannot read")
    flat3d = tmp_path / "cube.npy"
    np.save(flat3d, np.zeros((2, 2, 2)))
    _raises(seabed.load_elevation, flat3d, resolution=1.0, match="dimension")


# --------------------------------------------------------------------------- dispatch


@pytest.mark.parametrize("kind", ["flat", "rough", "ripples", "bumpy"])
def test_make_seabed_matches_direct_call(kind):
    params = {"size": [12.0, 8.0], "center": [1.0, 2.0], "resolution": 0.2, "seed": 3}
    made = seabed.make_seabed(kind, **params)
    direct = getattr(seabed, kind)(**params)
    np.testing.assert_array_equal(made.z, direct.z)
    assert made.extent == pytest.approx((-5.0, 7.0, -2.0, 6.0))


def test_make_seabed_grid(tmp_path):
    path = tmp_path / "bed.npy"
    np.save(path, np.ones((3, 3)))
    hf = seabed.make_seabed("grid", path=str(path), resolution=2.0)
    assert hf.extent == (0.0, 4.0, 0.0, 4.0)
    _raises(seabed.make_seabed, "grid", resolution=2.0, match="path")


def test_make_seabed_unknown_kind_and_parameter():
    msg = _raises(seabed.make_seabed, "gravel", match="unknown seabed kind")
    assert "ripples" in msg and "grid" in msg
    msg = _raises(seabed.make_seabed, "ripples", wave_length=1.0, match="wave_length")
    assert "wavelength" in msg and "irregularity" in msg


@pytest.mark.parametrize(
    ("params", "match"),
    [
        ({"size": (0.0, 5.0)}, "'size'"),
        ({"size": "big"}, "'size'"),
        ({"size": (1.0, 2.0, 3.0)}, "'size'"),
        ({"center": 3.0}, "'center'"),
        ({"resolution": -0.1}, "'resolution'"),
        ({"rms_height": float("nan")}, "'rms_height'"),
        ({"seed": 1.5}, "'seed'"),
        ({"spectral_exponent": 9.0}, "'spectral_exponent'"),
        ({"size": 1e5, "resolution": 0.01}, "coarser resolution"),
    ],
)
def test_make_seabed_bad_values(params, match):
    _raises(seabed.make_seabed, "rough", match=match, **params)


def test_ripples_bad_fractions():
    _raises(seabed.make_seabed, "ripples", size=5.0, irregularity=2.0, match="irregularity")
    _raises(seabed.make_seabed, "ripples", size=5.0, asymmetry=1.0, match="asymmetry")
    _raises(seabed.make_seabed, "bumpy", size=5.0, hollow_fraction=-0.1, match="hollow")
    _raises(seabed.make_seabed, "bumpy", size=5.0, bump_width=0.05, match="bump_width")


def test_seabed_reflectivity_map_from_npy_and_png(tmp_path):
    """Left half dark, right half bright, in both formats (PNG rows run north to south)."""
    import OpenImageIO as oiio

    values = np.where(np.arange(8)[None, :] < 4, 0.1, 0.9) * np.ones((6, 1))
    np.save(tmp_path / "map.npy", values)
    png = (values[::-1] * 255).astype(np.uint8)[:, :, None]
    out = oiio.ImageOutput.create(str(tmp_path / "map.png"))
    out.open(str(tmp_path / "map.png"), oiio.ImageSpec(8, 6, 1, oiio.UINT8))
    out.write_image(png)
    out.close()
    for name, scale in (("map.npy", 1.0), ("map.png", 0.5)):
        path = tmp_path / "patches.toml"
        path.write_text(
            "[sonar]\nmax_range = 20.0\nrange_bin = 0.05\n"
            '[seabed]\nkind = "flat"\nsize = [14.0, 10.0]\nresolution = 0.5\n'
            f'reflectivity_map = "{name}"\nreflectivity = {scale}\n[trajectory]\npings = 3\n'
        )
        scene = load_scene_file(path).scene
        centroid_x = scene.vertices[scene.faces].mean(axis=1)[:, 0]
        west, east = scene.reflectivity[centroid_x < -1.5], scene.reflectivity[centroid_x > 1.5]
        assert np.allclose(west, 0.1 * scale, atol=0.01) and np.allclose(
            east, 0.9 * scale, atol=0.01
        )
    np.save(tmp_path / "bad.npy", -values)
    path.write_text(path.read_text().replace(name, "bad.npy"))
    with pytest.raises(SonarRasterError, match="finite values >= 0"):
        load_scene_file(path)
