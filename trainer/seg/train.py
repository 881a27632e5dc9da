"""``cracktrain seg``: a flat training loop in the style of torchvision references/segmentation.

Thesis defaults: DeepLabV3-ResNet50, BCE, Adam lr 1e-4, batch 16, 30 epochs.
Synthetic shards (``--data``) and a real folder (``--real``) can be mixed; the
real set is repeated N times, N the largest value with N*|real| < |synthetic|
(``--real-repeat`` overrides). Validation (``--val-data``/``--val-real`` or
``--val-fraction`` of the training sources) picks ``best.pt`` by F1 at the
best threshold. ``--resume`` continues exactly: same next batches, same step.
Runs under ``torchrun`` (DDP; gloo on CPU, nccl on CUDA).

Shape, as in torchvision's reference: ``build_*`` helpers make the pieces,
``train_one_epoch`` runs the (rest of the) current epoch, ``evaluate`` scores a
model on a loader, and ``main`` wires them. The mutable position of the run
lives in one ``TrainState`` (what a checkpoint needs to resume step-exactly);
the fixed pieces live in one ``Run``. Steps receive both explicitly.
"""
from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import logging
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
import torch.distributed as dist
from torch.utils.data import DataLoader
from tqdm import tqdm

from crackgen.cli_aliases import deprecated_alias, deprecation_note
from trainer.core.checkpoint import load_checkpoint, rng_state, save_checkpoint, set_rng_state, steps_seen
from trainer.core.errors import TrainerInputError
from trainer.core.options import options_dict
from trainer.seg.appearance import SiteAdaptation, parse_band, targets_from_folder
from trainer.seg.augment import SampleConfig
from trainer.seg.builders import (
    DataOptions,
    add_data_args,
    describe,
    eval_loader,
    eval_stream,
    real_split,
    resolve_valid_channel,
    sample_config,
    shard_source,
)
from trainer.seg.config import SegTrainConfig
from trainer.seg.losses import LOSSES, Loss, make_loss
from trainer.seg.models import ARCHS, build_model
from trainer.seg.precise_bn import precise_bn
from trainer.seg.real_split import DEFAULT_GROUP_PATTERN, RealSplit
from trainer.seg.scoring import evaluate
from trainer.seg.sources import DEFAULT_MASK_MEMBER
from trainer.seg.stream import SegStream, dist_info, mix_repeat
from trainer.seg.target_bn import DEFAULT_BATCHES, adapt_bn_to_photos
from trainer.seg.threshold import THRESHOLD_KEY, threshold_record

log = logging.getLogger(__name__)

# Arguments that fix the data order, augmentation and model shape: a resume must not change them.
RESUME_FIXED_ARGS = ("arch", "depth", "valid_channel", "depth_norm", "relief", "mask_member", "seed", "batch_size",
                     "workers")
# How depth becomes the input channels: --test-only takes them from the checkpoint, as evaluate/predict do.
DEPTH_INPUT_ARGS = ("depth", "valid_channel", "depth_near", "depth_far", "depth_norm", "relief", "relief_range_mm",
                    "relief_sigma")


class _OldTargetFlag(argparse.Action):
    """``--adapt-target F`` / ``--bn-target F``, the old spellings of ``--target F --target-appearance|--target-bn``."""

    def __call__(self, parser, namespace, values, option_string=None):
        new = "--target-appearance" if self.dest == "adapt_target" else "--target-bn"
        deprecation_note("cracktrain", str(option_string), f"--target FOLDER {new}")
        setattr(namespace, self.dest, values)


def resolve_site_targets(args: SegTrainConfig) -> None:
    """``--target`` with ``--target-appearance`` / ``--target-bn`` (or their old spellings) -> the folder each
    use reads (``args.adapt_target``, ``args.bn_target``); one line when they do not fit together."""
    uses = [u for u, on in (("--target-appearance", args.target_appearance), ("--target-bn", args.target_bn)) if on]
    if args.target and not uses:
        raise TrainerInputError("--target needs --target-appearance and/or --target-bn (what to do with the photos)")
    if uses and not args.target:
        raise TrainerInputError(f"{' and '.join(uses)} need --target FOLDER")
    for on, dest in ((args.target_appearance, "adapt_target"), (args.target_bn, "bn_target")):
        if on:
            if getattr(args, dest) not in (None, args.target):
                raise TrainerInputError(f"two site photo folders given ({getattr(args, dest)} and --target "
                                        f"{args.target}): give one")
            setattr(args, dest, args.target)


