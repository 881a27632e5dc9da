"""The one base of every error crackgen raises on purpose.

Each stage keeps its own error class (``RecipeError``, ``ShardError`` ...) with its
historical builtin base (``ValueError``/``RuntimeError``) for callers that catch those,
and also inherits ``CrackgenError`` so a CLI or a driver can tell a deliberate, one-line
refusal from a bug with a single ``except``. Pure Python: trainer may import it.
"""
from __future__ import annotations


class CrackgenError(Exception):
    """Catch this to catch everything crackgen raises deliberately."""
