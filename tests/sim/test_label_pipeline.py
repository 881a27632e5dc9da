"""[label] in the pipeline (tiny renders): mask_thesis.png is written and read back; redraws are deterministic."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
from tiny_recipes import tiny_recipe

import crackgen.sim.groundtruth as groundtruth
from crackgen.config.recipe import parse_recipe
from crackgen.config.spec import make_spec
from crackgen.datagen.pipeline import SampleProducer
from crackgen.shards import ShardWriter, iter_samples, sample_key

pytestmark = [pytest.mark.blender, pytest.mark.slow]

def test_visible_policy_writes_both_labels_and_they_read_back(tmp_path):
    recipe = parse_recipe(tiny_recipe(5, lidar=False))
    p = SampleProducer(recipe, threads=1)
    s = p.make(0)
    p.close()
    m, meta = s.members, s.meta
    assert {"mask.png", "mask_thesis.png"} <= set(m)
    vis, thesis = m["mask.png"] > 0, m["mask_thesis.png"] > 0
    # inside the thesis mask, or on the walls of the rendered groove just beside it (tests/sim/test_groove_label.py)
    near_thesis = cv2.dilate(thesis.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    assert not (vis & ~near_thesis).any()
    lab = meta["label"]
    assert lab["policy"] == "visible" and lab["attempt"] == 0 and lab["action"] in ("ok", "empty")
    assert lab["pixel_fraction"] == pytest.approx(vis.mean())
    assert lab["thesis_pixel_fraction"] == pytest.approx(thesis.mean())
    with ShardWriter(tmp_path, 0) as w:
        w.add(sample_key(0, 0), {**m, "json": meta})
    (got,) = iter_samples(tmp_path / "shard-000000.tar", members=["mask", "mask_thesis"])
    np.testing.assert_array_equal(got["mask_thesis"], m["mask_thesis.png"])
    np.testing.assert_array_equal(got["mask"], m["mask.png"])


def test_redraw_draws_new_cracks_then_falls_back_to_empty(monkeypatch):
    calls = []

    def never_shows(rgb, label):
        calls.append(int(np.count_nonzero(label)))
        return 0.0

    monkeypatch.setattr(groundtruth, "label_contrast", never_shows)
    recipe = parse_recipe(tiny_recipe(5, lidar=False) + "[label]\ninvisible = \"redraw\"\nmax_redraws = 1\n")
    p = SampleProducer(recipe, threads=1)
    s = p.make(0)
    p.close()
    assert len(calls) == 2  # attempt 0, then one redraw
    lab = s.meta["label"]
    assert lab["attempt"] == 1 and lab["action"] == "empty" and lab["pixel_fraction"] == 0.0
    assert not (s.members["mask.png"] > 0).any() and (s.members["mask_thesis.png"] > 0).any()
    assert s.meta["spec"] == make_spec(recipe, 0, attempt=1).to_dict()  # the redrawn crack, reproducible
    assert s.meta["spec"]["crack"] != make_spec(recipe, 0).to_dict()["crack"]
    assert s.meta["spec"]["camera"] == make_spec(recipe, 0).to_dict()["camera"]
