"""The shard writer: one ``shard-NNNNNN.tar`` written all or nothing.

A shard is a POSIX (pax) tar whose members are grouped by sample key:
``000000-00017.rgb.png``, ``000000-00017.mask.png``, … ``000000-00017.json``.
Headers are deterministic (mtime 0, uid/gid 0, no user names, mode 0644, members
sorted within a sample), so identical content gives identical bytes and sha256.

Why all or nothing: the tar grows under a ``*.partial`` temp name, is fsynced and
hashed while written, then renamed (local) or uploaded whole (fsspec URL) only when
the ``with`` block ends cleanly; an exception removes the partial. So a shard file
under its final name is always complete, and ``--resume`` only has to clean
partials (``clean_partials``). Known members are held to the data contract in
``crackgen.shards.members`` before anything is written.
"""
from __future__ import annotations

import hashlib
import io
import os
import re
import tarfile
import tempfile
from typing import Any, BinaryIO, Mapping

import numpy as np

from crackgen.shards.codecs import CodecError, encode_member
from crackgen.shards.errors import ShardError
from crackgen.shards.manifest import ShardInfo, shard_name
from crackgen.shards.members import Codec, member_for_file, member_for_name
from crackgen.shards.storage import fsync_dir, get_fs, is_url, join, local_path

_KEY_RE = re.compile(r"^[A-Za-z0-9_-]+$")
_MEMBER_RE = re.compile(r"^[A-Za-z0-9_]+(\.[A-Za-z0-9_]+)*$")


def sample_key(shard: int, sample: int) -> str:
    """Key of sample ``sample`` within shard ``shard``: ``000003-00017`` (no dots, sorts in order)."""
    if shard < 0 or sample < 0:
        raise ValueError(f"shard and sample numbers must be >= 0, got {shard}, {sample}")
    return f"{shard:06d}-{sample:05d}"



class _HashingWriter:
    """File wrapper that hashes and counts bytes as tarfile writes them (no re-read)."""

    def __init__(self, f: BinaryIO):
        self.f = f
        self.sha = hashlib.sha256()
        self.n = 0

    def write(self, b) -> int:
        self.f.write(b)
        self.sha.update(b)
        self.n += len(b)
        return len(b)

    def tell(self) -> int:
        return self.n

    def flush(self) -> None:
        self.f.flush()


def _check_members(key: str, members: Mapping[str, Any]) -> None:
    """Hold known members to the data contract before anything is written."""
    if not members:
        raise ShardError(f"{key}: sample has no members")
    shapes: dict[str, tuple[int, int]] = {}
    for name, value in members.items():
        if not isinstance(name, str) or not _MEMBER_RE.match(name):
            raise ShardError(f"{key}: bad member name {name!r} (letters, digits, _ and dots, like 'rgb.png')")
        if "." not in name and name != "json":
            raise ShardError(f"{key}.{name}: member name needs an extension (e.g. '{name}.png')")
        if isinstance(value, (bytes, bytearray, memoryview)):
            continue
        kind = member_for_file(name)
        codec = kind.codec if kind is not None else None
        if codec is Codec.PNG_RGB:
            a = np.asarray(value)
            if a.dtype != np.uint8 or a.ndim != 3 or a.shape[2] != 3:
                raise ShardError(f"{key}.{name}: must be uint8 H×W×3 RGB, got {a.dtype} {a.shape}")
        elif codec is Codec.PNG_MASK:
            a = np.asarray(value)
            if a.dtype != np.uint8 or a.ndim != 2:
                raise ShardError(f"{key}.{name}: must be uint8 H×W, got {a.dtype} {a.shape}")
            if not np.isin(a, (0, 255)).all():
                raise ShardError(f"{key}.{name}: mask values must be 0 or 255, found {np.unique(a)[:8].tolist()}")
        elif codec is Codec.EXR_FLOAT:
            a = np.asarray(value)
            if a.ndim != 2 or a.dtype.kind != "f":
                raise ShardError(f"{key}.{name}: must be a float H×W map, got {a.dtype} {a.shape}")
        elif codec is Codec.EXR_CHANNELS:
            if not isinstance(value, Mapping) or not set(kind.channels) <= set(value):
                wanted = " and ".join(repr(c) for c in kind.channels)
                raise ShardError(f"{key}.{name}: must be a dict with channels {wanted}")
        elif codec is Codec.JSON and not isinstance(value, (Mapping, str)):
            raise ShardError(f"{key}.json: metadata must be a dict, got {type(value).__name__}")
        view = member_for_name(name)
        if view is not None and view.in_rgb_view and isinstance(value, np.ndarray) and value.ndim >= 2:
            shapes[name] = value.shape[:2]
    if len(set(shapes.values())) > 1:
        raise ShardError(f"{key}: RGB-view members differ in size: {shapes}")