def add_seg_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data", default=None, help="synthetic dataset folder (shards) or one .tar; A,B: several together")
    p.add_argument("--real", default=None, help="real image/mask folder to train on (mixed with --data)")
    p.add_argument("--real-repeat", type=int, default=None, help="repeat the real set N times (default: thesis rule)")
    p.add_argument("--val-data", default=None, help="synthetic validation shards")
    p.add_argument("--val-real", default=None, help="real validation folder")
    p.add_argument("--val-fraction", type=float, default=0.0,
                   help="hold out this fraction of --data/--real for validation (whole scenes of --data, whole groups of --real)")
    p.add_argument("--split-seed", type=int, default=0)
    p.add_argument("--group-pattern", default=DEFAULT_GROUP_PATTERN, metavar="REGEX",
                   help="--val-fraction of a real folder keeps groups whole: a file's group is the first capture "
                        "group of REGEX on its stem (default: up to the first '-'); 'none': every file its own group")
    p.add_argument("--arch", choices=ARCHS, default="deeplabv3_resnet50")
    p.add_argument("--loss", choices=LOSSES, default="bce")
    p.add_argument("--lr", type=float, default=1e-4)
    p.add_argument("--weight-decay", type=float, default=0.0)
    p.add_argument("--lr-scheduler", choices=("none", "poly", "cosine"), default="none")
    p.add_argument("--batch-size", "-b", type=int, default=16)
    p.add_argument("--epochs", type=int, default=30)
    p.add_argument("--max-steps", type=int, default=None, help="stop after this many optimizer steps (step budget)")
    p.add_argument("--crop", type=int, default=256, help="random crop size (px) for training; 0 = full images")
    p.add_argument("--rotate-deg", type=float, default=15.0)
    p.add_argument("--jitter", type=float, default=0.3)
    p.add_argument("--workers", "-j", type=int, default=2)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", default=None, help="cpu or cuda (default: cuda when available)")
    p.add_argument("--no-amp", action="store_true", help="disable mixed precision on CUDA")
    p.add_argument("--sync-bn", action="store_true", help="SyncBatchNorm under DDP")
    p.add_argument("--val-every", type=int, default=0,
                   help="validate every N steps (0: at each epoch end; -1: only once, after training); the final "
                        "weights are always validated last and their best-F1 threshold stored in checkpoint.pt")
    p.add_argument("--log-every", type=int, default=10)
    p.add_argument("--out", default="runs/seg", help="output folder (checkpoints, log.csv, tensorboard)")
    p.add_argument("--resume", default=None, help="checkpoint to continue from")
    p.add_argument("--init", default=None, metavar="CKPT",
                   help="start from this checkpoint's weights (e.g. synthetic pretraining), fresh optimizer and steps")
    p.add_argument("--precise-bn", type=int, default=None, metavar="BATCHES",
                   help="after training, recompute BatchNorm statistics with the final weights on this many training "
                        "batches (default: 50 with --init, where the running statistics lag behind; else 0 = off)")
    g = p.add_argument_group("unlabeled photos of the site: appearance transfer during training, target BN after it")
    g.add_argument("--target", default=None, metavar="FOLDER", help="folder of unlabeled photos of the site")
    g.add_argument("--target-appearance", action="store_true",
                   help="pull the synthetic RGB toward the --target photos while training (Fourier/Reinhard/histogram)")
    g.add_argument("--target-bn", action="store_true",
                   help="re-estimate BN statistics on the --target photos at the end (weights unchanged)")
    g.add_argument("--adapt-target", dest="adapt_target", default=None, metavar="FOLDER",
                   action=_OldTargetFlag, help=argparse.SUPPRESS)  # old: --target F --target-appearance
    g.add_argument("--adapt-methods", default="fourier,reinhard,histogram", help="methods drawn uniformly per sample")
    g.add_argument("--adapt-band", default="0.005,0.05", help="Fourier band MIN,MAX (fraction of min(H, W))")
    g.add_argument("--adapt-prob", type=float, default=1.0, help="chance that a synthetic sample is adapted")
    g.add_argument("--bn-target", dest="bn_target", default=None, metavar="FOLDER",
                   action=_OldTargetFlag, help=argparse.SUPPRESS)  # old: --target F --target-bn
    g.add_argument("--target-bn-batches", dest="bn_target_batches", type=int, default=DEFAULT_BATCHES,
                   help="target BN: batches of photo crops averaged")
    deprecated_alias(p, "--bn-target-batches", "--target-bn-batches", "cracktrain")
    p.add_argument("--test-only", action="store_true", help="only validate the --resume checkpoint")
    p.add_argument("--no-progress", action="store_true")
    add_data_args(p)


