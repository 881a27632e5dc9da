"""Old flag spellings kept for one release: hidden from --help, they still work and print one deprecation line.

Shared by ``crackgen`` and ``cracktrain`` so that both tools retire names the same way.
"""
from __future__ import annotations

import argparse
import sys
from typing import Any


class _Deprecated(argparse.Action):
    """Stores like the new option (same dest, type, nargs) and says once, on stderr, what to write instead."""

    def __init__(self, *args: Any, new: str, prog: str, store_const: Any = None, **kwargs: Any) -> None:
        self.new, self.prog, self.store_const = new, prog, store_const
        super().__init__(*args, **kwargs)

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                 option_string: str | None = None) -> None:
        deprecation_note(self.prog, str(option_string), self.new)
        setattr(namespace, self.dest, self.store_const if self.nargs == 0 else values)


def deprecated_alias(parser: argparse.ArgumentParser, old: str, new: str, prog: str) -> None:
    """Add ``old`` as a hidden alias of the already added option ``new``."""
    action = parser._option_string_actions[new]
    kwargs: dict[str, Any] = {"dest": action.dest, "help": argparse.SUPPRESS, "new": new, "prog": prog,
                              "default": argparse.SUPPRESS}
    if action.nargs == 0:
        kwargs.update(nargs=0, store_const=action.const if action.const is not None else True)
    else:
        kwargs.update(nargs=action.nargs, type=action.type, choices=action.choices, metavar=action.metavar)
    parser.add_argument(old, action=_Deprecated, **kwargs)


def deprecation_note(prog: str, old: str, new: str) -> None:
    """The one line an old spelling prints (for aliases argparse cannot express, such as a positional)."""
    print(f"{prog}: {old} is deprecated and will be removed; use {new}", file=sys.stderr)
