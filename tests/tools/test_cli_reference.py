"""docs/cli.md's argument reference is the parsers' own: a flag added, renamed or removed shows here."""
import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _generator():
    spec = importlib.util.spec_from_file_location("cli_reference", ROOT / "scripts" / "cli_reference.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_cli_reference_matches_the_parsers():
    gen = _generator()
    assert gen.reference_markdown() in (ROOT / "docs" / "cli.md").read_text(), \
        "run: python scripts/cli_reference.py"


def test_reference_lists_every_command_and_flag():
    from trainer.cli import build_parser

    text = _generator().reference_markdown()
    assert "### `cracktrain benchmark`" in text and "### `crackgen generate`" in text
    seg = next(a for a in build_parser()._actions if a.dest == "command").choices["seg"]
    for action in seg._actions:
        for flag in action.option_strings:
            if action.help != "==SUPPRESS==" and flag not in ("-h", "--help"):
                assert f"`{flag}`" in text, flag
