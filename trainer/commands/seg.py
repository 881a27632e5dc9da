"""``cracktrain seg``: train a segmentation model."""
from __future__ import annotations

import argparse
import json

NAME = "seg"
HELP = "train a segmentation model (thesis defaults: DeepLabV3-R50, Adam 1e-4, batch 16, 30 epochs)"


def add_args(p: argparse.ArgumentParser) -> None:
    from trainer.seg.train import add_seg_args

    add_seg_args(p)


def run(args: argparse.Namespace) -> int:
    import torch.distributed as dist

    from trainer.core.options import options_from
    from trainer.seg.config import SegTrainConfig
    from trainer.seg.train import main as train_main

    res = train_main(options_from(SegTrainConfig, args))
    distributed = dist.is_available() and dist.is_initialized()
    if not distributed or dist.get_rank() == 0:
        print(json.dumps({k: res[k] for k in ("step", "epoch", "best", "out")}))
    if distributed:
        dist.destroy_process_group()
    return 0
