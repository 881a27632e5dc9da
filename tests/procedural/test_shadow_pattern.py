"""Shadow occluder alpha pattern: coverage, softness, determinism, errors (pure numpy)."""
import numpy as np
import pytest

from crackgen.config.spec import ShadowSpec
from crackgen.procedural.shadow_pattern import PATTERNS, ShadowPatternError, shadow_alpha


def spec(**kw) -> ShadowSpec:
    base = dict(enabled=True, pattern="noise", seed=7, light_index=0, height_m=0.5, size_m=1.5,
                coverage=0.4, softness=0.0, offset_x_m=0.0, offset_y_m=0.0)
    base.update(kw)
    return ShadowSpec(**base)


@pytest.mark.parametrize("pattern", PATTERNS)
@pytest.mark.parametrize("coverage", [0.2, 0.5, 0.8])
def test_hard_pattern_hits_requested_coverage(pattern, coverage):
    a = shadow_alpha(spec(pattern=pattern, coverage=coverage), 128)
    assert a.shape == (128, 128) and a.dtype == np.float32
    assert set(np.unique(a)) <= {0.0, 1.0}  # softness 0: binary
    if pattern == "shapes":  # shapes are added until the target is passed: overshoot by < one shape
        assert coverage <= a.mean() < coverage + 0.12
    else:
        assert abs(a.mean() - coverage) < 0.03


@pytest.mark.parametrize("pattern", PATTERNS)
def test_softness_blurs_edges_but_keeps_coverage(pattern):
    hard = shadow_alpha(spec(pattern=pattern, softness=0.0), 128)
    soft = shadow_alpha(spec(pattern=pattern, softness=0.03), 128)
    partial = lambda a: ((a > 0.02) & (a < 0.98)).mean()  # noqa: E731
    assert partial(hard) == 0.0 and partial(soft) > 0.05
    assert abs(soft.mean() - hard.mean()) < 0.03
    assert soft.min() >= 0.0 and soft.max() <= 1.0


def test_pattern_is_a_function_of_the_seed():
    a = shadow_alpha(spec(seed=3), 64)
    np.testing.assert_array_equal(a, shadow_alpha(spec(seed=3), 64))
    assert not np.array_equal(a, shadow_alpha(spec(seed=4), 64))


def test_extreme_coverage():
    assert shadow_alpha(spec(coverage=0.0), 32).max() == 0.0
    assert shadow_alpha(spec(coverage=1.0), 32).min() == 1.0


def test_bad_spec_is_named():
    with pytest.raises(ShadowPatternError, match="shadow.pattern"):
        shadow_alpha(spec(pattern="dots"))
    with pytest.raises(ShadowPatternError, match="shadow.coverage"):
        shadow_alpha(spec(coverage=1.5))
    with pytest.raises(ShadowPatternError, match="px"):
        shadow_alpha(spec(), 4)
