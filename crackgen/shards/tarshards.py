"""WebDataset-style shards: the writer the generator uses and the reader the trainer uses.

A shard is a POSIX (pax) tar ``shard-NNNNNN.tar`` whose members are grouped by
sample key: ``000000-00017.rgb.png``, ``000000-00017.mask.png``, … ``000000-00017.json``.
Headers are deterministic (mtime 0, uid/gid 0, no user names, mode 0644, members
sorted within a sample), so identical content gives identical bytes and sha256.

Writing is all-or-nothing: the tar grows under a ``*.partial`` temp name, is
fsynced and hashed while written, then renamed (local) or uploaded whole (fsspec
URL) only when the ``with`` block ends cleanly. An exception removes the partial.

Reading (``iter_samples``) yields one dict per sample::

    {"__key__": "000000-00017", "__shard__": ".../shard-000000.tar",
     "rgb": uint8 H×W×3, "mask": uint8 H×W (0/255), "depth"/"tof"/"lidar"/
     "disp_sgm"/"disp_gt"/"crackmap": float32 H×W (-1 = no value),
     "tofraw": {"Z": float32 h×w range, "A": float32 h×w amplitude},
     "right": uint8 H×W×3, "meta": parsed JSON}

``tofraw`` decodes to a dict (channel name -> array) rather than an H×W×2
stack, so code says ``s["tofraw"]["A"]`` and never depends on channel order.
The same shards read with ``webdataset.WebDataset(urls).decode(codecs.wds_decoder)``.
"""
from __future__ import annotations

import io
import os
import re
import tarfile
import tempfile
import time
from dataclasses import dataclass, field
from typing import Any, Iterable, Iterator, Mapping, Sequence

import numpy as np

from crackgen.errors import CrackgenError
from crackgen.shards.codecs import CodecError, decode_member, encode_member
from crackgen.shards.manifest import (
    Manifest,
    ManifestError,
    ShardInfo,
    file_size,
    fsync_dir,
    get_fs,
    is_url,
    join,
    local_path,
    sha256_file,
    shard_index,
    shard_name,
)
from crackgen.shards.members import Codec, member_for_file, member_for_name, out_name

__all__ = [
    "ShardError", "ShardWriter", "ShardInfo", "ShardDataset", "Manifest", "ManifestError",
    "sample_key", "iter_samples", "load_sample", "list_shards", "open_dataset", "verify_dataset",
    "split_shards", "clean_partials", "benchmark_sample_io",
]

_KEY_RE = re.compile(r"^[A-Za-z0-9_-]+$")
_MEMBER_RE = re.compile(r"^[A-Za-z0-9_]+(\.[A-Za-z0-9_]+)*$")
_ZERO_BLOCK = bytes(tarfile.BLOCKSIZE)


class ShardError(CrackgenError, ValueError):
    """A shard (or a sample going into one) that is bad; the message names the shard file."""


def sample_key(shard: int, sample: int) -> str:
    """Key of sample ``sample`` within shard ``shard``: ``000003-00017`` (no dots, sorts in order)."""
    if shard < 0 or sample < 0:
        raise ValueError(f"shard and sample numbers must be >= 0, got {shard}, {sample}")
    return f"{shard:06d}-{sample:05d}"


# ================================================================ writer

class _HashingWriter:
    """File wrapper that hashes and counts bytes as tarfile writes them (no re-read)."""

    def __init__(self, f):
        import hashlib

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


# ================================================================ reader

@dataclass(frozen=True)
class ShardRef:
    """One shard to read: where it is and, when a manifest knows it, what it should hash to."""

    url: str
    sha256: str | None = None
    bytes: int | None = None
    samples: int | None = None

    @property
    def name(self) -> str:
        return self.url.rstrip("/").replace(os.sep, "/").rsplit("/", 1)[-1]


