"""The one base of every error crackgen raises on purpose.

Each stage keeps its own error class (``RecipeError``, ``ShardError`` ...) with its
historical builtin base (``ValueError``/``RuntimeError``) for callers that catch those,
and also inherits ``CrackgenError`` so a CLI or a driver can tell a deliberate, one-line
refusal from a bug with a single ``except``. Pure Python: trainer may import it.
"""
from __future__ import annotations

from pathlib import Path


class CrackgenError(Exception):
    """Catch this to catch everything crackgen raises deliberately."""


def path_error_line(exc: OSError) -> str:
    """One line for an OSError about a path the user gave (``exc.filename`` set), without the traceback.

    Why: makedirs under a dangling link says "File exists", which names nothing the user can fix.
    """
    name = str(exc.filename)
    for p in (Path(name), *Path(name).parents):  # the path itself or a folder above it
        if p.is_symlink() and not p.exists():
            return f"{p}: a link to a missing target ({p.readlink()}); cannot write under it"
    return f"{name}: {exc.strerror or exc}"
