"""``cracktrain predict``: real photos (optionally + depth) -> masks, overlays, crack size.

Per image it writes ``STEM_prob.png`` (probability x 255), ``STEM_mask.png``
(0/255), ``STEM_overlay.png`` (crack pixels tinted red) and ``STEM.json`` with
the crack pixel count and the crack measurement of ``fusion.measure.crack_measure``:
``crack_length`` is the thesis's length (the longest in-mask path, tip to tip), and
``measurement`` holds the sum of tip-to-tip lengths, the total length with branches,
mean and max width and the per-crack figures.  Units:

- metres in the camera view with ``--intrinsics K.json`` (fx, fy, cx, cy) and depth
  (``--real-depth-dir`` ..., dense or sparse: ``fusion.measure.metric_size`` fills the crack and
  the holes from the surrounding surface and lifts the path to 3-D);
- metres with ``--pixel-size-m`` (flat, fronto-parallel photos);
- otherwise pixels.

The input may also be a crackgen dataset (shards): each sample is measured with its own
ray-cast depth and K (``KEY.json`` cameras), in metres.

``OUT/report.json`` holds ``{"predicted": [per-image reports], "skipped":
[{"image": path, "reason": one line}]}``; inputs are skipped (instead of
stopping the run) only with ``--skip-bad``.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from tqdm import tqdm

from trainer.core.checkpoint import load_checkpoint
from trainer.core.device import pick_device
from trainer.core.errors import TrainerInputError
from trainer.seg.builders import DataOptions, add_data_args, real_folder
from trainer.seg.config import PredictOptions
from trainer.seg.scoring import inherit_depth, load_model, predict_probability
from trainer.seg.sources import _SHARD_MEMBER
from trainer.seg.threshold import operating_threshold

log = logging.getLogger(__name__)
REPORT_NAME = "report.json"


def add_predict_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", help="folder with images/ (+ depth subfolder) or a folder of images")
    p.add_argument("--checkpoint", "-c", required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--threshold", type=float, default=None,
                   help="crack where probability >= this (default: the threshold chosen on validation and stored in "
                        "the checkpoint, else 0.5)")
    p.add_argument("--pixel-size-m", type=float, default=None,
                   help="metres per pixel, for lengths in metres on a flat, fronto-parallel photo")
    p.add_argument("--intrinsics", default=None, metavar="K.json",
                   help="camera intrinsics (fx, fy, cx, cy in px): with depth (--real-depth-dir), sizes in metres "
                        "in the camera view")
    p.add_argument("--min-length", type=float, default=0.0, help="ignore cracks shorter than this (report units)")
    p.add_argument("--device", default=None)
    p.add_argument("--no-progress", action="store_true")
    add_data_args(p)


def overlay(rgb: np.ndarray, mask: np.ndarray, alpha: float = 0.6) -> np.ndarray:
    out = rgb.astype(np.float32).copy()
    red = np.array([255, 0, 0], np.float32)
    m = mask > 0
    out[m] = (1 - alpha) * out[m] + alpha * red
    return out.astype(np.uint8)


@dataclass
class PredictResult:
    """What ``run_predict`` did: per-image reports, skipped inputs with reasons, and the report file."""

    report: Path
    predicted: list[dict[str, Any]] = field(default_factory=list)
    skipped: list[dict[str, str]] = field(default_factory=list)

    def summary(self) -> str:
        """One line for the CLI, counting predicted and skipped inputs separately."""
        return f"{len(self.predicted)} predicted, {len(self.skipped)} skipped (see {self.report})"


def _is_dataset(root: Path) -> bool:
    return (root / "manifest.json").is_file() or any(root.glob("shard-*.tar"))


def _shard_samples(root: Path, model_depth: str) -> tuple[Any, int | None]:
    """(lazy iterator of samples, count or None) over a crackgen dataset: rgb, ray-cast depth and K,
    plus the depth member the model takes (``model_depth``: tof, lidar, gt or none)."""
    from crackgen.shards import ShardError, iter_samples, open_dataset

    try:
        total = open_dataset(str(root)).num_samples
    except ShardError as exc:
        raise TrainerInputError(f"{root}: cannot read the dataset: {exc}") from None

    def gen():
        try:
            members = ["rgb", "depth", "meta"] + ([_SHARD_MEMBER[model_depth]] if model_depth != "none" else [])
            for s in iter_samples(str(root), members=members):
                yield s
        except ShardError as exc:
            raise TrainerInputError(f"{root}: cannot read the dataset: {exc}") from None
    return gen(), total


def _shard_sample(root: Path, s: dict[str, Any], model_depth: str) -> dict[str, Any]:
    """Trainer sample dict: ``depth`` = the model's depth input, ``metric_depth`` = ray-cast depth for the measurement."""
    key = s["__key__"]
    try:
        K = np.asarray(s["meta"]["cameras"]["rgb"]["K"], dtype=np.float64)
    except (KeyError, TypeError):
        raise TrainerInputError(f"{root}: sample {key} has no cameras.rgb.K in its JSON") from None
    member = _SHARD_MEMBER.get(model_depth)
    if "rgb" not in s or "depth" not in s or (member and member not in s):
        raise TrainerInputError(f"{root}: sample {key} lacks rgb, depth or the model's depth member {member}")
    return {"key": key, "rgb": np.asarray(s["rgb"])[..., :3],
            "depth": np.asarray(s[member], np.float32) if member else None,
            "metric_depth": np.asarray(s["depth"], np.float32), "K": K, "path": f"{root}:{key}"}


