"""make_spec(..., attempt): attempt 0 is today's spec; a redraw re-keys the crack stream only."""
from __future__ import annotations

import numpy as np
import pytest

from crackgen.config.recipe import parse_recipe
from crackgen.config.spec import SECTION_STREAMS, make_spec, section_rng

RECIPE = parse_recipe("[dataset]\nseed = 11\n")


def test_attempt_zero_is_the_original_stream_exactly():
    for section, n in SECTION_STREAMS.items():
        seq = np.random.SeedSequence([11, 5], spawn_key=(n,))
        want = np.random.default_rng(seq).random(4)
        np.testing.assert_array_equal(section_rng(11, 5, section).random(4), want)
        np.testing.assert_array_equal(section_rng(11, 5, section, attempt=0).random(4), want)
    assert make_spec(RECIPE, 5, attempt=0).to_json() == make_spec(RECIPE, 5).to_json()


def test_redraw_changes_the_crack_only_and_is_deterministic():
    base = make_spec(RECIPE, 5).to_dict()
    seen = {base["crack"]["noise_seed"]}
    for attempt in (1, 2, 3):
        a = make_spec(RECIPE, 5, attempt=attempt).to_dict()
        assert a == make_spec(RECIPE, 5, attempt=attempt).to_dict()  # deterministic
        assert {k: v for k, v in a.items() if k != "crack"} == {k: v for k, v in base.items() if k != "crack"}
        assert a["crack"] != base["crack"]
        seen.add(a["crack"]["noise_seed"])
        seq = np.random.SeedSequence([11, 5], spawn_key=(SECTION_STREAMS["crack"], attempt))
        np.testing.assert_array_equal(section_rng(11, 5, "crack", attempt).random(3),
                                      np.random.default_rng(seq).random(3))
    assert len(seen) == 4
    # other sections ignore the attempt
    np.testing.assert_array_equal(section_rng(11, 5, "camera", 2).random(3), section_rng(11, 5, "camera").random(3))


def test_negative_attempt_is_refused():
    with pytest.raises(ValueError, match="attempt"):
        section_rng(11, 5, "crack", -1)
