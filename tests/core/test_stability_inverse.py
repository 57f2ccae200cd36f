"""Stress suite for the inverse: batches mixing clean records with zero ones, one or two
missing beams, a wild beam (a 50 m/s spike), all beams equal and all beams missing, in
float64 and float32. Every record gets a finite answer with an honest uncertainty, or NaN
with ``converged=False`` and a reason; no record disturbs its neighbours (clean records come
out bit for bit as in an all-clean batch); step counts stay bounded; extreme scales work.

One fixed batch shape (64 records, tests/sites.py's 30-degree table), shared with
test_inverse.py, so hypothesis examples never recompile.
"""

import functools

import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import lidarjax as lj
from lidarjax.flags import InverseFlag

from .. import sites

R = 64
DTYPES = (np.float64, np.float32)
CASES = ("clean", "zero", "miss1", "miss2", "wild", "equal", "nan")


@functools.cache
def truth():
    rng = np.random.default_rng(11)
    sims = sites.records(rng.uniform(0.0, 360.0, R), rng.uniform(0.5, 25.0, R))
    return np.asarray(sims.los), np.asarray(sims.free_speed), np.asarray(sims.free_direction)


@functools.cache
def reference(dtype):
    return lj.invert(sites.table(30.0), jnp.asarray(truth()[0], dtype))


def corrupt(clean, cases):
    los = clean.copy()
    for i, (kind, beam, other, value) in enumerate(cases):
        second = (beam + other) % 5  # a different beam
        if kind == "zero":
            los[i] = 0.0
        elif kind == "miss1":
            los[i][:, beam] = np.nan
        elif kind == "miss2":
            los[i][:, [beam, second]] = np.nan
        elif kind == "wild":
            los[i][:, beam] += np.copysign(50.0, value)
        elif kind == "equal":
            los[i] = value
        elif kind == "nan":
            los[i] = np.nan
    return los


def check(inv, cases, speed, direction, dtype):
    conv = np.asarray(inv.converged)
    s, d = np.asarray(inv.speed), np.asarray(inv.direction)
    s_std, d_std = np.asarray(inv.speed_std), np.asarray(inv.direction_std)
    flags = np.asarray(inv.flags)
    calm = (flags & InverseFlag.CALM) != 0
    # the general contract
    assert np.all(np.asarray(inv.num_steps) <= 8)
    assert np.all(np.isfinite(s[conv])) and not np.any(np.isnan(s_std[conv]))
    assert np.all(np.isfinite(d[conv & ~calm])) and np.all(np.isnan(d[calm]))
    assert np.all(np.isnan(s[~conv])) and np.all(np.isnan(d[~conv])) and np.all(flags[~conv] != 0)
    ref = reference(dtype)
    for i, (kind, _, _, value) in enumerate(cases):
        es = np.abs(s[i] / speed[i] - 1.0)
        ed = np.abs(np.asarray(lj.wrap180(d[i] - direction[i])))
        if kind == "clean":  # undisturbed by its neighbours, bit for bit
            np.testing.assert_array_equal(s[i], ref.speed[i])
            np.testing.assert_array_equal(d[i], ref.direction[i])
        elif kind == "zero":
            assert np.all(conv[i] & calm[i]) and np.all(s[i] == 0.0) and np.all(np.isinf(d_std[i]))
        elif kind in ("miss1", "miss2"):
            # with two beams gone, an opposite pair and the vertical beam alone cannot tell
            # the direction: in float32 that is flagged (float64 still resolves the
            # platform's small distortion of the response)
            ok = conv[i] | ((kind == "miss2") & ((flags[i] & InverseFlag.ILL_CONDITIONED) != 0))
            assert np.all(ok), (kind, flags[i])
            assert np.all(es[conv[i]] < 1e-3) and np.all(ed[conv[i]] < 0.05)
            assert np.all(np.asarray(inv.n_beams[i])[conv[i]] == (4 if kind == "miss1" else 3))
        elif kind == "wild":  # fitted, with a large residual and uncertainty
            assert np.all(conv[i])
            assert np.all(np.asarray(inv.residual_rms[i]) > 1.0) and np.all(s_std[i] > 1.0)
        elif kind == "equal":  # no direction explains it: large residual and uncertainty
            if value == 0.0:
                continue
            assert np.all(conv[i])
            assert np.all(np.asarray(inv.residual_rms[i]) > 0.5 * abs(value))
            assert np.all(s_std[i] > 0.5 * abs(value)) and np.all(d_std[i] > 20.0)
        elif kind == "nan":
            assert not np.any(conv[i]) and np.all(flags[i] & InverseFlag.TOO_FEW_BEAMS)


