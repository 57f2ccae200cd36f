"""Working precision helpers: dtypes and accurate differences of large coordinates.

Coordinates in UTM metres (~1e5-1e7) carry only ~0.03-1 m of resolution in float32. lidarjax
keeps every absolute coordinate as a pair ``(hi, lo)``: ``hi`` is the value rounded to the
working dtype and ``lo`` the rounding residual, computed in float64 on the host when the
input is concrete. Differences of two such coordinates are then accurate to float32 rounding
of the *difference*, not of the absolute value (the classic double-float trick). With x64
enabled and float64 inputs, ``lo`` is zero and nothing changes.

**Safe under an optimising compiler.** The trick needs ``hi_a - hi_b`` to be exact and the
residuals to be added to *that* difference, and a residual computed in-graph to be what it
says. Compilers take liberties with all three, so nothing here relies on arithmetic being
evaluated as written:

- XLA on GPU replaces a chain of float conversions ``A -> B -> C`` by ``A -> C``
  (``SimplifyFPConversions``, on with the default ``xla_allow_excess_precision``): the
  residual ``x - float64(float32(x))`` of a float64 coordinate split in-graph came out 0 (a
  float64 mount in a float32 field lost 0.25 m at a northing of 6e6 m; 1.4e-2 m/s in the
  forward model). `split` rounds such values with `split_bits` in their own dtype instead
  and converts each part once.
- A compiler allowed to reassociate (``--xla_cpu_enable_fast_math``, LLVM's ``reassoc``) may
  evaluate ``(hi_a - hi_b) + (lo_a - lo_b)`` as ``(hi_a + lo_a) - (hi_b + lo_b)``, which
  rounds the residuals away. `difference` subtracts the high parts through **integers**
  (`exact_sub`): both are scaled by the same power of two (built from its bits) to exact
  integers below ``2**30``, subtracted as int32 and converted back; a float -> int -> float
  conversion is not arithmetic any compiler rewrites, so the residuals cannot be folded into
  the high parts. Only the final ``hi + lo`` is a float sum, and every term in it is of the
  size of the difference, so any order of evaluation rounds at the difference's resolution.
- XLA on GPU (and on CPU) contracts ``a * b + c`` into one FMA rounding. `split_bits` splits
  a number exactly into two half-precision parts by power-of-two quantisation (``rint`` of
  the number scaled by a power of two), so products of the parts are exact and an FMA
  computes the same numbers; Dekker's splitting ``hi = c x - (c x - x)`` is no split at all
  when contracted (`lidarjax.scenes.turbulence` builds its exact ``U t`` from `split_bits`).

(Matrix products are the fourth liberty: on Ampere and later GPUs a float32 ``dot`` at
DEFAULT precision runs in TensorFloat-32, 10-bit mantissas. Code that needs float32 there
asks for ``Precision.HIGHEST``; see `lidarjax.forward`.)
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

#: Matrix products of float32 in full float32 precision: a GPU's default (TensorFloat-32,
#: 10-bit mantissas) would cost lidarjax's float32 results up to 3e-4 m/s. Passed as
#: ``precision=HIGHEST`` to every ``einsum``/``dot``/``matmul`` of the model.
HIGHEST = jax.lax.Precision.HIGHEST


def is_concrete(*values) -> bool:
    """True when none of the leaves is a tracer (validation can read the numbers)."""
    leaves = jax.tree_util.tree_leaves(values)
    return not any(isinstance(leaf, jax.core.Tracer) for leaf in leaves)


def is_host(value) -> bool:
    """True for a concrete value that is not itself a JAX array (numpy, Python numbers, lists
    of them): `split` and `Mount` read it in float64 on the host, where a JAX array or a
    tracer stays on the device."""
    return is_concrete(value) and not isinstance(value, jax.Array)


def default_float():
    """The default floating dtype of this JAX configuration (float64 only with x64 on)."""
    return jax.dtypes.canonicalize_dtype(np.float64)


def host_array(value):
    """A host (numpy) array or scalar, or a pytree of them, as JAX arrays on the default
    device, as ``jnp.asarray`` gives them (same dtypes, canonicalised without x64), without
    compiling and in one transfer: since jax 0.10 ``jnp.asarray`` of a numpy array runs an
    identity program (``lax.stage``) compiled once per shape and dtype; ``jax.device_put``
    only copies, a whole pytree in one call."""
    return jax.device_put(jax.tree_util.tree_map(np.asarray, value))


def safe_sqrt(square):
    """``sqrt(square)`` for ``square >= 0``, 0 where it is not positive, with a zero (not
    infinite or NaN) gradient there: the safe-mask form of a norm or RMS at the origin."""
    pos = square > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, square, 1)), 0)


def as_float(value, dtype=None):
    """A JAX float array of `dtype` (default: the configured default float dtype)."""
    value = jnp.asarray(value)
    if dtype is None:
        dtype = value.dtype if jnp.issubdtype(value.dtype, jnp.floating) else default_float()
    return value.astype(dtype)


def split(value, dtype=None):
    """Split `value` into ``(hi, lo)`` in `dtype` with ``hi + lo`` ~ value to float64 accuracy.

    Concrete inputs are read in float64 on the host; traced inputs give ``lo = 0`` (unless
    they are wider than `dtype`, in which case the residual is computed in-graph, see
    `_split_wide`). Derivatives: those of ``value`` go to ``hi``, none to ``lo``.
    """
    if dtype is None:
        dtype = default_float()
    if is_host(value):
        return host_array(split_host(value, dtype))
    value = jnp.asarray(value)
    if not jnp.issubdtype(value.dtype, jnp.floating):
        value = value.astype(dtype)
    if jnp.dtype(value.dtype).itemsize > jnp.dtype(dtype).itemsize:
        return _split_wide(value, jnp.dtype(dtype))
    hi = value.astype(dtype)
    return hi, jnp.zeros_like(hi)


def split_host(value, dtype):
    """`split` of host numbers, on the host: numpy ``(hi, lo)`` in `dtype`, read in float64."""
    v64 = np.asarray(value, dtype=np.float64)
    hi = np.asarray(v64, dtype=dtype)
    return hi, np.asarray(v64 - hi.astype(np.float64), dtype=dtype)


@functools.partial(jax.custom_jvp, nondiff_argnums=(1,))
def _split_wide(value, dtype):
    """`split` of a traced `value` wider than `dtype`, in-graph.

    Not ``lo = value - hi.astype(value.dtype)``: XLA on GPU (its ``SimplifyFPConversions``
    pass, on while ``xla_allow_excess_precision`` is, the default) replaces the round trip
    ``float64 -> float32 -> float64`` by the value itself, so that residual came out 0 and a
    float64 mount lost 0.25 m at a northing of 6e6 m in a float32 field. ``hi`` is rounded
    to the precision of `dtype` in the wide dtype instead (`split_bits`: ``rint`` at the
    right power of two, the same round-to-nearest-even as the conversion), so both parts
    come from arithmetic that no compiler simplifies, and each is converted once."""
    hi, lo = split_bits(value, int(jnp.finfo(dtype).nmant) + 1)
    return hi.astype(dtype), lo.astype(dtype)


@_split_wide.defjvp
def _split_wide_jvp(dtype, primals, tangents):
    (value,), (dv,) = primals, tangents
    hi, lo = _split_wide(value, dtype)
    return (hi, lo), (dv.astype(dtype), jnp.zeros_like(lo))


def difference(a_hi, a_lo, b_hi, b_lo, dtype):
    """``(a_hi + a_lo) - (b_hi + b_lo)`` in `dtype`, accurate when a and b are close.

    Each operand is first split again into `dtype` (they may be wider, e.g. float64 mounts
    with a float32 field), then the high parts are subtracted exactly (`exact_sub`, through
    integers, so that no fusing or reassociating compiler can fold the residuals into them
    first) and the residuals added. Derivatives: 1 with respect to `a_hi` and `a_lo`, -1 with
    respect to `b_hi` and `b_lo`.
    """
    a1, a2 = split(a_hi, dtype)
    b1, b2 = split(b_hi, dtype)
    return exact_sub(a1, b1) + ((a2 - b2) + (jnp.asarray(a_lo).astype(dtype)
                                             - jnp.asarray(b_lo).astype(dtype)))


def _int_dtype(dtype):
    """The signed integer dtype as wide as the floating `dtype`."""
    return {2: jnp.int16, 4: jnp.int32, 8: jnp.int64}[jnp.dtype(dtype).itemsize]


def _scale_limit(dtype) -> int:
    """Largest ``k`` with both ``2**k`` and ``2**-k`` normal numbers of `dtype`."""
    fi = jnp.finfo(dtype)
    return min(int(fi.maxexp) - 1, -int(fi.minexp))


def pow2(n, dtype):
    """``2.0 ** n`` in the floating `dtype` for integer `n` (clipped to the normal range),
    assembled from its exponent bits: exact, and no arithmetic a compiler could fuse."""
    fi = jnp.finfo(dtype)
    itype = _int_dtype(dtype)
    n = jnp.clip(jnp.asarray(n), int(fi.minexp), int(fi.maxexp) - 1).astype(itype)
    bits = (n + (int(fi.maxexp) - 1)) << int(fi.nmant)
    return jax.lax.bitcast_convert_type(bits.astype(itype), jnp.dtype(dtype))


def split_bits(x, bits: int):
    """``x = hi + lo`` exactly, ``hi`` with at most `bits` significant bits and ``lo`` with at
    most ``p - bits - 1`` (``p`` the precision of ``x``'s dtype, 24 for float32).

    ``hi = rint(x * 2**k) * 2**-k`` with ``k`` from ``x``'s binary exponent (`jnp.frexp`, bit
    operations): the scalings by powers of two are exact, ``rint`` is not an arithmetic
    operation, and ``lo = x - hi`` is exact whatever a compiler fuses (an FMA of the exact
    product gives the same number). With ``bits = p // 2`` all four products of two split
    numbers are exact in the dtype (Dekker's condition) without Dekker's ``c * x`` splitting,
    which FMA contraction breaks. Values below ``2**(minexp + bits)`` give ``hi = 0``."""
    x = jnp.asarray(x)
    _, e = jnp.frexp(x)
    lim = _scale_limit(x.dtype)
    k = jnp.clip(bits - e, -lim, lim)
    hi = jnp.rint(x * pow2(k, x.dtype)) * pow2(-k, x.dtype)
    return hi, x - hi


@jax.custom_jvp
def exact_sub(a, b):
    """``a - b`` rounded once, robust to FMA contraction and reassociation (see the module
    docs): for float32 the operands are scaled by a common power of two to integers below
    ``2**30`` and subtracted as int32. Exact when ``a`` and ``b`` are within a factor of two
    of each other (Sterbenz), correctly rounded (to ``2**-29`` relative) otherwise. NaN and
    infinities give ``a - b``. float64 subtracts directly (it rounds UTM coordinates to
    1e-9 m: no residual is worth protecting), narrower floats in float32 (exactly)."""
    a, b = jnp.asarray(a), jnp.asarray(b)
    dtype = jnp.result_type(a, b)
    a, b = jnp.broadcast_arrays(a.astype(dtype), b.astype(dtype))
    if dtype != jnp.float32:
        if jnp.dtype(dtype).itemsize < 4:
            return (a.astype(jnp.float32) - b.astype(jnp.float32)).astype(dtype)
        return a - b
    m = jnp.maximum(jnp.abs(a), jnp.abs(b))
    ok = jnp.isfinite(m)
    _, e = jnp.frexp(jnp.where(ok, m, 0))
    lim = _scale_limit(dtype)
    s = jnp.clip(30 - e, -lim, lim)  # |a| * 2**s < 2**30: the int32 difference cannot overflow
    up = pow2(s, dtype)
    ia = jnp.rint(jnp.where(ok, a, 0) * up).astype(jnp.int32)
    ib = jnp.rint(jnp.where(ok, b, 0) * up).astype(jnp.int32)
    d = (ia - ib).astype(dtype) * pow2(-s, dtype)
    return jnp.where(ok, d, a - b)


@exact_sub.defjvp
def _exact_sub_jvp(primals, tangents):
    a, b = primals
    da, db = tangents
    out = exact_sub(a, b)
    return out, jnp.broadcast_to(da - db, out.shape).astype(out.dtype)
