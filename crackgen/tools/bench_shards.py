"""Shard I/O benchmark: bytes per sample and write/read milliseconds per sample.

Why a tool and not library code: these figures go into issue notes and docs/results
tables (``crackgen bench --component shards --component-args='--size 512'``); nothing asserts them.
``synthetic_sample`` also serves tests that need a sample with every member
without rendering one.
"""
from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from typing import Any

import numpy as np

from crackgen.shards import ShardWriter, iter_samples, sample_key, shard_name


def synthetic_sample(rng: np.random.Generator, size_px: int = 512, tof_px: int = 160) -> dict[str, Any]:
    """A sample with every member and render-like statistics (smooth fields plus
    sensor noise, sparse maps mostly -1) so sizes/timings resemble real shards."""
    h = w = size_px
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32) / size_px
    shade = 0.5 + 0.25 * np.sin(6 * xx) * np.cos(4 * yy)
    rgb = np.clip((shade[..., None] + rng.normal(0, 0.04, (h, w, 3))) * 255, 0, 255).astype(np.uint8)
    mask = np.where(np.abs(yy - 0.5 - 0.1 * np.sin(9 * xx)) < 0.004, 255, 0).astype(np.uint8)
    depth = (0.5 + 0.05 * xx + 0.03 * yy - 0.002 * (mask > 0)).astype(np.float32)
    sparse = np.full((h, w), -1.0, np.float32)
    sel = rng.random((h, w)) < 0.05
    sparse[sel] = depth[sel] + rng.normal(0, 0.003, int(sel.sum())).astype(np.float32)
    lidar = np.full((h, w), -1.0, np.float32)
    lidar[:: max(1, h // 32), :] = depth[:: max(1, h // 32), :]
    disp = (0.06 * 500.0 / depth).astype(np.float32)
    disp_sgm = np.where(rng.random((h, w)) < 0.9, np.round(disp * 16) / 16, -1).astype(np.float32)
    tz = (0.5 + rng.normal(0, 0.002, (tof_px, tof_px))).astype(np.float32)
    ta = (100 + rng.normal(0, 3, (tof_px, tof_px))).astype(np.float32)
    crack = -np.where(mask > 0, 0.002, 0).astype(np.float32)
    return {
        "rgb.png": rgb, "mask.png": mask, "depth.exr": depth, "tof.exr": sparse,
        "tofraw.exr": {"Z": tz, "A": ta}, "lidar.exr": lidar, "right.png": rgb[:, ::-1].copy(),
        "disp_sgm.exr": disp_sgm, "disp_gt.exr": disp, "crackmap.exr": crack,
        "json": {"spec": {"seed": 1}, "K": np.eye(3), "timings": {"render_s": 1.0}},
    }


def benchmark_sample_io(size_px: int = 512, samples: int = 4, exr_compression: str = "zip",
                        out_dir: str | None = None, seed: int = 0) -> dict[str, float]:
    """Time writing and reading ``samples`` full samples; returns bytes/sample and ms/sample."""
    rng = np.random.default_rng(seed)
    data = [synthetic_sample(rng, size_px) for _ in range(samples)]
    with tempfile.TemporaryDirectory(dir=out_dir) as d:
        shard = os.path.join(d, shard_name(0))
        t0 = time.perf_counter()
        with ShardWriter(d, 0, exr_compression=exr_compression) as w:
            for i, s in enumerate(data):
                w.add(sample_key(0, i), s)
        t1 = time.perf_counter()
        n = sum(1 for _ in iter_samples(shard))
        t2 = time.perf_counter()
        m = sum(1 for _ in iter_samples(shard, members={"rgb", "mask", "depth"}))
        t3 = time.perf_counter()
    if not n == m == samples:
        raise RuntimeError(f"bench: read back {n} and {m} samples of {samples} written")
    return {
        "size_px": size_px, "exr_compression": exr_compression,
        "bytes_per_sample": w.info.bytes / samples,
        "write_ms_per_sample": 1e3 * (t1 - t0) / samples,
        "read_all_ms_per_sample": 1e3 * (t2 - t1) / samples,
        "read_rgb_mask_depth_ms_per_sample": 1e3 * (t3 - t2) / samples,
    }


def main(argv: list[str] | None = None) -> int:
    """Print ``benchmark_sample_io`` as JSON, one object per EXR compression asked for."""
    ap = argparse.ArgumentParser(prog="python -m crackgen.tools.bench_shards", description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=512, help="image side in pixels")
    ap.add_argument("--samples", type=int, default=4)
    ap.add_argument("--exr-compression", default="zip", help="comma-separated, e.g. zip,piz,none")
    args = ap.parse_args(argv)
    for comp in args.exr_compression.split(","):
        print(json.dumps(benchmark_sample_io(args.size, args.samples, comp.strip())))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
