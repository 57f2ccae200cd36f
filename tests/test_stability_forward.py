"""Stress suite for the forward model: random valid scenes give finite numbers or a NaN that a
flag explains, and finite gradients for every differentiable input.

Shapes are fixed (3 heights, Windcube V2), so hypothesis examples never recompile.
"""

import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import example, given, settings
from hypothesis import strategies as st

import lidarjax as lj

HEIGHTS = 3
OFFSET = np.array([1.0e6, 1.0e6, 0.0])  # UTM-like coordinates
EXPLAINS_NAN = lj.Flag.CALM | lj.Flag.RATIO_UNDEFINED | lj.Flag.BEAM_OUTSIDE | lj.Flag.POINT_OUTSIDE
DIRECTION_OUTPUTS = ("cff_th", "cfp_th")
RATIO_OUTPUTS = ("cff_u", "cff_v", "cff_U", "cfp_u", "cfp_v", "cfp_w", "cfp_U")


def unpack(p):
    speed, direction, cone, beta, gamma, psi, eps, alpha = (p[i] for i in range(8))
    heights = p[8:8 + HEIGHTS]
    loc = p[8 + HEIGHTS:11 + HEIGHTS]
    return speed, direction, cone, beta, gamma, psi, eps, alpha, heights, loc


def run(p):
    speed, direction, cone, beta, gamma, psi, eps, alpha, heights, loc = unpack(p)
    # sheared flow over flat ground at UTM-sized coordinates
    scene = lj.scenes.PowerLaw(jnp.asarray(OFFSET), jnp.zeros(3), speed, jnp.asarray(100.0),
                               alpha, direction, jnp.asarray(0.02))
    scan = lj.Scan(jnp.array([0.0, 90.0, 180.0, 270.0]), cone, vertical=True, method="windcube_v2")
    mount = lj.Mount(jnp.asarray(OFFSET) + loc, beta, gamma, psi, eps)
    return lj.simulate(scene, scan, mount, heights, u_ref=speed * lj.scenes.heading(direction))


run_jit = jax.jit(run)


def loss(p):
    sim = run(p)
    total = 0.0
    for leaf in (sim.los, sim.lidar_velocity, sim.point_velocity, sim.free_velocity,
                 sim.cff_w, sim.cff_th, sim.cfp_th, *[getattr(sim, n) for n in RATIO_OUTPUTS]):
        total = total + jnp.sum(jnp.where(jnp.isfinite(leaf), leaf, 0.0))
    return total + jnp.sum(jnp.nan_to_num(lj.wind_direction(sim.lidar_velocity)))


grad_jit = jax.jit(jax.grad(loss))

speeds = st.one_of(st.just(0.0), st.floats(0.0, 60.0))
directions = st.one_of(st.sampled_from([0.0, 90.0, 180.0, 270.0, 360.0]), st.floats(0.0, 360.0))
angles = st.floats(-360.0, 360.0)


@settings(max_examples=150, deadline=None)
@given(speed=speeds, direction=directions, cone=st.floats(5.0, 60.0), beta=angles,
       gamma=angles, psi=angles, eps=angles, alpha=st.floats(0.0, 0.4),
       heights=st.lists(st.floats(0.03, 300.0), min_size=HEIGHTS, max_size=HEIGHTS),
       loc=st.tuples(st.floats(-100, 100), st.floats(-100, 100), st.floats(0.0, 50.0)))
@example(speed=0.0, direction=0.0, cone=30.0, beta=0.0, gamma=0.0, psi=0.0, eps=0.0, alpha=0.1,
         heights=[0.05, 1.0, 300.0], loc=(0.0, 0.0, 0.0))
@example(speed=10.0, direction=360.0, cone=5.0, beta=90.0, gamma=0.0, psi=180.0, eps=0.0,
         alpha=0.0, heights=[0.03, 40.0, 300.0], loc=(0.0, 0.0, 0.0))
def test_outputs_finite_or_flagged_and_gradients_finite(
        speed, direction, cone, beta, gamma, psi, eps, alpha, heights, loc):
    p = jnp.asarray([speed, direction, cone, beta, gamma, psi, eps, alpha, *heights, *loc])
    sim = run_jit(p)
    flags = np.asarray(sim.flags)
    explained = (flags & EXPLAINS_NAN) != 0
    for name in ("los", "lidar_velocity", "point_velocity"):
        v = np.asarray(getattr(sim, name)).reshape(HEIGHTS, -1)
        assert np.all(np.isfinite(v[~explained])), (name, v, flags)
    assert np.all(np.isfinite(sim.free_velocity))
    for name in RATIO_OUTPUTS + DIRECTION_OUTPUTS:
        v = np.asarray(getattr(sim, name))
        assert not np.any(np.isinf(v)), name
        assert np.all(np.isfinite(v[~explained])), (name, v, flags)
        assert np.all(np.abs(v[np.isfinite(v)]) <= 1.0e4 + 180.0), name
    if speed**2 <= np.finfo(np.float64).tiny:  # calm, sqrt(tiny) ~ 1.5e-154 m/s included
        assert np.all(flags & lj.Flag.CALM)
        assert np.all(np.isnan(sim.cff_w))  # normalised by a zero free-stream speed
    else:
        assert np.all(np.isfinite(sim.cff_w))
    g = np.asarray(grad_jit(p))
    assert np.all(np.isfinite(g)), g
