"""Test configuration: float64 everywhere unless a test is about float32; on a CPU, XLA's
quick-to-compile code generation (below)."""

import gc
import os
import subprocess
import sys

# Compilation is two thirds of this suite's time on a CPU: ~4000 small programs, each compiled
# once. XLA compiles them faster with LLVM at -O0 and, where the jaxlib still has it (0.10;
# gone by 0.12), the legacy LLVM emitter instead of the MLIR fusion emitters: the simulate
# program compiles in 0.6 s instead of 1.7 s (jax 0.10) or 1.2 s instead of 1.5 s (jax 0.12),
# and the whole suite on 2 cores took 410 s instead of 830 s (jax 0.10); LLVM without its
# expensive passes (what `jax_disable_most_optimizations` also sets) takes 13 % off the CPU time
# of tests/core/test_forward.py (41.5 s -> 37.1 s, jax 0.10). The code computes
# the same IEEE operations; only roundings of fused a*b+c and the order of sums may differ,
# which the library must survive anyway (GPUs and fast-math compilers differ more:
# tests/core/test_fused_arithmetic.py runs those for real).
# Set when XLA_FLAGS is unset, the default backend is the CPU and this jaxlib knows the flags
# (an unknown XLA flag aborts the process: each set is probed in a subprocess first), before
# any backend starts, so every xdist worker inherits it. LIDARJAX_TEST_XLA=default keeps
# XLA's defaults (CI's Python 3.13 leg runs so: both code generators are tested).
# Each worker also compiles and runs on one thread: two workers already fill the 2 cores, and
# Eigen's intra-op pool and LLVM's split code generation only add thread overhead there (CPU
# time of test_forward.py + io/test_snapshots.py 72.3/77.2/74.3 s -> 69.0/73.3/71.6 s in
# three alternating pairs, jax 0.10).
_ONE_THREAD = " --xla_cpu_multi_thread_eigen=false --xla_cpu_parallel_codegen_split_count=1"
_QUICK = (
    "--xla_cpu_use_fusion_emitters=false --xla_backend_optimization_level=0"
    " --xla_llvm_disable_expensive_passes=true",
    "--xla_backend_optimization_level=0 --xla_llvm_disable_expensive_passes=true",
    "--xla_backend_optimization_level=0",
)
FAST_CPU_XLA_FLAGS = tuple(q + t for q in _QUICK for t in (_ONE_THREAD, ""))


def _fast_cpu_compilation() -> None:
    if os.environ.get("LIDARJAX_TEST_XLA", "fast") != "fast" or os.environ.get("XLA_FLAGS"):
        return
    for flags in FAST_CPU_XLA_FLAGS:
        try:
            probe = subprocess.run(
                [sys.executable, "-c", "import jax; print(jax.default_backend())"],
                env=dict(os.environ, XLA_FLAGS=flags), capture_output=True, text=True, timeout=300)
        except (OSError, subprocess.TimeoutExpired):
            return
        if probe.returncode == 0:
            if probe.stdout.strip().splitlines()[-1:] == ["cpu"]:
                os.environ["XLA_FLAGS"] = flags
            return


_fast_cpu_compilation()

import jax  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from hypothesis import settings  # noqa: E402

jax.config.update("jax_enable_x64", True)
# No Python tracebacks in the compiled programs' debug locations: building them for every
# operation is a tenth of the tracing, lowering and compiling of tests/core/test_forward.py
# and test_scanning.py (CPU 49.5 s -> 45.4 s, 47.8 -> 41.3 in a second pair); results and
# Python tracebacks are unchanged.
jax.config.update("jax_include_full_tracebacks_in_locations", False)
jax.config.update("jax_traceback_in_locations_limit", 0)
# Tracing and lowering allocate millions of short-lived Python objects beside a large heap of
# live ones (jaxprs, compiled programs, fixtures), so CPython's default thresholds (700, 10, 10)
# walk the whole heap every few seconds: 5 % of tests/core/test_inverse.py + test_joint.py's
# CPU time (4.8 s of 59 s; gen-2 passes of 0.2 s each). Collecting young objects after 20,000
# allocations and old ones rarely takes that to 1.0 s (59.3 -> 53.8 s CPU; test_forward.py +
# test_scanning.py 53.7 -> 51.6 s). Cycles are still collected; tests that measure memory
# call gc.collect() themselves.
gc.set_threshold(20_000, 20, 20)

