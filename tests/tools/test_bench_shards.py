"""The shard I/O benchmark writes and reads real shards, and its synthetic sample obeys the contract."""
from __future__ import annotations

import numpy as np

from crackgen.shards import MEMBERS, ShardWriter, iter_samples, member_for_file, sample_key
from crackgen.tools.bench_shards import benchmark_sample_io, synthetic_sample


def test_synthetic_sample_uses_registered_members_and_passes_the_writer(tmp_path):
    smp = synthetic_sample(np.random.default_rng(0), 32, 8)
    assert all(member_for_file(n) is not None for n in smp)
    with ShardWriter(tmp_path, 0) as w:
        w.add(sample_key(0, 0), smp)
    (got,) = iter_samples(tmp_path / "shard-000000.tar")
    np.testing.assert_array_equal(got["rgb"], smp["rgb.png"])
    assert set(got) - {"__key__", "__shard__"} == {member_for_file(n).yielded_as for n in smp}
    assert set(np.unique(got["mask"])) <= {0, 255} and MEMBERS["mask"].in_rgb_view


def test_benchmark_reports_sizes_and_times(tmp_path):
    r = benchmark_sample_io(size_px=32, samples=2, out_dir=str(tmp_path))
    assert r["bytes_per_sample"] > 32 * 32 * 3 * 0.1
    assert all(r[k] > 0 for k in ("write_ms_per_sample", "read_all_ms_per_sample"))
    assert list(tmp_path.iterdir()) == []  # its temp shard is gone
