"""``cracktrain seg``: a flat training loop in the style of torchvision references/segmentation.

Thesis defaults: DeepLabV3-ResNet50, BCE, Adam lr 1e-4, batch 16, 30 epochs.
Synthetic shards (``--data``) and a real folder (``--real``) can be mixed; the
real set is repeated N times, N the largest value with N*|real| < |synthetic|
(``--real-repeat`` overrides). Validation (``--val-data``/``--val-real`` or
``--val-fraction`` of the training sources) picks ``best.pt`` by F1 at the
best threshold. ``--resume`` continues exactly: same next batches, same step.
Runs under ``torchrun`` (DDP; gloo on CPU, nccl on CUDA).
"""
from __future__ import annotations

import argparse
import csv
import json
import logging
import math
import os
import time
from pathlib import Path
from typing import Any

import torch
import torch.distributed as dist
from torch.utils.data import DataLoader
from tqdm import tqdm

from trainer.augment import SampleConfig
from trainer.builders import add_data_args, describe, eval_loader, eval_stream, real_split, sample_config_from_args
from trainer.checkpoint import load_checkpoint, rng_state, save_checkpoint, set_rng_state
from trainer.errors import TrainerInputError
from trainer.losses import LOSSES, make_loss
from trainer.metrics import ConfusionHistogram
from trainer.models import ARCHS, build_model
from trainer.sources import ShardSource
from trainer.stream import SegStream, dist_info, mix_repeat

log = logging.getLogger(__name__)


def add_seg_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data", default=None, help="synthetic dataset folder (shards) or one .tar")
    p.add_argument("--real", default=None, help="real image/mask folder to train on (mixed with --data)")
    p.add_argument("--real-repeat", type=int, default=None, help="repeat the real set N times (default: thesis rule)")
    p.add_argument("--val-data", default=None, help="synthetic validation shards")
    p.add_argument("--val-real", default=None, help="real validation folder")
    p.add_argument("--val-fraction", type=float, default=0.0, help="hold out this fraction of --data/--real for validation")
    p.add_argument("--split-seed", type=int, default=0)
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
    p.add_argument("--val-every", type=int, default=0, help="validate every N steps (0: at each epoch end)")
    p.add_argument("--log-every", type=int, default=10)
    p.add_argument("--out", default="runs/seg", help="output folder (checkpoints, log.csv, tensorboard)")
    p.add_argument("--resume", default=None, help="checkpoint to continue from")
    p.add_argument("--test-only", action="store_true", help="only validate the --resume checkpoint")
    p.add_argument("--no-progress", action="store_true")
    add_data_args(p)


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


def _sources(args: argparse.Namespace) -> tuple[SegStream, SegStream | None]:
    cfg = sample_config_from_args(args)
    if not args.data and not args.real:
        raise TrainerInputError("give training data: --data SHARDS and/or --real FOLDER")
    frac = args.val_fraction
    syn = val_syn = None
    if args.data:
        syn = ShardSource(Path(args.data), args.depth, frac, "train" if frac > 0 else "all", args.split_seed)
        if frac > 0:
            val_syn = ShardSource(Path(args.data), args.depth, frac, "val", args.split_seed)
    real = val_real = None
    if args.real:
        real, val_real = real_split(args, args.real, frac, args.split_seed, getattr(args, "real_stems", None))
    if args.val_data:
        val_syn = ShardSource(Path(args.val_data), args.depth)
    if args.val_real:
        val_real = real_split(args, args.val_real, 0.0, 0)[0]
    repeat = args.real_repeat or (mix_repeat(len(real), len(syn)) if (real is not None and syn is not None) else 1)
    train_ds = SegStream(cfg, syn, real, real_repeat=repeat, batch_size=args.batch_size, train=True,
                         seed=args.seed, skip_bad=args.skip_bad)
    eval_cfg = SampleConfig(**{**cfg.__dict__, "crop": None})
    return train_ds, eval_stream(args, eval_cfg, val_syn, val_real)


