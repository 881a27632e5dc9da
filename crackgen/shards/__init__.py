"""Dataset shards: codecs, manifest, writer and reader (WebDataset convention).

``from crackgen.shards import iter_samples`` is the public reader contract.
"""
from crackgen.shards.members import (  # noqa: F401
    MEMBERS,
    RGB_MEMBERS,
    RGB_VIEW_MEMBERS,
    Codec,
    Member,
    member_for_file,
    member_for_name,
)
from crackgen.shards.tarshards import *  # noqa: F401,F403
from crackgen.shards.tarshards import __all__ as _tar_all
from crackgen.shards.tarshards import synthetic_sample  # noqa: F401

__all__ = [*_tar_all, "MEMBERS", "RGB_MEMBERS", "RGB_VIEW_MEMBERS", "Codec", "Member",
           "member_for_file", "member_for_name"]