# CI runs are reproducible: the same examples every run (locally hypothesis explores freely).
settings.register_profile("ci", derandomize=True, deadline=None, print_blob=True)
settings.register_profile("dev", deadline=None, print_blob=True)
settings.load_profile("ci" if os.environ.get("CI") else "dev")
os.environ.setdefault("LIDARJAX_NO_CACHE", "1")  # in-process CLI tests leave ~/.cache alone


def pytest_report_header(config):
    return f"XLA_FLAGS: {os.environ.get('XLA_FLAGS', '(unset)')}"


@pytest.fixture(scope="session")
def site_records():
    """48 records of the synthetic platform site (`tests/sites.py`): free-stream directions
    and speeds drawn uniformly (seed 3), simulated once per test process."""
    from . import sites

    rng = np.random.default_rng(3)
    return sites.records(rng.uniform(0.0, 360.0, 48), rng.uniform(3.0, 15.0, 48))


# Seconds the slowest test files took in a full run (`--junitxml`, summed per file; 2 workers
# on an idle 2-core machine, jax 0.10 with the quick CPU compilation above; files of 12 s and
# more): relative weights. With `--dist loadfile --no-loadscope-reorder` (pyproject.toml)
# xdist hands the files out in collection order: these go first, longest first, so that the
# two workers finish together instead of one of them starting a long file at the end. A file
# not listed keeps its place after them; a stale number only costs balance, never a test.
SLOW_FILES = {
    "tests/test_docs_examples.py": 98,
    "tests/core/test_design_placement.py": 58,
    "tests/core/test_batch.py": 48,
    "tests/core/test_inverse.py": 44,
    "tests/core/test_fused_arithmetic.py": 42,
    "tests/scenes/test_farm.py": 40,
    "tests/io/test_openfoam_table.py": 38,
    "tests/core/test_sensitivity.py": 37,
    "tests/io/test_snapshots.py": 37,
    "tests/core/test_series.py": 36,
    "tests/core/test_stability_forward.py": 33,
    "tests/cli/test_demo.py": 33,
    "tests/scenes/test_turbulence.py": 33,
    "tests/core/test_calibrate_exact.py": 32,
    "tests/core/test_forward.py": 31,
    "tests/cli/test_series.py": 29,
    "tests/core/test_probe.py": 27,
    "tests/io/test_openfoam_exact.py": 26,
    "tests/io/test_cellpoint_field.py": 26,
    "tests/core/test_mount.py": 26,
    "tests/core/test_joint.py": 26,
    "tests/cli/test_scanning_cli.py": 24,
    "tests/cli/test_cli_malformed.py": 24,
    "tests/cli/test_farm.py": 23,
    "tests/control/test_mann.py": 22,
    "tests/core/test_scanning_nodes.py": 22,
    "tests/core/test_scanning.py": 22,
    "tests/cli/test_calibrate.py": 22,
    "tests/core/test_unsteady.py": 20,
    "tests/core/test_spectral.py": 20,
    "tests/core/test_six_beam.py": 19,
    "tests/cli/test_cli.py": 18,
    "tests/test_docs.py": 17,
    "tests/io/test_monitor_points_rotations.py": 17,
    "tests/core/test_design_scanning.py": 17,
    "tests/workflows/test_farm_study.py": 17,
    "tests/workflows/test_seed_tables.py": 17,
    "tests/core/test_precision.py": 15,
    "tests/cli/test_design_cli.py": 14,
    "tests/control/test_series_rews.py": 14,
    "tests/control/test_spectra.py": 14,
    "tests/workflows/test_sensitivity_report.py": 14,
    "tests/core/test_calibrate_displacement.py": 13,
    "tests/core/test_graded_nodes.py": 13,
}


@pytest.hookimpl(trylast=True)
def pytest_sessionfinish(session):
    """Collect once, then freeze what survives: pytest's unraisable-exception check collects
    five times more at exit (`gc_collect_harder`), and each full pass over a worker's heap of
    compiled programs and caches (~1M objects) took 0.9 s. Garbage is still collected, and
    any `__del__` error it raises still reported, by this first pass."""
    gc.collect()
    gc.freeze()


def pytest_collection_modifyitems(session, config, items):
    rank = {f: k for k, f in enumerate(sorted(SLOW_FILES, key=SLOW_FILES.get, reverse=True))}
    items.sort(key=lambda item: rank.get(item.nodeid.split("::")[0], len(rank)))  # stable
