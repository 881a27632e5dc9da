"""cracktrain benchmark: the table on hand-made models and folders, thresholds from validation, refusals."""
import csv
import json
import math
import re
from pathlib import Path

import cv2
import numpy as np
import pytest
from real_folders import train_tiny_model, write_real_folder

from trainer.cli import main
from trainer.core.errors import TrainerInputError
from trainer.experiments.benchmark import core_seconds_per_sample, parse_costs, parse_renders
from trainer.experiments.config import BenchmarkOptions
from trainer.experiments.eval_sets import parse_set
from trainer.experiments.scoreboard import (
    EvalSet,
    ModelEntry,
    markdown_lines,
    plot_cost,
    plot_volume,
    score_all,
    summarise,
    write_csv,
)
from trainer.seg.metrics import ConfusionHistogram
from trainer.seg.sources import RealFolder

# One 2x4 photo: grey 0 (dark) or 200; the crack label marks two dark pixels and one bright one.
GREY = np.array([[0, 0, 200, 200], [0, 200, 200, 200]], np.uint8)
LABEL = np.array([[1, 1, 0, 0], [0, 0, 0, 1]], np.uint8) * 255


def write_folder(root, images, masks=None):
    (root / "images").mkdir(parents=True)
    (root / "masks").mkdir()
    for name, grey in images.items():
        cv2.imwrite(str(root / "images" / f"{name}.png"), np.repeat(grey[..., None], 3, 2))
    for name, m in (masks or {}).items():
        cv2.imwrite(str(root / "masks" / f"{name}.png"), m)
    return root


class Grey:
    """A hand-made model: crack probability = 1 - grey/255 ('dark') or grey/255 ('bright')."""

    def __init__(self, bright: bool) -> None:
        self.bright = bright

    def histogram(self, folder: RealFolder) -> ConfusionHistogram:
        hist = ConfusionHistogram.empty()
        import torch

        for k in folder.keys:
            s = folder.load(k)
            p = s["rgb"][..., 0].astype(np.float32) / 255.0
            hist.update(torch.from_numpy(p if self.bright else 1.0 - p), torch.from_numpy(s["mask"] > 127))
        return hist


