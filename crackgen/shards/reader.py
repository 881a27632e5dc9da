"""The shard reader: list a dataset's shards and yield decoded samples from them.

This is what the trainer imports (``from crackgen.shards import iter_samples``), so
it stays pure Python plus the codecs (no bpy). ``iter_samples`` yields one dict
per sample::

    {"__key__": "000000-00017", "__shard__": ".../shard-000000.tar",
     "rgb": uint8 H×W×3, "mask": uint8 H×W (0/255), "depth"/"tof"/"lidar"/
     "disp_sgm"/"disp_gt"/"crackmap": float32 H×W (-1 = no value),
     "tofraw": {"Z": float32 h×w range, "A": float32 h×w amplitude},
     "right": uint8 H×W×3, "meta": parsed JSON}

Keys are the member names of ``crackgen.shards.members`` (``Member.yielded_as``).
``tofraw`` decodes to a dict (channel name -> array) rather than an H×W×2 stack,
so code says ``s["tofraw"]["A"]`` and never depends on channel order. A dataset is
a directory or URL (its manifest's ``done`` shards, else ``shard-*.tar``), one
tar, a list of tars or a brace pattern; every failure is a ``ShardError`` naming
the shard. The same shards read with
``webdataset.WebDataset(urls).decode(crackgen.shards.codecs.wds_decoder)``.
"""
from __future__ import annotations

import os
import tarfile
from dataclasses import dataclass, field
from typing import Any, Iterable, Iterator, Mapping, Sequence

from crackgen.shards.codecs import CodecError, decode_member
from crackgen.shards.errors import ShardError
from crackgen.shards.manifest import Manifest, ManifestError, shard_index
from crackgen.shards.members import out_name
from crackgen.shards.storage import (
    StorageError,
    file_size,
    get_fs,
    is_url,
    join,
    local_path,
    open_binary,
    parent,
    sha256_file,
)

_ZERO_BLOCK = bytes(tarfile.BLOCKSIZE)  # a sound tar ends in zero blocks right after its last member


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


def expand_paths(path: Any) -> list[str] | None:
    """A list of tar paths for list/brace/.tar inputs, else None (a dataset directory or URL)."""
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
    """The manifest beside a listed tar, if a readable one is there (read once per directory)."""
    if root not in cache:
        try:
            cache[root] = Manifest.load(root, storage_options) if Manifest.exists(root, storage_options) else None
        except (ManifestError, StorageError):
            cache[root] = None
    return cache[root]


def shard_refs(path: Any, storage_options: Mapping[str, Any] | None = None) -> list[ShardRef]:
    """Shards to read, in order, with what the manifest (when there is one) says they hold."""
    cache: dict[str, Manifest | None] = {}
    files = expand_paths(path)
    if files is not None:
        refs = []
        for f in files:
            m = _manifest_for(parent(f), cache, storage_options)
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
    return [r.url for r in shard_refs(path, storage_options)]


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


def iter_shard(ref: ShardRef, verify: bool, keys: set[str] | None, want: set[str] | None,
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
        f = open_binary(ref.url, storage_options)
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
    refs = shard_refs(path, storage_options)
    if shard_indices is not None:
        idx = list(shard_indices)
        bad = [i for i in idx if not 0 <= i < len(refs)]
        if bad:
            raise ShardError(f"{path}: shard_indices {bad} out of range (dataset has {len(refs)} shards)")
        refs = [refs[i] for i in idx]
    key_set = set(keys) if keys is not None else None
    want = _normalise_members(members)
    for ref in refs:
        yield from iter_shard(ref, verify, key_set, want, storage_options)


def load_sample(path: Any, key: str, members: Iterable[str] | None = None,
                storage_options: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """One sample by key (for ``crackgen show``); reads the shard the key names first."""
    refs = shard_refs(path, storage_options)
    prefix = key.split("-", 1)[0]
    first = [r for r in refs if prefix.isdigit() and shard_index(r.name) == int(prefix)]
    want = _normalise_members(members)
    for ref in first + [r for r in refs if r not in first]:
        for s in iter_shard(ref, False, {key}, want, storage_options):
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
    if expand_paths(path) is None:
        root = os.fspath(path)
        if Manifest.exists(root, so):
            try:
                manifest = Manifest.load(root, so)
            except ManifestError as exc:
                raise ShardError(str(exc)) from None
    if not shards:
        raise ShardError(f"{path}: no finished shards (shard-*.tar) found")
    return ShardDataset(path, shards, manifest, so)
