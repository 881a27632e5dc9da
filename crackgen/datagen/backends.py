"""Where shards run: a local process pool (spawn) or Ray tasks, behind one ``Backend`` interface.

Both keep one ``SampleProducer`` (one live Blender scene) per worker process, cached
in a module global, so the scene is built once and reused for every shard the process
gets. Workers report each finished sample through a queue so the driver's progress
bar moves per sample, not per shard. A worker killed with -9 breaks the local pool;
the driver sees ``BrokenProcessPool``, stops, and returns a one-line reason: the
manifest then lists only finished shards and ``--resume`` redoes the rest.

``Job.max_shards_per_worker`` (``generate --worker-max-shards K``) replaces a worker
process with a fresh one after K shards: native libraries (Cycles, Embree) keep memory
that no allocator setting returns (crackgen/datagen/heap.py), so this bounds a long
run's RSS at what one worker reaches in K shards, for one scene build per K shards.

``generate`` picks a back end from ``BACKENDS`` by name; adding one is one class and
one registry line.
"""
from __future__ import annotations

import multiprocessing as mp
import os
import queue as _queue
import threading
import time
from collections import deque
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError, version
from typing import Any, Callable, Protocol

from crackgen.datagen.tasks import ShardResult, ShardTask, run_shard

ResultFn = Callable[[ShardResult], None]
SampleFn = Callable[[int], None]

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
    max_shards_per_worker: int = 0  # a fresh worker process after this many shards; 0 = keep it


class Backend(Protocol):
    """Runs shard tasks somewhere and reports back; the driver owns the manifest."""

    def run(self, job: Job, tasks: list[ShardTask], workers: int, on_result: ResultFn,
            on_sample: SampleFn) -> str | None:
        """Run ``tasks``; ``on_result`` per finished shard, ``on_sample(n)`` per finished sample.

        Returns None, or one line saying why the run stopped early.
        """
        ...


def worker_versions() -> dict[str, str]:
    """Generator-side versions for the manifest (bpy's from package metadata: no import)."""
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
        # Heavy (numba, scipy, the whole generator): only worker processes pay for it, not the driver.
        from crackgen.config.recipe import parse_recipe
        from crackgen.datagen.pipeline import SampleProducer

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

def _exit_with_parent(parent_pid: int, poll_s: float = 0.5) -> None:
    """Worker side: end this process once the driver is gone. A driver killed on its own (SIGTERM
    from a scheduler, -9) would otherwise leave its workers rendering on and writing shards into a
    dataset that no manifest lists, and a new run into the same folder would race them."""
    while os.getppid() == parent_pid:
        time.sleep(poll_s)
    os._exit(1)


def _init_local(progress_queue: Any, parent_pid: int | None = None) -> None:
    global _PROGRESS
    _PROGRESS = progress_queue
    if parent_pid is not None:
        threading.Thread(target=_exit_with_parent, args=(parent_pid,), daemon=True, name="exit-with-parent").start()


def _local_shard(job: Job, task: ShardTask) -> ShardResult:
    return run_shard(producer_for(job), job.out, task, job.storage_options, on_sample=_report)


def _drain(q: Any, update: SampleFn, stop: threading.Event) -> None:
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


@dataclass(frozen=True)
class LocalBackend:
    """Shards on a spawn process pool of ``workers`` processes on this machine."""

    address: str | None = None  # unused (no cluster); accepted so every back end is built alike

    def run(self, job: Job, tasks: list[ShardTask], workers: int, on_result: ResultFn,
            on_sample: SampleFn) -> str | None:
        """One single-process pool per worker slot ("lane"), each fed the next shard when it is free;
        a lane's pool is replaced after ``job.max_shards_per_worker`` shards. (Python 3.11's own
        ``max_tasks_per_child`` hangs with the spawn context, so the recycling is done here.)"""
        ctx = mp.get_context("spawn")  # fork would copy a half-initialised bpy/OpenMP state
        q = ctx.Queue()
        stop = threading.Event()
        drainer = threading.Thread(target=_drain, args=(q, on_sample, stop), daemon=True)
        drainer.start()
        todo = deque(tasks)

        def new_pool() -> ProcessPoolExecutor:
            return ProcessPoolExecutor(max_workers=1, mp_context=ctx, initializer=_init_local,
                                       initargs=(q, os.getpid()))

        lanes = [_Lane(new_pool()) for _ in range(max(1, min(workers, len(tasks))))]
        pending: dict[Any, tuple[ShardTask, _Lane]] = {}

        def feed(lane: _Lane) -> None:
            if todo:
                task = todo.popleft()
                pending[lane.pool.submit(_local_shard, job, task)] = (task, lane)

        aborted = None
        try:
            for lane in lanes:
                feed(lane)
            while pending and aborted is None:
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for fut in done:
                    task, lane = pending.pop(fut)
                    try:
                        on_result(fut.result())
                    except BrokenProcessPool:
                        aborted = (f"a worker process died (killed or out of memory) while shard {task.index} "
                                   f"was running; {len(pending) + len(todo) + 1} shards unfinished")
                        break
                    lane.shards += 1
                    if job.max_shards_per_worker and lane.shards >= job.max_shards_per_worker and todo:
                        lane.pool.shutdown(wait=True)  # its only process is idle: let it exit
                        lane.pool, lane.shards = new_pool(), 0
                    feed(lane)
        finally:
            for lane in lanes:
                lane.pool.shutdown(wait=aborted is None, cancel_futures=True)
            stop.set()
            drainer.join(timeout=5)
            q.close()
            if aborted is None:
                q.join_thread()
            else:
                q.cancel_join_thread()  # a killed worker may have left the pipe mid-message
        return aborted


@dataclass
class _Lane:
    """One worker slot of the local back end: its pool (one process) and the shards that process ran."""

    pool: ProcessPoolExecutor
    shards: int = 0


# ---------------------------------------------------------------- Ray

def _ray_shard(job: Job, task: ShardTask, progress: Any) -> ShardResult:
    global _PROGRESS
    _PROGRESS = progress
    return run_shard(producer_for(job), job.out, task, job.storage_options, on_sample=_report)


@dataclass(frozen=True)
class RayBackend:
    """Shards as Ray tasks on a local Ray instance (``workers`` CPUs) or the cluster at ``address``.

    Ray reuses worker processes between tasks of one function, so ``producer_for`` keeps the
    Blender scene alive across shards. The output must be reachable by every node: a shared
    path or an fsspec URL (s3://...).
    """

    address: str | None = None

    def run(self, job: Job, tasks: list[ShardTask], workers: int, on_result: ResultFn,
            on_sample: SampleFn) -> str | None:
        import ray  # optional dependency: only this back end needs it
        from ray.util.queue import Queue

        started = False
        if not ray.is_initialized():
            if self.address:
                ray.init(address=self.address, include_dashboard=False, log_to_driver=False)
            else:
                ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
            started = True
        try:
            progress = Queue()
            # max_calls: Ray replaces the worker process after that many shards (0 = never)
            remote = ray.remote(num_cpus=1, max_retries=1, max_calls=job.max_shards_per_worker)(_ray_shard)
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


# name -> constructor taking the cluster address (None = local); `--backend` choices are its keys
BACKENDS: dict[str, Callable[[str | None], Backend]] = {"local": LocalBackend, "ray": RayBackend}
