"""sim2real rows with site adaptation and fine-tuning, the label-efficiency curve, --init."""
import csv
import json

import pytest
import torch
from real_folders import write_real_folder
from synthetic_shards import write_shards

from trainer.augment import SampleConfig
from trainer.checkpoint import load_checkpoint
from trainer.cli import main
from trainer.site_adapt import SiteAdaptation
from trainer.sources import RealFolder, ShardSource, split_fraction
from trainer.stream import SegStream


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    base = tmp_path_factory.mktemp("sim2real")
    return {"real": write_real_folder(base / "real", n=12), "shards": write_shards(base / "shards", per_shard=4)}


COMMON = ["--arch", "unet", "--batch-size", "2", "--crop", "32", "--workers", "0", "--no-progress"]


def test_rows_with_adaptation_and_finetune(data, tmp_path, capsys):
    out = tmp_path / "s2r"
    rc = main(["sim2real", "--synthetic", str(data["shards"]), "--real", str(data["real"]),
               "--real-test-fraction", "0.25", "--target", "--max-steps", "4",
               "--runs", "synthetic,synthetic+fourier,synthetic+adapt,real,finetune", "--out", str(out), *COMMON])
    assert rc == 0
    table = json.loads((out / "sim2real.json").read_text())
    assert list(table["runs"]) == ["synthetic", "synthetic+fourier", "synthetic+adapt", "real", "finetune"]
    # the target is the 9 training images of the 12 (3 held out for the test), never the test photos
    assert table["target"].endswith(": 9 photos") and table["real_test_images"] == 3
    ft = table["runs"]["finetune"]
    assert ft["pretrain_steps"] == 2 and ft["steps"] == 4 and ft["pretrain_adapted"] is True
    for r in table["runs"].values():
        assert 0.0 <= r["best"]["f1"] <= 1.0
    # the fine-tuned model started from the pretrained one and trained 2 more steps on real photos
    assert load_checkpoint(out / "finetune" / "checkpoint.pt")["step"] == 2
    assert "| synthetic+fourier |" in capsys.readouterr().out


def test_adaptation_rows_need_a_target(data, tmp_path, capsys):
    rc = main(["sim2real", "--synthetic", str(data["shards"]), "--real", str(data["real"]),
               "--real-test-fraction", "0.25", "--runs", "synthetic+fourier", "--out", str(tmp_path), *COMMON])
    assert rc == 2 and "needs --target" in capsys.readouterr().err
    rc = main(["sim2real", "--synthetic", str(data["shards"]), "--real", str(data["real"]),
               "--real-test-fraction", "0.25", "--target", str(tmp_path / "nope"), "--out", str(tmp_path), *COMMON])
    assert rc == 2 and "no such folder" in capsys.readouterr().err


def test_curve_writes_csv_plot_and_headline(data, tmp_path):
    out = tmp_path / "c"
    rc = main(["sim2real", "--synthetic", str(data["shards"]), "--real", str(data["real"]),
               "--real-test-fraction", "0.25", "--curve", "0,2,4", "--repeats", "2", "--curve-steps", "2",
               "--pretrain-steps", "2", "--out", str(out), *COMMON])
    assert rc == 0
    rows = list(csv.DictReader(open(out / "curve" / "curve.csv")))
    # per repeat: finetune at N=0 (the pretrained model as it is) + both arms at N=2 and N=4
    assert len(rows) == 2 * 5
    assert {(r["arm"], r["n"]) for r in rows} == {("finetune", "0"), ("real", "2"), ("finetune", "2"),
                                                  ("real", "4"), ("finetune", "4")}
    assert all(r["steps"] == ("0" if r["n"] == "0" else "2") for r in rows)
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
                 "--out", str(tmp_path / "c")]) == 2
    assert "checkpoint is a unet" in capsys.readouterr().err


def test_stream_adapts_synthetic_rgb_only(data):
    photos = sorted((data["real"] / "images").glob("*.png"))
    dark = tuple(str(p) for p in photos)
    cfg = SampleConfig(channels="rgb", crop=None, rotate_deg=0.0, jitter=0.0)
    syn = ShardSource(data["shards"], "none")
    real = RealFolder(data["real"], stems=split_fraction([p.stem for p in photos], 0.5, 0)[0])

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


def test_lr_scheduler_reaches_every_row_and_old_curves_continue(data, tmp_path):
    out = tmp_path / "s"
    assert main(["sim2real", "--synthetic", str(data["shards"]), "--real", str(data["real"]),
                 "--real-test-fraction", "0.25", "--max-steps", "2", "--lr-scheduler", "cosine",
                 "--runs", "synthetic,finetune", "--out", str(out), *COMMON]) == 0
    for row in ("synthetic", "finetune_pretrain", "finetune"):
        ckpt = load_checkpoint(out / row / "checkpoint.pt")
        assert ckpt["args"]["lr_scheduler"] == "cosine"
        assert ckpt["optimizer"]["param_groups"][0]["lr"] < 1e-3  # annealed, not the constant 1e-3
    # a curve recorded before --lr-scheduler existed continues with the default, and refuses another value
    curve = ["sim2real", "--synthetic", str(data["shards"]), "--real", str(data["real"]), "--real-test-fraction",
             "0.25", "--curve", "0,2", "--repeats", "1", "--curve-steps", "1", "--pretrain-steps", "1",
             "--out", str(tmp_path / "c"), *COMMON]
    assert main(curve) == 0
    settings = tmp_path / "c" / "curve" / "curve_settings.json"
    old = json.loads(settings.read_text())
    del old["lr_scheduler"]
    settings.write_text(json.dumps(old))
    assert main(curve) == 0
    assert main([*curve, "--lr-scheduler", "poly"]) == 2


