"""Procedural materials: family files, map shapes/ranges, crack shading, distractors, normals."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy import ndimage

from crackgen.config.recipe import Recipe
from crackgen.config.spec import DistractorSpec, MaterialSpec, make_spec
from crackgen.procedural.crackmap import crack_map
from crackgen.procedural.distractors import DISTRACTORS
from crackgen.procedural.materials import (
    Family,
    MaterialError,
    Speckles,
    _speckles,
    list_families,
    load_family,
    material_maps,
    normal_from_height,
    resample_crack,
    save_preview,
)
from crackgen.procedural.texgrid import TexGrid

FAMILIES = ["asphalt", "concrete", "masonry", "steel"]
KINDS = ["joint", "sealant", "stain", "marking", "formwork", "rust_streak"]


@pytest.fixture(scope="module")
def cm():
    spec = make_spec(Recipe.model_validate({"crack": {"threshold": 0.06}}), 1)
    m = crack_map(spec.crack, 128, 2.0, measure=False)
    assert 0.01 < m.mask.mean() < 0.5
    return m


def empty_like(cm):
    return dataclasses.replace(cm, mask=np.zeros_like(cm.mask), depth_m=np.zeros_like(cm.depth_m))


def mspec(family="asphalt", seed=7, px=96, distractors=(), **kw) -> MaterialSpec:
    args = dict(hue_shift=0.02, value_scale=1.0, roughness_offset=0.0, crack_darkening=0.3, crack_roughness=0.97)
    args.update(kw)
    return MaterialSpec(family=family, seed=seed, texture_px=px, distractors=list(distractors), **args)


def test_every_family_file_loads():
    assert set(FAMILIES) <= set(list_families())
    for name in list_families():
        fam = load_family(name)
        assert isinstance(fam, Family) and fam.name == name
    assert load_family("masonry").bricks is not None
    assert load_family("steel").paint is not None
    assert load_family("asphalt").speckles


def test_unknown_family_is_one_line_error():
    with pytest.raises(MaterialError) as e:
        load_family("marble_xyz")
    msg = str(e.value)
    assert "\n" not in msg and "marble_xyz" in msg and "asphalt" in msg


_OK = "base_color = [0.1, 0.1, 0.1]\nroughness = 0.5\n"


@pytest.mark.parametrize(
    "body, field",
    [
        ("base_color = [0.1, 0.1, 0.1]\nroughness = 1.7\n", "roughness"),
        ("base_color = [0.1, 0.1]\nroughness = 0.5\n", "base_color"),
        (_OK + "shine = 3\n", "shine: unknown key"),
        (_OK + "[[layers]]\ntarget = 'colour'\nscale_m = 1\namplitude = 0.1\n", "layers.0.target"),
        (_OK + "[[speckles]]\ncoverage = 0.2\nsize_m = [0.01, 0.001]\ncolors = [[0,0,0]]\n", "size_m: min must be"),
        (_OK + "[bricks]\nsize_m = [0.2, 0.06]\nmortar_color = [0.3, 0.3, 0.3]\ncolors = [[0.3, 0.1, 0.1]]\n",
         "bricks.mortar_m"),
        ("base_color = [0.1, 0.1, 0.1\n", "not valid TOML"),
    ],
)
def test_bad_family_file_names_file_and_field(tmp_path, monkeypatch, body, field):
    (tmp_path / "materials").mkdir()
    (tmp_path / "materials" / "bad.toml").write_text(body)
    monkeypatch.setenv("CRACKGEN_ASSETS", str(tmp_path))
    with pytest.raises(MaterialError) as e:
        load_family("bad")
    msg = str(e.value)
    assert "\n" not in msg and "bad.toml" in msg and field in msg


def test_unknown_distractor_kind_names_field(cm):
    with pytest.raises(MaterialError, match=r"material\.distractors\[0\]\.kind"):
        material_maps(mspec(distractors=[DistractorSpec("graffiti", 1)]), cm)


@pytest.mark.parametrize("family", FAMILIES)
def test_maps_shapes_dtypes_ranges(cm, family):
    px = 96  # differs from the crack map's 128: exercises resampling
    m = material_maps(mspec(family, px=px), cm)
    assert m.albedo.shape == (px, px, 3) and m.albedo.dtype == np.float32
    assert m.normal.shape == (px, px, 3) and m.normal.dtype == np.float32
    for a in (m.roughness, m.height_m):
        assert a.shape == (px, px) and a.dtype == np.float32
    assert m.distractor_mask.shape == (px, px) and m.distractor_mask.dtype == bool
    assert m.crack_mask.shape == (px, px) and m.crack_mask.dtype == bool
    for a in (m.albedo, m.roughness, m.normal):
        assert np.isfinite(a).all() and a.min() >= 0.0 and a.max() <= 1.0
    assert m.albedo.std() > 0.005  # textured, not flat


def test_deterministic_and_seed_dependent(cm):
    ds = [DistractorSpec("stain", 3), DistractorSpec("joint", 4)]
    a = material_maps(mspec("concrete", seed=5, distractors=ds), cm)
    b = material_maps(mspec("concrete", seed=5, distractors=ds), cm)
    c = material_maps(mspec("concrete", seed=6, distractors=ds), cm)
    for f in ("albedo", "roughness", "normal", "height_m", "distractor_mask"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
    assert np.abs(a.albedo - c.albedo).mean() > 1e-3


@pytest.mark.parametrize("family", FAMILIES)
def test_crack_texels_darker_rougher_and_lower(cm, family):
    cd = 0.3
    spec = mspec(family, crack_darkening=cd, crack_roughness=0.97, roughness_offset=-0.1)
    with_crack = material_maps(spec, cm)
    without = material_maps(spec, empty_like(cm))
    inside = with_crack.crack_mask
    assert inside.any() and not without.crack_mask.any()
    np.testing.assert_array_equal(with_crack.albedo[~inside], without.albedo[~inside])
    # Per-texel darkening factor: crack_darkening with +-20 % variation, mean close to crack_darkening.
    ok = without.albedo[inside] > 1e-3
    ratio = with_crack.albedo[inside][ok] / without.albedo[inside][ok]
    assert ratio.min() >= 0.8 * cd - 1e-4 and ratio.max() <= 1.2 * cd + 1e-4
    assert abs(ratio.mean() - cd) < 0.05 * cd
    lum_in = with_crack.albedo[inside].mean()
    lum_out = with_crack.albedo[~inside].mean()
    assert lum_in < lum_out * cd * 1.5
    assert np.all(with_crack.roughness[inside] == np.float32(0.97))
    assert with_crack.roughness[inside].mean() > with_crack.roughness[~inside].mean()
    # crack depth enters the height map (normal map shading of the walls)
    _, depth = resample_crack(cm, spec.texture_px)
    np.testing.assert_allclose(without.height_m - with_crack.height_m, depth, atol=1e-6)
    assert np.abs(with_crack.normal - without.normal).max() > 0.1


@pytest.mark.parametrize("kind", KINDS)
def test_distractor_paints_only_its_mask_and_never_the_crack_mask(cm, kind):
    mask_before = cm.mask.copy()
    base = material_maps(mspec("asphalt", px=128), cm)
    m = material_maps(mspec("asphalt", px=128, distractors=[DistractorSpec(kind, 21)]), cm)
    dm = m.distractor_mask
    assert dm.any() and not base.distractor_mask.any()
    np.testing.assert_array_equal(cm.mask, mask_before)
    np.testing.assert_array_equal(m.crack_mask, base.crack_mask)
    changed = np.abs(m.albedo - base.albedo).max(axis=-1) > 1e-6
    assert not changed[~dm].any()  # nothing outside the mask
    assert changed[dm].mean() > 0.95  # (almost) everything inside it
    np.testing.assert_array_equal(m.roughness[~dm], base.roughness[~dm])


def test_distractor_kinds_look_as_described(cm):
    def maps(kind, seed=5):
        return material_maps(mspec("asphalt", px=128, distractors=[DistractorSpec(kind, seed)]), empty_like(cm))

    base = material_maps(mspec("asphalt", px=128), empty_like(cm))
    lum = lambda m: m.albedo.mean(axis=-1)  # noqa: E731
    j = maps("joint")
    assert lum(j)[j.distractor_mask].mean() < lum(base)[j.distractor_mask].mean()
    assert j.height_m[j.distractor_mask].mean() < base.height_m[j.distractor_mask].mean()
    s = maps("sealant")
    assert s.roughness[s.distractor_mask].mean() < base.roughness[s.distractor_mask].mean()
    mk = maps("marking")
    assert lum(mk)[mk.distractor_mask].mean() > 2 * lum(base)[mk.distractor_mask].mean()
    assert mk.roughness[mk.distractor_mask].mean() < base.roughness[mk.distractor_mask].mean()
    st = maps("stain")
    assert lum(st)[st.distractor_mask].mean() < lum(base)[st.distractor_mask].mean()
    # a sealant strip is wider than a saw-cut joint
    assert s.distractor_mask.sum() > j.distractor_mask.sum()


def test_normal_map_unit_length_and_hand_computed():
    px, texel = 32, 0.01
    flat = normal_from_height(np.full((px, px), 0.003, np.float32), texel)
    np.testing.assert_allclose(flat, np.broadcast_to([0.5, 0.5, 1.0], flat.shape), atol=1e-7)
    slope = 0.5
    x = (np.arange(px) + 0.5) * texel
    ramp_u = normal_from_height(np.tile(slope * x, (px, 1)).astype(np.float32), texel) * 2 - 1
    k = 1 / np.sqrt(1 + slope**2)
    np.testing.assert_allclose(ramp_u[5, 5], [-slope * k, 0.0, k], atol=1e-5)
    ramp_v = normal_from_height(np.tile(slope * x[:, None], (1, px)).astype(np.float32), texel) * 2 - 1
    # +Y of the normal map is +v (rows): height rising along v tilts the normal towards -v.
    np.testing.assert_allclose(ramp_v[5, 5], [0.0, -slope * k, k], atol=1e-5)


def test_generated_normals_are_unit_length(cm):
    m = material_maps(mspec("masonry", px=96), cm)
    n = m.normal * 2 - 1
    np.testing.assert_allclose(np.linalg.norm(n, axis=-1), 1.0, atol=1e-5)
    assert (n[..., 2] > 0).all()


def test_masonry_mortar_lines_at_brick_period(cm):
    px, size = 512, 1.0
    fam = load_family("masonry")
    pitch_v = fam.bricks.size_m[1] + fam.bricks.mortar_m
    flat = dataclasses.replace(empty_like(cm), size_m=size)
    m = material_maps(mspec("masonry", px=px), flat)
    assert not m.crack_mask.any() and not m.distractor_mask.any()  # mortar joints are not cracks
    # Bed joints are continuous along u: the row-mean height dips once per brick course.
    prof = m.height_m.mean(axis=1)
    prof = prof - prof.mean()
    ac = np.correlate(prof, prof, mode="full")[px - 1:]
    expected = pitch_v / (size / px)
    lags = np.arange(int(expected * 0.5), int(expected * 1.5))
    assert abs(lags[np.argmax(ac[lags])] - expected) <= 1.5
    # Mortar is darker-or-different in colour and lower: texels within the recessed joints.
    low = m.height_m < np.percentile(m.height_m, 5)
    assert low.any()
    mortar = np.asarray(fam.bricks.mortar_color)
    assert np.abs(m.albedo[low].mean(axis=0) - mortar).max() < np.abs(m.albedo[~low].mean(axis=0) - mortar).max()


def test_speckle_coverage_matches_family_setting():
    grid = TexGrid(256, 1.0)
    sp = Speckles(coverage=0.3, size_m=[0.01, 0.02], colors=[[1.0, 1.0, 1.0]], color_jitter=0.0, edge=0.01)
    alb = np.zeros((256, 256, 3), np.float32)
    rough = np.zeros((256, 256), np.float32)
    h = np.zeros((256, 256), np.float32)
    _speckles(sp, grid, np.random.default_rng(0), alb, rough, h)
    covered = (alb[..., 0] > 0.5).mean()
    assert 0.2 < covered <= 0.32  # overlaps only reduce it


def test_resample_crack_nearest_and_bilinear(cm):
    mask, depth = resample_crack(cm, 256)
    np.testing.assert_array_equal(mask, np.kron(cm.mask, np.ones((2, 2), bool)))
    assert abs(depth.mean() - cm.depth_m.mean()) < 0.02 * cm.depth_m.mean() + 1e-9
    same_mask, same_depth = resample_crack(cm, 128)
    np.testing.assert_array_equal(same_mask, cm.mask)


def test_save_preview_writes_png(tmp_path, cm):
    import cv2

    m = material_maps(mspec("steel", px=64, distractors=[DistractorSpec("marking", 2)]), cm)
    p = save_preview(m, tmp_path / "prev.png")
    img = cv2.imread(str(p))
    assert img.shape == (64, 4 * 64, 3)


# ---- issue 9: defaults unchanged, crack cavity, dirt, spall ------------------------------------

# sha256[:20] of albedo + roughness bytes at the base commit d227a01 (before clutter, cavity,
# dirt, spall and the photo family existed), for the spec in test_defaults_leave_maps_byte_identical.
BASE_HASHES = {
    "asphalt": "208f05ecabbcd9ef0a38", "concrete": "0c79d0f93bdc8ff2abbc", "masonry": "9f52ff875d87375fe209",
    "steel": "a89ba418e23dc20b3a8c", "blockwork": "36e5b6c3d65e4208363f",
}


@pytest.mark.parametrize("family", sorted(BASE_HASHES))
def test_defaults_leave_maps_byte_identical(family):
    import hashlib
    from types import SimpleNamespace

    flat = SimpleNamespace(mask=np.zeros((64, 64), bool), depth_m=np.zeros((64, 64), np.float32), size_m=1.5)
    s = MaterialSpec(family=family, seed=11, texture_px=64, hue_shift=0.02, value_scale=1.1, roughness_offset=-0.05,
                     crack_darkening=0.3, crack_roughness=0.9,
                     distractors=[DistractorSpec("stain", 5), DistractorSpec("joint", 6)])
    m = material_maps(s, flat)
    assert hashlib.sha256(m.albedo.tobytes() + m.roughness.tobytes()).hexdigest()[:20] == BASE_HASHES[family]
    assert not m.clutter_mask.any() and m.photo == ""


def test_old_spec_json_loads_and_renders_as_today(cm):
    from crackgen.config.spec import SampleSpec

    spec = make_spec(Recipe.model_validate({"material": {"texture_px": 64}}), 4)
    d = spec.to_dict()
    for k in ("crack_cavity", "crack_dirt", "crack_spall", "crack_seed", "photo_folder", "photo_fraction",
              "photo_size_m", "photo_clean", "clutter"):
        d["material"].pop(k)
    old = SampleSpec.from_dict(d).material  # a spec written before issue 9
    a, b = material_maps(old, cm), material_maps(spec.material, cm)
    for f in ("albedo", "roughness", "height_m", "normal"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))


def groove(px=64, size_m=0.064, half_w_m=0.003, depth_m=0.01):
    """Hand-made straight V-groove along u: 1 mm texels, 6 mm wide, 10 mm deep at the centre."""
    from types import SimpleNamespace

    v = (np.arange(px) + 0.5) * size_m / px - size_m / 2
    dist = np.abs(v)[:, None] * np.ones((1, px))
    depth = np.clip(1 - dist / half_w_m, 0, 1).astype(np.float32) * depth_m
    return SimpleNamespace(mask=depth > 0, depth_m=depth, size_m=size_m), dist


def test_cavity_darkens_crack_centres_more_than_edges():
    g, dist = groove()
    plain = material_maps(mspec("concrete", px=64), g)
    cav = material_maps(mspec("concrete", px=64, crack_cavity=1.0), g)
    inside = g.mask
    np.testing.assert_array_equal(cav.albedo[~inside], plain.albedo[~inside])  # only the crack changes
    ratio = cav.albedo.mean(-1) / np.maximum(plain.albedo.mean(-1), 1e-6)
    centre = inside & (dist < 0.001)
    edge = inside & (dist > 0.002)
    assert ratio[centre].mean() < 0.35  # near-black deep centre (on top of crack_darkening)
    assert ratio[edge].mean() > ratio[centre].mean() + 0.3
    assert np.all(ratio[inside] <= 1.0 + 1e-6)
    half = material_maps(mspec("concrete", px=64, crack_cavity=0.5), g)
    assert (half.albedo.mean(-1) / plain.albedo.mean(-1))[centre].mean() > ratio[centre].mean()


def test_dirt_fills_part_of_the_crack_and_spall_chips_its_edges():
    g, dist = groove()
    plain = material_maps(mspec("concrete", px=64, crack_cavity=1.0), g)
    dirt = material_maps(mspec("concrete", px=64, crack_cavity=1.0, crack_dirt=True, crack_seed=2), g)
    inside = g.mask
    filled = np.abs(dirt.albedo - plain.albedo).max(-1) > 1e-6
    assert not filled[~inside].any()  # dirt lies only in the crack
    assert 0.05 < filled[inside].mean() < 0.95  # partial
    assert dirt.albedo[filled].mean() > plain.albedo[filled].mean()  # lighter than the cavity
    assert dirt.height_m[filled].mean() > plain.height_m[filled].mean()  # raises the crack floor
    sp = material_maps(mspec("concrete", px=64, crack_spall=True, crack_seed=2), g)
    base = material_maps(mspec("concrete", px=64), g)
    chipped = np.abs(sp.height_m - base.height_m) > 0
    assert chipped.any() and not chipped[inside].any()  # along the border, never inside the crack
    assert dist[chipped].max() < 0.003 + 0.012  # within the chip reach of the crack
    assert (sp.height_m[chipped] < base.height_m[chipped]).all()
    np.testing.assert_array_equal(sp.crack_mask, base.crack_mask)  # unlabelled
    np.testing.assert_array_equal(
        material_maps(mspec("concrete", px=64, crack_spall=True, crack_seed=2), g).height_m, sp.height_m)


def test_formwork_is_a_regular_grid_of_lines_and_rust_runs_down_in_orange(cm):
    from crackgen.procedural.texgrid import TexGrid

    size = 3.0  # metres: several formwork panels in view
    grid = TexGrid(256, size)
    for seed in range(4):
        albedo = np.full((256, 256, 3), 0.5, np.float32)
        rough, height = np.full((256, 256), 0.6, np.float32), np.zeros((256, 256), np.float32)
        m = DISTRACTORS["formwork"](np.random.default_rng(seed), grid, albedo, rough, height)
        assert 0.002 < m.mean() < 0.2  # thin lines (and tie holes), not an area
        # straight joints across the whole patch (a joint drifts at most a few texels over 3 m): some band of
        # 6 rows holds a line over every column, and some band of 6 columns one over every row
        across_rows = max(m[j:j + 6].any(axis=0).mean() for j in range(0, 250))
        across_cols = max(m[:, j:j + 6].any(axis=1).mean() for j in range(0, 250))
        assert across_rows > 0.97 and across_cols > 0.97
        assert np.abs(albedo[m] - 0.5).min() > 1e-3 and np.allclose(albedo[~m], 0.5)
    albedo = np.full((256, 256, 3), 0.5, np.float32)
    rough, height = np.full((256, 256), 0.6, np.float32), np.zeros((256, 256), np.float32)
    m = DISTRACTORS["rust_streak"](np.random.default_rng(3), TexGrid(256, 1.0), albedo, rough, height)
    assert m.any() and np.allclose(albedo[~m], 0.5) and (height == 0).all()
    r, b = albedo[m][:, 0], albedo[m][:, 2]
    assert (r > b).all() and np.percentile(r - b, 90) > 0.1  # orange-brown, strongest near its sources
    ys, xs = np.nonzero(m)
    assert np.ptp(ys) > np.ptp(xs) / 4  # runs down the surface (+v), not across it


@pytest.mark.parametrize("family, depth", [("masonry", 0.006), ("blockwork", 0.008)])
def test_joint_relief_moves_the_mortar_recess_from_the_normal_map_into_the_mesh(cm, family, depth):
    from crackgen.procedural.surface import mesh_depth_at_uv, surface_vertices, with_relief

    flat = dataclasses.replace(empty_like(cm), size_m=0.6)  # 2.3 mm texels: a 10 mm joint is 4 texels wide
    off = material_maps(mspec(family, px=256), flat)
    on = material_maps(mspec(family, px=256, joint_relief_m=depth), flat)
    assert off.relief_m is None and on.relief_m is not None
    np.testing.assert_array_equal(on.albedo, off.albedo)  # the same wall: same joints, same draws
    relief = on.relief_m
    assert relief.max() == 0.0 and relief.min() == pytest.approx(-depth, abs=1e-6)
    mortar = relief < -0.9 * depth
    family_depth = load_family(family).bricks.mortar_depth_m
    # the normal map's height lost exactly the family's joint term: brick faces family_depth above the mortar
    np.testing.assert_allclose(off.height_m - on.height_m, family_depth * (1.0 + relief / depth), atol=1e-6)
    assert 0.03 < mortar.mean() < 0.3  # joints, not faces
    g = 513
    verts = with_relief(surface_vertices(flat, g), relief)
    assert with_relief(verts, None) is verts
    # the mesh holds the recess: its depth at the centres of mortar texels far from a face is the relief depth
    core = ndimage.binary_erosion(mortar)
    j, i = np.nonzero(core)
    u, v = (i + 0.5) / 256, (j + 0.5) / 256
    md = mesh_depth_at_uv(verts, g, u, v)
    assert core.any() and np.median(md) == pytest.approx(depth, rel=0.05)
    jb, ib = np.nonzero(relief == 0.0)
    assert np.median(mesh_depth_at_uv(verts, g, (ib + 0.5) / 256, (jb + 0.5) / 256)) < 0.05 * depth
    with pytest.raises(Exception, match="with_relief"):
        with_relief(verts[:-1], relief)


def test_joint_relief_ignores_families_without_joints(cm):
    flat = empty_like(cm)
    np.testing.assert_array_equal(material_maps(mspec("concrete", joint_relief_m=0.006), flat).height_m,
                                  material_maps(mspec("concrete"), flat).height_m)
    assert material_maps(mspec("concrete", joint_relief_m=0.006), flat).relief_m is None
