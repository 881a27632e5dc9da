"""``cracktrain fusion``: train the confidence CNN of the ToF/LiDAR-stereo fusion.

Thesis Ch. 3.3 / 4.6 after Agresti et al. 2019: targets C* = exp(-|D - D_GT|)
for the stereo and the ToF (or LiDAR) disparity, MSE loss over pixels with a
GT value, Adadelta lr 0.01, batch 32, random 128-px patches with flips and
+-5 deg rotation. Data: shards of ``recipes/stereo_tof.toml``; a seeded
fraction of the samples (``--val-fraction``; whole scenes) is held out, and its keys are
stored in the checkpoint so ``cracktrain fusion-eval`` scores exactly them.

Shape, as in torchvision's references: ``build_*`` make the pieces,
``train_step`` runs one optimizer step, ``validate`` scores the held-out
scenes, ``main`` wires them. Patches are drawn from a numpy Generator seeded
from (seed, step), so ``--resume`` continues with the same next batches.
"""
from __future__ import annotations

import argparse
import csv
import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import torch
from tqdm import tqdm

from crackgen.cli_aliases import deprecated_alias
from fusion.depth.confidence import confidence_target, fuse_max
from fusion.depth.densify import METHODS as DENSIFY_METHODS
from fusion.depth.inputs import LIDAR_VARIANTS, VARIANTS
from fusion.depth.metrics import disparity_metrics
from trainer.core.checkpoint import load_checkpoint, save_checkpoint
from trainer.core.device import pick_device
from trainer.core.errors import TrainerInputError
from trainer.core.holdout import shard_groups, split_fraction_by_group
from trainer.core.options import options_dict
from trainer.depthfusion.augment import corrupt_scene_stereo, corrupt_stereo
from trainer.depthfusion.config import FusionTrainConfig
from trainer.depthfusion.data import (
    DISP_REFS,
    FusionScene,
    channel_stats,
    cut_patch,
    disparity_reference,
    load_shard_scenes,
    normalise,
    patch_geometry,
    relative_input,
    shard_keys,
)
from trainer.depthfusion.model import DILATIONS, IN_CHANNELS, ConfidenceCNN, receptive_field

log = logging.getLogger(__name__)

OPTIMIZERS = ("adadelta", "adam")
RESUME_FIXED_ARGS = {"variant": None, "seed": None, "val_fraction": None, "split_seed": None, "densify": None,
                     "disp_ref": "none", "stereo_failures": 0.0, "lidar_resample": 0, "other_bm3d": 0.0,
                     "dilations": "thesis", "occluders": 0}  # name -> value assumed for checkpoints made before the option


def add_fusion_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data", required=True, help="shards with stereo + ToF (+ LiDAR) (recipes/stereo_tof.toml)")
    p.add_argument("--variant", choices=tuple(VARIANTS), default="tof",
                   help="tof: 4 channels (stereo, ToF, L-R diff, amplitude); lidar: 3 channels (stereo, LiDAR, "
                        "L-R diff warped by the LiDAR); lidar4: lidar + the L-R diff warped by the stereo")
    p.add_argument("--val-fraction", type=float, default=0.2,
                   help="held-out fraction of the samples (whole scenes when the recipe rendered several views per scene)")
    p.add_argument("--split-seed", type=int, default=0)
    p.add_argument("--crop", dest="patch", type=int, default=128, help="random patch side (px)")
    deprecated_alias(p, "--patch", "--crop", "cracktrain")
    p.add_argument("--batch-size", "-b", type=int, default=32)
    p.add_argument("--max-steps", dest="steps", type=int, default=2000, help="optimizer steps")
    deprecated_alias(p, "--steps", "--max-steps", "cracktrain")
    p.add_argument("--optimizer", choices=OPTIMIZERS, default="adadelta")
    p.add_argument("--lr", type=float, default=0.01)
    p.add_argument("--rotate-deg", type=float, default=5.0)
    p.add_argument("--no-flips", action="store_true")
    p.add_argument("--densify", choices=DENSIFY_METHODS, default="normconv", help="how sparse ToF/LiDAR is filled")
    p.add_argument("--other-bm3d", type=float, default=0.0, metavar="SIGMA",
                   help="BM3D-denoise the densified ToF/LiDAR candidate (noise std SIGMA, disparity px) before the CNN "
                        "sees it and the rules fuse it, in training, fuse and fusion-eval alike; 0 = off (thesis)")
    p.add_argument("--dilations", choices=tuple(DILATIONS), default="thesis",
                   help="thesis: the 3x3 layers undilated, a 15 px receptive field; wide: dilated 2,4,8,4,1, 43 px "
                        "(the same weights and cost), to see across LiDAR scan lines")
    p.add_argument("--disp-ref", choices=DISP_REFS, default="none",
                   help="median: feed disparities relative to the scene's ToF/LiDAR median (scale-free across scenes)")
    p.add_argument("--stereo-failures", type=float, default=0.0, metavar="P",
                   help="lidar variant: probability per patch of SGBM region failures pasted into the stereo "
                        "channel (offset / flat fill / speckle; trainer.depthfusion.augment); 0 = off (thesis)")
    p.add_argument("--lidar-resample", type=int, default=0, metavar="K",
                   help="lidar variant: K more copies of each training scene with a scan-line LiDAR re-drawn from "
                        "the GT at a random density (4-20 rows apart), noise (0.05-1 px) and dropout (0-30%%); 0 = off")
    p.add_argument("--occluders", type=int, default=0, metavar="K",
                   help="lidar variants: K more copies of each training scene with another training scene pasted in "
                        "front inside a random blob, 2-24 px nearer: a depth edge with half-occlusions; SGBM is re-run "
                        "and the LiDAR re-drawn from the composited GT (trainer.depthfusion.occluders); 0 = off")
    p.add_argument("--stereo-dir", default=None, help="external stereo disparity per sample: DIR/KEY.{exr,pfm,npy,...}")
    p.add_argument("--other-dir", default=None, help="external ToF/LiDAR disparity (e.g. completed LiDAR) per sample")
    p.add_argument("--val-every", type=int, default=0, help="validate every N steps (0: only at the end)")
    p.add_argument("--log-every", type=int, default=10)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", default=None, help="cpu or cuda (default: cuda when available)")
    p.add_argument("--threads", type=int, default=0, help="torch CPU threads (0: torch default)")
    p.add_argument("--out", default="runs/fusion", help="output folder (last.pt, best.pt, log.csv)")
    p.add_argument("--resume", default=None, help="checkpoint to continue from")
    p.add_argument("--no-progress", action="store_true")