def test_table_matches_the_hand_computed_one(tmp_path):
    one = write_folder(tmp_path / "one", {"x": GREY}, {"x": LABEL})
    # the second set is the first photo twice, one of them with every label flipped
    two = write_folder(tmp_path / "two", {"x": GREY, "y": GREY}, {"x": LABEL, "y": 255 - LABEL})
    sets = [EvalSet("one", RealFolder(one), "one photo"), EvalSet("two", RealFolder(two), "two photos")]
    entries = [ModelEntry("dark", "dark_s0", 0.5, "hand", Grey(False)),
               ModelEntry("dark", "dark_s1", 0.1, "hand", Grey(False)),
               ModelEntry("bright", "bright", 0.3, "hand", Grey(True))]
    rows = {(r.model, r.set): r for r in score_all(entries, sets)}

    # dark at 0.5 on 'one': predicts the 3 dark pixels; TP 2, FP 1, FN 1
    r = rows["dark_s0", "one"]
    assert (r.precision, r.recall, r.f1, r.iou) == pytest.approx((2 / 3, 2 / 3, 2 / 3, 0.5))
    assert r.f1_at_0_5 == pytest.approx(2 / 3)
    # oracle: every threshold above the bright pixels' 1 - 200/255 = 0.216 gives 2/3; the lowest is 0.22
    assert r.oracle_f1 == pytest.approx(2 / 3) and r.oracle_threshold == pytest.approx(0.22)
    # dark at 0.1: everything is crack; TP 3, FP 5, FN 0
    r = rows["dark_s1", "one"]
    assert (r.precision, r.recall, r.f1, r.iou) == pytest.approx((3 / 8, 1.0, 6 / 11, 3 / 8))
    # bright at 0.3 predicts the 5 bright pixels: TP 1, FP 4, FN 2
    r = rows["bright", "one"]
    assert (r.precision, r.recall, r.f1, r.iou) == pytest.approx((1 / 5, 1 / 3, 1 / 4, 1 / 7))
    # on 'two' the flipped copy adds TP 1, FP 2, FN 4 at 0.5 (its crack = the 5 bright and the 3rd dark pixel)
    r = rows["dark_s0", "two"]
    assert (r.precision, r.recall) == pytest.approx((3 / 6, 3 / 8))
    assert r.f1 == pytest.approx(6 / (6 + 3 + 5))

    summ = summarise(list(rows.values()))
    mean, sd, n = summ["dark"]["one"]["f1"]
    assert n == 2 and mean == pytest.approx((2 / 3 + 6 / 11) / 2)
    assert sd == pytest.approx(abs(2 / 3 - 6 / 11) / math.sqrt(2))  # sample sd (ddof 1) of two values
    assert math.isnan(summ["bright"]["one"]["f1"][1])  # one model: no spread is claimed
    md = "\n".join(markdown_lines(list(rows.values()), sets))
    assert f"| dark | 2 | {mean:.3f} ± {sd:.3f} |" in md and "| bright | 1 | 0.250 |" in md
    write_csv(list(rows.values()), tmp_path / "b.csv")
    assert len(list(csv.DictReader(open(tmp_path / "b.csv")))) == 6
    # what a row's training sample cost: a column, and F1 against it
    costed = "\n".join(markdown_lines(list(rows.values()), sets, {"dark": 8.25}))
    assert "| model | n | core-s / sample | one | two |" in costed
    assert f"| dark | 2 | 8.25 | {mean:.3f} ± {sd:.3f} |" in costed and "| bright | 1 | – | 0.250 |" in costed
    plot_cost(list(rows.values()), sets, {"dark": 8.25, "bright": 2.0}, tmp_path / "cost.png", "t")
    assert (tmp_path / "cost.png").stat().st_size > 0
    # how many renders a row trained on: a column before the cost, and the data-volume curve
    both = "\n".join(markdown_lines(list(rows.values()), sets, {"dark": 8.25}, {"dark": 800, "bright": 200}))
    assert "| model | n | renders | core-s / sample | one | two |" in both
    assert f"| dark | 2 | 800 | 8.25 | {mean:.3f} ± {sd:.3f} |" in both and "| bright | 1 | 200 | – | 0.250 |" in both
    plot_volume(list(rows.values()), sets, {"dark": 800, "bright": 200}, tmp_path / "volume.png", "t")
    assert (tmp_path / "volume.png").stat().st_size > 0


def test_cost_comes_from_a_crackgen_bench_file_and_bad_ones_are_one_line(tmp_path):
    bench = tmp_path / "bench.json"
    bench.write_text(json.dumps({"mean_total_s": 4.125, "threads": 2, "median_total_s": 4.0}))
    assert core_seconds_per_sample(bench) == pytest.approx(8.25)
    assert parse_costs([f"a={bench}"], ["a", "b"]) == {"a": pytest.approx(8.25)}
    (tmp_path / "bad.json").write_text(json.dumps({"median_total_s": 4.0}))
    for spec, msg in ((f"c={bench}", "no model row is labelled 'c'"), ("a", "expected LABEL=BENCH.json"),
                      (f"a={tmp_path / 'none.json'}", "no such file"),
                      (f"a={tmp_path / 'bad.json'}", "not a `crackgen bench --json` file")):
        with pytest.raises(TrainerInputError, match=re.escape(msg)):
            parse_costs([spec], ["a", "b"])
    with pytest.raises(TrainerInputError, match="given twice"):
        parse_costs([f"a={bench}", f"a={bench}"], ["a"])


def test_renders_name_a_row_and_a_positive_count_or_are_refused_in_one_line():
    assert parse_renders(["a=400", "b=1600"], ["a", "b"]) == {"a": 400, "b": 1600}
    for spec, msg in (("c=400", "no model row is labelled 'c'"), ("a", "expected LABEL=N"),
                      ("a=many", "'many' is not a whole number of renders > 0"), ("a=0", "'0' is not a whole number"),
                      ("a=2.5", "'2.5' is not a whole number")):
        with pytest.raises(TrainerInputError, match=re.escape(msg)):
            parse_renders([spec], ["a", "b"])
    with pytest.raises(TrainerInputError, match="--renders: 'a' given twice"):
        parse_renders(["a=1", "a=2"], ["a"])


