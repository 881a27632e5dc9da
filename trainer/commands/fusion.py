"""``cracktrain fusion``: train the stereo + ToF/LiDAR confidence CNN."""
from __future__ import annotations

import argparse

NAME = "fusion"
HELP = "train the ToF/LiDAR-stereo confidence CNN (thesis: Adadelta 0.01, batch 32, 128 px)"


def add_args(p: argparse.ArgumentParser) -> None:
    from trainer.depthfusion.train import add_fusion_args

    add_fusion_args(p)


def run(args: argparse.Namespace) -> int:
    from trainer.core.options import options_from
    from trainer.depthfusion.config import FusionTrainConfig
    from trainer.depthfusion.train import main as fusion_main

    res = fusion_main(options_from(FusionTrainConfig, args))
    b = res["best"]
    best = (f"; best held-out fused-max MAE {b['val_mae_fused_max']:.4f} px at step {b['step']} "
            f"(stereo {b['val_mae_stereo']:.4f}, other {b['val_mae_other']:.4f})") if "step" in b else ""
    print(f"trained {res['step']} steps on {res['train']} scenes ({res['val']} held out) in {res['seconds']} s"
          f"{best}; wrote {res['out']}/last.pt, best.pt, log.csv")
    return 0
