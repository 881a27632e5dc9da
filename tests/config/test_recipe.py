"""Recipe validation: defaults, field-named errors, distributions, property tests."""
import math
import string

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from crackgen.config.recipe import Dist, Recipe, RecipeError, load_recipe, parse_recipe

REPO = __import__("pathlib").Path(__file__).resolve().parents[2]


def problems(text: str) -> list[str]:
    with pytest.raises(RecipeError) as exc:
        parse_recipe(text)
    return exc.value.problems


def test_empty_recipe_is_all_defaults():
    r = parse_recipe("")
    assert r == Recipe()
    assert r.num_shards == math.ceil(r.dataset.samples / r.dataset.shard_size)


def test_required_recipes_are_shipped():
    assert {"demo.toml", "roads.toml"} <= {p.name for p in (REPO / "recipes").glob("*.toml")}


@pytest.mark.parametrize("path", sorted((REPO / "recipes").glob("*.toml")), ids=lambda p: p.name)
def test_shipped_recipes_validate(path):
    r = load_recipe(path)
    assert r.text == path.read_text()


def test_roads_is_thesis_scale():
    r = load_recipe(REPO / "recipes" / "roads.toml")
    assert r.dataset.samples == 10_000
    assert min(r.camera.width_px, r.camera.height_px) >= 512


@pytest.mark.parametrize(
    "text, expected",
    [
        ("[crack]\nthreshold = {min = 0.2, max = 0.1}", "crack.threshold.max: must be > crack.threshold.min"),
        ("[crack]\nthresold = 0.1", "crack.thresold: unknown key"),
        ("[crak]\nthreshold = 0.1", "crak: unknown key"),
        ("[crack.threshold]\nmin = 0.1\nmax = 0.2\nstep = 3", "crack.threshold.step: unknown key"),
        ("[crack]\nthreshold = {min = 0.1}", "crack.threshold.max: required with a range"),
        ("[crack]\nthreshold = 2.0", "crack.threshold: must be within (0, 1]"),
        ("[crack]\noctaves = 2.5", "crack.octaves: must be an integer"),
        ("[material]\nfamily = 'wood'", "material.family: unknown value 'wood'"),
        ("[lights]\nkind = {choices = ['sun'], weights = [1, 2]}", "lights.kind.weights: must have one weight per choice"),
        ("[lidar]\nvfov_min_deg = 10\nvfov_max_deg = 5", "lidar.vfov_max_deg: must be > lidar.vfov_min_deg"),
        ("[stereo]\nblock_size = 4", "stereo.block_size: must be odd"),
        ("[stereo]\nenabled = true\nnum_disparities = 128\n[camera]\nwidth_px = 128",
         "stereo.num_disparities: must be less than camera.width_px"),
        ("[render]\ndevice = 'tpu'", "render.device:"),
        ("[dataset]\nsamples = 0", "dataset.samples:"),
        ("this is = = not toml", "not valid TOML"),
    ],
)
def test_bad_recipes_name_the_field(text, expected):
    lines = problems(text)
    assert any(expected in line for line in lines), lines


@pytest.mark.parametrize("bad", ["nan", "inf", "-inf"])
@pytest.mark.parametrize(
    "template, where",
    [
        ("[crack]\nthreshold = {v}", "crack.threshold"),  # constant distribution
        ("[crack]\ndepth_m = {v}", "crack.depth_m"),
        ("[camera]\ntilt_deg = {v}", "camera.tilt_deg"),
        ("[camera]\ntilt_deg = {{min = {v}, max = 10}}", "camera.tilt_deg.min"),
        ("[crack]\nthreshold = {{min = 0.01, max = {v}}}", "crack.threshold.max"),
        ("[crack]\nthreshold = {{choices = [0.02, {v}]}}", "crack.threshold.choices"),
        ("[crack]\noctaves = {{choices = [4, {v}]}}", "crack.octaves.choices"),  # integer parameter
        ("[material]\nfamily = {{choices = ['asphalt', 'steel'], weights = [1, {v}]}}", "material.family.weights"),
        ("[shadow]\nprobability = {v}", "shadow.probability"),  # plain float fields
        ("[tof]\nsigma0_m = {v}", "tof.sigma0_m"),
        ("[tof]\nhfov_deg = {v}", "tof.hfov_deg"),
        ("[lidar]\nmax_range_m = {v}", "lidar.max_range_m"),
        ("[camera]\nsensor_width_mm = {v}", "camera.sensor_width_mm"),
        ("[material.distractors]\nstain = {v}", "material.distractors.stain"),
        ("[dataset]\nsamples = {v}", "dataset.samples"),  # plain int field
    ],
)
def test_non_finite_numbers_are_refused_naming_the_field(template, where, bad):
    lines = problems(template.format(v=bad))
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"{where}: ") and "must be a finite number, got" in lines[0], lines
    assert lines[0].endswith(f"got {bad}"), lines


def test_every_float_field_refuses_nan():
    # Walk the schema so a new float field (distribution or plain) cannot slip past the finite check.
    from pydantic import BaseModel

    def walk(model: BaseModel, prefix: list[str]):
        for name in type(model).model_fields:
            sub = getattr(model, name)
            if isinstance(sub, BaseModel) and not isinstance(sub, Dist):
                yield from walk(sub, prefix + [name])
            elif isinstance(sub, Dist) and any(isinstance(v, (int, float)) and not isinstance(v, bool) for v in sub.support()):
                yield prefix + [name]
            elif isinstance(sub, float):
                yield prefix + [name]

    paths = list(walk(Recipe(), []))
    assert len(paths) > 40
    for path in paths:
        *sections, key = path
        lines = problems(f"[{'.'.join(sections)}]\n{key} = nan\n")
        assert lines == [f"{'.'.join(path)}: must be a finite number, got nan"], lines


