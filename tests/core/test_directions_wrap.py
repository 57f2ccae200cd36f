"""No artefact at the 0/360 wrap: the reported direction, the correction addend, their
derivatives and the inverted direction are continuous as the inflow sweeps across north in
steps of 0.01 degrees (and 0 and 360 give the same results).

The site is tests/sites.py's (a Windcube V2 on a hemisphere, software north offset 10
degrees); the inverse reuses test_inverse's compiled shapes (64 records, 30-degree table).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj

from .. import sites

STEP = 0.01
# CFD inflow directions 348 .. 360, 360 again as 0, .. 12 degrees: the input wraps at 360 and
# the north-frame outputs (CFD + 10 degrees, give or take the platform's deviation) at 350
SWEEP = np.concatenate([348.0 + STEP * np.arange(1200), [360.0, 0.0], STEP * np.arange(1, 1201)])
DUPLICATE = 1200  # SWEEP[1200] = 360 and SWEEP[1201] = 0 are the same inflow


@jax.jit
def _sweep(directions):
    def one(d):
        def outputs(d):
            sim = sites.simulate_at(d, 10.0)
            return sim.lidar_direction, sim.cff_th, sim.lidar_speed
        return jax.jvp(outputs, (d,), (jnp.ones_like(d),))

    return jax.vmap(one)(directions)


@pytest.fixture(scope="module")
def sweep():
    (direction, addend, speed), (d_direction, d_addend, d_speed) = _sweep(jnp.asarray(SWEEP))
    return {k: np.asarray(v) for k, v in dict(
        direction=direction, addend=addend, speed=speed, d_direction=d_direction,
        d_addend=d_addend, d_speed=d_speed).items()}


def test_zero_and_360_are_the_same_inflow(sweep):
    for k, v in sweep.items():
        np.testing.assert_allclose(v[DUPLICATE], v[DUPLICATE + 1], rtol=1e-12, atol=1e-11,
                                   err_msg=k)


def test_reported_direction_and_addend_are_continuous_across_both_wraps(sweep):
    step = np.delete(np.diff(SWEEP), DUPLICATE)
    step = np.asarray(lj.wrap180(step))  # 0.01 everywhere, 360 -> 0 included
    np.testing.assert_allclose(step, STEP, rtol=1e-9)
    keep = np.arange(SWEEP.size) != DUPLICATE + 1
    d = sweep["direction"][keep]
    assert d.min() < 1.0 and d.max() > 359.0  # the output itself crosses north
    rate = np.asarray(lj.wrap180(np.diff(d, axis=0))) / STEP  # d(lidar direction) / d(inflow)
    assert np.all(np.abs(rate - 1.0) < 0.2), rate
    assert np.max(np.abs(np.diff(rate, axis=0))) < 1e-4  # smooth: no jump anywhere
    for k in ("addend", "speed"):
        rate = np.diff(sweep[k][keep], axis=0) / STEP
        assert np.max(np.abs(np.diff(rate, axis=0))) < 1e-4, k


def test_derivatives_with_respect_to_the_inflow_are_continuous(sweep):
    keep = np.arange(SWEEP.size) != DUPLICATE + 1
    for k in ("d_direction", "d_addend", "d_speed"):
        g = sweep[k][keep]
        assert np.all(np.isfinite(g)), k
        assert np.max(np.abs(np.diff(g, axis=0))) < 1e-4, k
    # the derivative agrees with the finite differences of the sweep, across the wraps too
    fd = np.asarray(lj.wrap180(np.diff(sweep["direction"][keep], axis=0))) / STEP
    mid = 0.5 * (sweep["d_direction"][keep][1:] + sweep["d_direction"][keep][:-1])
    np.testing.assert_allclose(fd, mid, atol=1e-5)


R = 64  # as test_inverse: one compiled solver for both modules


def test_inverted_direction_is_continuous_across_north():
    table = sites.table(30.0)
    north = np.linspace(-0.315, 0.315, R)  # 0.01-degree steps, north-frame truth
    sims = sites.records(np.mod(north - sites.EPSILON, 360.0), 8.0)
    inv = lj.invert(table, sims.los)
    assert np.all(inv.converged)
    d = np.asarray(inv.direction)  # (R, h)
    assert np.all((d >= 0.0) & (d < 360.0))
    assert np.any(d > 359.0, axis=0).all() and np.any(d < 1.0, axis=0).all()
    err = np.asarray(lj.wrap180(d - np.mod(north, 360.0)[:, None]))
    assert np.max(np.abs(err)) < 0.05  # the 30-degree table's interpolation error
    np.testing.assert_allclose(np.asarray(lj.wrap180(np.diff(d, axis=0))), 0.01, atol=1e-4)
    assert np.max(np.abs(np.diff(err, axis=0))) < 1e-4  # the error itself has no jump
