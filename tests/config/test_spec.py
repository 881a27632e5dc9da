"""SampleSpec: depends only on (recipe, index); each section has its own stream; JSON roundtrip is lossless."""
import dataclasses
import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from crackgen.config.recipe import Recipe, RecipeError, parse_recipe
from crackgen.config.spec import SECTION_STREAMS, SPEC_VERSION, SampleSpec, make_spec, section_rng


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


# ---- one random stream per section ------------------------------------------------------------

SECTIONS = [f.name for f in dataclasses.fields(SampleSpec) if f.name not in ("index", "recipe_seed", "version")]

# (section that changes, recipe text A, recipe text B): B differs from A only in that section.
TOGGLES = [
    ("stereo", "[stereo]\nenabled = false", "[stereo]\nenabled = true"),
    ("lights", "[lights]\ncount = {choices = [1, 2]}", "[lights]\ncount = {choices = [3, 4, 5]}"),
    ("tof", "[tof]\nenabled = true", "[tof]\nenabled = false"),
    ("lidar", "[lidar]\nenabled = true", "[lidar]\nenabled = false"),
    ("shadow", "[shadow]\nprobability = 0.1", "[shadow]\nprobability = 0.9"),
    (
        "material",
        "[material.distractors]\njoint = 0.0\nsealant = 0.0\nstain = 0.0\nmarking = 0.0",
        "[material.distractors]\njoint = 1.0\nsealant = 0.5\nstain = 0.0\nmarking = 1.0",
    ),
    ("adapt", '[adapt]\ntarget = ""', '[adapt]\ntarget = "photos"\nprobability = 0.7'),
    ("camera_effects", "[camera_effects]\nenabled = false", "[camera_effects]\nenabled = true\nnoise = 1.0"),
]


def drawn(spec: SampleSpec) -> dict[str, object]:
    """Each section's values; camera.baseline_m left out: it is the stereo draw, copied for the rig."""
    out = {name: getattr(spec, name) for name in SECTIONS}
    out["camera"] = dataclasses.replace(spec.camera, baseline_m=None)
    return out


def test_every_spec_section_has_its_own_stream():
    assert set(SECTIONS) <= set(SECTION_STREAMS)
    numbers = list(SECTION_STREAMS.values())
    assert sorted(numbers) == list(range(len(numbers)))  # unique, none skipped


def test_section_stream_is_the_spawned_child_of_the_sample_root():
    root = np.random.SeedSequence([123, 45])
    children = root.spawn(len(SECTION_STREAMS))
    for name, n in SECTION_STREAMS.items():
        expected = np.random.default_rng(children[n]).random(4)
        np.testing.assert_array_equal(section_rng(123, 45, name).random(4), expected)
    with pytest.raises(ValueError, match="unknown section 'bogus'"):
        section_rng(0, 0, "bogus")


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**63 - 1), index=st.integers(0, 10**6), toggle=st.sampled_from(TOGGLES))
def test_changing_one_section_leaves_every_other_section_unchanged(seed, index, toggle):
    section, text_a, text_b = toggle
    a = make_spec(parse_recipe(f"[dataset]\nseed = {seed}\n{text_a}"), index)
    b = make_spec(parse_recipe(f"[dataset]\nseed = {seed}\n{text_b}"), index)
    da, db = drawn(a), drawn(b)
    if section == "lights":
        # the shadow's light_index scales one fixed draw to the light count: the only cross-section link
        assert a.shadow.light_index < len(a.lights) and b.shadow.light_index < len(b.lights)
        da["shadow"] = dataclasses.replace(a.shadow, light_index=0)
        db["shadow"] = dataclasses.replace(b.shadow, light_index=0)
        n = min(len(a.lights), len(b.lights))
        assert a.lights[:n] == b.lights[:n]  # fixed draws per light: light i does not depend on the count
    if section == "material":
        assert dataclasses.replace(a.material, distractors=[]) == dataclasses.replace(b.material, distractors=[])
        assert {d.kind for d in b.material.distractors} >= {"joint", "marking"} and not a.material.distractors
    for name in SECTIONS:
        if name != section:
            assert da[name] == db[name], name


@pytest.mark.parametrize("section, text_a, text_b", TOGGLES, ids=[t[0] for t in TOGGLES])
def test_each_toggle_changes_its_own_section(section, text_a, text_b):
    # Guards the test above against toggles that change nothing.
    a = [make_spec(parse_recipe(text_a), i) for i in range(8)]
    b = [make_spec(parse_recipe(text_b), i) for i in range(8)]
    assert any(getattr(x, section) != getattr(y, section) for x, y in zip(a, b))


def test_stereo_baseline_comes_from_the_stereo_section():
    on = parse_recipe("[stereo]\nenabled = true\nbaseline_m = {min = 0.05, max = 0.2}")
    off = parse_recipe("[stereo]\nenabled = false\nbaseline_m = {min = 0.05, max = 0.2}")
    for i in range(5):
        s = make_spec(on, i)
        assert 0.05 <= s.stereo.baseline_m < 0.2 and s.camera.baseline_m == s.stereo.baseline_m
        assert s.stereo.baseline_m == pytest.approx(0.05 + 0.15 * section_rng(0, i, "stereo").random())
        t = make_spec(off, i)
        assert t.stereo.baseline_m == 0.0 and t.camera.baseline_m == 0.0


