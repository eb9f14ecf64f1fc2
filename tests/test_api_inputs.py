"""The Python API on a user's plain mistakes: one SonarRasterError saying what to do.

Cases from an audit of the public functions (2026-12-02): each used to end in a raw numpy,
attribute or type error from deep inside, or in silently wrong output (a side named "Port"
written as starboard, an all-NaN inversion).
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest
from conftest import SHARED_DATA

from sonar_raster import BeamProfile, Effects, apply_effects, invert, read_xtf, track_bottom
from sonar_raster.errors import InputWarning, SonarRasterError, SonarRasterTypeError
from sonar_raster.image import SonarImage
from sonar_raster.sonar import Sonar
from sonar_raster.trajectory import Trajectory

SAMPLE = SHARED_DATA / "xtf" / "scotsman-iver2.xtf"


def _side(pings: int = 40, bins: int = 300, seed: int = 0) -> np.ndarray:
    """Speckled seabed past a dark water column (first return at bin 100)."""
    image = np.random.default_rng(seed).exponential(1.0, (pings, bins))
    image[:, :100] *= 1e-3
    return image


def _image() -> SonarImage:
    side = _side().astype(np.float32)
    sonar = Sonar(max_range=15.0, range_bin=0.05, sides=("port", "starboard"))
    return SonarImage({"port": side, "starboard": side.copy()}, sonar)


@pytest.mark.parametrize(
    ("sides", "message"),
    [
        ({"Port": np.ones((4, 300), np.float32)}, "side(s) 'Port': name them 'port' or"),
        ({"stbd": np.ones((4, 300), np.float32)}, "side(s) 'stbd'"),
        ({"port": np.ones(300, np.float32)}, "must be 2-D (pings, bins)"),
        ([np.ones((4, 300))], "must be a dict"),
    ],
    ids=["capitalised", "abbreviated", "1-D", "list"],
)
def test_an_image_with_odd_sides_is_refused(sides, message):
    with pytest.raises(SonarRasterError) as err:
        SonarImage(sides, Sonar(max_range=15.0, range_bin=0.05))
    assert message in str(err.value)


def test_a_trajectory_of_columns_is_refused_not_reshaped():
    x = np.arange(10.0)
    rows = np.vstack([x, np.zeros(10), np.full(10, 5.0)])  # (3, 10): columns, not rows
    with pytest.raises(SonarRasterError, match=r"must be \(pings, 3\)"):
        Trajectory(rows, np.zeros(10), np.zeros(10))
    with pytest.raises(SonarRasterError, match="roll has 3 values for 10 headings"):
        Trajectory(rows.T, np.zeros(10), np.zeros(3))
    one = Trajectory(np.array([0.0, 0.0, 5.0]), np.zeros(1), np.zeros(1))  # one pose stays fine
    assert one.positions.shape == (1, 3)


def test_track_bottom_wants_the_sides_and_a_positive_contrast():
    image = _image()
    with pytest.raises(SonarRasterError, match=r"image\.sides"):
        track_bottom(image, 0.05)  # type: ignore[arg-type]
    with pytest.raises(SonarRasterError, match="min_contrast_db"):
        track_bottom(image.sides, 0.05, min_contrast_db=-5.0)
    with pytest.raises(SonarRasterError, match="different ping counts"):
        track_bottom({"port": _side(40), "starboard": _side(30)}, 0.05)
    assert np.all(np.isfinite(track_bottom(image.sides, 0.05).altitude))


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"tol": -1.0}, "tol must be > 0"),
        ({"max_iter": 0}, "max_iter must be >= 1"),
        ({"ping_spacing": 0.0}, "ping_spacing (metres) must be > 0"),
        ({"levels": 2.5}, "levels must be a whole number"),
        ({"beam": BeamProfile([0.1, 1.0], [1.0, np.nan])}, "NaN or infinite"),
        ({"beam": {"port": 1}}, "beam must be a BeamProfile or the path"),
    ],
    ids=["tol", "max_iter", "ping_spacing", "levels", "nan beam", "dict beam"],
)
def test_invert_checks_its_options_first(change, message):
    with pytest.raises(SonarRasterError) as err:
        invert(_side(), 0.05, **change)
    assert message in str(err.value)


def test_invert_wants_one_side_and_says_so():
    with pytest.raises(SonarRasterError, match=r"image\.sides\['starboard'\]"):
        invert(_image().sides, 0.05)  # type: ignore[arg-type]


def test_a_transposed_image_is_an_error_not_an_all_nan_result():
    rng = np.random.default_rng(0)
    image = rng.exponential(1.0, (1000, 16))  # 16 "pings" of 1000 bins, transposed
    image[:, :8] *= 1e-3
    with pytest.raises(SonarRasterError, match=r"as \(pings, slant-range bins\)"):
        invert(image, 0.04, ping_spacing=0.1)


def test_a_beam_profile_takes_lists_and_invert_takes_its_path(tmp_path: Path):
    beam = BeamProfile([0.2, 0.6, 1.2], [1.0, 2.0, 1.0])  # lists: kept as arrays
    assert isinstance(beam.gain, np.ndarray) and beam(np.array([0.4]))[0] == pytest.approx(1.5)
    beam.save(tmp_path / "beam_profile.json")
    with pytest.raises(SonarRasterError, match="two equal 1-D lists"):
        BeamProfile([0.2], [1.0])
    by_object = invert(_side(), 0.05, ping_spacing=0.1, beam=beam, max_iter=5)
    by_path = invert(_side(), 0.05, ping_spacing=0.1, beam=tmp_path / "beam_profile.json",
                     max_iter=5)  # fmt: skip
    by_folder = invert(_side(), 0.05, ping_spacing=0.1, beam=str(tmp_path), max_iter=5)
    assert by_object.settings["calibrated"] and by_path.settings["calibrated"]
    np.testing.assert_array_equal(by_object.elevation, by_path.elevation)
    np.testing.assert_array_equal(by_object.elevation, by_folder.elevation)


def test_apply_effects_checks_its_seed_effects_and_image():
    image = _image()
    fx = Effects(speckle="exponential")
    with pytest.raises(SonarRasterError, match="seed must be >= 0"):
        apply_effects(image, fx, seed=-1)
    with pytest.raises(SonarRasterError, match="seed must be a whole number"):
        apply_effects(image, fx, seed=1.5)  # type: ignore[arg-type]
    with pytest.raises(SonarRasterError, match="effects must be an Effects"):
        apply_effects(image, {"speckle": "exponential"})  # type: ignore[arg-type]
    with pytest.raises(SonarRasterError, match="takes a SonarImage"):
        apply_effects(image.sides["port"], fx)  # type: ignore[arg-type]
    a, b = (apply_effects(image, fx, seed=np.int64(3)) for _ in range(2))
    np.testing.assert_array_equal(a.sides["port"], b.sides["port"])


def test_read_xtf_takes_a_pair_or_a_range_of_pings():
    if not SAMPLE.is_file():
        pytest.skip(f"{SAMPLE} not present")
    by_slice = read_xtf(SAMPLE, slice(10, 15))[0].sides["port"]
    for pings in ((10, 15), range(10, 15)):
        np.testing.assert_array_equal(read_xtf(SAMPLE, pings)[0].sides["port"], by_slice)
    with pytest.raises(SonarRasterError, match=r"e\.g\. slice\(0, 100\) or \(0, 100\)"):
        read_xtf(SAMPLE, 5)  # type: ignore[arg-type]


def test_write_products_checks_the_side_and_its_folder(tmp_path: Path):
    from sonar_raster import write_products

    result = invert(_side(), 0.05, ping_spacing=0.1, max_iter=5)
    with pytest.raises(SonarRasterError, match="side must be 'port' or 'starboard'"):
        write_products(result, tmp_path / "a", "Port", 0.05, mesh=False, previews=False)
    (tmp_path / "file").write_text("mine")
    with pytest.raises(SonarRasterError, match="is a file; give a folder"):
        write_products(result, tmp_path / "file", "port", 0.05, mesh=False, previews=False)
    assert (tmp_path / "file").read_text() == "mine" and not (tmp_path / "a").exists()


def test_render_says_when_nothing_returned_and_names_a_misplaced_argument():
    from sonar_raster import load_scene, render
    from sonar_raster.errors import InputWarning

    setup = load_scene("flat_calibration")
    track = setup.trajectory.subset(slice(0, 4))
    below = Trajectory(track.positions * [1.0, 1.0, -1.0], track.headings, track.roll)
    with pytest.warns(InputWarning, match="zero everywhere: nothing in the swath returned"):
        image = render(setup.scene, setup.sonar, below)
    assert not any(np.any(side) for side in image.sides.values())
    with pytest.raises(
        SonarRasterError, match=r"the scene must be a Scene, got SceneSetup \(e\.g\. load_scene"
    ):
        render(setup, setup.sonar, track)  # type: ignore[arg-type]
    assert any(np.any(side) for side in render(setup.scene, setup.sonar, track).sides.values())


def test_lines_levels_looks_tilt_and_xtf_options_are_checked(tmp_path: Path):
    from sonar_raster.inversion.surface import Line, fit_lines
    from sonar_raster.io.xtf import write_xtf

    side = _side()
    track = np.column_stack([np.zeros(40), 0.1 * np.arange(40)])
    line = Line({"starboard": side}, 0.05, track, np.zeros(40))
    with pytest.raises(SonarRasterError, match=r"as a list, e\.g\. fit_lines\(\[line\]\)"):
        fit_lines(line)  # type: ignore[arg-type]
    with pytest.raises(SonarRasterError, match="levels must be >= 1"):
        fit_lines([line], levels=0)
    with pytest.raises(SonarRasterError, match="looks must be 'auto' or a number > 0"):
        fit_lines([line], looks="Auto")
    with pytest.raises(SonarRasterError, match=r"tilt is in radians.*math\.radians\(45\)"):
        Sonar(tilt=45)
    image, track = _image(), Trajectory.straight((0.0, 0.0, -5.0), 0.0, 0.1, 40)
    for options, message in (
        ({"altitude": np.ones(3)}, "one per ping (40), got 3 value(s)"),
        ({"altitude": -5.0}, "one finite value >= 0"),
        ({"ping_interval": 0.0}, "ping_interval (seconds) must be > 0"),
        ({"start_time": -1e12}, "start_time (seconds since 1970) must be >= 0"),
        ({"origin": (1.0,)}, "origin must be two finite numbers"),
    ):
        with pytest.raises(SonarRasterError) as err:
            write_xtf(tmp_path / "a.xtf", image, track, **options)
        assert message in str(err.value)
    with pytest.raises(SonarRasterError, match="name it .xtf"):
        write_xtf(tmp_path / "a.exr", image, track)
    assert list(tmp_path.iterdir()) == []
    assert write_xtf(tmp_path / "a.xtf", image, track, altitude=5.0).is_file()


def test_render_survey_takes_one_path_and_refuses_one_twice(tmp_path: Path):
    from sonar_raster import load_scene, render_survey

    setup = load_scene("flat_calibration")
    track = setup.trajectory.subset(slice(0, 4))
    with pytest.raises(SonarRasterError, match="an output is given twice"):
        render_survey(setup.scene, setup.sonar, track, [tmp_path / "a.exr", tmp_path / "a.exr"])
    assert list(tmp_path.iterdir()) == []
    written, _ = render_survey(setup.scene, setup.sonar, track, str(tmp_path / "one.exr"))
    assert sorted(p.name for p in written) == ["one.exr", "one.json"]


def test_a_scene_file_tilt_beyond_the_vertical_is_named_in_degrees(tmp_path: Path):
    from sonar_raster import load_scene_file

    scene = tmp_path / "s.toml"
    scene.write_text(
        '[sonar]\nmax_range = 30.0\ntilt_deg = 100.0\n[seabed]\nkind = "flat"\n'
        "size = [70.0, 20.0]\n[trajectory]\nstart = [0.0, 0.0]\naltitude = 10.0\n"
        "spacing = 0.1\npings = 4\n"
    )
    with pytest.raises(SonarRasterError, match="tilt_deg must be between -90 and 90 degrees"):
        load_scene_file(scene)


def test_invert_xtf_refuses_a_zero_altitude_instead_of_tracking():
    from sonar_raster import invert_xtf

    if not SAMPLE.is_file():
        pytest.skip(f"{SAMPLE} not present")
    with pytest.raises(SonarRasterError, match=r"altitude \(metres\) must be > 0"):
        invert_xtf(SAMPLE, pings=slice(0, 10), altitude=0.0, method="profiles")


def test_a_track_out_of_range_of_the_whole_scene_is_named_by_render():
    from sonar_raster import load_scene, render
    from sonar_raster.scenes.description import Overrides

    setup = load_scene("flat_calibration", Overrides(altitude=30.0, pings=2))  # max_range 30
    with pytest.warns(InputWarning, match=r"every ping is 30 m or more above the scene's highest "
                      r"point, at or beyond the sonar's max_range \(30 m\)"):  # fmt: skip
        render(setup.scene, setup.sonar, setup.trajectory)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"speed": -1.0}, "speed (m/s) must be > 0, got -1.0"),
        ({"speed": 0}, "speed (m/s) must be > 0, got 0"),
        ({"ping_spacing": math.nan}, "ping_spacing (metres) must be finite, got nan"),
        ({"beamwidth_deg": math.inf}, "beamwidth_deg (degrees) must be finite, got inf"),
        ({"heading_deg": math.inf}, "heading_deg (degrees) must be finite, got inf"),
        ({"altitude": -5.0}, "altitude (metres) must be > 0, got -5.0"),
        ({"pings": 2.5}, "pings must be a whole number, got 2.5"),
    ],
    ids=["negative speed", "zero speed", "nan spacing", "inf beam", "inf heading", "altitude",
         "pings"],
)  # fmt: skip
def test_overrides_name_a_bad_number(change, message):
    from sonar_raster.scenes.description import Overrides

    with pytest.raises(SonarRasterError) as err:
        Overrides(**change)
    assert message in str(err.value)


def test_a_part_or_scene_with_arrays_that_do_not_match_is_refused():
    from sonar_raster import MeshPart, Scene, build_scene

    v = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]])
    f = np.array([[0, 1, 2], [1, 3, 2]])
    with pytest.raises(SonarRasterError, match="'plate' has 4 reflectivity values for 2 faces"):
        MeshPart(v, f, np.full(4, 0.5), "plate")  # one per vertex
    with pytest.raises(SonarRasterError, match=r"faces must be \(m, 3\) vertex indices"):
        MeshPart(v, np.array([[0, 1, 3, 2]]), 0.5, "quad")
    scene = build_scene([MeshPart(v, f, np.array([0.2, 0.4]), "plate")])
    with pytest.raises(SonarRasterError, match="reflectivity has 3 values for 2 faces"):
        Scene(scene.vertices, scene.faces, np.ones(3), scene.object_id)
    with pytest.raises(SonarRasterError, match="a face index outside its 4 vertices"):
        Scene(v, np.array([[0, 1, 7]]), np.ones(1), np.zeros(1, np.int32))


def test_apply_effects_twice_warns_that_the_stages_compound():
    once = apply_effects(_image(), Effects(speckle="exponential"), seed=1)
    with pytest.warns(InputWarning, match=r"already has speckle applied \(its metadata"):
        apply_effects(once, Effects(speckle="exponential", gain_db=3.0), seed=2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        apply_effects(once, Effects(gain_db=3.0))  # another stage on top: no warning


def test_apply_effects_refuses_a_trajectory_shorter_than_the_image():
    short = Trajectory.straight((0.0, 0.0, 5.0), 0.0, 0.1, 10)
    with pytest.raises(SonarRasterError, match="the trajectory has 10 pings, the image 40"):
        apply_effects(_image(), Effects(along_beam_deg=1.0), trajectory=short)
    whole = Trajectory.straight((0.0, 0.0, 5.0), 0.0, 0.1, 40)
    apply_effects(_image(), Effects(along_beam_deg=1.0), trajectory=whole)


@pytest.mark.parametrize("settings", [{}, {"oversample": 4.0}], ids=["empty", "dict"])
def test_a_raster_renderer_checks_its_settings_first(settings):
    from sonar_raster.rendering.gl.raster import RasterRenderer

    with pytest.raises(SonarRasterTypeError, match=r"settings must be a RasterSettings \(e\.g\."):
        RasterRenderer(settings=settings)  # type: ignore[arg-type]


def test_a_released_renderer_says_so():
    from sonar_raster.rendering.gl.raster import RasterRenderer

    renderer = RasterRenderer()
    assert renderer.gl_info["gl_backend"] == renderer.backend
    renderer.release()
    with pytest.raises(SonarRasterError, match="this renderer was released; make a new one"):
        _ = renderer.gl_info


def test_a_misspelt_coherent_option_is_named_with_the_nearest():
    from sonar_raster import load_scene, render

    setup = load_scene("flat_calibration")
    track = setup.trajectory.subset(slice(0, 2))
    with pytest.raises(
        SonarRasterError,
        match=r"unknown coherent option\(s\) 'seeed'.*"
        r"spacing_wavelengths, seed, .* \(seeed: did you mean seed\?\)",
    ):
        render(setup.scene, setup.sonar, track, model="coherent", coherent={"seeed": 1})
    with pytest.raises(SonarRasterTypeError, match="coherent must be a dict"):
        render(setup.scene, setup.sonar, track, model="coherent", coherent=[1])  # type: ignore


def test_an_unknown_sensor_name_is_refused_with_the_presets():
    from sonar_raster.effects import list_presets

    with pytest.raises(SonarRasterError, match="unknown sensor preset 'klein'; known: "):
        Effects(sensor="klein")
    fx = Effects(sensor=list_presets()[0])
    assert fx.sensor == list_presets()[0] and Effects(sensor="ideal").stages == ()