# (case, beam, offset of a second beam, value of an all-equal record or the spike's sign);
# equal values are 0 or at least 1 mm/s (tinier ones are extreme scales, tested apart)
values = st.one_of(st.just(0.0), st.floats(1e-3, 20.0), st.floats(-20.0, -1e-3))
record_cases = st.tuples(st.sampled_from(CASES), st.integers(0, 4), st.integers(1, 4), values)


@settings(max_examples=20, deadline=None)
@given(cases=st.lists(record_cases, min_size=R, max_size=R))
def test_mixed_bad_records_in_one_batch(cases):
    clean, speed, direction = truth()
    los = corrupt(clean, cases)
    for dtype in DTYPES:
        inv = lj.invert(sites.table(30.0), jnp.asarray(los, dtype))
        assert inv.speed.dtype == dtype
        check(inv, cases, speed, direction, dtype)


@pytest.mark.parametrize("dtype", DTYPES)
def test_extreme_scales(dtype):
    """Solved in units of each record's RMS LOS, computed without squaring the LOS: in
    float32 a record at 1e-20 m/s used to underflow (NaN, NOT_CONVERGED), its uncertainty
    at 1e18 m/s to overflow."""
    clean, speed, direction = truth()
    scales = np.logspace(-30, 30, R)
    inv = lj.invert(sites.table(30.0), jnp.asarray(clean * scales[:, None, None], dtype))
    ref = reference(dtype)
    assert np.all(inv.converged)
    np.testing.assert_allclose(inv.speed, ref.speed * scales[:, None], rtol=1e-4)
    np.testing.assert_allclose(lj.wrap180(inv.direction - ref.direction), 0.0, atol=1e-3)
    assert np.all(np.isfinite(inv.speed_std)) and np.all(np.isfinite(inv.noise))
    # the clean records themselves: float32 against float64
    if dtype == np.float32:
        ref64 = reference(np.float64)
        np.testing.assert_allclose(ref.speed, ref64.speed, rtol=3e-6)
        np.testing.assert_allclose(lj.wrap180(ref.direction - ref64.direction), 0.0, atol=2e-4)


def test_start_near_359_converges_to_1_degree_in_float32():
    near = sites.table(30.0, first=-sites.EPSILON - 1.0)  # knots at 359, 29, ... (north)
    table = lj.ResponseTable(np.asarray(near.directions, np.float32),
                             np.asarray(near.response, np.float32))
    assert table.dtype == jnp.float32 and float(table.directions[-1]) == pytest.approx(359.0)
    truths = np.array([1.0, 0.2, 359.9])
    sims = sites.records(truths - sites.EPSILON, 8.0)
    los = truth()[0].copy()  # padded to the shared batch shape
    los[:3] = np.asarray(sims.los)
    inv = lj.invert(table, jnp.asarray(los, jnp.float32))
    assert inv.direction.dtype == jnp.float32 and np.all(inv.converged[:3])
    np.testing.assert_allclose(lj.wrap180(inv.direction[:3] - truths[:, None]), 0.0, atol=2e-3)
    assert np.all((inv.direction >= 0) & (inv.direction < 360))
    assert np.all(inv.num_steps[:3] <= 6)
