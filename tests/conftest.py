"""Test configuration: float64 everywhere unless a test is about float32."""

import jax

jax.config.update("jax_enable_x64", True)
