"""The error a bad shard raises, shared by the writer, the reader and the verifier.

It lives apart from them so none has to import another just to raise or catch it.
"""
from __future__ import annotations

from crackgen.errors import CrackgenError


class ShardError(CrackgenError, ValueError):
    """A shard (or a sample going into one) that is bad; the message names the shard file."""
