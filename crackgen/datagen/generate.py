"""`crackgen generate`: plan shards, run them on a backend, keep the manifest, resume.

Why shards are the unit of work: a worker process builds its Blender scene once and
then renders a whole shard of samples, so start-up cost is paid once per process,
and a shard is written all-or-nothing (``ShardWriter``: temp name + rename). The
driver alone writes the manifest, after each finished shard, so a killed run leaves
a manifest listing only shards that are really complete; ``--resume`` verifies those
(size + sha256) and redoes the rest. All randomness comes from the SampleSpec, so the
content does not depend on worker count or order.
"""
from __future__ import annotations

import json
import os
import sys
import time
from dataclasses import asdict, dataclass, field
from typing import Any, Callable, Mapping

from crackgen.config.recipe import Recipe, RecipeError
from crackgen.config.recipe_compat import resume_check
from crackgen.datagen.backends import BACKENDS, Job, worker_versions
from crackgen.datagen.heap import HeapSettingError, mmap_threshold_from_env
from crackgen.datagen.tasks import ShardResult, ShardTask
from crackgen.errors import CrackgenError, path_error_line
from crackgen.postrender.targets import TargetError, TargetPhotos
from crackgen.shards import clean_partials
from crackgen.shards.manifest import Manifest, ManifestError, ShardInfo, shard_index
from crackgen.shards.storage import get_fs, is_url, local_path


class GenerateError(CrackgenError, RuntimeError):
    """Output or run set-up problem (one line, names the path/option)."""


# ---------------------------------------------------------------- planning

def effective_recipe(recipe: Recipe, samples: int | None) -> Recipe:
    """The recipe with ``--samples`` applied (so its hash and shard plan reflect it)."""
    if samples is None or samples == recipe.dataset.samples:
        return recipe
    if samples < 1:
        raise GenerateError(f"--samples must be >= 1, got {samples}")
    out = recipe.model_copy(update={"dataset": recipe.dataset.model_copy(update={"samples": int(samples)})})
    out._text = f"# crackgen generate --samples {samples} (overrides dataset.samples)\n" + recipe.text
    return out


def plan_shards(recipe: Recipe) -> list[ShardTask]:
    """Contiguous blocks of ``shard_size`` sample indices; the last shard may be short."""
    n, size = recipe.dataset.samples, recipe.dataset.shard_size
    return [ShardTask(i, tuple(range(i * size, min((i + 1) * size, n)))) for i in range(recipe.num_shards)]