def test_every_section_differs_between_samples():
    r = parse_recipe('[stereo]\nenabled = true\n[adapt]\ntarget = "photos"\n[camera_effects]\nenabled = true\n'
                     '[camera.distortion]\nprobability = 1.0\n[lights]\nsky = 1.0')
    a, b = make_spec(r, 0), make_spec(r, 1)
    for name in SECTIONS:
        if name == "surface" or name == "render":
            continue  # compared through their single draw below
        assert getattr(a, name) != getattr(b, name), name
    assert a.surface.size_m != b.surface.size_m and a.render.seed != b.render.seed
    assert a.version == SPEC_VERSION == 2


def test_make_spec_refuses_a_non_recipe():
    with pytest.raises(TypeError, match="make_spec: recipe must be a Recipe, got dict"):
        make_spec({}, 0)


def test_adapt_draws_follow_the_recipe():
    r = parse_recipe('[adapt]\ntarget = "photos"\nprobability = 0.5\nmethod = {choices = ["fourier", "histogram"]}'
                     '\nband = {min = 0.01, max = 0.02}')
    specs = [make_spec(r, i).adapt for i in range(200)]
    on = [a for a in specs if a.enabled]
    assert 70 < len(on) < 130  # probability 0.5
    assert {a.method for a in on} == {"fourier", "histogram"}
    assert all(0.01 <= a.band < 0.02 for a in on if a.method == "fourier")
    assert all(a.band == 0.0 for a in on if a.method == "histogram")
    assert all(0.0 <= a.target_fraction < 1.0 and a.target == "photos" for a in on)
    assert not any(a.enabled for a in (make_spec(parse_recipe(""), i).adapt for i in range(5)))


def test_size_fov_makes_the_patch_cover_the_view_at_every_distance():
    from crackgen.sim.rig import make_rig

    r = parse_recipe("[surface]\nsize_fov = { min = 1.3, max = 1.6 }\n[camera]\nwidth_px = 256\nheight_px = 192\n"
                     "distance_m = { choices = [0.3, 1.0, 3.0] }\ntilt_deg = { min = 0, max = 20 }\n")
    sizes = {}
    for i in range(30):
        s = make_spec(r, i)
        cam = make_rig(s).rgb
        origins, dirs, _ = cam.pixel_rays()
        corners = [0, cam.width - 1, (cam.height - 1) * cam.width, cam.height * cam.width - 1]
        t = -origins[corners, 2] / dirs[corners, 2]  # where the corner rays meet the surface plane z = 0
        hit = origins[corners, :2] + t[:, None] * dirs[corners, :2]
        assert np.abs(hit).max() < s.surface.size_m / 2, (i, s.camera.distance_m)
        sizes.setdefault(s.camera.distance_m, []).append(s.surface.size_m)
    assert min(sizes[3.0]) > 5 * max(sizes[0.3])  # the patch grows with the view
    assert make_spec(parse_recipe(""), 0).surface == make_spec(parse_recipe("[surface]\nsize_fov = 0\n"), 0).surface
    with pytest.raises(RecipeError, match="surface.size_fov: 0 \\(off\\) or every value >= 0.5"):
        parse_recipe("[surface]\nsize_fov = { choices = [0, 1.5] }\n")


def _without_formwork_and_rust(a, b):
    """b's material less the formwork and rust streaks it gained over a, which only their surfaces get."""
    kinds = {d.kind for d in b.material.distractors} - {d.kind for d in a.material.distractors}
    fam = b.material.family
    assert ("formwork" in kinds) == (fam == "concrete") and ("rust_streak" in kinds) == (fam != "asphalt")
    extra = [d for d in b.material.distractors if d.kind in ("formwork", "rust_streak")]
    return dataclasses.replace(b.material, distractors=[d for d in b.material.distractors if d not in extra])


def _without_joint_relief(a, b):
    """b's material less its joint relief, which only brick and block walls get (and off leaves out of the JSON)."""
    assert (0.003 <= b.material.joint_relief_m <= 0.01) == (b.material.family in ("masonry", "blockwork"))
    assert a.material.joint_relief_m == 0.0 and "joint_relief_m" not in a.to_dict()["material"]
    assert type(b).from_json(b.to_json()) == b
    return dataclasses.replace(b.material, joint_relief_m=0.0)


@pytest.mark.parametrize("on_text, zero_text, strip", [
    ("[material.distractors]\nformwork = 1.0\nrust_streak = 1.0\n", "[material.distractors]\nformwork = 0.0\n",
     _without_formwork_and_rust),
    ("joint_relief_m = { min = 0.003, max = 0.01 }\n", "joint_relief_m = 0\n", _without_joint_relief),
])
def test_surface_specific_options_only_on_their_surfaces_and_they_move_no_other_draw(on_text, zero_text, strip):
    base = "[material]\nfamily = {choices = [\"asphalt\", \"concrete\", \"masonry\", \"blockwork\", \"steel\"]}\n"
    off, on = parse_recipe(base), parse_recipe(base + on_text)
    assert on.hash != off.hash and off.hash == parse_recipe(base + zero_text).hash  # off at 0: old hashes hold
    seen = set()
    for i in range(40):
        a, b = make_spec(off, i), make_spec(on, i)
        assert strip(a, b) == a.material
        assert drawn(a) | {"material": None} == drawn(b) | {"material": None}
        seen.add(b.material.family)
    assert seen == {"asphalt", "concrete", "masonry", "blockwork", "steel"}
