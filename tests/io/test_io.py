import json
import math
import os
from datetime import datetime

import numpy as np
import OpenImageIO as oiio
import pytest

from sonar_raster.errors import SonarRasterError
from sonar_raster.image import SonarImage
from sonar_raster.io import images as io
from sonar_raster.sonar import Sonar

PINGS, BINS = 37, 53  # non-square, so a transpose cannot pass


@pytest.fixture(autouse=True)
def _strict_float():
    with np.errstate(all="raise"):
        yield


def random_image(seed: int = 7, metadata: dict | None = None) -> SonarImage:
    rng = np.random.default_rng(seed)
    sides = {
        "port": rng.random((PINGS, BINS), dtype=np.float32),
        "starboard": rng.random((PINGS, BINS), dtype=np.float32) * 3.0,
    }
    sides["port"][0, :4] = 0.0  # some shadow
    meta = (
        {"scene": {"name": "flat", "seed": np.int64(3)}, "samples": 4}
        if metadata is None
        else metadata
    )
    return SonarImage(sides, Sonar(range_bin=0.05, max_range=BINS * 0.05), meta)


def read_png(path):
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    spec = inp.spec()
    pixels = inp.read_image(format=spec.format)
    attrs = {a.name: a.value for a in spec.extra_attribs}
    inp.close()
    return pixels, spec, attrs


def listing(directory):
    return sorted(p.name for p in directory.iterdir())


# EXR


def test_exr_round_trip_is_bit_exact_per_side(tmp_path):
    image = random_image()
    written = io.write_image(image, tmp_path / "out.exr")
    assert written == [tmp_path / "out.exr", tmp_path / "out.json"]
    sides, attrs = io.read_exr(tmp_path / "out.exr")
    assert sorted(sides) == ["port", "starboard"]
    for name in ("port", "starboard"):
        assert sides[name].dtype == np.float32
        assert sides[name].shape == (PINGS, BINS)
        np.testing.assert_array_equal(sides[name], image.sides[name])
    assert attrs["compression"] == "zip"


def test_exr_attributes(tmp_path):
    image = random_image()
    io.write_image(image, tmp_path / "out.exr", sidecar=False)
    _, attrs = io.read_exr(tmp_path / "out.exr")
    assert attrs["sonar:units"] == "m^2 (beam-weighted backscattering area, K=1)"
    assert attrs["sonar:layout"] == "rows=pings, columns=slant-range bins near->far"
    assert attrs["sonar:n_bins"] == BINS
    assert attrs["sonar:sides"] == "port,starboard"
    assert attrs["sonar:beam"] == "uniform"
    assert attrs["sonar:frequency_hz"] == pytest.approx(400e3)
    assert attrs["sonar:range_bin_m"] == pytest.approx(0.05, rel=1e-7)  # EXR floats are 32-bit
    assert set(image.sonar.to_dict()) <= {k.removeprefix("sonar:") for k in attrs}
    assert json.loads(attrs["sonar_raster:scene.name"]) == "flat"
    assert json.loads(attrs["sonar_raster:scene.seed"]) == 3
    assert json.loads(attrs["sonar_raster:samples"]) == 4


def test_exr_one_side(tmp_path):
    image = random_image()
    only = SonarImage({"starboard": image.sides["starboard"]}, image.sonar)
    io.write_image(only, tmp_path / "s.exr", sidecar=False)
    sides, _ = io.read_exr(tmp_path / "s.exr")
    assert list(sides) == ["starboard"]
    np.testing.assert_array_equal(sides["starboard"], image.sides["starboard"])


def test_large_metadata_stays_out_of_the_header(tmp_path):
    image = random_image(metadata={"track": list(range(5000)), "name": "x"})
    io.write_image(image, tmp_path / "out.exr")
    _, attrs = io.read_exr(tmp_path / "out.exr")
    assert "sonar_raster:track" not in attrs
    assert json.loads(attrs["sonar_raster:name"]) == "x"
    doc = json.loads((tmp_path / "out.json").read_text())
    assert doc["metadata"]["track"] == list(range(5000))


# display mapping


