"""manifest.json: how a dataset was made and which shards are finished.

The manifest is the dataset's ledger. It stores the recipe's full text and hash,
the generator and library versions, the planned shard count and, per shard, its
sample count, sha256, size and status (``done`` | ``failed``) with per-sample
failures. ``--resume`` trusts a shard only when ``is_done`` re-checks size (and
sha256) on disk, so a shard truncated after it was recorded is redone.

Only the driver process writes the manifest (workers return ``ShardInfo``); each
save replaces the whole file atomically (temp + ``os.replace`` locally, one whole
object on fsspec stores), so a reader never sees half a manifest.

This module also owns shard file names (``shard-000123.tar``) and the library
versions recorded with a dataset. Files are read and written through
``crackgen.shards.storage``, so the root may be a local dir or an fsspec URL.
"""
from __future__ import annotations

import dataclasses
import datetime as _dt
import json
import os
import platform
import re
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping

from crackgen.errors import CrackgenError
from crackgen.shards.storage import file_size, join, read_bytes, sha256_file, write_bytes_atomic

MANIFEST_NAME = "manifest.json"
MANIFEST_FORMAT = "crackgen-shards"
MANIFEST_VERSION = 1
SHARD_PATTERN = "shard-%06d.tar"
_SHARD_RE = re.compile(r"^shard-(\d{6,})\.tar$")


class ManifestError(CrackgenError, ValueError):
    """A manifest that is missing, unreadable or inconsistent (message names the file)."""


# ---------------------------------------------------------------- shard names

def shard_name(index: int) -> str:
    if index < 0:
        raise ValueError(f"shard index must be >= 0, got {index}")
    return SHARD_PATTERN % index


def shard_index(name: str) -> int | None:
    """Index from ``shard-000123.tar`` (any directory/URL prefix), else None."""
    m = _SHARD_RE.match(name.rstrip("/").rsplit("/", 1)[-1].rsplit(os.sep, 1)[-1])
    return int(m.group(1)) if m else None


def library_versions(extra: Mapping[str, str] | None = None) -> dict[str, str]:
    """Versions of the libraries that shape the bytes; ``extra`` adds e.g. bpy from the worker side.

    bpy is deliberately not imported here: the reader side must stay light.
    """
    import cv2
    import numpy
    import OpenEXR

    import crackgen

    out = {
        "python": platform.python_version(),
        "crackgen": crackgen.__version__,
        "numpy": numpy.__version__,
        "opencv": cv2.__version__,
        "OpenEXR": getattr(OpenEXR, "__version__", "unknown"),
    }
    out.update({str(k): str(v) for k, v in (extra or {}).items()})
    return out


def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


# ---------------------------------------------------------------- records

