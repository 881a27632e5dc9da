"""``cracktrain fusion-eval``: the thesis-style fusion table on held-out shards (Tables 3.6-3.8).

Rows: stereo, ToF (or LiDAR), fused with the max rule, fused with the softmax-
weighted rule, the max-fused map after BM3D and, as its baseline, the ToF/LiDAR
map after the same BM3D (a filter alone can beat an input); ``--all-filters`` adds BM3D
before fusion and CLAHE before/after (the thesis's other settings). Columns:
MSE, MAE, RMSE (px), % of pixels with error > 1/2/3/5 px, density. Per-scene
metrics are averaged over scenes. By default the scenes are the checkpoint's
held-out keys, so the table never scores training data. ``--real-stereo``
scores a LiDAR model on real stereo pairs with a LiDAR simulated from their GT
(``trainer.depthfusion.real_scenes``).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from crackgen.cli_aliases import deprecated_alias
from fusion.depth.inputs import LIDAR_VARIANTS, OTHER_NAME
from fusion.depth.metrics import average_metrics, disparity_metrics, format_table
from fusion.depth.postfilter import PostFilter
from trainer.core.device import pick_device
from trainer.core.errors import TrainerInputError
from trainer.depthfusion.apply import add_stereo_holes_arg, fuse_scene, load_fusion_model
from trainer.depthfusion.config import FusionEvalOptions
from trainer.depthfusion.data import load_shard_scenes, shard_keys
from trainer.depthfusion.real_scenes import SimulatedLidar, add_real_args, real_scene


def add_fusion_eval_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--checkpoint", "-c", dest="ckpt", default=None, help="checkpoint from cracktrain fusion")
    deprecated_alias(p, "--ckpt", "--checkpoint", "cracktrain")
    p.add_argument("--data", default=None, help="shards to score (default: the checkpoint's --data)")
    p.add_argument("--keys", choices=("val", "all"), default="val",
                   help="val: the checkpoint's held-out samples; all: every sample of --data")
    p.add_argument("--stereo-dir", default=None, help="external stereo disparity per sample: DIR/KEY.{exr,pfm,npy,...}")
    p.add_argument("--other-dir", default=None, help="external ToF/LiDAR disparity per sample")
    p.add_argument("--bm3d-sigma", type=float, default=0.5, help="BM3D noise std (disparity px)")
    p.add_argument("--all-filters", action="store_true", help="also BM3D before, CLAHE before and after")
    p.add_argument("--out", default=None, help="write metrics.json and table.md here")
    p.add_argument("--device", default=None)
    p.add_argument("--threads", type=int, default=0)
    p.add_argument("--no-progress", action="store_true")
    add_stereo_holes_arg(p)
    add_real_args(p)


def evaluate_scene(model, cfg, scene, device, filters: dict[str, PostFilter],
                   stereo_holes: str = "cnn") -> dict[str, dict[str, float]]:
    """Metrics of every row for one scene."""
    base = fuse_scene(model, cfg, scene.x, device, None, scene.stereo_valid, stereo_holes)
    other = OTHER_NAME[cfg["variant"]]
    rows = {"stereo": disparity_metrics(base["stereo"], scene.gt),
            other: disparity_metrics(base["other"], scene.gt),
            "fused, max": disparity_metrics(base["fused_max"], scene.gt),
            "fused, weighted": disparity_metrics(base["fused_weighted"], scene.gt)}
    for name, f in filters.items():
        fused = (f.apply(base["fused_max"]) if f.stage == "after" else
                 fuse_scene(model, cfg, scene.x, device, f, scene.stereo_valid, stereo_holes)["fused_max"])
        rows[name] = disparity_metrics(fused, scene.gt)
        if f.stage == "after" and f.method == "bm3d":  # the fair baseline: the same filter on the input alone
            rows[f"{other} + BM3D after"] = disparity_metrics(f.apply(base["other"]), scene.gt)
    return rows


def run_fusion_eval(args: FusionEvalOptions) -> dict[str, Any]:
    if args.threads > 0:
        torch.set_num_threads(args.threads)
    device = pick_device(args.device)
    model, cfg, ckpt = load_fusion_model(args.ckpt, device)
    if args.real_stereo:
        if cfg["variant"] not in LIDAR_VARIANTS:
            raise TrainerInputError(f"--real-stereo simulates a LiDAR: {args.ckpt} is a {cfg['variant']} model")
        data = ", ".join(str(Path(f).name) for f in args.real_stereo)
        lidar_sim = SimulatedLidar(args.lidar_lines, args.lidar_sigma_px, args.lidar_dropout, args.seed)
        scenes = [real_scene(f, lidar_sim, cfg["densify"], cfg["variant"], cfg.get("other_bm3d", 0.0))
                  for f in args.real_stereo]
    else:
        data = args.data or ckpt["args"].get("data")
        if data is None:
            raise TrainerInputError("give --data: the checkpoint does not name its data")
        keys = ckpt.get("val_keys") if args.keys == "val" else shard_keys(data)
        if not keys:
            raise TrainerInputError(f"checkpoint {args.ckpt} holds no held-out keys (trained with --val-fraction 0): "
                                    "use --keys all with other --data")
        stereo_dir = args.stereo_dir or ckpt["args"].get("stereo_dir")
        other_dir = args.other_dir or ckpt["args"].get("other_dir")
        scenes = load_shard_scenes(data, cfg["variant"], keys=keys, densify=cfg["densify"], stereo_dir=stereo_dir,
                                   other_dir=other_dir, progress=not args.no_progress,
                                   other_bm3d=cfg.get("other_bm3d", 0.0))
    filters = {"fused, max + BM3D after": PostFilter("bm3d", "after", args.bm3d_sigma)}
    if args.all_filters:
        filters.update({"BM3D before, fused max": PostFilter("bm3d", "before", args.bm3d_sigma),
                        "fused, max + CLAHE after": PostFilter("clahe", "after"),
                        "CLAHE before, fused max": PostFilter("clahe", "before")})
    per_scene = {}
    for s in tqdm(scenes, desc="fusion-eval", unit="scene", disable=args.no_progress):
        per_scene[s.key] = evaluate_scene(model, cfg, s, device, filters, args.stereo_holes)
    rows = list(next(iter(per_scene.values())))
    mean = {r: average_metrics(per_scene[k][r] for k in per_scene) for r in rows}
    table = format_table(mean)
    res = {"data": str(data), "keys": "real" if args.real_stereo else args.keys, "scenes": len(scenes), "variant": cfg["variant"],
           "ckpt": str(args.ckpt), "stereo_holes": args.stereo_holes, "mean": mean, "per_scene": per_scene, "table": table}
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "metrics.json").write_text(json.dumps({k: v for k, v in res.items() if k != "table"}, indent=2,
                                                     default=lambda o: float(o) if isinstance(o, np.floating) else str(o)))
        (out / "table.md").write_text(table + "\n")
    return res
