"""Dataset-level metrics and PR curve on hand-counted cases."""
import numpy as np
import pytest
import torch

from trainer.seg.metrics import ConfusionHistogram, plot_pr_curve, scores


def test_confusion_summed_over_images_matches_hand_count():
    h = ConfusionHistogram.empty()
    # image 1: prediction at 0.5 = [[1,0,1],[0,0,1]] -> TP 1, FN 1, FP 2, TN 2
    h.update(torch.tensor([[0.9, 0.2, 0.7], [0.1, 0.0, 0.6]]), torch.tensor([[1, 1, 0], [0, 0, 0]]))
    # image 2: prediction at 0.5 = [[0,1,0],[1,1,0]] (0.5 >= 0.5) -> TP 2, FN 1, FP 1, TN 2
    h.update(torch.tensor([[0.4, 0.8, 0.3], [0.5, 0.95, 0.49]]), torch.tensor([[0, 1, 0], [0, 1, 1]]))
    m = h.at(0.5)
    assert (m["tp"], m["fp"], m["fn"], m["tn"]) == (3, 3, 2, 4)
    assert m["accuracy"] == pytest.approx(7 / 12)
    assert m["precision"] == pytest.approx(3 / 6)
    assert m["recall"] == pytest.approx(3 / 5)
    assert m["f1"] == pytest.approx(6 / 11)
    assert m["iou"] == pytest.approx(3 / 8)


def test_scores_zero_division_is_zero():
    s = scores(0, 0, 10, 0)
    assert s["precision"] == 0 and s["recall"] == 0 and s["f1"] == 0 and s["accuracy"] == 1


def test_pr_curve_and_best_threshold_constructed(tmp_path):
    h = ConfusionHistogram.empty()
    # crack pixels 0.3, 0.8, 0.9; background pixels 0.1, 0.2, 0.85
    h.update(torch.tensor([0.3, 0.8, 0.9, 0.1, 0.2, 0.85]), torch.tensor([1, 1, 1, 0, 0, 0]))
    assert (h.at(0.0)["tp"], h.at(0.0)["fp"]) == (3, 3)  # everything positive at t = 0
    assert (h.at(0.30)["tp"], h.at(0.30)["fp"]) == (3, 1)  # p >= t, 0.3 counts
    assert (h.at(0.31)["tp"], h.at(0.31)["fp"]) == (2, 1)
    assert (h.at(0.86)["tp"], h.at(0.86)["fp"]) == (1, 0)
    assert (h.at(1.0)["tp"], h.at(1.0)["fp"]) == (0, 0)
    best = h.best()
    # F1 by hand: t<=0.1: 6/9, (0.1,0.2]: 6/8, (0.2,0.3]: 6/7, (0.3,0.8]: 4/6, (0.8,0.85]: 2/4+..., best 6/7
    assert best["threshold"] == pytest.approx(0.21)  # lowest threshold with the best F1
    assert best["f1"] == pytest.approx(6 / 7)
    assert best["precision"] == pytest.approx(3 / 4) and best["recall"] == pytest.approx(1.0)
    curve = h.pr_curve()
    assert len(curve["threshold"]) == 101
    assert np.all(np.diff(curve["recall"]) <= 0)  # recall never rises with the threshold
    plot_pr_curve(h, tmp_path / "pr.png")
    assert (tmp_path / "pr.png").stat().st_size > 1000


def test_histogram_equals_101_direct_passes():
    g = torch.Generator().manual_seed(0)
    p = torch.rand(5000, generator=g)
    t = torch.rand(5000, generator=g) < 0.3
    h = ConfusionHistogram.empty()
    h.update(p[:2000], t[:2000])
    h.update(p[2000:], t[2000:])
    c = h.confusion()
    for k in (0, 7, 50, 99, 100):
        pred = p >= torch.tensor(k / 100, dtype=torch.float64).float()
        assert c["tp"][k] == int((pred & t).sum()) and c["fp"][k] == int((pred & ~t).sum())
        assert c["fn"][k] == int((~pred & t).sum()) and c["tn"][k] == int((~pred & ~t).sum())
