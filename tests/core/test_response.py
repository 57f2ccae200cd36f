"""ResponseTable: periodic spline evaluation, convergence order, construction, validation."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.interpolate import CubicSpline

import lidarjax as lj

from .. import sites


def _smooth(d):
    """A periodic test response with several harmonics, shaped (n, 2, 3)."""
    r = np.deg2rad(np.asarray(d, np.float64))[:, None, None]
    k = np.arange(2)[None, :, None] + 1.0
    b = np.arange(3)[None, None, :] * 0.7
    return np.exp(np.sin(r + b)) * k + 0.3 * np.cos(3 * r - b) / k


def _order(spacings, errors):
    return np.polyfit(np.log(spacings), np.log(errors), 1)[0]


def test_matches_scipy_periodic_cubic_spline_non_uniform():
    rng = np.random.default_rng(0)
    d = np.sort(rng.choice(np.arange(0.0, 360.0, 2.5), size=23, replace=False))
    values = _smooth(d)
    table = lj.ResponseTable(d, values)
    ref = CubicSpline(np.append(d, d[0] + 360), np.concatenate([values, values[:1]]),
                      axis=0, bc_type="periodic")
    x = rng.uniform(-720.0, 720.0, 400)
    xw = np.mod(x - d[0], 360.0) + d[0]
    np.testing.assert_allclose(table.response_at(x), ref(xw), rtol=0, atol=1e-12)
    dx = table.response_spline.derivative(jnp.asarray(x))
    np.testing.assert_allclose(dx, ref(xw, 1), rtol=0, atol=1e-12)
    assert not table.response_spline.uniform


def test_any_order_of_directions_gives_the_same_table():
    d = np.array([0.0, 40.0, 100.0, 190.0, 300.0])
    values = _smooth(d)
    perm = np.array([3, 0, 4, 1, 2])
    a = lj.ResponseTable(d, values)
    b = lj.ResponseTable(d[perm] - 360.0, values[perm])  # shuffled and shifted by a period
    x = np.linspace(-30, 400, 97)
    np.testing.assert_allclose(a.response_at(x), b.response_at(x), atol=1e-13)
    np.testing.assert_allclose(b.directions, d)


def test_periodic_continuous_and_differentiable_across_the_wrap():
    d = np.arange(0.0, 360.0, 30.0) + 7.0
    table = lj.ResponseTable(d, _smooth(d))
    f = lambda x: table.response_at(x)[..., 1, 2]  # noqa: E731
    g = jax.grad(f)
    h = jax.grad(g)
    f, g, h = (jax.jit(jax.vmap(fn)) for fn in (f, g, h))
    x = np.array([0.0, 7.0, 359.0, 3.0])
    np.testing.assert_allclose(f(x), f(x + 360.0), atol=1e-12)
    np.testing.assert_allclose(f(x), f(x - 720.0), atol=1e-12)
    # continuity of value, first and second derivative at the wrap (knot at 7 deg)
    for fn in (f, g, h):
        left, right = fn(np.array([7.0 - 1e-9, 367.0 - 1e-9])), fn(np.array([7.0 + 1e-9, 7.0]))
        np.testing.assert_allclose(left, right, atol=1e-6)
    # gradient matches central differences
    x = np.array([3.0, 100.3, 355.5])
    np.testing.assert_allclose(g(x), (f(x + 1e-5) - f(x - 1e-5)) / 2e-5, rtol=1e-6)


@pytest.mark.parametrize("layout", ["uniform", "zephycube"])
def test_convergence_order_at_least_cubic_spline(layout):
    """Max error against the exact response falls like spacing**4 (measured order)."""
    x = np.linspace(0.0, 360.0, 2001)[:-1] + 0.123
    exact = _smooth(x)
    spacings, errors = [], []
    for level in range(4):
        f = 2.0**level
        if layout == "uniform":
            d = np.arange(0.0, 360.0, 30.0 / f)
        else:  # ZephyCube's plan: 5 deg over the prevailing sector, 15 deg elsewhere, refined
            d = np.concatenate([np.arange(0.0, 80.0, 5.0 / f), np.arange(80.0, 360.0, 15.0 / f)])
        table = lj.ResponseTable(d, _smooth(d))
        errors.append(np.max(np.abs(np.asarray(table.response_at(x)) - exact)))
        spacings.append(15.0 / f)
    order = _order(spacings, errors)
    assert order > 3.7, (order, errors)


def test_from_simulations_normalises_and_tabulates_everything():
    table = sites.table(30.0, fields=True)
    assert table.response.shape == (12, len(sites.HEIGHTS), 5)
    # north-frame directions: CFD directions + the software north offset
    np.testing.assert_allclose(table.directions, np.arange(0.0, 360.0, 30.0) + sites.EPSILON,
                               atol=1e-9)
    sim = sites.records([60.0], 7.0)  # CFD 60 deg = north 70 deg, a tabulated direction
    np.testing.assert_allclose(table.response_at(70.0), sim.los[0] / 7.0, atol=1e-12)
    np.testing.assert_allclose(table.reconstructed_at(70.0), sim.lidar_velocity[0] / 7.0,
                               atol=1e-12)
    np.testing.assert_allclose(table.point_at(70.0), sim.point_velocity[0] / 7.0, atol=1e-12)
    # beam vectors in the north frame project the beam-point velocity onto the LOS
    proj = jnp.einsum("hbk,bk->hb", table.beam_velocity_at(70.0), table.beam_vectors)
    np.testing.assert_allclose(proj, table.response_at(70.0), atol=1e-12)
    centre = table.centre_projection_at(70.0)
    np.testing.assert_allclose(centre[:, -1], table.point_at(70.0)[:, 2], atol=1e-12)
    # a list of Simulations gives the same table as a stacked one
    runs = [jax.tree_util.tree_map(lambda a, i=i: a[i], sites.records([0.0, 120.0, 240.0], 3.0))
            for i in range(3)]
    a = lj.ResponseTable.from_simulations(runs)
    b = lj.ResponseTable.from_simulations(sites.records([0.0, 120.0, 240.0], 3.0))
    np.testing.assert_allclose(a.response, b.response)
    assert a.point is not None and a.beam_vectors is None


def test_beams_missing_in_every_run_are_kept_as_missing():
    d = np.arange(0.0, 360.0, 45.0)
    values = _smooth(d)
    values[:, 1, 2] = np.nan
    table = lj.ResponseTable(d, values)
    assert not bool(table.valid[1, 2]) and bool(table.valid.sum() == 5)
    out = table.response_at(np.array([10.0, 200.0]))
    assert np.all(np.isnan(out[:, 1, 2])) and np.all(np.isfinite(out[:, 0]))


def test_float32_table_stays_float32():
    d = np.arange(0.0, 360.0, 30.0)
    table = lj.ResponseTable(d, _smooth(d).astype(np.float32))
    assert table.dtype == jnp.float32
    assert table.response_at(np.float32(12.5)).dtype == jnp.float32


@pytest.mark.parametrize(
    "directions, response, match",
    [
        ([0.0, 90.0], np.zeros((2, 1, 1)), "at least 3"),
        ([0.0, 90.0, 360.0], np.zeros((3, 1, 1)), "unique modulo 360"),
        ([0.0, 90.0, 90.0], np.zeros((3, 1, 1)), "unique modulo 360"),
        ([0.0, 90.0, np.nan], np.zeros((3, 1, 1)), "finite"),
        ([0.0, 90.0, 180.0], np.zeros((3, 2)), r"\(s, h, b\)"),
        ([0.0, 90.0, 180.0], np.zeros((4, 2, 2)), r"\(s, h, b\)"),
        ([0.0, 90.0, 180.0], np.array([[[1.0]], [[np.nan]], [[1.0]]]), "NaN at direction 90"),
    ],
)
def test_validation(directions, response, match):
    with pytest.raises(ValueError, match=match):
        lj.ResponseTable(directions, response)


def test_validation_of_optional_arrays_and_simulations():
    d = [0.0, 120.0, 240.0]
    with pytest.raises(ValueError, match="reconstructed"):
        lj.ResponseTable(d, np.zeros((3, 2, 4)), reconstructed=np.zeros((3, 2, 2)))
    with pytest.raises(ValueError, match="beam_vectors"):
        lj.ResponseTable(d, np.zeros((3, 2, 4)), beam_vectors=np.ones((4, 3)))
    table = lj.ResponseTable(d, np.zeros((3, 2, 4)))
    with pytest.raises(ValueError, match="no `point`"):
        table.point_at(3.0)
    no_ref = lj.simulate(sites.scene(0.0), sites.SCAN, sites.MOUNT, jnp.asarray(sites.HEIGHTS))
    with pytest.raises(ValueError, match="u_ref"):
        lj.ResponseTable.from_simulations([no_ref, no_ref, no_ref])
    with pytest.raises(ValueError, match="`fields` needs `mount`"):
        lj.ResponseTable.from_simulations(sites.records([0.0, 1.0, 2.0], 1.0), fields=[None] * 3)