@dataclass
class FusionRun:
    """The fixed pieces of a run."""

    args: FusionTrainConfig
    device: torch.device
    train: list[FusionScene]
    val: list[FusionScene]
    mean: list[float]
    std: list[float]
    model: ConfidenceCNN
    optimizer: torch.optim.Optimizer


# ------------------------------------------------------------------ building blocks

def build_split(args: FusionTrainConfig) -> tuple[list[str], list[str]]:
    keys = shard_keys(args.data)
    if len(keys) < 2:
        raise TrainerInputError(f"--data {args.data} has {len(keys)} sample(s); fusion training needs at least 2")
    train_keys, val_keys = split_fraction_by_group(keys, shard_groups(args.data), args.val_fraction,
                                                   args.split_seed)  # views of one scene on one side
    if not train_keys:
        raise TrainerInputError(f"--val-fraction {args.val_fraction} leaves no training sample of {len(keys)}")
    return train_keys, val_keys


def build_optimizer(args: FusionTrainConfig, model: torch.nn.Module) -> torch.optim.Optimizer:
    if args.optimizer == "adadelta":
        return torch.optim.Adadelta(model.parameters(), lr=args.lr)
    return torch.optim.Adam(model.parameters(), lr=args.lr)


def sample_config(variant: str, mean: Sequence[float], std: Sequence[float], densify: str,
                  disp_ref: str = "none", other_bm3d: float = 0.0, dilations: str = "thesis") -> dict[str, Any]:
    """What ``fuse`` and ``fusion-eval`` need to rebuild the inputs and the network exactly as in training."""
    return {"task": "fusion", "variant": variant, "in_channels": IN_CHANNELS[variant], "channels": list(VARIANTS[variant]),
            "mean": list(mean), "std": list(std), "densify": densify, "disp_ref": disp_ref, "other_bm3d": other_bm3d,
            "dilations": list(DILATIONS[dilations]), "receptive_field_px": receptive_field(DILATIONS[dilations])}


def make_batch(scenes: Sequence[FusionScene], args: FusionTrainConfig, step: int, mean, std
               ) -> tuple[torch.Tensor, torch.Tensor]:
    """(x [B,C,P,P] normalised, target [B,2,P,P] with NaN where the GT has no value) for ``step``."""
    rng = np.random.default_rng(np.random.SeedSequence([args.seed, step]))
    size = min(args.patch, *(min(s.x.shape[:2]) for s in scenes))
    xs, ts = [], []
    for _ in range(args.batch_size):
        scene = scenes[rng.integers(len(scenes))]
        g = patch_geometry(scene.x.shape, size, rng, args.rotate_deg, not args.no_flips)
        if args.stereo_failures > 0 and args.variant == "lidar4":  # before the cut: channel 3 is recomputed
            xs_scene, _ = corrupt_scene_stereo(scene.x, scene.grey, g.x0, g.y0, size, rng, args.stereo_failures)
            x, gt = cut_patch(xs_scene, scene.gt, g)
        else:
            x, gt = cut_patch(scene.x, scene.gt, g)
            if args.stereo_failures > 0:
                x, _ = corrupt_stereo(x, rng, args.stereo_failures)
        ts.append(np.stack([confidence_target(x[..., 0], gt), confidence_target(x[..., 1], gt)]))
        ref = disparity_reference(scene.x, args.disp_ref)  # the whole scene's, as at inference
        xs.append(normalise(relative_input(x, ref), mean, std).transpose(2, 0, 1))
    return torch.from_numpy(np.stack(xs)), torch.from_numpy(np.stack(ts))


