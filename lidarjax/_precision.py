"""Working precision helpers: dtypes and accurate differences of large coordinates.

Coordinates in UTM metres (~1e5-1e7) carry only ~0.03-1 m of resolution in float32. lidarjax
keeps every absolute coordinate as a pair ``(hi, lo)``: ``hi`` is the value rounded to the
working dtype and ``lo`` the rounding residual, computed in float64 on the host when the
input is concrete. Differences of two such coordinates are then accurate to float32 rounding
of the *difference*, not of the absolute value (the classic double-float trick). With x64
enabled and float64 inputs, ``lo`` is zero and nothing changes.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np


def is_concrete(*values) -> bool:
    """True when none of the leaves is a tracer (validation can read the numbers)."""
    leaves = jax.tree_util.tree_leaves(values)
    return not any(isinstance(leaf, jax.core.Tracer) for leaf in leaves)


def default_float():
    """The default floating dtype of this JAX configuration (float64 only with x64 on)."""
    return jnp.asarray(0.0).dtype


def as_float(value, dtype=None):
    """A JAX float array of `dtype` (default: the configured default float dtype)."""
    value = jnp.asarray(value)
    if dtype is None:
        dtype = value.dtype if jnp.issubdtype(value.dtype, jnp.floating) else default_float()
    return value.astype(dtype)


def split(value, dtype=None):
    """Split `value` into ``(hi, lo)`` in `dtype` with ``hi + lo`` ~ value to float64 accuracy.

    Concrete inputs are read in float64 on the host; traced inputs give ``lo = 0`` (unless
    they are wider than `dtype`, in which case the residual is computed in-graph).
    """
    if dtype is None:
        dtype = default_float()
    if is_concrete(value) and not isinstance(value, jax.Array):
        v64 = np.asarray(value, dtype=np.float64)
        hi = np.asarray(v64, dtype=dtype)
        lo = np.asarray(v64 - hi.astype(np.float64), dtype=dtype)
        return jnp.asarray(hi), jnp.asarray(lo)
    value = jnp.asarray(value)
    if not jnp.issubdtype(value.dtype, jnp.floating):
        value = value.astype(dtype)
    hi = value.astype(dtype)
    lo = (value - hi.astype(value.dtype)).astype(dtype)
    return hi, lo


def difference(a_hi, a_lo, b_hi, b_lo, dtype):
    """``(a_hi + a_lo) - (b_hi + b_lo)`` in `dtype`, accurate when a and b are close.

    Each operand is first split again into `dtype` (they may be wider, e.g. float64 mounts
    with a float32 field), then the high parts are subtracted exactly (Sterbenz) and the
    residuals added.
    """
    a1, a2 = split(a_hi, dtype)
    b1, b2 = split(b_hi, dtype)
    return (a1 - b1) + ((a2 - b2) + (a_lo.astype(dtype) - b_lo.astype(dtype)))
