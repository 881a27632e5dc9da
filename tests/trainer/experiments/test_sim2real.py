"""sim2real rows with site adaptation and fine-tuning, the label-efficiency curve, --init."""
import csv
import json

import pytest
import torch
from real_folders import write_real_folder
from synthetic_shards import write_shards

from trainer.cli import main
from trainer.core.checkpoint import load_checkpoint
from trainer.seg.appearance import SiteAdaptation
from trainer.seg.augment import SampleConfig
from trainer.seg.sources import RealFolder, ShardSource
from trainer.seg.stream import SegStream


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    base = tmp_path_factory.mktemp("sim2real")
    return {"real": write_real_folder(base / "real", n=12), "shards": write_shards(base / "shards", per_shard=4)}


COMMON = ["--arch", "unet", "--batch-size", "2", "--crop", "32", "--workers", "0", "--no-progress"]


def test_rows_with_adaptation_and_finetune(data, tmp_path, capsys):
    out = tmp_path / "s2r"
    rc = main(["sim2real", "--data", str(data["shards"]), "--real", str(data["real"]),
               "--test-fraction", "0.25", "--target", "--max-steps", "4",
               "--runs", "synthetic,synthetic+fourier,synthetic+adapt,real,finetune", "--out", str(out), *COMMON])
    assert rc == 0
    table = json.loads((out / "sim2real.json").read_text())
    assert list(table["runs"]) == ["synthetic", "synthetic+fourier", "synthetic+adapt", "real", "finetune"]
    # the target is the training images of the 12 (the validation and test photos held out), never the others
    assert table["real_test_images"] == 3 and table["real_val_images"] == 2
    assert table["target"].endswith(f": {table['real_train_images']} photos") and table["real_train_images"] == 7
    ft = table["runs"]["finetune"]
    assert ft["pretrain_steps"] == 2 and ft["steps"] == 4 and ft["pretrain_adapted"] is True
    for name, r in table["runs"].items():
        assert 0.0 <= r["test"]["f1"] <= 1.0 and 0.0 <= r["oracle"]["f1"] <= 1.0
        # the threshold was chosen on the validation split and stored with the model that is scored
        assert load_checkpoint(out / name / "checkpoint.pt")["val_threshold"]["threshold"] == r["threshold"]
        assert r["oracle"]["f1"] >= r["test"]["f1"]  # the test-label optimum is an upper bound
    # the fine-tuned model started from the pretrained one and trained 2 more steps on real photos
    assert load_checkpoint(out / "finetune" / "checkpoint.pt")["step"] == 2
    assert "| synthetic+fourier |" in capsys.readouterr().out


def test_adaptation_rows_need_a_target(data, tmp_path, capsys):
    rc = main(["sim2real", "--data", str(data["shards"]), "--real", str(data["real"]),
               "--test-fraction", "0.25", "--runs", "synthetic+fourier", "--out", str(tmp_path), *COMMON])
    assert rc == 1 and "needs --target" in capsys.readouterr().err
    rc = main(["sim2real", "--data", str(data["shards"]), "--real", str(data["real"]),
               "--test-fraction", "0.25", "--target", str(tmp_path / "nope"), "--out", str(tmp_path), *COMMON])
    assert rc == 1 and "no such folder" in capsys.readouterr().err


