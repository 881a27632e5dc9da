"""Dataset shards (WebDataset convention): one concern per module, re-exported here.

- ``members``: the registry of member names, codecs and pixel grids;
- ``codecs``: member value <-> bytes (PNG, OpenEXR, JSON);
- ``storage``: local paths and fsspec URLs (size, hash, read, atomic replace);
- ``manifest``: ``manifest.json``, shard names, recorded versions;
- ``writer``: ``ShardWriter``, all-or-nothing tars;
- ``reader``: ``iter_samples`` and friends (what the trainer imports);
- ``verify``: ``verify_dataset``, every problem of a dataset, one line each;
- ``scenes``: which samples are views of one scene (the unit of a hold-out split).

``from crackgen.shards import iter_samples`` is the public reader contract.
"""
from crackgen.shards.codecs import CodecError, decode_member, encode_member, wds_decoder
from crackgen.shards.errors import ShardError
from crackgen.shards.manifest import Manifest, ManifestError, ShardInfo, ShardRecord, shard_index, shard_name
from crackgen.shards.members import (
    MEMBERS,
    RGB_MEMBERS,
    RGB_VIEW_MEMBERS,
    Codec,
    Member,
    member_for_file,
    member_for_name,
)
from crackgen.shards.reader import (
    ShardDataset,
    ShardRef,
    iter_samples,
    list_shards,
    load_sample,
    open_dataset,
    split_shards,
)
from crackgen.shards.scenes import scene_group, views_per_scene
from crackgen.shards.storage import StorageError
from crackgen.shards.verify import verify_dataset
from crackgen.shards.writer import ShardWriter, clean_partials, sample_key

__all__ = [
    # reader (the trainer's contract)
    "iter_samples", "load_sample", "list_shards", "split_shards", "open_dataset", "ShardDataset", "ShardRef",
    # writer
    "ShardWriter", "sample_key", "clean_partials",
    # scenes (hold-out groups)
    "views_per_scene", "scene_group",
    # verify
    "verify_dataset",
    # manifest
    "Manifest", "ShardInfo", "ShardRecord", "shard_name", "shard_index",
    # members and codecs
    "MEMBERS", "RGB_MEMBERS", "RGB_VIEW_MEMBERS", "Codec", "Member", "member_for_file", "member_for_name",
    "encode_member", "decode_member", "wds_decoder",
    # errors
    "ShardError", "ManifestError", "CodecError", "StorageError",
]
