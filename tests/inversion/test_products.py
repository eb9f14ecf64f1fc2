"""Inversion products: reprojected and evenly lit ground-range images, mesh, previews, CLI."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from sonar_raster.errors import SonarRasterError
from sonar_raster.inversion.products import even_illumination, mean_incidence_cos, reproject
from sonar_raster.inversion.solver import invert
from sonar_raster.meshio.export import export, seabed_mesh
from sonar_raster.rendering.gl.preview import BACKGROUND, render_previews
from sonar_raster.scene import build_scene
from sonar_raster.scenes.seabed import make_seabed
from sonar_raster.sonar import BeamPattern, Sonar
from sonar_raster.trajectory import Trajectory

ALT, PINGS, SPACING, BIN = 10.0, 32, 0.1, 0.05
SONAR = Sonar(
    max_range=20.0,
    range_bin=BIN,
    beam=BeamPattern.gaussian(50.0),
    tilt=math.radians(20.0),
    sides=("starboard",),
)
TRACK = Trajectory.straight((0.0, -1.6, ALT), 0.0, SPACING, PINGS)
REFLECTIVITY = 0.5
PRODUCTS = {
    "elevation.exr",
    "reflectivity.exr",
    "beam.exr",
    "ground.exr",
    "even.exr",
    "beam_profile.json",
    "seabed.glb",
    "seabed.ply",
    "preview_az045.png",
    "preview_az135.png",
    "preview_az225.png",
    "preview_az315.png",
    "inversion.json",
}


@pytest.fixture(scope="module")
def flat_image(gl_renderer):
    flat = make_seabed("flat", size=(40.0, 8.0), center=(12.0, 0.0))
    scene = build_scene([flat.mesh(REFLECTIVITY)])
    return gl_renderer.render(scene, SONAR, TRACK).sides["starboard"].astype(np.float64)


@pytest.fixture(scope="module")
def flat_inversion(flat_image):
    return invert(flat_image, BIN, ping_spacing=SPACING, max_iter=30)


def _lit(inv) -> np.ndarray:
    """Cells between 20° and 60° depression (well inside the beam, away from nadir) that have
    an estimate (the last cells before the end of the data have none)."""
    dep = np.arctan2(ALT, inv.x)
    known = np.all(np.isfinite(inv.elevation), axis=0)
    return (dep > math.radians(20)) & (dep < math.radians(60)) & known


def test_reprojected_flat_seabed_is_the_flat_lambertian_profile(flat_image, flat_inversion):
    inv = flat_inversion
    lit = _lit(inv)
    ground = reproject(flat_image, BIN, inv.x, np.full(inv.elevation.shape, -ALT))
    # Analytic: over a flat seabed the renderer gives w Φ(α) R cos θ per metre of ground range.
    rho = np.hypot(inv.x, ALT)
    expected = SPACING * SONAR.gain(np.arctan2(ALT, inv.x)) * REFLECTIVITY * ALT / rho
    np.testing.assert_allclose(
        ground[:, lit], np.broadcast_to(expected[lit], ground[:, lit].shape), rtol=0.005
    )
    # At the recovered elevation: the same pings agree with each other (flat along track) and
    # with the analytic profile, since the recovered Z is flat to a few centimetres.
    recovered = inv.reprojected[:, lit]
    assert np.all(np.isfinite(recovered))
    assert np.max(np.std(recovered, axis=0) / np.mean(recovered, axis=0)) < 1e-3
    np.testing.assert_allclose(np.mean(recovered, axis=0), expected[lit], rtol=0.02)


def test_reprojection_is_nan_without_elevation_or_beyond_the_image():
    slant = np.ones((3, 100))
    x = (np.arange(40) + 0.5) * 0.2
    z = np.full((3, 40), -2.0)
    z[1, 5] = np.nan
    out = reproject(slant, 0.05, x, z)
    assert np.isnan(out[1, 5]) and np.isfinite(out[0, 5])
    beyond = np.hypot(x, 2.0) >= 100 * 0.05
    assert np.all(np.isnan(out[:, beyond])) and np.all(np.isfinite(out[0, ~beyond]))


def test_even_illumination_divides_out_beam_and_mean_incidence():
    rng = np.random.default_rng(11)
    x = (np.arange(50) + 0.5) * 0.3
    z = -5.0 + 0.1 * rng.standard_normal((4, 50))
    r = rng.uniform(0.2, 0.9, (4, 50))
    beam = np.exp(-(((np.arctan2(5.0, x) - 0.6) / 0.4) ** 2)) * np.ones((4, 1))
    cos_mean = 5.0 / np.sqrt(x**2 + 25.0)  # a level patch at about 5 m depth
    assert np.allclose(mean_incidence_cos(x, np.full((4, 50), -5.0)), cos_mean, rtol=1e-12)
    ground = beam * r * mean_incidence_cos(x, z)
    np.testing.assert_allclose(even_illumination(ground, beam, x, z), r, rtol=1e-12)
    beam[:, :3] = 0.0
    assert np.all(np.isnan(even_illumination(ground, beam, x, z)[:, :3]))


def test_even_illumination_divides_out_a_seabeds_law_too():
    from sonar_raster.inversion.law import scattering_law
    from sonar_raster.scenes.sediments import law_factor, material_index

    x = (np.arange(50) + 0.5) * 0.3
    z = np.full((2, 50), -5.0)
    r = np.full((2, 50), 0.4)
    cos = mean_incidence_cos(x, z)
    factor = law_factor(np.full(cos.shape, material_index("sand")), cos, 400e3)
    ground = r * cos * factor  # a flat sand seabed under a uniform beam
    sand = scattering_law("sand", 400e3)
    even = even_illumination(ground, np.ones_like(z), x, z, sand)
    # the law's smooth curve against the renderers' linear table: within 3 % on 1° steps
    np.testing.assert_allclose(even, r, rtol=0.03)
    assert np.ptp(factor) > 1.0  # Lambert's division alone would leave the law in


def test_even_image_of_uniform_reflectivity_is_uniform(flat_inversion):
    inv = flat_inversion
    even = inv.even[:, _lit(inv)]
    assert np.all(np.isfinite(even))
    # Uniform to 0.5 % (the model's scale between Φ and R is free, so no absolute level) ...
    assert np.std(even) / np.mean(even) < 0.005
    # ... and on a level seabed it is the recovered reflectivity.
    np.testing.assert_allclose(even, inv.reflectivity[:, _lit(inv)], rtol=0.015)


def _grid(pings=5, cells=7):
    x = 2.0 + (np.arange(cells) + 0.5) * 0.5
    yy, xx = np.meshgrid(np.arange(pings), x, indexing="ij")
    z = -8.0 + 0.1 * np.sin(xx) + 0.05 * yy
    return x, z


@pytest.mark.parametrize("side", ["starboard", "port"])
def test_mesh_vertices_bounds_and_orientation(side):
    x, z = _grid()
    z[0, 0] = np.nan  # one unknown corner cell: its vertex and its one square drop out
    mesh = seabed_mesh(x, z, -z, 0.25, side, textured=False)
    assert len(mesh.vertices) == z.size - 1
    assert len(mesh.faces) == 2 * ((5 - 1) * (7 - 1) - 1)
    sign = -1.0 if side == "port" else 1.0
    xs = sign * x
    assert mesh.bounds[0] == pytest.approx([xs.min(), 0.0, np.nanmin(z)])
    assert mesh.bounds[1] == pytest.approx([xs.max(), 4 * 0.25, np.nanmax(z)])
    assert np.all(mesh.face_normals[:, 2] > 0)  # counter-clockwise from above on both sides


def test_mesh_round_trips_through_trimesh(tmp_path):
    import trimesh

    x, z = _grid()
    texture = np.linspace(0.0, 1.0, z.size).reshape(z.shape)
    for kind, textured in (("glb", True), ("ply", False)):
        mesh = seabed_mesh(x, z, texture, 0.25, textured=textured)
        path = tmp_path / f"m.{kind}"
        path.write_bytes(export(mesh, kind))
        back = trimesh.load(path, force="mesh", process=False)
        assert len(back.faces) == len(mesh.faces)
        np.testing.assert_allclose(
            np.sort(back.vertices, axis=0), np.sort(mesh.vertices, axis=0), atol=1e-5
        )
        if textured:
            assert back.visual.kind == "texture"
            assert back.visual.material.baseColorTexture.size == (z.shape[1], z.shape[0])
        else:
            grey = back.visual.vertex_colors[:, 0].astype(float)
            # The grey ramp follows the texture: first vertex darkest, last brightest.
            assert grey[0] == 0 and grey[-1] == 255


def test_mesh_without_any_estimate_is_an_error():
    x, z = _grid()
    with pytest.raises(SonarRasterError):
        seabed_mesh(x, np.full_like(z, np.nan), z, 0.25)


def test_previews_are_non_empty_images_of_the_requested_size():
    x, z = _grid(12, 20)
    mesh = seabed_mesh(x, z, np.cos(z * 30.0), 0.25, textured=False)
    images = render_previews(mesh, (96, 64))
    assert len(images) == 4
    background = np.round(255 * np.array(BACKGROUND))
    for image in images:
        assert image.shape == (64, 96, 3) and image.dtype == np.uint8
        drawn = np.any(np.abs(image.astype(float) - background) > 2, axis=2)
        assert 0.02 < drawn.mean() < 0.98
    assert not np.array_equal(images[0], images[2])  # opposite sides differ


def test_cli_writes_every_product_atomically(flat_image, tmp_path):
    from sonar_raster.cli.app import main

    np.save(tmp_path / "flat.npy", flat_image)
    out = tmp_path / "out"
    argv = ["invert", str(tmp_path / "flat.npy"), "-o", str(out), "--range-bin", str(BIN)]
    assert main([*argv, "--ping-spacing", str(SPACING), "--max-iter", "5", "--quiet"]) == 0
    assert {p.name for p in out.iterdir()} == PRODUCTS  # and no temporary file left
    doc = json.loads((out / "inversion.json").read_text())
    assert len(doc["iterations_per_level"]) == 3
    assert all(n <= 5 for n in doc["iterations_per_level"])
    assert [lv["factor"] for lv in doc["levels"]] == [4, 2, 1]
    assert doc["ping_spacing_m"] == pytest.approx(SPACING)
    assert set(doc["products"]) == PRODUCTS - {"inversion.json"}
    # Calibrated mode from the profile just written, and no mesh or previews.
    again = tmp_path / "again"
    beam = ["--beam", str(out / "beam_profile.json"), "--no-mesh", "--no-previews"]
    argv[3] = str(again)
    assert main([*argv, "--max-iter", "3", "--quiet", *beam, "--levels", "2"]) == 0
    assert {p.name for p in again.iterdir()} == {
        n for n in PRODUCTS if not n.startswith(("seabed", "preview"))
    }


def test_cli_failure_in_a_late_product_leaves_nothing(flat_image, tmp_path, monkeypatch, capsys):
    import sonar_raster.rendering.gl.preview as preview
    from sonar_raster.cli.app import main

    def broken(*args, **kwargs):
        raise SonarRasterError("no headless OpenGL")

    monkeypatch.setattr(preview, "render_previews", broken)
    np.save(tmp_path / "flat.npy", flat_image)
    out = tmp_path / "out"
    argv = ["invert", str(tmp_path / "flat.npy"), "-o", str(out), "--range-bin", str(BIN)]
    assert main([*argv, "--max-iter", "2", "--quiet"]) == 2
    assert "no headless OpenGL" in capsys.readouterr().err
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize(
    "extra",
    [["--beam", "missing.json"], ["--levels", "0"], ["--tol", "-1"]],
)
def test_cli_bad_options_fail_cleanly(extra, tmp_path, monkeypatch, capsys):
    from sonar_raster.cli.app import main

    monkeypatch.chdir(tmp_path)
    np.save("img.npy", np.ones((8, 50)))
    try:
        code = main(["invert", "img.npy", "-o", "out", "--range-bin", "0.05", *extra])
    except SystemExit as exc:  # argparse rejects the option itself
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("sonar-raster: error:") and "\n" not in err
    assert not (tmp_path / "out").exists()
