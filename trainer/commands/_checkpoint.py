"""The checkpoint a command works on: ``--checkpoint/-c``, or the deprecated positional of older releases."""
from __future__ import annotations

import argparse

from crackgen.cli_aliases import deprecation_note
from trainer.core.errors import TrainerInputError


def resolve_checkpoint(args: argparse.Namespace, command: str) -> str:
    """Set and return ``args.checkpoint``; one line when it is missing or given twice differently."""
    old = getattr(args, "model", None)
    if old is not None:
        if args.checkpoint is not None and args.checkpoint != old:
            raise TrainerInputError(f"two checkpoints given ({old} and --checkpoint {args.checkpoint}): give one")
        deprecation_note("cracktrain", f"{command} CHECKPOINT (positional)", f"{command} --checkpoint CHECKPOINT")
        args.checkpoint = old
    if args.checkpoint is None:
        raise TrainerInputError("--checkpoint is required")
    return args.checkpoint