def test_curve_writes_csv_plot_and_headline(data, tmp_path):
    out = tmp_path / "c"
    rc = main(["curve", "--data", str(data["shards"]), "--real", str(data["real"]),
               "--test-fraction", "0.25", "--sizes", "0,2,4", "--repeats", "2", "--curve-steps", "2",
               "--pretrain-steps", "2", "--cross", f"walls={write_real_folder(tmp_path / 'walls', n=3)}", "--out", str(out), *COMMON])
    assert rc == 0
    rows = list(csv.DictReader(open(out / "curve" / "curve.csv")))
    # per repeat: finetune at N=0 (the pretrained model as it is) + both arms at N=2 and N=4
    assert len(rows) == 2 * 5
    assert {(r["arm"], r["n"]) for r in rows} == {("finetune", "0"), ("real", "2"), ("finetune", "2"),
                                                  ("real", "4"), ("finetune", "4")}
    assert all(r["steps"] == ("0" if r["n"] == "0" else "2") for r in rows)
    # total steps include each repeat's own pretraining (2 steps) in the fine-tune arm
    assert all(int(r["total_steps"]) == int(r["steps"]) + (2 if r["arm"] == "finetune" else 0) for r in rows)
    assert {r["repeat"] for r in rows} == {"0", "1"}
    pre = [load_checkpoint(out / "curve" / f"r{r}" / "pretrain" / "checkpoint.pt") for r in (0, 1)]
    assert [c["args"]["seed"] for c in pre] == [0, 1]  # every repeat pretrains its own model
    zero = [r for r in rows if r["n"] == "0"]
    assert len({r["f1"] for r in zero}) == 2  # so N = 0 has a spread
    assert all(0.0 <= float(r["f1:walls"]) <= 1.0 for r in rows)  # the extra set, at the same thresholds
    assert (out / "curve" / "curve.png").stat().st_size > 0
    assert "no fine-tune point at N = 30" in (out / "curve" / "curve.md").read_text()


def test_init_loads_weights_and_refuses_another_arch(data, tmp_path, capsys):
    base = ["seg", "--real", str(data["real"]), "--batch-size", "2", "--crop", "32", "--workers", "0",
            "--no-progress", "--max-steps", "2"]
    assert main([*base, "--arch", "unet", "--out", str(tmp_path / "a")]) == 0
    # lr 0: one step from --init leaves the weights exactly as loaded
    assert main([*base, "--arch", "unet", "--lr", "0", "--init", str(tmp_path / "a/checkpoint.pt"),
                 "--out", str(tmp_path / "b")]) == 0
    a = load_checkpoint(tmp_path / "a/checkpoint.pt")["model"]
    b = load_checkpoint(tmp_path / "b/checkpoint.pt")["model"]
    assert all(torch.equal(a[k], b[k]) for k in a if a[k].dtype.is_floating_point and "running" not in k)
    assert main([*base, "--arch", "lraspp_mobilenet_v3_large", "--init", str(tmp_path / "a/checkpoint.pt"),
                 "--out", str(tmp_path / "c")]) == 1
    assert "checkpoint is a unet" in capsys.readouterr().err


def test_stream_adapts_synthetic_rgb_only(data):
    photos = sorted((data["real"] / "images").glob("*.png"))
    dark = tuple(str(p) for p in photos)
    cfg = SampleConfig(channels="rgb", crop=None, rotate_deg=0.0, jitter=0.0)
    syn = ShardSource(data["shards"], "none")
    real = RealFolder(data["real"], stems=[p.stem for p in photos][::2])

    def batches(adapt):
        ds = SegStream(cfg, syn, real, batch_size=1, train=True, seed=3, adapt=adapt, shuffle_buffer=1)
        return {s["key"]: s for s in ds}

    plain = batches(None)
    adapted = batches(SiteAdaptation(dark, ("reinhard",)))
    assert plain.keys() == adapted.keys()
    for k in plain:
        assert torch.equal(plain[k]["mask"], adapted[k]["mask"])
        same = torch.equal(plain[k]["image"], adapted[k]["image"])
        assert same == (k in real.keys), k  # real photos untouched, every synthetic one changed


def test_lr_scheduler_reaches_every_row_and_a_curve_refuses_another(data, tmp_path):
    out = tmp_path / "s"
    assert main(["sim2real", "--data", str(data["shards"]), "--real", str(data["real"]),
                 "--test-fraction", "0.25", "--max-steps", "2", "--lr-scheduler", "cosine",
                 "--runs", "synthetic,finetune", "--out", str(out), *COMMON]) == 0
    for row in ("synthetic", "finetune_pretrain", "finetune"):
        ckpt = load_checkpoint(out / row / "checkpoint.pt")
        assert ckpt["args"]["lr_scheduler"] == "cosine"
        assert ckpt["optimizer"]["param_groups"][0]["lr"] < 1e-3  # annealed, not the constant 1e-3
    # a curve continues with the same settings and refuses another schedule
    curve = ["curve", "--data", str(data["shards"]), "--real", str(data["real"]), "--test-fraction",
             "0.25", "--sizes", "0,2", "--repeats", "1", "--curve-steps", "1", "--pretrain-steps", "1",
             "--cross", "none", "--out", str(tmp_path / "c"), *COMMON]
    assert main(curve) == 0
    assert main(curve) == 0
    assert main([*curve, "--lr-scheduler", "poly"]) == 1