def masked_mse(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """MSE between predicted and target confidences over pixels with a GT (target not NaN)."""
    ok = torch.isfinite(target)
    if not ok.any():
        return pred.sum() * 0.0
    return ((pred - torch.nan_to_num(target)) ** 2)[ok].mean()


def train_step(run: FusionRun, step: int) -> float:
    run.model.train()
    x, t = make_batch(run.train, run.args, step, run.mean, run.std)
    loss = masked_mse(run.model(x.to(run.device)), t.to(run.device))
    run.optimizer.zero_grad(set_to_none=True)
    loss.backward()
    run.optimizer.step()
    return float(loss.detach())


@torch.no_grad()
def predict_confidence(model: ConfidenceCNN, x: np.ndarray, mean, std, device: torch.device,
                       disp_ref: str = "none") -> np.ndarray:
    """(H,W,C) raw inputs -> (2,H,W) confidences (stereo, other) of one whole scene."""
    model.eval()
    x = relative_input(x, disparity_reference(x, disp_ref))
    inp = torch.from_numpy(normalise(x, mean, std).transpose(2, 0, 1)[None]).to(device)
    return model(inp)[0].float().cpu().numpy()


def validate(run: FusionRun) -> dict[str, float]:
    """Held-out confidence MSE and the fused-max MAE / input MAEs, averaged over scenes."""
    losses, mae = [], {"stereo": [], "other": [], "fused_max": []}
    for s in run.val:
        c = predict_confidence(run.model, s.x, run.mean, run.std, run.device, run.args.disp_ref)
        t = np.stack([confidence_target(s.x[..., 0], s.gt), confidence_target(s.x[..., 1], s.gt)])
        ok = np.isfinite(t)
        losses.append(float(np.mean((c[ok] - t[ok]) ** 2)))
        mae["stereo"].append(disparity_metrics(s.x[..., 0], s.gt)["mae"])
        mae["other"].append(disparity_metrics(s.x[..., 1], s.gt)["mae"])
        mae["fused_max"].append(disparity_metrics(fuse_max(s.x[..., 0], s.x[..., 1], c[0], c[1]), s.gt)["mae"])
    out = {"val_loss": float(np.mean(losses))}
    out.update({f"val_mae_{k}": float(np.nanmean(v)) for k, v in mae.items()})
    return out


def checkpoint_payload(run: FusionRun, step: int, best: dict[str, Any], val_keys: list[str]) -> dict[str, Any]:
    return {"model": run.model.state_dict(), "optimizer": run.optimizer.state_dict(), "step": step,
            "args": options_dict(run.args), "sample_config": sample_config(run.args.variant, run.mean, run.std, run.args.densify,
                                                           run.args.disp_ref, run.args.other_bm3d, run.args.dilations),
            "best": best, "val_keys": val_keys, "train_keys": [s.key for s in run.train]}


def check_resume(args: FusionTrainConfig, ckpt: dict[str, Any]) -> None:
    old = ckpt["args"]
    changed = [k for k, before in RESUME_FIXED_ARGS.items() if old.get(k, before) != getattr(args, k)]
    if changed:
        raise TrainerInputError(f"--resume {args.resume}: {', '.join(changed)} differ from the checkpoint's")
    if ckpt.get("sample_config", {}).get("task") != "fusion":
        raise TrainerInputError(f"--resume {args.resume} is not a fusion checkpoint")


# ------------------------------------------------------------------ main

def main(args: FusionTrainConfig) -> dict[str, Any]:
    if args.threads > 0:
        torch.set_num_threads(args.threads)
    if args.batch_size < 1 or args.patch < 8 or args.steps < 0:
        raise TrainerInputError("--batch-size must be >= 1, --crop >= 8 and --max-steps >= 0")
    if not 0.0 <= args.stereo_failures <= 1.0:
        raise TrainerInputError(f"--stereo-failures must be a probability in [0, 1], got {args.stereo_failures}")
    if args.stereo_failures > 0 and args.variant not in LIDAR_VARIANTS:
        raise TrainerInputError("--stereo-failures needs --variant lidar or lidar4: the ToF variant's grey difference "
                                "is warped by the stereo disparity, which a pasted failure would contradict")
    if args.lidar_resample < 0 or (args.lidar_resample > 0 and args.variant not in LIDAR_VARIANTS):
        raise TrainerInputError(f"--lidar-resample must be >= 0 and needs --variant lidar or lidar4, got "
                                f"{args.lidar_resample} with --variant {args.variant}")
    if args.lidar_resample > 0 and args.other_dir:
        raise TrainerInputError("--lidar-resample re-draws the LiDAR from the GT: it cannot be combined with --other-dir")
    if args.occluders < 0 or (args.occluders > 0 and args.variant not in LIDAR_VARIANTS):
        raise TrainerInputError(f"--occluders must be >= 0 and needs --variant lidar or lidar4, got "
                                f"{args.occluders} with --variant {args.variant}")
    if args.occluders > 0 and (args.other_dir or args.stereo_dir):
        raise TrainerInputError("--occluders re-runs SGBM and re-draws the LiDAR on composited views: it cannot be "
                                "combined with --stereo-dir or --other-dir")
    device = pick_device(args.device)
    if device.type == "cuda" and not torch.cuda.is_available():
        raise TrainerInputError("--device cuda but CUDA is not available")
    ckpt = load_checkpoint(args.resume) if args.resume else None
    if ckpt is not None:
        check_resume(args, ckpt)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    train_keys, val_keys = build_split(args)
    progress = not args.no_progress
    if args.other_bm3d < 0:
        raise TrainerInputError(f"--other-bm3d must be >= 0 (BM3D sigma in disparity px), got {args.other_bm3d}")
    load = dict(variant=args.variant, densify=args.densify, stereo_dir=args.stereo_dir, other_dir=args.other_dir,
                progress=progress, other_bm3d=args.other_bm3d)
    train = load_shard_scenes(args.data, keys=train_keys, lidar_resample=args.lidar_resample, seed=args.seed,
                              occluders=args.occluders, **load)
    val = load_shard_scenes(args.data, keys=val_keys, **load) if val_keys else []
    mean, std = channel_stats(train, args.disp_ref) if ckpt is None else (ckpt["sample_config"]["mean"], ckpt["sample_config"]["std"])
    torch.manual_seed(args.seed)
    model = ConfidenceCNN(IN_CHANNELS[args.variant], DILATIONS[args.dilations]).to(device)
    optimizer = build_optimizer(args, model)
    start, best = 0, {"val_mae_fused_max": math.inf}
    if ckpt is not None:
        model.load_state_dict(ckpt["model"])
        optimizer.load_state_dict(ckpt["optimizer"])
        start, best = int(ckpt["step"]), ckpt["best"]
    run = FusionRun(args, device, train, val, mean, std, model, optimizer)
    log.info("fusion %s: %d train / %d held-out scenes, %d params, %s", args.variant, len(train), len(val),
             sum(p.numel() for p in model.parameters()), device)
    new_log = not (out / "log.csv").exists() or ckpt is None
    t0, recent, val = time.perf_counter(), [], {}
    with open(out / "log.csv", "w" if new_log else "a", newline="") as fh:
        writer = csv.writer(fh)
        if new_log:
            writer.writerow(["step", "loss", "val_loss", "val_mae_stereo", "val_mae_other", "val_mae_fused_max", "seconds"])
        bar = tqdm(range(start, args.steps), desc="fusion", unit="step", disable=not progress, initial=start,
                   total=args.steps)
        for step in bar:
            recent.append(train_step(run, step))
            done = step + 1
            last = done == args.steps
            if val_keys and ((args.val_every and done % args.val_every == 0) or last):
                val = validate(run)
                if val["val_mae_fused_max"] < best["val_mae_fused_max"]:
                    best = {"step": done, **val}
                    save_checkpoint(out / "best.pt", checkpoint_payload(run, done, best, val_keys))
            if done % args.log_every == 0 or last or val:
                loss = float(np.mean(recent))
                bar.set_postfix(loss=f"{loss:.4f}")
                writer.writerow([done, f"{loss:.6f}"] + [f"{val[k]:.6f}" if k in val else "" for k in
                                 ("val_loss", "val_mae_stereo", "val_mae_other", "val_mae_fused_max")]
                                + [f"{time.perf_counter() - t0:.1f}"])
                fh.flush()
                recent, val = [], {}
        save_checkpoint(out / "last.pt", checkpoint_payload(run, args.steps, best, val_keys))
    return {"step": args.steps, "best": best, "out": str(out), "train": len(train), "val": len(val_keys),
            "seconds": round(time.perf_counter() - t0, 1)}
