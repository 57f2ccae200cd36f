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