def test_finetune_lr_and_plain_pretraining(data, tmp_path, capsys):
    out = tmp_path / "f"
    assert main(["sim2real", "--synthetic", str(data["shards"]), "--real", str(data["real"]),
                 "--real-test-fraction", "0.25", "--target", "--max-steps", "4", "--runs", "finetune",
                 "--finetune-lr", "3e-4", "--plain-pretrain", "--out", str(out), *COMMON]) == 0
    ft = json.loads((out / "sim2real.json").read_text())["runs"]["finetune"]
    assert ft["pretrain_adapted"] is False and ft["finetune_lr"] == 3e-4
    assert load_checkpoint(out / "finetune_pretrain" / "checkpoint.pt")["args"]["lr"] == 1e-3
    assert load_checkpoint(out / "finetune" / "checkpoint.pt")["args"]["lr"] == 3e-4
    assert load_checkpoint(out / "finetune_pretrain" / "checkpoint.pt")["args"]["adapt_targets"] is None
    assert main(["sim2real", "--synthetic", str(data["shards"]), "--real", str(data["real"]),
                 "--real-test-fraction", "0.25", "--runs", "finetune", "--finetune-lr", "0",
                 "--out", str(out), *COMMON]) == 2
    assert "--finetune-lr must be > 0" in capsys.readouterr().err


def test_finetune_row_from_a_pretrained_synthetic_model_spends_every_step_on_real(data, tmp_path, capsys):
    syn = tmp_path / "syn"
    assert main(["sim2real", "--synthetic", str(data["shards"]), "--real", str(data["real"]),
                 "--real-test-fraction", "0.25", "--max-steps", "2", "--runs", "synthetic", "--out", str(syn), *COMMON]) == 0
    pre = syn / "synthetic" / "checkpoint.pt"
    out = tmp_path / "ft"
    assert main(["sim2real", "--pretrained", str(pre), "--real", str(data["real"]), "--real-test-fraction", "0.25",
                 "--max-steps", "3", "--runs", "finetune", "--out", str(out), *COMMON]) == 0  # no --synthetic needed
    ft = json.loads((out / "sim2real.json").read_text())["runs"]["finetune"]
    assert ft["pretrained"] == str(pre) and ft["pretrain_steps"] == 2 and ft["steps"] == 3
    ckpt = load_checkpoint(out / "finetune" / "checkpoint.pt")
    assert ckpt["step"] == 3 and ckpt["args"]["init"] == str(pre) and ckpt["args"]["data"] is None
    assert not (out / "finetune_pretrain").exists()
    assert main(["sim2real", "--pretrained", str(tmp_path / "nope.pt"), "--real", str(data["real"]),
                 "--real-test-fraction", "0.25", "--max-steps", "3", "--runs", "finetune", "--out", str(out), *COMMON]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nope.pt" in err[0]
    assert json.loads((out / "sim2real.json").read_text())["runs"]["finetune"] == ft  # the finished row is kept


def test_a_second_run_adds_rows_and_keeps_the_earlier_ones(data, tmp_path):
    out = tmp_path / "s2r"
    base = ["sim2real", "--real", str(data["real"]), "--real-test-fraction", "0.25", "--out", str(out), *COMMON]
    assert main([*base, "--max-steps", "2", "--runs", "real"]) == 0
    first = json.loads((out / "sim2real.json").read_text())["runs"]["real"]
    assert main([*base, "--max-steps", "2", "--synthetic", str(data["shards"]), "--runs", "synthetic"]) == 0
    assert json.loads((out / "sim2real.json").read_text())["runs"] == {"real": first} | {
        "synthetic": json.loads((out / "sim2real.json").read_text())["runs"]["synthetic"]}
    assert "| real |" in (out / "sim2real.md").read_text()
    # other settings (budget): the earlier rows are not comparable and are replaced
    assert main([*base, "--max-steps", "3", "--synthetic", str(data["shards"]), "--runs", "synthetic"]) == 0
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
                 "--real-test-fraction", "0.25", "--max-steps", "2", "--runs", "finetune", "--out", str(out), *COMMON]) == 0
    ft = json.loads((out / "sim2real.json").read_text())["runs"]["finetune"]
    assert ft["pretrain_steps"] == 5  # 2 + 3
    assert load_checkpoint(out / "finetune" / "checkpoint.pt")["args"]["init_steps"] == 5
