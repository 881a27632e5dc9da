"""``cracktrain``: train, evaluate, predict, compare sim-to-real, adapt BN to a site, fuse depth, fuse images, split, benchmark.

Every subcommand exits non-zero with a one-line reason on bad input
(missing folder, no images, unreadable file, bad checkpoint).
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path
from typing import Sequence

from trainer.errors import TrainerInputError


def build_parser() -> argparse.ArgumentParser:
    from trainer.adapt_bn import add_adapt_bn_args
    from trainer.bench import add_bench_args
    from trainer.benchmark import add_benchmark_args
    from trainer.evaluate import add_eval_args
    from trainer.fuse_images import add_fuse_args as add_fuse_images_args
    from trainer.fusion_apply import add_fuse_args
    from trainer.fusion_eval import add_fusion_eval_args
    from trainer.fusion_train import add_fusion_args
    from trainer.predict import add_predict_args
    from trainer.pseudo_label import add_pseudo_label_args
    from trainer.sim2real import add_sim2real_args
    from trainer.split import add_split_command_args
    from trainer.train import add_seg_args

    p = argparse.ArgumentParser(prog="cracktrain", description="Crack segmentation on synthetic shards and real photos.")
    p.add_argument("-v", "--verbose", action="store_true")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, adder, help_ in (
        ("seg", add_seg_args, "train a segmentation model (thesis defaults: DeepLabV3-R50, Adam 1e-4, batch 16, 30 epochs)"),
        ("evaluate", add_eval_args, "dataset-level metrics + PR curve of a checkpoint"),
        ("predict", add_predict_args, "masks, overlays and crack length/width (px or metres) for real photos"),
        ("sim2real", add_sim2real_args,
         "synthetic (+ adaptation) vs real vs mixed vs fine-tune, or the label-efficiency curve, on real test data"),
        ("adapt-bn", add_adapt_bn_args,
         "move a trained model's BatchNorm statistics to a folder of unlabeled site photos (AdaBN)"),
        ("pseudo-label", add_pseudo_label_args,
         "label a folder of unlabeled site photos with a model's confident predictions (self-training data)"),
        ("fusion", add_fusion_args, "train the ToF/LiDAR-stereo confidence CNN (thesis: Adadelta 0.01, batch 32, 128 px)"),
        ("fuse", add_fuse_args, "fuse a stereo and a ToF/LiDAR disparity file with a trained confidence CNN"),
        ("fusion-eval", add_fusion_eval_args, "thesis-style table: stereo, ToF/LiDAR, fused max/weighted, + BM3D"),
        ("split", add_split_command_args, "grouped, seeded train / validation / test split of a real folder"),
        ("benchmark", add_benchmark_args,
         "score models on DeepCrack's test split and the cross-domain sets at their validation thresholds"),
        ("bench", add_bench_args, "loader samples/s and model step time"),
        ("fuse-images", add_fuse_images_args, "guided-filter fusion of an exposure or focus stack; prints Q_Y, Q_C, Q_G, Q_MI"),
    ):
        adder(sub.add_parser(name, help=help_, description=help_))
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    try:
        if args.command == "seg":
            import torch.distributed as dist

            from trainer.train import main as train_main

            res = train_main(args)
            if not (dist.is_available() and dist.is_initialized()) or dist.get_rank() == 0:
                print(json.dumps({k: res[k] for k in ("step", "epoch", "best", "out")}))
            if dist.is_available() and dist.is_initialized():
                dist.destroy_process_group()
        elif args.command == "evaluate":
            from trainer.evaluate import run_evaluate

            s = run_evaluate(args)
            a, b = s["at_threshold"], s["best"]
            print(f"@{a['threshold']:.2f} ({s['threshold_source']}): acc {a['accuracy']:.4f} P {a['precision']:.4f} "
                  f"R {a['recall']:.4f} F1 {a['f1']:.4f} IoU {a['iou']:.4f}")
            print(f"oracle, best on these labels @{b['threshold']:.2f}: acc {b['accuracy']:.4f} P {b['precision']:.4f} R {b['recall']:.4f} F1 {b['f1']:.4f} IoU {b['iou']:.4f}")
            print(f"wrote {s['out']}/metrics.json and pr_curve.png")
        elif args.command == "predict":
            from trainer.predict import run_predict

            print(run_predict(args).summary())
        elif args.command == "sim2real":
            from trainer.sim2real import run_sim2real

            res = run_sim2real(args)
            report = Path(res["out"]) / "curve.md" if args.curve else Path(args.out) / "sim2real.md"
            print(report.read_text())
            print(f"wrote {report.parent}")
        elif args.command == "adapt-bn":
            from trainer.adapt_bn import run_adapt_bn

            r = run_adapt_bn(args)
            print(f"BN statistics of {r['source']} re-estimated on {r['batches']} batches of {r['crop']}-px crops "
                  f"from {r['photos']} photos in {r['target']}; wrote {args.out}")
        elif args.command == "pseudo-label":
            from trainer.pseudo_label import run_pseudo_label

            r = run_pseudo_label(args)
            print(f"pseudo-labelled {r['photos']} photos with {r['settings']['teacher']} "
                  f"(target BN {'on' if r['settings']['target_bn'] else 'off'}, portion {r['settings']['portion']}): "
                  f"crack {100 * r['crack_fraction']:.2f}% of pixels (p >= {r['threshold_crack']:.3f}), background "
                  f"{100 * r['background_fraction']:.1f}%, ignored {100 * r['ignored_fraction']:.1f}%; wrote {args.out} "
                  "(images/, masks/, ignore/, pseudo_labels.json); train on it with seg --real")
        elif args.command == "fusion":
            from trainer.fusion_train import main as fusion_main

            res = fusion_main(args)
            b = res["best"]
            best = (f"; best held-out fused-max MAE {b['val_mae_fused_max']:.4f} px at step {b['step']} "
                    f"(stereo {b['val_mae_stereo']:.4f}, other {b['val_mae_other']:.4f})") if "step" in b else ""
            print(f"trained {res['step']} steps on {res['train']} scenes ({res['val']} held out) in {res['seconds']} s"
                  f"{best}; wrote {res['out']}/last.pt, best.pt, log.csv")
        elif args.command == "fuse":
            from fusion.depth_metrics import format_table
            from trainer.fusion_apply import run_fuse

            res = run_fuse(args)
            if "metrics" in res:
                print(format_table(res["metrics"]))
            print(f"wrote {', '.join(res['written'])} to {res['out']}")
        elif args.command == "fusion-eval":
            from trainer.fusion_eval import run_fusion_eval

            res = run_fusion_eval(args)
            print(f"{res['variant']} fusion, {res['scenes']} {'held-out ' if res['keys'] == 'val' else ''}scenes of "
                  f"{res['data']} (disparity px, mean over scenes)")
            print(res["table"])
            if args.out:
                print(f"wrote {args.out}/metrics.json and table.md")
        elif args.command == "split":
            from trainer.split import run_split

            s = run_split(args.source, args.out, val_fraction=args.val_fraction, test_fraction=args.test_fraction,
                          seed=args.split_seed, group_pattern=args.group_pattern, image_dir=args.image_dir,
                          mask_dir=args.mask_dir, mask_suffix=args.mask_suffix, extra_dirs=args.extra_dir)
            print(f"{s.counts()} -> {args.out}/train, val, test and split.json")
        elif args.command == "benchmark":
            from trainer.benchmark import run_benchmark

            r = run_benchmark(args)
            print(Path(r["out"], "benchmark.md").read_text())
            print(f"scored {r['models']} models ({r['labels']} rows) on {len(r['sets'])} sets in {r['seconds']} s; "
                  f"wrote {r['out']}/benchmark.csv, .md, .png, .json")
        elif args.command == "fuse-images":
            from trainer.fuse_images import run_fuse

            r = run_fuse(args)
            print(f"Q_Y {r['Q_Y']:.4f}  Q_C {r['Q_C']:.4f}  Q_G {r['Q_G']:.4f}  Q_MI {r['Q_MI']:.4f}")
            print(f"fused {r['inputs']} images ({r['levels']}-level) -> {r['out']}")
        elif args.command == "bench":
            from trainer.bench import format_bench, run_bench

            res = run_bench(args)
            print(json.dumps(res, indent=2) if args.json else format_bench(res))
    except TrainerInputError as exc:
        print(f"cracktrain {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"cracktrain {args.command}: interrupted", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
