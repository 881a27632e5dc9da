"""Scenes for the confidence CNN: from shards or from files, plus the random-patch sampler.

A ``FusionScene`` holds the raw (unnormalised) input stack of one scene (see
``fusion.depth.inputs``) and, when known, its GT disparity. Scenes come from

* shards written by ``crackgen generate`` with stereo + ToF (+ LiDAR) on:
  members ``rgb``, ``right``, ``disp_sgm``, ``disp_tof``/``tofamp`` or
  ``disp_lidar``, ``disp_gt``;
* plain files (``cracktrain fuse``): the plug-in point for stronger inputs, e.g.
  a LEAStereo disparity or a PENet-completed LiDAR map, used as they are.

``--stereo-dir`` / ``--other-dir`` swap a shard's stereo or ToF/LiDAR
disparity for ``DIR/KEY.{exr,pfm,npy,tif,png}`` so an external network's output
can be fused and evaluated against the same GT.

Training patches (thesis: 128 px, flips, +-5 deg rotation) are cut by
``random_patch`` with an explicit numpy Generator: inputs are resampled
bilinearly with replicated borders, the GT with nearest neighbour and -1
outside, so no GT value is invented.
"""
from __future__ import annotations

import logging
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import cv2
import numpy as np

from fusion.depth.inputs import LIDAR_VARIANTS, VARIANTS, FusionInputError, FusionInputs, build_inputs, replace_lidar
from fusion.depth.layered_stereo import StereoView
from fusion.depth.scanline_lidar import random_scanline_lidar
from fusion.geometry.stereo import to_grey
from trainer.core.errors import TrainerInputError
from trainer.core.imageio import DEPTH_EXTS, read_float_map
from trainer.depthfusion.occluders import occluder_scenes

log = logging.getLogger(__name__)

OTHER_MEMBERS = {"tof": ("disp_tof", "tofamp"), "lidar": ("disp_lidar",), "lidar4": ("disp_lidar",)}


@dataclass
class FusionScene:
    key: str
    x: np.ndarray  # (H,W,C) float32 raw input channels, VARIANTS order
    gt: np.ndarray | None  # (H,W) float32 GT disparity, -1 none
    stereo_valid: np.ndarray | None = None  # (H,W) bool: measured stereo (not a filled hole); None = all
    grey: tuple[np.ndarray, np.ndarray] | None = None  # (left, right) uint8 grey, kept for lidar4 training:
    # its stereo grey difference is recomputed after a stereo failure is pasted (trainer.depthfusion.augment)


def _external(folder: str | Path | None, key: str) -> np.ndarray | None:
    if folder is None:
        return None
    for ext in DEPTH_EXTS:
        p = Path(folder) / f"{key}{ext}"
        if p.is_file():
            return read_float_map(p)
    raise TrainerInputError(f"{folder}: no disparity file for sample {key} ({'/'.join(DEPTH_EXTS)})")


def scene_from_sample(sample: dict, variant: str, densify: str = "normconv", stereo_dir: str | Path | None = None,
                      other_dir: str | Path | None = None, other_bm3d: float = 0.0) -> FusionScene:
    """One shard sample -> FusionScene; a missing member is a one-line error naming it."""
    key = sample["__key__"]
    need = ("rgb", "right", "disp_sgm", "disp_gt") + OTHER_MEMBERS[variant]
    missing = [m for m in need if m not in sample]
    if missing:
        raise TrainerInputError(f"sample {key} has no {', '.join(missing)} member(s): the {variant} variant needs a "
                                f"recipe with stereo and {'ToF' if variant == 'tof' else 'LiDAR'} on (recipes/stereo_tof.toml)")
    ext_stereo, ext_other = _external(stereo_dir, key), _external(other_dir, key)
    stereo = sample["disp_sgm"] if ext_stereo is None else ext_stereo
    other = sample[OTHER_MEMBERS[variant][0]] if ext_other is None else ext_other
    try:
        inp = build_inputs(variant, stereo, other, sample["rgb"], sample["right"],
                           sample.get("tofamp"), densify, other_bm3d)
    except FusionInputError as exc:
        raise TrainerInputError(f"sample {key}: {exc}") from None
    grey = (to_grey(sample["rgb"]), to_grey(sample["right"])) if variant == "lidar4" else None
    return FusionScene(key, inp.x, np.asarray(sample["disp_gt"], np.float32), inp.stereo_valid, grey)