def test_display_mapping_known_values():
    ref, dr = 2.0, 60.0
    intensity = np.array([ref, ref * 10 ** (-dr / 10), 0.0, ref * 10 ** (-3.0), ref * 10, 1e-12])
    codes, used = io.display_mapping(intensity, dr, ref)
    assert used == ref
    np.testing.assert_allclose(codes, [1.0, 0.0, 0.0, 0.5, 1.0, 0.0], atol=1e-12)


def test_display_mapping_reference_is_995th_percentile_of_nonzero():
    values = np.concatenate([np.zeros(500), np.linspace(1.0, 1000.0, 1000)])
    _, ref = io.display_mapping(values, 40.0)
    assert ref == pytest.approx(np.percentile(np.linspace(1.0, 1000.0, 1000), 99.5))


def test_display_mapping_all_zero_image():
    codes, ref = io.display_mapping(np.zeros((3, 4)), 60.0)
    assert ref == 1.0
    assert not codes.any()


@pytest.mark.parametrize(
    ("values", "dr", "ref"),
    [([1.0, np.nan], 60.0, None), ([1.0, -1.0], 60.0, None), ([1.0], 0.0, None), ([1.0], 60, 0.0)],
)
def test_display_mapping_rejects_bad_input(values, dr, ref):
    with pytest.raises(SonarRasterError):
        io.display_mapping(np.array(values), dr, ref)


# PNG


def bright_pixel_image() -> SonarImage:
    port = np.zeros((PINGS, BINS), np.float32)
    starboard = np.zeros((PINGS, BINS), np.float32)
    port[3, 5] = 1.0
    starboard[3, 5] = 1.0
    return SonarImage({"port": port, "starboard": starboard}, Sonar(max_range=BINS * 0.05))


def test_png_display_layout(tmp_path):
    io.write_image(bright_pixel_image(), tmp_path / "out.png", dynamic_range_db=20.0)
    pixels, spec, _ = read_png(tmp_path / "out.png")
    assert (spec.height, spec.width, spec.nchannels) == (PINGS, 2 * BINS, 1)
    grey = pixels[:, :, 0]
    bright = np.argwhere(grey == 255)
    # port: range increases to the left, so bin 5 is column BINS - 1 - 5
    # starboard: range increases to the right, starting at column BINS
    assert bright.tolist() == [[3, BINS - 1 - 5], [3, BINS + 5]]


def test_png_codes_and_text_attributes(tmp_path):
    image = random_image()
    io.write_image(image, tmp_path / "out.png", dynamic_range_db=50.0)
    pixels, spec, attrs = read_png(tmp_path / "out.png")
    assert spec.format == oiio.UINT8
    ref = float(attrs["sonar:display_ref_level_m2"])
    assert float(attrs["sonar:display_dynamic_range_db"]) == 50.0
    assert attrs["sonar:display_max_code"] == "255"
    assert "ref = " in attrs["ImageDescription"]
    assert attrs["sonar:n_bins"] == str(BINS)
    assert attrs["sonar:range_bin_m"] == "0.05"  # exact, PNG text
    assert json.loads(attrs["sonar_raster:scene.name"]) == "flat"
    codes, expected_ref = io.display_mapping(image.display(), 50.0)
    assert ref == expected_ref
    np.testing.assert_array_equal(pixels[:, :, 0], np.rint(codes * 255).astype(np.uint8))
    # the documented inverse recovers the intensity to within half a code step
    display = image.display().astype(np.float64)
    code = pixels[:, :, 0].astype(np.float64)
    visible = code > 0
    inverse = ref * 10 ** (50.0 / 10 * (code[visible] / 255 - 1))
    step_db = 50.0 / 255
    error_db = np.abs(10 * np.log10(inverse / display[visible]))
    assert error_db.max() <= step_db / 2 + 1e-9


