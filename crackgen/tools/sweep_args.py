"""Parse `crackgen bench --sweep KEY=V1,V2 --combo "K=V K=V"` into named recipe variants.

Why its own module: the settings are validated, all of them, before any render starts, so a
typo in the tenth value fails in a second with one line, not after an hour of renders.
Keys are dotted recipe keys (``render.samples``, ``material.texture_px``) or ``layout``
(``WxT``: W worker processes of T Cycles threads each). Values are typed: ``on/true`` and
``off/false`` are booleans, then integers, floats, else strings.
"""
from __future__ import annotations

import itertools
import re
from dataclasses import dataclass, field
from typing import Any

from pydantic import ValidationError

from crackgen.config.recipe import Recipe, _format_errors
from crackgen.errors import CrackgenError

LAYOUT_KEY = "layout"
_LAYOUT = re.compile(r"^(\d+)x(\d+)$")
_INT = re.compile(r"^[+-]?\d+$")


class SweepError(CrackgenError, ValueError):
    """A --sweep/--combo argument that cannot be used (one line, names the argument)."""


@dataclass(frozen=True)
class Layout:
    workers: int
    threads: int  # Cycles threads per worker; 0 = the cores split between the workers

    def label(self) -> str:
        return f"{self.workers}x{self.threads}"


@dataclass
class Setting:
    """One row of the sweep: a recipe variant and the worker layout it runs with."""

    label: str
    overrides: dict[str, Any] = field(default_factory=dict)  # dotted key -> typed value
    layout: Layout | None = None  # None = the command's --workers/--threads


def parse_value(text: str) -> Any:
    """'on'/'true' -> True, 'off'/'false' -> False, '8' -> 8, '0.5' -> 0.5, else the string."""
    low = text.strip().lower()
    if low in ("on", "true"):
        return True
    if low in ("off", "false"):
        return False
    if _INT.match(low):
        return int(low)
    try:
        return float(low)
    except ValueError:
        return text.strip()


def parse_layout(text: str, arg: str) -> Layout:
    m = _LAYOUT.match(text.strip().lower())
    if not m or int(m.group(1)) < 1:
        raise SweepError(f"{arg}: layout must be WORKERSxTHREADS like 2x1 (workers >= 1, threads >= 0), got {text!r}")
    return Layout(int(m.group(1)), int(m.group(2)))


def _split_pair(text: str, arg: str) -> tuple[str, str]:
    key, sep, values = text.partition("=")
    if not sep or not key.strip() or not values.strip():
        raise SweepError(f"{arg}: expected KEY=VALUE[,VALUE...], got {text!r}")
    return key.strip(), values.strip()


def parse_sweep(text: str) -> tuple[str, list[Any]]:
    """'render.samples=8,16' -> ('render.samples', [8, 16]); layouts stay as Layout objects."""
    arg = f"--sweep {text}"
    key, values = _split_pair(text, arg)
    parts = [v for v in values.split(",")]
    if any(not v.strip() for v in parts):
        raise SweepError(f"{arg}: empty value in {values!r}")
    if key == LAYOUT_KEY:
        return key, [parse_layout(v, arg) for v in parts]
    return key, [parse_value(v) for v in parts]


def parse_combo(text: str) -> dict[str, Any]:
    """'render.samples=16 render.denoise=off' -> {'render.samples': 16, 'render.denoise': False}."""
    arg = f"--combo {text!r}"
    out: dict[str, Any] = {}
    for pair in text.split():
        key, value = _split_pair(pair, arg)
        if "," in value:
            raise SweepError(f"{arg}: one value per key in a combo, got {pair!r}")
        out[key] = parse_layout(value, arg) if key == LAYOUT_KEY else parse_value(value)
    if not out:
        raise SweepError(f"{arg}: no KEY=VALUE pairs")
    return out


def _fmt(v: Any) -> str:
    if isinstance(v, Layout):
        return v.label()
    if isinstance(v, bool):
        return "on" if v else "off"
    return str(v)


def _make_setting(pairs: dict[str, Any]) -> Setting:
    label = " ".join(f"{k}={_fmt(v)}" for k, v in pairs.items())
    layout = pairs.get(LAYOUT_KEY)
    return Setting(label, {k: v for k, v in pairs.items() if k != LAYOUT_KEY}, layout)


def build_settings(sweeps: list[str], combos: list[str], grid: bool = False) -> list[Setting]:
    """Baseline first, then one-at-a-time variations (or their full grid) and the explicit combos."""
    axes = [parse_sweep(s) for s in sweeps]
    keys = [k for k, _ in axes]
    dup = {k for k in keys if keys.count(k) > 1}
    if dup:
        raise SweepError(f"--sweep: key {sorted(dup)[0]!r} given twice; list all its values in one --sweep")
    settings = [Setting("baseline")]
    if grid and axes:
        for values in itertools.product(*[v for _, v in axes]):
            settings.append(_make_setting(dict(zip(keys, values))))
    else:
        for key, values in axes:
            settings.extend(_make_setting({key: v}) for v in values)
    settings.extend(_make_setting(parse_combo(c)) for c in combos)
    seen: set[str] = set()
    unique = []
    for s in settings:
        if s.label not in seen:
            seen.add(s.label)
            unique.append(s)
    return unique


def apply_overrides(recipe: Recipe, overrides: dict[str, Any], arg: str = "override") -> Recipe:
    """A copy of ``recipe`` with dotted keys set; SweepError (one line) for unknown keys or bad values."""
    data = recipe.model_dump(mode="json", exclude_none=True)
    for key, value in overrides.items():
        node = data
        parts = key.split(".")
        for i, part in enumerate(parts):
            if not isinstance(node, dict) or part not in node:
                where = ".".join(parts[:i]) or "recipe"
                known = ", ".join(sorted(node)) if isinstance(node, dict) else ""
                raise SweepError(f"{arg}: unknown key {key!r} (no {part!r} in {where}; it has: {known})")
            if i < len(parts) - 1:
                node = node[part]
        old = node[parts[-1]]
        if isinstance(old, dict) and "value" not in old and not any(k in old for k in ("min", "choices")):
            raise SweepError(f"{arg}: {key!r} is a section, not a value")
        node[parts[-1]] = value
    try:
        return Recipe.model_validate(data)
    except ValidationError as exc:
        raise SweepError(f"{arg}: {_format_errors(exc)[0]}") from None


def resolve(recipe: Recipe, settings: list[Setting]) -> list[tuple[Setting, Recipe]]:
    """Every setting's recipe, validated up front."""
    out = []
    for s in settings:
        arg = f"setting {s.label!r}" if s.overrides else "baseline"
        out.append((s, apply_overrides(recipe, s.overrides, arg)))
    return out
