"""The fusion hold-out split keeps the views of one scene together (``[camera] views_per_scene`` > 1)."""
from __future__ import annotations

import numpy as np
from fusion_samples import fusion_sample

from crackgen.shards import Manifest, ShardWriter, sample_key
from trainer.core.holdout import split_fraction
from trainer.depthfusion.config import FusionTrainConfig
from trainer.depthfusion.train import build_split


def _dataset(root, views: int):
    rng = np.random.default_rng(3)
    m = Manifest(root, recipe_text="", recipe_hash="h", recipe_canonical={"camera": {"views_per_scene": views}},
                 num_shards=3, shard_size=5)
    for s in range(3):
        with ShardWriter(root, s) as w:
            for i in range(s * 5, s * 5 + 5):  # 5 per shard, 3 views per scene: scenes straddle shards
                w.add(sample_key(s, i), fusion_sample(rng))
        m.mark_done(w.info)
    m.save()
    return root


def test_views_of_one_scene_are_never_on_both_sides(tmp_path):
    root = _dataset(tmp_path, views=3)
    train, val = build_split(FusionTrainConfig(data=str(root), val_fraction=0.4, split_seed=1))
    assert len(train) + len(val) == 15 and train and val
    scene = lambda k: int(k[-5:]) // 3  # noqa: E731
    assert not {scene(k) for k in train} & {scene(k) for k in val}
    assert len(val) % 3 == 0  # whole scenes held out


def test_one_view_per_scene_splits_as_before(tmp_path):
    root = _dataset(tmp_path, views=1)
    keys = [sample_key(i // 5, i) for i in range(15)]
    assert build_split(FusionTrainConfig(data=str(root), val_fraction=0.4, split_seed=1)) == split_fraction(
        keys, 0.4, 1)