def _expand(path: Any) -> list[str] | None:
    """A list of tar paths for list/brace inputs, else None (a directory)."""
    if isinstance(path, (list, tuple)):
        return [os.fspath(p) for p in path]
    s = os.fspath(path)
    if "{" in s and ".." in s:
        import braceexpand  # webdataset's dependency; same notation as WebDataset urls

        return list(braceexpand.braceexpand(s))
    if s.endswith(".tar"):
        return [s]
    return None


def _manifest_for(root: str, cache: dict[str, Manifest | None], storage_options) -> Manifest | None:
    if root not in cache:
        try:
            cache[root] = Manifest.load(root, storage_options) if Manifest.exists(root, storage_options) else None
        except ManifestError:
            cache[root] = None
    return cache[root]


def _parent(url: str) -> str:
    if is_url(url):
        return url.rstrip("/").rsplit("/", 1)[0]
    return os.path.dirname(local_path(url)) or "."


def _refs(path: Any, storage_options: Mapping[str, Any] | None = None) -> list[ShardRef]:
    cache: dict[str, Manifest | None] = {}
    files = _expand(path)
    if files is not None:
        refs = []
        for f in files:
            m = _manifest_for(_parent(f), cache, storage_options)
            idx = shard_index(f)
            rec = m.shard(idx) if (m is not None and idx is not None) else None
            if rec is not None and rec.status == "done":
                refs.append(ShardRef(f, rec.sha256, rec.bytes, rec.samples))
            else:
                refs.append(ShardRef(f))
        return refs
    root = os.fspath(path)
    if is_url(root):
        fs, p = get_fs(root, storage_options)
        if not fs.exists(p):
            raise ShardError(f"{root}: dataset not found")
    elif not os.path.isdir(local_path(root)):
        raise ShardError(f"{root}: dataset directory not found (and not a .tar)")
    m = None
    if Manifest.exists(root, storage_options):
        try:
            m = Manifest.load(root, storage_options)
        except ManifestError as exc:
            raise ShardError(str(exc)) from None
    if m is not None:
        return [ShardRef(join(root, r.name), r.sha256, r.bytes, r.samples) for r in m.done()]
    if is_url(root):
        fs, p = get_fs(root, storage_options)
        names = sorted(x.rsplit("/", 1)[-1] for x in fs.glob(p.rstrip("/") + "/shard-*.tar"))
    else:
        names = sorted(n for n in os.listdir(local_path(root)) if shard_index(n) is not None)
    return [ShardRef(join(root, n)) for n in names]


def list_shards(path: Any, storage_options: Mapping[str, Any] | None = None) -> list[str]:
    """Shard paths/URLs in read order: manifest ``done`` shards by index, else ``shard-*.tar`` sorted."""
    return [r.url for r in _refs(path, storage_options)]


def split_shards(shards: Sequence[Any], rank: int, world: int) -> list[Any]:
    """Shards for ``rank`` of ``world`` readers (round robin, disjoint, covering).

    For DDP × DataLoader workers use ``rank = ddp_rank * num_workers + worker_id``
    and ``world = ddp_world * num_workers``.
    """
    if world < 1 or not 0 <= rank < world:
        raise ValueError(f"need 0 <= rank < world, got rank={rank}, world={world}")
    return list(shards)[rank::world]


def _normalise_members(members: Iterable[str] | None) -> set[str] | None:
    if members is None:
        return None
    if isinstance(members, str):
        members = [members]
    out = set()
    for m in members:
        out.add(out_name(m))  # "json" and "meta" both name the metadata
    return out


def _open_binary(url: str, storage_options):
    if is_url(url):
        fs, p = get_fs(url, storage_options)
        return fs.open(p, "rb")
    return open(local_path(url), "rb")