def cycles_threads(recipe: Recipe, workers: int, cores: int | None = None) -> int:
    """Cycles threads per worker: the recipe's value, else the cores split between workers."""
    if recipe.render.threads > 0:
        return recipe.render.threads
    cores = cores or os.cpu_count() or 1
    return max(1, cores // max(1, workers))


# ---------------------------------------------------------------- output directory

def parse_storage_options(text: str | None) -> dict[str, Any]:
    """fsspec storage options from JSON (``--storage-options`` or ``CRACKGEN_STORAGE_OPTIONS``)."""
    text = text if text is not None else os.environ.get("CRACKGEN_STORAGE_OPTIONS")
    if not text:
        return {}
    try:
        opts = json.loads(text)
    except json.JSONDecodeError as exc:
        raise GenerateError(f"--storage-options: not valid JSON: {exc}") from None
    if not isinstance(opts, dict):
        raise GenerateError("--storage-options: must be a JSON object")
    return opts


def _listing(out: str, storage_options: Mapping[str, Any]) -> list[str] | None:
    """Names in the output dir, or None when it does not exist."""
    if is_url(out):
        fs, p = get_fs(out, storage_options)
        if not fs.exists(p):
            return None
        try:
            return [x.rstrip("/").rsplit("/", 1)[-1] for x in fs.ls(p, detail=False)]
        except (FileNotFoundError, NotADirectoryError):
            return None
    p = local_path(out)
    if not os.path.exists(p):
        return None
    if not os.path.isdir(p):
        raise GenerateError(f"{out}: exists and is not a directory")
    return os.listdir(p)


def _ours(name: str) -> bool:
    return shard_index(name) is not None or name.endswith(".partial")


def prepare_output(recipe: Recipe, out: str, resume: bool, storage_options: Mapping[str, Any],
                   versions: Mapping[str, str] | None = None,
                   log: Callable[[str], None] | None = None) -> tuple[Manifest, list[ShardTask], list[str]]:
    """Check the output dir and return (manifest, shards to make, notes on shards being redone).

    Refuses a non-empty dir without ``--resume`` and a dir made from another recipe, so
    nothing already made is lost or mixed. A dataset begun by a crackgen whose schema had
    fewer fields resumes when the recipe is the same (``crackgen.config.recipe_compat``).
    """
    names = _listing(out, storage_options)
    plan = plan_shards(recipe)
    notes: list[str] = []
    has_manifest = names is not None and "manifest.json" in names
    if names and not resume:
        raise GenerateError(f"{out}: directory is not empty; use --resume to continue it, or choose a new --out")
    if has_manifest:
        try:
            manifest = Manifest.load(out, storage_options)
        except ManifestError as exc:
            raise GenerateError(str(exc)) from None
        try:
            manifest.check_recipe(recipe.hash)
        except ManifestError as exc:
            try:
                note = resume_check(manifest.recipe_canonical, manifest.recipe_text, recipe)
            except RecipeError as why:
                raise GenerateError(f"cannot resume: {exc} ({why})") from None
            (log or (lambda s: print(s, file=sys.stderr)))(note)
        manifest.storage_options = dict(storage_options)
    else:
        foreign = [n for n in (names or []) if not _ours(n)]
        if foreign:
            raise GenerateError(f"{out}: not a crackgen dataset (no manifest.json, holds {foreign[0]!r}); "
                                "choose an empty --out")
        manifest = Manifest.for_recipe(out, recipe, versions=versions, storage_options=storage_options)
    if not is_url(out):
        try:
            os.makedirs(local_path(out), exist_ok=True)
        except OSError as exc:  # a parent that is a file, a broken link, no permission, a full disk
            raise GenerateError(f"{out}: cannot create the output directory ({path_error_line(exc)})") from None
        clean_partials(out)
    todo = []
    for task in plan:
        rec = manifest.shard(task.index)
        problem = manifest.problem(task.index, verify=True) if rec is not None else "not made yet"
        if problem is None and rec.failures:
            problem = f"{rec.name}: {len(rec.failures)} failed samples"
        if problem is None and rec.samples + len(rec.failures) != len(task.samples):
            problem = f"{rec.name}: {rec.samples} samples, plan says {len(task.samples)}"
        if problem is not None:
            todo.append(task)
            if rec is not None:
                notes.append(problem)
    manifest.save()
    return manifest, todo, notes


# ---------------------------------------------------------------- the run

@dataclass
class Summary:
    out: str
    samples: int = 0  # samples written in this run
    shards: int = 0  # shards finished in this run
    skipped_shards: int = 0  # already finished and verified (resume)
    bytes: int = 0
    wall_s: float = 0.0
    failures: list[dict[str, str]] = field(default_factory=list)
    shard_errors: list[str] = field(default_factory=list)
    redone: list[str] = field(default_factory=list)
    aborted: str | None = None  # e.g. a worker died
    timings: dict[str, float] = field(default_factory=dict)
    worker_processes: int = 0  # distinct worker processes that finished shards (more with --worker-max-shards)

    @property
    def ok(self) -> bool:
        return not (self.failures or self.shard_errors or self.aborted)

    def lines(self) -> list[str]:
        rate = self.samples / self.wall_s if self.wall_s > 0 else 0.0
        out = [
            f"{self.samples} samples in {self.shards} shards ({self.skipped_shards} already done), "
            f"{self.bytes / 1e6:.1f} MB, {self.wall_s:.1f} s ({rate:.2f} samples/s)",
            f"failures: {len(self.failures)} samples, {len(self.shard_errors)} shards; "
            f"{self.worker_processes} worker process{'es' if self.worker_processes != 1 else ''}",
            f"output: {self.out}",
        ]
        out += [f"  failed {f['key']}: {f['error']}" for f in self.failures[:20]]
        out += [f"  shard error: {e}" for e in self.shard_errors]
        if self.aborted:
            out.append(f"aborted: {self.aborted}; run again with --resume to finish the unfinished shards")
        return out

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "ok": self.ok}


