"""``cracktrain``: train, evaluate, predict, compare sim-to-real, adapt to a site, fuse depth, merge image stacks.

One module per command in ``trainer.commands``. Bad input (missing folder, no images, unreadable file,
bad checkpoint) exits 1 with one line naming what is wrong, as in ``crackgen``; a malformed command
line exits 2 (argparse).
"""
from __future__ import annotations

import argparse
import functools
import logging
import sys
from typing import Sequence

from crackgen.cli_aliases import deprecation_note
from crackgen.errors import path_error_line
from fusion.errors import FusionError
from trainer.core.errors import TrainerInputError

EXIT_BAD_INPUT = 1


def _renamed(old: str, new: str, run):
    @functools.wraps(run)
    def wrapper(args: argparse.Namespace) -> int:
        deprecation_note("cracktrain", old, new)
        return run(args)
    return wrapper


def build_parser() -> argparse.ArgumentParser:
    from trainer.commands import COMMANDS

    p = argparse.ArgumentParser(prog="cracktrain", description="Crack segmentation on synthetic shards and real photos.")
    p.add_argument("-v", "--verbose", action="store_true")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for cmd in COMMANDS:
        sp = sub.add_parser(cmd.NAME, help=cmd.HELP, description=cmd.HELP)
        cmd.add_args(sp)
        sp.set_defaults(func=cmd.run)
        for old in getattr(cmd, "OLD_NAMES", ()):
            op = sub.add_parser(old, help=argparse.SUPPRESS, description=cmd.HELP)
            cmd.add_args(op)
            op.set_defaults(func=_renamed(old, cmd.NAME, cmd.run))
    sub._choices_actions = [a for a in sub._choices_actions if a.help != argparse.SUPPRESS]  # hide old names
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    try:
        return args.func(args)
    except (TrainerInputError, FusionError) as exc:
        print(f"cracktrain {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as exc:
        if not exc.filename:  # not about a path the user gave: a defect, keep its traceback
            raise
        # e.g. --out under a file or a dangling link, a full disk, no permission
        print(f"cracktrain {args.command}: error: {path_error_line(exc)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print(f"cracktrain {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
