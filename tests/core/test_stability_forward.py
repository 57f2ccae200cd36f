"""Stress suite for the forward model: random valid scenes give finite numbers or a NaN that a
flag explains, and finite gradients for every differentiable input.

Scenes: a power-law shear at UTM-sized coordinates (float64, point probe); a model-scale
platform at UTM coordinates (a 0.35 m hemisphere, the lidar 1 to 5 cm above its deck or
flank, heights from 3 cm) seen by a 1:100 CW probe in float32; the same platform gridded,
with solid (NaN) nodes inside the body, seen by an even-node pulsed probe in float32. Every
configuration is compiled once with fixed shapes (3 heights, Windcube V2), so hypothesis
examples never recompile. Then two regressions.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
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
    return lj.simulate(scene, scan, mount, heights, u_ref=speed * lj.heading(direction))


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
# a free stream of sqrt(tiny) = 2**-511 m/s: the lidar's squares about tiny, calm, finite
# gradients (the flag at tiny itself: tests/core/test_forward.py::test_calm_has_one_definition)
@example(speed=2.0**-511, direction=0.0, cone=30.0, beta=0.0, gamma=0.0, psi=0.0, eps=0.0,
         alpha=0.0, heights=[1.0, 40.0, 300.0], loc=(0.0, 0.0, 0.0))
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
    assert_calm_where_no_direction(sim)
    if speed**2 <= np.finfo(np.float64).tiny:  # calm, sqrt(tiny) ~ 1.5e-154 m/s included
        assert np.all(flags & lj.Flag.CALM)
        assert np.all(np.isnan(sim.cff_w))  # normalised by a zero free-stream speed
    else:
        assert np.all(np.isfinite(sim.cff_w))
    g = np.asarray(grad_jit(p))
    assert np.all(np.isfinite(g)), g


# -- shared checks -------------------------------------------------------------------------
def masked_total(sim):
    """Sum of every output family with NaN entries masked out (what a user's loss does)."""
    total = 0.0
    for leaf in (sim.los, sim.lidar_velocity, sim.point_velocity, sim.free_velocity,
                 sim.cff_w, sim.cff_th, sim.cfp_th, *[getattr(sim, n) for n in RATIO_OUTPUTS]):
        total = total + jnp.sum(jnp.where(jnp.isfinite(leaf), leaf, 0.0))
    total = total + jnp.sum(jnp.nan_to_num(lj.wind_direction(sim.lidar_velocity)))
    return total + jnp.sum(lj.horizontal_speed(jnp.nan_to_num(sim.lidar_velocity)))


def assert_calm_where_no_direction(sim):
    """`Flag.CALM` is set exactly where the lidar's direction is NaN from a finite vector
    (one definition; a NaN vector is `BEAM_OUTSIDE`)."""
    finite = np.all(np.isfinite(sim.lidar_velocity), axis=-1)
    np.testing.assert_array_equal(np.isnan(lj.wind_direction(sim.lidar_velocity)) & finite,
                                  (np.asarray(sim.flags) & lj.Flag.CALM) != 0)


def assert_finite_or_explained(sim, speed):
    """Every output is finite, or NaN with a flag that explains it (never inf); CALM exactly
    where the direction is NaN."""
    assert_calm_where_no_direction(sim)
    flags = np.asarray(sim.flags)
    beam = (flags & (lj.Flag.BEAM_OUTSIDE)) != 0
    point = (flags & lj.Flag.POINT_OUTSIDE) != 0
    explained = (flags & EXPLAINS_NAN) != 0
    h = flags.shape[0]
    for name in ("los", "lidar_velocity", "point_velocity", "free_velocity", "condition_number",
                 *RATIO_OUTPUTS, *DIRECTION_OUTPUTS, "cff_w"):
        v = np.asarray(getattr(sim, name))
        assert not np.any(np.isinf(v)), name
        if name in ("free_velocity", "condition_number"):
            assert np.all(np.isfinite(v)), name
            continue
        v = v.reshape(h, -1)
        if name == "los":
            np.testing.assert_array_equal(np.isnan(v).any(-1), beam)  # NaN LOS <=> flag
        elif name == "lidar_velocity":
            np.testing.assert_array_equal(np.isnan(v).any(-1), beam)
        elif name == "point_velocity":
            np.testing.assert_array_equal(np.isnan(v).any(-1), point)
        elif name == "cff_w" and speed == 0.0:
            assert np.all(np.isnan(v)), "cff_w is normalised by the (zero) free-stream speed"
        else:
            assert np.all(np.isfinite(v[~explained])), (name, v, flags)


def value_and_gradient(run):
    """One compiled function: the simulation and the gradient of `masked_total`."""
    def f(*args):
        sim = run(*args)
        return masked_total(sim), sim
    return jax.jit(jax.value_and_grad(f, argnums=tuple(range(2)), has_aux=True))


# -- model-scale platform: hemisphere of 0.35 m, lidar a few cm above the deck -------------
MODEL_R = 0.35
UTM = np.array([512_345.678, 6_123_456.789, 3.0])  # easting, northing, ground datum
PROBES = {
    "point": lj.PointProbe(),
    # 1:100 model scale; 4 nodes (even: no node at the focus) laid over the support cut at
    # the lidar, down to the lowest heights
    "pulsed": lj.PulsedProbe(n_nodes=4).scaled(100.0),
    "cw": lj.CWProbe().scaled(100.0),
}
DTYPES = {"float64": jnp.float64, "float32": jnp.float32}


def deck_location(rho, theta, clearance):
    """A point `clearance` m above the hemisphere's surface at horizontal radius `rho`."""
    return np.array([rho * np.cos(theta), rho * np.sin(theta),
                     np.sqrt(MODEL_R**2 - rho**2) + clearance])


def _model_scale(p, scale):
    """A CW probe (1:100 scale, stretched by `scale`) in float32 over the platform."""
    speed, direction, cone, beta, gamma, psi, eps, radius = (p[i] for i in range(8))
    heights, loc = p[8:8 + HEIGHTS], p[8 + HEIGHTS:11 + HEIGHTS]
    f32 = jnp.float32
    scene = lj.scenes.Hemisphere(jnp.asarray(UTM, f32), jnp.zeros(3, f32), radius.astype(f32),
                                 speed.astype(f32), direction.astype(f32))
    scan = lj.Scan(jnp.array([0.0, 90.0, 180.0, 270.0]), cone, vertical=True,
                   method="windcube_v2")
    mount = lj.Mount(jnp.asarray(UTM) + loc, beta, gamma, psi, eps)
    return lj.simulate(scene, scan, mount, heights.astype(f32),
                       u_ref=speed * lj.heading(direction),
                       probe=PROBES["cw"].scaled(scale))


model_scale = value_and_gradient(_model_scale)


@settings(max_examples=30, deadline=None)
@given(speed=speeds, direction=directions, cone=st.floats(5.0, 60.0), beta=angles,
       gamma=angles, psi=angles, eps=angles,
       heights=st.lists(st.floats(0.03, 3.0), min_size=HEIGHTS, max_size=HEIGHTS),
       rho=st.floats(0.0, 0.33), theta=st.floats(0.0, 2 * np.pi),
       clearance=st.floats(0.01, 0.05), scale=st.floats(0.7, 1.5))
@example(speed=0.0, direction=0.0, cone=5.0, beta=0.0, gamma=0.0, psi=0.0, eps=0.0,
         heights=[0.03, 0.3, 3.0], rho=0.0, theta=0.0, clearance=0.01, scale=1.0)
@example(speed=60.0, direction=360.0, cone=60.0, beta=90.0, gamma=0.0, psi=180.0, eps=0.0,
         heights=[0.03, 0.04, 0.05], rho=0.33, theta=1.0, clearance=0.01, scale=1.0)
# found by hypothesis: a free stream of 3e-19 m/s (its square still a normal float32) gave
# inf gradients of the direction addends and cfp_w (the reverse pass squared 1 / speed)
@example(speed=2.7833376140953104e-19, direction=0.0, cone=5.0, beta=0.0, gamma=0.0, psi=0.0,
         eps=0.0, heights=[1.0, 1.0, 1.0], rho=0.0, theta=0.0, clearance=0.03125, scale=1.0)
# float32's sqrt(tiny) = 2**-63 m/s: squares about tiny, the calm boundary
@example(speed=2.0**-63, direction=0.0, cone=5.0, beta=0.0, gamma=0.0, psi=0.0,
         eps=0.0, heights=[1.0, 1.0, 1.0], rho=0.0, theta=0.0, clearance=0.03125, scale=1.0)
def test_model_scale_platform_float32(speed, direction, cone, beta, gamma, psi, eps, heights,
                                      rho, theta, clearance, scale):
    loc = deck_location(rho, theta, clearance)
    p = jnp.asarray([speed, direction, cone, beta, gamma, psi, eps, MODEL_R, *heights, *loc])
    (_, sim), grads = model_scale(p, jnp.asarray(scale))
    assert sim.los.dtype == jnp.float32
    assert_finite_or_explained(sim, speed)
    for g in grads:  # with respect to every input, the probe's length scale included
        assert np.all(np.isfinite(np.asarray(g))), g


# -- a gridded platform at UTM coordinates, solid nodes inside the body --------------------
GRID_AXES = tuple(UTM[a] + np.linspace(lo, hi, 25)
                  for a, (lo, hi) in enumerate(((-1.2, 1.2), (-1.2, 1.2), (0.0, 2.4))))
UNIT_GRID = np.asarray(lj.GridField.from_function(
    lj.scenes.hemisphere(MODEL_R, 1.0, 0.0, centre=UTM).sample, *GRID_AXES).velocity)
SOLID = np.isnan(UNIT_GRID)


@functools.cache
def gridded(probe_name, dtype_name):
    probe, dtype = PROBES[probe_name], DTYPES[dtype_name]

    def run(p, velocity):
        speed, cone, beta, gamma, psi, eps = (p[i] for i in range(6))
        heights, loc = p[6:6 + HEIGHTS], p[6 + HEIGHTS:9 + HEIGHTS]
        # scale the flow by the speed, keeping the solid nodes NaN (a safe mask: NaN * speed
        # would make the gradient with respect to the speed NaN)
        velocity = jnp.where(SOLID, jnp.nan, speed * jnp.where(SOLID, 0.0, velocity))
        field = lj.GridField(*GRID_AXES, velocity.astype(dtype))
        scan = lj.Scan(jnp.array([0.0, 90.0, 180.0, 270.0]), cone, vertical=True,
                       method="windcube_v2")
        mount = lj.Mount(jnp.asarray(UTM) + loc, beta, gamma, psi, eps)
        return lj.simulate(field, scan, mount, heights.astype(dtype),
                           u_ref=speed * lj.heading(0.0), probe=probe)

    return value_and_gradient(run)


@pytest.mark.parametrize("probe_name, dtype_name", [("pulsed", "float32")])
@settings(max_examples=30, deadline=None)
@given(speed=speeds, cone=st.floats(5.0, 60.0), beta=angles, gamma=angles, psi=angles,
       eps=angles, heights=st.lists(st.floats(0.03, 1.5), min_size=HEIGHTS, max_size=HEIGHTS),
       rho=st.floats(0.0, 0.33), theta=st.floats(0.0, 2 * np.pi),
       clearance=st.floats(0.01, 0.05))
@example(speed=0.0, cone=30.0, beta=0.0, gamma=0.0, psi=0.0, eps=0.0, heights=[0.03, 0.5, 1.5],
         rho=0.0, theta=0.0, clearance=0.02)
def test_gridded_platform_at_utm_coordinates(probe_name, dtype_name, speed, cone, beta, gamma,
                                             psi, eps, heights, rho, theta, clearance):
    loc = deck_location(rho, theta, clearance)
    p = jnp.asarray([speed, cone, beta, gamma, psi, eps, *heights, *loc])
    (_, sim), grads = gridded(probe_name, dtype_name)(p, jnp.asarray(UNIT_GRID))
    assert sim.los.dtype == DTYPES[dtype_name]
    assert_finite_or_explained(sim, speed)
    for g in grads:  # with respect to the inputs and every node of the field
        assert np.all(np.isfinite(np.asarray(g))), g


# -- regressions ---------------------------------------------------------------------------
SHOULDER = lj.scenes.hemisphere(radius=20.0, speed=10.0, direction=250.0)
SHOULDER_GRID = lj.GridField.from_function(
    SHOULDER.sample, np.linspace(-40, 40, 21), np.linspace(-40, 40, 21), np.linspace(0, 80, 21))


@pytest.mark.parametrize("field, probe", [(SHOULDER, lj.PulsedProbe(n_nodes=5)),
                                          (SHOULDER_GRID, lj.PointProbe())],
                         ids=["scene-pulsed", "grid-point"])
def test_nan_results_masked_out_of_a_loss_keep_its_gradient_finite(field, probe):
    """A beam focus or a probe node inside the body (NaN) used to make the reverse-mode
    gradient of every input NaN (``0 * NaN`` in the backward pass), even for a loss that
    masks the NaN results out; forward mode was finite. Now it is finite and matches
    finite differences."""
    heights = jnp.array([1.0, 30.0])
    u_ref = 10.0 * lj.heading(250.0)

    def loss(x):
        scan = lj.Scan(jnp.array([0.0, 90.0, 180.0, 270.0]), x[7], vertical=True,
                       method="windcube_v2")
        mount = lj.Mount(x[:3], *(x[i] for i in range(3, 7)))
        sim = lj.simulate(field, scan, mount, heights, u_ref=u_ref, probe=probe)
        return masked_total(sim), sim.flags

    # on the body's shoulder: the lowest beams hit the body; at 30 m the pulsed probe's
    # nodes behind the lidar (cut, zero weight) lie inside it
    x0 = np.array([-18.5, 0.3, 7.7, 10.0, 0.0, 180.0, 5.0, 28.0])  # off grid lines (kinks)
    value_and_grad = jax.jit(jax.value_and_grad(loss, has_aux=True))
    (_, flags), g = value_and_grad(jnp.asarray(x0))
    assert flags[0] & lj.Flag.BEAM_OUTSIDE and not flags[1] & lj.Flag.BEAM_OUTSIDE
    assert np.all(np.isfinite(g)), g
    eps = 1e-6
    for i in range(x0.size):
        dx = eps * np.eye(x0.size)[i]
        fd = (value_and_grad(jnp.asarray(x0 + dx))[0][0]
              - value_and_grad(jnp.asarray(x0 - dx))[0][0]) / (2 * eps)
        assert float(g[i]) == pytest.approx(float(fd), rel=1e-5, abs=1e-6), i


def test_even_node_probe_below_its_innermost_offset_still_averages():
    """An even node count has no node at the focus. A fixed rule cut at the lidar used to
    keep no node below the innermost offset (LOS 0/0 = NaN, mislabelled BEAM_OUTSIDE); the
    rule is now laid over the cut support, so at 5 m all four nodes average the field within
    5 m of the focus (flagged: the cut drops most of the weighting)."""
    probe = lj.PulsedProbe(n_nodes=4)
    mount = lj.Mount([3.0, 2.0, 20.5])
    heights = jnp.array([5.0, 80.0])
    offsets, _ = probe.nodes(jnp.array(5.0))
    np.testing.assert_allclose(offsets, [-3.75, -1.25, 1.25, 3.75])
    sim = lj.simulate(SHOULDER, lj.windcube_v2(), mount, heights, probe=probe)
    point = lj.simulate(SHOULDER, lj.windcube_v2(), mount, heights)
    assert sim.flags[0] == lj.Flag.PROBE_TRUNCATED and sim.flags[1] == 0
    assert np.all(np.isfinite(sim.los))
    # by hand: the four nodes within the focus range of the focus, renormalised
    for b in range(5):
        n = np.asarray(sim.directions[b])
        r = float(5.0 / np.cos(np.radians(28.0))) if b < 4 else 5.0
        o, w = (np.asarray(a) for a in probe.nodes(jnp.array(r)))
        pts = np.array([3.0, 2.0, 20.5]) + (r + o)[:, None] * n
        expected = np.sum(w * (np.asarray(SHOULDER.sample(pts)) @ n)) / np.sum(w)
        assert float(sim.los[0, b]) == pytest.approx(expected, rel=1e-9)
    assert np.all(np.abs(sim.los[1] - point.los[1]) > 1e-6)  # a real volume average above
