"""Label-efficiency curve: nested, seeded subsets from the training split; headline arithmetic."""
import pytest

from trainer.core.errors import TrainerInputError
from trainer.core.holdout import split_fraction
from trainer.experiments.curve import CurvePoint, headline, labels_to_match, nested_subsets, parse_sizes, summarise


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
    with pytest.raises(TrainerInputError, match="--sizes"):
        parse_sizes("10,x")


def _pt(n, arm, f1, r=0):
    return CurvePoint(n=n, repeat=r, arm=arm, f1=f1, precision=0, recall=0, iou=0, threshold=0.5, f1_at_05=f1 / 2,
                      oracle_f1=f1 + 0.01, steps=1, total_steps=1 + 600 * (arm == "finetune"), seconds=1,
                      cross={"walls": f1 / 3} if r % 2 else {})


def test_labels_to_match_and_headline():
    pts = [_pt(10, "real", 0.30), _pt(30, "real", 0.50), _pt(60, "real", 0.70), _pt(120, "real", 0.80),
           _pt(30, "finetune", 0.58, 0), _pt(30, "finetune", 0.62, 1)]
    s = summarise(pts)
    assert s["finetune"][30]["mean"] == pytest.approx(0.60)
    assert s["finetune"][30]["std"] == pytest.approx(0.0282842712, rel=1e-6)  # sample sd: sqrt(0.02**2 * 2 / 1)
    assert summarise(pts, "f1:walls")["finetune"][30] == pytest.approx(
        {"mean": 0.62 / 3, "std": 0.0, "min": 0.62 / 3, "max": 0.62 / 3, "count": 1})  # one repeat has the set
    # 0.60 lies halfway between N=30 (0.50) and N=60 (0.70): 45 photos
    assert labels_to_match(s["real"], 0.60) == pytest.approx(45.0)
    assert "about 45 photos" in headline(s, 30) and "1.5x" in headline(s, 30)
    assert labels_to_match(s["real"], 0.95) is None
    assert "does not reach it" in headline(summarise([_pt(10, "real", 0.1), _pt(30, "finetune", 0.9)]))


def test_csv_round_trip_keeps_every_field(tmp_path):
    from trainer.experiments.curve import read_csv, write_csv

    pts = [_pt(10, "real", 0.31, 0), _pt(30, "finetune", 0.625, 2)]
    write_csv(pts, tmp_path / "curve.csv")
    assert read_csv(tmp_path / "curve.csv") == pts
    assert read_csv(tmp_path / "missing.csv") == []
    (tmp_path / "bad.csv").write_text("a,b\n1,2\n")
    with pytest.raises(TrainerInputError, match="not a curve CSV"):
        read_csv(tmp_path / "bad.csv")


def test_curve_continues_only_with_the_same_settings(tmp_path):
    import argparse

    from trainer.core.options import options_from
    from trainer.experiments.config import ExperimentOptions
    from trainer.experiments.sim2real import add_curve_args, check_curve_settings

    p = argparse.ArgumentParser()
    add_curve_args(p)
    args = options_from(ExperimentOptions, p.parse_args(["--data", "s", "--real", "r", "--sizes", "0,10",
                                                          "--curve-steps", "100"]))
    check_curve_settings(args, tmp_path, None)  # first run records them
    check_curve_settings(args, tmp_path, None)  # the same settings continue
    args.curve, args.repeats = "0,10,30", 5  # more sizes and repeats extend the same curve
    check_curve_settings(args, tmp_path, None)
    args.curve_steps = 200
    with pytest.raises(TrainerInputError, match=r"curve_steps 100 -> 200"):
        check_curve_settings(args, tmp_path, None)
    other = tmp_path / "other"
    other.mkdir()
    (other / "curve.csv").write_text("n\n")
    with pytest.raises(TrainerInputError, match="no curve_settings.json"):
        check_curve_settings(args, other, None)


def test_train_or_reuse_keeps_finished_and_resumes_interrupted(tmp_path, monkeypatch):

    import torch

    import trainer.experiments.sim2real as s2r
    from trainer.seg.config import SegTrainConfig

    calls = []
    monkeypatch.setattr(s2r, "train_seg", lambda ns: calls.append(ns.resume) or {"step": ns.max_steps, "seconds": 1.0})

    def ns(name, init=None):
        (tmp_path / name).mkdir(exist_ok=True)
        return SegTrainConfig(out=str(tmp_path / name), max_steps=100, init=init, precise_bn=None, resume=None)

    def ckpt(name, step, init=None, precise_bn=None, **extra):
        torch.save({"model": {}, "args": {"init": init, "precise_bn": precise_bn}, "sample_config": {}, "step": step,
                    **extra}, tmp_path / name / "checkpoint.pt")

    assert s2r.train_or_reuse(ns("fresh"))["seconds"] == 1.0 and calls == [None]  # nothing there: trains
    n = ns("done", init="pre.pt")
    ckpt("done", 100, init="pre.pt", finished=True)
    assert s2r.train_or_reuse(n)["seconds"] == 0.0 and len(calls) == 1  # finished: kept
    n = ns("done_no_bn")
    n.precise_bn = 50
    ckpt("done_no_bn", 100, finished=True)  # finished without the precise BN now asked for: resumed to add it
    s2r.train_or_reuse(n)
    assert calls[-1] == str(tmp_path / "done_no_bn" / "checkpoint.pt")
    n = ns("killed", init="pre.pt")
    ckpt("killed", 40)
    s2r.train_or_reuse(n)
    assert calls[-1] == str(tmp_path / "killed" / "checkpoint.pt")  # interrupted: resumed
    n = ns("no_bn_yet", init="pre.pt")
    ckpt("no_bn_yet", 100)  # all steps done, precise BN (fine-tune) may not be: resumed, which redoes it
    s2r.train_or_reuse(n)
    assert calls[-1] == str(tmp_path / "no_bn_yet" / "checkpoint.pt")
    n = ns("old_pretrain")
    ckpt("old_pretrain", 100)  # no precise BN without --init: a checkpoint at the last step is final
    assert s2r.train_or_reuse(n)["seconds"] == 0.0
