"""Appearance adaptation: exact spectral/statistical properties on hand-made images."""
import numpy as np
import pytest

from crackgen.postrender.adapt import (
    AdaptError,
    adapt_views,
    band_halfwidth,
    fit_reinhard,
    fourier_adapt,
    low_frequency_window,
    to_lab,
)


def _img(rng, h=64, w=80, lo=40, hi=200):
    return rng.integers(lo, hi, size=(h, w, 3)).astype(np.uint8)


def _spectrum(x):
    return np.fft.fftshift(np.fft.fft2(x.astype(np.float64), axes=(0, 1)), axes=(0, 1))


def test_fourier_zero_band_is_identity():
    rng = np.random.default_rng(0)
    src, tgt = _img(rng), _img(rng)
    assert np.array_equal(fourier_adapt(src, tgt, 0.0), src.astype(np.float32))
    assert np.array_equal(adapt_views([src], tgt, "fourier", 0.0)[0], src)


@pytest.mark.parametrize("shape", [(64, 80, 3), (63, 81, 3)])
def test_fourier_swaps_low_amplitude_and_keeps_phase(shape):
    rng = np.random.default_rng(1)
    src = rng.random(shape) * 255
    tgt = rng.random(shape) * 120 + 60
    band = 0.05
    out = fourier_adapt(src, tgt, band).astype(np.float64)
    fo, fs, ft = _spectrum(out), _spectrum(src), _spectrum(tgt)
    win = low_frequency_window(shape, band_halfwidth(shape, band))
    assert band_halfwidth(shape, band) == 3
    # low band: the target's amplitude; everywhere else: the source's amplitude
    np.testing.assert_allclose(np.abs(fo)[win], np.abs(ft)[win], rtol=1e-4, atol=1e-2)
    outside = np.ones(shape, bool)
    outside[win] = False
    np.testing.assert_allclose(np.abs(fo)[outside], np.abs(fs)[outside], rtol=1e-4, atol=1e-2)
    # phase is the source's wherever the spectrum is not ~0
    ok = np.abs(fs) > 1.0
    dphi = np.angle(fo[ok] * np.conj(fs[ok]))
    assert np.max(np.abs(dphi)) < 1e-3
    # the band includes DC, so mean brightness moves to the target's
    assert abs(out.mean() - tgt.mean()) < 1e-3 * 255


def test_reinhard_matches_target_lab_mean_and_std():
    # hand-made: a dull greenish gradient source, a warm contrasty target
    yy, xx = np.mgrid[0:48, 0:64]
    src = np.stack([60 + xx, 90 + yy, 70 + (xx + yy) // 4], -1).astype(np.uint8)
    tgt = np.stack([120 + (xx % 16) * 4, 100 + (yy % 12) * 3, 80 + ((xx + yy) % 10) * 2], -1).astype(np.uint8)
    fit = fit_reinhard(src, tgt)
    lab = fit.apply_lab(to_lab(src)).reshape(-1, 3)
    lt = to_lab(tgt).reshape(-1, 3)
    np.testing.assert_allclose(lab.mean(0), lt.mean(0), atol=1e-3)
    np.testing.assert_allclose(lab.std(0), lt.std(0), rtol=1e-4)
    # end to end through uint8 RGB: within rounding/gamut of the target's statistics
    out = to_lab(adapt_views([src], tgt, "reinhard")[0]).reshape(-1, 3)
    np.testing.assert_allclose(out.mean(0), lt.mean(0), atol=1.0)
    np.testing.assert_allclose(out.std(0), lt.std(0), atol=1.0)


def test_histogram_matching_matches_target_cdf():
    rng = np.random.default_rng(2)
    src = rng.integers(0, 256, size=(64, 64, 3)).astype(np.uint8)
    tgt = np.clip(rng.normal(90, 20, size=(64, 64, 3)), 0, 255).astype(np.uint8)
    out = adapt_views([src], tgt, "histogram")[0]
    for c in range(3):
        q = [5, 25, 50, 75, 95]
        np.testing.assert_allclose(np.percentile(out[..., c], q), np.percentile(tgt[..., c], q), atol=3)


@pytest.mark.parametrize("method", ["fourier", "reinhard", "histogram"])
def test_left_and_right_views_get_the_same_transform(method):
    rng = np.random.default_rng(3)
    left, tgt = _img(rng), _img(rng, lo=0, hi=120)
    right = left.copy()
    out_l, out_r = adapt_views([left, right], tgt, method, 0.03)
    assert np.array_equal(out_l, out_r)
    # and the transform fitted on the left acts on a different right view identically per pixel
    if method != "fourier":
        other = _img(rng)
        a = adapt_views([left, other], tgt, method)[1]
        b = adapt_views([left, left], tgt, method)[1]
        assert not np.array_equal(a, b)


def test_inputs_untouched_and_bad_input_named():
    rng = np.random.default_rng(4)
    src, tgt = _img(rng), _img(rng)
    before = src.copy()
    adapt_views([src], tgt, "reinhard")
    assert np.array_equal(src, before)
    with pytest.raises(AdaptError, match="unknown adaptation method 'fda'"):
        adapt_views([src], tgt, "fda")
    with pytest.raises(AdaptError, match="target photo"):
        adapt_views([src], tgt[..., 0], "reinhard")