def test_finetune_lr_and_plain_pretraining(data, tmp_path, capsys):
    out = tmp_path / "f"
    assert main(["sim2real", "--data", str(data["shards"]), "--real", str(data["real"]),
                 "--test-fraction", "0.25", "--target", "--max-steps", "4", "--runs", "finetune",
                 "--finetune-lr", "3e-4", "--plain-pretrain", "--out", str(out), *COMMON]) == 0
    ft = json.loads((out / "sim2real.json").read_text())["runs"]["finetune"]
    assert ft["pretrain_adapted"] is False and ft["finetune_lr"] == 3e-4
    assert load_checkpoint(out / "finetune_pretrain" / "checkpoint.pt")["args"]["lr"] == 1e-3
    assert load_checkpoint(out / "finetune" / "checkpoint.pt")["args"]["lr"] == 3e-4
    assert load_checkpoint(out / "finetune_pretrain" / "checkpoint.pt")["args"]["adapt_targets"] is None
    assert main(["sim2real", "--data", str(data["shards"]), "--real", str(data["real"]),
                 "--test-fraction", "0.25", "--runs", "finetune", "--finetune-lr", "0",
                 "--out", str(out), *COMMON]) == 1
    assert "--finetune-lr must be > 0" in capsys.readouterr().err


def test_finetune_row_from_a_pretrained_synthetic_model_spends_every_step_on_real(data, tmp_path, capsys):
    syn = tmp_path / "syn"
    assert main(["sim2real", "--data", str(data["shards"]), "--real", str(data["real"]),
                 "--test-fraction", "0.25", "--max-steps", "2", "--runs", "synthetic", "--out", str(syn), *COMMON]) == 0
    pre = syn / "synthetic" / "checkpoint.pt"
    out = tmp_path / "ft"
    assert main(["sim2real", "--pretrained", str(pre), "--real", str(data["real"]), "--test-fraction", "0.25",
                 "--max-steps", "3", "--runs", "finetune", "--out", str(out), *COMMON]) == 0  # no --synthetic needed
    ft = json.loads((out / "sim2real.json").read_text())["runs"]["finetune"]
    assert ft["pretrained"] == str(pre) and ft["pretrain_steps"] == 2 and ft["steps"] == 3
    ckpt = load_checkpoint(out / "finetune" / "checkpoint.pt")
    assert ckpt["step"] == 3 and ckpt["args"]["init"] == str(pre) and ckpt["args"]["data"] is None
    assert not (out / "finetune_pretrain").exists()
    assert main(["sim2real", "--pretrained", str(tmp_path / "nope.pt"), "--real", str(data["real"]),
                 "--test-fraction", "0.25", "--max-steps", "3", "--runs", "finetune", "--out", str(out), *COMMON]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nope.pt" in err[0]
    assert json.loads((out / "sim2real.json").read_text())["runs"]["finetune"] == ft  # the finished row is kept


def test_a_second_run_adds_rows_and_keeps_the_earlier_ones(data, tmp_path):
    out = tmp_path / "s2r"
    base = ["sim2real", "--real", str(data["real"]), "--test-fraction", "0.25", "--out", str(out), *COMMON]
    assert main([*base, "--max-steps", "2", "--runs", "real"]) == 0
    first = json.loads((out / "sim2real.json").read_text())["runs"]["real"]
    assert main([*base, "--max-steps", "2", "--data", str(data["shards"]), "--runs", "synthetic"]) == 0
    assert json.loads((out / "sim2real.json").read_text())["runs"] == {"real": first} | {
        "synthetic": json.loads((out / "sim2real.json").read_text())["runs"]["synthetic"]}
    assert "| real |" in (out / "sim2real.md").read_text()
    # other settings (budget): the earlier rows are not comparable and are replaced
    assert main([*base, "--max-steps", "3", "--data", str(data["shards"]), "--runs", "synthetic"]) == 0
    assert list(json.loads((out / "sim2real.json").read_text())["runs"]) == ["synthetic"]
    assert main([*base, "--max-steps", "3", "--lr-scheduler", "cosine", "--runs", "real"]) == 0  # other schedule
    assert list(json.loads((out / "sim2real.json").read_text())["runs"]) == ["real"]


def test_pretrain_steps_count_a_chain_of_init_trainings(data, tmp_path):
    """A second cycle (seg --init) on a synthetic model: the fine-tune row reports every synthetic step."""
    syn = tmp_path / "syn"
    assert main(["seg", "--data", str(data["shards"]), "--max-steps", "2", "--out", str(syn), *COMMON]) == 0
    more = tmp_path / "more"
    assert main(["seg", "--data", str(data["shards"]), "--init", str(syn / "checkpoint.pt"), "--max-steps", "3",
                 "--out", str(more), *COMMON]) == 0
    assert load_checkpoint(more / "checkpoint.pt")["args"]["init_steps"] == 2
    out = tmp_path / "ft"
    assert main(["sim2real", "--pretrained", str(more / "checkpoint.pt"), "--real", str(data["real"]),
                 "--test-fraction", "0.25", "--max-steps", "2", "--runs", "finetune", "--out", str(out), *COMMON]) == 0
    ft = json.loads((out / "sim2real.json").read_text())["runs"]["finetune"]
    assert ft["pretrain_steps"] == 5  # 2 + 3
    assert load_checkpoint(out / "finetune" / "checkpoint.pt")["args"]["init_steps"] == 5


def test_the_threshold_is_chosen_without_test_labels(tmp_path):
    """Two identical folders except that every test label of the second is flipped: the same training and the
    same chosen threshold; only the test scores differ (so the test labels were read, but only to score)."""
    import cv2

    from trainer.seg.real_split import read_split

    runs = {}
    for name in ("plain", "flipped"):
        real = write_real_folder(tmp_path / name, n=12)
        if name == "flipped":
            for stem in read_split(tmp_path / "plain_run").test:
                m = real / "masks" / f"{stem}.png"
                cv2.imwrite(str(m), 255 - cv2.imread(str(m), cv2.IMREAD_GRAYSCALE))
        assert main(["sim2real", "--real", str(real), "--test-fraction", "0.25", "--max-steps", "3",
                     "--runs", "real", "--out", str(tmp_path / f"{name}_run"), *COMMON]) == 0
        runs[name] = json.loads((tmp_path / f"{name}_run" / "sim2real.json").read_text())["runs"]["real"]
    assert read_split(tmp_path / "plain_run").test == read_split(tmp_path / "flipped_run").test
    assert runs["plain"]["threshold"] == runs["flipped"]["threshold"]
    assert runs["plain"]["val_f1"] == runs["flipped"]["val_f1"]
    assert runs["plain"]["test"]["f1"] != runs["flipped"]["test"]["f1"]
    assert runs["plain"]["oracle"]["f1"] != runs["flipped"]["oracle"]["f1"]


def test_an_image_folder_from_another_generator_trains_the_synthetic_row(data, tmp_path, capsys):
    other = write_real_folder(tmp_path / "gen2d", n=6)
    out = tmp_path / "s"
    assert main(["sim2real", "--data", str(other), "--real", str(data["real"]), "--test-fraction", "0.25",
                 "--max-steps", "2", "--runs", "synthetic", "--out", str(out), *COMMON]) == 0
    ckpt = load_checkpoint(out / "synthetic" / "checkpoint.pt")
    assert ckpt["args"]["real"] == str(other) and ckpt["args"]["data"] is None and ckpt["args"]["precise_bn"] == 50
    assert main(["sim2real", "--data", str(other), "--real", str(data["real"]), "--test-fraction", "0.25",
                 "--max-steps", "2", "--runs", "mixed", "--out", str(out), *COMMON]) == 1
    assert "trains the 'synthetic' row only" in capsys.readouterr().err
