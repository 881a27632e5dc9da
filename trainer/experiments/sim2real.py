"""``cracktrain sim2real``: does synthetic data help on real cracks, and how many labels does it save?

Rows (same architecture, step budget, seed and precise BN; each final model gets its
threshold on the real validation split and is scored once on the real test split:
P/R/F1/IoU at that threshold, F1 at 0.5, and the test-label optimum as an oracle):

- ``synthetic``: synthetic shards only;
- ``synthetic+fourier`` / ``+reinhard`` / ``+histogram`` / ``synthetic+adapt`` (all three
  drawn per sample): synthetic shards adapted toward unlabeled target photos
  (``--target``; with no folder, the *images* of the real training split, labels unused);
- ``synthetic+bn``: the ``synthetic`` row's model with its BatchNorm statistics re-estimated on
  the unlabeled target photos (AdaBN, ``trainer.seg.target_bn``): same weights, no extra steps;
- ``synthetic+pseudo``: the ``synthetic`` row's model trained on for ``--self-train-steps`` on the
  renders plus the target photos with its own confident predictions as labels (class-balanced
  self-training, ``trainer.adapt.pseudo_label``; uncertain pixels ignored), no labels used;
- ``real``: the real training split only;
- ``mixed``: synthetic + real (real repeated N times, thesis rule);
- ``finetune``: synthetic pretraining for ``--finetune-fraction`` of the budget (adapted
  when ``--target`` is given, unless ``--plain-pretrain``), then fine-tuning on the real split
  for the rest (at ``--finetune-lr``): the same total step budget as every other row. With
  ``--pretrained CKPT`` (a finished synthetic model, a reusable asset like an ImageNet one)
  the row fine-tunes it on the real split for the whole ``--max-steps``: the same *real* steps
  as the ``real`` row.

``--curve 0,10,30,...`` instead runs the label-efficiency curve (``trainer.experiments.curve``):
for each N and repeat, real-only and synthetic -> fine-tune on the same N photos with the
same ``--curve-steps``; one synthetic pretraining (``--pretrain-steps``, or a ``--pretrained``
checkpoint) is shared. A second run with the same ``--out`` keeps finished points and resumes
an interrupted training, so more repeats or sizes extend the curve.

The real data is split by group (``trainer.seg.real_split``: DeepCrack's tiles ``NAME-k`` stay
together) into train / validation / test (``--val-fraction``, ``--test-fraction``, default
60 / 20 / 20 of the photos, ``--split-seed``, ``--group-pattern``); with ``--real-test FOLDER``
the test set is that folder and ``--real`` is split into train / validation. The split is
written to ``OUT/split.json``. Rows whose inputs are missing are skipped. Cross-domain sets
are scored on the finished rows by ``cracktrain benchmark OUT``.

``--data`` may also be a folder of images/ + masks/ from another generator (a 2-D one
such as Syncrack): it trains the ``synthetic`` row only.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from crackgen.cli_aliases import deprecated_alias
from trainer.adapt.adabn import adapt_checkpoint
from trainer.adapt.pseudo_label import PseudoSettings, write_pseudo_folder
from trainer.core.checkpoint import load_checkpoint, steps_seen
from trainer.core.device import pick_device
from trainer.core.errors import TrainerInputError
from trainer.core.options import options_from
from trainer.experiments.config import ExperimentOptions
from trainer.experiments.curve import (
    CurvePoint,
    headline,
    nested_subsets,
    parse_sizes,
    plot_curve,
    read_csv,
    summarise,
    table_lines,
)
from trainer.experiments.curve import write_csv as write_curve_csv
from trainer.experiments.eval_sets import DEFAULT_REAL_ROOT, cross_domain_sets
from trainer.experiments.scoreboard import EvalSet
from trainer.seg.appearance import targets_from_folder, targets_from_paths
from trainer.seg.builders import (
    DataOptions,
    add_data_args,
    add_split_args,
    eval_loader,
    grouped_split,
    real_folder,
)
from trainer.seg.config import SegTrainConfig
from trainer.seg.metrics import ConfusionHistogram
from trainer.seg.real_split import RealSplit, split_groups
from trainer.seg.scoring import evaluate, load_model, report
from trainer.seg.sources import RealFolder
from trainer.seg.stream import SegStream
from trainer.seg.threshold import choose_threshold, store_threshold
from trainer.seg.train import main as train_seg
from trainer.seg.train import precise_bn_batches

log = logging.getLogger(__name__)

BASE_RUNS = ("synthetic", "real", "mixed", "finetune")
ADAPT_RUNS = {"synthetic+fourier": "fourier", "synthetic+reinhard": "reinhard",
              "synthetic+histogram": "histogram", "synthetic+adapt": "fourier,reinhard,histogram"}
BN_RUN = "synthetic+bn"  # target BN on the synthetic row's model
PSEUDO_RUN = "synthetic+pseudo"  # self-training on the target photos from the synthetic row's model
TARGET_RUNS = (*ADAPT_RUNS, BN_RUN, PSEUDO_RUN)  # rows that need --target
# with --target and no --runs; self-training is asked for by name (it helps on some sets and hurts on others: docs/results/sim2real.md)
DEFAULT_TARGET_RUNS = (*ADAPT_RUNS, BN_RUN)


def add_experiment_args(p: argparse.ArgumentParser, *, out: str) -> None:
    """What sim2real and the curve share: the data, its grouped split, the model and its budget."""
    p.add_argument("--data", dest="synthetic", default=None, help="synthetic shards (A,B: several datasets together)")
    deprecated_alias(p, "--synthetic", "--data", "cracktrain")
    p.add_argument("--real", required=True, help="real folder, split by group into train / validation / test (train / validation with --real-test)")
    p.add_argument("--real-test", default=None, help="real test folder (default: the test side of --real's split)")
    p.add_argument("--arch", default="lraspp_mobilenet_v3_large")
    p.add_argument("--max-steps", type=int, default=300, help="step budget of every row (curve: of its pretraining)")
    p.add_argument("--batch-size", "-b", type=int, default=4)
    p.add_argument("--crop", type=int, default=192)
    p.add_argument("--lr", type=float, default=1e-3)
    p.add_argument("--lr-scheduler", choices=("none", "poly", "cosine"), default="none",
                   help="learning-rate schedule of every training (a fine-tune's two phases each run their own)")
    p.add_argument("--loss", default="bce")
    p.add_argument("--workers", "-j", type=int, default=2)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--precise-bn", type=int, default=50, metavar="BATCHES",
                   help="every final model gets its BatchNorm statistics recomputed on this many training "
                        "batches (0: none); the same for every row and both curve arms")
    p.add_argument("--target", nargs="?", const="", default=None, metavar="FOLDER",
                   help="adapt synthetic RGB toward these unlabeled photos; no FOLDER: the real training split's images")
    p.add_argument("--adapt-band", default="0.005,0.05", help="Fourier band MIN,MAX (fraction of min(H, W))")
    p.add_argument("--adapt-prob", type=float, default=1.0, help="chance that a synthetic sample is adapted")
    p.add_argument("--finetune-lr", type=float, default=None,
                   help="fine-tuning: learning rate on the real photos (default --lr)")
    p.add_argument("--plain-pretrain", action="store_true",
                   help="fine-tuning: pretrain on the renders as they are, even with --target (default: adapted)")
    p.add_argument("--pretrained", default=None, metavar="CKPT[,CKPT...]",
                   help="finetune row: start from this synthetic checkpoint instead of pretraining (the row then "
                        "spends all --max-steps on the real split); curve: one checkpoint per repeat, comma-separated")
    p.add_argument("--real-root", default=DEFAULT_REAL_ROOT, help="where --cross looks for relative folders")
    p.add_argument("--out", default=out)
    p.add_argument("--device", default=None)
    p.add_argument("--no-progress", action="store_true")
    add_split_args(p, val_fraction=0.2, test_fraction=0.2)
    add_data_args(p)


def _add_rows_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--runs", default=None,
                   help=f"comma list of {', '.join(BASE_RUNS + TARGET_RUNS)} "
                        f"(default: the four base rows, plus {', '.join(DEFAULT_TARGET_RUNS)} with --target)")
    p.add_argument("--finetune-fraction", type=float, default=0.5,
                   help="finetune row: share of --max-steps spent on synthetic pretraining")
    p.add_argument("--self-train-steps", type=int, default=None,
                   help="synthetic+pseudo row: steps on renders + pseudo-labelled target photos (default --max-steps / 2)")
    p.add_argument("--pseudo-portion", type=float, default=0.5,
                   help="synthetic+pseudo row: share of the predicted crack pixels kept as labels (rest ignored)")
    p.add_argument("--pseudo-background-portion", type=float, default=None,
                   help="synthetic+pseudo row: share of the predicted background kept (default --pseudo-portion)")


def _add_curve_args(p: argparse.ArgumentParser, hidden: bool) -> None:
    def h(text: str) -> str:
        return argparse.SUPPRESS if hidden else text
    p.add_argument("--repeats", type=int, default=3, help=h("repeats (different nested subsets and seeds)"))
    p.add_argument("--curve-steps", type=int, default=None, help=h("steps per model on N photos (default --max-steps)"))
    p.add_argument("--pretrain-steps", type=int, default=None,
                   help=h("synthetic pretraining steps per repeat (default --max-steps)"))
    p.add_argument("--cross", action="append", default=None, metavar="NAME=FOLDER",
                   help=h("extra sets scored at each model's validation threshold (repeatable; default the three "
                          "cross-domain sets under --real-root; 'none': no extra sets)"))


def add_sim2real_args(p: argparse.ArgumentParser) -> None:
    add_experiment_args(p, out="runs/sim2real")
    _add_rows_args(p)
    # `sim2real --curve` is the old spelling of `cracktrain curve`: still accepted, with its options, for one release
    p.add_argument("--curve", default=None, metavar="N,N,...", help=argparse.SUPPRESS)
    _add_curve_args(p, hidden=True)


def add_curve_args(p: argparse.ArgumentParser) -> None:
    add_experiment_args(p, out="runs/curve")
    p.add_argument("--sizes", dest="curve", default="0,10,30,60,120,180", metavar="N,N,...",
                   help="labelled real photo counts N of the curve's points")
    _add_curve_args(p, hidden=False)
    # the sim2real rows' own settings at their defaults, so both commands share one code path
    p.set_defaults(runs=None, finetune_fraction=0.5, self_train_steps=None, pseudo_portion=0.5,
                   pseudo_background_portion=None)


# ------------------------------------------------------------------ shared steps

def seg_args(args: ExperimentOptions, out: Path, data: str | None, real: str | None, stems: list[str] | None,
             **overrides: Any) -> SegTrainConfig:
    """``cracktrain seg`` settings for one training of this comparison: the shared flags as given, seg's own
    defaults for the rest."""
    shared = {f.name: getattr(args, f.name) for f in dataclasses.fields(SegTrainConfig)
              if hasattr(args, f.name) and f.name not in ("out", "real")}
    fixed = {"data": data, "real": real, "real_stems": stems, "out": str(out),
             "precise_bn": args.precise_bn,  # every row alike (seg's own default skips it without --init)
             "val_fraction": 0.0, "val_data": None, "val_real": None, "resume": None, "test_only": False,
             "adapt_target": None, "adapt_targets": None, "init": None, "bn_target": None, "bn_targets": None,
             # sim2real's --target means its own rows
             "target": None, "target_appearance": False, "target_bn": False}
    return SegTrainConfig(**(shared | fixed | overrides))


@dataclass
class RealSets:
    """The real data of one comparison: training stems of ``--real``, and the validation and test folders."""

    train_stems: list[str]
    val: RealFolder
    test: RealFolder
    test_root: str
    split: RealSplit


def real_sets_for(args: ExperimentOptions, out: Path) -> RealSets:
    """Grouped split of ``--real`` (train / val / test, or train / val with ``--real-test``), written to OUT."""
    if args.real_test:
        split = split_groups(real_folder(DataOptions.from_args(args), args.real).keys, val_fraction=args.val_fraction, test_fraction=0.0,
                             seed=args.split_seed, group_pattern=args.group_pattern,
                             source=str(Path(args.real).resolve()))
        test_root, test = args.real_test, real_folder(DataOptions.from_args(args), args.real_test)
    else:
        if not args.test_fraction > 0:
            raise TrainerInputError("give a real test set: --real-test FOLDER or --test-fraction F > 0")
        split = grouped_split(DataOptions.from_args(args), args.real, val_fraction=args.val_fraction,
                              test_fraction=args.test_fraction, seed=args.split_seed)
        test_root, test = args.real, real_folder(DataOptions.from_args(args), args.real, split.test)
    if not args.val_fraction > 0:
        raise TrainerInputError("--val-fraction must be > 0: thresholds are chosen on the validation split")
    out.mkdir(parents=True, exist_ok=True)
    split.write(out)
    return RealSets(split.train, real_folder(DataOptions.from_args(args), args.real, split.val), test, test_root, split)


def adaptation_targets(args: ExperimentOptions, train_stems: list[str] | None) -> tuple[str, ...] | None:
    """Target photos: ``--target FOLDER``, or the real training split's images (never the test split's)."""
    if args.target is None:
        return None
    if args.target:
        return targets_from_folder(args.target)
    folder = real_folder(DataOptions.from_args(args), args.real, train_stems)
    return targets_from_paths([folder.image_path(k) for k in folder.keys])


def histogram(checkpoint: Path, folder: RealFolder, args: ExperimentOptions,
              device: torch.device) -> ConfusionHistogram:
    model, cfg, _ = load_model(checkpoint, device)
    ds = SegStream(cfg, None, folder, train=False, seed=args.seed, skip_bad=args.skip_bad)
    return evaluate(model, eval_loader(ds, args.workers, device), device, device.type == "cuda")


def choose_and_score(checkpoint: Path, sets: RealSets, args: ExperimentOptions, device: torch.device,
                     store: bool = True) -> dict[str, Any]:
    """Threshold from the validation split (stored in the checkpoint unless ``store`` is off: a checkpoint
    the user handed in is never rewritten), then one score of the test split."""
    rec = choose_threshold(histogram(checkpoint, sets.val, args, device),
                           f"validation split of {args.real} ({len(sets.val)} photos, split seed {args.split_seed})",
                           len(sets.val))
    if store:
        store_threshold(checkpoint, rec)
    r = report(histogram(checkpoint, sets.test, args, device), rec["threshold"])
    return {"checkpoint": str(checkpoint), "threshold": rec["threshold"], "val_f1": rec["val_f1"],
            "test": r["at_threshold"], "at_0.5": r["at_0.5"], "oracle": r["oracle"]}


def train_and_score(ns: SegTrainConfig, sets: RealSets, args: ExperimentOptions,
                    device: torch.device) -> dict[str, Any]:
    info = train_seg(ns)
    return {"steps": info["step"], "train_seconds": round(info["seconds"], 1),
            **choose_and_score(Path(ns.out) / "checkpoint.pt", sets, args, device)}


# ------------------------------------------------------------------ the rows

def wanted_runs(args: ExperimentOptions) -> list[str]:
    if args.runs is None:
        return list(BASE_RUNS) + (list(DEFAULT_TARGET_RUNS) if args.target is not None else [])
    runs = [r.strip() for r in args.runs.split(",") if r.strip()]
    for r in runs:
        if r not in BASE_RUNS and r not in TARGET_RUNS:
            raise TrainerInputError(f"--runs: unknown run {r!r} ({', '.join(BASE_RUNS + TARGET_RUNS)})")
        if r in TARGET_RUNS and args.target is None:
            raise TrainerInputError(f"--runs {r} needs --target (a folder, or none for the real training images)")
    return runs


def synthetic_is_folder(path: str | None) -> bool:
    """``--data`` names a folder of images/ + masks/ (another generator's output), not shards."""
    return bool(path) and "," not in str(path) and (Path(path) / "images").is_dir() \
        and not (Path(path) / "manifest.json").is_file()


def run_row(name: str, args: ExperimentOptions, out: Path, sets: RealSets,
            targets: tuple[str, ...] | None, device: torch.device) -> dict[str, Any]:
    """Train and score one row; a row that needs synthetic shards is skipped without them."""
    if name != "real" and not args.synthetic and not (name == "finetune" and args.pretrained):
        return {"skipped": "no --data shards given"}
    stems = sets.train_stems
    if name == "real":
        return train_and_score(seg_args(args, out / name, None, args.real, stems), sets, args, device)
    if synthetic_is_folder(args.synthetic):
        if name != "synthetic":
            raise TrainerInputError(f"--data {args.synthetic} is an image folder: it trains the 'synthetic' row "
                                    f"only, not {name!r} (--runs synthetic,real)")
        ns = seg_args(args, out / name, None, args.synthetic, None, image_dir="images", mask_dir="masks",
                      mask_suffix="", real_depth_dir=None)
        return train_and_score(ns, sets, args, device)
    if name == "mixed":
        return train_and_score(seg_args(args, out / name, args.synthetic, args.real, stems), sets, args, device)
    if name in ADAPT_RUNS:
        ns = seg_args(args, out / name, args.synthetic, None, None, adapt_targets=targets,
                      adapt_methods=ADAPT_RUNS[name])
        return train_and_score(ns, sets, args, device)
    if name == "synthetic":
        return train_and_score(seg_args(args, out / name, args.synthetic, None, None), sets, args, device)
    if name == BN_RUN:
        return target_bn_row(args, out, targets, sets, device)
    if name == PSEUDO_RUN:
        return pseudo_label_row(args, out, targets, sets, device)
    if args.finetune_lr is not None and not args.finetune_lr > 0:
        raise TrainerInputError(f"--finetune-lr must be > 0, got {args.finetune_lr}")
    if args.pretrained:
        return finetune_pretrained_row(args, out, name, stems, sets, device)
    # finetune: pretrain on synthetic (adapted when targets exist), then the rest of the budget on real
    if not 0.0 < args.finetune_fraction < 1.0:
        raise TrainerInputError(f"--finetune-fraction must be in (0, 1), got {args.finetune_fraction}")
    pre_steps = max(1, round(args.max_steps * args.finetune_fraction))
    pre_targets = None if args.plain_pretrain else targets
    pre = seg_args(args, out / "finetune_pretrain", args.synthetic, None, None, max_steps=pre_steps,
                   adapt_targets=pre_targets, precise_bn=0)  # an intermediate model: only the final one gets it
    t0 = time.perf_counter()
    train_seg(pre)
    ft = seg_args(args, out / name, None, args.real, stems, max_steps=args.max_steps - pre_steps,
                  init=str(out / "finetune_pretrain" / "checkpoint.pt"), lr=args.finetune_lr or args.lr)
    res = train_and_score(ft, sets, args, device)
    res["pretrain_steps"] = pre_steps
    res["pretrain_adapted"] = pre_targets is not None
    res["finetune_lr"] = args.finetune_lr or args.lr
    res["train_seconds"] = round(time.perf_counter() - t0, 1)
    res["steps"] = args.max_steps
    return res


def finetune_pretrained_row(args: ExperimentOptions, out: Path, name: str, stems: list[str] | None,
                            sets: RealSets, device: torch.device) -> dict[str, Any]:
    """``--pretrained CKPT`` fine-tuned on the real split for all ``--max-steps``."""
    pre_step = steps_seen(load_checkpoint(args.pretrained))  # with its own --init chain
    lr = args.finetune_lr or args.lr
    ft = seg_args(args, out / name, None, args.real, stems, init=str(args.pretrained), lr=lr)
    res = train_and_score(ft, sets, args, device)
    res.update({"pretrained": str(args.pretrained), "pretrain_steps": pre_step, "finetune_lr": lr, "steps": args.max_steps})
    return res


def target_bn_row(args: ExperimentOptions, out: Path, targets: tuple[str, ...] | None, sets: RealSets,
                  device: torch.device) -> dict[str, Any]:
    """The ``synthetic`` row's model (trained here unless that row already finished) with BN statistics
    from the target photos: what target BN alone is worth, on identical weights."""
    assert targets is not None
    base = seg_args(args, out / "synthetic", args.synthetic, None, None)
    info = train_or_reuse(base)
    t0 = time.perf_counter()
    dst = out / BN_RUN / "checkpoint.pt"
    record = adapt_checkpoint(out / "synthetic" / "checkpoint.pt", dst, targets, device,
                              target=describe_target(args, targets) or "", batch_size=args.batch_size,
                              crop=args.crop, workers=args.workers, seed=args.seed)
    res = choose_and_score(dst, sets, args, device)
    return {"steps": info["step"], "train_seconds": round(info["seconds"] + time.perf_counter() - t0, 1),
            **res, "target_bn": record}


def pseudo_label_row(args: ExperimentOptions, out: Path, targets: tuple[str, ...] | None, sets: RealSets,
                     device: torch.device) -> dict[str, Any]:
    """The ``synthetic`` row's model (trained here unless finished), then ``--self-train-steps`` on the renders
    plus the target photos pseudo-labelled by that model (``trainer.adapt.pseudo_label``)."""
    assert targets is not None
    steps = args.self_train_steps if args.self_train_steps is not None else max(1, args.max_steps // 2)
    if steps <= 0:
        raise TrainerInputError(f"--self-train-steps must be > 0, got {steps}")
    base = seg_args(args, out / "synthetic", args.synthetic, None, None)
    info = train_or_reuse(base)
    teacher = out / "synthetic" / "checkpoint.pt"
    t0 = time.perf_counter()
    settings = PseudoSettings(teacher=str(teacher), portion=args.pseudo_portion,
                              background_portion=args.pseudo_background_portion, batch_size=args.batch_size,
                              crop=args.crop, seed=args.seed)
    labels = out / PSEUDO_RUN / "labels"
    record = write_pseudo_folder(targets, labels, settings, device, workers=args.workers,
                                 progress=not args.no_progress)
    ns = seg_args(args, out / PSEUDO_RUN / "student", args.synthetic, str(labels), None, init=str(teacher),
                  max_steps=steps, image_dir="images", mask_dir="masks", mask_suffix="", ignore_dir="ignore",
                  real_depth_dir=None)
    res = train_and_score(ns, sets, args, device)
    res["train_seconds"] = round(info["seconds"] + time.perf_counter() - t0, 1)
    res.update({"steps": info["step"] + steps, "self_train_steps": steps, "pseudo_labels": record})
    return res


def run_sim2real(args: ExperimentOptions) -> dict[str, Any]:
    if args.curve:
        return run_curve(args)
    if args.pretrained and not Path(args.pretrained).is_file():
        raise TrainerInputError(f"--pretrained {args.pretrained} does not exist")
    out = Path(args.out)
    runs = wanted_runs(args)
    sets = real_sets_for(args, out)
    targets = adaptation_targets(args, sets.train_stems) \
        if any(r in TARGET_RUNS or r == "finetune" for r in runs) else None
    device = pick_device(args.device)
    results: dict[str, Any] = {}
    cfg = DataOptions.from_args(args)
    table = {"arch": args.arch, "channels": cfg.channels, "depth": args.depth, "depth_norm": cfg.depth_norm,
             "mask_member": args.mask_member or "mask.png", "max_steps": args.max_steps,
             "batch_size": args.batch_size, "crop": args.crop, "seed": args.seed, "lr": args.lr,
             "lr_scheduler": args.lr_scheduler, "loss": args.loss, "precise_bn": args.precise_bn,
             "real_train": args.real, "real_train_images": len(sets.train_stems), "real_val_images": len(sets.val),
             "real_test": sets.test_root, "real_test_images": len(sets.test), "split_seed": args.split_seed,
             "val_fraction": args.val_fraction, "test_fraction": args.test_fraction if not args.real_test else None,
             "group_pattern": sets.split.group_pattern, "synthetic": args.synthetic,
             "target": describe_target(args, targets), "runs": results}
    results.update(earlier_rows(out, table, runs))
    for i, name in enumerate(runs, 1):
        log.info("sim2real: row %d/%d '%s'", i, len(runs), name)
        results[name] = run_row(name, args, out, sets, targets, device)
        # after every row, so an interrupted comparison keeps the rows it finished
        (out / "sim2real.json").write_text(json.dumps(table, indent=2))
        (out / "sim2real.md").write_text("\n".join(rows_markdown(args, table)) + "\n")
    return table


def earlier_rows(out: Path, table: dict[str, Any], runs: list[str]) -> dict[str, Any]:
    """Rows of an earlier comparison in ``out`` with the same settings that this run does not redo, so that
    adding a row (``--runs X``) keeps the table's other rows. Other settings: the old table is replaced."""
    path = out / "sim2real.json"
    if not path.is_file():
        return {}
    old = json.loads(path.read_text())
    skip = ("runs", "target", "synthetic")  # these two only concern the rows that use them
    if {k: v for k, v in old.items() if k not in skip} != {k: v for k, v in table.items() if k not in skip}:
        log.info("sim2real: %s was made with other settings; its rows are replaced", path)
        return {}
    kept = {k: v for k, v in old.get("runs", {}).items() if k not in runs}
    for key, uses in (("synthetic", lambda k: k != "real"), ("target", lambda k: k in TARGET_RUNS or k == "finetune")):
        if table[key] is None:
            table[key] = old.get(key)
        elif old.get(key) is not None and table[key] != old[key]:  # rows made from other data are not comparable
            kept = {k: v for k, v in kept.items() if not uses(k)}
    return kept


def describe_target(args: ExperimentOptions, targets: tuple[str, ...] | None) -> str | None:
    if targets is None:
        return None
    where = args.target or "the real training split's images (labels unused)"
    return f"{where}: {len(targets)} photos"


def rows_markdown(args: ExperimentOptions, table: dict[str, Any]) -> list[str]:
    lines = [f"# Sim-to-real: {args.arch}, {args.max_steps} steps, batch {args.batch_size}, crop {args.crop}, "
             f"seed {args.seed}", "",
             f"Input {table['channels']} (depth {table['depth']}, {table['depth_norm']}); synthetic labels "
             f"`{table['mask_member']}`; precise BN {table['precise_bn']} batches on every row. Real data "
             f"{table['real_train']} split by group (`{table['group_pattern']}`, split seed {table['split_seed']}): "
             f"{table['real_train_images']} train / {table['real_val_images']} validation photos; test "
             f"{table['real_test']} ({table['real_test_images']} photos). Each row's threshold is chosen on the "
             "validation split; P/R/F1/IoU on the test split at that threshold, F1 at 0.5, and the test-label "
             "optimum (an oracle: it looks at the test labels)."]
    if table["target"]:
        lines.append(f"Adaptation target: {table['target']}.")
    lines += ["", "| training data | threshold (val) | precision | recall | **F1** | IoU | F1 @ 0.5 | oracle F1 |",
              "|---|---|---|---|---|---|---|---|"]
    for name, r in table["runs"].items():
        if "skipped" in r:
            lines.append(f"| {name} | skipped: {r['skipped']} | | | | | | |")
        else:
            t, o = r["test"], r["oracle"]
            lines.append(f"| {name} | {r['threshold']:.2f} | {t['precision']:.3f} | {t['recall']:.3f} | "
                         f"**{t['f1']:.3f}** | {t['iou']:.3f} | {r['at_0.5']['f1']:.3f} | "
                         f"{o['f1']:.3f} @ {o['threshold']:.2f} |")
    return lines


# ------------------------------------------------------------------ the label-efficiency curve

# What a curve's numbers depend on. A second run with the same --out continues the curve (more repeats or sizes,
# or after a kill) only when these match what curve_settings.json recorded.
CURVE_SETTINGS = ("synthetic", "real", "real_test", "test_fraction", "val_fraction", "group_pattern", "split_seed",
                  "seed", "arch", "loss", "lr", "batch_size", "crop", "curve_steps", "pretrain_steps", "max_steps",
                  "depth", "depth_norm", "mask_member", "precise_bn", "pretrained", "lr_scheduler", "cross")


def check_curve_settings(args: ExperimentOptions, out: Path, targets: tuple[str, ...] | None) -> None:
    """Record the settings in ``out``, or refuse (one line) to continue a curve made with other ones."""
    now = {k: getattr(args, k, None) for k in CURVE_SETTINGS} | {"target": describe_target(args, targets)}
    path = out / "curve_settings.json"
    if not path.is_file():
        if (out / "curve.csv").is_file():
            raise TrainerInputError(f"{out}: has a curve.csv but no curve_settings.json, so it cannot be continued "
                                    "safely; use a new --out")
        path.write_text(json.dumps(now, indent=2))
        return
    before = json.loads(path.read_text())
    changed = [f"{k} {before.get(k)!r} -> {v!r}" for k, v in now.items() if before.get(k) != v]
    if changed:
        raise TrainerInputError(f"{out} holds a curve made with other settings ({'; '.join(changed)}); "
                                "use a new --out or the same settings")


def train_or_reuse(ns: SegTrainConfig) -> dict[str, Any]:
    """Train, unless ``ns.out`` already holds this training: finished (kept) or interrupted (resumed)."""
    path = Path(ns.out) / "checkpoint.pt"
    if path.is_file():
        ckpt = load_checkpoint(path)
        same_bn = precise_bn_batches(options_from(SegTrainConfig, ckpt["args"])) == precise_bn_batches(ns)
        legacy_final = ckpt["step"] >= (ns.max_steps or 0) and precise_bn_batches(ns) == 0  # before the flag existed
        if (ckpt.get("finished") and same_bn) or legacy_final:
            log.info("kept the finished training in %s (%d steps)", ns.out, ckpt["step"])
            return {"step": ckpt["step"], "seconds": 0.0, "out": ns.out}
        why = "interrupted" if ckpt["step"] < (ns.max_steps or 0) else "its precise BN differs"
        log.info("resuming the training in %s at step %d (%s)", ns.out, ckpt["step"], why)
        ns = dataclasses.replace(ns, resume=str(path))
    return train_seg(ns)


def small_set_repeat(n: int, args: ExperimentOptions) -> int:
    """Repeat a few photos so every loader slot fills two batches (10 photos, batch 8, 2 workers: x4).
    A fixed step budget sees the same photos either way; only the epoch length changes."""
    return max(1, math.ceil(2 * args.batch_size * max(1, args.workers) / max(1, n)))


def curve_pretrained(args: ExperimentOptions, out: Path, targets: tuple[str, ...] | None
                     ) -> list[tuple[Path, int, float]]:
    """One synthetic-pretrained model per repeat, (checkpoint, its steps, seconds spent here): given by
    ``--pretrained A,B,C`` (one per repeat) or pretrained here with the repeat's seed."""
    if args.pretrained:
        paths = [Path(p.strip()) for p in args.pretrained.split(",") if p.strip()]
        if len(paths) != args.repeats:
            raise TrainerInputError(f"--pretrained gives {len(paths)} checkpoint(s) for {args.repeats} repeats: the "
                                    "curve needs one pretrained model per repeat (pretrained with different seeds)")
        for p in paths:
            if not p.is_file():
                raise TrainerInputError(f"--pretrained {p} does not exist")
        return [(p, steps_seen(load_checkpoint(p)), 0.0) for p in paths]
    found = []
    for r in range(args.repeats):
        pre = seg_args(args, out / f"r{r}" / "pretrain", args.synthetic, None, None, seed=args.seed + r,
                       max_steps=args.pretrain_steps or args.max_steps, adapt_targets=targets)
        log.info("curve: synthetic pretraining of repeat %d (%d steps, seed %d%s)", r, pre.max_steps, pre.seed,
                 ", adapted" if targets else "")
        info = train_or_reuse(pre)
        found.append((Path(pre.out) / "checkpoint.pt", int(info["step"]), float(info["seconds"])))
    return found


def score_point(ckpt: Path, sets: RealSets, cross: list[EvalSet], args: ExperimentOptions,
                device: torch.device, store: bool) -> dict[str, Any]:
    """Validation threshold, test scores at it, and F1 on each extra set at the same threshold."""
    res = choose_and_score(ckpt, sets, args, device, store)
    res["cross"] = {c.name: report(histogram(ckpt, c.folder, args, device), res["threshold"])["at_threshold"]["f1"]
                    for c in cross}
    return res


def run_curve(args: ExperimentOptions) -> dict[str, Any]:
    """Real-only vs synthetic -> fine-tune on nested subsets of N labelled photos (see trainer.experiments.curve)."""
    if not args.synthetic and not args.pretrained:
        raise TrainerInputError("the curve needs --data shards (or --pretrained checkpoints) for the fine-tune arm")
    if args.repeats < 1:
        raise TrainerInputError(f"--repeats must be >= 1, got {args.repeats}")
    sizes = parse_sizes(args.curve)
    out = Path(args.out) / "curve"
    sets = real_sets_for(args, out)
    cross = cross_domain_sets(args.cross, args, args.real_root)
    targets = adaptation_targets(args, sets.train_stems)
    steps = args.curve_steps or args.max_steps
    device = pick_device(args.device)
    check_curve_settings(args, out, targets)
    done = {(p.n, p.repeat, p.arm): p for p in read_csv(out / "curve.csv")}
    t_start = time.perf_counter()
    pretrained = curve_pretrained(args, out, targets)
    points: list[CurvePoint] = []
    jobs = [(r, n, arm) for r in range(args.repeats) for n in sizes for arm in ("real", "finetune")
            if not (n == 0 and arm == "real")]
    for k, (r, n, arm) in enumerate(jobs, 1):
        subset = nested_subsets(sets.train_stems, sizes, args.seed, r)[n]
        if (n, r, arm) in done:  # finished and scored by an earlier run of the same curve
            points.append(done[(n, r, arm)])
            log.info("curve %d/%d: repeat %d, N=%d, %s: kept from %s", k, len(jobs), r, n, arm, out / "curve.csv")
            continue
        log.info("curve %d/%d: repeat %d, N=%d, %s", k, len(jobs), r, n, arm)
        t0 = time.perf_counter()
        pre_ckpt, pre_steps, _ = pretrained[r]
        if n == 0:
            ckpt, trained = pre_ckpt, 0
        else:
            ns = seg_args(args, out / f"r{r}" / f"n{n:04d}_{arm}", None, args.real, subset, max_steps=steps,
                          seed=args.seed + r, init=str(pre_ckpt) if arm == "finetune" else None,
                          real_repeat=small_set_repeat(n, args))
            train_or_reuse(ns)
            ckpt, trained = Path(ns.out) / "checkpoint.pt", steps
        s = score_point(ckpt, sets, cross, args, device, store=not (n == 0 and args.pretrained))
        t = s["test"]
        points.append(CurvePoint(n=n, repeat=r, arm=arm, f1=t["f1"], precision=t["precision"], recall=t["recall"],
                                 iou=t["iou"], threshold=s["threshold"], f1_at_05=s["at_0.5"]["f1"],
                                 oracle_f1=s["oracle"]["f1"], steps=trained,
                                 total_steps=trained + (pre_steps if arm == "finetune" else 0),
                                 seconds=round(time.perf_counter() - t0, 1), cross=s["cross"]))
        write_curve_csv(points, out / "curve.csv")  # after every point: an interrupted curve keeps what it has
    summary = summarise(points)
    cross_summary = {c.name: summarise(points, f"f1:{c.name}") for c in cross}
    pre_desc = (f"pretrain {pretrained[0][1]} steps per repeat ({len(pretrained)} models, seeds "
                f"{args.seed}..{args.seed + args.repeats - 1}){' (adapted)' if targets else ''}")
    title = f"{args.arch}, {steps} steps per model, {pre_desc}, {args.repeats} repeats"
    plot_curve(summary, out / "curve.png", title, cross_summary)
    head = headline(summary, 30)
    md = [f"# Label-efficiency curve: {title}", "",
          f"Real data: {args.real} split by group (`{sets.split.group_pattern}`, split seed {args.split_seed}): "
          f"N drawn from {len(sets.train_stems)} training photos; thresholds chosen on {len(sets.val)} validation "
          f"photos; test {sets.test_root} ({len(sets.test)} photos). F1 at each model's validation threshold, "
          "mean ± sample sd over the repeats; total steps per point (with pretraining) in curve.csv.", "",
          *table_lines(summary), "", f"**{head}**", ""]
    for name, summ in cross_summary.items():
        md += [f"Cross-domain set `{name}` (evaluation only), same models and thresholds:", "",
               *table_lines(summ), ""]
    md += [f"Wall time: {time.perf_counter() - t_start:.0f} s."]
    (out / "curve.md").write_text("\n".join(md) + "\n")
    result = {"sizes": sizes, "repeats": args.repeats, "steps": steps, "pretrain_steps": [p[1] for p in pretrained],
              "adapted": targets is not None, "headline": head, "summary": summary, "cross": cross_summary,
              "out": str(out)}
    (out / "curve.json").write_text(json.dumps(result, indent=2))
    return result
