"""Batch and chunk sizes chosen per backend and its free memory (a shared helper layer).

lidarjax vmaps many small independent problems (inversions, records, Monte Carlo samples,
CFD runs). How many to put in one compiled batch depends on the machine: on a CPU, small
batches (hundreds) are fastest, because a vmapped batch runs as many solver steps as its
slowest member and the cores are few; on a GPU or TPU the whole problem in one batch is
fastest (an H100 solves 131,072 inversions at once 22 times faster than in batches of 512)
as long as it fits in memory. Every public argument that sets such a size defaults to None,
meaning `default_batch` here; an explicit number always wins.

Sizes are also bucketed (`bucket`: 1, 2, 3, 4, 6, 8, 12, 16, 24, ...; at most 1.5 times the
need) so that a campaign of files of different lengths compiles a handful of times, not once
per length.

Nothing here imports the rest of lidarjax.
"""

from __future__ import annotations

import os

import jax
import numpy as np

__all__: list[str] = []

#: Items per batch on a CPU, tuned on a 2-core CPU (benchmarks/inverse.py, benchmarks/series.py):
#: inversions (record-heights) per vmapped batch, records per `simulate_statistics` chunk,
#: Monte Carlo samples per `lax.map` batch; None = as many as fit the memory budget (CFD runs
#: simulated together by `simulate_settings`).
CPU_BATCH: dict[str, int | None] = {
    "invert": 512,
    "statistics": 64,
    "monte_carlo": 256,
    "rotations": None,
}
#: Fraction of the free device memory one batch may use on an accelerator (the estimates of
#: bytes per item are rough; XLA needs room for its temporaries).
ACCELERATOR_FRACTION = 0.25
#: Fraction of the available host memory one batch may use on a CPU.
CPU_FRACTION = 0.125
#: Budget when the free memory cannot be read (bytes).
FALLBACK_BUDGET = 1 << 30


def _device(device=None):
    return jax.local_devices()[0] if device is None else device


def is_accelerator(device=None) -> bool:
    """True unless `device` (default: JAX's first local device) is a CPU."""
    return _device(device).platform != "cpu"


def free_memory(device=None) -> int | None:
    """Free memory of `device` in bytes (default: JAX's first local device), or None when
    unknown: ``bytes_limit - bytes_in_use`` from ``device.memory_stats()`` on an
    accelerator; the available physical memory (``os.sysconf``) on a CPU."""
    device = _device(device)
    if device.platform == "cpu":
        try:
            return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
        except (AttributeError, ValueError, OSError):
            return None
    try:
        stats = device.memory_stats()
    except Exception:  # noqa: BLE001 - backends without statistics raise various errors
        return None
    if not stats or "bytes_limit" not in stats:
        return None
    return max(int(stats["bytes_limit"]) - int(stats.get("bytes_in_use", 0)), 0)


def memory_budget(device=None) -> int:
    """Bytes one batch may use: a fraction of `free_memory` (`ACCELERATOR_FRACTION` on an
    accelerator, `CPU_FRACTION` on a CPU), `FALLBACK_BUDGET` when it is unknown."""
    free = free_memory(device)
    if free is None:
        return FALLBACK_BUDGET
    return int(free * (ACCELERATOR_FRACTION if is_accelerator(device) else CPU_FRACTION))


def bucket(n: int) -> int:
    """The smallest of 1, 2, 3, 4, 6, 8, 12, 16, 24, ... (``2**k`` and ``3 * 2**k``) that is
    at least `n` (0 for ``n <= 0``): padded sizes that waste at most a third of a batch and
    take few distinct values."""
    n = int(n)
    if n <= 2:
        return max(n, 0)
    p = 1 << (n - 1).bit_length()  # next power of two >= n
    return 3 * p // 4 if 3 * p // 4 >= n else p


def floor_bucket(n: int) -> int:
    """The largest of 1, 2, 3, 4, 6, 8, 12, ... that is at most `n` (at least 1)."""
    n = max(int(n), 1)
    p = 1 << (n.bit_length() - 1)  # largest power of two <= n
    return 3 * p // 2 if p >= 2 and 3 * p // 2 <= n else p


def default_batch(kind: str, bytes_per_item: float, n_items: int, *, device=None) -> int:
    """Items per batch for this backend.

    - `kind`: a key of `CPU_BATCH` (``"invert"``, ``"statistics"``, ``"monte_carlo"``,
      ``"rotations"``).
    - `bytes_per_item`: a (generous) estimate of the memory one item needs while it runs.
    - `n_items`: how many items there are in all.

    On an accelerator: ``bucket(n_items)`` (the whole problem in one batch) when that fits in
    `memory_budget`, else the largest `floor_bucket` that does. On a CPU: `CPU_BATCH[kind]`
    (None: ``bucket(n_items)``), lowered to what fits in `memory_budget` if needed. At least 1.
    """
    if kind not in CPU_BATCH:
        raise ValueError(f"default_batch: unknown kind {kind!r}; choose from {sorted(CPU_BATCH)}.")
    whole = max(bucket(n_items), 1)
    fit = max(int(memory_budget(device) // max(float(bytes_per_item), 1.0)), 1)
    if is_accelerator(device):
        return whole if whole <= fit else floor_bucket(fit)
    cpu = CPU_BATCH[kind]
    want = whole if cpu is None else cpu
    return want if want <= fit else floor_bucket(fit)


def positive_size(value, fname: str, name: str, alternatives: str = "or None (chosen per "
                  "backend)") -> int:
    """`value` as a positive int (an int or an integral float), else a `ValueError` naming
    `fname`'s argument `name` and what else it accepts (`alternatives`)."""
    number = isinstance(value, int | float | np.integer | np.floating) and not isinstance(
        value, bool)
    if not number or not float(value).is_integer() or value < 1:
        raise ValueError(f"{fname}: `{name}` must be a positive int {alternatives}, got "
                         f"{value!r}.")
    return int(value)
