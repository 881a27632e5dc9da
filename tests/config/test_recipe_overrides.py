"""`--set KEY=VALUE`: typed TOML values, the text edited in place, schema errors named."""
import pytest

from crackgen.config.recipe import RecipeError, load_recipe, parse_recipe
from crackgen.config.recipe_overrides import apply_sets, override_text, parse_set

REPO = __import__("pathlib").Path(__file__).resolve().parents[2]
CLOSEUP = REPO / "recipes" / "closeup.toml"


@pytest.mark.parametrize("arg, key, value", [
    ("render.samples=8", "render.samples", 8),
    ("render.denoise=false", "render.denoise", False),
    ("crack.probability=0.5", "crack.probability", 0.5),
    ("crack.shape=fbm", "crack.shape", "fbm"),
    ('crack.shape="fbm"', "crack.shape", "fbm"),
    ("camera.distance_m={ min = 0.6, max = 1.2 }", "camera.distance_m", {"min": 0.6, "max": 1.2}),
    ('material.family={ choices = ["asphalt"] }', "material.family", {"choices": ["asphalt"]}),
])
def test_parse_set_types_values_as_toml(arg, key, value):
    assert parse_set(arg) == (key, value)


@pytest.mark.parametrize("arg", ["render", "render.samples=", "=8", "render..samples=8", "crack.shape={min=1"])
def test_parse_set_refuses_malformed_arguments_in_one_line(arg):
    with pytest.raises(RecipeError) as exc:
        parse_set(arg)
    assert len(exc.value.problems) == 1 and "--set" in exc.value.problems[0]


def test_override_edits_only_the_named_lines_and_keeps_comments():
    text = CLOSEUP.read_text()
    new = override_text(text, [("crack.shape", "fbm"), ("camera.distance_m", {"min": 0.6, "max": 1.2})])
    old_lines, new_lines = text.splitlines(), new.splitlines()
    assert new_lines[0].startswith("# crackgen --set crack.shape=")
    changed = [(a, b) for a, b in zip(old_lines, new_lines[1:]) if a != b]
    assert len(new_lines) == len(old_lines) + 1 and len(changed) == 2
    assert all("#" in b for _, b in changed)  # the field's own comment survives
    r = parse_recipe(new)
    assert r.crack.shape.value == "fbm" and (r.camera.distance_m.min, r.camera.distance_m.max) == (0.6, 1.2)


def test_apply_sets_changes_the_recipe_and_its_hash_and_nothing_else():
    base = load_recipe(CLOSEUP)
    out = apply_sets(base, ["material.clutter.pores=0", "render.samples=4"])
    assert out.material.clutter.pores == 0 and out.render.samples == 4
    assert out.hash != base.hash and parse_recipe(out.text).hash == out.hash  # workers parse the same recipe
    same = out.model_copy(update={"material": base.material, "render": base.render})
    assert same.model_dump() == base.model_dump()
    assert apply_sets(base, []) is base


def test_apply_sets_adds_missing_tables_and_keys():
    base = parse_recipe("[dataset]\nsamples = 4\n")
    out = apply_sets(base, ["material.clutter.voids=0.5", "label.policy=thesis"])
    assert out.material.clutter.voids == 0.5 and out.label.policy == "thesis" and out.dataset.samples == 4


@pytest.mark.parametrize("arg, named", [
    ("crack.shapez=fbm", "crack.shapez"),
    ("crack.shape=blob", "crack.shape"),
    ("render.samples=abc", "render.samples"),
    ("nosuch.key=1", "nosuch"),
])
def test_apply_sets_schema_errors_name_the_field(arg, named):
    with pytest.raises(RecipeError) as exc:
        apply_sets(load_recipe(CLOSEUP), [arg])
    assert any(p.startswith(named) for p in exc.value.problems)
