"""[adapt] in the generator: only the RGB views change, the same way in both views, checked up front."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
from tiny_recipes import tiny_recipe

from crackgen.config.recipe import parse_recipe
from crackgen.datagen.generate import GenerateError, GenerateOptions, generate
from crackgen.datagen.pipeline import SampleProducer


def _photos(folder, n=3):
    folder.mkdir()
    rng = np.random.default_rng(0)
    for i in range(n):  # warm, dark, contrasty "site" photos, unlike the renders
        img = np.clip(rng.normal([40, 60, 110], 35, size=(40, 52, 3)), 0, 255).astype(np.uint8)
        cv2.imwrite(str(folder / f"site_{i}.jpg"), img)
    return folder


def _recipe(target: str | None, method: str = "reinhard"):
    text = tiny_recipe(5, width=64, height=48, spp=1, stereo=True, lidar=False)
    if target is not None:
        text += f'[adapt]\ntarget = "{target}"\nmethod = "{method}"\nband = 0.05\n'
    return parse_recipe(text)


@pytest.mark.blender
@pytest.mark.slow
def test_only_rgb_views_change_and_metadata_says_how(tmp_path):
    photos = _photos(tmp_path / "site")
    plain = SampleProducer(_recipe(None), threads=1)
    a = plain.make(0)
    plain.close()
    for method in ("reinhard", "fourier"):
        prod = SampleProducer(_recipe(str(photos), method), threads=1)
        b, again = prod.make(0), prod.make(0)
        prod.close()
        # labels, depth and every sensor member are exactly the clean render's (stable draws per section)
        for k in a.members:
            if k in ("rgb.png", "right.png"):
                assert not np.array_equal(a.members[k], b.members[k]), (method, k)
            elif isinstance(a.members[k], dict):
                for c in a.members[k]:
                    assert np.array_equal(a.members[k][c], b.members[k][c]), (method, k)
            else:
                assert np.array_equal(a.members[k], b.members[k]), (method, k)
        meta = b.meta["adapt"]
        assert meta["applied"] and meta["method"] == method and meta["target"].startswith("site_")
        assert meta["views"] == ["rgb", "right"] and ("band" in meta) == (method == "fourier")
        assert a.meta["adapt"] == {"applied": False}
        # deterministic per seed
        assert np.array_equal(b.members["rgb.png"], again.members["rgb.png"]) and b.meta == again.meta
        # the adapted render's mean colour moved toward the site photos' (about RGB 110, 60, 40)
        site = np.array([110.0, 60.0, 40.0])
        before = np.abs(a.members["rgb.png"].reshape(-1, 3).mean(0) - site).sum()
        after = np.abs(b.members["rgb.png"].reshape(-1, 3).mean(0) - site).sum()
        assert after < 0.5 * before, (method, before, after)


@pytest.mark.parametrize("make", ["missing", "empty", "unreadable"])
def test_bad_target_folder_is_refused_before_rendering(tmp_path, make):
    target = tmp_path / "site"
    if make != "missing":
        target.mkdir()
    if make == "unreadable":
        (target / "a.jpg").write_bytes(b"\x00garbage")
    out = tmp_path / "out"
    with pytest.raises(GenerateError, match="adapt target"):
        generate(_recipe(str(target)), GenerateOptions(out=str(out), progress=False))
    assert not out.exists()  # nothing made, nothing lost


def test_validate_names_a_bad_target_folder(tmp_path, capsys):
    from crackgen.tools.cli import main

    recipe = tmp_path / "r.toml"
    recipe.write_text(f'[adapt]\ntarget = "{tmp_path / "photos"}"\n')
    assert main(["validate", str(recipe)]) == 1
    assert "no such folder" in capsys.readouterr().err
    _photos(tmp_path / "photos")
    assert main(["validate", str(recipe)]) == 0
