"""Inserting an object into a simulated recording equals rendering object and seabed together.

A flat seabed is rendered along a straight track with a Gaussian beam and sensor effects
(spreading, receiver noise, optionally speckle), written as XTF and read back as a recording;
a box is inserted at (ping, ground range). The same box rendered with the seabed, with the
same effects, is the truth. Measured (``python -m pytest tests/insert -q -s`` prints them):
mean intensity on the highlight and in the shadow, and each ping's shadow end.
"""

from __future__ import annotations

import math

import numpy as np
from conftest import box_from_bounds, plane

from sonar_raster.effects.chain import Effects, apply_effects
from sonar_raster.image import SonarImage
from sonar_raster.insert import insert_objects, read_recording
from sonar_raster.inversion.shadows import find_shadows
from sonar_raster.io.xtf import write_xtf
from sonar_raster.scene import build_scene
from sonar_raster.sonar import BeamPattern, Sonar
from sonar_raster.trajectory import Trajectory

ALTITUDE, PINGS, SPACING = 8.0, 48, 0.1
BOX = (1.2, 0.8, 1.0)  # across, along, height (m)
GROUND, PING = 12.0, 24
#: Highlight mean within this fraction of the truth's (clean), shadow mean likewise.
CLEAN_TOLERANCE = 0.05
#: With speckle (independent realisations), the highlight mean within this fraction.
SPECKLE_TOLERANCE = 0.15


def _sonar() -> Sonar:
    return Sonar(
        frequency_hz=600e3, max_range=24.0, range_bin=0.04, beam=BeamPattern.gaussian(40.0),
        tilt=math.radians(15.0), sides=("port", "starboard"),
    )  # fmt: skip


def _scene(with_box: bool):
    length = PINGS * SPACING
    parts = [plane(80.0, 0.0, 0.3, center=(0.0, 0.5 * length))]
    if with_box:
        y = PING * SPACING
        x0, y0 = GROUND - 0.5 * BOX[0], y - 0.5 * BOX[1]
        parts.append(box_from_bounds([[x0, y0, 0.0], [x0 + BOX[0], y0 + BOX[1], BOX[2]]], 0.9))
    return build_scene(parts)


def _track() -> Trajectory:
    return Trajectory.straight((0.0, 0.0, ALTITUDE), 0.0, SPACING, PINGS)


def _effects(speckle: bool) -> Effects:
    return Effects(spreading=True, noise_db=-100.0, speckle="exponential" if speckle else "off")


def _simulate(gl, with_box: bool, speckle: bool, seed: int) -> SonarImage:
    raw = gl.render(_scene(with_box), _sonar(), _track())
    return apply_effects(raw, _effects(speckle), seed=seed, trajectory=_track())


def _inserted(gl, tmp_path, speckle: bool, seed: int, beam: bool = True):
    recording = _simulate(gl, False, speckle, seed)
    path = tmp_path / f"sim{seed}.xtf"
    write_xtf(path, recording, _track(), altitude=ALTITUDE)
    rec = read_recording(path)
    assert not rec.amplitude  # this project's XTF holds intensities
    spec = f"box:size={BOX[0]},{BOX[1]},{BOX[2]}:reflectivity=0.9"
    known = (_sonar().beam, _sonar().tilt) if beam else None
    return insert_objects(rec, [spec], at=[(PING, GROUND)], seed=seed, renderer=gl, beam=known)


def _means(ins, truth: SonarImage) -> dict[str, tuple[float, float]]:
    side = "starboard"
    cls = ins.classes[side]
    got, want = ins.intensity[side], truth.sides[side].astype(np.float64)
    return {
        name: (float(got[cls == k].mean()), float(want[cls == k].mean()))
        for name, k in (("highlight", 1), ("shadow", 2))
    }


def test_clean_insertion_matches_joint_render(gl, tmp_path):
    ins = _inserted(gl, tmp_path, speckle=False, seed=1)
    truth = _simulate(gl, True, False, seed=1)
    means = _means(ins, truth)
    for name, (got, want) in means.items():
        print(f"clean {name}: inserted {got:.4g}, joint render {want:.4g}, "
              f"ratio {got / want:.4f}")  # fmt: skip
        assert abs(got / want - 1.0) < CLEAN_TOLERANCE, name
    # the shadow's end, found in each image by the shadow detector, within one bin
    rows = np.flatnonzero((ins.classes["starboard"] == 2).any(axis=1))
    dr = ins.recording.range_bin
    found_in = find_shadows(ins.intensity["starboard"][rows], dr, ins.recording.altitude[rows])
    found_tr = find_shadows(truth.sides["starboard"][rows].astype(float), dr,
                            ins.recording.altitude[rows])  # fmt: skip
    both = (found_in.end > 0) & (found_tr.end > 0)
    assert both.sum() >= len(rows) - 2  # the two edge pings may hold partial shadows
    diff = found_in.end[both] - found_tr.end[both]
    print(f"shadow end, inserted - joint: {diff.tolist()} bins over {both.sum()} pings")
    assert np.max(np.abs(diff)) <= 1
    # the other side and the rows no object reaches are the recording's, bit for bit
    assert np.array_equal(ins.intensity["port"], ins.recording.intensity["port"])
    other = np.setdiff1d(np.arange(PINGS), ins.rows)
    assert np.array_equal(
        ins.intensity["starboard"][other], ins.recording.intensity["starboard"][other]
    )


def test_unknown_beam_darkens_a_tall_object_as_stated(gl, tmp_path):
    """Without the beam pattern the highlight gets the seabed's beam at its range (documented)."""
    ins = _inserted(gl, tmp_path, speckle=False, seed=1, beam=False)
    got, want = _means(ins, _simulate(gl, True, False, seed=1))["highlight"]
    print(f"unknown beam: highlight ratio {got / want:.4f}")
    assert 0.75 < got / want < 0.9


def test_speckled_insertion_matches_joint_render(gl, tmp_path):
    ratios = []
    for seed in (2, 3, 4):
        ins = _inserted(gl, tmp_path, speckle=True, seed=seed)
        truth = _simulate(gl, True, True, seed=100 + seed)
        got, want = _means(ins, truth)["highlight"]
        ratios.append(got / want)
        assert ins.stats["starboard"].looks < 2.0  # one-look speckle is found as such
    print(f"speckled highlight mean ratios (3 realisations): {np.round(ratios, 3).tolist()}")
    assert abs(float(np.mean(ratios)) - 1.0) < SPECKLE_TOLERANCE
