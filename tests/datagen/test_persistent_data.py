"""With Cycles persistent data a sample must still depend only on (recipe, index), not on what its worker
rendered before: the shadow occluder once kept a stale alpha image across a sample without a shadow."""
from __future__ import annotations

import numpy as np
from tiny_recipes import tiny_recipe

from crackgen.config.recipe import parse_recipe
from crackgen.config.spec import make_spec
from crackgen.datagen.pipeline import SampleProducer

RECIPE = parse_recipe(tiny_recipe(21, name="pd", samples=4, shard_size=2, spp=2)
                      .replace("[render]\n", "[render]\npersistent_data = true\n", 1))


def _make(indices, recipe=RECIPE):
    producer = SampleProducer(recipe, threads=1)
    try:
        return {i: producer.make(i).members for i in indices}
    finally:
        producer.close()


def test_a_sample_after_others_renders_as_in_a_fresh_worker():
    # shadow, none, shadow, shadow: sample 3's occluder image was the one shown before the shadow-free sample
    assert [make_spec(RECIPE, i).shadow.enabled for i in range(4)] == [True, False, True, True]
    after = _make(range(4))
    fresh = _make([1, 3])
    for i in (1, 3):
        for key in ("rgb.png", "mask.png", "depth.exr"):
            np.testing.assert_array_equal(after[i][key], fresh[i][key], err_msg=f"sample {i} {key}")


def test_views_of_a_scene_render_as_in_a_fresh_worker_with_persistent_data():
    # K = 3 with persistent data: the views after a scene's first keep the mesh and textures Cycles holds;
    # a worker that starts inside a scene (resume, another worker's shard) uploads them fresh, and must match
    text = tiny_recipe(21, name="pd_views", samples=6, shard_size=2, spp=2)
    text = text.replace("[render]\n", "[render]\npersistent_data = true\n", 1).replace("[camera]\n", "[camera]\nviews_per_scene = 3\n", 1)
    recipe = parse_recipe(text)
    assert recipe.camera.views_per_scene == 3 and recipe.render.persistent_data
    after = _make(range(6), recipe)
    fresh = _make([1, 2, 5], recipe)
    for i in (1, 2, 5):
        for key in ("rgb.png", "mask.png", "depth.exr"):
            np.testing.assert_array_equal(after[i][key], fresh[i][key], err_msg=f"sample {i} {key}")
