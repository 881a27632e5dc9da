"""May a dataset begun from one recipe be resumed with another? Field by field, not hash against hash.

Why: the recipe hash covers the whole schema with its defaults filled in, so a crackgen that
adds a recipe field changes the hash of every recipe, and a hash check alone would refuse to
resume any dataset begun before the upgrade. New fields default to the behaviour from before
they existed, so a field that is new *and* at its default renders as before. Everything else
that differs (a value the user changed, a default that changed, a field that went away) would
mix two datasets in one directory and is refused, naming the fields.

Manifests keep the canonical recipe (every field, defaults filled) since this check existed.
For older manifests only the recipe text is stored; it is re-read with today's schema, which
cannot see a changed default, and the note says so.
"""
from __future__ import annotations

import re
from typing import Any, Mapping

from crackgen.config.recipe import Recipe, RecipeError, parse_recipe

_SAMPLES_NOTE = re.compile(r"^# crackgen generate --samples (\d+) ")  # written by generate.effective_recipe


def canonical(recipe: Recipe) -> dict[str, Any]:
    """Every field of the recipe, defaults filled, as JSON values (what the hash is taken over)."""
    return recipe.model_dump(mode="json")


def flatten(tree: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{"a": {"b": 1}}`` -> ``{"a.b": 1}``; lists and scalars are leaves."""
    out: dict[str, Any] = {}
    for key, value in tree.items():
        path = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out.update(flatten(value, path + "."))
        else:
            out[path] = value
    return out


def stored_canonical_from_text(text: str) -> dict[str, Any] | None:
    """The stored recipe text re-read with today's schema (``--samples`` note applied); None if it no longer reads."""
    try:
        recipe = parse_recipe(text, "stored recipe")
    except RecipeError:
        return None
    m = _SAMPLES_NOTE.match(text)
    if m:
        recipe = recipe.model_copy(update={"dataset": recipe.dataset.model_copy(update={"samples": int(m.group(1))})})
    return canonical(recipe)


def _show(v: Any) -> str:
    s = repr(v)
    return s if len(s) <= 40 else s[:37] + "..."


def resume_differences(stored: Mapping[str, Any], current: Mapping[str, Any],
                       defaults: Mapping[str, Any]) -> tuple[list[str], list[str]]:
    """(blocking differences, new fields at their defaults) between two canonical recipes."""
    old, new, dflt = flatten(stored), flatten(current), flatten(defaults)
    blocking, added = [], []
    for key in sorted(old.keys() | new.keys()):
        if key not in new:
            blocking.append(f"{key} is no longer a recipe field (was {_show(old[key])})")
        elif key not in old:
            if key in dflt and new[key] == dflt[key]:
                added.append(key)
            else:
                blocking.append(f"{key} = {_show(new[key])} is new and not its default {_show(dflt.get(key))}")
        elif old[key] != new[key]:
            blocking.append(f"{key}: {_show(old[key])} -> {_show(new[key])}")
    return blocking, added


def resume_check(stored_canonical: Mapping[str, Any] | None, stored_text: str, recipe: Recipe) -> str:
    """A one-line note when ``recipe`` may resume the dataset; raises RecipeError naming what differs."""
    current = canonical(recipe)
    exact = stored_canonical is not None
    stored = stored_canonical if exact else stored_canonical_from_text(stored_text)
    if stored is None:
        raise RecipeError(["the dataset's stored recipe no longer reads with this crackgen's schema"], "resume")
    defaults = canonical(Recipe())
    blocking, added = resume_differences(stored, current, defaults)
    if blocking:
        more = f" (and {len(blocking) - 3} more)" if len(blocking) > 3 else ""
        raise RecipeError([f"the recipe differs: {'; '.join(blocking[:3])}{more}"], "resume")
    fields = ", ".join(added) if added else "none"
    how = "" if exact else " (older manifest: a changed default would not show)"
    return f"resuming a dataset begun by another crackgen version: same recipe; new fields at their defaults: {fields}{how}"


__all__ = ["canonical", "flatten", "resume_check", "resume_differences", "stored_canonical_from_text"]
