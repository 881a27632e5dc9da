"""Grouped train / validation / test splits of a real folder.

Why groups: crack datasets cut one photo into tiles (DeepCrack ``11116``,
``11116-1`` ... ``11116-4``). Tiles of one crack on both sides of a split score
a model partly on cracks it trained on, so every split here keeps a group
whole. A file's group is the first capture group of ``--group-pattern`` matched
against its stem (default: the stem up to the first ``-``); ``none`` makes every
file its own group.

The sides are filled group by group in one seeded order of the sorted group
names, each group going to the held-out side (validation, test) furthest below
its share of the *photos*, or to training once both are full. So the photo
counts come close to the fractions (a fraction of the groups alone could put
one 20-tile group in a 60-photo test set), and the result depends only on the
names, the fractions, the pattern and the seed.
"""
from __future__ import annotations

import json
import re
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from trainer.core.errors import TrainerInputError

DEFAULT_GROUP_PATTERN = r"^([^-]+)-"  # DeepCrack, ShadowCrack, AigleRN: tiles are NAME-k
NO_GROUPS = "none"
SIDES = ("train", "val", "test")
SPLIT_FILE = "split.json"


def compile_group_pattern(text: str | None) -> re.Pattern[str] | None:
    """``--group-pattern``: a regex with one capture group, or ``none`` (every file its own group)."""
    if text is None:
        text = DEFAULT_GROUP_PATTERN
    if text.strip().lower() == NO_GROUPS:
        return None
    try:
        pattern = re.compile(text)
    except re.error as exc:
        raise TrainerInputError(f"--group-pattern {text!r} is not a regular expression ({exc})") from None
    if pattern.groups < 1:
        raise TrainerInputError(f"--group-pattern {text!r} needs a capture group, e.g. '^([^-]+)-'")
    return pattern


def group_of(stem: str, pattern: re.Pattern[str] | None) -> str:
    """The group a file stem belongs to: the pattern's first capture group, else the stem itself."""
    if pattern is None:
        return stem
    m = pattern.search(stem)
    return m.group(1) if m and m.group(1) else stem


def groups_of(stems: Sequence[str], pattern: re.Pattern[str] | None) -> dict[str, list[str]]:
    """Group name -> its sorted stems."""
    out: dict[str, list[str]] = {}
    for s in sorted(stems):
        out.setdefault(group_of(s, pattern), []).append(s)
    return out


def check_fractions(val: float, test: float) -> None:
    for name, f in (("--val-fraction", val), ("--test-fraction", test)):
        if not 0.0 <= f < 1.0:
            raise TrainerInputError(f"{name} must be in [0, 1), got {f}")
    if val + test >= 1.0:
        raise TrainerInputError(f"--val-fraction {val} + --test-fraction {test} leave nothing to train on")


@dataclass
class RealSplit:
    """One grouped split of a real folder: the stems of each side and the groups they came from."""

    source: str
    seed: int
    val_fraction: float
    test_fraction: float
    group_pattern: str
    train: list[str] = field(default_factory=list)
    val: list[str] = field(default_factory=list)
    test: list[str] = field(default_factory=list)
    groups: dict[str, list[str]] = field(default_factory=dict)

    def side(self, name: str) -> list[str]:
        if name not in SIDES:
            raise TrainerInputError(f"split side must be one of {SIDES}, got {name!r}")
        return getattr(self, name)

    def group_sides(self) -> dict[str, set[str]]:
        """Group -> the sides its stems landed on (one side each, by construction)."""
        side_of = {s: name for name in SIDES for s in self.side(name)}
        return {g: {side_of[s] for s in stems if s in side_of} for g, stems in self.groups.items()}

    def counts(self) -> str:
        return " / ".join(f"{len(self.side(n))} {n}" for n in SIDES) + f" photos in {len(self.groups)} groups"

    def to_json(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> "RealSplit":
        return cls(**data)

    def write(self, folder: str | Path) -> Path:
        path = Path(folder) / SPLIT_FILE
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.to_json(), indent=1) + "\n")
        return path


def split_groups(stems: Sequence[str], *, val_fraction: float, test_fraction: float, seed: int,
                 group_pattern: str | None = None, source: str = "") -> RealSplit:
    """Train / validation / test stems with every group on one side (see the module docstring)."""
    check_fractions(val_fraction, test_fraction)
    pattern = compile_group_pattern(group_pattern)
    groups = groups_of(stems, pattern)
    names = sorted(groups)
    n = sum(len(v) for v in groups.values())
    want = {"val": val_fraction * n, "test": test_fraction * n}
    got = {"train": [], "val": [], "test": []}
    order = np.random.default_rng(np.random.SeedSequence([int(seed), 0x5EED, 3])).permutation(len(names))
    for i in order:
        g = names[i]
        size = len(groups[g])
        # the held-out side furthest below its target takes the group if that brings it closer to the target
        deficit = {side: want[side] - len(got[side]) for side in ("val", "test") if want[side] > 0}
        side = max(deficit, key=lambda s: (deficit[s] / want[s], s == "test"), default=None)
        if side is None or deficit[side] < size / 2:
            side = "train"
        got[side].extend(groups[g])
    for side, frac in (("val", val_fraction), ("test", test_fraction)):
        if frac > 0 and not got[side]:
            raise TrainerInputError(f"{source or 'real folder'}: {side} fraction {frac} of {n} photos in "
                                    f"{len(groups)} groups leaves the {side} split empty (groups too large?)")
    if not got["train"]:
        raise TrainerInputError(f"{source or 'real folder'}: the split leaves no training photos")
    return RealSplit(source=str(source), seed=int(seed), val_fraction=float(val_fraction),
                     test_fraction=float(test_fraction),
                     group_pattern=NO_GROUPS if pattern is None else pattern.pattern,
                     train=sorted(got["train"]), val=sorted(got["val"]), test=sorted(got["test"]),
                     groups=groups)


def read_split(path: str | Path) -> RealSplit:
    """A ``split.json`` written by ``RealSplit.write`` (a file or the folder holding it)."""
    p = Path(path)
    if p.is_dir():
        p = p / SPLIT_FILE
    try:
        return RealSplit.from_json(json.loads(p.read_text()))
    except FileNotFoundError:
        raise TrainerInputError(f"{p} does not exist") from None
    except (ValueError, TypeError) as exc:
        raise TrainerInputError(f"{p}: not a split written by cracktrain ({exc})") from None
