"""Typed options from a parsed command line: commands build them, libraries take them.

A library function takes one of the option dataclasses (``SegTrainConfig``, ``EvaluateOptions``, ...),
never an ``argparse.Namespace``; ``options_from`` is the one bridge, used by the command modules and
by experiments that re-run a command's library with other settings.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any, TypeVar

T = TypeVar("T")


def options_from(cls: type[T], source: Any, **overrides: Any) -> T:
    """``cls`` filled from the attributes (or keys) of ``source`` that name its fields, then ``overrides``.

    Attributes of ``source`` that are not fields (``func``, deprecated aliases a command already resolved)
    are left out; a field ``source`` lacks keeps its default.
    """
    get = source.get if isinstance(source, Mapping) else (lambda k, d: getattr(source, k, d))
    missing = object()
    values = {}
    for f in dataclasses.fields(cls):  # type: ignore[arg-type]
        v = get(f.name, missing)
        if v is not missing:
            values[f.name] = v
    values.update(overrides)
    return cls(**values)


def options_dict(opts: Any) -> dict[str, Any]:
    """Plain dict of an options dataclass (stored in checkpoints as their ``args``)."""
    return {f.name: getattr(opts, f.name) for f in dataclasses.fields(opts)}
