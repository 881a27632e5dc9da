"""One IterableDataset over synthetic shards and/or a real folder, for DDP + workers.

Why this shape: shards are streamed (WebDataset style, no random access) and
the real set is mixed in repeated N times (thesis 5.4). Each epoch has a
deterministic *plan* computed from (seed, epoch) alone:

* shards are permuted and dealt to the S = world_size x num_workers slots
  (``order[slot::S]``); with fewer shards than slots, every slot reads all
  shards and keeps every S-th sample instead;
* real items (each real sample repeated ``real_repeat`` times) are permuted and
  dealt ``[slot::S]``;
* each slot interleaves its synthetic and real items in a seeded random order
  and shuffles synthetic samples with a seeded buffer;
* in training every slot yields the *same* number of samples, a multiple of the
  batch size (the minimum over slots; the few extra samples are dropped for this
  epoch and differ between epochs). Equal counts keep DDP ranks in lock-step and
  make the DataLoader's round-robin over workers predictable, so a resumed run
  can skip exactly the batches it already trained on (``skip_batches``).

Augmentation draws come from a generator seeded by (seed, epoch, sample id),
so batches are identical whatever the worker count of a resumed run... as long
as it uses the same world size and worker count (the plan depends on S).

Bad samples: without ``skip_bad`` the first unreadable file stops the run with
its name; with it, the file is logged and the slot takes its next item.
"""
from __future__ import annotations

import logging
from typing import Any, Iterator

import numpy as np
import torch.distributed as dist
from torch.utils.data import IterableDataset, get_worker_info

from trainer.core.errors import TrainerInputError
from trainer.seg.appearance import SiteAdaptation
from trainer.seg.augment import SampleConfig, sample_generator, sample_to_tensors
from trainer.seg.sources import RealFolder, ShardSource

log = logging.getLogger(__name__)


def dist_info() -> tuple[int, int]:
    """(rank, world_size); (0, 1) without an initialised process group."""
    if dist.is_available() and dist.is_initialized():
        return dist.get_rank(), dist.get_world_size()
    return 0, 1


