"""Culling draws only what each draw's fans can see, whatever the attitude: with it on, the image
is the same as drawing the whole scene every time.

Pitch leans the fans along track (a fan pitched 22 degrees nose down meets a seabed 10 m below
4 m behind its ping), crab turns them off the track, roll tilts the beam in the fan, and a
climbing or descending track changes the pings' height along a segment. Each case renders a
seabed of small triangles (so culling keeps a small part of it) with ``cull=True`` and
``cull=False`` and asks for the same image bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import SHARED_DATA

from sonar_raster.rendering.gl.raster import RasterSettings
from sonar_raster.scene import build_scene
from sonar_raster.scenes.seabed import heightfield_mesh
from sonar_raster.sonar import Sonar
from sonar_raster.trajectory import Trajectory

ALTITUDE, SPACING, PINGS = 10.0, 0.25, 20
SONAR = Sonar(max_range=25.0, range_bin=0.05)  # 1 m subdivision edge: the grid's cells fit


def _seabed(z0: float = 0.0):
    """A 160 m square seabed of 1 m cells with 0.4 m swells (heights matter to the cull)."""
    x = np.arange(161) - 80.0
    z = z0 + 0.4 * np.sin(x[None, :] / 3.0) * np.cos(x[:, None] / 5.0)
    return build_scene([heightfield_mesh(z, -80.0, -80.0, 1.0, 1.0)])


SEABED = _seabed()


def _track(pitch, roll, crab, climb: float = 0.0, n: int = PINGS) -> Trajectory:
    """Northbound pings at x = 0 (the vehicle heads ``crab`` degrees right of north), climbing
    ``climb`` metres per metre; pitch and roll in degrees, one value or one per ping."""
    k = np.arange(n)
    pos = np.column_stack(
        [np.zeros(n), SPACING * k - 2.5, ALTITUDE + climb * SPACING * (k - n // 2)]
    )
    return Trajectory(
        pos,
        np.full(n, math.radians(crab)),
        np.radians(np.broadcast_to(roll, n)),
        np.radians(np.broadcast_to(pitch, n)),
    )


def _both(gl, scene, sonar, traj):
    """Renders with and without culling, restoring the renderer's settings afterwards.

    The seabed grid is rasterised (``heightfield=False``): level fans would sweep it instead,
    and the culling is what is tested here.
    """
    saved = gl.settings
    try:
        gl.settings = RasterSettings(cull=True, heightfield=False)
        culled = gl.render(scene, sonar, traj)
        gl.settings = RasterSettings(cull=False, heightfield=False)
        whole = gl.render(scene, sonar, traj)
    finally:
        gl.settings = saved
    return culled, whole


def _assert_same(culled, whole, n_faces: int) -> None:
    drawn = culled.metadata["counters"]["triangles_drawn"]
    draws = culled.metadata["counters"]["draws"]
    assert drawn < 0.5 * draws * n_faces, "the case must exercise culling (a small part kept)"
    for side, image in whole.sides.items():
        assert image.sum(axis=1).min() > 0, f"{side}: every ping sees seabed"
        got = culled.sides[side]
        lost = int(np.sum((got.sum(axis=1) == 0) & (image.sum(axis=1) > 0)))
        diff = float(np.abs(got.astype(np.float64) - image).sum() / image.sum())
        assert np.array_equal(got, image), f"{side}: {lost} black rows, relative L1 {diff:.3g}"


@pytest.mark.parametrize(
    "pitch,roll,crab",
    [
        (-22.0, 0.0, 0.0),
        (22.0, 0.0, 0.0),
        (-40.0, 0.0, 0.0),
        (0.0, 25.0, 0.0),
        (0.0, 0.0, 30.0),
        (0.0, 0.0, -30.0),
        (-15.0, 10.0, -20.0),
        (30.0, -12.0, 25.0),
    ],
)
def test_culled_image_equals_the_whole_scene_drawn(gl, pitch, roll, crab):
    culled, whole = _both(gl, SEABED, SONAR, _track(pitch, roll, crab))
    _assert_same(culled, whole, len(SEABED.faces))


@pytest.mark.parametrize("climb", [-0.3, 0.3])
def test_culled_image_equals_the_whole_scene_on_a_climbing_pitched_track(gl, climb):
    """Pitch changing ping to ping (several draws) on a track climbing or descending."""
    pitch = np.linspace(-25.0, -12.0, 40)
    culled, whole = _both(gl, SEABED, SONAR, _track(pitch, 4.0, 8.0, climb=climb, n=40))
    _assert_same(culled, whole, len(SEABED.faces))


def test_descending_segment_sees_to_the_end_of_its_range(gl):
    """The look angles of a draw reach the far range of its lowest ping, not only its first.

    A straight track descending 4 m over 200 pings is one draw; its last ping must see the
    flat seabed as far as the same ping rendered alone (before: out to 436 of 600 bins)."""
    n = 200
    pos = np.column_stack([np.zeros(n), 0.2 * np.arange(n) - 20.0, 14.0 - 0.02 * np.arange(n)])
    traj = Trajectory(pos, np.zeros(n), 0.0)
    sonar = Sonar(max_range=30.0, range_bin=0.05, sides=("starboard",))
    scene = build_scene([heightfield_mesh(np.zeros((121, 121)), -60.0, -60.0, 1.0, 1.0)])
    whole = gl.render(scene, sonar, traj)
    assert whole.metadata["draws"] == 1
    alone = gl.render(scene, sonar, traj.subset(slice(n - 3, n))).sides["starboard"][-1]
    last = whole.sides["starboard"][-1]
    assert np.flatnonzero(last)[-1] == np.flatnonzero(alone)[-1] == sonar.n_bins - 1
    assert np.abs(last - alone).sum() <= 1e-3 * alone.sum()


XTF = SHARED_DATA / "xtf" / "scotsman-iver2.xtf"


def test_culled_image_equals_the_whole_scene_on_a_recorded_track(gl):
    """The OpenSidescan sample's attitudes (pitch down to -22.9 degrees, roll, crab) over a
    synthetic seabed at the recorded altitude: the pings the culling used to lose."""
    if not XTF.is_file():
        pytest.skip(f"{XTF} not present")
    from sonar_raster.io.xtf import read_xtf_track

    rows = slice(80, 120)
    traj, altitude, _ = read_xtf_track(XTF, rows)
    assert np.degrees(traj.pitch).min() < -20.0
    z0 = float(np.mean(traj.positions[:, 2] - np.nan_to_num(altitude, nan=ALTITUDE)))
    centre = traj.positions.mean(axis=0)
    shifted = Trajectory(
        traj.positions - [centre[0], centre[1], 0.0], traj.headings, traj.roll, traj.pitch
    )
    sonar = Sonar(max_range=30.0, range_bin=0.05)
    culled, whole = _both(gl, _seabed(z0), sonar, shifted)
    _assert_same(culled, whole, len(SEABED.faces))
