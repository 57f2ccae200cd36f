"""Shared tolerances and checks for the lidarjax tests."""

from __future__ import annotations

import os
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

RTOL64 = 1e-12
ATOL64 = 1e-12

#: The test tree, its committed data and the repository root.
TESTS = Path(__file__).resolve().parent
DATA = TESTS / "data"
REPO = TESTS.parent


def windcube_folder() -> Path | None:
    """The real Windcube files (`../shared/data/windcube/`; `LIDARJAX_WINDCUBE_DATA` wins), or
    None when this checkout has none beside it (main checkout or a worktree one level down)."""
    env = os.environ.get("LIDARJAX_WINDCUBE_DATA")
    if env:
        return Path(env)
    for base in (REPO.parent, REPO.parent.parent):
        folder = base / "shared" / "data" / "windcube"
        if folder.is_dir():
            return folder
    return None


def windcube_file(name: str) -> Path:
    """One real Windcube file, or skip the test naming it when the data are absent."""
    folder = windcube_folder()
    if folder is None or not (folder / name).is_file():
        pytest.skip(f"real Windcube data not available ({name})")
    return folder / name


#: Real scanning-lidar files the project commits (obtained from a package registry with
#: their licence): tests/data/scanning/.
SCANNING = DATA / "scanning"


def scanning_file(name: str) -> Path:
    """A real scanning-lidar file: committed in `SCANNING`, else (cuts of public repositories
    that this project may not commit, see tests/data/scanning/README.md) from
    `LIDARJAX_SCANNING_DATA` or ``../shared/data/scanning/``; skip the test naming it when
    absent."""
    if (SCANNING / name).is_file():
        return SCANNING / name
    places = [Path(os.environ["LIDARJAX_SCANNING_DATA"])] if os.environ.get("LIDARJAX_SCANNING_DATA") else []
    places += [base / "shared" / "data" / "scanning" for base in (REPO.parent, REPO.parent.parent)]
    for folder in places:
        if (folder / name).is_file():
            return folder / name
    pytest.skip(f"real scanning-lidar file not available ({name}: tests/data/scanning/README.md)")


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


def assert_grad_matches_fd(f, x, eps=1e-6, rtol=1e-6, atol=1e-8, jit=False):
    """Reverse-mode, forward-mode and centred finite differences agree, and are finite. With
    `jit`, each derivative is one compiled function (taken eagerly, the jit calls inside `f`
    compile once more per transformation: a reverse-mode forward pass and its transpose); not
    for an `f` that needs concrete values before its own jit (`simulate_scan`)."""
    x = jnp.asarray(x, dtype=jnp.float64)
    wrap = jax.jit if jit else (lambda g: g)
    g_rev = np.asarray(wrap(jax.grad(f))(x))
    g_fwd = np.asarray(wrap(jax.jacfwd(f))(x))
    g_fd = central_difference(f, x, eps)
    assert np.all(np.isfinite(g_rev)), g_rev
    np.testing.assert_allclose(g_rev, g_fwd, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(g_rev, g_fd, rtol=rtol, atol=atol)
