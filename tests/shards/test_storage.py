"""Storage helpers treat local paths and fsspec URLs alike, and the shards package is layered."""
from __future__ import annotations

import os

import pytest

from crackgen.errors import CrackgenError
from crackgen.shards.storage import (
    StorageError,
    file_size,
    get_fs,
    is_url,
    join,
    local_path,
    parent,
    read_bytes,
    sha256_file,
    write_bytes_atomic,
)


def test_locations_local_file_url_and_remote():
    assert not is_url("data/roads") and not is_url("file:///tmp/x") and is_url("s3://b/p")
    assert local_path("file:///tmp/x") == "/tmp/x"
    assert join("s3://b/p/", "m.json") == "s3://b/p/m.json"
    assert join("file:///tmp/d", "m.json") == os.path.join("/tmp/d", "m.json")
    assert parent("s3://b/p/shard-000001.tar") == "s3://b/p"
    assert parent("shard-000001.tar") == "."


@pytest.mark.parametrize("root", ["local", "memory"])
def test_atomic_write_then_size_hash_and_read_agree(tmp_path, root):
    import hashlib
    import uuid

    base = str(tmp_path) if root == "local" else f"memory://storage-{uuid.uuid4().hex}"
    path = join(base, "a.bin")
    assert file_size(path) is None
    write_bytes_atomic(path, b"old")
    write_bytes_atomic(path, b"new bytes")
    assert read_bytes(path) == b"new bytes"
    assert file_size(path) == 9
    assert sha256_file(path) == hashlib.sha256(b"new bytes").hexdigest()
    if root == "local":
        assert os.listdir(tmp_path) == ["a.bin"]  # no temp file left beside it


def test_unknown_protocol_is_a_one_line_storage_error():
    with pytest.raises(StorageError, match=r"nosuchproto://x/y: cannot open storage") as info:
        get_fs("nosuchproto://x/y")
    assert isinstance(info.value, CrackgenError) and "\n" not in str(info.value)


def _shards_imports(module: str) -> set[str]:
    """Sibling modules of crackgen.shards that ``module`` imports (read from its source)."""
    import ast

    import crackgen.shards

    path = os.path.join(os.path.dirname(crackgen.shards.__file__), f"{module}.py")
    tree = ast.parse(open(path, encoding="utf-8").read())
    names = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
    names |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    return {n.split(".")[2] for n in names if n.startswith("crackgen.shards.")}


def test_shards_modules_are_layered_without_cycles():
    """members/storage sit at the bottom; writer/reader/verify only look down, never back up."""
    assert _shards_imports("members") == set()
    assert _shards_imports("storage") == set()
    assert _shards_imports("codecs") <= {"members"}
    assert _shards_imports("manifest") <= {"storage"}
    for top in ("writer", "reader"):
        assert _shards_imports(top) <= {"codecs", "errors", "manifest", "members", "storage"}, top
    assert _shards_imports("verify") <= {"errors", "manifest", "reader"}
