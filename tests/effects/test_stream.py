"""Effects on a track streamed in blocks of pings (``apply_effects_blocks``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sonar_raster.effects import chain
from sonar_raster.effects.along_track import kernel_sigma_pings
from sonar_raster.effects.chain import Effects, apply_effects, apply_effects_blocks
from sonar_raster.effects.presets import preset
from sonar_raster.image import SonarImage
from sonar_raster.sonar import BeamPattern, Sonar

SONAR = Sonar(
    max_range=30.0,
    range_bin=0.05,
    beam=BeamPattern.gaussian(50.0),
    tilt=math.radians(15.0),
    frequency_hz=600e3,
)
PINGS = 300


def _image() -> SonarImage:
    """Water before a first return that wanders by a few bins, a seabed of random level."""
    rng = np.random.default_rng(0)
    sides = {}
    for name in ("port", "starboard"):
        a = np.zeros((PINGS, SONAR.n_bins))
        first = 160 + (np.arange(PINGS) % 7)
        for i in range(PINGS):
            a[i, first[i] :] = rng.uniform(0.5, 1.5, SONAR.n_bins - first[i]) * 1e-3
        sides[name] = a.astype(np.float32)
    return SonarImage(sides, SONAR, {})


def _blocks(image: SonarImage, n: int):
    for a in range(0, PINGS, n):
        sides = {k: v[a : a + n] for k, v in image.sides.items()}
        yield SonarImage(sides, SONAR, {"first_ping": a})


def _joined(blocks) -> dict[str, np.ndarray]:
    out = list(blocks)
    assert [b.metadata["first_ping"] for b in out] == sorted(b.metadata["first_ping"] for b in out)
    return {k: np.concatenate([b.sides[k] for b in out]) for k in out[0].sides}


@pytest.mark.parametrize("block", [37, 64, PINGS])
def test_blocks_join_into_the_whole_images_effects(block):
    """Without random stages the streamed image is the whole one: the along-track beam sees
    the neighbouring blocks through the halo (without it: 20 % off at the block edges). Left:
    the FFT blur's ringing from pings beyond the halo, below 5e-4 of the peak."""
    image = _image()
    fx = Effects(
        along_beam_deg=1.5,
        water_column_db=-80.0,
        spreading=True,
        absorption=True,
        tvg="log",
        saturation=1e-3,
        bits=16,
    )
    whole = apply_effects(image, fx, ping_spacing=0.1)
    got = _joined(apply_effects_blocks(_blocks(image, block), fx, ping_spacing=0.1))
    for side, values in whole.sides.items():
        err = float(np.abs(got[side] - values).max() / values.max())
        assert err <= (0.0 if block == PINGS else 1e-3), (side, err)


def test_random_stages_keep_their_statistics_and_one_full_scale():
    image = _image()
    fx = preset("marine-sonic-600-max").effects()  # speckle, MAX recorder, noise, headroom
    whole = apply_effects(image, fx, ping_spacing=0.1, seed=1)
    blocks = list(apply_effects_blocks(_blocks(image, 64), fx, ping_spacing=0.1, seed=1))
    scales = {b.metadata["effects"]["full_scale"] for b in blocks}
    assert len(scales) == 1  # later blocks clip and quantise where the first block did
    assert scales.pop() == pytest.approx(whole.metadata["effects"]["full_scale"], rel=0.02)
    got = _joined(iter(blocks))
    for side, values in whole.sides.items():
        for lo in range(200, 600, 100):
            cut, ref = got[side][:, lo : lo + 100], values[:, lo : lo + 100]
            assert cut.mean() / ref.mean() == pytest.approx(1.0, abs=0.02)
            contrast = np.mean(cut.std(axis=0) / cut.mean(axis=0))
            assert contrast == pytest.approx(np.mean(ref.std(axis=0) / ref.mean(axis=0)), abs=0.03)
    assert {b.metadata["effects"]["stream_seed"] for b in blocks} == {1}
    again = _joined(apply_effects_blocks(_blocks(image, 64), fx, ping_spacing=0.1, seed=1))
    other = _joined(apply_effects_blocks(_blocks(image, 64), fx, ping_spacing=0.1, seed=2))
    assert np.array_equal(again["port"], got["port"]) and not np.array_equal(
        other["port"], got["port"]
    )


def test_the_halo_covers_the_widest_along_track_kernel():
    image = _image()
    fx = Effects(along_beam_deg=1.5)
    blocks = list(apply_effects_blocks(_blocks(image, 64), fx, ping_spacing=0.1))
    sigma = kernel_sigma_pings(SONAR.n_bins, SONAR.range_bin, 0.1, math.radians(1.5), None)
    assert blocks[0].metadata["effects"]["halo_pings"] >= chain.HALO_SIGMAS * sigma.max()
