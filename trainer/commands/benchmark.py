"""``cracktrain benchmark``: the cross-domain scoreboard."""
from __future__ import annotations

import argparse
from pathlib import Path

NAME = "benchmark"
HELP = "score models on DeepCrack's test split and the cross-domain sets at their validation thresholds"


def add_args(p: argparse.ArgumentParser) -> None:
    from trainer.experiments.benchmark import add_benchmark_args

    add_benchmark_args(p)


def run(args: argparse.Namespace) -> int:
    from trainer.core.options import options_from
    from trainer.experiments.benchmark import run_benchmark
    from trainer.experiments.config import BenchmarkOptions

    r = run_benchmark(options_from(BenchmarkOptions, args))
    print(Path(r["out"], "benchmark.md").read_text())
    plots = "".join(f", {name}" for name, on in (("cost.png", r["core_seconds_per_sample"]),
                                                 ("volume.png", r["renders"])) if on)
    print(f"scored {r['models']} models ({r['labels']} rows) on {len(r['sets'])} sets in {r['seconds']} s; "
          f"wrote {r['out']}/benchmark.csv, .md, .png, .json{plots}")
    return 0