def test_png_known_intensities_give_known_codes(tmp_path):
    port = np.full((PINGS, BINS), 1e-9, np.float32)
    port[0, 0], port[0, 1], port[0, 2] = 0.0, 1.0, 1e-6  # DR = 60 dB below 1.0 is 1e-6
    port[1:, :] = 1.0  # makes the 99.5th percentile exactly 1.0
    image = SonarImage({"port": port}, Sonar(sides=("port",), max_range=BINS * 0.05))
    io.write_image(image, tmp_path / "k.png", bit_depth=16, sidecar=False, dynamic_range_db=60.0)
    pixels, spec, attrs = read_png(tmp_path / "k.png")
    assert pixels.dtype == np.uint16 and spec.format == oiio.UINT16
    assert float(attrs["sonar:display_ref_level_m2"]) == 1.0
    row = pixels[0, ::-1, 0]  # port columns run far -> near
    assert (row[0], row[1], row[2], row[3]) == (0, 65535, 0, 0)


def test_bad_bit_depth(tmp_path):
    with pytest.raises(SonarRasterError, match="8 or 16"):
        io.write_image(random_image(), tmp_path / "x.png", bit_depth=12)
    assert listing(tmp_path) == []


# sidecar


def test_sidecar_contents(tmp_path):
    image = random_image()
    io.write_image(image, tmp_path / "out.png", dynamic_range_db=45.0)
    doc = json.loads((tmp_path / "out.json").read_text())
    assert doc["sonar"] == json.loads(json.dumps(image.sonar.to_dict()))
    assert doc["metadata"] == {"scene": {"name": "flat", "seed": 3}, "samples": 4}
    assert doc["shape"] == [PINGS, BINS]
    assert doc["sides"] == ["port", "starboard"]
    mapping = doc["display_mapping"]
    assert mapping["dynamic_range_db"] == 45.0
    assert mapping["ref_level_m2"] == io.display_mapping(image.display(), 45.0)[1]
    assert "log10" in mapping["formula"]
    assert isinstance(doc["package_version"], str) and doc["package_version"]
    assert datetime.fromisoformat(doc["written_utc"]).utcoffset().total_seconds() == 0


def test_sidecar_converts_numpy_and_non_finite(tmp_path):
    meta = {"a": np.arange(3), "b": np.float32(0.5), "c": math.inf, "d": (1, 2), "e": None}
    io.write_image(random_image(metadata=meta), tmp_path / "m.exr")
    doc = json.loads((tmp_path / "m.json").read_text())
    assert doc["metadata"] == {"a": [0, 1, 2], "b": 0.5, "c": "inf", "d": [1, 2], "e": None}


def test_metadata_that_json_cannot_store(tmp_path):
    with pytest.raises(SonarRasterError, match="JSON"):
        io.write_image(random_image(metadata={"x": object()}), tmp_path / "o.exr")
    assert listing(tmp_path) == []


def test_no_sidecar(tmp_path):
    assert io.write_image(random_image(), tmp_path / "n.png", sidecar=False) == [tmp_path / "n.png"]
    assert listing(tmp_path) == ["n.png"]


# errors and atomic writes


def test_unsupported_extension(tmp_path):
    with pytest.raises(SonarRasterError, match=r"\.exr, \.png"):
        io.write_image(random_image(), tmp_path / "out.tif")
    assert listing(tmp_path) == []


def test_missing_directory(tmp_path):
    target = tmp_path / "out" / "x.png"
    with pytest.raises(SonarRasterError, match="does not exist; create it first"):
        io.write_image(random_image(), target)
    assert listing(tmp_path) == []


def test_parent_is_a_file(tmp_path):
    (tmp_path / "f").write_text("")
    with pytest.raises(SonarRasterError, match="not a directory"):
        io.write_image(random_image(), tmp_path / "f" / "x.exr")
    assert listing(tmp_path) == ["f"]


def test_unwritable_directory(tmp_path, monkeypatch):
    def refuse(tmp, *args):
        raise PermissionError(13, "Permission denied", str(tmp))

    monkeypatch.setattr(io, "write_oiio", refuse)
    with pytest.raises(SonarRasterError, match="cannot write .*x.png: Permission denied"):
        io.write_image(random_image(), tmp_path / "x.png")
    assert listing(tmp_path) == []


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0, reason="root writes anywhere")
def test_read_only_directory(tmp_path):
    target = tmp_path / "ro"
    target.mkdir()
    target.chmod(0o500)
    try:
        with pytest.raises(SonarRasterError, match="cannot write"):
            io.write_image(random_image(), target / "x.png")
        assert listing(target) == []
    finally:
        target.chmod(0o700)


