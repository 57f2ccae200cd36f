"""Shared tolerances and checks for the lidarjax tests."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

RTOL64 = 1e-12
ATOL64 = 1e-12


def tree_allclose(a, b, rtol=RTOL64, atol=ATOL64) -> bool:
    """True when two pytrees have the same structure and all leaves are close (NaN == NaN)."""
    la, ta = jax.tree_util.tree_flatten(a)
    lb, tb = jax.tree_util.tree_flatten(b)
    if ta != tb:
        return False
    return all(
        np.allclose(np.asarray(x), np.asarray(y), rtol=rtol, atol=atol, equal_nan=True)
        for x, y in zip(la, lb, strict=True)
    )


def central_difference(f, x, eps=1e-6):
    """Centred finite-difference gradient of scalar `f` at array `x` (float64)."""
    x = np.asarray(x, dtype=np.float64)
    g = np.zeros_like(x)
    for idx in np.ndindex(x.shape):
        dx = np.zeros_like(x)
        dx[idx] = eps
        g[idx] = (float(f(jnp.asarray(x + dx))) - float(f(jnp.asarray(x - dx)))) / (2 * eps)
    return g


def assert_grad_matches_fd(f, x, eps=1e-6, rtol=1e-6, atol=1e-8):
    """Reverse-mode, forward-mode and centred finite differences agree, and are finite."""
    x = jnp.asarray(x, dtype=jnp.float64)
    g_rev = np.asarray(jax.grad(f)(x))
    g_fwd = np.asarray(jax.jacfwd(f)(x))
    g_fd = central_difference(f, x, eps)
    assert np.all(np.isfinite(g_rev)), g_rev
    np.testing.assert_allclose(g_rev, g_fwd, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(g_rev, g_fd, rtol=rtol, atol=atol)