def _iter_shard(ref: ShardRef, verify: bool, keys: set[str] | None, want: set[str] | None,
                storage_options) -> Iterator[dict[str, Any]]:
    """Yield decoded samples of one shard; every failure becomes a ShardError naming it."""
    label = ref.url
    if verify:
        size = file_size(ref.url, storage_options)
        if size is None:
            raise ShardError(f"{label}: shard missing")
        if ref.bytes is not None and size != ref.bytes:
            raise ShardError(f"{label}: size {size} bytes, manifest says {ref.bytes} (truncated?)")
        if ref.sha256:
            digest = sha256_file(ref.url, storage_options)
            if digest != ref.sha256:
                raise ShardError(f"{label}: sha256 mismatch (file {digest[:16]}…, manifest {ref.sha256[:16]}…)")
    try:
        f = _open_binary(ref.url, storage_options)
    except FileNotFoundError:
        raise ShardError(f"{label}: shard missing") from None
    except OSError as exc:
        raise ShardError(f"{label}: cannot open: {exc}") from None
    with f:
        try:
            tar = tarfile.open(fileobj=f, mode="r:")
        except (tarfile.TarError, EOFError, OSError) as exc:
            raise ShardError(f"{label}: not a readable tar: {exc}") from None
        current: dict[str, Any] | None = None
        done_keys: set[str] = set()
        while True:
            try:
                ti = tar.next()
            except (tarfile.TarError, EOFError, OSError) as exc:
                raise ShardError(f"{label}: truncated or corrupt tar: {exc}") from None
            if ti is None:
                break
            if not ti.isreg():
                continue
            base = ti.name.rsplit("/", 1)[-1]
            if "." not in base:
                raise ShardError(f"{label}: member {ti.name!r} has no key.suffix form")
            key, suffix = base.split(".", 1)
            if current is None or key != current["__key__"]:
                if current is not None:
                    done_keys.add(current["__key__"])
                    if keys is None or current["__key__"] in keys:
                        yield current
                if key in done_keys:
                    raise ShardError(f"{label}: sample {key!r} is split in two places (members not grouped)")
                current = {"__key__": key, "__shard__": ref.url}
            if keys is not None and key not in keys:
                continue
            name = out_name(suffix)
            if want is not None and name not in want:
                continue
            try:
                data = tar.extractfile(ti).read()
            except (tarfile.TarError, EOFError, OSError) as exc:
                raise ShardError(f"{label}: truncated or corrupt tar at {ti.name}: {exc}") from None
            if len(data) != ti.size:
                raise ShardError(f"{label}: truncated tar: {ti.name} has {len(data)} of {ti.size} bytes")
            try:
                current[name] = decode_member(suffix, data)
            except CodecError as exc:
                raise ShardError(f"{label}: unreadable member {key}.{exc}") from None
        # tarfile stops silently on a short or garbled header after the first one;
        # a sound archive ends in a zero block exactly where it stopped.
        try:
            f.seek(tar.offset)
            tail = f.read(tarfile.BLOCKSIZE)
        except OSError as exc:
            raise ShardError(f"{label}: cannot read the tar end: {exc}") from None
        if tail != _ZERO_BLOCK:
            raise ShardError(f"{label}: truncated or corrupt tar (no end-of-archive block at byte {tar.offset})")
        if current is not None and (keys is None or current["__key__"] in keys):
            yield current


def iter_samples(
    path: Any,
    verify: bool = False,
    keys: Iterable[str] | None = None,
    members: Iterable[str] | None = None,
    shard_indices: Iterable[int] | None = None,
    storage_options: Mapping[str, Any] | None = None,
) -> Iterator[dict[str, Any]]:
    """Yield one dict per sample (see module doc) from a dataset dir, tar(s) or fsspec URL.

    - ``verify``: check each shard's size and sha256 against the manifest first.
    - ``keys``: only these sample keys (others are skipped without decoding).
    - ``members``: decode only these (``{"rgb", "mask", "depth"}``; ``meta``/``json`` for the
      JSON); ``__key__``/``__shard__`` are always present.
    - ``shard_indices``: positions in ``list_shards(path)`` to read (e.g. from ``split_shards``).
    """
    refs = _refs(path, storage_options)
    if shard_indices is not None:
        idx = list(shard_indices)
        bad = [i for i in idx if not 0 <= i < len(refs)]
        if bad:
            raise ShardError(f"{path}: shard_indices {bad} out of range (dataset has {len(refs)} shards)")
        refs = [refs[i] for i in idx]
    key_set = set(keys) if keys is not None else None
    want = _normalise_members(members)
    for ref in refs:
        yield from _iter_shard(ref, verify, key_set, want, storage_options)