def test_complex_image_is_rejected(tmp_path):
    image = random_image()
    sides = {k: v.astype(np.complex64) for k, v in image.sides.items()}
    with pytest.raises(SonarRasterError, match="real numbers"):
        io.write_image(SonarImage(sides, image.sonar), tmp_path / "x.exr")


@pytest.mark.parametrize("bad", [np.nan, np.inf, 1e39])
def test_non_finite_values(tmp_path, bad):
    image = random_image()
    sides = {k: v.astype(np.float64) for k, v in image.sides.items()}
    sides["starboard"][2, 2] = bad  # 1e39 is finite but overflows float32
    with pytest.raises(SonarRasterError, match="an image to write must be finite"):
        io.write_image(SonarImage(sides, image.sonar), tmp_path / "x.exr")
    assert listing(tmp_path) == []


@pytest.mark.parametrize("shape", [(0, BINS), (PINGS, 0)])
def test_empty_image(tmp_path, shape):
    image = SonarImage({"port": np.zeros(shape, np.float32)}, Sonar())
    with pytest.raises(SonarRasterError, match="empty"):
        io.write_image(image, tmp_path / "x.png")
    with pytest.raises(SonarRasterError, match="no sides"):
        io.write_image(SonarImage({}, Sonar()), tmp_path / "x.png")


def test_failure_after_image_temp_leaves_existing_files_untouched(tmp_path, monkeypatch):
    (tmp_path / "out.png").write_bytes(b"old png")
    (tmp_path / "out.json").write_bytes(b"old json")
    seen = []

    def broken_json(tmp, doc):
        seen.extend(p.name for p in tmp_path.iterdir() if p.name.startswith("."))
        tmp.write_text("{half")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(io, "write_json", broken_json)
    with pytest.raises(SonarRasterError, match="No space left on device"):
        io.write_image(random_image(), tmp_path / "out.png")
    assert len(seen) == 1 and seen[0].startswith(".out.png.") and seen[0].endswith(".png")
    assert listing(tmp_path) == ["out.json", "out.png"]
    assert (tmp_path / "out.png").read_bytes() == b"old png"
    assert (tmp_path / "out.json").read_bytes() == b"old json"


def test_encoder_failure_leaves_existing_file_untouched(tmp_path, monkeypatch):
    (tmp_path / "out.exr").write_bytes(b"old exr")

    def half_written(tmp, pixels, spec):
        tmp.write_bytes(b"\x76\x2f\x31\x01 partial")
        raise RuntimeError("disk went away")

    monkeypatch.setattr(io, "write_oiio", half_written)
    with pytest.raises(SonarRasterError, match="cannot write .*out.exr: disk went away"):
        io.write_image(random_image(), tmp_path / "out.exr")
    assert listing(tmp_path) == ["out.exr"]
    assert (tmp_path / "out.exr").read_bytes() == b"old exr"


def test_overwrite_replaces_existing_file(tmp_path):
    (tmp_path / "out.exr").write_bytes(b"old exr")
    io.write_image(random_image(), tmp_path / "out.exr")
    sides, _ = io.read_exr(tmp_path / "out.exr")
    np.testing.assert_array_equal(sides["port"], random_image().sides["port"])
    assert listing(tmp_path) == ["out.exr", "out.json"]


def test_read_exr_missing_file(tmp_path):
    with pytest.raises(SonarRasterError, match="cannot read"):
        io.read_exr(tmp_path / "nope.exr")


def test_auto_dynamic_range_spans_the_image():
    values = np.geomspace(1e-3, 1.0, 1001)  # 30 dB from the weakest to the strongest
    values[::7] = 0.0  # zeros (shadow) are ignored
    dr = io.auto_dynamic_range(values)
    assert 28.0 < dr < 30.0
    assert io.auto_dynamic_range(np.full(10, 2.0)) == io.AUTO_RANGE_DB[0]
    assert io.auto_dynamic_range(np.zeros(10)) == io.AUTO_RANGE_DB[1]
    assert io.auto_dynamic_range(np.geomspace(1e-12, 1.0, 1000)) == io.AUTO_RANGE_DB[1]
