"""Test configuration: float64 everywhere unless a test is about float32."""

import os

import jax
import numpy as np
import pytest
from hypothesis import settings

jax.config.update("jax_enable_x64", True)

# CI runs are reproducible: the same examples every run (locally hypothesis explores freely).
settings.register_profile("ci", derandomize=True, deadline=None, print_blob=True)
settings.register_profile("dev", deadline=None, print_blob=True)
settings.load_profile("ci" if os.environ.get("CI") else "dev")
os.environ.setdefault("LIDARJAX_NO_CACHE", "1")  # in-process CLI tests leave ~/.cache alone


@pytest.fixture(scope="session")
def site_records():
    """48 records of the synthetic platform site (`tests/sites.py`): free-stream directions
    and speeds drawn uniformly (seed 3), simulated once per test process."""
    from . import sites

    rng = np.random.default_rng(3)
    return sites.records(rng.uniform(0.0, 360.0, 48), rng.uniform(3.0, 15.0, 48))


# Seconds the slowest test files took in a full run (`--junitxml`, summed per file; 2 workers
# on a 2-core machine): relative weights. With `--dist loadfile --no-loadscope-reorder`
# (pyproject.toml) xdist hands the files out in collection order: these go first, longest
# first, so that the two workers finish together instead of one of them starting a long
# file at the end. A file not listed keeps its place after them; a stale number only costs
# balance, never a test.
SLOW_FILES = {
    "tests/core/test_inverse.py": 111,
    "tests/core/test_batch.py": 95,
    "tests/core/test_probe.py": 93,
    "tests/core/test_fused_arithmetic.py": 69,
    "tests/core/test_sensitivity.py": 61,
    "tests/cli/test_demo.py": 61,
    "tests/core/test_stability_forward.py": 61,
    "tests/core/test_forward.py": 58,
    "tests/scenes/test_turbulence.py": 57,
    "tests/core/test_series.py": 53,
    "tests/cli/test_scanning_cli.py": 51,
    "tests/cli/test_calibrate.py": 50,
    "tests/core/test_unsteady.py": 47,
    "tests/scenes/test_farm.py": 45,
    "tests/core/test_scanning_nodes.py": 45,
    "tests/core/test_scanning.py": 45,
    "tests/workflows/test_seed_tables.py": 44,
    "tests/io/test_openfoam_exact.py": 41,
    "tests/core/test_mount.py": 41,
    "tests/core/test_joint.py": 40,
    "tests/workflows/test_farm_study.py": 39,
    "tests/cli/test_farm.py": 38,
    "tests/io/test_cellpoint_field.py": 38,
    "tests/core/test_response.py": 38,
    "tests/core/test_spectral.py": 37,
    "tests/core/test_six_beam.py": 37,
    "tests/cli/test_series.py": 35,
    "tests/core/test_field.py": 28,
    "tests/scenes/test_analytic.py": 28,
    "tests/cli/test_cli_malformed.py": 26,
    "tests/core/test_calibrate.py": 25,
    "tests/workflows/test_monitor_points.py": 24,
    "tests/cli/test_cli.py": 24,
    "tests/core/test_scanning_reconstruct.py": 23,
    "tests/core/test_precision.py": 22,
    "tests/workflows/test_sensitivity_report.py": 20,
}


def pytest_collection_modifyitems(session, config, items):
    rank = {f: k for k, f in enumerate(sorted(SLOW_FILES, key=SLOW_FILES.get, reverse=True))}
    items.sort(key=lambda item: rank.get(item.nodeid.split("::")[0], len(rank)))  # stable