def resampled_lidar_scenes(scene: FusionScene, sample: dict, copies: int, seed: int,
                           densify: str = "normconv", variant: str = "lidar", other_bm3d: float = 0.0
                           ) -> list[FusionScene]:
    """``copies`` more scenes of one LiDAR-variant sample, each with a scan-line LiDAR
    re-drawn from its GT at a random density and noise (``random_scanline_lidar``); the
    stereo channel is the sample's own. Keys ``KEY~lidarJ``; draws seeded by (seed, key, J)."""
    out = []
    for j in range(copies):
        rng = np.random.default_rng(np.random.SeedSequence([seed, zlib.crc32(scene.key.encode()), j]))
        lidar, _ = random_scanline_lidar(scene.gt, rng)
        if not (lidar > 0).any():
            continue
        inp = replace_lidar(FusionInputs(variant, scene.x, scene.stereo_valid), lidar, sample["rgb"], sample["right"],
                            densify, other_bm3d)
        out.append(FusionScene(f"{scene.key}~lidar{j}", inp.x, scene.gt, inp.stereo_valid, scene.grey))
    return out


def load_shard_scenes(path: str | Path, variant: str, keys: Sequence[str] | None = None, densify: str = "normconv",
                      stereo_dir: str | Path | None = None, other_dir: str | Path | None = None,
                      progress: bool = True, lidar_resample: int = 0, seed: int = 0,
                      other_bm3d: float = 0.0, occluders: int = 0) -> list[FusionScene]:
    """All (or ``keys``) samples of a dataset as scenes, in key order; with ``lidar_resample`` K
    (LiDAR variant) each sample also gives K scenes with a re-drawn LiDAR (``resampled_lidar_scenes``);
    with ``occluders`` K, K scenes with another sample pasted in front (``trainer.depthfusion.occluders``)."""
    from tqdm import tqdm

    from crackgen.shards import iter_samples, list_shards

    if variant not in VARIANTS:
        raise TrainerInputError(f"unknown --variant {variant!r}; choose from {', '.join(VARIANTS)}")
    if lidar_resample and variant not in LIDAR_VARIANTS:
        raise TrainerInputError(f"--lidar-resample needs a LiDAR variant ({', '.join(LIDAR_VARIANTS)}), got {variant}")
    if occluders and variant not in LIDAR_VARIANTS:
        raise TrainerInputError(f"--occluders needs a LiDAR variant ({', '.join(LIDAR_VARIANTS)}), got {variant}")
    if not Path(path).exists():
        raise TrainerInputError(f"--data {path} does not exist")
    members = {"rgb", "right", "disp_sgm", "disp_gt", *OTHER_MEMBERS[variant]}
    try:
        if not list_shards(path):
            raise TrainerInputError(f"--data {path} holds no shards")
        scenes, views = [], []
        for s in tqdm(iter_samples(path, keys=keys, members=members), desc="fusion inputs",
                      unit="scene", disable=not progress, total=len(keys) if keys is not None else None):
            scenes.append(scene_from_sample(s, variant, densify, stereo_dir, other_dir, other_bm3d))
            if lidar_resample > 0:
                scenes += resampled_lidar_scenes(scenes[-1], s, lidar_resample, seed, densify, variant, other_bm3d)
            if occluders > 0:
                views.append((s["__key__"], StereoView(s["rgb"], s["right"], np.asarray(s["disp_gt"], np.float32))))
        if occluders > 0:
            scenes += [FusionScene(key, inp.x, gt, inp.stereo_valid, grey) for key, inp, gt, grey in
                       occluder_scenes(views, occluders, seed, variant, densify, other_bm3d, progress)]
    except TrainerInputError:
        raise
    except Exception as exc:  # ShardError, CodecError, ManifestError: name the dataset
        raise TrainerInputError(f"--data {path}: {type(exc).__name__}: {exc}") from None
    if not scenes:
        raise TrainerInputError(f"--data {path}: no samples{' with the requested keys' if keys else ''}")
    return sorted(scenes, key=lambda s: s.key)


def shard_keys(path: str | Path) -> list[str]:
    """Sample keys of a dataset, read from the tar headers only."""
    from crackgen.shards import iter_samples

    try:
        return sorted(s["__key__"] for s in iter_samples(path, members=set()))
    except Exception as exc:
        raise TrainerInputError(f"--data {path}: {type(exc).__name__}: {exc}") from None


# ------------------------------------------------------------------ normalisation and patches

DISP_REFS = ("none", "median")


