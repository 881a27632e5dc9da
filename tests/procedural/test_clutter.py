"""Clutter: exact masks, never the crack mask, determinism, each kind looks as described."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from crackgen.config.recipe import CLUTTER_KINDS, Recipe, parse_recipe
from crackgen.config.spec import ClutterSpec, MaterialSpec, make_spec
from crackgen.procedural.clutter import CLUTTER
from crackgen.procedural.crackmap import crack_map
from crackgen.procedural.materials import MaterialError, material_maps


@pytest.fixture(scope="module")
def cm():
    spec = make_spec(Recipe.model_validate({"crack": {"threshold": 0.05}}), 2)
    return crack_map(spec.crack, 128, 0.6, measure=False)


def empty_like(cm):
    return dataclasses.replace(cm, mask=np.zeros_like(cm.mask), depth_m=np.zeros_like(cm.depth_m))


def mspec(family="concrete", clutter=(), **kw) -> MaterialSpec:
    args = dict(family=family, seed=4, texture_px=128, hue_shift=0.0, value_scale=1.0, roughness_offset=0.0,
                crack_darkening=0.3, crack_roughness=0.97, clutter=list(clutter))
    args.update(kw)
    return MaterialSpec(**args)


def lum(m):
    return m.albedo.mean(axis=-1)


def test_recipe_kinds_match_painters():
    assert tuple(CLUTTER) == CLUTTER_KINDS


@pytest.mark.parametrize("kind", CLUTTER_KINDS)
def test_clutter_paints_only_its_mask_and_never_the_crack(cm, kind):
    mask_before, depth_before = cm.mask.copy(), cm.depth_m.copy()
    base = material_maps(mspec(), cm)
    m = material_maps(mspec(clutter=[ClutterSpec(kind, 9, 1.0)]), cm)
    cmask = m.clutter_mask
    assert cmask.any() and not base.clutter_mask.any()
    assert not m.distractor_mask.any()
    np.testing.assert_array_equal(cm.mask, mask_before)  # the GT source is untouched
    np.testing.assert_array_equal(cm.depth_m, depth_before)
    np.testing.assert_array_equal(m.crack_mask, base.crack_mask)
    changed = (np.abs(m.albedo - base.albedo).max(axis=-1) > 1e-6) | (np.abs(m.height_m - base.height_m) > 0)
    assert not changed[~cmask].any()  # nothing outside the mask
    assert changed[cmask].mean() > 0.9
    np.testing.assert_array_equal(m.roughness[~cmask], base.roughness[~cmask])


@pytest.mark.parametrize("kind", CLUTTER_KINDS)
def test_clutter_is_deterministic_per_seed(cm, kind):
    a = material_maps(mspec(clutter=[ClutterSpec(kind, 3, 0.8)]), cm)
    b = material_maps(mspec(clutter=[ClutterSpec(kind, 3, 0.8)]), cm)
    c = material_maps(mspec(clutter=[ClutterSpec(kind, 4, 0.8)]), cm)
    for f in ("albedo", "roughness", "height_m", "clutter_mask"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
    assert (a.clutter_mask != c.clutter_mask).any()


def test_clutter_kinds_look_as_described(cm):
    flat = empty_like(cm)
    base = material_maps(mspec(), flat)

    def maps(kind, amount=1.0):
        return material_maps(mspec(clutter=[ClutterSpec(kind, 5, amount)]), flat)

    # pores are 0.5-5 mm: look at them on a close-up patch (1.2 mm texels; at 4.7 mm they are sub-texel)
    close = dataclasses.replace(flat, size_m=0.15)
    base_close = material_maps(mspec(), close)
    p = material_maps(mspec(clutter=[ClutterSpec("pores", 5, 1.0)]), close)
    faint = maps("pores")  # sub-texel pores darken their texel by their area only
    assert np.percentile((lum(faint) / lum(base))[faint.clutter_mask], 10) > np.percentile(
        (lum(p) / lum(base_close))[p.clutter_mask], 10)
    # pits: visibly dark (well under half the surrounding brightness) and dented
    ratio = lum(p)[p.clutter_mask] / lum(base_close)[p.clutter_mask]
    core = p.clutter_mask & (lum(p) < 0.5 * lum(base_close))  # pit interiors: under half the brightness
    assert core.sum() > 50 and np.percentile(ratio, 10) < 0.35
    assert p.height_m[core].mean() < base_close.height_m[core].mean()
    # more amount, more pores
    assert maps("pores", 1.0).clutter_mask.sum() > maps("pores", 0.2).clutter_mask.sum()
    g = maps("gaps")
    assert lum(g)[g.clutter_mask].mean() < lum(base)[g.clutter_mask].mean()
    assert g.height_m[g.clutter_mask].mean() < base.height_m[g.clutter_mask].mean()
    mo = maps("moss")
    a_in, a_base = mo.albedo[mo.clutter_mask].mean(axis=0), base.albedo[mo.clutter_mask].mean(axis=0)
    assert a_in[1] > a_in[2] * 1.5 and a_in[1] / a_in[0] > a_base[1] / a_base[0]  # greenish
    pa = maps("patch")
    inner = pa.clutter_mask & (np.abs(pa.albedo - base.albedo).max(-1) > 1e-6)
    assert 0.01 < inner.mean() < 0.6  # one bounded patch
    assert pa.roughness[inner].mean() < base.roughness[inner].mean()  # smoother material
    st = maps("stains")
    assert lum(st)[st.clutter_mask].mean() < lum(base)[st.clutter_mask].mean()


def test_unknown_clutter_kind_names_field(cm):
    with pytest.raises(MaterialError, match=r"material\.clutter\[0\]\.kind"):
        material_maps(mspec(clutter=[ClutterSpec("graffiti", 1, 1.0)]), cm)


def test_clutter_draws_are_appended_and_follow_the_recipe():
    off = parse_recipe("")
    on = parse_recipe("[material.clutter]\npores = 1.0\ngaps = 1.0\nmoss = 0.0\n[material]\ncrack_cavity = 0.7")
    for i in range(6):
        a, b = make_spec(off, i), make_spec(on, i)
        assert not a.material.clutter and a.material.crack_cavity == 0.0
        assert [c.kind for c in b.material.clutter] == ["pores", "gaps"]
        assert b.material.crack_cavity == 0.7
        assert all(0.3 <= c.amount <= 1.0 for c in b.material.clutter)
        keep = ("clutter", "crack_cavity")
        assert dataclasses.replace(a.material, **{k: None for k in keep}) == dataclasses.replace(
            b.material, **{k: None for k in keep})
        for name in ("crack", "lights", "camera", "shadow", "surface"):
            assert getattr(a, name) == getattr(b, name)


def test_voids_are_compact_dark_holes_larger_than_pores(cm):
    """Bugholes: dark, dented, 3-24 mm across and compact (no long thin shapes a model could take for a crack)."""
    from scipy import ndimage

    flat = dataclasses.replace(empty_like(cm), size_m=0.3)  # 2.3 mm texels over 0.3 m
    base = material_maps(mspec(), flat)
    v = material_maps(mspec(clutter=[ClutterSpec("voids", 7, 1.0)]), flat)
    p = material_maps(mspec(clutter=[ClutterSpec("pores", 7, 1.0)]), flat)
    core = v.clutter_mask & (lum(v) < 0.5 * lum(base))
    assert v.height_m[core].mean() < base.height_m[core].mean()
    lab, n = ndimage.label(v.clutter_mask)
    assert n >= 3
    texel_mm = 300 / 128
    sizes = []
    for sl in ndimage.find_objects(lab):
        h, w = (sl[0].stop - sl[0].start) * texel_mm, (sl[1].stop - sl[1].start) * texel_mm
        sizes.append(max(h, w))
        assert max(h, w) <= 24 * 1.4 + 2 * texel_mm  # ragged outline: at most ~40% over the nominal size
        assert max(h, w) / max(min(h, w), texel_mm) < 3.5  # compact, never crack-like
    assert np.median(sizes) > 3.0
    lab_p, n_p = ndimage.label(p.clutter_mask)
    assert v.clutter_mask.sum() / n > p.clutter_mask.sum() / max(n_p, 1)  # larger than pores, on average
