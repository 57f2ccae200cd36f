"""The design search's local stage on cheap objectives with closed-form optima: a box whose
optimum is a corner, one whose optimum is on an edge, and one whose optimum is inside. The
default local search (`BoxBFGS`, projected BFGS with an active set) stops exactly on the bound
and reports `converged`; an optimistix minimiser in sigmoid variables never reaches it."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

from lidarjax.design import _search

LO = jnp.array([0.0, -1.0])
HI = jnp.array([2.0, 1.0])


def _quadratic(c, x):
    """A convex quadratic with its unconstrained minimum at `c` (coupled axes)."""
    d = x - c
    return d[0] ** 2 + 3.0 * d[1] ** 2 + 0.5 * d[0] * d[1], jnp.asarray(True), x


def _search_at(c, solver=None, max_steps=60):
    solver = _search.default_solver(LO.dtype) if solver is None else solver
    return _search.search(_quadratic, jnp.asarray(c, LO.dtype), LO, HI, n_coarse=16, n_starts=2,
                          solver=solver, max_steps=max_steps)


def _gradient(c, x):
    d = np.asarray(x) - np.asarray(c)
    return np.array([2 * d[0] + 0.5 * d[1], 6 * d[1] + 0.5 * d[0]])


def test_corner_optimum_converges_exactly_on_the_bounds():
    """The minimum (3, 2) lies beyond both upper bounds: the optimum is the corner (2, 1),
    reached exactly, converged in a few steps, the reported gradient the objective's there
    (pointing out of the box: both components negative)."""
    res = _search_at([3.0, 2.0])
    assert res["converged"] and res["feasible"]
    assert res["x"].tolist() == [2.0, 1.0]
    assert res["value"] == pytest.approx(1.0 + 3.0 + 0.5)
    np.testing.assert_allclose(res["gradient"], _gradient([3.0, 2.0], [2.0, 1.0]), rtol=1e-12)
    assert np.all(res["gradient"] < 0)
    assert res["steps"].max() <= 6, res["steps"]


def test_edge_optimum_converges_on_the_bound_with_the_free_variable_at_its_minimum():
    """The minimum (1, -3) lies below the lower bound of y: the optimum is on the edge
    y = -1, with x minimising the objective along it: 2 (x - 1) + 0.5 (-1 + 3) = 0, x = 0.5;
    the gradient there is zero along the edge and points out of the box across it."""
    res = _search_at([1.0, -3.0])
    assert res["converged"]
    assert res["x"][1] == -1.0
    assert res["x"][0] == pytest.approx(0.5, abs=1e-6)
    g = res["gradient"]
    assert abs(g[0]) < 1e-6 and g[1] > 0
    np.testing.assert_allclose(g, _gradient([1.0, -3.0], res["x"]), rtol=1e-9, atol=1e-12)
    assert res["steps"].max() <= 15, res["steps"]


def test_interior_optimum_and_an_optimistix_solver():
    """An interior minimum: found to the tolerance by both local searches. An optimistix
    minimiser (sigmoid variables) still serves, but on a corner it runs to `max_steps`."""
    for solver in (None, optx.BFGS(rtol=1e-6, atol=1e-9)):
        res = _search_at([0.7, 0.3], solver)
        assert res["converged"]
        np.testing.assert_allclose(res["x"], [0.7, 0.3], atol=1e-6)
        assert np.all(np.abs(res["gradient"]) < 1e-6)
    res = _search_at([3.0, 2.0], optx.BFGS(rtol=1e-6, atol=1e-9), max_steps=20)
    assert not res["converged"] and res["steps"].min() == 20
    np.testing.assert_allclose(res["x"], [2.0, 1.0], atol=1e-3)
