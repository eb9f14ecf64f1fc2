"""The coherent model's compiled loop (``engine="compiled"``) gives the numpy path's image.

Two implementations of the same model: the numpy array passes of ``model._render_block`` and
the per-facet loop of ``compiled.render_runs``. They must count the same scatterers, visible
scatterers and terms and give the same image to float rounding, on scenes that exercise every
branch (both sides and shadows, a vertical beam and rolling pings, the sinc horizontal beam and
the Eq. 10 law, a crabbed and pitched track, no jitter); the compiled loop's own cosine, sine,
arctangent, logarithm and power of two against numpy's.
"""

import math

import numpy as np
import pytest

from sonar_raster.errors import SonarRasterError
from sonar_raster.rendering.coherent import compiled
from sonar_raster.rendering.coherent.model import HorizontalBeam, render_coherent
from sonar_raster.sonar import BeamPattern, Sonar
from sonar_raster.trajectory import Trajectory

SONAR = Sonar(frequency_hz=20e3, max_range=12.0, range_bin=0.1, sides=("port", "starboard"))
BEAMED = Sonar(
    frequency_hz=20e3,
    max_range=12.0,
    range_bin=0.1,
    sides=("port", "starboard"),
    beam=BeamPattern.gaussian(50.0),
    tilt=math.radians(20.0),
)


def _track(kind: str) -> Trajectory:
    if kind == "straight":
        return Trajectory.straight((0.0, 0.6, 4.0), 0.0, 0.2, 8)
    n = 8
    pos = np.column_stack([np.full(n, 0.3), 0.6 + 0.2 * np.arange(n), np.full(n, 4.0)])
    if kind == "rolling":  # roll changes from ping to ping: the beam gain is per term
        return Trajectory(pos, np.zeros(n), np.linspace(-0.1, 0.15, n), 0.0)
    # crabbed 15° and pitched 5°: the terms take the fan's shear map
    return Trajectory(pos, np.full(n, math.radians(15.0)), 0.0, math.radians(5.0))


CASES = {
    "two sides, shadows": (SONAR, "straight", {}),
    "vertical beam, rolling": (BEAMED, "rolling", {}),
    "sinc beam, eq10 law": (
        BEAMED,
        "straight",
        {"horizontal_beam": HorizontalBeam(0.05, "sinc"), "scattering": "eq10"},
    ),
    "crab and pitch": (BEAMED, "crabbed", {}),
    "no jitter": (SONAR, "straight", {"jitter_wavelengths": 0.0}),
}


@pytest.mark.parametrize("case", list(CASES))
def test_compiled_engine_equals_the_numpy_path(shadow_scene, case):
    sonar, track, extra = CASES[case]
    kw = {"spacing_wavelengths": 0.5, "seabed_spacing_wavelengths": 1.0, "seed": 3, **extra}
    fast = render_coherent(shadow_scene, sonar, _track(track), engine="compiled", **kw)
    slow = render_coherent(shadow_scene, sonar, _track(track), engine="numpy", **kw)
    a, b = fast.metadata, slow.metadata
    assert a["engine"] == "compiled" and b["engine"] == "numpy"
    assert a["n_scatterers"] == b["n_scatterers"] > 10_000
    assert a["n_visible"] == b["n_visible"] < a["n_scatterers"]  # some are in shadow
    assert a["n_pairs"] == b["n_pairs"]
    assert a["facet_area_m2"] == pytest.approx(b["facet_area_m2"], rel=1e-12)
    for side in fast.sides:
        x, y = fast.sides[side].astype(float), slow.sides[side].astype(float)
        assert y.sum() > 0
        assert np.abs(x - y).sum() / y.sum() < 2e-6, side


def test_auto_engine_is_compiled_where_it_applies_and_numpy_elsewhere(shadow_scene):
    track = _track("straight")
    kw = {"spacing_wavelengths": 2.0, "seabed_spacing_wavelengths": 2.0}
    assert render_coherent(shadow_scene, SONAR, track, **kw).metadata["engine"] == "compiled"
    rays = render_coherent(shadow_scene, SONAR, track, visibility="rays", **kw)
    assert rays.metadata["engine"] == "numpy"
    with pytest.raises(SonarRasterError, match="compiled engine needs"):
        render_coherent(shadow_scene, SONAR, track, visibility="rays", engine="compiled", **kw)
    with pytest.raises(SonarRasterError, match="engine must be one of"):
        render_coherent(shadow_scene, SONAR, track, engine="gpu", **kw)


def test_compiled_cosine_sine_arctangent_log_and_exp2_match_numpy():
    rng = np.random.default_rng(0)
    f = np.concatenate([rng.uniform(-0.5, 0.5, 20000), [-0.5, -0.375, -0.25, 0.0, 0.125, 0.5]])
    cs = np.array([compiled.cos_sin_cycles(v) for v in f])
    assert np.abs(cs[:, 0] - np.cos(2 * np.pi * f)).max() < 1e-12
    assert np.abs(cs[:, 1] - np.sin(2 * np.pi * f)).max() < 1e-12
    y, x = rng.normal(size=(2, 20000)) * np.exp(rng.uniform(-5, 5, (2, 20000)))
    y = np.concatenate([y, [0.0, 1.0, -1.0, 0.0, 2.0, -3.0]])
    x = np.concatenate([x, [1.0, 0.0, 0.0, -1.0, 2.0, -3.0]])
    y, x = np.append(y, [0.0, 0.0]), np.append(x, [0.0, -2.0])  # the origin, π
    at = np.array([compiled.atan2(a, b) for a, b in zip(y, x, strict=True)])
    assert np.abs(at - np.arctan2(y, x)).max() < 1e-10
    u = np.concatenate([rng.uniform(0, 1, 20000), [2.0**-53, 0.5, 0.7071067811865476, 1.0]])
    lg = np.array([compiled.log(v) for v in u])
    assert np.abs(lg - np.log(u)).max() < 1e-13
    z = np.concatenate([rng.uniform(-40.0, 5.0, 20000), [-32.0, -0.5, 0.0, 0.5, 1.0]])
    ex = np.array([compiled.exp2(v) for v in z])
    assert np.abs(ex / np.exp2(z) - 1.0).max() < 1e-13
