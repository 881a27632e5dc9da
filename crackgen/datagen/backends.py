"""Where shards run: a local process pool (spawn) or Ray tasks.

Both keep one ``SampleProducer`` (one live Blender scene) per worker process, cached
in a module global, so the scene is built once and reused for every shard the process
gets. Workers report each finished sample through a queue so the driver's progress
bar moves per sample, not per shard. A worker killed with -9 breaks the local pool;
the driver sees ``BrokenProcessPool``, stops, and returns a one-line reason: the
manifest then lists only finished shards and ``--resume`` redoes the rest.
"""
from __future__ import annotations

import queue as _queue
import threading
from dataclasses import dataclass, field
from typing import Any, Callable

from crackgen.datagen.generate import ShardResult, ShardTask, run_shard

_PRODUCER: Any = None
_PRODUCER_KEY: tuple | None = None
_PROGRESS: Any = None  # worker side: a queue the driver drains


@dataclass(frozen=True)
class Job:
    """What every worker needs to know (plain data so it pickles to spawn/Ray workers)."""

    recipe_text: str
    out: str
    threads: int
    storage_options: dict[str, Any] = field(default_factory=dict)


def worker_versions() -> dict[str, str]:
    """Generator-side versions for the manifest (bpy's from package metadata: no import)."""
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    for pkg in ("bpy", "open3d-cpu", "opensimplex"):
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            pass
    return out


def producer_for(job: Job):
    """This process's SampleProducer, built on first use (Blender scene built once)."""
    global _PRODUCER, _PRODUCER_KEY
    key = (job.recipe_text, job.threads)
    if _PRODUCER is None or _PRODUCER_KEY != key:
        from crackgen.datagen.pipeline import SampleProducer
        from crackgen.config.recipe import parse_recipe

        _PRODUCER = SampleProducer(parse_recipe(job.recipe_text, "recipe"), threads=job.threads)
        _PRODUCER_KEY = key
    return _PRODUCER


def _report(n: int) -> None:
    if _PROGRESS is not None:
        try:
            _PROGRESS.put_nowait(n)
        except Exception:  # noqa: BLE001 - progress is best effort, never fail a shard for it
            pass


# ---------------------------------------------------------------- local process pool

def _init_local(progress_queue: Any) -> None:
    global _PROGRESS
    _PROGRESS = progress_queue


def _local_shard(job: Job, task: ShardTask) -> ShardResult:
    return run_shard(producer_for(job), job.out, task, job.storage_options, on_sample=_report)


def _drain(q: Any, update: Callable[[int], None], stop: threading.Event) -> None:
    while not stop.is_set():
        try:
            update(q.get(timeout=0.2))
        except _queue.Empty:
            continue
        except (EOFError, OSError, ValueError):
            return
    while True:  # what is left after the last result
        try:
            update(q.get_nowait())
        except Exception:  # noqa: BLE001
            return


def run_local(job: Job, tasks: list[ShardTask], workers: int, on_result: Callable[[ShardResult], None],
              on_sample: Callable[[int], None]) -> str | None:
    """Run ``tasks`` on a spawn process pool; returns None, or why the run stopped early."""
    import multiprocessing as mp
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    ctx = mp.get_context("spawn")  # fork would copy a half-initialised bpy/OpenMP state
    q = ctx.Queue()
    stop = threading.Event()
    drainer = threading.Thread(target=_drain, args=(q, on_sample, stop), daemon=True)
    drainer.start()
    workers = max(1, min(workers, len(tasks)))
    aborted = None
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_init_local, initargs=(q,))
    try:
        pending = {pool.submit(_local_shard, job, t): t for t in tasks}
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                task = pending.pop(fut)
                try:
                    on_result(fut.result())
                except BrokenProcessPool:
                    aborted = (f"a worker process died (killed or out of memory) while shard {task.index} "
                               f"was running; {len(pending) + 1} shards unfinished")
                    pending.clear()
                    break
    finally:
        pool.shutdown(wait=aborted is None, cancel_futures=True)
        stop.set()
        drainer.join(timeout=5)
        q.close()
        if aborted is None:
            q.join_thread()
        else:
            q.cancel_join_thread()  # a killed worker may have left the pipe mid-message
    return aborted


# ---------------------------------------------------------------- Ray

def _ray_shard(job: Job, task: ShardTask, progress: Any) -> ShardResult:
    global _PROGRESS
    _PROGRESS = progress
    return run_shard(producer_for(job), job.out, task, job.storage_options, on_sample=_report)


def run_ray(job: Job, tasks: list[ShardTask], workers: int, on_result: Callable[[ShardResult], None],
            on_sample: Callable[[int], None], address: str | None = None) -> str | None:
    """Shards as Ray tasks on a local Ray instance (``workers`` CPUs) or the cluster at ``address``.

    Ray reuses worker processes between tasks of one function, so ``producer_for`` keeps the
    Blender scene alive across shards. The output must be reachable by every node: a shared
    path or an fsspec URL (s3://...).
    """
    import ray
    from ray.util.queue import Queue

    started = False
    if not ray.is_initialized():
        if address:
            ray.init(address=address, include_dashboard=False, log_to_driver=False)
        else:
            ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
        started = True
    try:
        progress = Queue()
        remote = ray.remote(num_cpus=1, max_retries=1)(_ray_shard)
        refs = {remote.remote(job, t, progress): t for t in tasks}
        aborted = None
        while refs:
            ready, _ = ray.wait(list(refs), num_returns=1, timeout=0.2)
            while True:
                try:
                    on_sample(progress.get_nowait())
                except Exception:  # noqa: BLE001 - ray.util.queue.Empty
                    break
            for r in ready:
                task = refs.pop(r)
                try:
                    on_result(ray.get(r))
                except ray.exceptions.RayError as exc:
                    aborted = f"Ray task for shard {task.index} failed: {str(exc).splitlines()[0]}"
                    on_result(ShardResult(task.index, None, [], {}, error=aborted))
        return aborted
    finally:
        if started:
            ray.shutdown()

