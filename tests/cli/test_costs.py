"""Jobs say what they will cost before they start and are refused beyond the limits (issue 19):
raster renders (time, disk), inversions (time from the image size), datasets (disk, memory)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sonar_raster import _budget
from sonar_raster.cli import render as render_cli
from sonar_raster.cli.app import main

SCENE = "flat_calibration"  # 50 pings x 600 bins x 2 sides, renders in well under a second
XTF = Path(__file__).resolve().parents[3] / "shared" / "data" / "xtf" / "scotsman-iver2.xtf"


def one_error_line(err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("sonar-raster: error: ") and "Traceback" not in err
    return lines[0]


def test_a_render_larger_than_the_free_disk_is_refused_before_rendering(
    tmp_path, capsys, monkeypatch
):
    monkeypatch.setattr(_budget, "free_disk", lambda folder: 100_000)
    out = tmp_path / "out.exr"
    assert main(["render", SCENE, "-o", str(out), "-q"]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert "free in" in line and "--pings" in line and "--force" in line
    assert list(tmp_path.iterdir()) == []
    assert main(["render", SCENE, "-o", str(out), "-q", "--force"]) == 0


def test_the_disk_estimate_bounds_what_is_written(tmp_path):
    """Upper-end, but not absurd: the files written are at most the estimate and more than a
    fiftieth of it."""
    outs = [tmp_path / "a.png", tmp_path / "a.exr", tmp_path / "a.xtf"]
    args = ["render", SCENE, "--pings", "400", "-q"] + [a for o in outs for a in ("-o", str(o))]
    assert main(args) == 0
    parsed = _parse(args)
    setup = render_cli.load_setup(parsed)
    sizes = render_cli._output_sizes(parsed, setup, False, outs)
    estimate = sum(s for _, s in sizes)
    written = sum(p.stat().st_size for p in tmp_path.iterdir())
    assert written <= estimate < 50 * written


def _parse(argv):
    from sonar_raster.cli.app import _parser

    return _parser().parse_args(argv)


def test_a_long_render_is_announced_and_refused_past_an_hour(tmp_path, capsys, monkeypatch):
    out = str(tmp_path / "out.png")
    monkeypatch.setattr(render_cli, "_RAY_SECONDS", 20.0 / 288_000)  # 288 000 rays: 20 s
    assert main(["render", SCENE, "-o", out]) == 0
    err = capsys.readouterr().err
    assert "rendering 50 pings x 600 bins x 2 sides: about" in err and "estimated 2" in err
    assert main(["render", SCENE, "-o", out, "-q"]) == 0
    assert capsys.readouterr().err == ""  # -q: no estimate
    monkeypatch.setattr(render_cli, "_RAY_SECONDS", 1.0)
    assert main(["render", SCENE, "-o", out, "--oversample", "4", "-q"]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert "over the 60 min limit" in line and "--oversample" in line and "--force" in line
    assert main(["render", SCENE, "-o", out, "--pings", "10", "-q", "--force"]) == 0


def test_render_rays_follow_the_sampling_settings():
    base = _parse(["render", SCENE, "-o", "x.png"])
    setup = render_cli.load_setup(base)
    one = render_cli.raster_estimate(base, setup, False, [])
    more = render_cli.raster_estimate(
        _parse(["render", SCENE, "-o", "x.png", "--along-samples", "8", "--oversample", "8"]),
        setup, False, [],
    )  # fmt: skip
    assert one.counts["cells"] == 50 * 600 * 2 == more.counts["cells"]
    assert more.counts["rays"] / one.counts["rays"] == pytest.approx(16.0, rel=0.01)


def test_an_inversion_estimated_over_an_hour_is_refused(tmp_path, capsys, monkeypatch):
    from sonar_raster.cli import invert as invert_cli

    np.save(tmp_path / "img.npy", np.ones((40, 64), np.float32))
    monkeypatch.setattr(invert_cli, "_PIXEL_SECONDS", 2.0)  # 2560 px: 85 min
    cmd = ["invert", str(tmp_path / "img.npy"), "--range-bin", "0.1", "-o", str(tmp_path / "o")]
    assert main([*cmd, "-q"]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert "img.npy" in line and "2560 pixels" in line and "crop the image" in line
    assert not (tmp_path / "o").exists()
    monkeypatch.setattr(invert_cli, "_PIXEL_SECONDS", 0.01)  # 26 s: announced, then run
    run = [
        *cmd,
        "--altitude",
        "1",
        "--max-iter",
        "2",
        "--levels",
        "1",
        "--no-mesh",
        "--no-previews",
    ]
    assert main(run) == 0
    assert "estimated 26 s" in capsys.readouterr().err


def test_an_xtf_inversion_is_sized_from_the_file_before_reading_it(tmp_path, capsys, monkeypatch):
    from sonar_raster.cli import invert as invert_cli

    if not XTF.is_file():
        pytest.fail(f"{XTF} is missing: the shared data must sit beside the clone")
    monkeypatch.setattr(invert_cli, "_PIXEL_SECONDS", 1.0)
    assert main(["invert", str(XTF), "-o", str(tmp_path / "o"), "-q"]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert "scotsman-iver2.xtf" in line and "--pings A:B" in line


def test_survey_lines_given_by_ping_ranges_are_sized_by_those_pings(tmp_path, monkeypatch):
    """``--line-pings`` reads 80 of the file's 461 pings: the estimate is theirs, not the file's."""
    from sonar_raster.cli import invert as invert_cli
    from sonar_raster.errors import SonarRasterError

    if not XTF.is_file():
        pytest.fail(f"{XTF} is missing: the shared data must sit beside the clone")
    sized = []

    def stop(pixels, what, lower, args):
        sized.append(pixels)
        raise SonarRasterError("stopped by the test")

    monkeypatch.setattr(invert_cli, "check_cost", stop)
    args = ["invert", str(XTF), "--line-pings", "100:140,140:180", "--method", "profiles"]
    assert main([*args, "-o", str(tmp_path / "o"), "-q"]) == 2
    assert sized == [2 * 40 * 2 * 1024]  # two lines of 40 pings, two sides of 1024 samples


def test_a_dataset_larger_than_the_free_disk_or_memory_is_refused(tmp_path, capsys, monkeypatch):
    out = tmp_path / "ds"
    monkeypatch.setattr(_budget, "free_disk", lambda folder: 10_000_000)
    assert main(["dataset", "dataset_default", "-o", str(out), "-n", "20", "-q"]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert "20 samples of 512 pings x 1024 bins x 1 sides" in line and "lower -n" in line
    assert not out.exists()
    monkeypatch.setattr(_budget, "free_disk", lambda folder: 1 << 40)
    monkeypatch.setattr(_budget, "physical_memory", lambda: 1 << 28)
    assert main(["dataset", "dataset_default", "-o", str(out), "-n", "2", "-q",
                 "--workers", "4"]) == 2  # fmt: skip
    assert "--workers" in one_error_line(capsys.readouterr().err)
    assert not out.exists()


def test_a_dataset_on_recordings_is_sized_by_their_samples(tmp_path, capsys, monkeypatch):
    """A ``[background]`` window keeps its recording's samples per ping (3000 here), not the
    config's bins (1024 by default): the disk estimate counts the recording's."""
    from sonar_raster.image import SonarImage
    from sonar_raster.io.xtf import write_xtf
    from sonar_raster.sonar import Sonar
    from sonar_raster.trajectory import Trajectory

    rng = np.random.default_rng(0)
    sides = {s: rng.exponential(1.0, (40, 3000)).astype(np.float32) for s in ("port", "starboard")}
    sonar = Sonar(max_range=90.0, range_bin=0.03, sides=("port", "starboard"))
    track = Trajectory.straight((0.0, 0.0, -5.0), 0.0, 0.1, 40)
    write_xtf(tmp_path / "rec.xtf", SonarImage(sides, sonar), track)
    config = tmp_path / "bg.toml"
    config.write_text(
        '[dataset]\nname = "bg"\npings = 32\nsides = ["port", "starboard"]\n'
        '[background]\nrecordings = ["rec.xtf"]\n[[objects]]\nprimitive = "box"\n'
    )
    out = tmp_path / "ds"
    monkeypatch.setattr(_budget, "free_disk", lambda folder: 10_000)
    assert main(["dataset", str(config), "-o", str(out), "-n", "2", "-q"]) == 2
    assert "2 samples of 32 pings x 3000 bins x 2 sides" in one_error_line(capsys.readouterr().err)
    assert not out.exists()


@pytest.mark.parametrize(
    ("count", "most"),
    [("100000", 100000), ("{ integers = [3, 70000] }", 70000), ("{ choice = [1, 90000] }", 90000),
     ("{ poisson = 60000 }", 61476)],
)  # fmt: skip
def test_a_dataset_with_more_objects_than_memory_holds_is_refused_before_drawing(
    tmp_path, capsys, monkeypatch, count, most
):
    """Each object costs a sample about 300 KB (measured: docs/datasets.md); a count that would
    need more memory than the machine has is one error line before any draw (it used to draw
    three trial samples of 100 000 objects first, then run out of memory)."""
    from sonar_raster.scenes.bundled import bundled_dataset_config

    text = bundled_dataset_config("dataset_default").read_text()
    config = tmp_path / "many.toml"
    config.write_text(text.replace("count = { integers = [0, 2] }", f"count = {count}", 1))
    monkeypatch.setattr(_budget, "physical_memory", lambda: 16 << 30)
    out = tmp_path / "ds"
    assert main(["dataset", str(config), "-o", str(out), "-n", "2"]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert f"up to {most + 7} objects" in line and "objects' count" in line
    assert not out.exists()


def test_check_disk_adds_up_outputs_on_one_file_system(tmp_path, monkeypatch):
    from sonar_raster.errors import SonarRasterError

    monkeypatch.setattr(_budget, "free_disk", lambda folder: 1000)
    _budget.check_disk([(tmp_path / "a", 600)], "job", "lower it")
    with pytest.raises(SonarRasterError, match=r"about 1\.2 KiB, more than the 1000 B free"):
        _budget.check_disk([(tmp_path / "a", 600), (tmp_path / "new" / "b", 600)], "job", "x")
    _budget.check_disk([(tmp_path / "a", 6000)], "job", "lower it", force=True)


def test_free_disk_of_a_folder_yet_to_be_made_is_its_parent_s(tmp_path):
    assert _budget.free_disk(tmp_path / "not" / "yet") == _budget.free_disk(tmp_path)


def test_a_long_track_is_sized_before_it_is_made(tmp_path, capsys, monkeypatch):
    """--pings 100000000: refused from a two-ping load of the scene (the full track alone
    would take 10 GB and 18 s to make), in one line, nothing written."""
    loaded = []
    real = render_cli.load_setup

    def spy(args):
        loaded.append(args.pings)
        return real(args)

    monkeypatch.setattr(render_cli, "load_setup", spy)
    monkeypatch.setattr(_budget, "free_disk", lambda folder: 1 << 30)
    out = tmp_path / "out.png"
    assert main(["render", SCENE, "--pings", "100000000", "-o", str(out)]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert "rendering 100000000 pings x 600 bins x 2 sides would write about" in line
    assert "--pings" in line and loaded == [2]
    assert list(tmp_path.iterdir()) == []


def test_the_surface_fit_is_sized_at_its_own_rate(tmp_path, capsys, monkeypatch):
    """``--method surface`` costs several times the per-ping method per pixel: its estimate
    uses its own rate, so a job the profiles would run is refused for the surface fit."""
    from sonar_raster.cli import invert as invert_cli
    from sonar_raster.inversion import method

    np.save(tmp_path / "img.npy", np.ones((40, 64), np.float32))
    monkeypatch.setattr(invert_cli, "_PIXEL_SECONDS", 0.1)  # 2560 px: 4 min, runs
    monkeypatch.setattr(method, "SURFACE_PIXEL_SECONDS", 2.0)  # 85 min: refused
    cmd = ["invert", str(tmp_path / "img.npy"), "--range-bin", "0.1", "-o", str(tmp_path / "o")]
    assert main([*cmd, "--method", "surface", "-q"]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert "2560 pixels" in line and "crop the image" in line
    assert not (tmp_path / "o").exists()


def test_an_xtf_file_says_the_estimate_of_the_method_it_chose_once(tmp_path, capsys, monkeypatch):
    """``--method auto`` checks the file's size as the profiles would without saying it, reads
    it, chooses, and says the chosen method's estimate from the samples read."""
    from sonar_raster.cli import invert as invert_cli
    from sonar_raster.inversion import method
    from sonar_raster.inversion import xtf as inv_xtf

    if not XTF.is_file():
        pytest.fail(f"{XTF} is missing: the shared data must sit beside the clone")

    class Stop(Exception):
        pass

    def stop(*args, **kwargs):
        raise Stop

    monkeypatch.setattr(inv_xtf, "invert_xtf", stop)  # only the choice and the estimates
    monkeypatch.setattr(invert_cli, "_PIXEL_SECONDS", 1e-3)  # the file: 16 min as profiles
    monkeypatch.setattr(method, "SURFACE_PIXEL_SECONDS", 2e-3)  # 31 min as one surface
    with pytest.raises(Stop):
        main(["invert", str(XTF), "-o", str(tmp_path / "o")])
    captured = capsys.readouterr()
    assert [x for x in captured.out.splitlines() if x.startswith("method:")][0].startswith(
        "method: surface (a speckled image"
    )
    said = [x for x in captured.err.splitlines() if "estimated" in x]
    pixels = 461 * 1024 * 2  # the pings read, 1024 samples a side
    memory = pixels * method.SURFACE_PIXEL_BYTES / 2**30
    assert said == [
        f"inverting scotsman-iver2.xtf: about {pixels:.2g} pixels; estimated "
        f"{round(pixels * 2e-3 / 60)} min, {memory:.1f} GiB of memory"
    ]


