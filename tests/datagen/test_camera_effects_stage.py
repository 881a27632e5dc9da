"""[camera_effects] in the generator: only the RGB views change, both the same way; labels stay aligned."""
from __future__ import annotations

import numpy as np
import pytest
from tiny_recipes import tiny_recipe

from crackgen.config.recipe import RecipeError, parse_recipe
from crackgen.datagen.pipeline import STAGES, SampleProducer
from fusion.geometry.stereo import sgbm_disparity

ALL_ON = "[camera_effects]\nenabled = true\nexposure = 1.0\nvignetting = 1.0\nnoise = 1.0\njpeg = 1.0\n"


def _make(extra: str):
    prod = SampleProducer(parse_recipe(tiny_recipe(5, stereo=True, lidar=False) + extra), threads=1)
    try:
        return prod.make(0), prod.make(0)
    finally:
        prod.close()


@pytest.mark.blender
@pytest.mark.slow
def test_only_rgb_views_change_and_metadata_says_how():
    (a, _), (b, again) = _make(""), _make(ALL_ON)
    for k in a.members:
        if k in ("rgb.png", "right.png"):
            assert not np.array_equal(a.members[k], b.members[k]), k
            assert b.members[k].shape == a.members[k].shape and b.members[k].dtype == np.uint8
        elif isinstance(a.members[k], dict):
            for c in a.members[k]:
                assert np.array_equal(a.members[k][c], b.members[k][c]), k
        else:
            assert np.array_equal(a.members[k], b.members[k]), k  # mask, depth, sensors: byte-identical
    fx = b.meta["camera_effects"]
    assert fx["applied"][:2] == ["exposure", "vignetting"] and {"noise", "jpeg"} <= set(fx["applied"])
    assert fx["views"] == ["rgb", "right"] and a.meta["camera_effects"] == {"applied": []}
    assert b.meta["spec"]["camera_effects"]["jpeg_quality"] == fx["jpeg_quality"]
    # deterministic per seed
    assert np.array_equal(b.members["rgb.png"], again.members["rgb.png"]) and b.meta == again.meta
    assert STAGES.index("camera_effects") == STAGES.index("adapt") - 1 and "camera_effects" in b.timings


@pytest.mark.blender
@pytest.mark.slow
def test_sgbm_can_match_the_views_the_camera_saw():
    """sgbm_input = "camera": SGBM reads the very RGB views stored after the camera effects; nothing else changes."""
    camera = ALL_ON + "defocus = 1.0\n"
    clean, _ = _make(camera)
    text = tiny_recipe(5, stereo=True, lidar=False).replace(
        "[stereo]\nenabled = true\n", '[stereo]\nenabled = true\nsgbm_input = "camera"\n') + camera
    prod = SampleProducer(parse_recipe(text), threads=1)
    try:
        seen, again = prod.make(0), prod.make(0)
    finally:
        prod.close()
    for k in ("rgb.png", "right.png", "mask.png", "depth.exr", "disp_gt.exr"):
        assert np.array_equal(clean.members[k], seen.members[k]), k  # the same images and labels
    sgm = seen.members["disp_sgm.exr"]
    assert not np.array_equal(clean.members["disp_sgm.exr"], sgm)  # noise, blur and JPEG reach the matcher
    recomputed = sgbm_disparity(seen.members["rgb.png"], seen.members["right.png"], 16, 5)
    assert np.array_equal(recomputed, sgm)  # ... exactly the stored views
    assert seen.meta["sensors"]["stereo"]["sgbm_input"] == "camera"
    assert seen.meta["camera_effects"] == clean.meta["camera_effects"]
    assert np.array_equal(again.members["disp_sgm.exr"], sgm)  # deterministic per seed


def test_sgbm_on_camera_views_needs_camera_effects():
    text = tiny_recipe(5, stereo=True, lidar=False).replace(
        "[stereo]\nenabled = true\n", '[stereo]\nenabled = true\nsgbm_input = "camera"\n')
    with pytest.raises(RecipeError, match=r"stereo\.sgbm_input: \"camera\" needs \[camera_effects\]"):
        parse_recipe(text)