def test_validate_cli_refuses_nan(tmp_path, capsys):
    from crackgen.tools.cli import main

    path = tmp_path / "nan.toml"
    path.write_text("[crack]\nthreshold = nan\n")
    assert main(["validate", str(path)]) != 0
    assert capsys.readouterr().err.strip() == "crack.threshold: must be a finite number, got nan"


def test_search_range_is_checked_only_with_stereo_on():
    assert parse_recipe("[stereo]\nnum_disparities = 128\n[camera]\nwidth_px = 64").stereo.enabled is False
    assert parse_recipe("[stereo]\nenabled = true\nnum_disparities = 112\n[camera]\nwidth_px = 128").stereo.enabled


def test_every_problem_is_reported_once_per_line():
    lines = problems("[crack]\nthresold = 1\n[camera]\ntilt_deg = 200\n")
    assert len(lines) == 2
    assert all("\n" not in line for line in lines)


def test_missing_file_is_one_line(tmp_path):
    with pytest.raises(RecipeError) as exc:
        load_recipe(tmp_path / "nope.toml")
    assert exc.value.problems == [f"{tmp_path / 'nope.toml'}: recipe file not found"]


def test_every_field_is_documented_with_default():
    from pydantic import BaseModel

    def walk(model):
        for name, info in type(model).model_fields.items():
            sub = getattr(model, name)
            is_section = isinstance(sub, BaseModel) and not isinstance(sub, Dist)
            assert info.description or is_section, name
            if is_section:
                walk(sub)

    walk(Recipe())


def test_choice_draw_follows_weights():
    d = Dist.model_validate({"choices": ["a", "b"], "weights": [1, 3]})
    rng = np.random.default_rng(0)
    draws = [d.draw(rng) for _ in range(4000)]
    assert abs(draws.count("b") / 4000 - 0.75) < 0.03


def test_uniform_draw_in_range_and_consumes_one_number():
    d = Dist.model_validate({"min": 2.0, "max": 3.0})
    a, b = np.random.default_rng(1), np.random.default_rng(1)
    x = [d.draw(a) for _ in range(100)]
    assert all(2.0 <= v < 3.0 for v in x)
    Dist.model_validate(5.0).draw(b)  # constants consume a number too, so layouts stay stable
    assert a.random() == pytest.approx(np.random.default_rng(1).random(101)[-1])
    assert b.random() == pytest.approx(np.random.default_rng(1).random(2)[-1])


# ---- property tests ---------------------------------------------------------------------------

# (section, field, lo, hi) for numeric distribution fields with finite closed ranges
NUMERIC = [
    ("crack", "threshold", 0.001, 1.0),
    ("crack", "depth_m", 0.0, 0.2),
    ("camera", "tilt_deg", 0.0, 80.0),
    ("camera", "distance_m", 0.05, 100.0),
    ("lights", "elevation_deg", 1.0, 90.0),
    ("shadow", "coverage", 0.0, 1.0),
    ("tof", "bias_m", -1.0, 1.0),
]

finite = dict(allow_nan=False, allow_infinity=False)


@st.composite
def valid_numeric(draw):
    sec, field, lo, hi = draw(st.sampled_from(NUMERIC))
    a = draw(st.floats(lo, hi, **finite))
    b = draw(st.floats(lo, hi, **finite))
    if draw(st.booleans()) and a != b:
        value = f"{{ min = {min(a, b)!r}, max = {max(a, b)!r} }}"
    else:
        value = repr(a)
    return sec, field, value


@settings(max_examples=60, deadline=None)
@given(valid_numeric(), st.integers(0, 2**32), st.integers(1, 50))
def test_random_valid_recipes_validate(item, seed, samples):
    sec, field, value = item
    text = f"[dataset]\nseed = {seed}\nsamples = {samples}\n[{sec}]\n{field} = {value}\n"
    r = parse_recipe(text)
    assert r.dataset.samples == samples
    # and a spec can be drawn from it, with the value inside the declared range
    from crackgen.config.spec import make_spec

    make_spec(r, samples - 1)


@st.composite
def invalid_numeric(draw):
    sec, field, lo, hi = draw(st.sampled_from(NUMERIC))
    kind = draw(st.sampled_from(["below", "above", "inverted", "typo"]))
    if kind == "below":
        return sec, field, f"{field} = {lo - draw(st.floats(0.01, 1e3, **finite))!r}", f"{sec}.{field}"
    if kind == "above":
        return sec, field, f"{field} = {hi + draw(st.floats(0.01, 1e3, **finite))!r}", f"{sec}.{field}"
    if kind == "inverted":
        a = draw(st.floats(lo, hi, **finite))
        b = draw(st.floats(lo, hi, **finite).filter(lambda x: x != a))
        return sec, field, f"{field} = {{ min = {max(a, b)!r}, max = {min(a, b)!r} }}", f"{sec}.{field}.max"
    junk = draw(st.text(string.ascii_lowercase, min_size=1, max_size=6))
    return sec, field, f"{field}_{junk} = 1", f"{sec}.{field}_{junk}"


@settings(max_examples=60, deadline=None)
@given(invalid_numeric())
def test_random_invalid_recipes_are_refused_with_field_name(item):
    sec, _, line, where = item
    lines = problems(f"[{sec}]\n{line}\n")
    assert any(l.startswith(where + ":") for l in lines), (lines, where)


def test_recipe_families_match_asset_files():
    from crackgen.config.recipe import FAMILIES
    from crackgen.procedural.materials import list_families

    assert sorted(FAMILIES) == list_families()