# ------------------------------------------------------------------ state and logging

@dataclass
class TrainState:
    """Where the run stands; stored in every checkpoint so ``--resume`` continues at the next batch."""

    epoch: int = 0
    batch_in_epoch: int = 0
    step: int = 0
    best: dict[str, Any] = field(default_factory=lambda: {"f1": -1.0})
    target_bn: dict[str, Any] | None = None  # set once BN statistics were moved to site photos
    val_threshold: dict[str, Any] | None = None  # the final weights' threshold, chosen on validation


class _Logger:
    """CSV + TensorBoard on rank 0 (TensorBoard is optional at import time)."""

    def __init__(self, out: Path, enabled: bool) -> None:
        self.enabled = enabled
        self.tb = None
        if not enabled:
            return
        new = not (out / "log.csv").exists()
        self.f = open(out / "log.csv", "a", newline="")
        self.csv = csv.writer(self.f)
        if new:
            self.csv.writerow(["step", "epoch", "kind", "name", "value"])
        try:
            from torch.utils.tensorboard import SummaryWriter

            self.tb = SummaryWriter(str(out / "tb"))
        except Exception as exc:  # tensorboard missing on a slim GPU box: CSV still works
            log.warning("TensorBoard disabled: %s", exc)

    def scalar(self, kind: str, name: str, value: float, step: int, epoch: int) -> None:
        if not self.enabled:
            return
        self.csv.writerow([step, epoch, kind, name, repr(float(value))])
        if self.tb is not None:
            self.tb.add_scalar(f"{kind}/{name}", value, step)

    def close(self) -> None:
        if self.enabled:
            self.f.close()
            if self.tb is not None:
                self.tb.close()


@dataclass
class Run:
    """The fixed pieces of one training run, built once by ``main`` and handed to each step."""

    args: SegTrainConfig
    out: Path
    device: torch.device
    amp: bool
    main_proc: bool
    world: int
    cfg: SampleConfig
    model: torch.nn.Module  # what runs forward (DDP-wrapped under torchrun)
    bare: torch.nn.Module  # the unwrapped model whose state_dict is saved
    optimizer: torch.optim.Optimizer
    lr_scheduler: torch.optim.lr_scheduler.LRScheduler
    scaler: torch.amp.GradScaler
    criterion: Loss
    logger: _Logger
    progress: bool
    steps_per_epoch: int
    epochs: int
    total_steps: int


# ------------------------------------------------------------------ setup helpers

