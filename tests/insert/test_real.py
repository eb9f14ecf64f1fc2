"""Objects inserted into the OpenSidescan sample: shadow geometry, shadow contrast, the XTF copy.

Measured on ``scotsman-iver2.xtf`` (``python -m pytest tests/insert/test_real.py -q -s``
prints every number): a 1 m box's shadow, found in the composite by the shadow detector
(:func:`sonar_raster.inversion.shadows.find_shadows`), ends where ``Ls = H x / (h − H)`` puts
it with the tracked altitude (h the vertical altitude, the tracked first return times
cos(pitch); x the box's far edge), on the object's own ping row (within one bin); and its
shadow-to-seabed contrast, measured as for the real wreck, is compared with the wreck's.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import SHARED_DATA

from sonar_raster.insert import insert_objects, read_recording
from sonar_raster.inversion.shadows import find_shadows, object_pings
from sonar_raster.io.xtf import read_xtf

SAMPLE = SHARED_DATA / "xtf" / "scotsman-iver2.xtf"
HEIGHT, WIDTH = 1.0, 1.5
#: (ping, signed ground range) of the boxes: port, clear of the wreck; pitch -22.7 and -7.9 deg.
PLACES = ((100, -10.0), (420, -12.0))
#: The inserted shadow must be at least this dark against the seabed beyond it (dB).
MIN_CONTRAST_DB = 10.0


@pytest.fixture(scope="module")
def rec():
    if not SAMPLE.is_file():
        pytest.skip(f"{SAMPLE} not present")
    return read_recording(SAMPLE)


def _contrast_db(image: np.ndarray, found, rows: np.ndarray) -> float:
    """Mean shadow over mean seabed from 10 to 80 bins beyond the shadow's end, dB."""
    dark, seabed = [], []
    for i in rows:
        a, b = int(found.start[i]), int(found.end[i])
        if a >= 0:
            dark.append(image[i, a:b])
            seabed.append(image[i, b + 10 : b + 80])
    return 10.0 * math.log10(np.concatenate(dark).mean() / np.concatenate(seabed).mean())


def _box(gl, rec, ping, ground):
    spec = f"box:size={WIDTH},{WIDTH},{HEIGHT}"
    return insert_objects(rec, [spec], at=[(ping, ground)], seed=1, renderer=gl)


SLOPED = pytest.mark.xfail(
    strict=True,
    reason=(
        "ping 420 lies on a 16-degree along-track slope: since the raster keeps each ping's own "
        "altitude for its fan extent (the culling fix of 2026-11-24), the shadow ends at bin 619 "
        "at every oversampling (1.9-4), 1.47 bins short of H·x/(h−H); the earlier 620 came only "
        "at oversample 2.0. Open: whether the box should stand on the sloped seabed"
    ),
)


@pytest.mark.parametrize(("ping", "ground"), [PLACES[0], pytest.param(*PLACES[1], marks=SLOPED)])
def test_inserted_shadow_length_follows_the_tracked_altitude(gl, rec, ping, ground):
    ins = _box(gl, rec, ping, ground)
    rows = np.arange(ping - 1, ping + 2)
    dr = rec.range_bin
    found = find_shadows(ins.intensity["port"][rows], dr, rec.altitude[rows])
    x = abs(ground) + 0.5 * WIDTH
    h_fan = rec.altitude[rows]
    h = rec.vertical_altitude()[rows]
    length = HEIGHT * x / (h - HEIGHT)
    predicted = np.sqrt((x + length) ** 2 + h_fan**2) / dr  # slant bins of the shadow's end
    shown = np.round(predicted, 1).tolist()
    print(f"ping {ping}: shadow end found {found.end.tolist()}, predicted {shown} bins "
          f"(Ls {np.round(length, 2).tolist()} m)")  # fmt: skip
    # the object's own row: the box stands at that ping's seabed depth. Rows beside it meet a
    # seabed tracked 0.04 m higher or lower per ping here (a 16-degree along-track slope at
    # ping 420), under a box that stands level: their shadows are that much shorter or longer.
    assert found.end[1] > 0
    assert abs(found.end[1] - predicted[1]) <= 1.0


def test_inserted_shadow_contrast_against_the_wreck(gl, rec):
    real = rec.intensity["starboard"]
    wreck = find_shadows(real, rec.range_bin, rec.altitude)
    wreck_db = _contrast_db(real, wreck, np.flatnonzero(object_pings(wreck.height)))
    for ping, ground in PLACES:
        ins = _box(gl, rec, ping, ground)
        rows = np.flatnonzero((ins.classes["port"] == 2).any(axis=1))
        image = ins.intensity["port"][rows]
        found = find_shadows(image, rec.range_bin, rec.altitude[rows])
        box_db = _contrast_db(image, found, np.flatnonzero(found.start >= 0))
        untouched = _contrast_db(
            rec.intensity["port"][rows], found, np.flatnonzero(found.start >= 0)
        )
        print(f"shadow contrast: box at ping {ping} {box_db:.1f} dB, the wreck {wreck_db:.1f} dB "
              f"(difference {box_db - wreck_db:+.1f} dB; the same cells before insertion "
              f"{untouched:.1f} dB)")  # fmt: skip
        assert box_db < -MIN_CONTRAST_DB
        assert untouched > -3.0  # the darkness comes from the insertion


def test_xtf_copy_changes_only_the_objects_rows(gl, rec, tmp_path):
    from sonar_raster.insert.outputs import insertion_jobs
    from sonar_raster.io.commit import commit

    ins = _box(gl, rec, *PLACES[0])
    commit(insertion_jobs(ins, tmp_path / "out.xtf"))
    before, nav_before = read_xtf(SAMPLE)
    after, nav_after = read_xtf(tmp_path / "out.xtf")
    assert np.array_equal(nav_before.x, nav_after.x, equal_nan=True)
    assert np.array_equal(after.sides["starboard"], before.sides["starboard"])
    changed = np.flatnonzero(np.any(after.sides["port"] != before.sides["port"], axis=1))
    assert set(changed) <= set(ins.rows.tolist()) and len(changed) > 0
    # amplitudes: the file holds the square root of the composite, to the uint16 step
    want = np.sqrt(ins.intensity["port"][changed])
    assert np.max(np.abs(after.sides["port"][changed] - want)) <= 0.5 + 1e-6
    raw_in, raw_out = SAMPLE.read_bytes(), (tmp_path / "out.xtf").read_bytes()
    assert len(raw_in) == len(raw_out)
    assert raw_in[:1024] == raw_out[:1024]  # the file header as recorded
