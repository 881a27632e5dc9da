"""``cracktrain bench``: loader samples/s and model step time."""
from __future__ import annotations

import argparse
import json

NAME = "bench"
HELP = "loader samples/s and model step time"


def add_args(p: argparse.ArgumentParser) -> None:
    from trainer.experiments.bench import add_bench_args

    add_bench_args(p)


def run(args: argparse.Namespace) -> int:
    from trainer.core.options import options_from
    from trainer.experiments.bench import format_bench, run_bench
    from trainer.experiments.config import BenchOptions

    res = run_bench(options_from(BenchOptions, args))
    print(json.dumps(res, indent=2) if args.json else format_bench(res))
    return 0
