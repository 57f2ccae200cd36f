"""float32 accuracy under what XLA on a GPU does to arithmetic, reproduced on the CPU.

Three things differ from the CPU:

- a float32 ``dot`` at DEFAULT precision runs in TensorFloat-32 (10-bit mantissas) on
  Ampere and later;
- ``SimplifyFPConversions`` (on with the default ``xla_allow_excess_precision``) replaces a
  chain of float conversions ``A -> B -> C`` by ``A -> C``, so ``float64 -> float32 ->
  float64`` is a no-op;
- products feeding sums are contracted into FMAs (one rounding).

`fusing` evaluates a function's jaxpr operation by operation with all three (TF32 operands
for float32 dots without an explicit precision, conversion chains collapsed, every float32
``add``/``sub`` of a ``mul`` computed as an exact FMA). On the code before this file it gives
the H100's numbers: 1.36e-2 m/s in tests/core/test_precision.py and 1.7e-3 m/s in
test_field.py (the in-graph residual ``x - float64(float32(x))`` of a float64 mount in a
float32 field came out 0) and 3e-4 in the turbulence time sampler (its TF32 line
projections); FMA contraction alone was harmless there, and is kept in as a guard. A
compiler that may also *reassociate* sums (``--xla_cpu_enable_fast_math``) is run for real,
in a subprocess: it folds the low parts of coordinates into their high parts unless the high
parts are subtracted where it cannot see (`lidarjax._precision.exact_sub`).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.extend import core as jcore

import lidarjax as lj
from lidarjax._precision import difference, exact_sub, split, split_bits
from lidarjax.angles import heading
from lidarjax.scenes.turbulence import advected_distance

from ..helpers import REPO
from ..scenes.test_turbulence import _sampler_values, long_advection_pair, sample_at

F32 = np.dtype(np.float32)


# -- the emulated fusing compiler --------------------------------------------------------------
@jax.jit
def fma32(x, y, z):
    """``x * y + z`` for float32 arrays with ONE rounding (an exact FMA): the product is exact
    in float64, the sum is rounded to odd in float64 (nearest plus a sticky last bit, from the
    exact two-sum error), and rounding that to float32 is then the correctly rounded result
    (Boldo and Melquiond 2008: 53 >= 2 * 24 + 2). Every float64 step is exact or rounded once
    whether or not a compiler contracts it (the product of two float32 is exact); the sticky
    bit is one step of the bit pattern (the sum is not 0 where the error is not). Operands and
    result pass optimization barriers: XLA's CPU loop fusion recomputes a fused operand at each
    use, and the sum here has five (the emulated frozen-turbulence sampler compiled in 6.3 s
    without them, 1.1 s with); ``nextafter`` for the step made the emulated forward model
    compile in 5.5 s instead of 2.9 s (1.6 s not emulated)."""
    x, y, z = jax.lax.optimization_barrier(
        jnp.broadcast_arrays(*(jnp.asarray(v, jnp.float64) for v in (x, y, z))))
    p = x * y
    s = p + z
    bb = s - p
    err = (p - (s - bb)) + (z - bb)
    bits = jax.lax.bitcast_convert_type(s, jnp.int64)
    away = jax.lax.bitcast_convert_type(bits + jnp.where((err > 0) == (s > 0), 1, -1), jnp.float64)
    odd = jnp.where((err != 0) & (bits & 1 == 0) & jnp.isfinite(s), away, s)
    return jax.lax.optimization_barrier(odd.astype(jnp.float32))


@jax.jit
def tf32(x):
    """float32 values rounded to TensorFloat-32 (10 explicit mantissa bits, to nearest)."""
    x = jnp.asarray(x, jnp.float32)
    u = jax.lax.bitcast_convert_type(x, jnp.uint32)
    r = jax.lax.bitcast_convert_type((u + jnp.uint32(0x1000)) & jnp.uint32(0xFFFFE000), jnp.float32)
    return jnp.where(jnp.isfinite(x), r, x)


_CALLS = {"pjit", "jit", "closed_call", "core_call", "remat", "checkpoint", "custom_jvp_call",
          "custom_vjp_call", "custom_vjp_call_jaxpr", "custom_lin"}
_LAYOUT = {"broadcast_in_dim", "reshape", "squeeze", "expand_dims", "transpose"}


def _is_f32(aval) -> bool:
    return getattr(aval, "dtype", None) == F32


def _is_float(aval) -> bool:
    dtype = getattr(aval, "dtype", None)
    return dtype is not None and jnp.issubdtype(dtype, jnp.floating)


def _default_precision(params) -> bool:
    prec = params.get("precision")
    precs = prec if isinstance(prec, tuple) else (prec,)
    return all(p in (None, jax.lax.Precision.DEFAULT) for p in precs)


def _subjaxpr(params):
    for key in ("jaxpr", "call_jaxpr", "fun_jaxpr"):
        sub = params.get(key)
        if isinstance(sub, jcore.ClosedJaxpr):
            return sub
    return None


def _eval(jaxpr, consts, args, fma, tf32_dots, excess):
    env = {}
    product = {}  # var -> (x, y): its value is the float32 product x * y, not yet summed
    converted = {}  # var -> the value a chain of float conversions started from

    def read(v):
        return v.val if isinstance(v, jcore.Literal) else env[v]

    for v, val in zip(jaxpr.constvars, consts, strict=True):
        env[v] = val
    for v, val in zip(jaxpr.invars, args, strict=True):
        env[v] = val
    for eqn in jaxpr.eqns:
        name = eqn.primitive.name
        invals = [read(v) for v in eqn.invars]
        sub = _subjaxpr(eqn.params) if name in _CALLS else None
        out = None
        if sub is not None:
            out = _eval(sub.jaxpr, sub.consts, invals, fma, tf32_dots, excess)
        elif (name == "dot_general" and tf32_dots and _default_precision(eqn.params)
              and all(_is_f32(v.aval) for v in eqn.invars)):
            params = dict(eqn.params, precision=jax.lax.Precision.HIGHEST)
            out = [eqn.primitive.bind(*(tf32(x) for x in invals), **params)]
        elif name in ("add", "sub") and fma and _is_f32(eqn.outvars[0].aval):
            a, b = eqn.invars
            pa = None if isinstance(a, jcore.Literal) else product.get(a)
            pb = None if isinstance(b, jcore.Literal) else product.get(b)
            sign = 1.0 if name == "add" else -1.0
            if pa is not None:  # x y + b or x y - b
                out = [fma32(pa[0], pa[1], sign * jnp.asarray(invals[1], F32))]
            elif pb is not None:  # a + x y or a - x y
                out = [fma32(sign * jnp.asarray(pb[0], F32), pb[1], invals[0])]
        elif name == "convert_element_type" and excess and _is_float(eqn.outvars[0].aval):
            a = eqn.invars[0]
            if not isinstance(a, jcore.Literal) and a in converted:  # A -> B -> C is A -> C
                source = converted[a]
                out = [eqn.primitive.bind(source, **eqn.params)]
                converted[eqn.outvars[0]] = source
            elif _is_float(a.aval):
                converted[eqn.outvars[0]] = invals[0]
        if out is None:
            out = eqn.primitive.bind(*invals, **eqn.params)
            out = out if eqn.primitive.multiple_results else [out]
        for v, val in zip(eqn.outvars, out, strict=True):
            env[v] = val
        if fma and name == "mul" and _is_f32(eqn.outvars[0].aval):
            product[eqn.outvars[0]] = tuple(jnp.asarray(x, F32) for x in invals)
        elif fma and name in _LAYOUT and not isinstance(eqn.invars[0], jcore.Literal) \
                and eqn.invars[0] in product:
            product[eqn.outvars[0]] = tuple(eqn.primitive.bind(x, *invals[1:], **eqn.params)
                                            for x in product[eqn.invars[0]])
    return [read(v) for v in jaxpr.outvars]


def fusing(fn, *, fma=True, tf32_dots=True, excess=True, one_program=True):
    """`fn` evaluated as XLA on a GPU runs it: products feeding sums contracted into exact
    FMAs (`fma`), float32 dots at DEFAULT precision in TF32 (`tf32_dots`) and chains of float
    conversions ``A -> B -> C`` replaced by ``A -> C`` (`excess`: ``SimplifyFPConversions``,
    on with the default ``xla_allow_excess_precision``; it makes ``float64 -> float32 ->
    float64`` a no-op). Nested jit and custom-derivative calls are evaluated inside (loops and
    conditionals are run as they are). The emulation is traced into one compiled program
    (`one_program`; the same operations with the FMAs, TF32 roundings and collapsed conversions
    spelt out), or dispatched operation by operation, each compiled on its own (hundreds of
    small programs; for the time sampler's lines, whose emulated program takes XLA's CPU
    compiler 6 s, longer than dispatching its operations)."""

    def run(*args):
        closed, shape = jax.make_jaxpr(fn, return_shape=True)(*args)
        flat = jax.tree_util.tree_leaves(args)
        emulate = lambda consts, flat: _eval(closed.jaxpr, consts, flat, fma, tf32_dots,  # noqa: E731
                                             excess)
        out = (jax.jit(emulate) if one_program else emulate)(closed.consts, flat)
        return jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(shape), out)

    return run


def test_the_emulator_fuses_and_rounds_like_a_gpu():
    rng = np.random.default_rng(0)
    a, b, c = (rng.normal(size=1000).astype(np.float32) for _ in range(3))
    exact = np.float32(a.astype(np.float64) * b + c)  # double rounding aside, the FMA
    fused = np.asarray(fusing(lambda a, b, c: a * b + c)(a, b, c))
    assert np.mean(fused == exact) > 0.999
    assert np.any(fused != a * b + c)  # numpy rounds the product on its own
    # a Dekker split is no longer a split once the compiler fuses it
    x = jnp.float32(np.pi)
    dekker = lambda x: x - ((4097.0 * x) - ((4097.0 * x) - x))  # noqa: E731
    assert float(dekker(x)) != 0.0 and float(fusing(dekker)(x)) == 0.0
    # TF32 dots: 1e-4-ish relative errors, none with an explicit HIGHEST precision
    m = rng.normal(size=(3, 3)).astype(np.float32)
    full = np.asarray(m, np.float64) @ np.asarray(m, np.float64)
    assert np.max(np.abs(np.asarray(fusing(lambda m: m @ m)(m)) - full)) > 1e-4
    hi = fusing(lambda m: jnp.matmul(m, m, precision=jax.lax.Precision.HIGHEST))(m)
    np.testing.assert_allclose(hi, full, rtol=1e-6, atol=1e-6)
    # excess precision: float64 -> float32 -> float64 is a no-op
    v = jnp.float64(6_123_456.789)
    roundtrip = lambda v: v - v.astype(jnp.float32).astype(jnp.float64)  # noqa: E731
    assert float(roundtrip(v)) != 0.0 and float(fusing(roundtrip)(v)) == 0.0
    # the FMA keeps the low bits of the product
    x, y, z = np.float32(1 + 2**-12), np.float32(1 + 2**-12), np.float32(-(1 + 2**-11))
    assert fma32(x, y, z) == np.float32(2**-24)


# -- the error-free building blocks --------------------------------------------------------------
def test_split_bits_is_exact_and_short_under_fusion():
    rng = np.random.default_rng(1)
    x = np.concatenate([rng.uniform(-1e6, 1e6, 2000), 10.0 ** rng.uniform(-30, 30, 2000),
                        [0.0, 1.0, -1.0, 4095.5, 4096.0, 86400.37]]).astype(np.float32)
    for run in (jax.jit(lambda v: split_bits(v, 12)), fusing(lambda v: split_bits(v, 12))):
        hi, lo = (np.asarray(a) for a in run(x))
        np.testing.assert_array_equal(hi.astype(np.float64) + lo, x.astype(np.float64))
        for part, bits in ((hi, 12), (lo, 11)):
            m, _ = np.frexp(part.astype(np.float64))
            assert np.all(m * 2.0**bits == np.round(m * 2.0**bits))  # at most `bits` bits


def test_split_of_float64_in_graph_keeps_its_residual_under_fusion():
    """A float64 coordinate split into float32 inside jit (a float64 mount with a float32
    field): the residual does not come from a ``float64 -> float32 -> float64`` round trip,
    which XLA on GPU simplifies away."""
    v = jnp.asarray(6_123_456.789 + np.linspace(-300.0, 300.0, 101))
    for run in (jax.jit(lambda v: split(v, jnp.float32)), fusing(lambda v: split(v, jnp.float32))):
        hi, lo = run(v)
        assert hi.dtype == lo.dtype == jnp.float32
        np.testing.assert_array_equal(hi, np.asarray(v).astype(np.float32))
        np.testing.assert_allclose(np.asarray(hi, np.float64) + np.asarray(lo, np.float64), v,
                                   rtol=0, atol=1e-8)
    g = jax.grad(lambda v: jnp.sum(split(v, jnp.float32)[0]))(v)  # derivatives go to hi
    np.testing.assert_array_equal(g, 1.0)


def test_exact_sub_and_difference_at_utm_under_fusion():
    rng = np.random.default_rng(2)
    a64 = 6_123_456.789 + rng.uniform(-500, 500, 200)
    b64 = 6_123_456.789 + rng.uniform(-500, 500, 200)
    want = a64 - b64
    (ah, al), (bh, bl) = split(a64, jnp.float32), split(b64, jnp.float32)
    diff32 = lambda *parts: difference(*parts, jnp.float32)  # noqa: E731
    for run in (jax.jit(diff32), fusing(diff32)):
        got = np.asarray(run(ah, al, bh, bl), np.float64)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-4)  # float32 of ~500 m
    # exactly rounded, wherever the operands are; derivatives of a - b
    a, b = np.float32([3.0, 1e30, -2.5e-3, 7.0, 0.0]), np.float32([1.0 + 2**-23, 1.0, 4e6, 0.0, 0.0])
    np.testing.assert_array_equal(exact_sub(a, b), a - b)
    np.testing.assert_array_equal(exact_sub(np.float32([np.nan, np.inf]), np.float32([1, 1])),
                                  [np.nan, np.inf])
    g = jax.grad(lambda a, b: jnp.sum(exact_sub(a, b) * jnp.arange(5.0)), (0, 1))(a, b)
    np.testing.assert_array_equal(g[0], np.arange(5.0))
    np.testing.assert_array_equal(g[1], -np.arange(5.0))


def test_advected_distance_float32_under_fusion():
    """A day of advection: exact ``U t mod L`` (float64 of the float32 inputs) to a few ulp of
    the box length, also when the compiler fuses (under reassociation: the subprocess test
    below; Dekker's two-product was 1.4 cm off there)."""
    rng = np.random.default_rng(3)
    u = rng.uniform(2.0, 25.0, 256).astype(np.float32)
    t = np.concatenate([rng.uniform(0.0, 86400.0, 128),
                        rng.uniform(-7200.0, 7200.0, 128)]).astype(np.float32)
    length = np.float32(256.0)
    want = np.fmod(u.astype(np.float64) * t.astype(np.float64), 256.0)
    for run in (jax.jit(advected_distance), fusing(advected_distance)):
        got = np.asarray(run(u, t, length), np.float64)
        diff = np.mod(got - want + 128.0, 256.0) - 128.0  # the same point of the periodic box
        assert np.max(np.abs(diff)) < 4 * np.spacing(np.float32(256.0))
        assert np.all(np.abs(got) < 256.0 * (1 + 1e-6))
    # derivatives of speed * time (and -n per unit length)
    p = np.float32([10.3, 86400.37, 256.0])
    g = jax.grad(lambda p: advected_distance(p[0], p[1], p[2]))(jnp.asarray(p))
    r = float(advected_distance(*(jnp.float32(v) for v in p)))
    n = np.round((np.float64(p[0]) * np.float64(p[1]) - r) / 256.0)
    np.testing.assert_allclose(g, [p[1], p[0], -n], rtol=1e-6)


# -- the float32 paths of the package -------------------------------------------------------------
def test_frozen_turbulence_float32_long_advection_under_fusion():
    """Direct sampling (the advected distance) and the time sampler's lines (projection
    dots) keep 2e-5 of the amplitude at a day's advection when the compiler fuses."""
    _, pts, f32, f64 = long_advection_pair(16)
    ts = np.float32([600.37, 3600.37, 86400.37])[:, None]
    want = np.asarray(sample_at(f64, jnp.asarray(pts, jnp.float64), jnp.asarray(ts, jnp.float64)))
    direct = fusing(lambda t: f32.sample_local_at(jnp.asarray(pts), t))(jnp.asarray(ts))
    np.testing.assert_allclose(np.asarray(direct), want, atol=2e-5)
    lines = fusing(lambda t: f32.time_sampler(jnp.asarray(pts), n_times=1000)(t),
                   one_program=False)(jnp.asarray(ts))
    np.testing.assert_allclose(np.asarray(lines), want, atol=2e-5)
    assert np.asarray(lines).dtype == np.float32
    want_los = _sampler_values(f64, jnp.asarray(pts, jnp.float64), jnp.asarray([0.3, -0.2, 0.9]),
                               jnp.asarray(ts, jnp.float64), 1000)
    los = fusing(lambda t: f32.time_sampler(jnp.asarray(pts), jnp.float32([0.3, -0.2, 0.9]),
                                            n_times=1000)(t), one_program=False)(jnp.asarray(ts))
    np.testing.assert_allclose(np.asarray(los), np.asarray(want_los), atol=2e-5)


E0 = np.array([512_345.678, 6_123_456.789, 0.0])


@pytest.fixture(scope="module")
def utm_fields():
    axes = (E0[0] + np.linspace(-100.0, 100.0, 41), E0[1] + np.linspace(-100.0, 100.0, 41),
            np.linspace(0.0, 120.0, 25))
    scene = lj.scenes.hemisphere(20.0, 10.0, 130.0, centre=E0)
    return {np.dtype(d).name: lj.GridField.from_function(scene.sample, *axes, dtype=d)
            for d in (np.float64, np.float32)}


def test_forward_model_float32_at_utm_under_fusion(utm_fields):
    """The forward model in float32 at UTM coordinates (tests/core/test_precision.py) under
    the emulated GPU, with a tilted mount (the tilt and heading rotations are composed by a
    matrix product: TF32 put the beams 5e-4 off)."""
    mount = lj.Mount(E0 + np.array([1.234, -2.345, 21.0]), epsilon=5.0, pitch=1.5, roll=-0.7)
    heights = np.array([5.0, 20.0, 60.0])
    u_ref = 10.0 * heading(130.0)

    def sim(field, dtype):
        return lj.simulate(field, lj.windcube_v2(), mount, jnp.asarray(heights, dtype), u_ref=u_ref)

    a = sim(utm_fields["float64"], jnp.float64)
    b = fusing(lambda: sim(utm_fields["float32"], jnp.float32))()
    assert b.los.dtype == jnp.float32 and np.all(np.isfinite(a.los))
    np.testing.assert_allclose(b.los, a.los, atol=2e-5)  # m/s, for a 10 m/s wind
    np.testing.assert_allclose(b.lidar_speed, a.lidar_speed, atol=2e-5)
    np.testing.assert_allclose(b.cff_U, a.cff_U, atol=3e-6)


def test_grid_field_float32_at_utm_under_fusion():
    """tests/core/test_field.py::test_float32_at_utm_coordinates under the emulated GPU: a
    float64 mount in a float32 field at UTM coordinates (1.7e-3 m/s off before)."""
    e0, n0 = 512_345.678, 6_123_456.789
    grad = np.array([[0.01, 0.02, 0.0], [0.0, -0.01, 0.03], [0.0, 0.0, 0.0]])
    scene = lj.scenes.linear([8.0, -3.0, 0.0], grad, point=[0.0, 0.0, 0.0])
    x, y, z = e0 + np.linspace(0, 200, 21), n0 + np.linspace(0, 200, 21), np.linspace(0, 100, 11)
    pts = np.stack(np.meshgrid(x, y, z, indexing="ij"), -1) - np.array([e0, n0, 0.0])
    field = lj.GridField(x, y, z, jnp.asarray(np.asarray(scene.sample(pts), np.float32)))
    mount = lj.Mount([e0 + 101.234567, n0 + 99.876543, 5.0])
    assert mount.location.dtype == jnp.float64
    sim = fusing(lambda: lj.simulate(field, lj.windcube_v1(), mount, jnp.array([40.0], jnp.float32)))()
    exact = lj.simulate(scene, lj.windcube_v1(), lj.Mount([101.234567, 99.876543, 5.0]), [40.0])
    assert sim.los.dtype == jnp.float32
    np.testing.assert_allclose(sim.los, exact.los, atol=2e-5)
    # absolute float64 points sampled in-graph
    p = jnp.asarray([[e0 + 33.3, n0 + 77.7, 12.5], [e0 + 150.01, n0 + 20.02, 60.0]])
    got = fusing(lambda p: field.sample(p))(p)
    want = scene.sample(np.asarray(p) - np.array([e0, n0, 0.0]))
    np.testing.assert_allclose(got, want, atol=2e-5)


# -- a compiler that reassociates, for real ------------------------------------------------------
_FAST_MATH_SCRIPT = textwrap.dedent("""
    import json
    import numpy as np, jax, jax.numpy as jnp
    import lidarjax as lj
    from lidarjax._precision import difference, split
    from lidarjax.scenes.turbulence import advected_distance

    out = {}
    a64 = np.array([512_345.678 + 101.234567, 6_123_456.789 + 99.876543, 5.0])
    b64 = np.array([512_345.678, 6_123_456.789, 0.0])
    d = jax.jit(difference, static_argnums=4)(*split(a64, jnp.float32), *split(b64, jnp.float32),
                                                jnp.float32)
    out["difference"] = float(np.max(np.abs(np.asarray(d, np.float64) - (a64 - b64))))
    u, t = np.float32(10.3), np.float32(86400.37)
    r = float(jax.jit(advected_distance)(u, t, np.float32(256.0)))
    w = float(np.fmod(np.float64(u) * np.float64(t), 256.0))
    out["advected"] = abs((r - w + 128.0) % 256.0 - 128.0)
    # tests/core/test_field.py::test_float32_at_utm_coordinates
    e0, n0 = 512_345.678, 6_123_456.789
    grad = np.array([[0.01, 0.02, 0.0], [0.0, -0.01, 0.03], [0.0, 0.0, 0.0]])
    scene = lj.scenes.linear([8.0, -3.0, 0.0], grad, point=[0.0, 0.0, 0.0])
    x, y, z = e0 + np.linspace(0, 200, 21), n0 + np.linspace(0, 200, 21), np.linspace(0, 100, 11)
    pts = np.stack(np.meshgrid(x, y, z, indexing="ij"), -1) - np.array([e0, n0, 0.0])
    field = lj.GridField(x, y, z, jnp.asarray(np.asarray(scene.sample(pts), np.float32)))
    sim = lj.simulate(field, lj.windcube_v1(), lj.Mount([e0 + 101.234567, n0 + 99.876543, 5.0]),
                      jnp.array([40.0], jnp.float32))
    exact = lj.simulate(scene, lj.windcube_v1(), lj.Mount([101.234567, 99.876543, 5.0]), [40.0])
    out["field_los"] = float(np.max(np.abs(np.asarray(sim.los, np.float64) - exact.los)))
    print(json.dumps(out))
""")


def test_float32_at_utm_under_a_reassociating_compiler():
    """``--xla_cpu_enable_fast_math`` lets XLA reassociate and contract: the coordinate
    difference (0.4 m off when the residuals were added before the high parts were
    subtracted), the advected distance and the forward model at UTM keep their accuracy."""
    env = dict(os.environ, XLA_FLAGS="--xla_cpu_enable_fast_math=true", JAX_ENABLE_X64="1",
               JAX_PLATFORMS="cpu", PYTHONPATH=str(REPO))
    res = subprocess.run([sys.executable, "-c", _FAST_MATH_SCRIPT], env=env, cwd=REPO,
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    out = json.loads(res.stdout.strip().splitlines()[-1])
    assert out["difference"] < 1e-4, out  # float32 of ~100 m
    assert out["advected"] < 1e-4, out  # a few ulp of 256 m
    assert out["field_los"] < 2e-5, out  # m/s
