"""The recorder's downsampling (XTF DownsampleMethod MAX / RMS) and K texture below the bin.

Each statistic is checked against a closed form or an independent implementation: the looks a
recorder makes by keeping the largest (or the mean) of n sub-samples per recorded bin follow
from the pulse's resolution and the bin size alone.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sonar_raster.effects import speckle as speckle_module
from sonar_raster.effects.chain import Effects, apply_effects, subsamples_per_bin
from sonar_raster.effects.presets import preset
from sonar_raster.effects.speckle import downsampled_mean, recorded_speckle_field
from sonar_raster.errors import SonarRasterError
from sonar_raster.image import SonarImage
from sonar_raster.sonar import Sonar

FWHM = 2.0 * math.sqrt(2.0 * math.log(2.0))


def field(n: int, sigma_fine: float, how: str, shape=(200, 1000), nu=None, seed=1) -> np.ndarray:
    ss = np.random.SeedSequence(seed)
    return recorded_speckle_field(shape, ss, np.zeros(shape[1]), sigma_fine, n, how, nu)


def contrast(x: np.ndarray) -> float:
    return float(x.std() / x.mean())


def lag1_range(x: np.ndarray) -> float:
    return float(np.corrcoef(x[:, :-1].ravel(), x[:, 1:].ravel())[0, 1])


# -- one-point laws against closed forms -------------------------------------------------------
@pytest.mark.parametrize("n", [2, 3, 5])
def test_max_of_independent_subsamples_has_the_order_statistic_contrast(n):
    """Max of n independent unit-mean exponentials: mean H_n, variance Σ 1/k² (Rényi)."""
    k = np.arange(1, n + 1)
    mean, var = float(np.sum(1.0 / k)), float(np.sum(1.0 / k**2))
    x = field(n, 0.0, "max")
    assert x.mean() == pytest.approx(1.0, abs=0.01)
    assert contrast(x) == pytest.approx(math.sqrt(var) / mean, abs=0.01)
    assert downsampled_mean(n, 0.0, "max") == pytest.approx(mean, rel=0.005)
    assert abs(lag1_range(x)) < 0.01  # independent sub-samples: independent bins


def test_a_coarse_bin_of_thousands_of_subsamples_keeps_to_its_memory(monkeypatch):
    """One recorded bin of 3200 sub-samples (a 20 m bin of the Marine Sonic's recorder): the
    normalising Monte Carlo and the field draw at most 2**24 sub-samples at once (they drew
    64 x 4096 x 3200 = 839 M), and stay right."""
    from sonar_raster.effects import speckle

    drawn = []
    fine = speckle._fine_field

    def counted(entropy, pings, columns, n, *rest):
        drawn.append(pings * (columns[1] - columns[0]) * n)
        return fine(entropy, pings, columns, n, *rest)

    monkeypatch.setattr(speckle, "_fine_field", counted)
    n = 3200
    mean = float(np.sum(1.0 / np.arange(1, n + 1)))  # E max of n independent exponentials
    assert downsampled_mean(n, 0.0, "max") == pytest.approx(mean, rel=0.01)
    x = recorded_speckle_field((100, 60), np.random.SeedSequence(1), 0.5, 0.0, n, "max")
    assert x.shape == (100, 60) and x.mean() == pytest.approx(1.0, abs=0.03)
    assert drawn and max(drawn) <= 1 << 24


@pytest.mark.parametrize("n", [2, 4])
def test_mean_of_independent_subsamples_is_n_look_speckle(n):
    x = field(n, 0.0, "mean")
    assert x.mean() == pytest.approx(1.0, abs=0.01)
    assert contrast(x) == pytest.approx(1.0 / math.sqrt(n), abs=0.01)


def independent_max(n: int, res_bins: float, bins: int = 40_000, seed: int = 5):
    """Second implementation: a 1-D complex Gaussian process on a 16-times finer grid, FFT
    filtered by the amplitude kernel, squared, maximum over each recorded bin's n sub-samples
    (the sub-samples taken at every 16/n-th fine point)."""
    fine_per_bin = 16 * n
    sig_amp = math.sqrt(2.0) * res_bins * fine_per_bin / FWHM
    m = bins * fine_per_bin
    rng = np.random.default_rng(seed)
    f = np.fft.rfftfreq(m)
    h = np.exp(-2.0 * math.pi**2 * sig_amp**2 * f**2)
    re = np.fft.irfft(np.fft.rfft(rng.standard_normal(m)) * h, m)
    im = np.fft.irfft(np.fft.rfft(rng.standard_normal(m)) * h, m)
    inten = (re * re + im * im).reshape(bins, n, 16)[:, :, 8]
    x = inten.max(axis=1)
    return x / x.mean()


def test_marine_sonic_looks_follow_its_pulse_and_bin():
    """The -max preset's 10-cycle pulse (1.25 cm) and 2.93 cm bins: 5 sub-samples of ρ/2, MAX;
    the recorded speckle's contrast and bin-to-bin correlation follow from those alone and
    agree with an independent 1-D implementation."""
    p = preset("marine-sonic-600-max")
    fx = p.effects()
    bin_m = p.sonar().range_bin
    n = subsamples_per_bin(fx, bin_m)
    assert fx.downsample == "max"
    assert p.range_resolution_m == pytest.approx(1500.0 * 10 / 600e3 / 2)
    assert n == round(bin_m / (p.range_resolution_m / 2)) == 5
    res_bins = p.range_resolution_m / bin_m
    x = field(n, res_bins * n / FWHM, "max", shape=(400, 1024))
    y = independent_max(n, res_bins)
    assert contrast(x) == pytest.approx(contrast(y), abs=0.015)
    assert lag1_range(x) == pytest.approx(float(np.corrcoef(y[:-1], y[1:])[0, 1]), abs=0.02)
    assert 0.6 < contrast(x) < 0.75  # several looks: well below single-look speckle's 1


def test_a_pulse_as_long_as_the_bin_gives_fewer_looks():
    """Max over sub-samples of one resolution cell: correlated, so contrast stays nearer 1
    and neighbouring bins correlate more than with the short pulse."""
    short = field(5, 0.4 * 5 / FWHM, "max")
    long = field(2, 1.0 * 2 / FWHM, "max")
    assert contrast(long) > contrast(short) + 0.1
    assert lag1_range(long) > lag1_range(short) + 0.1


def test_looks_of_the_subsamples_add_to_those_of_the_recorder():
    """Mean of n independent L-look sub-samples: n L looks, contrast 1 / sqrt(n L)."""
    ss = np.random.SeedSequence(6)
    x = recorded_speckle_field((200, 1000), ss, np.zeros(1000), 0.0, 2, "mean", None, 2.5)
    assert x.mean() == pytest.approx(1.0, abs=0.01)
    assert contrast(x) == pytest.approx(1.0 / math.sqrt(5.0), abs=0.01)


# -- K texture below the bin ---------------------------------------------------------------------
@pytest.mark.parametrize("nu", [1.0, 4.0])
def test_k_shape_is_recovered_from_a_simulated_patch(nu):
    """Mean of n independent K(ν) sub-samples: contrast² = (1 + 2/ν) / n, so
    ν̂ = 2 / (n c² - 1) recovers the shape."""
    n = 3
    x = field(n, 0.0, "mean", shape=(400, 1000), nu=nu, seed=3)
    c2 = contrast(x) ** 2
    assert x.mean() == pytest.approx(1.0, abs=0.02)
    assert 2.0 / (n * c2 - 1.0) == pytest.approx(nu, rel=0.15)


def test_k_texture_under_max_keeps_unit_mean_and_heavier_tail():
    plain = field(5, 0.4 * 5 / FWHM, "max", shape=(300, 1000))
    textured = field(5, 0.4 * 5 / FWHM, "max", shape=(300, 1000), nu=2.0)
    assert textured.mean() == pytest.approx(1.0, abs=0.02)
    assert np.quantile(textured, 0.999) > 1.5 * np.quantile(plain, 0.999)


# -- the chain -----------------------------------------------------------------------------------
def image(pings: int = 300, bins: int = 512, bin_m: float = 0.03) -> SonarImage:
    sonar = Sonar(max_range=bins * bin_m, range_bin=bin_m)
    data = np.ones((pings, bins), np.float32)
    return SonarImage({"port": data, "starboard": data.copy()}, sonar, {})


def test_the_chain_downsamples_speckle_and_noise():
    fx = Effects(
        speckle="exponential", range_resolution_m=0.0125, downsample="max", sample_spacing_m=0.00625
    )
    out = apply_effects(image(), fx, seed=4).sides["port"].astype(np.float64)
    ref = field(5, 0.0125 * 5 / (FWHM * 0.03), "max", shape=(300, 512))
    assert out.mean() == pytest.approx(1.0, abs=0.02)
    assert contrast(out) == pytest.approx(contrast(ref), abs=0.02)
    zero = SonarImage({"port": np.zeros((300, 512), np.float32)}, image().sonar, {})
    noise = apply_effects(
        zero,
        Effects(
            noise_db=0.0, range_resolution_m=0.0125, downsample="max", sample_spacing_m=0.00625
        ),
        seed=4,
    )
    n = noise.sides["port"].astype(np.float64)
    assert n.mean() == pytest.approx(1.0, abs=0.02)  # the noise level is kept
    assert contrast(n) == pytest.approx(contrast(ref), abs=0.03)  # and has the recorder's law
    again = apply_effects(image(), fx, seed=4).sides["port"]
    assert np.array_equal(again, apply_effects(image(), fx, seed=4).sides["port"])


def test_blocks_join_without_seams(monkeypatch):
    """Each recorded column draws its own noise stream: the field does not depend on the block
    size it is made in (bit for bit), so block edges are invisible."""
    a = field(5, 0.4 * 5 / FWHM, "max", shape=(50, 300), nu=2.0)
    monkeypatch.setattr(speckle_module, "_BLOCK_BINS", 37)
    b = field(5, 0.4 * 5 / FWHM, "max", shape=(50, 300), nu=2.0)
    assert np.array_equal(a, b)


def test_downsampling_off_or_one_subsample_keeps_the_old_field():
    base = Effects(speckle="exponential", range_resolution_m=0.03)
    one = Effects(
        speckle="exponential", range_resolution_m=0.03, downsample="max", sample_spacing_m=0.03
    )
    a = apply_effects(image(50, 64), base, seed=2).sides["port"]
    b = apply_effects(image(50, 64), one, seed=2).sides["port"]
    assert np.array_equal(a, b)


def test_bad_downsample_settings_are_refused():
    with pytest.raises(SonarRasterError, match="downsample"):
        Effects(downsample="median")
    with pytest.raises(SonarRasterError, match="sample_spacing_m"):
        Effects(downsample="max", sample_spacing_m=-1.0)


def test_a_scene_table_sets_the_recorder():
    fx = Effects.from_table(
        {"speckle": "exponential", "downsample": "mean", "sample_spacing_m": 0.01}
    )
    assert (fx.downsample, fx.sample_spacing_m) == ("mean", 0.01)
    assert subsamples_per_bin(fx, 0.05) == 5 and subsamples_per_bin(fx, 0.004) == 1
    assert subsamples_per_bin(Effects(sample_spacing_m=0.01), 0.05) == 1  # off: one per bin


def test_a_coarse_bin_s_speckle_is_drawn_in_bounded_memory():
    """112 sub-samples a bin (a 0.7 m bin of the default 6.25 mm recorder): the speckle's mean
    and a small image's field each peaked at 0.8 GB of arrays when drawn at once; in blocks of
    2**21 sub-samples they stay near 0.1 GB, with the same values (each column its own stream)."""
    import tracemalloc

    downsampled_mean.cache_clear()
    tracemalloc.start()
    try:
        mean = downsampled_mean(112, 0.0, "max")
        _, mean_peak = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        field = recorded_speckle_field(
            (3000, 8), np.random.SeedSequence(2), np.full(8, 0.7), 1.2, 112, "max"
        )
        _, field_peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert mean_peak < 250e6 and field_peak < 250e6, (mean_peak, field_peak)
    harmonic = float(np.sum(1.0 / np.arange(1, 113)))  # E[max] of 112 independent exponentials
    assert mean == pytest.approx(harmonic, rel=0.005)
    assert field.mean() == pytest.approx(1.0, rel=0.05)