@torch.no_grad()
def evaluate_model(model: torch.nn.Module, loader: DataLoader, device: torch.device, amp: bool = False,
                   progress: bool = False, on_batch: Any = None) -> ConfusionHistogram:
    """Dataset-level histogram of probabilities (summed over DDP ranks)."""
    model.eval()
    hist = ConfusionHistogram.empty()
    for batch in tqdm(loader, desc="eval", disable=not progress, leave=False):
        x = batch["image"].to(device, non_blocking=True)
        target = batch.get("mask_full", batch["mask"]).to(device)
        with torch.autocast(device_type=device.type, dtype=torch.float16, enabled=amp):
            logits = model(x)
        if logits.shape[-2:] != target.shape[-2:]:
            logits = torch.nn.functional.interpolate(logits.float(), size=target.shape[-2:], mode="bilinear", align_corners=False)
        prob = torch.sigmoid(logits.float())
        hist.update(prob, target)
        if on_batch is not None:
            on_batch(batch, prob)
    hist.all_reduce()
    return hist


def _scheduler(args: argparse.Namespace, opt: torch.optim.Optimizer, total: int) -> torch.optim.lr_scheduler.LRScheduler:
    if args.lr_scheduler == "poly":
        return torch.optim.lr_scheduler.PolynomialLR(opt, total_iters=total, power=0.9)
    if args.lr_scheduler == "cosine":
        return torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=total)
    return torch.optim.lr_scheduler.ConstantLR(opt, factor=1.0, total_iters=0)


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


