"""GridField: trilinear interpolation against scipy, NaN semantics, validation, precision."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.interpolate import RegularGridInterpolator

import lidarjax as lj

RNG = np.random.default_rng(0)


def random_field(stretched: bool):
    x = np.linspace(-5.0, 5.0, 7)
    y = np.linspace(0.0, 3.0, 5)
    z = np.linspace(0.0, 2.0, 6)
    if stretched:
        x = np.cumsum(RNG.uniform(0.5, 2.0, 7)) - 4.0
        z = np.array([0.0, 0.1, 0.3, 0.7, 1.5, 3.1])
    vel = RNG.normal(size=(x.size, y.size, z.size, 3))
    return x, y, z, vel


@pytest.mark.parametrize("stretched", [False, True])
def test_matches_scipy_regular_grid_interpolator(stretched):
    x, y, z, vel = random_field(stretched)
    field = lj.GridField(x, y, z, vel)
    assert field.uniform == (not stretched, True, not stretched)
    pts = np.stack([RNG.uniform(x[0], x[-1], 500), RNG.uniform(y[0], y[-1], 500),
                    RNG.uniform(z[0], z[-1], 500)], -1)
    pts[:3] = [[x[0], y[0], z[0]], [x[-1], y[-1], z[-1]], [x[2], y[1], z[3]]]  # nodes, corners
    ref = RegularGridInterpolator((x, y, z), vel, method="linear")(pts)
    got = np.asarray(field.sample(pts))
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12)
    d = RNG.normal(size=(500, 3))
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    local = pts - np.array([x[0], y[0], z[0]])
    np.testing.assert_allclose(field.los_local(jnp.asarray(local), jnp.asarray(d)),
                               np.sum(ref * d, -1), rtol=1e-12, atol=1e-12)


def test_outside_and_solid_give_nan_never_clamped():
    x, y, z, vel = random_field(False)
    vel[3, 2, 2] = np.nan
    field = lj.GridField(x, y, z, vel)
    eps = 1e-9
    outside = np.array([[x[0] - eps, 1.0, 1.0], [x[-1] + eps, 1.0, 1.0], [0.0, y[-1] + eps, 1.0],
                        [0.0, 1.0, z[0] - eps], [np.nan, 1.0, 1.0]])
    assert np.all(np.isnan(field.sample(outside)))
    # every cell touching node (3, 2, 2) is NaN; a cell away from it is finite
    touching = np.array([[(x[3] + x[2]) / 2, (y[2] + y[1]) / 2, (z[2] + z[3]) / 2],
                         [(x[3] + x[4]) / 2, (y[2] + y[3]) / 2, (z[2] + z[1]) / 2]])
    assert np.all(np.isnan(field.sample(touching)))
    assert np.all(np.isfinite(field.sample(np.array([[x[0] + 0.1, y[0] + 0.1, z[0] + 0.1]]))))


def test_linear_field_reproduced_exactly_and_from_function():
    grad = RNG.normal(size=(3, 3))
    scene = lj.scenes.linear([1.0, -2.0, 0.5], grad, point=[0.3, 0.2, 0.1])
    x = np.array([-1.0, -0.2, 0.5, 1.7, 3.0])
    field = lj.GridField.from_function(scene.sample, x, np.linspace(-1, 1, 4), np.linspace(0, 2, 3))
    pts = RNG.uniform([-1, -1, 0], [3, 1, 2], size=(200, 3))
    np.testing.assert_allclose(field.sample(pts), scene.sample(pts), rtol=1e-12, atol=1e-12)


def test_gradients_wrt_points_and_values():
    x, y, z, vel = random_field(False)
    field = lj.GridField(x, y, z, vel)
    p = jnp.array([0.3, 1.1, 0.7])
    jac = jax.jacfwd(lambda q: field.sample(q))(p)
    h = 1e-6
    fd = np.stack([(field.sample(p + h * e) - field.sample(p - h * e)) / (2 * h)
                   for e in np.eye(3)], -1)
    np.testing.assert_allclose(jac, fd, rtol=1e-6, atol=1e-8)
    gv = jax.grad(lambda v: lj.GridField(x, y, z, v).sample(p)[0])(jnp.asarray(vel))
    assert np.isclose(float(jnp.sum(gv)), 1.0)  # trilinear weights sum to one
    assert int(jnp.sum(gv != 0)) == 8


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(x=[0.0, 1.0, 1.0]), "strictly increasing"),
        (dict(x=[0.0, 2.0, 1.0]), "strictly increasing"),
        (dict(x=[[0.0, 1.0]]), "1-D"),
        (dict(x=[0.0]), "at least 2"),
        (dict(velocity=np.zeros((3, 2, 2))), "shape"),
        (dict(velocity=np.zeros((3, 2, 3, 3))), "shape"),
        (dict(y=[0.0, np.inf]), "NaN or inf"),
        (dict(velocity=np.full((3, 2, 2, 3), np.inf)), "inf"),
    ],
)
def test_bad_grids_raise(kwargs, message):
    args = dict(x=[0.0, 1.0, 2.0], y=[0.0, 1.0], z=[0.0, 1.0], velocity=np.zeros((3, 2, 2, 3)))
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        lj.GridField(**args)


def test_float32_at_utm_coordinates():
    """Coordinates near 1e6 m keep their float64 accuracy in a float32 field."""
    e0, n0 = 512_345.678, 6_123_456.789
    grad = np.array([[0.01, 0.02, 0.0], [0.0, -0.01, 0.03], [0.0, 0.0, 0.0]])
    scene = lj.scenes.linear([8.0, -3.0, 0.0], grad, point=[0.0, 0.0, 0.0])
    x = e0 + np.linspace(0, 200, 21)
    y = n0 + np.linspace(0, 200, 21)
    z = np.linspace(0, 100, 11)
    pts64 = np.stack(np.meshgrid(x, y, z, indexing="ij"), -1) - np.array([e0, n0, 0.0])
    vel = np.asarray(scene.sample(pts64), np.float32)
    field = lj.GridField(x, y, z, jnp.asarray(vel))
    assert field.dtype == jnp.float32
    mount = lj.Mount([e0 + 101.234567, n0 + 99.876543, 5.0])
    sim = lj.simulate(field, lj.windcube_v1(), mount, jnp.array([40.0], jnp.float32))
    assert sim.los.dtype == jnp.float32
    exact = lj.simulate(scene, lj.windcube_v1(), lj.Mount([101.234567, 99.876543, 5.0]), [40.0])
    np.testing.assert_allclose(sim.los, exact.los, atol=2e-5)


@pytest.mark.parametrize("dtype, message", [
    (np.complex128, "complex"), (np.float16, "float16"), (np.dtype("U3"), "must be numbers")])
def test_velocity_dtypes_a_field_cannot_hold_are_refused_in_one_line(dtype, message):
    x = np.linspace(0.0, 10.0, 4)
    vel = np.zeros((4, 4, 4, 3), dtype=dtype)
    with pytest.raises(ValueError, match=rf"GridField: `velocity` .*{message}"):
        lj.GridField(x, x, x, vel)
