"""A tiny fusion sample with the members the generator writes with stereo + ToF + LiDAR on, made
without Blender: a slanted plane, stereo that is noisy where the image has no texture, ToF
that is noisy where its amplitude is low, so confidence is learnable."""
from __future__ import annotations

import numpy as np

from crackgen.shards import ShardWriter, sample_key

H, W = 40, 56


def fusion_sample(rng: np.random.Generator) -> dict:
    yy, xx = np.mgrid[:H, :W]
    gt = (8.0 + 0.02 * xx + 0.01 * yy).astype(np.float32)
    tex = rng.integers(0, 255, (H, W), dtype=np.uint8)
    tex[:, W // 2:] = 128  # no texture on the right half: stereo fails there
    left = np.repeat(tex[..., None], 3, axis=2)
    right = np.roll(left, -8, axis=1)
    stereo = gt + rng.normal(0, 0.05, gt.shape).astype(np.float32)
    stereo[:, W // 2:] += rng.normal(0, 2.0, (H, W - W // 2)).astype(np.float32)
    amp = np.where(yy < H // 2, 0.8, 0.05).astype(np.float32)  # dark lower half: noisy ToF
    tof = gt + rng.normal(0, 1, gt.shape).astype(np.float32) * np.where(yy < H // 2, 0.05, 2.0).astype(np.float32)
    sparse = np.zeros((H, W), bool)
    sparse[::2, ::2] = True
    lidar = np.where(yy % 8 == 0, gt, -1.0).astype(np.float32)
    return {"rgb.png": left, "right.png": right, "disp_gt.exr": gt, "disp_sgm.exr": np.maximum(stereo, 0.5),
            "disp_tof.exr": np.where(sparse, np.maximum(tof, 0.5), -1.0).astype(np.float32),
            "tofamp.exr": np.where(sparse, amp, -1.0).astype(np.float32), "disp_lidar.exr": lidar,
            "json": {"synthetic": True}}


def write_fusion_shards(root, seed: int, shards: int = 2, per_shard: int = 3):
    """``shards`` x ``per_shard`` samples of ``fusion_sample`` from one seeded Generator, in ``root``."""
    rng = np.random.default_rng(seed)
    for s in range(shards):
        with ShardWriter(root, s) as w:
            for i in range(per_shard):
                w.add(sample_key(s, i), fusion_sample(rng))
    return root