@dataclass
class GenerateOptions:
    out: str
    workers: int = 1
    backend: str = "local"  # a key of backends.BACKENDS: local | ray
    ray_address: str | None = None
    samples: int | None = None
    resume: bool = False
    storage_options: dict[str, Any] = field(default_factory=dict)
    progress: bool = True
    worker_max_shards: int = 0  # replace a worker process after this many shards (0 = never)


def check_inputs(recipe: Recipe) -> None:
    """Files the recipe points to, checked before any rendering: the [adapt] target photos and the
    photo family's folder (when the family distribution can draw "photo"), and CRACKGEN_MMAP_THRESHOLD."""
    try:
        mmap_threshold_from_env()
    except HeapSettingError as exc:
        raise GenerateError(str(exc)) from None
    if recipe.adapt.enabled:
        try:
            TargetPhotos(recipe.adapt.target)
        except TargetError as exc:
            raise GenerateError(str(exc)) from None
    m = recipe.material
    weights = m.family.weights or [1.0] * len(m.family.support())
    if any(f == "photo" and w > 0 for f, w in zip(m.family.support(), weights)):
        try:
            TargetPhotos(m.photo_folder, what="material.photo_folder")
        except TargetError as exc:
            raise GenerateError(str(exc)) from None


def generate(recipe: Recipe, opts: GenerateOptions, log: Callable[[str], None] | None = None) -> Summary:
    """Make (or finish) the dataset of ``recipe`` in ``opts.out``; returns the run summary."""
    log = log or (lambda s: print(s, file=sys.stderr))
    make_backend = BACKENDS.get(opts.backend)
    if make_backend is None:
        raise GenerateError(f"--backend must be one of {', '.join(BACKENDS)}, got {opts.backend!r}")
    if opts.workers < 1:
        raise GenerateError(f"--workers must be >= 1, got {opts.workers}")
    if opts.worker_max_shards < 0:
        raise GenerateError(f"--worker-max-shards must be >= 0 (0 = never replace a worker), got {opts.worker_max_shards}")
    recipe = effective_recipe(recipe, opts.samples)
    check_inputs(recipe)
    manifest, todo, notes = prepare_output(recipe, opts.out, opts.resume, opts.storage_options,
                                           versions=worker_versions(), log=log)
    summary = Summary(out=opts.out, skipped_shards=recipe.num_shards - len(todo), redone=notes)
    for n in notes:
        log(f"redoing {n}")
    if not todo:
        log(f"{opts.out}: all {recipe.num_shards} shards already done and verified")
        return summary
    threads = cycles_threads(recipe, opts.workers)
    total = sum(len(t.samples) for t in todo)
    bar = _bar(total, opts.progress)
    t0 = time.perf_counter()

    pids: set[int] = set()

    def on_result(res: ShardResult) -> None:
        if res.worker_pid:
            pids.add(res.worker_pid)
            summary.worker_processes = len(pids)
        if res.info is None:
            manifest.mark_failed(res.index, res.failures + [{"key": "*", "error": res.error or "unknown"}])
            summary.shard_errors.append(f"shard {res.index}: {res.error}")
        else:
            info = ShardInfo(**res.info)
            manifest.mark_done(info, res.failures, timings=res.timings)
            summary.shards += 1
            summary.samples += info.samples
            summary.bytes += info.bytes
        summary.failures.extend(res.failures)
        for k, v in res.timings.items():
            summary.timings[k] = summary.timings.get(k, 0.0) + v
        manifest.save()

    job = Job(recipe_text=recipe.text, out=opts.out, threads=threads, storage_options=dict(opts.storage_options),
              max_shards_per_worker=opts.worker_max_shards)
    try:
        summary.aborted = make_backend(opts.ray_address).run(job, todo, opts.workers, on_result, bar.update)
    finally:
        bar.close()
        summary.wall_s = time.perf_counter() - t0
    return summary


def _bar(total: int, enabled: bool):
    from tqdm import tqdm

    return tqdm(total=total, unit="sample", desc="generate", disable=not enabled, dynamic_ncols=True,
                smoothing=0.1, file=sys.stderr)

