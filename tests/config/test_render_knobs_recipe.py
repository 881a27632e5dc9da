"""[render] speed knobs in the recipe: defaults, one-line errors, old sample JSON still loads."""
from __future__ import annotations

import json

import pytest

from crackgen.config.recipe import Recipe, RecipeError, parse_recipe
from crackgen.config.spec import RENDER_KNOBS, SampleSpec, make_spec


def test_knobs_reach_the_sample_spec():
    r = parse_recipe("[render]\nadaptive_threshold = 0.05\ndenoise_prefilter = \"fast\"\nlight_tree = false\n")
    spec = make_spec(r, 3)
    assert (spec.render.adaptive_threshold, spec.render.denoise_prefilter, spec.render.light_tree) == (0.05, "fast", False)
    assert set(RENDER_KNOBS) <= set(Recipe().render.model_dump())


@pytest.mark.parametrize("line,problem", [
    ('denoise_prefilter = "slow"', "render.denoise_prefilter: Input should be 'none', 'fast' or 'accurate'"),
    ('denoise_passes = "albedo"', "render.denoise_passes: Input should be"),
    ("diffuse_bounces = -1", "render.diffuse_bounces: Input should be greater than or equal to 0"),
    ("adaptive_threshold = 2.0", "render.adaptive_threshold: Input should be less than or equal to 1"),
    ("clamp_indirect = nan", "render.clamp_indirect: must be a finite number"),
    ("light_tree = 3", "render.light_tree: Input should be a valid boolean"),
    ("caustic = false", "render.caustic: unknown key"),
])
def test_bad_knob_is_one_line_naming_the_field(line, problem):
    with pytest.raises(RecipeError) as exc:
        parse_recipe(f"[render]\n{line}\n")
    assert len(exc.value.problems) == 1
    assert exc.value.problems[0].startswith(problem)


def test_sample_json_written_before_the_knobs_still_loads_with_the_factory_values():
    d = make_spec(Recipe(), 0).to_dict()
    for k in RENDER_KNOBS:
        del d["render"][k]
    spec = SampleSpec.from_json(json.dumps(d))
    assert spec.render == make_spec(Recipe(), 0).render  # the defaults are the values a default recipe draws
