"""Photo family: albedo from the photo, deterministic, black-hat cleaning, folder errors before rendering."""
from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from crackgen.config.recipe import parse_recipe
from crackgen.config.spec import MaterialSpec, make_spec
from crackgen.datagen.generate import GenerateError, check_inputs
from crackgen.procedural.materials import MaterialError, material_maps
from crackgen.procedural.photo import PhotoLook, _cover, photo_maps, remove_thin_dark_lines, srgb_to_linear
from crackgen.procedural.texgrid import TexGrid


class FlatCrackMap:
    def __init__(self, px=64, size_m=0.5):
        self.mask = np.zeros((px, px), bool)
        self.depth_m = np.zeros((px, px), np.float32)
        self.size_m = size_m


def blobs(seed: int, px: int = 96) -> np.ndarray:
    """A crack-free 'surface photo': smooth random blotches plus grain, uint8 RGB."""
    rng = np.random.default_rng(seed)
    f = cv2.GaussianBlur(rng.random((px, px)).astype(np.float32), (0, 0), 4)
    f = (f - f.min()) / (f.max() - f.min())
    g = 60 + 150 * f + rng.normal(0, 6, (px, px))
    rgb = np.stack([g, g * 0.95, g * 0.9], -1)
    return np.clip(rgb, 0, 255).astype(np.uint8)


@pytest.fixture()
def folder(tmp_path):
    d = tmp_path / "photos"
    d.mkdir()
    for i, ext in enumerate(["png", "jpg", "png"]):
        cv2.imwrite(str(d / f"p{i}.{ext}"), cv2.cvtColor(blobs(i), cv2.COLOR_RGB2BGR))
    return d


def pspec(folder, fraction=0.0, size_m=0.5, clean="none", seed=3, px=96) -> MaterialSpec:
    return MaterialSpec(family="photo", seed=seed, texture_px=px, hue_shift=0.0, value_scale=1.0,
                        roughness_offset=0.0, crack_darkening=0.3, crack_roughness=0.97, photo_folder=str(folder),
                        photo_fraction=fraction, photo_size_m=size_m, photo_clean=clean)


def test_albedo_comes_from_the_photo(folder):
    m = material_maps(pspec(folder, 0.0, size_m=0.5), FlatCrackMap(size_m=0.5))
    assert m.photo == "p0.png"
    lum = m.albedo.mean(-1)
    # Same geometry (rotation, flip, offset come first from the same stream) applied to the raw
    # photo and to an unrelated one: the albedo follows its own photo texel by texel.
    grid = TexGrid(96, 0.5)

    def covered(photo):
        lin = srgb_to_linear(photo.astype(np.float32) / 255.0)
        return _cover(lin, grid, 0.5, np.random.default_rng(np.random.SeedSequence([3, 3]))).mean(-1)

    same = float(np.corrcoef(covered(blobs(0)).ravel(), lum.ravel())[0, 1])
    other = float(np.corrcoef(covered(blobs(1)).ravel(), lum.ravel())[0, 1])
    assert same > 0.95 and abs(other) < 0.5
    # plausible linear albedo, roughness and height from the photo
    assert 0.1 < lum.mean() < 0.4 and m.albedo.max() <= 0.9
    assert m.roughness.std() > 0.01 and np.isfinite(m.normal).all()
    dark = lum < np.percentile(lum, 10)
    assert m.height_m[dark].mean() < m.height_m[~dark].mean()  # dark = low


