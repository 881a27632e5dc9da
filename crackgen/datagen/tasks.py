"""One shard as a unit of work: what to make (``ShardTask``), what comes back (``ShardResult``)
and the worker-side loop that makes it (``run_shard``).

This module sits below both the driver (``generate``) and the back ends (``backends``):
both need these types and neither needs the other's internals, so there is no import
loop to hide. Timings never go into a sample's JSON (they would make two runs of one
recipe differ byte for byte); ``run_shard`` sums them per shard into ``ShardResult``
and the driver records them in the manifest, which is not part of any shard's sha256.
"""
from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Protocol

from crackgen.shards import ShardWriter, sample_key

RETRIES = 1  # a failing sample is tried 1 + RETRIES times before it is recorded as failed
ProgressFn = Callable[[int], None]


@dataclass(frozen=True)
class ShardTask:
    """One shard to make: its index and the global sample indices it holds."""

    index: int
    samples: tuple[int, ...]


@dataclass
class ShardResult:
    """What a worker sends back for one shard (plain data: crosses process/Ray boundaries)."""

    index: int
    info: dict[str, Any] | None  # ShardInfo.to_dict() when the shard file was written
    failures: list[dict[str, str]] = field(default_factory=list)  # {key, error} per failed sample
    timings: dict[str, float] = field(default_factory=dict)  # per-stage seconds summed over the shard
    error: str | None = None  # shard-level failure (nothing written)
    worker_pid: int = 0  # the process that ran it (how many processes a run used, with worker recycling)


class ProducedSample(Protocol):
    """What ``run_shard`` needs of one produced sample (``crackgen.datagen.pipeline.Sample``)."""

    members: Mapping[str, Any]  # member name (``rgb.png``...) -> array / dict of arrays
    meta: Mapping[str, Any]  # goes into KEY.json: must not hold anything run-dependent
    timings: Mapping[str, float]  # per-stage seconds: kept out of the shard


class SampleSource(Protocol):
    """Makes sample ``index`` of one recipe (``SampleProducer``; a replay stub in tests)."""

    def make(self, index: int) -> ProducedSample: ...


def one_line(exc: BaseException) -> str:
    """``Type: first line of message`` — what the manifest and the summary show."""
    msg = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {msg[0] if msg else ''}".rstrip(": ")


def sample_key_for(shard: int, sample: int) -> str:
    """Key ``SSSSSS-IIIII``: shard index and the *global* sample index (= the spec index),
    so a key names its spec directly and stays unique across the dataset."""
    return sample_key(shard, sample)


def add_timings(totals: dict[str, float], timings: Mapping[str, float]) -> None:
    """Add per-stage seconds into ``totals`` (in place)."""
    for stage, seconds in timings.items():
        totals[stage] = totals.get(stage, 0.0) + float(seconds)


def run_shard(producer: SampleSource, out: str, task: ShardTask, storage_options: Mapping[str, Any] | None = None,
              on_sample: ProgressFn | None = None, retries: int = RETRIES) -> ShardResult:
    """Make and write every sample of ``task`` with ``producer``.

    A sample that raises is retried ``retries`` times, then recorded in ``failures`` and
    skipped; the shard still completes with the others. Only a failure of the shard file
    itself (disk, upload) makes the whole shard fail; then nothing final is written.
    """
    failures: list[dict[str, str]] = []
    totals: dict[str, float] = {}
    try:
        with ShardWriter(out, task.index, storage_options=storage_options) as writer:
            for i in task.samples:
                key = sample_key_for(task.index, i)
                err: BaseException | None = None
                for _attempt in range(1 + retries):
                    try:
                        sample = producer.make(i)
                        t0 = time.perf_counter()
                        writer.add(key, {**sample.members, "json": dict(sample.meta)})
                        add_timings(totals, {**sample.timings, "encode_write": time.perf_counter() - t0})
                        err = None
                        break
                    except Exception as exc:  # noqa: BLE001 - the failure policy is the point
                        err = exc
                if err is not None:
                    failures.append({"key": key, "error": one_line(err)})
                if on_sample is not None:
                    on_sample(1)
        info = writer.info.to_dict()
    except Exception as exc:  # noqa: BLE001
        return ShardResult(task.index, None, failures, totals, error=one_line(exc), worker_pid=os.getpid())
    return ShardResult(task.index, info, failures, totals, worker_pid=os.getpid())