def train(args: argparse.Namespace) -> dict[str, Any]:
    """Run training (or --test-only); returns the final/best validation summary."""
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
    ckpt = load_checkpoint(args.resume) if args.resume else None
    if ckpt is not None:
        for k in ("arch", "depth", "valid_channel", "seed", "batch_size", "workers"):
            if k in ckpt["args"] and ckpt["args"][k] != getattr(args, k) and not args.test_only:
                raise TrainerInputError(f"--{k.replace('_', '-')} {getattr(args, k)!r} differs from the checkpoint's {ckpt['args'][k]!r}; exact resume needs the same value")
    train_ds, val_ds = _sources(args)
    cfg = train_ds.cfg
    torch.manual_seed(args.seed)
    model = build_model(args.arch, cfg.in_channels).to(device)
    amp = device.type == "cuda" and not args.no_amp
    if device.type == "cuda":
        model = model.to(memory_format=torch.channels_last)
    if distributed and args.sync_bn:
        model = torch.nn.SyncBatchNorm.convert_sync_batchnorm(model)
    bare = model
    if distributed:
        model = torch.nn.parallel.DistributedDataParallel(model, device_ids=[device.index] if device.type == "cuda" else None)
    spe = train_ds.steps_per_epoch(args.workers)
    epochs = args.epochs if args.max_steps is None else math.ceil(args.max_steps / spe)
    total = epochs * spe if args.max_steps is None else args.max_steps
    opt = torch.optim.Adam(bare.parameters(), lr=args.lr, weight_decay=args.weight_decay)
    sched = _scheduler(args, opt, total)
    scaler = torch.amp.GradScaler("cuda", enabled=amp)
    loss_fn = make_loss(args.loss)
    epoch, batch_in_epoch, step = 0, 0, 0
    best: dict[str, Any] = {"f1": -1.0}
    if ckpt is not None:
        bare.load_state_dict(ckpt["model"])
        if not args.test_only:
            opt.load_state_dict(ckpt["optimizer"])
            sched.load_state_dict(ckpt["lr_scheduler"])
            if amp and ckpt.get("scaler"):
                scaler.load_state_dict(ckpt["scaler"])
            epoch, batch_in_epoch, step = ckpt["epoch"], ckpt["batch_in_epoch"], ckpt["step"]
            best = ckpt.get("best", best)
            set_rng_state(ckpt["rng"])
    progress = main_proc and not args.no_progress
    logger = _Logger(out, main_proc and not args.test_only)

    def validate() -> dict[str, Any] | None:
        if val_ds is None:
            return None
        hist = evaluate_model(model, eval_loader(val_ds, args.workers, device), device, amp, progress)
        summary = hist.summary(0.5)
        for k in ("f1", "iou", "precision", "recall"):
            logger.scalar("val", k, summary["best"][k], step, epoch)
        logger.scalar("val", "best_threshold", summary["best"]["threshold"], step, epoch)
        model.train()
        return summary

    if args.test_only:
        summary = validate()
        if summary is None:
            raise TrainerInputError("--test-only needs validation data (--val-data/--val-real/--val-fraction)")
        if main_proc:
            (out / "metrics_val.json").write_text(json.dumps({k: v for k, v in summary.items() if k != "pr_curve"}, indent=2))
        return summary

    def checkpoint_payload() -> dict[str, Any]:
        return {
            "model": bare.state_dict(), "optimizer": opt.state_dict(), "lr_scheduler": sched.state_dict(),
            "scaler": scaler.state_dict() if amp else None, "epoch": epoch, "batch_in_epoch": batch_in_epoch,
            "step": step, "args": vars(args), "sample_config": cfg.__dict__, "rng": rng_state(), "best": best,
            "world_size": world,
        }

    def after_validation(summary: dict[str, Any] | None) -> None:
        nonlocal best
        if summary is None or not main_proc:
            return
        b = summary["best"]
        if b["f1"] > best.get("f1", -1.0):
            best = {**b, "step": step, "epoch": epoch}
            save_checkpoint(out / "best.pt", {**checkpoint_payload(), "best": best})
        (out / "metrics_val.json").write_text(json.dumps(
            {"step": step, "epoch": epoch, "latest": {k: v for k, v in summary.items() if k != "pr_curve"}, "best": best}, indent=2))

    if main_proc:
        log.info("training %s on %s, %d steps/epoch, %d steps total, device %s", args.arch, describe(train_ds), spe, total, device)
    loader_gen = torch.Generator().manual_seed(args.seed)  # keeps DataLoader seeding off the global RNG
    model.train()
    t0 = time.perf_counter()
    last_summary = None
    bar = tqdm(total=total, initial=step, desc="train", disable=not progress)
    while step < total and epoch < epochs:
        if batch_in_epoch >= spe:
            epoch, batch_in_epoch = epoch + 1, 0
            continue
        train_ds.set_epoch(epoch, skip_batches=batch_in_epoch)
        loader = DataLoader(train_ds, batch_size=args.batch_size, num_workers=args.workers,
                            pin_memory=device.type == "cuda", generator=loader_gen,
                            persistent_workers=False, prefetch_factor=2 if args.workers > 0 else None)
        for batch in loader:
            x = batch["image"].to(device, non_blocking=True)
            y = batch["mask"].to(device, non_blocking=True)
            if device.type == "cuda":
                x = x.contiguous(memory_format=torch.channels_last)
            with torch.autocast(device_type=device.type, dtype=torch.float16, enabled=amp):
                logits = model(x)
            loss = loss_fn(logits, y)
            opt.zero_grad(set_to_none=True)
            scaler.scale(loss).backward()
            scaler.step(opt)
            scaler.update()
            sched.step()
            step += 1
            batch_in_epoch += 1
            lv = float(loss.detach())
            if not math.isfinite(lv):
                raise FloatingPointError(f"loss is {lv} at step {step}; lower --lr or check the data")
            logger.scalar("train", "loss", lv, step, epoch)
            if step % max(1, args.log_every) == 0:
                logger.scalar("train", "lr", opt.param_groups[0]["lr"], step, epoch)
            bar.update(1)
            bar.set_postfix(loss=f"{lv:.4f}", epoch=epoch)
            if args.val_every and step % args.val_every == 0:
                last_summary = validate()
                after_validation(last_summary)
            if step >= total or batch_in_epoch >= spe:
                break
        if batch_in_epoch >= spe:
            epoch, batch_in_epoch = epoch + 1, 0
            if not args.val_every:
                last_summary = validate()
                after_validation(last_summary)
        if main_proc:
            save_checkpoint(out / "checkpoint.pt", checkpoint_payload())
    bar.close()
    if main_proc:
        save_checkpoint(out / "checkpoint.pt", checkpoint_payload())
        if val_ds is not None and best.get("f1", -1) < 0:
            after_validation(validate())
    logger.close()
    elapsed = time.perf_counter() - t0
    if main_proc:
        log.info("done: %d steps in %.1f s; best val F1 %s", step, elapsed, best.get("f1"))
    return {"step": step, "epoch": epoch, "best": best, "seconds": elapsed, "out": str(out)}
