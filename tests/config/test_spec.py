"""SampleSpec: depends only on (recipe, index); JSON roundtrip is lossless."""
import json

import pytest

from crackgen.config.recipe import Recipe, parse_recipe
from crackgen.config.spec import SampleSpec, make_spec


def test_spec_depends_only_on_recipe_and_index():
    r = Recipe()
    a = [make_spec(r, i) for i in (0, 1, 2)]
    b = [make_spec(r, i) for i in (2, 1, 0)][::-1]  # different order, fresh calls
    assert a == b
    assert a[0] != a[1]
    assert a[0].crack.noise_seed != a[1].crack.noise_seed


def test_recipe_seed_changes_every_sample():
    a = make_spec(parse_recipe("[dataset]\nseed = 1"), 0)
    b = make_spec(parse_recipe("[dataset]\nseed = 2"), 0)
    assert a.crack != b.crack and a.camera != b.camera


def test_json_roundtrip_is_lossless():
    r = parse_recipe("[stereo]\nenabled = true\n[material.distractors]\nstain = 1.0\njoint = 1.0")
    for i in range(5):
        s = make_spec(r, i)
        back = SampleSpec.from_json(s.to_json())
        assert back == s
        assert back.to_json() == s.to_json()
    kinds = {d.kind for d in make_spec(r, 0).material.distractors}
    assert {"joint", "stain"} <= kinds  # probability 1 -> always present


def test_draws_respect_recipe_ranges():
    r = parse_recipe("[crack]\nthreshold = {min = 0.02, max = 0.03}\n[camera]\ntilt_deg = 10\n")
    for i in range(20):
        s = make_spec(r, i)
        assert 0.02 <= s.crack.threshold < 0.03
        assert s.camera.tilt_rad == pytest.approx(0.17453292519943295)
        assert 1 <= len(s.lights)


def test_from_dict_rejects_unknown_keys():
    d = make_spec(Recipe(), 0).to_dict()
    d["crack"]["bogus"] = 1
    with pytest.raises(ValueError, match="bogus"):
        SampleSpec.from_dict(json.loads(json.dumps(d)))
