"""Per-material APL-UW scattering laws in the raster (law texture) and the reference renderer."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import plane

from sonar_raster.rendering.analytic import flat_seabed_profile
from sonar_raster.rendering.reference import render_reference
from sonar_raster.scene import build_scene
from sonar_raster.scenes.sediments import law_factor, material_index, sediment
from sonar_raster.sonar import BeamPattern, Sonar
from sonar_raster.trajectory import Trajectory

ALTITUDE = 8.0


def _scene(material: str, law: bool = True):
    part = plane(200.0, reflectivity=sediment(material).reflectivity)
    part = type(part)(
        part.vertices,
        part.faces,
        part.reflectivity,
        "seabed",
        True,
        material_index(material) if law else 0,
    )
    return build_scene([part])


def _expected(sonar: Sonar, material: str, spacing: float, side: str) -> np.ndarray:
    """Lambert's closed form times the law's factor at each bin's centre incidence angle."""
    lambert = flat_seabed_profile(
        sonar, ALTITUDE, sediment(material).reflectivity, spacing, side=side
    )
    r = (np.arange(sonar.n_bins) + 0.5) * sonar.range_bin
    cos_t = np.clip(ALTITUDE / np.maximum(r, ALTITUDE), 0.0, 1.0)
    law = np.full(sonar.n_bins, material_index(material))
    return lambert * law_factor(law, cos_t, sonar.frequency_hz, sonar.sound_speed)


@pytest.mark.parametrize("material", ["sand", "mud", "rock"])
def test_raster_flat_seabed_follows_the_law(gl, material):
    sonar = Sonar(
        max_range=40.0,
        range_bin=0.05,
        beam=BeamPattern.gaussian(30.0),
        tilt=math.radians(15),
        frequency_hz=600e3,
    )
    spacing = 0.2
    traj = Trajectory.straight((0.0, -2.0, ALTITUDE), 0.0, spacing, 12)
    image = gl.render(_scene(material), sonar, traj)
    lambert = gl.render(_scene(material, law=False), sonar, traj)
    first = int(math.ceil(ALTITUDE / sonar.range_bin)) + 40  # 2 m beyond nadir: smooth law
    for side in ("port", "starboard"):
        expected = _expected(sonar, material, spacing, side)
        got = image.sides[side].astype(np.float64).mean(axis=0)
        err = np.abs(got[first:] / expected[first:] - 1.0)
        assert err.max() < 0.01, f"{material} {side}: worst bin off by {err.max():.4f}"
        # and the law is not Lambert: the profiles differ by its shape (mud, the flattest: 1 dB)
        ratio = got[first:] / lambert.sides[side].astype(np.float64).mean(axis=0)[first:]
        assert np.ptp(10 * np.log10(ratio)) > 0.8


def test_raster_matches_reference_with_laws(gl):
    """Two discretisations of the same law agree on the mean profile (sand and mud halves)."""
    sand = plane(60.0, reflectivity=sediment("sand").reflectivity, center=(0.0, -30.0))
    mud = plane(60.0, reflectivity=sediment("mud").reflectivity, center=(0.0, 30.0))
    parts = [
        type(p)(p.vertices, p.faces, p.reflectivity, name, True, material_index(name))
        for p, name in ((sand, "sand"), (mud, "mud"))
    ]
    scene = build_scene(parts)
    sonar = Sonar(max_range=25.0, range_bin=0.1, sides=("starboard",), frequency_hz=400e3)
    rows = []
    for y in (-30.0, 30.0):
        traj = Trajectory.straight((0.0, y - 1.0, ALTITUDE), 0.0, 0.5, 4)
        ref = render_reference(scene, sonar, traj).sides["starboard"].astype(np.float64)
        got = gl.render(scene, sonar, traj).sides["starboard"].astype(np.float64)
        first = int(math.ceil(ALTITUDE / sonar.range_bin)) + 2
        a, b = got.mean(axis=0)[first:], ref.mean(axis=0)[first:]
        rows.append(b)
        np.testing.assert_allclose(a, b, rtol=0.01)
    # sand and mud really differ (the test would pass trivially with one law for both)
    assert np.max(np.abs(10 * np.log10(rows[0] / rows[1]))) > 3.0