@pytest.mark.parametrize(
    ("edit", "workers"),
    [
        ({"pings = 512": "pings = 16", "bins = 1024": "bins = 64"}, 48),  # each worker's own
        ({}, 20),  # the sand's micro-relief grid: up to 0.95 M nodes a sample
    ],
)
def test_many_workers_are_refused_by_what_each_holds_before_its_image(
    tmp_path, capsys, monkeypatch, edit, workers
):
    """A worker holds about 350 MB before its image (imports, GL context, effects) and a
    seabed's micro-relief mesh about 400 B per node (measured: docs/performance.md); the
    estimate once counted the image alone (13 MiB a worker for 16 pings x 64 bins, 57 MiB for
    the default config), so 48 or 20 workers were let start on a 16 GiB machine."""
    from sonar_raster.scenes.bundled import bundled_dataset_config

    text = bundled_dataset_config("dataset_default").read_text()
    for old, new in edit.items():
        text = text.replace(old, new, 1)
    config = tmp_path / "workers.toml"
    config.write_text(text)
    monkeypatch.setattr(_budget, "physical_memory", lambda: 16 << 30)
    out = tmp_path / "ds"
    argv = ["dataset", str(config), "-o", str(out), "-n", "2", "--workers", str(workers)]
    assert main(argv) == 2
    line = one_error_line(capsys.readouterr().err)
    assert f"{workers} workers rendering" in line and "--workers" in line
    assert not out.exists()


def test_the_main_process_beside_its_workers_is_counted(tmp_path, monkeypatch):
    """With a pool the main process holds its own memory beside the workers' (295 MB measured
    beside two); with one worker it is the worker."""
    from sonar_raster.errors import SonarRasterError

    needs = {}

    def record(need, what, lower, *, force=False):
        needs[what.split(" workers")[0]] = need
        raise SonarRasterError("stop here")

    monkeypatch.setattr(_budget, "check_memory", record)
    for workers in ("1", "2", "3"):
        out = tmp_path / f"ds{workers}"
        assert (
            main(["dataset", "dataset_default", "-o", str(out), "-n", "2", "--workers", workers])
            == 2
        )
    assert needs["2"] - 2 * needs["1"] == pytest.approx(needs["3"] - 3 * needs["1"])
    assert needs["2"] - 2 * needs["1"] > 250e6
