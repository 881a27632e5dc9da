"""The checkout carries no link to one machine's disk and none of the README's output folders.

A tracked `data -> /work/data` link once made `crackgen generate --out data/closeup` (the README's first
command) fail on every fresh clone; outputs (data/, runs/, out/) belong to the user, not to the repo.
"""
import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
OUTPUTS = ("data", "runs", "out")


def _tracked() -> list[tuple[str, str]]:
    """(mode, path) of every tracked file; skips outside a git checkout."""
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    res = subprocess.run(["git", "ls-files", "-s", "-z"], cwd=ROOT, capture_output=True, text=True, check=True)
    rows = []
    for entry in filter(None, res.stdout.split("\0")):
        meta, path = entry.split("\t", 1)
        rows.append((meta.split()[0], path))
    return rows


def test_tracked_links_stay_inside_the_repo():
    bad = []
    for mode, path in _tracked():
        if mode == "120000":
            target = os.readlink(ROOT / path) if (ROOT / path).is_symlink() else "?"
            inside = not os.path.isabs(target) and (ROOT / path).parent.joinpath(target).resolve().is_relative_to(ROOT)
            if not inside:
                bad.append(f"{path} -> {target}")
    assert not bad, f"tracked links leave the repo: {bad}"


def test_output_folders_are_not_tracked():
    bad = [p for _, p in _tracked() if p.split("/", 1)[0] in OUTPUTS]
    assert not bad, f"outputs tracked: {bad[:5]}"