@dataclass(frozen=True)
class ShardInfo:
    """What a worker reports for a finished shard (the driver records it)."""

    name: str
    samples: int
    sha256: str
    bytes: int

    @property
    def index(self) -> int:
        idx = shard_index(self.name)
        if idx is None:
            raise ValueError(f"{self.name}: not a shard-NNNNNN.tar name")
        return idx

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclass
class ShardRecord:
    """One shard's line in the manifest."""

    name: str
    index: int
    status: str  # "done" | "failed"
    samples: int = 0
    sha256: str = ""
    bytes: int = 0
    failures: list[dict[str, str]] = field(default_factory=list)
    # per-stage seconds summed over the shard: kept here, not in the samples, so shards stay byte-identical
    timings: dict[str, float] = field(default_factory=dict)

    STATUSES = ("done", "failed")

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name, "index": self.index, "status": self.status, "samples": self.samples,
            "sha256": self.sha256, "bytes": self.bytes, "failures": list(self.failures),
            "timings": {k: round(v, 6) for k, v in sorted(self.timings.items())},
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], where: str) -> "ShardRecord":
        try:
            rec = cls(
                name=str(d["name"]), index=int(d["index"]), status=str(d["status"]),
                samples=int(d.get("samples", 0)), sha256=str(d.get("sha256", "")),
                bytes=int(d.get("bytes", 0)),
                failures=[{"key": str(f["key"]), "error": str(f["error"])} for f in d.get("failures", [])],
                timings={str(k): float(v) for k, v in dict(d.get("timings", {})).items()},
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise ManifestError(f"{where}: bad shard entry {dict(d)!r}: {exc!r}") from None
        if rec.status not in cls.STATUSES:
            raise ManifestError(f"{where}: shard {rec.name}: status must be one of {cls.STATUSES}, got {rec.status!r}")
        return rec


def _failures(failures: Iterable[Any]) -> list[dict[str, str]]:
    """Accept {key, error} dicts or (key, error) pairs."""
    out = []
    for f in failures:
        if isinstance(f, Mapping):
            out.append({"key": str(f["key"]), "error": str(f["error"])})
        else:
            k, e = f
            out.append({"key": str(k), "error": str(e)})
    return out


# ---------------------------------------------------------------- manifest

class Manifest:
    """The ledger of one dataset directory (local or fsspec URL)."""

    def __init__(
        self,
        root: str | os.PathLike,
        *,
        recipe_text: str = "",
        recipe_hash: str = "",
        recipe_canonical: Mapping[str, Any] | None = None,
        num_shards: int = 0,
        shard_size: int = 0,
        versions: Mapping[str, str] | None = None,
        generator_version: str | None = None,
        created: str | None = None,
        shards: Iterable[ShardRecord] = (),
        storage_options: Mapping[str, Any] | None = None,
    ):
        import crackgen

        self.root = os.fspath(root)
        self.recipe_text = recipe_text
        self.recipe_hash = recipe_hash
        # every recipe field, defaults filled: lets a newer crackgen tell added fields from changed ones
        self.recipe_canonical = dict(recipe_canonical) if recipe_canonical is not None else None
        self.num_shards = int(num_shards)
        self.shard_size = int(shard_size)
        # library versions of this process plus what the caller adds (bpy comes from the worker side)
        self.versions = library_versions(versions)
        self.generator_version = generator_version or crackgen.__version__
        self.created = created or _now()
        self.storage_options = dict(storage_options or {})
        self._shards: dict[int, ShardRecord] = {s.index: s for s in shards}

    # ---- construction
    @classmethod
    def for_recipe(cls, root: str | os.PathLike, recipe: Any, versions: Mapping[str, str] | None = None,
                   storage_options: Mapping[str, Any] | None = None) -> "Manifest":
        """A fresh manifest for a ``crackgen.config.recipe.Recipe`` (duck-typed: text, hash, num_shards, dataset)."""
        return cls(root, recipe_text=recipe.text, recipe_hash=recipe.hash,
                   recipe_canonical=recipe.model_dump(mode="json"), num_shards=recipe.num_shards,
                   shard_size=recipe.dataset.shard_size, versions=versions,
                   storage_options=storage_options)

    @property
    def path(self) -> str:
        return join(self.root, MANIFEST_NAME)

    @classmethod
    def exists(cls, root: str | os.PathLike, storage_options: Mapping[str, Any] | None = None) -> bool:
        return file_size(join(os.fspath(root), MANIFEST_NAME), storage_options) is not None

    @classmethod
    def load(cls, root: str | os.PathLike, storage_options: Mapping[str, Any] | None = None) -> "Manifest":
        root = os.fspath(root)
        where = join(root, MANIFEST_NAME)
        try:
            data = json.loads(read_bytes(where, storage_options).decode("utf-8"))
        except FileNotFoundError:
            raise ManifestError(f"{where}: no manifest") from None
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ManifestError(f"{where}: not valid JSON: {exc}") from None
        except OSError as exc:
            raise ManifestError(f"{where}: cannot read: {exc}") from None
        if not isinstance(data, dict) or data.get("format") != MANIFEST_FORMAT:
            raise ManifestError(f"{where}: not a crackgen manifest (format must be {MANIFEST_FORMAT!r})")
        if data.get("format_version") != MANIFEST_VERSION:
            raise ManifestError(f"{where}: format_version {data.get('format_version')!r} unsupported "
                                f"(this reader knows {MANIFEST_VERSION})")
        try:
            m = cls(
                root,
                recipe_text=str(data["recipe_text"]), recipe_hash=str(data["recipe_hash"]),
                recipe_canonical=data.get("recipe_canonical"),  # absent in manifests before 2026-12-03
                num_shards=int(data["num_shards"]), shard_size=int(data["shard_size"]),
                generator_version=str(data["generator_version"]),
                created=str(data["created"]),
                shards=[ShardRecord.from_dict(s, where) for s in data["shards"]],
                storage_options=storage_options,
            )
            m.versions = {str(k): str(v) for k, v in dict(data["versions"]).items()}  # as recorded, not ours
            return m
        except (KeyError, TypeError, ValueError) as exc:
            if isinstance(exc, ManifestError):
                raise
            raise ManifestError(f"{where}: missing or bad field: {exc!r}") from None

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": MANIFEST_FORMAT,
            "format_version": MANIFEST_VERSION,
            "generator_version": self.generator_version,
            "versions": dict(sorted(self.versions.items())),
            "created": self.created,
            "updated": _now(),
            "recipe_hash": self.recipe_hash,
            "recipe_text": self.recipe_text,
            **({"recipe_canonical": self.recipe_canonical} if self.recipe_canonical is not None else {}),
            "num_shards": self.num_shards,
            "shard_size": self.shard_size,
            "num_samples_done": self.num_samples,
            "shards": [self._shards[i].to_dict() for i in sorted(self._shards)],
        }

    def save(self) -> None:
        data = json.dumps(self.to_dict(), indent=1).encode("utf-8")
        write_bytes_atomic(self.path, data, self.storage_options)

    # ---- queries
    @property
    def shards(self) -> list[ShardRecord]:
        return [self._shards[i] for i in sorted(self._shards)]

    def shard(self, index: int) -> ShardRecord | None:
        return self._shards.get(index)

    def done(self) -> list[ShardRecord]:
        """Shards recorded as done, in index order (what readers iterate)."""
        return [s for s in self.shards if s.status == "done"]

    @property
    def num_samples(self) -> int:
        return sum(s.samples for s in self.done())

    def pending(self) -> list[int]:
        """Planned shard indices not recorded as done (cheap: no disk checks)."""
        return [i for i in range(self.num_shards) if i not in self._shards or self._shards[i].status != "done"]

    def check_recipe(self, recipe_hash: str) -> None:
        """Refuse to resume into a dataset made from a different recipe."""
        if self.recipe_hash and recipe_hash != self.recipe_hash:
            raise ManifestError(f"{self.path}: made from recipe {self.recipe_hash[:16]}, "
                                f"not {recipe_hash[:16]}; use a new --out directory")

    def problem(self, index: int, verify: bool = True) -> str | None:
        """One line saying why shard ``index`` is not a good finished shard, or None if it is."""
        rec = self._shards.get(index)
        name = rec.name if rec else shard_name(index)
        if rec is None:
            return f"{name}: not recorded in the manifest"
        if rec.status != "done":
            return f"{name}: marked {rec.status} in the manifest ({len(rec.failures)} failures)"
        url = join(self.root, rec.name)
        size = file_size(url, self.storage_options)
        if size is None:
            return f"{name}: missing ({url})"
        if size != rec.bytes:
            return f"{name}: size {size} bytes, manifest says {rec.bytes} (truncated or rewritten)"
        if verify:
            digest = sha256_file(url, self.storage_options)
            if digest != rec.sha256:
                return f"{name}: sha256 mismatch (file {digest[:16]}…, manifest {rec.sha256[:16]}…)"
        return None

    def is_done(self, index: int, verify: bool = True) -> bool:
        """Recorded done and on disk with the recorded size (and sha256 when ``verify``)."""
        return self.problem(index, verify) is None

    # ---- updates (driver only)
    def mark_done(self, info: ShardInfo, failures: Iterable[Any] = (),
                  timings: Mapping[str, float] | None = None) -> ShardRecord:
        """Record a finished shard; ``failures`` lists samples left out of it ({key, error}),
        ``timings`` its per-stage seconds summed over its samples."""
        rec = ShardRecord(name=info.name, index=info.index, status="done", samples=info.samples,
                          sha256=info.sha256, bytes=info.bytes, failures=_failures(failures),
                          timings={str(k): float(v) for k, v in (timings or {}).items()})
        self._shards[rec.index] = rec
        return rec

    def mark_failed(self, index: int, failures: Iterable[Any]) -> ShardRecord:
        """Record a shard that could not be finished, with why (per sample or ``{key: '*'}``)."""
        rec = ShardRecord(name=shard_name(index), index=index, status="failed", failures=_failures(failures))
        self._shards[index] = rec
        return rec

    def url(self, name: str) -> str:
        return join(self.root, name)
