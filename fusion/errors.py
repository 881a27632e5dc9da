"""One base for every error the fusion package raises on purpose, so a command catches them all by name.

It derives from ValueError, as each of them did before, so existing ``except ValueError`` callers keep working.
"""
from __future__ import annotations


class FusionError(ValueError):
    """Bad input to a fusion function; the message is one line naming what is wrong."""
