"""The checkpoint a command works on: ``--checkpoint/-c``, or the deprecated positional of older releases."""
from __future__ import annotations

import argparse

from crackgen.cli_aliases import deprecation_note
from trainer.core.errors import TrainerInputError


def resolve_checkpoint(args: argparse.Namespace, command: str, dest: str = "checkpoint") -> str:
    """Set and return ``args.<dest>`` (``--checkpoint``); one line when it is missing or given twice differently."""
    old = getattr(args, "model", None)
    if old is not None:
        if getattr(args, dest) is not None and getattr(args, dest) != old:
            raise TrainerInputError(f"two checkpoints given ({old} and --checkpoint {getattr(args, dest)}): give one")
        deprecation_note("cracktrain", f"{command} CHECKPOINT (positional)", f"{command} --checkpoint CHECKPOINT")
        setattr(args, dest, old)
    if getattr(args, dest) is None:
        raise TrainerInputError("--checkpoint is required")
    return getattr(args, dest)