def test_photo_is_deterministic_and_drawn_from_the_sorted_folder(folder):
    a = material_maps(pspec(folder, 0.5, size_m=0.2), FlatCrackMap())
    b = material_maps(pspec(folder, 0.5, size_m=0.2), FlatCrackMap())
    for f in ("albedo", "roughness", "height_m", "normal"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
    assert a.photo == "p1.jpg"
    assert material_maps(pspec(folder, 0.99), FlatCrackMap()).photo == "p2.png"
    c = material_maps(pspec(folder, 0.5, size_m=0.2, seed=4), FlatCrackMap())
    assert np.abs(a.albedo - c.albedo).mean() > 1e-3  # the seed moves rotation / offset / brightness


def test_photo_tiles_to_cover_a_larger_patch(folder):
    grid = TexGrid(128, 1.0)
    a, r, h = photo_maps(blobs(0), grid, 0.25, "none", PhotoLook(), np.random.default_rng(0))
    assert a.shape == (128, 128, 3) and r.shape == h.shape == (128, 128)
    # four photo sides per patch side: no flat (border-filled) region anywhere
    for q in (a[:32, :32], a[-32:, -32:], a[:32, -32:]):
        assert q.std() > 0.01


def test_blackhat_removes_a_thin_dark_line_but_keeps_a_round_pore():
    img = np.full((160, 160, 3), 170, np.uint8)
    img += np.random.default_rng(0).integers(0, 8, img.shape, dtype=np.uint8)
    cv2.line(img, (10, 30), (150, 90), (40, 40, 40), 2)
    cv2.circle(img, (50, 120), 4, (30, 30, 30), -1)
    line = np.zeros((160, 160), np.uint8)
    cv2.line(line, (10, 30), (150, 90), 1, 2)
    cleaned, removed = remove_thin_dark_lines(img)
    gray = cleaned.mean(-1)
    assert removed[line.astype(bool)].mean() > 0.95
    assert gray[line.astype(bool)].mean() > 140  # the line is inpainted with the surface
    assert gray[118:123, 48:53].mean() < 60  # the pore is untouched
    assert not removed[115:126, 45:56].any()


def test_wide_clean_also_removes_a_wide_open_crack_that_blackhat_keeps():
    from crackgen.procedural.photo import photo_maps
    from crackgen.procedural.texgrid import TexGrid

    img = np.full((240, 240, 3), 170, np.uint8)
    img += np.random.default_rng(1).integers(0, 8, img.shape, dtype=np.uint8)
    cv2.line(img, (10, 60), (230, 180), (25, 25, 25), 22)  # 22 px wide: beyond the thin pass (~12 px)
    cv2.circle(img, (60, 200), 4, (30, 30, 30), -1)
    grid = TexGrid(240, 1.0)

    def darkest_band(clean):
        albedo, _, _ = photo_maps(img, grid, 1.0, clean, PhotoLook(albedo_mean=(0.3, 0.3)),
                                  np.random.default_rng(0))
        lum = albedo.mean(-1)
        return float(np.percentile(lum, 3) / np.median(lum))

    assert darkest_band("blackhat") < 0.3  # the wide crack survives the thin pass
    assert darkest_band("wide") > 0.5  # and is gone after the wide one


def test_photo_clean_runs_inside_the_family(tmp_path):
    d = tmp_path / "lined"
    d.mkdir()
    img = np.full((128, 128, 3), 160, np.uint8)
    cv2.line(img, (5, 64), (123, 70), (20, 20, 20), 2)
    cv2.imwrite(str(d / "a.png"), img)
    cm = FlatCrackMap(size_m=0.5)
    raw = material_maps(pspec(d, clean="none", px=128), cm).albedo.mean(-1)
    clean = material_maps(pspec(d, clean="blackhat", px=128), cm).albedo.mean(-1)
    assert clean.min() > 0.5 * clean.mean() and raw.min() < 0.3 * raw.mean()


@pytest.mark.parametrize("case", ["missing", "empty", "unreadable"])
def test_bad_photo_folder_is_one_line_error_before_rendering(tmp_path, case):
    d = tmp_path / "ph"
    if case != "missing":
        d.mkdir()
    if case == "unreadable":
        (d / "x.jpg").write_bytes(b"not an image")
    recipe = parse_recipe(f'[material]\nfamily = {{choices = ["concrete", "photo"]}}\nphoto_folder = "{d}"')
    with pytest.raises(GenerateError) as e:
        check_inputs(recipe)
    msg = str(e.value)
    assert "\n" not in msg and "material.photo_folder" in msg and str(d) in msg
    with pytest.raises(MaterialError, match="material.photo_folder"):
        material_maps(pspec(d), FlatCrackMap())


def test_photo_folder_is_checked_only_when_photo_can_be_drawn(tmp_path):
    check_inputs(parse_recipe(f'[material]\nfamily = "concrete"\nphoto_folder = "{tmp_path / "nope"}"'))
    with pytest.raises(Exception, match="photo_folder: required"):
        parse_recipe('[material]\nfamily = "photo"')


def test_photo_spec_draws(folder):
    r = parse_recipe(f'[material]\nfamily = "photo"\nphoto_folder = "{folder}"\nphoto_size_m = {{min = 0.2, max = 0.4}}')
    specs = [make_spec(r, i).material for i in range(8)]
    assert all(s.photo_folder == str(folder) and 0.2 <= s.photo_size_m <= 0.4 for s in specs)
    assert len({s.photo_fraction for s in specs}) == 8 and all(0 <= s.photo_fraction < 1 for s in specs)
    plain = make_spec(parse_recipe(""), 0).material
    assert plain.photo_folder == "" and dataclasses.replace(specs[0], family="x") != specs[0]