def mix_repeat(n_real: int, n_synthetic: int) -> int:
    """Largest N with N * n_real < n_synthetic (thesis 5.4); at least 1."""
    if n_real <= 0 or n_synthetic <= 0:
        return 1
    return max(1, (n_synthetic - 1) // n_real)


class SegStream(IterableDataset):
    """Samples from shards and/or a real folder as tensors ({"image", "mask", "key"})."""

    def __init__(
        self,
        cfg: SampleConfig,
        shards: ShardSource | None = None,
        real: RealFolder | None = None,
        *,
        real_repeat: int = 1,
        batch_size: int = 1,
        train: bool = True,
        seed: int = 0,
        skip_bad: bool = False,
        shuffle_buffer: int = 64,
        adapt: SiteAdaptation | None = None,
    ) -> None:
        super().__init__()
        if shards is None and real is None:
            raise TrainerInputError("no data: give synthetic shards (--data) and/or a real folder (--real)")
        self.cfg, self.shards, self.real = cfg, shards, real
        self.real_repeat = max(1, int(real_repeat)) if real is not None else 0
        self.batch_size, self.train, self.seed = batch_size, train, seed
        self.skip_bad, self.shuffle_buffer = skip_bad, shuffle_buffer
        self.adapt = adapt if train else None  # site adaptation of synthetic RGB (training only)
        self.epoch, self.skip_batches = 0, 0
        self.num_workers = 0  # set by the training script to the DataLoader's value

    def set_epoch(self, epoch: int, skip_batches: int = 0) -> None:
        self.epoch, self.skip_batches = epoch, skip_batches

    def __len__(self) -> int:
        """Samples per epoch over all slots (train: after quota truncation)."""
        n_real = len(self.real) * self.real_repeat if self.real is not None else 0
        total = (len(self.shards) if self.shards is not None else 0) + n_real
        if not self.train:
            return total
        return self.quota(self._n_slots()) * self._n_slots()

    # ---------------------------------------------------------------- planning
    def _n_slots(self) -> int:
        return dist_info()[1] * max(1, self.num_workers)

    def _plan(self, n_slots: int) -> list[dict[str, list]]:
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, self.epoch, 1]))
        plans: list[dict[str, list]] = [{"syn": [], "real": []} for _ in range(n_slots)]
        if self.shards is not None:
            n_sh = len(self.shards.shards)
            order = rng.permutation(n_sh) if self.train else np.arange(n_sh)
            if n_sh >= n_slots:
                for s in range(n_slots):
                    plans[s]["syn"] = [(int(i), k) for i in order[s::n_slots] for k in self.shards.shard_keys[i]]
            else:
                flat = [(int(i), k) for i in order for k in self.shards.shard_keys[i]]
                for s in range(n_slots):
                    plans[s]["syn"] = flat[s::n_slots]
        if self.real is not None:
            items = [(rep, i) for rep in range(self.real_repeat) for i in range(len(self.real))]
            perm = rng.permutation(len(items)) if self.train else np.arange(len(items))
            items = [items[j] for j in perm]
            for s in range(n_slots):
                plans[s]["real"] = items[s::n_slots]
        return plans

    def quota(self, n_slots: int) -> int:
        """Samples each slot yields in training (equal for all slots, multiple of the batch)."""
        plans = self._plan(n_slots)
        q = min(len(p["syn"]) + len(p["real"]) for p in plans)
        q -= q % self.batch_size
        if q == 0:
            raise TrainerInputError(
                f"too few training samples for batch size {self.batch_size} x {n_slots} loader slot(s) "
                f"(smallest slot has {min(len(p['syn']) + len(p['real']) for p in plans)}); lower --batch-size or --workers")
        return q

    def steps_per_epoch(self, num_workers: int) -> int:
        """Batches per rank per epoch (training)."""
        self.num_workers = num_workers
        return self.quota(self._n_slots()) // self.batch_size * max(1, num_workers)

    # ---------------------------------------------------------------- iteration
    def _syn_iter(self, syn: list[tuple[int, str]], slot: int) -> Iterator[tuple[tuple[int, ...], dict | None]]:
        """Decoded synthetic samples of this slot, buffer-shuffled with a seeded generator."""
        assert self.shards is not None
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, self.epoch, 3, slot]))
        by_shard: dict[int, list[str]] = {}
        for i, k in syn:
            by_shard.setdefault(i, []).append(k)
        buf: list[tuple[tuple[int, ...], dict | None]] = []

        def produce() -> Iterator[tuple[tuple[int, ...], dict | None]]:
            for i, keys in by_shard.items():
                wanted = set(keys)
                try:
                    for j, s in enumerate(self.shards.iter_shard(i, wanted)):
                        yield (0, i, j), s
                except TrainerInputError as exc:
                    if not self.skip_bad:
                        raise
                    log.warning("skipping rest of shard: %s", exc)
                    yield (0, i, -1), None

        for item in produce():
            if not self.train or self.shuffle_buffer <= 1:
                yield item
                continue
            if len(buf) < self.shuffle_buffer:
                buf.append(item)
                continue
            j = int(rng.integers(len(buf)))
            buf[j], item = item, buf[j]
            yield item
        while buf:
            yield buf.pop(int(rng.integers(len(buf)))) if self.train else buf.pop(0)

    def _load_real(self, idx: int) -> dict[str, Any] | None:
        assert self.real is not None
        key = self.real.keys[idx]
        try:
            return self.real.load(key)
        except TrainerInputError as exc:
            if not self.skip_bad:
                raise
            log.warning("skipping bad sample: %s", exc)
            return None

    def __iter__(self) -> Iterator[dict[str, Any]]:
        rank, world = dist_info()
        wi = get_worker_info()
        n_workers, worker = (wi.num_workers, wi.id) if wi is not None else (1, 0)
        b = self.skip_batches if self.train else 0
        # The DataLoader always starts its round-robin at worker 0, so after skipping b
        # batches worker w plays the role of worker (w + b) % W and skips (w + b) // W batches.
        role, skip_own = (worker + b) % n_workers, (worker + b) // n_workers
        n_slots, slot = world * n_workers, rank * n_workers + role
        plan = self._plan(n_slots)[slot]
        if self.train:
            quota = self.quota(n_slots)
            skip = skip_own * self.batch_size
            order = np.array([0] * len(plan["syn"]) + [1] * len(plan["real"]), dtype=np.int8)
            np.random.default_rng(np.random.SeedSequence([self.seed, self.epoch, 2, slot])).shuffle(order)
        else:
            quota, skip = len(plan["syn"]) + len(plan["real"]), 0
            order = np.array([0] * len(plan["syn"]) + [1] * len(plan["real"]), dtype=np.int8)
        syn_it = self._syn_iter(plan["syn"], slot) if plan["syn"] else iter(())
        real_items = iter(plan["real"])
        emitted = 0
        for src in order:
            if emitted >= quota:
                break
            if src == 0:
                ids, sample = next(syn_it)
            else:
                rep, idx = next(real_items)
                ids = (1, rep, idx)
                if emitted < skip:  # already trained on: no need to decode
                    emitted += 1
                    continue
                sample = self._load_real(idx)
            if sample is None:
                continue
            emitted += 1
            if emitted <= skip:
                continue
            if src == 0 and self.adapt is not None:
                rng = np.random.default_rng(np.random.SeedSequence([self.seed, self.epoch, 4, *ids]))
                sample = {**sample, "rgb": self.adapt.apply(sample["rgb"], rng)}
            g = sample_generator(self.seed, self.epoch, *ids) if self.train else None
            out = sample_to_tensors(sample, self.cfg, g)
            out["key"] = sample["key"]
            yield out
        if self.train and emitted < quota:
            raise TrainerInputError(f"loader slot {slot}: only {emitted} of {quota} samples were readable (--skip-bad dropped too many)")
