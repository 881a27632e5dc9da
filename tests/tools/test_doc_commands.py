"""Every ``crackgen …`` and ``cracktrain …`` command line in README.md and docs/ parses with today's parsers.

Only parsing: the flags must exist, required arguments be present and choices valid; nothing is run.
Command lines are the lines of fenced code blocks (backslash continuations joined, comments dropped,
``&&``/``;``/``|`` chains split); inline code spans are mentions (``crackgen stats``), not command lines.
"""
from __future__ import annotations

import contextlib
import io
import shlex
from pathlib import Path

import pytest

from crackgen.tools.cli import build_parser as crackgen_parser
from trainer.cli import build_parser as cracktrain_parser

ROOT = Path(__file__).resolve().parents[2]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
TOOLS = {"crackgen": crackgen_parser, "cracktrain": cracktrain_parser}
SEPARATORS = {"&&", "||", ";", "|"}


def fenced_lines(text: str) -> list[str]:
    lines, inside, buf = [], False, ""
    for raw in text.splitlines():
        if raw.lstrip().startswith("```"):
            inside, buf = not inside, ""
            continue
        if not inside:
            continue
        line = raw.strip()
        if line.endswith("\\"):
            buf += line[:-1] + " "
            continue
        lines.append(buf + line)
        buf = ""
    return lines


def commands(text: str) -> list[list[str]]:
    found = []
    for line in fenced_lines(text):
        try:
            tokens = shlex.split(line, comments=True)
        except ValueError:
            continue
        cmd: list[str] = []
        for tok in tokens + [";"]:
            if tok in SEPARATORS:
                while cmd and ("=" in cmd[0] and not cmd[0].startswith("-") or cmd[0] in ("$", "time", "nohup")):
                    cmd = cmd[1:]  # env assignments and prefixes before the tool
                if cmd and Path(cmd[0]).name in TOOLS:
                    found.append([Path(cmd[0]).name, *cmd[1:]])
                cmd = []
            else:
                cmd.append(tok)
    return found


def all_commands() -> list[tuple[str, list[str]]]:
    return [(f"{doc.relative_to(ROOT)}", cmd) for doc in DOCS if doc.is_file() for cmd in commands(doc.read_text())]


def test_the_docs_hold_commands_of_both_tools():
    tools = {cmd[0] for _, cmd in all_commands()}
    assert tools == {"crackgen", "cracktrain"}


@pytest.mark.parametrize("where,cmd", all_commands(), ids=lambda v: " ".join(v) if isinstance(v, list) else v)
def test_documented_command_parses(where, cmd):
    parser = TOOLS[cmd[0]]()
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        try:
            parser.parse_args(cmd[1:])
        except SystemExit as exc:
            if exc.code not in (0, None):  # --help exits 0
                pytest.fail(f"{where}: `{' '.join(cmd)}` does not parse: {err.getvalue().strip().splitlines()[-1]}")


def test_a_broken_command_is_caught():
    bad = commands("```bash\ncracktrain seg --no-such-flag 1\ncrackgen generate\n```")
    assert len(bad) == 2
    for cmd in bad:
        with contextlib.redirect_stderr(io.StringIO()), pytest.raises(SystemExit):
            TOOLS[cmd[0]]().parse_args(cmd[1:])