def _set_args(**kw):
    return BenchmarkOptions(models=[], out="unused", **kw)


def test_a_folder_with_mismatched_names_is_refused_in_one_line(tmp_path, capsys):
    bad = write_folder(tmp_path / "bad", {"a": GREY, "b": GREY}, {"a": LABEL, "c": LABEL})
    with pytest.raises(TrainerInputError, match=r"1 image\(s\) without a mask \(b\); 1 mask\(s\) without an image \(c\)"):
        parse_set(f"bad={bad}", _set_args())
    good = write_folder(tmp_path / "good", {"a": GREY}, {"a": LABEL})
    assert main(["benchmark", str(tmp_path / "nope.pt"), "--set", f"bad={bad}", "--set", f"good={good}",
                 "--out", str(tmp_path / "o"), "--no-progress"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bad" in err[0] and "without a mask" in err[0]
    assert not (tmp_path / "o").exists()  # refused before anything was written


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    return train_tiny_model(tmp_path_factory.mktemp("bench"))


def test_benchmark_cli_scores_checkpoints_at_their_validation_threshold(tiny, tmp_path):
    other = write_real_folder(tmp_path / "other", n=4)
    val = write_real_folder(tmp_path / "val", n=3)
    out = tmp_path / "b"
    bench = tmp_path / "bench.json"
    bench.write_text(json.dumps({"mean_total_s": 1.5, "threads": 2}))
    assert main(["benchmark", f"tiny={tiny['ckpt']}", f"tiny={tiny['ckpt']}", "--set", f"other={other}",
                 "--val", f"v={val}", "--cost", f"tiny={bench}", "--renders", "tiny=400", "--out", str(out), "-j", "0",
                 "--no-progress"]) == 0
    rows = list(csv.DictReader(open(out / "benchmark.csv")))
    assert len(rows) == 2 and {r["set"] for r in rows} == {"other"}
    assert rows[0]["threshold_source"] == "benchmark --val v"  # the tiny model stored none: chosen on --val
    assert (out / "benchmark.png").stat().st_size > 0 and "| tiny | 2 | 400 | 3.00 |" in (out / "benchmark.md").read_text()
    assert (out / "cost.png").stat().st_size > 0 and (out / "volume.png").stat().st_size > 0
    record = json.loads((out / "benchmark.json").read_text())
    assert record["core_seconds_per_sample"] == {"tiny": 3.0} and record["renders"] == {"tiny": 400}
    # --errors: what the row's first model gets wrong, with overlays of its worst images
    assert main(["benchmark", f"tiny={tiny['ckpt']}", "--set", f"other={other}", "--val", f"v={val}", "--errors", "2",
                 "--out", str(tmp_path / "e"), "-j", "0", "--no-progress"]) == 0
    errors = json.loads((tmp_path / "e" / "errors.json").read_text())["tiny"]["other"]
    assert errors["images"] == 4 and len(errors["overlays"]) <= 2 and errors["fp"] >= 0
    assert all(Path(p).is_file() for p in errors["overlays"]) and "| tiny | other |" in (tmp_path / "e" / "benchmark.md").read_text()
    # flipping every label of the scored set leaves the threshold as it was: it never looks at them
    flipped = tmp_path / "flipped"
    write_real_folder(flipped, n=4)
    for m in (flipped / "masks").iterdir():
        cv2.imwrite(str(m), 255 - cv2.imread(str(m), cv2.IMREAD_GRAYSCALE))
    assert main(["benchmark", f"tiny={tiny['ckpt']}", "--set", f"other={flipped}", "--val", f"v={val}",
                 "--out", str(tmp_path / "f"), "-j", "0", "--no-progress"]) == 0
    again = list(csv.DictReader(open(tmp_path / "f" / "benchmark.csv")))
    assert again[0]["threshold"] == rows[0]["threshold"] and again[0]["f1"] != rows[0]["f1"]


def test_a_model_is_refused_on_photos_of_groups_it_trained_on(tiny, tmp_path, capsys):
    # the tiny model trained on every photo of tiny['real']; a set that is a symlinked part of it is refused
    part = tmp_path / "part"
    for sub in ("images", "masks"):
        (part / sub).mkdir(parents=True)
        (part / sub / "003.png").symlink_to(tiny["real"] / sub / "003.png")
    assert main(["benchmark", str(tiny["ckpt"]), "--set", f"part={part}", "--val", "none",
                 "--out", str(tmp_path / "o"), "--no-progress"]) == 1
    assert "trained on photos of 1 group(s) of set part (003)" in capsys.readouterr().err


def test_seg_stores_the_validation_threshold_and_predict_uses_it(tmp_path):
    import json

    from trainer.core.checkpoint import load_checkpoint

    real, val = write_real_folder(tmp_path / "r", n=8), write_real_folder(tmp_path / "v", n=3)
    run = tmp_path / "run"
    assert main(["seg", "--real", str(real), "--val-real", str(val), "--val-every", "-1", "--max-steps", "2",
                 "--arch", "unet", "-b", "2", "--crop", "32", "-j", "0", "--no-progress", "--out", str(run)]) == 0
    rec = load_checkpoint(run / "checkpoint.pt")["val_threshold"]
    assert rec["chosen_on"] == f"--val-real {val}" and rec["photos"] == 3 and 0.0 <= rec["threshold"] <= 1.0
    assert load_checkpoint(run / "best.pt")["val_threshold"]["threshold"] == rec["threshold"]
    val_rows = [r for r in csv.DictReader(open(run / "log.csv")) if r["kind"] == "val" and r["name"] == "f1"]
    assert len(val_rows) == 1  # --val-every -1: validated once, after training
    assert main(["predict", str(real), "-c", str(run / "checkpoint.pt"), "--out", str(tmp_path / "p"),
                 "--no-progress"]) == 0
    rep = json.loads((tmp_path / "p" / "000.json").read_text())
    assert rep["threshold"] == rec["threshold"] and rep["threshold_source"].startswith("validation")


def test_seg_val_fraction_on_real_data_keeps_groups_whole(tmp_path):
    from trainer.seg.real_split import read_split

    root = tmp_path / "tiles"
    write_real_folder(root, n=12)
    for i, p in enumerate(sorted((root / "images").iterdir())):  # 4 photos cut into 3 tiles each: NAME-k
        for sub in ("images", "masks"):
            (root / sub / p.name).rename(root / sub / f"photo{i // 3}-{i % 3}.png")
    run = tmp_path / "run"
    assert main(["seg", "--real", str(root), "--val-fraction", "0.25", "--val-every", "-1", "--max-steps", "1",
                 "--arch", "unet", "-b", "2", "--crop", "32", "-j", "0", "--no-progress", "--out", str(run)]) == 0
    split = read_split(run)
    assert len(split.val) == 3 and len({s.split("-")[0] for s in split.val}) == 1  # one whole photo
    assert not {s.split("-")[0] for s in split.val} & {s.split("-")[0] for s in split.train}


def test_a_moved_sim2real_folder_names_its_own_checkpoints(tmp_path):
    """sim2real.json records where each row's checkpoint was written; a renamed copy must score its own."""
    import shutil

    from trainer.experiments.benchmark import expand_model

    first = tmp_path / "run_a"
    for row in ("synthetic", "real"):
        (first / row).mkdir(parents=True)
        (first / row / "checkpoint.pt").write_bytes(row.encode())
    runs = {row: {"checkpoint": str(first / row / "checkpoint.pt"), "test": {}} for row in ("synthetic", "real")}
    (first / "sim2real.json").write_text(json.dumps({"runs": runs}))
    moved = tmp_path / "run_b"
    shutil.move(first, moved)
    shutil.copytree(moved, first)  # the original is back too: the moved copy must not point at it
    found = dict(expand_model(f"v1={moved}"))
    assert found == {"v1 synthetic": moved / "synthetic" / "checkpoint.pt", "v1 real": moved / "real" / "checkpoint.pt"}
    assert expand_model(str(first))[0][1] == first / "synthetic" / "checkpoint.pt"
