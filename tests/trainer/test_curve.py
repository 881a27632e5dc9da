"""Label-efficiency curve: nested, seeded subsets from the training split; headline arithmetic."""
import pytest

from trainer.curve import CurvePoint, headline, labels_to_match, nested_subsets, parse_sizes, summarise
from trainer.errors import TrainerInputError
from trainer.sources import split_fraction


def test_subsets_nested_seeded_and_disjoint_from_test():
    names = [f"{i:05d}" for i in range(300)]
    train, test = split_fraction(names, 0.2, seed=0)
    sizes = parse_sizes("0,10,30,60,120,240")
    subs = [nested_subsets(train, sizes, seed=0, repeat=r) for r in range(3)]
    for s in subs:
        for a, b in zip(sizes, sizes[1:]):
            assert set(s[a]) <= set(s[b]) and len(s[b]) == b
        assert not set(s[240]) & set(test)
    assert subs[0][10] != subs[1][10]  # repeats draw different photos
    assert nested_subsets(train, sizes, 0, 1) == subs[1]  # and are reproducible
    with pytest.raises(TrainerInputError, match="training split has 240"):
        nested_subsets(train, [241], 0, 0)
    with pytest.raises(TrainerInputError, match="--curve"):
        parse_sizes("10,x")


def _pt(n, arm, f1, r=0):
    return CurvePoint(n=n, repeat=r, arm=arm, f1=f1, precision=0, recall=0, iou=0, threshold=0.5, steps=1, seconds=1)


def test_labels_to_match_and_headline():
    pts = [_pt(10, "real", 0.30), _pt(30, "real", 0.50), _pt(60, "real", 0.70), _pt(120, "real", 0.80),
           _pt(30, "finetune", 0.58, 0), _pt(30, "finetune", 0.62, 1)]
    s = summarise(pts)
    assert s["finetune"][30]["mean"] == pytest.approx(0.60)
    # 0.60 lies halfway between N=30 (0.50) and N=60 (0.70): 45 photos
    assert labels_to_match(s["real"], 0.60) == pytest.approx(45.0)
    assert "about 45 photos" in headline(s, 30) and "1.5x" in headline(s, 30)
    assert labels_to_match(s["real"], 0.95) is None
    assert "does not reach it" in headline(summarise([_pt(10, "real", 0.1), _pt(30, "finetune", 0.9)]))
