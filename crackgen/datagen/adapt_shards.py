"""``crackgen adapt``: the [adapt] stage on shards that are already rendered.

Why: rendering is the expensive step, and the photos of a new site arrive later.
Each source shard becomes an output shard of the same name; every member is decoded
and re-encoded with the same codecs (a lossless round trip, so masks, depth and sensor
members keep their exact bytes) and only the RGB views change. The draws come from the
sample's own ``adapt`` stream (``SeedSequence([seed, index])``, stream ``adapt``), so
``crackgen adapt`` with the recipe's seed and options picks the same photo, method and
band as rendering with that ``[adapt]`` table would. Output shards are written
all-or-nothing and recorded in a manifest; ``--resume`` keeps the verified ones.
"""
from __future__ import annotations

import hashlib
import json
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from pydantic import ValidationError
from tqdm import tqdm

from crackgen.config.recipe import AdaptSection, RecipeError, parse_recipe
from crackgen.config.spec import draw_adapt, section_rng
from crackgen.errors import CrackgenError
from crackgen.postrender.stage import adapt_members
from crackgen.postrender.targets import TargetError, TargetPhotos
from crackgen.shards import Manifest, ManifestError, ShardError, ShardWriter, iter_samples, member_for_name
from crackgen.shards.storage import local_path


class AdaptShardsError(CrackgenError, ValueError):
    """Bad input to ``crackgen adapt`` (one line, names the path or option)."""


@dataclass
class AdaptSummary:
    out: str
    samples: int = 0
    adapted: int = 0
    shards: int = 0
    skipped_shards: int = 0
    bytes: int = 0
    wall_s: float = 0.0

    def lines(self) -> list[str]:
        return [f"{self.samples} samples ({self.adapted} adapted) in {self.shards} shards "
                f"({self.skipped_shards} already done), {self.bytes / 1e6:.1f} MB, {self.wall_s:.1f} s",
                f"output: {self.out}"]


def adapt_section(target: str, method: str, weights: str | None, band: str, probability: float) -> AdaptSection:
    """The options as an ``[adapt]`` table, validated by the recipe schema (same messages)."""
    methods = [m.strip() for m in method.split(",") if m.strip()]
    table: dict[str, Any] = {"target": target, "probability": probability,
                             "method": {"choices": methods} if len(methods) > 1 else (methods[0] if methods else "")}
    if weights:
        try:
            table["method"] = {"choices": methods, "weights": [float(w) for w in weights.split(",")]}
        except ValueError:
            raise AdaptShardsError(f"--weights: expected comma-separated numbers, got {weights!r}") from None
    try:
        lo, hi = (float(x) for x in (band.split(",") * 2)[:2])
    except ValueError:
        raise AdaptShardsError(f"--band: expected MIN,MAX fractions, got {band!r}") from None
    table["band"] = {"min": lo, "max": hi} if hi > lo else lo
    try:
        return AdaptSection.model_validate(table)
    except ValidationError as exc:
        e = exc.errors()[0]
        loc = ".".join(str(p) for p in e["loc"] if not str(p).startswith("function-after"))
        raise AdaptShardsError(f"adapt {loc}: {e['msg']}") from None


def source_seed(manifest: Manifest) -> int:
    """The source recipe's dataset seed (the default for the adapt draws)."""
    try:
        return parse_recipe(manifest.recipe_text, "source recipe").dataset.seed
    except RecipeError:
        return 0


def adapt_dataset(src: str, out: str, section: AdaptSection, seed: int | None = None, resume: bool = False,
                  progress: bool = True, log: Callable[[str], None] | None = None) -> AdaptSummary:
    """Write ``out``: the shards of ``src`` with their RGB views adapted per ``section``."""
    log = log or (lambda s: print(s, file=sys.stderr))
    try:
        source = Manifest.load(src)
    except ManifestError as exc:
        raise AdaptShardsError(f"{src}: not a finished crackgen dataset ({exc})") from None
    try:
        targets = TargetPhotos(section.target)
    except TargetError as exc:
        raise AdaptShardsError(str(exc)) from None
    seed = source_seed(source) if seed is None else int(seed)
    options = {"target": str(Path(section.target).resolve()), "seed": seed,
               "section": section.model_dump(mode="json"), "photos": [p.name for p in targets.paths]}
    digest = hashlib.sha256((source.recipe_hash + json.dumps(options, sort_keys=True)).encode()).hexdigest()
    manifest = _output_manifest(out, source, digest, options, resume)
    todo = [r for r in source.done() if not manifest.is_done(r.index, verify=True)]
    summary = AdaptSummary(out=out, skipped_shards=len(source.done()) - len(todo))
    if not todo:
        log(f"{out}: all {len(source.done())} shards already adapted and verified")
        return summary
    bar = tqdm(total=sum(r.samples for r in todo), unit="sample", desc="adapt", disable=not progress,
               file=sys.stderr, dynamic_ncols=True)
    t0 = time.perf_counter()
    try:
        for rec in todo:
            with ShardWriter(out, rec.index) as w:
                for s in iter_samples(source.url(rec.name), verify=True):
                    members, adapted = _adapt_sample(s, section, seed, targets)
                    w.add(s["__key__"], members)
                    summary.samples += 1
                    summary.adapted += int(adapted)
                    bar.update(1)
            manifest.mark_done(w.info)
            manifest.save()
            summary.shards += 1
            summary.bytes += w.info.bytes
    except ShardError as exc:
        raise AdaptShardsError(f"{exc} (finished shards are kept; run again with --resume)") from None
    finally:
        bar.close()
        summary.wall_s = time.perf_counter() - t0
    return summary


def _adapt_sample(s: dict[str, Any], section: AdaptSection, seed: int,
                  targets: TargetPhotos) -> tuple[dict[str, Any], bool]:
    meta = s["meta"]
    index = int(meta.get("index", shard_index_of_key(s["__key__"])))
    spec = draw_adapt(section, section_rng(seed, index, "adapt"))
    members = {f"{name}.{_ext(name)}": value for name, value in s.items()
               if not name.startswith("__") and name != "meta"}
    members, adapt_meta = adapt_members(spec, members, targets if spec.enabled else None)
    members["json"] = {**meta, "adapt": {**adapt_meta, "by": "crackgen adapt", "seed": seed}}
    return members, spec.enabled


def shard_index_of_key(key: str) -> int:
    """Global sample index from a ``SSSSSS-IIIII`` key (the generator's key form)."""
    return int(key.rsplit("-", 1)[-1])


def _ext(member: str) -> str:
    m = member_for_name(member)
    if m is None:
        raise AdaptShardsError(f"unknown shard member {member!r}")
    return m.ext


def _output_manifest(out: str, source: Manifest, digest: str, options: dict[str, Any], resume: bool) -> Manifest:
    path = Path(local_path(out))
    if path.exists() and any(path.iterdir()):
        if not resume:
            raise AdaptShardsError(f"{out}: directory is not empty; use --resume to continue it, or choose a new --out")
        try:
            m = Manifest.load(out)
            m.check_recipe(digest)
        except ManifestError as exc:
            raise AdaptShardsError(f"cannot resume {out}: {exc}") from None
        return m
    os.makedirs(path, exist_ok=True)
    note = "\n".join(f"# {line}" for line in json.dumps(options, indent=1).splitlines())
    text = f"{source.recipe_text.rstrip()}\n\n# ---- crackgen adapt (post-render, RGB views only):\n{note}\n"
    m = Manifest(out, recipe_text=text, recipe_hash=digest, num_shards=source.num_shards,
                 shard_size=source.shard_size, versions=source.versions)
    m.save()
    return m