class ShardWriter:
    """Write one shard, all or nothing.

    >>> with ShardWriter("data/roads", 3) as w:
    ...     w.add(sample_key(3, 0), {"rgb.png": rgb, "mask.png": mask, "depth.exr": depth, "json": meta})
    >>> w.info  # ShardInfo(name='shard-000003.tar', samples=1, sha256=..., bytes=...)

    ``add`` encodes every member before writing any, so a sample that fails to
    encode raises (``ShardError``/``CodecError`` naming key and member) and leaves
    the shard consistent: the caller may record the failure and carry on.
    For fsspec URLs the tar is built in ``tmp_dir`` (default: system temp) and
    uploaded to its final name on close; nothing appears there before that.
    A final shard of the same name is replaced (identical content gives identical
    bytes, so redoing a shard the manifest did not record is safe).
    """

    def __init__(self, out: str | os.PathLike, shard_index: int, *, exr_compression: str = "zip",
                 storage_options: Mapping[str, Any] | None = None, tmp_dir: str | os.PathLike | None = None):
        self.out = os.fspath(out)
        self.index = int(shard_index)
        self.name = shard_name(self.index)
        self.url = join(self.out, self.name)
        self.remote = is_url(self.out)
        self.exr_compression = exr_compression
        self.storage_options = dict(storage_options or {})
        self.tmp_dir = os.fspath(tmp_dir) if tmp_dir is not None else None
        self.info: ShardInfo | None = None
        self.keys: list[str] = []
        self._seen: set[str] = set()
        self._tmp: str | None = None
        self._file = None
        self._hw: _HashingWriter | None = None
        self._tar: tarfile.TarFile | None = None

    # ---- lifecycle
    def open(self) -> "ShardWriter":
        if self._tar is not None:
            raise ShardError(f"{self.name}: writer already open")
        if self.remote:
            d = self.tmp_dir or tempfile.gettempdir()
        else:
            d = local_path(self.out)
        os.makedirs(d, exist_ok=True)
        fd, self._tmp = tempfile.mkstemp(dir=d, prefix=self.name + ".", suffix=".partial")
        self._file = os.fdopen(fd, "wb")
        self._hw = _HashingWriter(self._file)
        self._tar = tarfile.open(fileobj=self._hw, mode="w", format=tarfile.PAX_FORMAT)
        return self

    def __enter__(self) -> "ShardWriter":
        return self.open()

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None:
            self.abort()
        else:
            self.close()

    @property
    def samples(self) -> int:
        return len(self.keys)

    def add(self, key: str, members: Mapping[str, Any]) -> None:
        """Append one sample; ``members`` maps member names (``rgb.png``, ``json``…) to values."""
        if self._tar is None:
            raise ShardError(f"{self.name}: writer is not open (use it as a context manager)")
        if not isinstance(key, str) or not _KEY_RE.match(key):
            raise ShardError(f"{self.name}: bad sample key {key!r} (letters, digits, '-', '_'; no dots)")
        if key in self._seen:
            raise ShardError(f"{self.name}: sample key {key!r} added twice")
        _check_members(key, members)
        encoded = {}
        for name in sorted(members):
            try:
                encoded[name] = encode_member(name, members[name], name=f"{key}.{name}",
                                              exr_compression=self.exr_compression)
            except CodecError as exc:
                raise ShardError(f"{self.name}: {exc}") from None
        for name, data in encoded.items():
            ti = tarfile.TarInfo(f"{key}.{name}")
            ti.size = len(data)
            ti.mtime = 0
            ti.mode = 0o644
            ti.uid = ti.gid = 0
            ti.uname = ti.gname = ""
            ti.type = tarfile.REGTYPE
            self._tar.addfile(ti, io.BytesIO(data))
        self._seen.add(key)
        self.keys.append(key)

    def close(self) -> ShardInfo:
        """Finish the tar, fsync, then rename/upload it to its final name."""
        if self.info is not None:
            return self.info
        if self._tar is None:
            raise ShardError(f"{self.name}: writer was never opened")
        try:
            self._tar.close()
            self._file.flush()
            os.fsync(self._file.fileno())
            self._file.close()
            info = ShardInfo(name=self.name, samples=len(self.keys), sha256=self._hw.sha.hexdigest(),
                             bytes=self._hw.n)
            os.chmod(self._tmp, 0o644)
            if self.remote:
                fs, p = get_fs(self.url, self.storage_options)
                fs.put_file(self._tmp, p)
                os.remove(self._tmp)
            else:
                os.replace(self._tmp, local_path(self.url))
                fsync_dir(os.path.dirname(os.path.abspath(local_path(self.url))))
        except BaseException:
            self.abort()
            raise
        self._tmp = None
        self._tar = None
        self.info = info
        return info

    def abort(self) -> None:
        """Drop the partial file; nothing final is written."""
        try:
            if self._file is not None and not self._file.closed:
                self._file.close()
        finally:
            if self._tmp and os.path.exists(self._tmp):
                os.remove(self._tmp)
            self._tmp = None
            self._tar = None


def clean_partials(root: str | os.PathLike) -> list[str]:
    """Remove ``*.partial`` leftovers of killed writers in a local dataset dir (for ``--resume``)."""
    root = local_path(os.fspath(root))
    if is_url(root) or not os.path.isdir(root):
        return []
    removed = []
    for n in sorted(os.listdir(root)):
        if n.endswith(".partial"):
            os.remove(os.path.join(root, n))
            removed.append(n)
    return removed
