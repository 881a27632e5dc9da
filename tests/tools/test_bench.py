"""The bench's memory trend: a slow leak must show, a one-off warm-up jump must not."""

import pytest

from crackgen.tools.bench import rss_trend_per_100


def test_trend_is_the_slope_of_the_second_half_per_100_samples():
    leak = [800.0 + 0.5 * i for i in range(40)]  # +0.5 MB per sample
    assert rss_trend_per_100(leak) == pytest.approx(50.0)


def test_early_jump_then_flat_has_no_trend():
    trace = [700.0] * 5 + [900.0] * 35  # allocator pools fill once, then stay
    assert rss_trend_per_100(trace) == pytest.approx(0.0, abs=1e-9)


def test_noise_around_a_flat_line_stays_near_zero():
    trace = [750.0 + (3.0 if i % 2 else -3.0) for i in range(200)]
    assert abs(rss_trend_per_100(trace)) < 0.5


def test_too_few_samples_give_no_trend():
    assert rss_trend_per_100([1.0] * 9) is None
    assert rss_trend_per_100([]) is None
