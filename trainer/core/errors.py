"""One exception type for bad user input, so the CLI can print a one-line reason."""
from __future__ import annotations

from crackgen.errors import CrackgenError


class TrainerInputError(CrackgenError, ValueError):
    """Bad input (missing folder, unreadable file, size mismatch, bad checkpoint).

    The message always names the offending file, folder or flag, so the CLI can
    print it on one line and exit non-zero instead of showing a deep traceback.
    """
