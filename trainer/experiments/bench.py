"""``cracktrain bench``: loader throughput and model step time, for issue notes.

``--fusion tof|lidar`` times the depth-fusion confidence CNN instead.

Loader: samples/s through the same SegStream + DataLoader as training (with
augmentation), for each requested worker count. Model: mean time of one
forward+backward+Adam step at the given size and batch (after warm-up).
"""
from __future__ import annotations

import argparse
import time
from typing import Any

import torch
from torch.utils.data import DataLoader

from trainer.core.device import pick_device
from trainer.core.errors import TrainerInputError
from trainer.experiments.config import BenchOptions
from trainer.seg.builders import DataOptions, add_data_args, real_folder, sample_config, shard_source
from trainer.seg.losses import make_loss
from trainer.seg.models import ARCHS, build_model
from trainer.seg.stream import SegStream


def add_bench_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data", default=None, help="synthetic shards to read")
    p.add_argument("--real", default=None, help="real folder to read")
    p.add_argument("--workers", default="0,1,2", help="comma list of DataLoader worker counts")
    p.add_argument("--samples", type=int, default=64, help="samples to load per worker setting")
    p.add_argument("--crop", type=int, default=256)
    p.add_argument("--arch", choices=ARCHS, default="lraspp_mobilenet_v3_large")
    p.add_argument("--model-size", type=int, default=256)
    p.add_argument("--batch-size", "-b", type=int, default=4)
    p.add_argument("--steps", type=int, default=5)
    p.add_argument("--device", default=None)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", action="store_true")
    p.add_argument("--no-model", action="store_true")
    p.add_argument("--fusion", choices=("tof", "lidar", "lidar4"), default=None,
                   help="time the confidence CNN of the depth fusion (Adadelta, masked MSE) instead of --arch")
    add_data_args(p)


def bench_loader(ds: SegStream, workers: int, samples: int) -> dict[str, float]:
    loader = DataLoader(ds, batch_size=1, num_workers=workers)
    t0, n, first = time.perf_counter(), 0, None
    for _ in loader:
        n += 1
        if first is None:
            first = time.perf_counter() - t0
        if n >= samples:
            break
    dt = time.perf_counter() - t0
    return {"workers": workers, "samples": n, "seconds": round(dt, 3), "samples_per_s": round(n / dt, 2),
            "samples_per_s_per_worker": round(n / dt / max(1, workers), 2), "first_sample_s": round(first or 0.0, 3)}


def time_steps(model: torch.nn.Module, opt: torch.optim.Optimizer, loss_of, x: torch.Tensor, steps: int,
               device: torch.device) -> list[float]:
    """Seconds of each of ``steps`` training steps after one warm-up step (CUDA synchronised)."""
    times = []
    for i in range(steps + 1):
        if device.type == "cuda":
            torch.cuda.synchronize()
        t0 = time.perf_counter()
        loss = loss_of(model(x))
        opt.zero_grad()
        loss.backward()
        opt.step()
        if device.type == "cuda":
            torch.cuda.synchronize()
        if i > 0:
            times.append(time.perf_counter() - t0)
    return times


def bench_model(arch: str, in_channels: int, size: int, batch: int, steps: int, device: torch.device) -> dict[str, Any]:
    torch.manual_seed(0)
    model = build_model(arch, in_channels).to(device).train()
    opt = torch.optim.Adam(model.parameters(), 1e-4)
    loss_fn = make_loss("bce")
    x = torch.randn(batch, in_channels, size, size, device=device)
    y = (torch.rand(batch, 1, size, size, device=device) > 0.9).float()
    times = time_steps(model, opt, lambda out: loss_fn(out, y), x, steps, device)
    return {"arch": arch, "in_channels": in_channels, "size": size, "batch": batch, "device": str(device),
            "threads": torch.get_num_threads(), "step_s_mean": round(sum(times) / len(times), 4),
            "step_s_min": round(min(times), 4), "params_M": round(sum(p.numel() for p in model.parameters()) / 1e6, 2)}


def bench_fusion_model(variant: str, size: int, batch: int, steps: int, device: torch.device) -> dict[str, Any]:
    """One training step of the confidence CNN (thesis: batch 32, 128-px patches)."""
    from trainer.depthfusion.model import IN_CHANNELS, ConfidenceCNN
    from trainer.depthfusion.train import masked_mse

    torch.manual_seed(0)
    model = ConfidenceCNN(IN_CHANNELS[variant]).to(device).train()
    opt = torch.optim.Adadelta(model.parameters(), lr=0.01)
    x = torch.randn(batch, IN_CHANNELS[variant], size, size, device=device)
    y = torch.rand(batch, 2, size, size, device=device)
    times = time_steps(model, opt, lambda out: masked_mse(out, y), x, steps, device)
    return {"arch": f"confidence_cnn_{variant}", "in_channels": IN_CHANNELS[variant], "size": size, "batch": batch,
            "device": str(device), "threads": torch.get_num_threads(), "step_s_mean": round(sum(times) / len(times), 4),
            "step_s_min": round(min(times), 4), "params_M": round(sum(p.numel() for p in model.parameters()) / 1e6, 2)}


def run_bench(args: BenchOptions) -> dict[str, Any]:
    opts = DataOptions.from_args(args)
    cfg = sample_config(opts, crop=args.crop, rotate_deg=15.0, jitter=0.3)  # seg's training augmentation
    res: dict[str, Any] = {"loader": [], "model": None}
    if args.data or args.real:
        shards = shard_source(opts, args.data) if args.data else None
        real = real_folder(opts, args.real) if args.real else None
        for w in (int(x) for x in args.workers.split(",")):
            ds = SegStream(cfg, shards, real, batch_size=1, train=True, seed=args.seed, skip_bad=args.skip_bad)
            res["loader"].append(bench_loader(ds, w, args.samples))
    elif args.no_model:
        raise TrainerInputError("nothing to benchmark: give --data/--real or drop --no-model")
    if not args.no_model:
        device = pick_device(args.device)
        if args.fusion:
            res["model"] = bench_fusion_model(args.fusion, args.model_size, args.batch_size, args.steps, device)
            return res
        res["model"] = bench_model(args.arch, cfg.in_channels, args.model_size, args.batch_size, args.steps, device)
    return res


def format_bench(res: dict[str, Any]) -> str:
    lines = []
    if res["loader"]:
        lines.append("workers  samples/s  per worker  first sample (s)")
        for r in res["loader"]:
            lines.append(f"{r['workers']:>7}  {r['samples_per_s']:>9}  {r['samples_per_s_per_worker']:>10}  {r['first_sample_s']:>16}")
    m = res["model"]
    if m:
        lines.append(f"model {m['arch']} ({m['in_channels']} ch, {m['params_M']} M params) {m['batch']}x{m['size']}^2 on "
                     f"{m['device']} ({m['threads']} threads): step {m['step_s_mean']} s mean, {m['step_s_min']} s min")
    return "\n".join(lines)
