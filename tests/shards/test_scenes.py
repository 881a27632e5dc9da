"""Views of one scene as the hold-out group: read from the manifest, without the recipe code."""
from __future__ import annotations

import pytest

from crackgen.shards import Manifest, ManifestError, scene_group, views_per_scene


def _manifest(root, text="", canonical=None):
    Manifest(root, recipe_text=text, recipe_hash="h", recipe_canonical=canonical, num_shards=1, shard_size=8).save()


def test_views_per_scene_comes_from_the_canonical_recipe_then_the_text_then_defaults_to_one(tmp_path):
    assert views_per_scene(tmp_path) == 1  # no manifest: shards written by hand or by an older tool
    _manifest(tmp_path, text="[camera]\nviews_per_scene = 3\n", canonical={"camera": {"views_per_scene": 4}})
    assert views_per_scene(tmp_path) == 4
    _manifest(tmp_path, text="# crackgen --set camera.views_per_scene=3\n[camera]\nviews_per_scene = 3  # views\n")
    assert views_per_scene(tmp_path) == 3
    _manifest(tmp_path, text="[camera]\nwidth_px = 64\n")
    assert views_per_scene(tmp_path) == 1


def test_a_broken_views_per_scene_is_named(tmp_path):
    _manifest(tmp_path, canonical={"camera": {"views_per_scene": 0}})
    with pytest.raises(ManifestError, match="views_per_scene must be a positive integer"):
        views_per_scene(tmp_path)
    _manifest(tmp_path, text="[camera\n")
    with pytest.raises(ManifestError, match="recipe_text is not valid TOML"):
        views_per_scene(tmp_path)


def test_scene_group_puts_the_views_of_one_scene_together():
    keys = [f"{i // 5:06d}-{i:05d}" for i in range(12)]  # shard-index keys, index global as the writer writes them
    assert [scene_group(k, 1) for k in keys] == keys
    groups = [scene_group(k, 4) for k in keys]
    assert groups == [f"scene-{i // 4:06d}" for i in range(12)]  # a scene straddling shards 0 and 1 stays one
    with pytest.raises(ValueError, match="does not end in a sample index"):
        scene_group("000000-abc", 4)
