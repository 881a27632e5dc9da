"""`crackgen` command line: generate, validate, inspect, bench, show.

Each subcommand imports its heavy modules lazily so `crackgen --help` and
`crackgen validate` stay fast. Bad input exits non-zero with one line per problem.
"""
from __future__ import annotations

import argparse
import sys

from crackgen import __version__


def _cmd_validate(args: argparse.Namespace) -> int:
    from crackgen.recipe import RecipeError, load_recipe, summary

    try:
        recipe = load_recipe(args.recipe)
    except RecipeError as exc:
        for line in exc.problems:
            print(line, file=sys.stderr)
        return 1
    print(f"{args.recipe}: OK")
    print(summary(recipe))
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="crackgen", description="Synthetic RGB-D crack datasets from headless Blender.")
    p.add_argument("--version", action="version", version=f"crackgen {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", required=True)

    v = sub.add_parser("validate", help="check a recipe and print its summary")
    v.add_argument("recipe")
    v.set_defaults(func=_cmd_validate)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
