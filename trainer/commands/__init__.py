"""One module per ``cracktrain`` command: ``NAME``, ``HELP``, ``add_args(parser)`` and ``run(args) -> int``.

The commands parse, call library functions and print a short summary; the work lives in the libraries.
"""
from __future__ import annotations

from trainer.commands import (
                              adapt_bn,
                              bench,
                              benchmark,
                              curve,
                              evaluate,
                              fusion,
                              fusion_eval,
                              fusion_fuse,
                              merge_stack,
                              predict,
                              pseudo_label,
                              seg,
                              sim2real,
                              split,
)

COMMANDS = (seg, evaluate, predict, split, benchmark, sim2real, curve, adapt_bn, pseudo_label, fusion, fusion_fuse,
            fusion_eval, merge_stack, bench)
