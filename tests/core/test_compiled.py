"""`lidarjax._util.compiled`: small public array functions run as one compiled program."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj
from lidarjax._util import compiled
from lidarjax.response import _fit


def _counted():
    traces = []

    @compiled
    def f(x, y):
        traces.append(1)
        return jnp.sin(x) * y

    return f, traces


def test_numbers_and_lists_are_dynamic_inputs():
    f, traces = _counted()
    for k in range(4):  # four values of a Python number: one trace
        np.testing.assert_allclose(f(0.1 * k, [1.0, 2.0]), np.sin(0.1 * k) * np.array([1.0, 2.0]),
                                   rtol=1e-15)
    assert len(traces) == 1
    f(0.3, np.array([3.0, 4.0]))  # a numpy array of the same shape: no new trace
    assert len(traces) == 1
    f(0.3, (1.0, 2.0, 3.0))  # a new shape traces again
    assert len(traces) == 2
    for k in range(3):  # by keyword: dynamic too, and the positional call's program
        np.testing.assert_allclose(f(0.2, y=[1.0 + k, 2.0]), np.sin(0.2) * np.array([1.0 + k, 2.0]),
                                   rtol=1e-15)
    assert len(traces) == 2


def test_inside_transformations_and_for_methods():
    f, _ = _counted()
    g = jax.grad(lambda x: f(x, 2.0))(0.4)
    assert g == pytest.approx(2 * np.cos(0.4), rel=1e-14)
    vm = jax.jit(jax.vmap(lambda x: f(x, 1.0)))(jnp.arange(3.0))
    np.testing.assert_allclose(vm, np.sin(np.arange(3.0)), rtol=1e-15)

    class Scale(eqx.Module):
        a: jax.Array
        label: str = eqx.field(static=True)

        @compiled
        def __call__(self, x):
            return self.a * x

    s = Scale(jnp.asarray(3.0), "x")
    assert float(s(2.0)) == 6.0
    assert float(jax.grad(lambda a: Scale(a, "x")(2.0))(1.0)) == 2.0


def test_public_helpers_keep_their_results_and_errors():
    v = np.array([[3.0, 4.0, 0.5], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(lj.horizontal_speed(v), [5.0, 0.0])
    d = lj.wind_direction([-1.0, 0.0, 0.0])  # a list, as before
    assert float(d) == pytest.approx(90.0)
    assert np.isnan(lj.wind_direction(v)[1])
    assert float(lj.wrap180(190)) == -170.0
    knots = np.arange(0.0, 360.0, 30.0)
    spline = _fit(knots, np.cos(np.deg2rad(knots))[:, None] * np.ones((1, 2)), np.float64)
    np.testing.assert_allclose(spline(60.0), [0.5, 0.5], rtol=1e-12)  # at a knot
    with pytest.raises(ValueError, match="per_row"):
        spline.per_row(np.zeros((2, 3)))
