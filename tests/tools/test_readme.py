"""README stays true: set-up commands, generated recipe reference, CLI subcommands."""
from pathlib import Path

from crackgen.config.recipe_doc import reference_markdown
from crackgen.tools.cli import build_parser

README = (Path(__file__).resolve().parents[2] / "README.md").read_text()


def test_setup_commands():
    assert "make demo" in README and "make test" in README


def test_recipe_reference_matches_schema():
    assert reference_markdown() in README, "run: python -m crackgen.config.recipe_doc and paste into README.md"


def test_every_crackgen_subcommand_is_documented():
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    for name in sub.choices:
        assert f"`{name}" in README, name


def test_every_cracktrain_subcommand_is_documented():
    from trainer.cli import build_parser as train_parser

    sub = next(a for a in train_parser()._actions if a.dest == "command")
    for name in sub.choices:
        assert f"`{name}" in README, name
