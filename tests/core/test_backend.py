"""`lidarjax._backend`: batch sizes per backend and free memory (issue 18). The CPU keeps its
tuned sizes; an accelerator with room takes the whole problem at once, bucketed; a fake
device stands in for a GPU."""

import jax
import numpy as np
import pytest

from lidarjax import _backend
from lidarjax._backend import (
    CPU_BATCH,
    bucket,
    default_batch,
    floor_bucket,
    free_memory,
    is_accelerator,
    memory_budget,
    positive_size,
)
from lidarjax.inverse import DEFAULT_BATCH_SIZE, _batching


class FakeDevice:
    """A device with `memory_stats` as an accelerator reports them (or None / an error)."""

    def __init__(self, platform="gpu", limit=80e9, in_use=1e9, stats=True):
        self.platform = platform
        self._stats = stats
        self._limit, self._in_use = limit, in_use

    def memory_stats(self):
        if self._stats == "raise":
            raise RuntimeError("no statistics on this backend")
        if not self._stats:
            return None
        return {"bytes_limit": int(self._limit), "bytes_in_use": int(self._in_use),
                "peak_bytes_in_use": int(self._in_use)}


def test_buckets_are_few_and_waste_at_most_a_third():
    assert [bucket(n) for n in range(14)] == [0, 1, 2, 3, 4, 6, 6, 8, 8, 12, 12, 12, 12, 16]
    assert [floor_bucket(n) for n in range(1, 14)] == [1, 2, 3, 4, 4, 6, 6, 8, 8, 8, 8, 12, 12]
    n = np.arange(1, 100_000)
    b = np.array([bucket(int(k)) for k in n])
    assert np.all(b >= n) and np.all(b <= 1.5 * n)
    assert len(set(b.tolist())) == 34  # two per octave: 99,999 lengths, 34 shapes
    f = np.array([floor_bucket(int(k)) for k in n])
    assert np.all(f <= n) and np.all(f * 1.5 >= n)
    assert set(f.tolist()) <= set(b.tolist())


@pytest.fixture
def on_cpu(monkeypatch):
    """The CPU's sizes, whatever backend runs the suite (a GPU run checks them too)."""
    cpu = jax.devices("cpu")
    monkeypatch.setattr(jax, "local_devices", lambda: cpu)


def test_cpu_keeps_its_tuned_sizes(on_cpu):
    assert not is_accelerator()
    assert DEFAULT_BATCH_SIZE == CPU_BATCH["invert"] == 512
    assert default_batch("invert", 7_000, 10**6) == 512
    assert default_batch("invert", 7_000, 10) == 512  # the caller pads or trims
    assert default_batch("statistics", 1e5, 10**4) == 64
    assert default_batch("monte_carlo", 1e4, 5_000) == 256
    # no fixed CPU size: the whole problem (bucketed) when it fits
    assert default_batch("rotations", 1e6, 5) == 6
    # memory still bounds the CPU sizes: an item as large as the budget goes one at a time
    budget = memory_budget()
    assert budget > 0
    assert default_batch("invert", budget, 10**6) == 1
    assert default_batch("statistics", budget / 10, 10**6) == 8  # floor_bucket(10)
    free = free_memory()
    assert free is None or free > 0
    with pytest.raises(ValueError, match="unknown kind 'inverse'"):
        default_batch("inverse", 1, 1)


def test_accelerator_with_room_takes_the_whole_problem():
    gpu = FakeDevice(limit=80e9, in_use=2e9)
    assert is_accelerator(gpu) and free_memory(gpu) == int(78e9)
    assert memory_budget(gpu) == int(78e9 * _backend.ACCELERATOR_FRACTION)
    # 131,072 inversions of ~7 kB: 0.9 GB, well inside a quarter of 78 GB
    assert default_batch("invert", 7_000, 131_072, device=gpu) == 131_072
    assert default_batch("invert", 7_000, 100_000, device=gpu) == 131_072  # bucketed
    assert default_batch("statistics", 1e5, 50, device=gpu) == 64
    # too large for memory: the largest bucket that fits
    small = FakeDevice(limit=1e9, in_use=0.2e9)  # budget 0.2 GB
    fit = int(0.8e9 * _backend.ACCELERATOR_FRACTION) // 7_000
    got = default_batch("invert", 7_000, 10**6, device=small)
    assert got == floor_bucket(fit) and got <= fit < 1.5 * got
    # unknown memory: the fixed fallback budget
    for unknown in (FakeDevice(stats=False), FakeDevice(stats="raise")):
        assert free_memory(unknown) is None
        assert memory_budget(unknown) == _backend.FALLBACK_BUDGET
    assert default_batch("invert", 1_000, 10**7, device=FakeDevice(stats=None)) == floor_bucket(
        _backend.FALLBACK_BUDGET // 1_000)


def test_a_real_accelerator_takes_the_whole_problem():
    """On the backend running the suite: the CPU's tuned batch, or on a GPU with room every
    record in one batch."""
    n, h, b, dirs = 10_000, 4, 5, 24
    per_batch, n_pad = _batching(None, n, h, b, dirs, 8, "invert")
    if is_accelerator():
        assert jax.default_backend() != "cpu" and (per_batch, n_pad) == (None, bucket(n))
    else:
        assert jax.default_backend() == "cpu" and per_batch == 512 // h


def test_invert_chooses_its_batches_from_the_device(monkeypatch, on_cpu):
    """`invert`'s default batch: 512 problems on a CPU; on a (fake) GPU with room, every
    record in one batch, padded to a bucket."""
    n, h, b, dirs = 10_000, 4, 5, 24
    per_batch, n_pad = _batching(None, n, h, b, dirs, 8, "invert")
    assert per_batch == 512 // h and n_pad == bucket(-(-n // per_batch)) * per_batch
    assert _batching("all", n, h, b, dirs, 8, "invert") == (None, bucket(n))
    assert _batching(96, 64, h, b, dirs, 8, "invert") == (24, 72)  # 3 batches of 24 records
    assert _batching(None, 5, h, b, dirs, 8, "invert") == (None, 6)  # one small batch
    monkeypatch.setattr(jax, "local_devices", lambda: [FakeDevice()])
    assert is_accelerator()
    assert _batching(None, n, h, b, dirs, 8, "invert") == (None, bucket(n))
    monkeypatch.setattr(jax, "local_devices", lambda: [FakeDevice(limit=2e8, in_use=0)])
    per_batch, n_pad = _batching(None, n, h, b, dirs, 8, "invert")
    assert per_batch is not None and per_batch * h * 8 * (32 * b + 8 * dirs + 256) <= 0.5e8


def test_sizes_are_checked():
    assert positive_size(3, "f", "n") == 3 and positive_size(4.0, "f", "n") == 4
    assert positive_size(np.int64(7), "f", "n") == 7
    for bad in (0, -2, 2.5, "8", True, None, np.nan):
        with pytest.raises(ValueError, match=r"f: `n` must be a positive int or None"):
            positive_size(bad, "f", "n")
    for bad in (0, "some", 1.5):
        with pytest.raises(ValueError, match=r"invert: `batch_size` must be a positive int "
                                             r"\(problems per batch\), 'all' or None"):
            _batching(bad, 10, 4, 5, 24, 8, "invert")
