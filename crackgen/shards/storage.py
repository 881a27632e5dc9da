"""Where shard files live: local paths and fsspec URLs behind one small set of calls.

Why one module: the manifest, the writer and the reader all need "how big is it",
"hash it", "read it", "replace it atomically" for both a local directory and an
object store (``s3://bucket/prefix``, ``memory://x``). Here, and only here, a
location is told apart (``is_url``) and fsspec is imported (lazily, so local use
never needs it). ``storage_options`` go to fsspec unchanged (e.g. ``client_kwargs``
for S3). ``file://`` URLs are treated as local paths.
"""
from __future__ import annotations

import hashlib
import os
import tempfile
from typing import IO, Any, Mapping

from crackgen.errors import CrackgenError

_CHUNK = 1 << 20  # read size for hashing: large enough to stream, small enough to stay flat in memory


class StorageError(CrackgenError, ValueError):
    """A location that cannot be opened (unknown protocol, missing fsspec backend); names the URL."""


def is_url(path: str | os.PathLike) -> bool:
    """True for fsspec URLs other than ``file://`` (those are treated as local paths)."""
    s = os.fspath(path)
    return "://" in s and not s.startswith("file://")


def local_path(path: str | os.PathLike) -> str:
    """The filesystem path of a local location (``file://`` prefix dropped)."""
    s = os.fspath(path)
    return s[len("file://"):] if s.startswith("file://") else s


def get_fs(url: str, storage_options: Mapping[str, Any] | None = None):
    """(filesystem, path-inside-it) for an fsspec URL; fsspec is imported only here."""
    import fsspec

    try:
        return fsspec.core.url_to_fs(url, **dict(storage_options or {}))
    except (ImportError, ValueError) as exc:
        raise StorageError(f"{url}: cannot open storage: {exc}") from None


def join(root: str, name: str) -> str:
    """Join a file name onto a local dir or a URL."""
    if is_url(root):
        return root.rstrip("/") + "/" + name
    return os.path.join(local_path(root), name)


def parent(path: str) -> str:
    """The directory (or URL prefix) that holds ``path``; ``.`` for a bare local name."""
    if is_url(path):
        return path.rstrip("/").rsplit("/", 1)[0]
    return os.path.dirname(local_path(path)) or "."


def file_size(path: str, storage_options: Mapping[str, Any] | None = None) -> int | None:
    """Size in bytes, or None when the file is missing."""
    if is_url(path):
        fs, p = get_fs(path, storage_options)
        try:
            return int(fs.size(p))
        except FileNotFoundError:
            return None
    try:
        return os.path.getsize(local_path(path))
    except FileNotFoundError:
        return None


def open_binary(path: str, storage_options: Mapping[str, Any] | None = None) -> IO[bytes]:
    """A seekable binary file opened for reading (FileNotFoundError when missing)."""
    if is_url(path):
        fs, p = get_fs(path, storage_options)
        return fs.open(p, "rb")
    return open(local_path(path), "rb")


def sha256_file(path: str, storage_options: Mapping[str, Any] | None = None) -> str:
    """sha256 of a whole file (local or fsspec), read in 1 MiB chunks."""
    h = hashlib.sha256()
    with open_binary(path, storage_options) as f:
        while chunk := f.read(_CHUNK):
            h.update(chunk)
    return h.hexdigest()


def read_bytes(path: str, storage_options: Mapping[str, Any] | None = None) -> bytes:
    """The whole file's bytes (for small files such as the manifest)."""
    if is_url(path):
        fs, p = get_fs(path, storage_options)
        return fs.cat_file(p)
    with open(local_path(path), "rb") as f:
        return f.read()


def write_bytes_atomic(path: str, data: bytes, storage_options: Mapping[str, Any] | None = None) -> None:
    """Replace ``path`` with ``data`` so readers see the old or the new file, never half."""
    if is_url(path):
        fs, p = get_fs(path, storage_options)
        fs.pipe_file(p, data)  # one PUT: object stores swap whole objects
        return
    p = local_path(path)
    d = os.path.dirname(os.path.abspath(p))
    os.makedirs(d, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=d, prefix=os.path.basename(p) + ".", suffix=".partial")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o644)
        os.replace(tmp, p)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise
    fsync_dir(d)


def fsync_dir(d: str) -> None:
    """Make a rename durable (POSIX); silently skipped where directories cannot be opened."""
    try:
        fd = os.open(d, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
