"""The forward model: closed-form biases, frame chain, retracing, vmap, precision, gradients."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import lidarjax as lj
from lidarjax.forward import _simulate_jit

from ..helpers import assert_grad_matches_fd

HEIGHTS = np.array([10.0, 40.0, 80.0])
SCANS = {"v1": lj.windcube_v1(30.0), "v2": lj.windcube_v2(28.0), "zephir": lj.zephir(30.0, 12)}


def rz(deg):
    t = np.radians(deg)
    return np.array([[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1]])


def expected_bias_lidar(kind, grad_lidar, h, cone):
    """Closed-form reconstruction bias (lidar frame) in a constant-gradient flow.

    With s_b = n_b . (V0 + r G n_b) and r = h / cos c (derivation in the README):
    - DBS (V1): u: h dw/dx, v: h dw/dy, w: h tan^2 c dv/dy (the seed's w uses S0/S2 only);
    - V2: as V1 for u, v; w exact (vertical beam);
    - sine fit with N >= 4 evenly spaced beams: u, v as DBS, w: h tan^2 c (du/dx + dv/dy) / 2.
    """
    g = grad_lidar
    t2 = np.tan(np.radians(cone)) ** 2
    bu, bv = h * g[2, 0], h * g[2, 1]
    bw = {"v1": h * t2 * g[1, 1], "v2": 0.0 * h, "zephir": h * t2 * (g[0, 0] + g[1, 1]) / 2}[kind]
    return np.stack([bu, bv, bw], -1)


@pytest.mark.parametrize("kind", ["v1", "v2", "zephir"])
@pytest.mark.parametrize("angles", [(0, 0, 0, 0), (81, 0, 180, 0), (33, 12, 57, -21), (200, -30, 90, 45)])
def test_constant_gradient_bias_closed_form(kind, angles):
    beta, gamma, psi, eps = angles
    rng = np.random.default_rng(abs(hash((kind, angles))) % 2**32)
    grad = rng.normal(scale=0.05, size=(3, 3))
    v0 = np.array([6.0, -3.0, 0.4])
    loc = np.array([120.0, -40.0, 15.0])
    scene = lj.scenes.linear(v0, grad, point=loc)
    scan = SCANS[kind]
    mount = lj.Mount(loc, beta=beta, gamma=gamma, psi=psi, epsilon=eps)
    sim = lj.simulate(scene, scan, mount, HEIGHTS)
    rv = rz(psi - beta - gamma)  # CFD -> lidar velocities (positions use its transpose)
    bias_lidar = expected_bias_lidar(kind, rv @ grad @ rv.T, HEIGHTS, float(scan.cone_angle))
    bias_north = bias_lidar @ rz(-eps).T
    np.testing.assert_allclose(sim.lidar_velocity - sim.point_velocity, bias_north, atol=1e-12)
    # the point velocity itself: the true flow above the lidar in the north frame
    truth = (v0 + HEIGHTS[:, None] * grad[:, 2]) @ (rz(-eps) @ rv).T
    np.testing.assert_allclose(sim.point_velocity, truth, atol=1e-12)


def test_gridded_linear_field_gives_the_same_bias():
    """Trilinear interpolation reproduces linear fields: the grid agrees with the scene."""
    grad = np.array([[0.01, -0.02, 0.03], [0.02, 0.01, -0.04], [0.05, -0.01, 0.002]])
    scene = lj.scenes.linear([5.0, 2.0, 0.0], grad)
    x = np.linspace(-80, 80, 9)
    field = lj.GridField.from_function(scene.sample, x, x, np.array([0.0, 30.0, 60.0, 100.0]))
    mount = lj.Mount([3.0, -2.0, 1.0], beta=40, psi=180, epsilon=10)
    a = lj.simulate(field, SCANS["v1"], mount, HEIGHTS)
    b = lj.simulate(scene, SCANS["v1"], mount, HEIGHTS)
    np.testing.assert_allclose(a.los, b.los, atol=1e-12)
    np.testing.assert_allclose(a.lidar_velocity, b.lidar_velocity, atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(
    beta=st.floats(-360, 360), gamma=st.floats(-180, 180), psi=st.floats(-360, 360),
    eps=st.floats(-180, 180), direction=st.floats(0, 360), speed=st.floats(0.5, 40),
    w=st.floats(-2, 2),
)
def test_uniform_flow_is_reconstructed_exactly(beta, gamma, psi, eps, direction, speed, w):
    scene = lj.scenes.uniform(speed, direction, w)
    mount = lj.Mount([1.0, 2.0, 3.0], beta=beta, gamma=gamma, psi=psi, epsilon=eps)
    for scan in SCANS.values():
        sim = lj.simulate(scene, scan, mount, HEIGHTS, u_ref=scene.sample(jnp.zeros(3)))
        np.testing.assert_allclose(sim.lidar_velocity, sim.point_velocity, atol=1e-11)
        np.testing.assert_allclose(sim.free_velocity, sim.point_velocity[0], atol=1e-12)
        np.testing.assert_allclose(sim.cff_U, 1.0, rtol=1e-11)
        np.testing.assert_allclose(sim.cfp_th, 0.0, atol=1e-8)
        # north-frame direction: CFD direction rotated clockwise by beta + gamma - psi + epsilon
        expected = (direction + beta + gamma - psi + eps) % 360
        got = np.asarray(sim.lidar_direction)
        np.testing.assert_allclose(lj.wrap180(got - expected), 0.0, atol=1e-8)


def test_outside_field_is_nan_and_flagged():
    scene = lj.scenes.hemisphere(radius=20.0)
    # lidar on the body's shoulder: low beams hit the hemisphere
    sim = lj.simulate(scene, SCANS["v1"], lj.Mount([-18.5, 0.0, 7.7]), [1.0, 60.0])
    assert np.isnan(sim.los[0]).any() and np.isnan(sim.lidar_velocity[0]).all()
    assert sim.flags[0] & lj.Flag.BEAM_OUTSIDE
    assert not sim.flags[1] & lj.Flag.BEAM_OUTSIDE and np.all(np.isfinite(sim.lidar_velocity[1]))


def test_no_retrace_when_numbers_change():
    scene = lj.scenes.hemisphere(20.0, 10.0, 200.0)
    lj.simulate(scene, SCANS["v1"], lj.Mount([0.0, 0.0, 21.0]), HEIGHTS, u_ref=[1.0, 0.0, 0.0])
    before = _simulate_jit._cache_size()
    for k in range(4):
        s2 = lj.scenes.hemisphere(20.0 + k, 9.0 + k, 10.0 * k)
        mount = lj.Mount([k, 1.0, 21.0 + k], beta=k * 30.0, gamma=k, psi=180.0 - k, epsilon=k)
        lj.simulate(s2, lj.windcube_v1(25.0 + k), mount, HEIGHTS + k, u_ref=[k, 1.0, 0.0])
    assert _simulate_jit._cache_size() == before


def test_vmap_over_directions_mounts_and_cones_matches_loop():
    heights = jnp.asarray(HEIGHTS)
    dirs = jnp.array([0.0, 90.0, 200.0])

    def one(direction, beta, cone):
        scene = lj.scenes.hemisphere(20.0, 10.0, direction)
        scan = lj.windcube_v2(cone)
        return lj.simulate(scene, scan, lj.Mount([3.0, 2.0, 21.0], beta=beta, psi=180.0), heights,
                           u_ref=10.0 * lj.heading(direction))

    betas = jnp.array([0.0, 45.0, 330.0])
    cones = jnp.array([20.0, 28.0, 35.0])
    batched = jax.vmap(one)(dirs, betas, cones)
    for i in range(3):
        single = one(float(dirs[i]), float(betas[i]), float(cones[i]))
        np.testing.assert_allclose(batched.los[i], single.los, rtol=1e-13)
        np.testing.assert_allclose(batched.cff_th[i], single.cff_th, atol=1e-11)


def test_vmap_over_stacked_grid_fields():
    x = np.linspace(-60, 60, 13)
    z = np.linspace(0, 120, 13)
    fields = [lj.GridField.from_function(lj.scenes.hemisphere(20.0, 10.0, d).sample, x, x, z)
              for d in (0.0, 120.0)]
    stacked = jnp.stack([f.velocity for f in fields])
    template = fields[0]
    scan, mount = SCANS["v1"], lj.Mount([0.0, 0.0, 21.0])

    def run(vel):
        f = lj.GridField(np.asarray(x), np.asarray(x), np.asarray(z), vel)
        return lj.simulate(f, scan, mount, HEIGHTS).lidar_velocity

    got = jax.vmap(run)(stacked)
    for i, f in enumerate(fields):
        np.testing.assert_allclose(got[i], lj.simulate(f, scan, mount, HEIGHTS).lidar_velocity)
    assert template.uniform == (True, True, True)


def test_float32_follows_input():
    scene64 = lj.scenes.hemisphere(20.0, 10.0, 300.0)
    scene32 = lj.scenes.hemisphere(20.0, 10.0, 300.0, dtype=jnp.float32)
    mount = lj.Mount([5.0, 1.0, 21.0], beta=30.0, psi=180.0, epsilon=3.0)
    a = lj.simulate(scene32, SCANS["zephir"], mount, HEIGHTS, u_ref=[1.0, 2.0, 0.0])
    b = lj.simulate(scene64, SCANS["zephir"], mount, HEIGHTS, u_ref=[1.0, 2.0, 0.0])
    assert a.los.dtype == jnp.float32 and a.cff_U.dtype == jnp.float32
    assert b.los.dtype == jnp.float64
    np.testing.assert_allclose(a.lidar_velocity, b.lidar_velocity, atol=2e-5)
    np.testing.assert_allclose(a.cff_th, b.cff_th, atol=5e-4)


@pytest.mark.parametrize("dtype", [jnp.float64, jnp.float32])
def test_calm_has_one_definition(dtype):
    """A uniform wind whose horizontal square is at or below ``finfo.tiny`` but nonzero (the
    speed ``sqrt(tiny)``, exactly 2**-511 or 2**-63, whose square is `tiny` itself, and below
    it) is `Flag.CALM` exactly where the simulation's and `wind_direction`'s directions are
    NaN, in every direction; above it, neither. (Gradients there: the `@example` at 2**-511
    in tests/core/test_stability_forward.py.)"""
    tiny = np.finfo(dtype).tiny
    root = float(np.sqrt(tiny))  # a power of two: the cardinal winds reconstruct exactly
    speeds = np.array([0.0, 1e-3 * root, 0.5 * root, root, 1.01 * root, 1.0])
    dirs = np.array([0.0, 90.0, 180.0, 270.0, 45.0])
    scan = lj.windcube_v2(30.0)

    def run(speed, direction):
        field = lj.scenes.Uniform(jnp.zeros(3, dtype), jnp.zeros(3, dtype), speed, direction,
                                  jnp.zeros((), dtype))
        sim = lj.simulate(field, scan, lj.Mount(jnp.zeros(3, dtype)), jnp.array([50.0], dtype))
        return sim.flags[0], sim.lidar_velocity[0], sim.lidar_direction[0]

    s, d = (jnp.asarray(a, dtype) for a in np.meshgrid(speeds, dirs, indexing="ij"))
    flags, velocity, direction = jax.jit(jax.vmap(run))(s.ravel(), d.ravel())
    calm = (np.asarray(flags) & lj.Flag.CALM) != 0
    assert velocity.dtype == dtype
    np.testing.assert_array_equal(np.isnan(direction), calm)
    np.testing.assert_array_equal(np.isnan(lj.wind_direction(velocity)), calm)
    calm = calm.reshape(speeds.size, dirs.size)
    # the cardinal winds' squares, in numpy (in the dtype, subnormals kept)
    h = np.asarray(velocity[:, :2]).reshape(speeds.size, dirs.size, 2)
    assert np.all(np.sum(h[:4, :4] ** 2, -1) <= tiny) and np.all(np.sum(h[4:] ** 2, -1) > tiny)
    assert np.all(calm[:4]) and not np.any(calm[5])  # sqrt(tiny) itself included
    assert np.all(calm[4, :4] == 0)  # 1.01 sqrt(tiny): not calm (45 degrees depends on
    # whether the backend flushes subnormal component squares: the flag and NaN agree either way)


SCENE = lj.scenes.hemisphere(20.0, 10.0, 260.0)
U_REF = 10.0 * np.asarray(lj.heading(260.0))


def loss(params, scan=SCANS["v2"]):
    """A scalar of every output family, as a function of all numeric inputs."""
    loc, angles, cone, heights, u_ref = params
    scan = lj.Scan(scan.azimuths, cone, vertical=scan.vertical, method=scan.method)
    mount = lj.Mount(loc, *angles)
    sim = lj.simulate(SCENE, scan, mount, heights, u_ref=u_ref)
    return (jnp.sum(sim.lidar_speed) + jnp.sum(sim.cff_U) + 0.1 * jnp.sum(sim.cff_th)
            + jnp.sum(sim.cfp_U) + 0.01 * jnp.sum(sim.cfp_th) + jnp.sum(sim.los ** 2) * 1e-3)


PARAMS = (jnp.array([6.0, -4.0, 20.5]), jnp.array([30.0, 5.0, 180.0, -10.0]), jnp.array(28.0),
          jnp.array([8.0, 30.0]), jnp.asarray(U_REF))


def test_gradients_match_finite_differences():
    """d/d(location, beta, gamma, psi, epsilon, cone, heights, u_ref) of every output family."""
    sizes = [int(np.size(p)) for p in PARAMS]
    flat0 = jnp.concatenate([jnp.ravel(p) for p in PARAMS])

    def f(flat):
        parts = jnp.split(flat, np.cumsum(sizes)[:-1])
        return loss(tuple(p.reshape(np.shape(q)) for p, q in zip(parts, PARAMS, strict=True)))

    assert_grad_matches_fd(jax.jit(f), flat0, eps=1e-6, rtol=2e-6, atol=1e-7)


def test_gradient_wrt_field_values_matches_jvp_and_fd():
    x = np.linspace(-60, 60, 9)
    z = np.linspace(0, 100, 6)
    vel = np.asarray(lj.GridField.from_function(lj.scenes.uniform(8.0, 250.0).sample, x, x, z).velocity)
    vel = vel + np.random.default_rng(3).normal(scale=0.3, size=vel.shape)
    mount = lj.Mount([1.0, 2.0, 1.0], beta=20.0, psi=180.0)

    def f(v):
        sim = lj.simulate(lj.GridField(x, x, z, v), SCANS["v1"], mount, HEIGHTS[:2], u_ref=U_REF)
        return jnp.sum(sim.lidar_speed) + jnp.sum(sim.cff_th)

    f = jax.jit(f)
    g = jax.grad(f)(jnp.asarray(vel))
    direction = np.random.default_rng(4).normal(size=vel.shape)
    fd = (f(vel + 1e-6 * direction) - f(vel - 1e-6 * direction)) / 2e-6
    assert np.all(np.isfinite(g))
    assert float(jnp.sum(g * direction)) == pytest.approx(float(fd), rel=1e-6)


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: lj.simulate(SCENE, SCANS["v1"], lj.Mount([0, 0, 21.0]), [0.0, 10.0]), "positive"),
        (lambda: lj.simulate(SCENE, SCANS["v1"], lj.Mount([0, 0, 21.0]), [[10.0]]), "1-D"),
        (lambda: lj.simulate(SCENE, SCANS["v1"], lj.Mount([0, 0, 21.0]), [10.0], u_ref=[1.0, 2.0]),
         "u_ref"),
        (lambda: lj.simulate(np.zeros(3), SCANS["v1"], lj.Mount([0, 0, 1.0]), [1.0]), "field"),
        (lambda: lj.Mount([0.0, 1.0]), "location"),
        (lambda: lj.Mount([0.0, 1.0, 2.0], beta=np.nan), "beta"),
        (lambda: lj.windcube_v1(0.0), r"\(0, 90\)"),
        (lambda: lj.windcube_v1(90.0), r"\(0, 90\)"),
        (lambda: lj.zephir(30.0, 2), "at least 3"),
        (lambda: lj.Scan([0.0, 0.0, 0.0, 0.0], 30.0), "cannot determine"),
        (lambda: lj.Scan([0.0, 180.0], 30.0), "cannot determine"),
        (lambda: lj.Scan([0.0, 90.0, 180.0], 30.0, method="windcube_v1"), "4 tilted beams"),
        (lambda: lj.Scan([0.0, 90.0, 180.0, 270.0], 30.0, method="windcube_v2"), "vertical"),
        (lambda: lj.Scan([0.0, 90.0, 180.0], 30.0, method="dbs"), "unknown method"),
    ],
)
def test_bad_input_raises_before_compiling(call, message):
    with pytest.raises(ValueError, match=message):
        call()