def init_distributed() -> tuple[torch.device, bool]:
    """Init DDP from torchrun's env vars when WORLD_SIZE > 1; returns (device, distributed)."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    local = int(os.environ.get("LOCAL_RANK", "0"))
    cuda = torch.cuda.is_available()
    if world > 1 and not (dist.is_available() and dist.is_initialized()):
        if cuda:
            torch.cuda.set_device(local)
        dist.init_process_group(backend="nccl" if cuda else "gloo")
    return torch.device("cuda", local) if cuda else torch.device("cpu"), world > 1


def load_resume_checkpoint(args: SegTrainConfig) -> dict[str, Any] | None:
    """The ``--resume`` checkpoint, refused when an argument that fixes the data order changed."""
    if not args.resume:
        return None
    ckpt = load_checkpoint(args.resume)
    if args.test_only:
        for k in DEPTH_INPUT_ARGS:
            if k in ckpt["args"]:
                setattr(args, k, ckpt["args"][k])
        return ckpt
    if args.valid_channel is None and "valid_channel" in ckpt["args"]:
        args.valid_channel = ckpt["args"]["valid_channel"]
    args.valid_channel = resolve_valid_channel(args.depth, args.valid_channel)
    for k in RESUME_FIXED_ARGS:
        if k in ckpt["args"] and ckpt["args"][k] != getattr(args, k):
            raise TrainerInputError(f"--{k.replace('_', '-')} {getattr(args, k)!r} differs from the checkpoint's "
                                    f"{ckpt['args'][k]!r}; exact resume needs the same value")
    return ckpt


def build_datasets(args: SegTrainConfig) -> tuple[SegStream, SegStream | None, RealSplit | None]:
    """(training stream, validation stream or None, grouped split of --real or None) from the data flags."""
    opts = DataOptions.from_args(args)
    cfg = sample_config(opts, crop=args.crop, rotate_deg=args.rotate_deg, jitter=args.jitter)
    if not args.data and not args.real:
        raise TrainerInputError("give training data: --data SHARDS and/or --real FOLDER")
    frac = args.val_fraction
    syn = val_syn = None
    if args.data:
        syn = shard_source(opts, args.data, frac, "train" if frac > 0 else "all", args.split_seed)
        if frac > 0:
            val_syn = shard_source(opts, args.data, frac, "val", args.split_seed)
    real = val_real = split = None
    if args.real:
        real, val_real, split = real_split(opts, args.real, frac, args.split_seed, args.real_stems)
    if args.val_data:
        val_syn = shard_source(opts, args.val_data)
    if args.val_real:
        val_real = real_split(opts, args.val_real, 0.0, 0)[0]
    repeat = args.real_repeat or (mix_repeat(len(real), len(syn)) if (real is not None and syn is not None) else 1)
    train_ds = SegStream(cfg, syn, real, real_repeat=repeat, batch_size=args.batch_size, train=True,
                         seed=args.seed, skip_bad=args.skip_bad, adapt=site_adaptation(args) if syn else None)
    eval_cfg = SampleConfig(**{**cfg.__dict__, "crop": None})
    return train_ds, eval_stream(eval_cfg, val_syn, val_real, seed=args.seed, skip_bad=args.skip_bad), split


def site_adaptation(args: SegTrainConfig) -> SiteAdaptation | None:
    """From ``--target F --target-appearance`` (a folder), or ``args.adapt_targets`` (paths set by sim2real)."""
    targets = args.adapt_targets
    if not targets and args.adapt_target:
        targets = targets_from_folder(args.adapt_target)
    if not targets:
        return None
    methods = tuple(m.strip() for m in args.adapt_methods.split(",") if m.strip())
    return SiteAdaptation(tuple(targets), methods, parse_band(args.adapt_band), args.adapt_prob)


def load_init_weights(path: str, bare: torch.nn.Module, args: SegTrainConfig) -> None:
    """Weights only from ``--init`` (pretrain -> fine-tune); arch and input channels must match."""
    ckpt = load_checkpoint(path)
    src = ckpt.get("args", {})
    if src.get("arch") not in (None, args.arch):
        raise TrainerInputError(f"--init {path}: checkpoint is a {src.get('arch')}, this run trains a {args.arch}")
    try:
        bare.load_state_dict(ckpt["model"])
    except RuntimeError as exc:
        first = str(exc).strip().splitlines()[0]
        raise TrainerInputError(f"--init {path}: weights do not fit this model ({first})") from None
    # provenance: every step the starting weights have seen, through chains of --init (stored with the args)
    args.init_steps = steps_seen(ckpt)


def precise_bn_batches(args: SegTrainConfig) -> int:
    """Batches for ``--precise-bn``: given, else 50 after ``--init`` (a fine-tune) and 0 otherwise."""
    if args.precise_bn is not None:
        return max(0, int(args.precise_bn))
    return 50 if args.init else 0


def finish_precise_bn(run: Run, train_ds: SegStream, state: TrainState) -> None:
    """Precise BN with the final weights (see ``trainer.seg.precise_bn``), on a fresh pass over the
    training stream with its own loader generator; logged and stored in the checkpoint args."""
    n = precise_bn_batches(run.args)
    if n <= 0:
        return
    train_ds.set_epoch(state.epoch + 1)
    loader = DataLoader(train_ds, batch_size=run.args.batch_size, num_workers=run.args.workers,
                        generator=torch.Generator().manual_seed(run.args.seed + 1),
                        prefetch_factor=2 if run.args.workers > 0 else None)
    used = precise_bn(run.model, loader, run.device, n)
    if run.main_proc:
        log.info("precise BN: BatchNorm statistics recomputed with the final weights on %d training batches", used)


def bn_target_photos(args: SegTrainConfig) -> tuple[str, ...] | None:
    """Photos for target BN: ``args.bn_targets`` (paths set by sim2real) or ``--target F --target-bn``."""
    photos = args.bn_targets
    if not photos and args.bn_target:
        photos = targets_from_folder(args.bn_target)
    return tuple(photos) if photos else None


def finish_target_bn(run: Run, state: TrainState) -> None:
    """BN statistics from the unlabeled site photos (``trainer.seg.target_bn``), after precise BN; the record
    goes into the final checkpoint (``target_bn``)."""
    photos = bn_target_photos(run.args)
    if photos is None:
        return
    used = adapt_bn_to_photos(run.bare, photos, run.cfg, run.device, crop=run.cfg.crop,
                              batches=run.args.bn_target_batches, batch_size=run.args.batch_size,
                              workers=run.args.workers, seed=run.args.seed)
    state.target_bn = {"target": run.args.bn_target or "photos given by sim2real", "photos": len(photos),
                       "batches": used, "crop": run.cfg.crop}
    run.model.train()
    if run.main_proc:
        log.info("target BN: BatchNorm statistics re-estimated on %d batches of %d unlabeled photos", used, len(photos))


def build_network(args: SegTrainConfig, in_channels: int, device: torch.device,
                  distributed: bool) -> tuple[torch.nn.Module, torch.nn.Module]:
    """(model to run, bare model to save): seeded init, channels_last on CUDA, SyncBN/DDP under torchrun."""
    torch.manual_seed(args.seed)
    model = build_model(args.arch, in_channels).to(device)
    if device.type == "cuda":
        model = model.to(memory_format=torch.channels_last)
    if distributed and args.sync_bn:
        model = torch.nn.SyncBatchNorm.convert_sync_batchnorm(model)
    bare = model
    if distributed:
        ids = [device.index] if device.type == "cuda" else None
        model = torch.nn.parallel.DistributedDataParallel(model, device_ids=ids)
    return model, bare


def step_budget(args: SegTrainConfig, steps_per_epoch: int) -> tuple[int, int]:
    """(epochs, total steps): ``--epochs`` of full epochs, or enough epochs to cover ``--max-steps``."""
    if args.max_steps is None:
        return args.epochs, args.epochs * steps_per_epoch
    return math.ceil(args.max_steps / steps_per_epoch), args.max_steps


def build_lr_scheduler(args: SegTrainConfig, opt: torch.optim.Optimizer,
                       total: int) -> torch.optim.lr_scheduler.LRScheduler:
    if args.lr_scheduler == "poly":
        return torch.optim.lr_scheduler.PolynomialLR(opt, total_iters=total, power=0.9)
    if args.lr_scheduler == "cosine":
        return torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=total)
    return torch.optim.lr_scheduler.ConstantLR(opt, factor=1.0, total_iters=0)


def restore(ckpt: dict[str, Any] | None, bare: torch.nn.Module, opt: torch.optim.Optimizer,
            sched: torch.optim.lr_scheduler.LRScheduler, scaler: torch.amp.GradScaler, amp: bool,
            weights_only: bool) -> TrainState:
    """Load weights and, unless ``weights_only`` (--test-only), optimizer, schedule, position and RNG."""
    state = TrainState()
    if ckpt is None:
        return state
    bare.load_state_dict(ckpt["model"])
    if weights_only:
        return state
    opt.load_state_dict(ckpt["optimizer"])
    sched.load_state_dict(ckpt["lr_scheduler"])
    if amp and ckpt.get("scaler"):
        scaler.load_state_dict(ckpt["scaler"])
    state.epoch, state.batch_in_epoch, state.step = ckpt["epoch"], ckpt["batch_in_epoch"], ckpt["step"]
    state.best = ckpt.get("best", state.best)
    set_rng_state(ckpt["rng"])
    return state


def checkpoint_payload(run: Run, state: TrainState) -> dict[str, Any]:
    """torchvision-layout checkpoint plus what step-exact resume needs (see ``trainer.core.checkpoint``)."""
    return {
        "model": run.bare.state_dict(), "optimizer": run.optimizer.state_dict(),
        "lr_scheduler": run.lr_scheduler.state_dict(), "scaler": run.scaler.state_dict() if run.amp else None,
        "epoch": state.epoch, "batch_in_epoch": state.batch_in_epoch, "step": state.step, "args": options_dict(run.args),
        "sample_config": run.cfg.__dict__, "rng": rng_state(), "best": state.best, "world_size": run.world,
    } | ({THRESHOLD_KEY: state.val_threshold} if state.val_threshold else {})


# ------------------------------------------------------------------ steps

def validate(run: Run, val_ds: SegStream | None, state: TrainState) -> dict[str, Any] | None:
    """Score the model on the validation stream (every rank), log it, and leave the model in train mode."""
    if val_ds is None:
        return None
    hist = evaluate(run.model, eval_loader(val_ds, run.args.workers, run.device), run.device, run.amp, run.progress)
    summary = hist.summary(0.5) | {"samples": len(val_ds)}
    for k in ("f1", "iou", "precision", "recall"):
        run.logger.scalar("val", k, summary["best"][k], state.step, state.epoch)
    run.logger.scalar("val", "best_threshold", summary["best"]["threshold"], state.step, state.epoch)
    run.model.train()
    return summary


def validation_source(args: SegTrainConfig) -> str:
    """What the validation stream holds, for the threshold record."""
    parts = [f"--val-real {args.val_real}"] if args.val_real else []
    parts += [f"--val-data {args.val_data}"] if args.val_data else []
    if args.val_fraction > 0:
        parts.append(f"--val-fraction {args.val_fraction:g} of the training data (split seed {args.split_seed})")
    return ", ".join(parts)


def record_validation(run: Run, state: TrainState, summary: dict[str, Any] | None) -> None:
    """On rank 0: keep ``best.pt`` for the best F1 so far (with its validation threshold) and write
    ``metrics_val.json``."""
    if summary is None or not run.main_proc:
        return
    b = summary["best"]
    if b["f1"] > state.best.get("f1", -1.0):
        state.best = {**b, "step": state.step, "epoch": state.epoch}
        record = threshold_record(b, validation_source(run.args), summary["samples"])
        save_checkpoint(run.out / "best.pt", checkpoint_payload(run, state) | {THRESHOLD_KEY: record})
    latest = {k: v for k, v in summary.items() if k != "pr_curve"}
    (run.out / "metrics_val.json").write_text(json.dumps(
        {"step": state.step, "epoch": state.epoch, "latest": latest, "best": state.best}, indent=2))


def train_step(run: Run, batch: dict[str, Any]) -> float:
    """One optimizer step on one batch (AMP and channels_last on CUDA); returns the loss."""
    x = batch["image"].to(run.device, non_blocking=True)
    y = batch["mask"].to(run.device, non_blocking=True)
    if run.device.type == "cuda":
        x = x.contiguous(memory_format=torch.channels_last)
    with torch.autocast(device_type=run.device.type, dtype=torch.float16, enabled=run.amp):
        logits = run.model(x)
    ignore = batch.get("ignore")
    if ignore is not None and bool(ignore.any()):  # pseudo-labels: uncertain pixels carry no loss
        loss = run.criterion(logits, y, 1.0 - ignore.to(run.device, non_blocking=True))
    else:
        loss = run.criterion(logits, y)
    run.optimizer.zero_grad(set_to_none=True)
    run.scaler.scale(loss).backward()
    run.scaler.step(run.optimizer)
    run.scaler.update()
    run.lr_scheduler.step()
    return float(loss.detach())


def train_one_epoch(run: Run, train_ds: SegStream, val_ds: SegStream | None, state: TrainState,
                    loader_gen: torch.Generator, bar: tqdm) -> None:
    """Train the rest of ``state.epoch`` (from ``state.batch_in_epoch``), stopping at the step budget.

    Validates every ``--val-every`` steps; the epoch-end validation is ``main``'s.
    """
    args = run.args
    train_ds.set_epoch(state.epoch, skip_batches=state.batch_in_epoch)
    loader = DataLoader(train_ds, batch_size=args.batch_size, num_workers=args.workers,
                        pin_memory=run.device.type == "cuda", generator=loader_gen,
                        persistent_workers=False, prefetch_factor=2 if args.workers > 0 else None)
    for batch in loader:
        lv = train_step(run, batch)
        state.step += 1
        state.batch_in_epoch += 1
        if not math.isfinite(lv):
            raise FloatingPointError(f"loss is {lv} at step {state.step}; lower --lr or check the data")
        run.logger.scalar("train", "loss", lv, state.step, state.epoch)
        if state.step % max(1, args.log_every) == 0:
            run.logger.scalar("train", "lr", run.optimizer.param_groups[0]["lr"], state.step, state.epoch)
        bar.update(1)
        bar.set_postfix(loss=f"{lv:.4f}", epoch=state.epoch)
        if args.val_every > 0 and state.step % args.val_every == 0:
            record_validation(run, state, validate(run, val_ds, state))
        if state.step >= run.total_steps or state.batch_in_epoch >= run.steps_per_epoch:
            break


def run_test_only(run: Run, val_ds: SegStream | None, state: TrainState) -> dict[str, Any]:
    """``--test-only``: validate the loaded weights and write ``metrics_val.json``."""
    summary = validate(run, val_ds, state)
    if summary is None:
        raise TrainerInputError("--test-only needs validation data (--val-data/--val-real/--val-fraction)")
    if run.main_proc:
        (run.out / "metrics_val.json").write_text(
            json.dumps({k: v for k, v in summary.items() if k != "pr_curve"}, indent=2))
    return summary


def fit(run: Run, train_ds: SegStream, val_ds: SegStream | None, state: TrainState) -> None:
    """Epoch loop: train, roll over the epoch, validate at its end (unless --val-every), checkpoint."""
    loader_gen = torch.Generator().manual_seed(run.args.seed)  # keeps DataLoader seeding off the global RNG
    run.model.train()
    bar = tqdm(total=run.total_steps, initial=state.step, desc="train", disable=not run.progress)
    while state.step < run.total_steps and state.epoch < run.epochs:
        if state.batch_in_epoch >= run.steps_per_epoch:
            state.epoch, state.batch_in_epoch = state.epoch + 1, 0
            continue
        train_one_epoch(run, train_ds, val_ds, state, loader_gen, bar)
        if state.batch_in_epoch >= run.steps_per_epoch:
            state.epoch, state.batch_in_epoch = state.epoch + 1, 0
            if run.args.val_every == 0:
                record_validation(run, state, validate(run, val_ds, state))
        if run.main_proc:
            save_checkpoint(run.out / "checkpoint.pt", checkpoint_payload(run, state))
    bar.close()
    finish_precise_bn(run, train_ds, state)
    finish_target_bn(run, state)
    if val_ds is not None:  # the final weights, as saved: their threshold is the one they are used at
        summary = validate(run, val_ds, state)
        record_validation(run, state, summary)
        state.val_threshold = threshold_record(summary["best"], validation_source(run.args), summary["samples"])
    if run.main_proc:
        final = {"finished": True} | ({"target_bn": state.target_bn} if state.target_bn else {})
        save_checkpoint(run.out / "checkpoint.pt", checkpoint_payload(run, state) | final)


def main(config: SegTrainConfig) -> dict[str, Any]:
    """Run training (or --test-only); returns the final/best validation summary."""
    args = dataclasses.replace(config)  # resolved below (targets, crop, labels, validity): the caller's stays as given
    device, distributed = init_distributed()
    if args.device:
        device = torch.device(args.device)
    rank, world = dist_info()
    main_proc = rank == 0
    out = Path(args.out)
    if main_proc:
        out.mkdir(parents=True, exist_ok=True)
    if args.crop == 0:
        args.crop = None
    resolve_site_targets(args)
    args.mask_member = args.mask_member or DEFAULT_MASK_MEMBER  # stored resolved in the checkpoint
    ckpt = load_resume_checkpoint(args)
    args.valid_channel = resolve_valid_channel(args.depth, args.valid_channel)  # stored resolved too
    train_ds, val_ds, split = build_datasets(args)
    if split is not None and main_proc:
        split.write(out)
    if bn_target_photos(args) and train_ds.cfg.channels != "rgb":  # checked before any step is trained
        raise TrainerInputError(f"--target-bn needs an RGB model (--depth none); photos have no {args.depth} depth")
    model, bare = build_network(args, train_ds.cfg.in_channels, device, distributed)
    amp = device.type == "cuda" and not args.no_amp
    spe = train_ds.steps_per_epoch(args.workers)
    epochs, total = step_budget(args, spe)
    opt = torch.optim.Adam(bare.parameters(), lr=args.lr, weight_decay=args.weight_decay)
    sched = build_lr_scheduler(args, opt, total)
    scaler = torch.amp.GradScaler("cuda", enabled=amp)
    criterion = make_loss(args.loss)
    if args.init and ckpt is None:
        load_init_weights(args.init, bare, args)
    elif ckpt is not None and "init_steps" in ckpt.get("args", {}):  # a resumed fine-tune keeps its provenance
        args.init_steps = ckpt["args"]["init_steps"]
    state = restore(ckpt, bare, opt, sched, scaler, amp, weights_only=args.test_only)
    run = Run(args=args, out=out, device=device, amp=amp, main_proc=main_proc, world=world, cfg=train_ds.cfg,
              model=model, bare=bare, optimizer=opt, lr_scheduler=sched, scaler=scaler, criterion=criterion,
              logger=_Logger(out, main_proc and not args.test_only), progress=main_proc and not args.no_progress,
              steps_per_epoch=spe, epochs=epochs, total_steps=total)
    if args.test_only:
        return run_test_only(run, val_ds, state)
    if main_proc:
        c = train_ds.cfg
        depth_in = "none" if c.channels == "rgb" else (
            f"{args.depth} {c.depth_norm}" + (f" ({c.relief}, +-{c.relief_range_mm:g} mm)" if c.depth_norm == "relief"
                                             else "") + (" + validity" if c.channels == "rgbdv" else ""))
        log.info("training %s on %s (labels %s, depth %s), %d steps/epoch, %d steps total, device %s",
                 args.arch, describe(train_ds), args.mask_member, depth_in, spe, total, device)
    t0 = time.perf_counter()
    try:
        fit(run, train_ds, val_ds, state)
    finally:
        run.logger.close()
    elapsed = time.perf_counter() - t0
    if main_proc:
        log.info("done: %d steps in %.1f s; best val F1 %s", state.step, elapsed, state.best.get("f1"))
    return {"step": state.step, "epoch": state.epoch, "best": state.best, "seconds": elapsed, "out": str(out)}
