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


def _make(indices):
    producer = SampleProducer(RECIPE, threads=1)
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
