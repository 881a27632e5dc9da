"""Applying a trained confidence CNN: one scene -> confidences and fused maps; ``cracktrain fuse``.

``fuse_scene`` is shared by ``cracktrain fuse`` (files) and ``cracktrain
fusion-eval`` (held-out shards), so both fuse identically. A post-filter
(``fusion.depth.postfilter``) runs either on both candidate disparities before the
CNN sees them (``before``) or on the fused maps (``after``).

``cracktrain fuse`` is the plug-in point for stronger inputs: any stereo
disparity (e.g. LEAStereo) and any ToF or completed LiDAR disparity (e.g.
PENet) in the left view, as EXR/PFM/TIFF/PNG/NPY files (-1, 0, inf, NaN =
no value); sparse maps are densified as in training.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np
import torch

from crackgen.cli_aliases import deprecated_alias
from fusion.depth.confidence import fuse_max, fuse_weighted, softmax_weights
from fusion.depth.inputs import VARIANTS, FusionInputError, build_inputs
from fusion.depth.metrics import disparity_metrics
from fusion.depth.postfilter import FILTERS, STAGES, PostFilter, PostFilterError
from trainer.core.checkpoint import load_checkpoint
from trainer.core.device import pick_device
from trainer.core.errors import TrainerInputError
from trainer.core.imageio import read_float_map, read_rgb
from trainer.depthfusion.config import FuseOptions
from trainer.depthfusion.model import THESIS, ConfidenceCNN
from trainer.depthfusion.train import predict_confidence


def load_fusion_model(path: str | Path, device: torch.device) -> tuple[ConfidenceCNN, dict[str, Any], dict[str, Any]]:
    """(model, sample_config, checkpoint) of a ``cracktrain fusion`` checkpoint."""
    ckpt = load_checkpoint(path)
    cfg = ckpt["sample_config"]
    if not isinstance(cfg, dict) or cfg.get("task") != "fusion":
        raise TrainerInputError(f"checkpoint {path} is not a fusion checkpoint (made by cracktrain fusion)")
    model = ConfidenceCNN(cfg["in_channels"], tuple(cfg.get("dilations", THESIS)))
    model.load_state_dict(ckpt["model"])
    return model.to(device).eval(), cfg, ckpt


def post_filter_from_args(args: FuseOptions) -> PostFilter | None:
    if args.post == "none":
        return None
    try:
        return PostFilter(args.post, args.post_stage, args.bm3d_sigma, args.clahe_clip)
    except PostFilterError as exc:
        raise TrainerInputError(str(exc)) from None


STEREO_HOLES = ("cnn", "other")


def fuse_scene(model: ConfidenceCNN, cfg: dict[str, Any], x: np.ndarray, device: torch.device,
               post: PostFilter | None = None, stereo_valid: np.ndarray | None = None,
               stereo_holes: str = "cnn") -> dict[str, np.ndarray]:
    """Raw input stack (H,W,C) -> confidences and fused maps (max and weighted rules).

    ``stereo_holes="cnn"`` (the thesis's dense input): a filled stereo hole competes
    on its confidence like a measured value. ``"other"``: where the stereo had no
    measurement (``stereo_valid`` False) the rules take the ToF/LiDAR value, as they
    do for any candidate without a value. On the flat renders the filled holes
    (mostly SGBM's left band) are good extrapolations and ``cnn`` is better; on real
    scenes they span occlusions and ``other`` is better (docs/results/depth-fusion.md).
    """
    if stereo_holes not in STEREO_HOLES:
        raise TrainerInputError(f"--stereo-holes must be one of {', '.join(STEREO_HOLES)}, got {stereo_holes!r}")
    x = x.copy()
    if post is not None and post.stage == "before":
        x[..., 0], x[..., 1] = post.apply(x[..., 0]), post.apply(x[..., 1])
    c = predict_confidence(model, x, cfg["mean"], cfg["std"], device, cfg.get("disp_ref", "none"))
    ds = x[..., 0]
    if stereo_holes == "other" and stereo_valid is not None:
        ds = np.where(stereo_valid, ds, np.float32(-1.0))
    out = {"conf_stereo": c[0], "conf_other": c[1], "stereo": x[..., 0], "other": x[..., 1],
           "fused_max": fuse_max(ds, x[..., 1], c[0], c[1]),
           "fused_weighted": fuse_weighted(ds, x[..., 1], c[0], c[1]),
           "weight_other": softmax_weights(c[0], c[1])[1].astype(np.float32)}
    if post is not None and post.stage == "after":
        out["fused_max"], out["fused_weighted"] = post.apply(out["fused_max"]), post.apply(out["fused_weighted"])
    return out


def add_stereo_holes_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--stereo-holes", choices=STEREO_HOLES, default="cnn",
                   help="where the stereo input had no value (filled for the CNN): let the filled value compete on "
                        "confidence (cnn, the thesis, default) or take the ToF/LiDAR value (other: real scenes "
                        "with occlusions)")


# ------------------------------------------------------------------ cracktrain fuse

def add_post_args(p: argparse.ArgumentParser, default: str) -> None:
    p.add_argument("--post", choices=FILTERS, default=default, help="post-filter (thesis: BM3D after fusion is best)")
    p.add_argument("--post-stage", choices=STAGES, default="after", help="filter the inputs (before) or the fused map")
    p.add_argument("--bm3d-sigma", type=float, default=0.5, help="BM3D noise std (disparity px)")
    p.add_argument("--clahe-clip", type=float, default=2.0)


def add_fuse_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--checkpoint", "-c", dest="ckpt", default=None, help="checkpoint from cracktrain fusion")
    deprecated_alias(p, "--ckpt", "--checkpoint", "cracktrain")
    p.add_argument("--stereo", required=True, help="stereo disparity in the left view (px; any stereo method)")
    p.add_argument("--other", required=True, help="ToF or LiDAR disparity in the left view (px; sparse or completed)")
    p.add_argument("--left", required=True, help="left image")
    p.add_argument("--right", required=True, help="right image")
    p.add_argument("--amplitude", default=None, help="ToF amplitude in the left view (tof variant)")
    p.add_argument("--gt", default=None, help="GT disparity: also print the error table")
    p.add_argument("--out", required=True, help="folder for fused_max.exr, fused_weighted.exr, confidences")
    p.add_argument("--device", default=None)
    add_post_args(p, default="none")
    add_stereo_holes_arg(p)


def _read_map(path: str | None, flag: str) -> np.ndarray | None:
    if path is None:
        return None
    if not Path(path).is_file():
        raise TrainerInputError(f"{flag} {path} does not exist")
    return read_float_map(path)


def write_maps(out: Path, maps: dict[str, np.ndarray]) -> list[Path]:
    """Float maps as one-channel EXR (the project's float format)."""
    from crackgen.shards import encode_member

    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, m in maps.items():
        p = out / f"{name}.exr"
        p.write_bytes(encode_member("exr", np.ascontiguousarray(m, dtype=np.float32), name))
        paths.append(p)
    return paths


def run_fuse(args: FuseOptions) -> dict[str, Any]:
    device = pick_device(args.device)
    model, cfg, _ = load_fusion_model(args.ckpt, device)
    variant = cfg["variant"]
    if variant not in VARIANTS:
        raise TrainerInputError(f"checkpoint {args.ckpt} has unknown variant {variant!r}")
    for flag in ("left", "right"):
        if not Path(getattr(args, flag)).is_file():
            raise TrainerInputError(f"--{flag} {getattr(args, flag)} does not exist")
    stereo, other = _read_map(args.stereo, "--stereo"), _read_map(args.other, "--other")
    amp, gt = _read_map(args.amplitude, "--amplitude"), _read_map(args.gt, "--gt")
    if variant == "tof" and amp is None:
        raise TrainerInputError(f"checkpoint {args.ckpt} is a ToF model: give --amplitude")
    try:
        inp = build_inputs(variant, stereo, other, read_rgb(args.left), read_rgb(args.right), amp, cfg["densify"],
                           cfg.get("other_bm3d", 0.0))
    except FusionInputError as exc:
        raise TrainerInputError(str(exc)) from None
    maps = fuse_scene(model, cfg, inp.x, device, post_filter_from_args(args), inp.stereo_valid, args.stereo_holes)
    written = write_maps(Path(args.out), {k: maps[k] for k in ("fused_max", "fused_weighted", "conf_stereo", "conf_other")})
    res: dict[str, Any] = {"out": str(args.out), "written": [p.name for p in written], "stereo_holes": args.stereo_holes}
    if gt is not None:
        if gt.shape != stereo.shape:
            raise TrainerInputError(f"--gt is {gt.shape}, --stereo is {stereo.shape}")
        res["metrics"] = {k: disparity_metrics(maps[k], gt) for k in ("stereo", "other", "fused_max", "fused_weighted")}
        (Path(args.out) / "metrics.json").write_text(json.dumps(res["metrics"], indent=2))
    return res