def disparity_reference(x: np.ndarray, mode: str) -> float:
    """The per-scene offset taken off both disparity channels before standardising.

    ``median``: the median of the ToF/LiDAR candidate over its valid pixels, so the
    network sees disparities relative to the scene's own level (in px) instead of
    the training renders' absolute range, which real scenes leave (2-55 px against
    the renders' 20-35 px). ``none``: the thesis's absolute disparities.
    """
    if mode == "none":
        return 0.0
    if mode != "median":
        raise TrainerInputError(f"unknown disparity reference {mode!r}; choose from {', '.join(DISP_REFS)}")
    other = x[..., 1]
    ok = np.isfinite(other) & (other > 0)
    return float(np.median(other[ok])) if ok.any() else 0.0


def relative_input(x: np.ndarray, ref: float) -> np.ndarray:
    """(…,C) raw channels with ``ref`` taken off the two disparity channels (0 and 1)."""
    if ref == 0.0:
        return x
    x = x.astype(np.float32, copy=True)
    x[..., :2] -= np.float32(ref)
    return x


def channel_stats(scenes: Sequence[FusionScene], disp_ref: str = "none") -> tuple[list[float], list[float]]:
    """Per-channel mean and std over all pixels of ``scenes`` (after the disparity reference),
    stored in the checkpoint so that training, evaluation and ``fuse`` normalise identically."""
    x = np.concatenate([relative_input(s.x, disparity_reference(s.x, disp_ref)).reshape(-1, s.x.shape[-1])
                        for s in scenes]).astype(np.float64)
    std = x.std(0)
    return x.mean(0).tolist(), np.where(std > 1e-6, std, 1.0).tolist()


def normalise(x: np.ndarray, mean: Sequence[float], std: Sequence[float]) -> np.ndarray:
    """(…,C) raw channels -> (x - mean) / std, float32."""
    return ((x - np.asarray(mean, np.float32)) / np.asarray(std, np.float32)).astype(np.float32)


@dataclass(frozen=True)
class PatchGeometry:
    """Where a training patch is cut: integer corner, rotation about its centre, flips."""

    x0: int
    y0: int
    size: int
    angle_deg: float
    flip_lr: bool
    flip_ud: bool


def patch_geometry(shape: tuple[int, int], size: int, rng: np.random.Generator, rotate_deg: float = 5.0,
                   flips: bool = True) -> PatchGeometry:
    """A random patch of a (H, W) scene; the draws (x0, y0, angle, two flips) in that order."""
    h, w = shape[:2]
    x0 = int(rng.integers(0, max(w - size, 0) + 1))  # integer corner: without rotation the patch is an exact crop
    y0 = int(rng.integers(0, max(h - size, 0) + 1))
    angle = float(rng.uniform(-rotate_deg, rotate_deg)) if rotate_deg > 0 else 0.0
    flip_lr = bool(flips and rng.random() < 0.5)
    flip_ud = bool(flips and rng.random() < 0.5)
    return PatchGeometry(x0, y0, size, angle, flip_lr, flip_ud)


def cut_patch(x: np.ndarray, gt: np.ndarray, g: PatchGeometry) -> tuple[np.ndarray, np.ndarray]:
    """(x (s,s,C), gt (s,s)) of ``g``: inputs bilinear with replicated borders, GT nearest with -1 outside."""
    half = (g.size - 1) / 2
    m = cv2.getRotationMatrix2D((g.x0 + half, g.y0 + half), g.angle_deg, 1.0)
    m[:, 2] -= (g.x0, g.y0)  # the patch centre lands on the output centre
    xp = cv2.warpAffine(x, m, (g.size, g.size), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    if xp.ndim == 2:
        xp = xp[..., None]
    gp = cv2.warpAffine(gt, m, (g.size, g.size), flags=cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT,
                        borderValue=-1.0)
    if g.flip_lr:
        xp, gp = xp[:, ::-1], gp[:, ::-1]
    if g.flip_ud:
        xp, gp = xp[::-1], gp[::-1]
    return np.ascontiguousarray(xp), np.ascontiguousarray(gp)


def random_patch(scene: FusionScene, size: int, rng: np.random.Generator, rotate_deg: float = 5.0,
                 flips: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """A ``size`` x ``size`` patch (x (s,s,C), gt (s,s)) at a random place, rotated by U(-r, r)
    degrees about its centre and flipped left-right / up-down with probability 1/2 each."""
    return cut_patch(scene.x, scene.gt, patch_geometry(scene.x.shape, size, rng, rotate_deg, flips))