def _measure(mask: np.ndarray, sample: dict[str, Any], K: np.ndarray | None, args: PredictOptions):
    """(measurement, unit): metres in the view (K + depth), metres per pixel, or pixels."""
    from fusion.measure.crack_measure import measure_cracks
    from fusion.measure.metric_size import MetricSizeError, measure_in_view

    K = sample.get("K", K)
    if K is not None:
        depth = sample.get("metric_depth", sample.get("depth"))
        if depth is None:
            raise TrainerInputError(f"{sample['path']}: --intrinsics needs depth (--real-depth-dir ...), none found")
        try:
            return measure_in_view(mask, depth, K, min_length=args.min_length), "m"
        except MetricSizeError as exc:
            raise TrainerInputError(f"{sample['path']}: {exc}") from None
    return measure_cracks(mask, args.pixel_size_m, min_length=args.min_length), ("m" if args.pixel_size_m else "px")


def run_predict(args: PredictOptions) -> PredictResult:
    from fusion.measure.metric_size import MetricSizeError, load_intrinsics  # pure numpy/scipy

    if args.intrinsics and args.pixel_size_m:
        raise TrainerInputError("give --intrinsics (with depth) or --pixel-size-m, not both")
    K = None
    if args.intrinsics:
        try:
            K = load_intrinsics(args.intrinsics)
        except MetricSizeError as exc:
            raise TrainerInputError(str(exc)) from None
    device = pick_device(args.device)
    model, cfg, train_args = load_model(args.checkpoint, device)
    args = inherit_depth(args, train_args, cfg)
    threshold, source = operating_threshold(load_checkpoint(args.checkpoint), args.threshold)
    log.info("threshold %.2f: %s", threshold, source)
    root = Path(args.input)
    if not root.is_dir():
        raise TrainerInputError(f"input folder {root} does not exist")
    if _is_dataset(root):
        items, total = _shard_samples(root, args.depth)

        def load(item):
            return _shard_sample(root, item, args.depth)

        def image_path(item):
            return f"{root}:{item['__key__']}"
    else:
        read = dataclasses.replace(
            args, image_dir=args.image_dir if (root / args.image_dir).is_dir() else ".",  # a flat folder of photos
            depth="gt" if K is not None and args.real_depth_dir else args.depth)  # depth for the measurement too
        folder = real_folder(DataOptions.from_args(read), root, require_masks=False)
        items, total, load, image_path = folder.keys, len(folder.keys), folder.load, folder.image_path
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    result = PredictResult(report=out / REPORT_NAME)
    for item in tqdm(items, total=total, desc="predict", disable=args.no_progress):
        try:
            sample = load(item)
            if cfg.channels == "rgb" and sample.get("depth") is not None:  # kept for the measurement only
                sample = {**sample, "metric_depth": sample["depth"], "depth": None}
        except TrainerInputError as exc:
            if not args.skip_bad:
                raise
            log.warning("skipped: %s", exc)
            result.skipped.append({"image": str(image_path(item)), "reason": str(exc)})
            continue
        key = sample["key"]
        prob = predict_probability(model, cfg, sample, device)
        mask = (prob >= threshold).astype(np.uint8) * 255
        cv2.imwrite(str(out / f"{key}_prob.png"), np.round(prob * 255).astype(np.uint8))
        cv2.imwrite(str(out / f"{key}_mask.png"), mask)
        cv2.imwrite(str(out / f"{key}_overlay.png"), cv2.cvtColor(overlay(sample["rgb"], mask), cv2.COLOR_RGB2BGR))
        meas, unit = _measure(mask > 0, sample, K, args)
        rep = {"image": sample["path"], "threshold": threshold, "threshold_source": source, "crack_pixels": int((mask > 0).sum()),
               "crack_fraction": float((mask > 0).mean()), "crack_length": float(meas.longest_path),
               "length_unit": unit, "length_definition": "longest in-mask path, tip to tip (thesis 5.1.4)",
               "measurement": {k: v for k, v in meas.to_dict().items() if k != "components"},
               "cracks": meas.to_dict()["components"], "max_probability": float(prob.max())}
        (out / f"{key}.json").write_text(json.dumps(rep, indent=2))
        result.predicted.append(rep)
    result.report.write_text(json.dumps({"predicted": result.predicted, "skipped": result.skipped}, indent=2))
    if not result.predicted:
        raise TrainerInputError(f"{root}: none of {len(result.skipped)} image(s) could be read (see {result.report})")
    return result