def load_sample(path: Any, key: str, members: Iterable[str] | None = None,
                storage_options: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """One sample by key (for ``crackgen show``); reads the shard the key names first."""
    refs = _refs(path, storage_options)
    prefix = key.split("-", 1)[0]
    first = [r for r in refs if prefix.isdigit() and shard_index(r.name) == int(prefix)]
    want = _normalise_members(members)
    for ref in first + [r for r in refs if r not in first]:
        for s in _iter_shard(ref, False, {key}, want, storage_options):
            return s
    raise ShardError(f"{path}: no sample with key {key!r}")


@dataclass
class ShardDataset:
    """An opened dataset: its shard list (and manifest when there is one).

    Iterating yields samples like ``iter_samples``; ``split`` gives a rank's share.
    """

    path: Any
    shards: list[str]
    manifest: Manifest | None = None
    storage_options: dict[str, Any] = field(default_factory=dict)

    @property
    def num_samples(self) -> int | None:
        """Total samples of the listed shards when the manifest knows them, else None."""
        if self.manifest is None:
            return None
        counts = {self.manifest.url(r.name): r.samples for r in self.manifest.done()}
        if not all(s in counts for s in self.shards):
            return None
        return sum(counts[s] for s in self.shards)

    def __iter__(self) -> Iterator[dict[str, Any]]:
        return self.iter()

    def iter(self, **kwargs: Any) -> Iterator[dict[str, Any]]:
        return iter_samples(self.shards, storage_options=self.storage_options, **kwargs)

    def split(self, rank: int, world: int) -> "ShardDataset":
        return ShardDataset(self.path, split_shards(self.shards, rank, world), self.manifest, self.storage_options)


def open_dataset(path: Any, storage_options: Mapping[str, Any] | None = None) -> ShardDataset:
    """Open a dataset dir / tar(s) / URL; ShardError if there is nothing readable there."""
    so = dict(storage_options or {})
    shards = list_shards(path, so)
    manifest = None
    if _expand(path) is None:
        root = os.fspath(path)
        if Manifest.exists(root, so):
            try:
                manifest = Manifest.load(root, so)
            except ManifestError as exc:
                raise ShardError(str(exc)) from None
    if not shards:
        raise ShardError(f"{path}: no finished shards (shard-*.tar) found")
    return ShardDataset(path, shards, manifest, so)


def verify_dataset(path: Any, decode: bool = True,
                   storage_options: Mapping[str, Any] | None = None) -> list[str]:
    """One problem line per bad shard (missing, truncated, sha mismatch, unreadable member, failed).

    With a manifest every planned shard is checked (size + sha256) and, with
    ``decode``, every member is decoded; without one each ``shard-*.tar`` is read
    through. An empty list means the dataset is sound.
    """
    problems: list[str] = []
    so = dict(storage_options or {})
    root = None if _expand(path) is not None else os.fspath(path)
    if root is not None and Manifest.exists(root, so):
        try:
            m = Manifest.load(root, so)
        except ManifestError as exc:
            return [str(exc)]
        indices = sorted(set(range(m.num_shards)) | {r.index for r in m.shards})
        good = []
        for i in indices:
            p = m.problem(i, verify=True)
            if p is None:
                r = m.shard(i)
                good.append(ShardRef(m.url(r.name), r.sha256, r.bytes, r.samples))
            else:
                problems.append(p)
        refs = good
    else:
        try:
            refs = _refs(path, so)
        except ShardError as exc:
            return [str(exc)]
        if not refs:
            return [f"{path}: no shards found"]
    for ref in refs:
        try:
            n = 0
            for _ in _iter_shard(ref, False, None, None if decode else set(), so):
                n += 1
            if ref.samples is not None and n != ref.samples:
                problems.append(f"{ref.name}: {n} samples, manifest says {ref.samples}")
        except ShardError as exc:
            problems.append(str(exc).replace(ref.url, ref.name, 1))
    return problems


# ================================================================ benchmark

def synthetic_sample(rng: np.random.Generator, size_px: int = 512, tof_px: int = 160) -> dict[str, Any]:
    """A sample with every member and render-like statistics (smooth fields plus
    sensor noise, sparse maps mostly -1) so sizes/timings resemble real shards."""
    h = w = size_px
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32) / size_px
    shade = 0.5 + 0.25 * np.sin(6 * xx) * np.cos(4 * yy)
    rgb = np.clip((shade[..., None] + rng.normal(0, 0.04, (h, w, 3))) * 255, 0, 255).astype(np.uint8)
    mask = np.where(np.abs(yy - 0.5 - 0.1 * np.sin(9 * xx)) < 0.004, 255, 0).astype(np.uint8)
    depth = (0.5 + 0.05 * xx + 0.03 * yy - 0.002 * (mask > 0)).astype(np.float32)
    sparse = np.full((h, w), -1.0, np.float32)
    sel = rng.random((h, w)) < 0.05
    sparse[sel] = depth[sel] + rng.normal(0, 0.003, int(sel.sum())).astype(np.float32)
    lidar = np.full((h, w), -1.0, np.float32)
    lidar[:: max(1, h // 32), :] = depth[:: max(1, h // 32), :]
    disp = (0.06 * 500.0 / depth).astype(np.float32)
    disp_sgm = np.where(rng.random((h, w)) < 0.9, np.round(disp * 16) / 16, -1).astype(np.float32)
    tz = (0.5 + rng.normal(0, 0.002, (tof_px, tof_px))).astype(np.float32)
    ta = (100 + rng.normal(0, 3, (tof_px, tof_px))).astype(np.float32)
    crack = -np.where(mask > 0, 0.002, 0).astype(np.float32)
    return {
        "rgb.png": rgb, "mask.png": mask, "depth.exr": depth, "tof.exr": sparse,
        "tofraw.exr": {"Z": tz, "A": ta}, "lidar.exr": lidar, "right.png": rgb[:, ::-1].copy(),
        "disp_sgm.exr": disp_sgm, "disp_gt.exr": disp, "crackmap.exr": crack,
        "json": {"spec": {"seed": 1}, "K": np.eye(3), "timings": {"render_s": 1.0}},
    }


def benchmark_sample_io(size_px: int = 512, samples: int = 4, exr_compression: str = "zip",
                        out_dir: str | None = None, seed: int = 0) -> dict[str, float]:
    """Time writing and reading ``samples`` full samples; returns bytes/sample and ms/sample."""
    rng = np.random.default_rng(seed)
    data = [synthetic_sample(rng, size_px) for _ in range(samples)]
    with tempfile.TemporaryDirectory(dir=out_dir) as d:
        t0 = time.perf_counter()
        with ShardWriter(d, 0, exr_compression=exr_compression) as w:
            for i, s in enumerate(data):
                w.add(sample_key(0, i), s)
        t1 = time.perf_counter()
        n = sum(1 for _ in iter_samples(os.path.join(d, shard_name(0))))
        t2 = time.perf_counter()
        m = sum(1 for _ in iter_samples(os.path.join(d, shard_name(0)), members={"rgb", "mask", "depth"}))
        t3 = time.perf_counter()
    assert n == m == samples
    return {
        "size_px": size_px, "exr_compression": exr_compression,
        "bytes_per_sample": w.info.bytes / samples,
        "write_ms_per_sample": 1e3 * (t1 - t0) / samples,
        "read_all_ms_per_sample": 1e3 * (t2 - t1) / samples,
        "read_rgb_mask_depth_ms_per_sample": 1e3 * (t3 - t2) / samples,
    }
