"""Dataset shards: codecs, manifest, writer and reader (WebDataset convention).

``from crackgen.shards import iter_samples`` is the public reader contract.
"""
from crackgen.shards.tarshards import *  # noqa: F401,F403
from crackgen.shards.tarshards import __all__, synthetic_sample  # noqa: F401
