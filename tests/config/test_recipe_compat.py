"""Resuming across crackgen versions: new fields at their defaults pass, every other difference is named."""
import pytest

from crackgen.config.recipe import Recipe, RecipeError, parse_recipe
from crackgen.config.recipe_compat import canonical, resume_check, resume_differences, stored_canonical_from_text

TEXT = """
[dataset]
name = "c"
seed = 3
samples = 4
[stereo]
enabled = true
"""


def _without(tree, dotted):
    out = {k: (dict(v) if isinstance(v, dict) else v) for k, v in tree.items()}
    section, key = dotted.split(".")
    del out[section][key]
    return out


def test_a_field_added_since_at_its_default_resumes_and_is_named():
    recipe = parse_recipe(TEXT)
    older = _without(canonical(recipe), "stereo.sgbm_input")  # what a crackgen before the field stored
    note = resume_check(older, TEXT, recipe)
    assert "stereo.sgbm_input" in note and "older manifest" not in note
    blocking, added = resume_differences(older, canonical(recipe), canonical(Recipe()))
    assert blocking == [] and added == ["stereo.sgbm_input"]


def test_new_field_off_its_default_a_changed_value_and_a_removed_field_are_refused():
    recipe = parse_recipe(TEXT)
    now, dflt = canonical(recipe), canonical(Recipe())
    older = _without(canonical(parse_recipe(TEXT + 'sgbm_input = "clean"\n')), "stereo.sgbm_input")
    camera = parse_recipe(TEXT + 'sgbm_input = "camera"\n[camera_effects]\nenabled = true\n')
    blocking, _ = resume_differences(older, canonical(camera), dflt)
    assert any("stereo.sgbm_input = 'camera' is new and not its default 'clean'" in b for b in blocking)
    changed = {**now, "dataset": {**now["dataset"], "seed": 4}}
    with pytest.raises(RecipeError, match=r"dataset.seed: 4 -> 3"):
        resume_check(changed, TEXT, recipe)
    gone = {**now, "stereo": {**now["stereo"], "old_knob": 1}}
    assert resume_differences(gone, now, dflt)[0] == ["stereo.old_knob is no longer a recipe field (was 1)"]
    # a default that changed between versions is a changed value, caught from the stored canonical recipe
    spp = {**now, "render": {**now["render"], "samples": now["render"]["samples"] + 1}}
    with pytest.raises(RecipeError, match="render.samples"):
        resume_check(spp, TEXT, recipe)


def test_older_manifests_are_compared_by_their_text_with_the_samples_note():
    noted = "# crackgen generate --samples 9 (overrides dataset.samples)\n" + TEXT
    assert stored_canonical_from_text(noted)["dataset"]["samples"] == 9
    nine = parse_recipe(TEXT).model_copy(update={"dataset": parse_recipe(TEXT).dataset.model_copy(update={"samples": 9})})
    assert "older manifest" in resume_check(None, noted, nine)
    with pytest.raises(RecipeError, match="dataset.samples: 9 -> 4"):
        resume_check(None, noted, parse_recipe(TEXT))
    with pytest.raises(RecipeError, match="no longer reads"):
        resume_check(None, "[dataset]\nbogus_field = 1\n", parse_recipe(TEXT))
