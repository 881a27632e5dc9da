"""`--set KEY=VALUE`: change recipe fields from the command line without copying the file.

Why: ablations and site variants differ from a shipped recipe in one or two fields, and a
copied file drifts. The override edits the recipe's TOML text in place (tomlkit keeps every
other line and comment), so the edited text is what the manifest stores and what the workers
parse: the dataset records exactly what it was made from, and its hash changes with it.
Values are TOML (``8``, ``0.5``, ``true``, ``"fbm"``, ``{ min = 0.6, max = 1.2 }``,
``["a", "b"]``); a bare word that is not TOML is a string (``crack.shape=fbm``).
"""
from __future__ import annotations

import tomllib
from typing import Any

import tomlkit
from tomlkit.items import Table

from crackgen.config.recipe import Recipe, RecipeError, parse_recipe


def parse_set(text: str) -> tuple[str, Any]:
    """``'crack.shape=fbm'`` -> ``('crack.shape', 'fbm')``; RecipeError (one line) if malformed."""
    key, sep, raw = text.partition("=")
    key, raw = key.strip(), raw.strip()
    parts = key.split(".")
    if not sep or not raw or not key or any(not p.strip() for p in parts):
        raise RecipeError([f"--set {text!r}: expected SECTION.KEY=VALUE, e.g. crack.shape=fbm"], "--set")
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        if any(c in raw for c in "{}[]\"'="):
            raise RecipeError([f"--set {key}: {raw!r} is not a TOML value"], "--set") from None
        value = raw  # a bare word: a string
    return key, value


def _toml_item(value: Any) -> Any:
    """Inline tables stay inline (``{ min = .., max = .. }``), as recipes write them."""
    if isinstance(value, dict):
        t = tomlkit.inline_table()
        t.update({k: _toml_item(v) for k, v in value.items()})
        return t
    return value


def override_text(text: str, overrides: list[tuple[str, Any]]) -> str:
    """The recipe TOML text with each dotted key set (missing tables and keys are added)."""
    doc = tomlkit.parse(text)
    for key, value in overrides:
        parts = key.split(".")
        node: Any = doc
        for i, part in enumerate(parts[:-1]):
            if part not in node:
                node[part] = tomlkit.table()
            node = node[part]
            if not isinstance(node, (Table, dict)):
                raise RecipeError([f"--set {key}: {'.'.join(parts[:i + 1])} is a value, not a table"], "--set")
        node[parts[-1]] = _toml_item(value)
    shown = " ".join(f"{k}={tomlkit.item(_toml_item(v)).as_string()}" for k, v in overrides)
    return f"# crackgen --set {shown}\n" + tomlkit.dumps(doc)


def apply_sets(recipe: Recipe, sets: list[str], source: str = "recipe") -> Recipe:
    """``recipe`` with the ``--set`` arguments applied and validated against the schema."""
    if not sets:
        return recipe
    text = override_text(recipe.text, [parse_set(s) for s in sets])
    return parse_recipe(text, f"{source} with --set")
