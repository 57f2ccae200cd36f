"""What every benchmark script shares (run as ``python3 benchmarks/<name>.py``, so this folder
is on ``sys.path``): one timer and one record of the machine it ran on."""

from __future__ import annotations

import os
import platform
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


def machine() -> dict:
    """The one machine record every benchmark writes under ``"machine"``: JAX backend and
    device, CPU count (and the CPUs this process may use), OS, Python and library versions."""
    import jax

    dev = jax.devices()[0]
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        usable = os.cpu_count()
    return {
        "backend": jax.default_backend(),
        "device": getattr(dev, "device_kind", str(dev)),
        "devices": jax.device_count(),
        "cpus": os.cpu_count(),
        "cpus_usable": usable,
        "processor": platform.processor() or platform.machine(),
        "platform": platform.platform(),
        "python": platform.python_version(),
        "jax": jax.__version__,
        "numpy": np.__version__,
    }


def machine_line(m: dict) -> str:
    """One line for reports: ``cpu (2 CPUs), Linux-..., Python 3.11.7, JAX 0.10.2``."""
    where = (f"{m['device']} ({m['backend']})" if m["backend"] != "cpu"
             else f"CPU ({m['cpus_usable']} of {m['cpus']} cores usable)")
    return f"{where}, {m['platform']}, Python {m['python']}, JAX {m['jax']}, numpy {m['numpy']}"
