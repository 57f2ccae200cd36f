"""Timing shared by the benchmark scripts (run as ``python3 benchmarks/<name>.py``, so this
folder is on ``sys.path``)."""

from __future__ import annotations

import time

import numpy as np


def median_time(fn, repeats: int, *, warm: bool = True) -> float:
    """Median wall time (s) of `repeats` calls of `fn`, after one untimed call when `warm`
    (compilation and caches out of the figure). `fn` must block until its result is ready."""
    if warm:
        fn()
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return float(np.median(times))
