"""Test configuration: float64 everywhere unless a test is about float32."""

import os

import jax
from hypothesis import settings

jax.config.update("jax_enable_x64", True)

# CI runs are reproducible: the same examples every run (locally hypothesis explores freely).
settings.register_profile("ci", derandomize=True, deadline=None, print_blob=True)
settings.register_profile("dev", deadline=None, print_blob=True)
settings.load_profile("ci" if os.environ.get("CI") else "dev")
os.environ.setdefault("LIDARJAX_NO_CACHE", "1")  # in-process CLI tests leave ~/.cache alone
