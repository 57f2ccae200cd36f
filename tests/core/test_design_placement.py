"""`lidarjax.design_placement`: the optimiser against a dense grid search of the same
objective (hemisphere platform, committed OpenFOAM roof case), its gradients against central
finite differences, and bad input (one-line errors before compiling, or flagged results)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj
from lidarjax.design import (
    RegionBox,
    RegionPolygon,
    design_placement,
    evaluate_placements,
    placement_objective,
    placement_problem,
)

from ..helpers import DATA

R = 20.0
HEIGHTS = [10.0, 25.0, 40.0, 60.0]
DIRS = np.arange(0.0, 360.0, 30.0)  # 12 directions
ROSE = 1.0 + 0.8 * np.cos(np.deg2rad(DIRS - 270.0))  # mostly from the west
SQUARE = [(-12.0, -12.0), (12.0, -12.0), (12.0, 12.0), (-12.0, 12.0)]


def dome(x, y):
    return jnp.sqrt(jnp.maximum(R**2 - x**2 - y**2, 0.0))


def _grid(lo, hi, n):
    a = np.linspace(lo[0], hi[0], n)
    b = np.linspace(lo[1], hi[1], n)
    return np.stack(np.meshgrid(a, b, indexing="ij"), -1).reshape(-1, 2)


@pytest.fixture(scope="module")
def roof():
    scene = lj.scenes.hemisphere(radius=R, speed=10.0)
    region = RegionPolygon(SQUARE, height=1.0, surface=dome)
    kw = dict(directions=DIRS, weights=ROSE)
    res = design_placement(scene, lj.windcube_v1(), lj.Mount([0.0, 0.0, 21.0]), HEIGHTS, region,
                           **kw)
    problem = placement_problem(scene, lj.windcube_v1(), lj.Mount([0.0, 0.0, 21.0]), HEIGHTS,
                                region, **kw)[0]
    # one compiled evaluation of the objective: the dense grid and the central-difference
    # points of `test_reported_gradient_matches_central_differences`
    grid = _grid((-12.0, -12.0), (12.0, 12.0), 50)  # 2,500 candidates x 12 directions
    fd_points = _fd_points([res.x, FD_X0])
    values, ok = evaluate_placements(problem, np.concatenate([grid, fd_points, EDGE]))
    n, m = grid.shape[0], fd_points.shape[0]
    return res, problem, (grid, values[:n], ok[:n]), values[n:n + m], values[n + m:]


#: the edge x = -5 m of `test_optimum_on_a_regions_edge_or_corner_converges_there`'s region
EDGE = np.stack([np.full(61, -5.0), np.linspace(-3.0, 3.0, 61)], -1)
FD_X0 = np.array([3.0, -5.0])  # a point off the optimum, where the gradient is not small
FD_H = 1e-5


def _fd_points(xs):
    """``x + h e_i`` and ``x - h e_i`` for each ``x`` of `xs` and axis ``i``, in that order."""
    return np.array([x + s * FD_H * e for x in xs for e in np.eye(len(x)) for s in (1, -1)])


def _central(values, n_points, d):
    """Central differences from objective values at `_fd_points` of `n_points` points."""
    v = np.asarray(values, np.float64).reshape(n_points, d, 2)
    return (v[..., 0] - v[..., 1]) / (2 * FD_H)


def test_hemisphere_roof_matches_dense_grid_search_with_10x_fewer_evaluations(roof):
    res, problem, (grid, values, ok), *_ = roof
    assert res.feasible and res.converged and res.names == ("x", "y")
    assert ok.mean() > 0.5  # some corners see a beam through the dome
    best = np.nanmin(values)
    assert res.value <= 1.01 * best
    n_grid_forward = grid.shape[0] * len(DIRS)
    assert res.n_forward * 10 <= n_grid_forward, (res.n_forward, n_grid_forward)
    assert res.n_forward == res.n_evaluations * len(DIRS)
    # the optimum's location is on the roof, 1 m above the dome
    x, y, z = res.location
    np.testing.assert_allclose(z, np.sqrt(R**2 - x**2 - y**2) + 1.0, rtol=0, atol=1e-9)
    # the path starts at the start and descends
    np.testing.assert_allclose(res.path[0], res.start)
    assert np.all(np.diff(res.path_values) <= 1e-15)
    assert res.path_values[-1] == pytest.approx(res.value, rel=1e-12)
    # roses: one row per direction, sorted, C_U at the optimum better than at the start
    assert res.rose.speed_ratio.shape == (12, 4)
    np.testing.assert_allclose(np.asarray(res.rose.directions), DIRS, atol=1e-9)
    assert res.value <= res.start_value


def test_reported_gradient_matches_central_differences(roof):
    """The gradient the design reports at its optimum, and JAX's gradient of the objective
    at a point off it, against central differences of the objective (evaluated beside the
    grid search, `roof`)."""
    import jax

    res, problem, _, fd_values, _ = roof
    fd = _central(fd_values, 2, 2)
    g = np.asarray(jax.grad(lambda x: placement_objective(problem, x)[0])(jnp.asarray(FD_X0)))
    np.testing.assert_allclose(res.gradient, fd[0], rtol=1e-4, atol=1e-8)
    np.testing.assert_allclose(g, fd[1], rtol=1e-4, atol=1e-8)


def test_optimum_on_a_regions_edge_or_corner_converges_there(roof):
    """Squares of the roof beside its optimum (x = -6.8 m, y = 0; the same compiled search):
    east of it the optimum lies on the west edge x = -5 m, the best of that edge; north-east
    of it on the corner (-1, 6) m, the best of the dense grid's candidates in the square.
    Both end exactly on the bound, converged, the gradient pointing out of the region."""
    _, problem, (grid, values, ok), _, edge_values = roof
    east = RegionPolygon([(-5.0, -3.0), (-1.0, -3.0), (-1.0, 3.0), (-5.0, 3.0)], height=1.0,
                         surface=dome)
    res = design_placement(lj.scenes.hemisphere(radius=R, speed=10.0), lj.windcube_v1(),
                           lj.Mount([-3.0, 2.0, 21.0]), HEIGHTS, east, directions=DIRS,
                           weights=ROSE)
    assert res.converged and res.message == "converged"
    assert res.x[0] == -5.0 and res.gradient[0] > 0 and abs(res.gradient[1]) < 1e-9
    assert res.value <= np.min(edge_values) + 1e-12
    # the objective is even in y (the rose and the directions are): two minima on the edge
    assert abs(abs(res.x[1]) - abs(EDGE[np.argmin(edge_values), 1])) <= 0.1  # 0.1 m spacing
    assert res.path.shape[0] <= 12
    north_east = RegionPolygon([(-5.0, 2.0), (-1.0, 2.0), (-1.0, 6.0), (-5.0, 6.0)],
                               height=1.0, surface=dome)
    res = design_placement(lj.scenes.hemisphere(radius=R, speed=10.0), lj.windcube_v1(),
                           lj.Mount([-3.0, 4.0, 21.0]), HEIGHTS, north_east, directions=DIRS,
                           weights=ROSE)
    assert res.converged and res.x.tolist() == [-1.0, 6.0] and np.all(res.gradient < 0)
    inside = ok & np.all((grid >= [-5.0, 2.0]) & (grid <= [-1.0, 6.0]), axis=1)
    assert inside.sum() > 50 and res.value <= np.min(values[inside])
    np.testing.assert_allclose(res.location[2], float(dome(-1.0, 6.0)) + 1.0, rtol=1e-12)


def test_objective_surrogates_bound_the_exact_worst(roof):
    """The p-norm surrogate is below the exact worst error and above the RMS (weighted power
    means are monotone in p); the reported worst and RMS are the exact ones at the optimum."""
    res = roof[0]
    assert res.rms <= res.value <= res.worst
    e2 = (np.asarray(res.rose.speed_ratio) - 1) ** 2 + (0.01 * np.asarray(
        res.rose.direction_addend)) ** 2
    assert res.worst == pytest.approx(np.sqrt(e2.max()), rel=1e-12)


def test_uncertainty_and_cone_and_heading_variables():
    """The uncertainty objective equals sqrt(mean u(C_U)^2) of lidarjax.uncertainty at the
    same placement, and the cone angle and heading offset become decision variables."""
    scene = lj.scenes.hemisphere(radius=R, speed=10.0)
    region = RegionBox((-8.0, -8.0, 22.0), (8.0, 8.0, 22.0))
    dirs = np.array([0.0, 90.0, 180.0, 270.0])
    std = {"epsilon": 0.5, "pitch": 0.3, "roll": 0.3}
    problem = placement_problem(scene, lj.windcube_v1(), lj.Mount([0.0, 0.0, 22.0]), HEIGHTS,
                                region, directions=dirs, objective="uncertainty", std=std)[0]
    x = np.array([4.0, -3.0])
    value = float(placement_objective(problem, x)[0])
    us = []
    for d in dirs:
        s = lj.scenes.hemisphere(radius=R, speed=10.0, direction=d)
        b = lj.uncertainty(s, lj.windcube_v1(), lj.Mount([4.0, -3.0, 22.0]), HEIGHTS, std=std,
                           u_ref=10.0 * np.asarray(lj.heading(d)), outputs=["cff_U"])
        us.append(np.asarray(b.std["cff_U"]))
    np.testing.assert_allclose(value, np.sqrt(np.mean(np.square(us))), rtol=1e-10)
    res = design_placement(scene, lj.windcube_v1(), lj.Mount([0.0, 0.0, 22.0]), HEIGHTS, region,
                           directions=dirs, objective="rms", cone_angle=(15.0, 35.0),
                           heading=(-45.0, 45.0), n_coarse=27, n_starts=2)
    assert res.names == ("x", "y", "cone_angle", "heading") and res.feasible
    assert 15.0 <= res.x[2] <= 35.0 and -45.0 <= res.x[3] <= 45.0
    assert res.value <= res.start_value


def test_bad_input_errors_before_compiling():
    scene = lj.scenes.hemisphere(radius=R)
    m = lj.Mount([0.0, 0.0, 21.0])
    with pytest.raises(ValueError, match="empty region"):
        RegionBox((0.0, 0.0, 0.0), (-1.0, 1.0, 1.0))
    with pytest.raises(ValueError, match="zero area"):
        RegionPolygon([(0, 0), (1, 1), (2, 2)], height=1.0)
    with pytest.raises(ValueError, match="objective"):
        design_placement(scene, lj.windcube_v1(), m, HEIGHTS, RegionBox((0, 0, 21), (1, 1, 21)),
                         directions=DIRS, objective="best")
    grid = lj.GridField(np.arange(0.0, 50, 5), np.arange(0.0, 50, 5), np.arange(0.0, 50, 5),
                        np.ones((10, 10, 10, 3)))
    with pytest.raises(ValueError, match="outside the grid in x"):
        design_placement(grid, lj.windcube_v1(), lj.Mount([10.0, 10.0, 1.0]), HEIGHTS,
                         RegionBox((100.0, 0.0, 1.0), (120.0, 10.0, 1.0)), u_ref=[5.0, 0, 0])


def test_all_solid_region_and_non_finite_objective_are_flagged():
    """Every candidate inside the hemisphere, or a user objective that is NaN everywhere: a
    flagged result with NaN location and a message, never a converged optimum."""
    scene = lj.scenes.hemisphere(radius=R)
    m = lj.Mount([0.0, 0.0, 5.0])
    inside = RegionBox((-5.0, -5.0, 2.0), (5.0, 5.0, 8.0))
    res = design_placement(scene, lj.windcube_v1(), m, [10.0], inside, directions=[270.0],
                           n_coarse=8, n_starts=2, max_steps=5)
    assert not res.feasible and not res.converged
    assert np.all(np.isnan(res.location)) and np.isnan(res.value)
    assert "infeasible" in res.message
    res = design_placement(scene, lj.windcube_v1(), lj.Mount([0.0, 0.0, 21.0]), [10.0],
                           RegionBox((-5.0, -5.0, 21.0), (5.0, 5.0, 21.0)), directions=[270.0],
                           objective=lambda sim: jnp.nan * jnp.sum(sim.lidar_speed), n_coarse=8,
                           n_starts=2, max_steps=5)
    assert not res.feasible and np.all(np.isnan(res.x))
    # a clearance larger than the distance to the dome makes the low candidates infeasible
    problem = placement_problem(scene, lj.windcube_v1(), lj.Mount([0.0, 0.0, 21.0]), [10.0],
                                RegionBox((-5.0, -5.0, 21.0), (5.0, 5.0, 21.0)),
                                directions=[270.0], min_clearance=2.0)[0]
    assert not bool(placement_objective(problem, [0.0, 0.0])[1])  # 1 m above the top
    problem = placement_problem(scene, lj.windcube_v1(), lj.Mount([0.0, 0.0, 21.0]), [10.0],
                                RegionBox((-5.0, -5.0, 21.0), (5.0, 5.0, 21.0)),
                                directions=[270.0], min_clearance=0.5)[0]
    assert bool(placement_objective(problem, [0.0, 0.0])[1])


@pytest.fixture(scope="module")
def openfoam_roof():
    field = lj.io.load_field(DATA / "openfoam" / "windAroundBuildings_cut",
                             region=([76.0, 106.0, 20.0], [116.0, 146.0, 80.0]), spacing=2.0)
    return field


def test_openfoam_roof_case_against_grid_search(openfoam_roof):
    """The committed windAroundBuildings cut (inflow 10 m/s along +x): a lidar 1 m above the
    38 m roof (the polygon's surface read from the grid's solid nodes); the optimum is within
    1 % of a 50 x 50 grid search of the same objective, in fewer evaluations."""
    field = openfoam_roof
    # the 38 m roof (east of x = 96 the building has a lower notch, and below 34 m the cut
    # mesh ends: NaN there is "outside the cut", not a surface to stand on)
    region = RegionPolygon([(90.0, 120.0), (96.0, 120.0), (96.0, 132.0), (90.0, 132.0)],
                           height=1.0)
    kw = dict(u_ref=[10.0, 0.0, 0.0])
    heights = [10.0, 20.0, 30.0]
    mount = lj.Mount([96.0, 126.0, 39.0])
    res = design_placement(field, lj.windcube_v2(), mount, heights, region, n_coarse=36,
                           n_starts=3, max_steps=30, **kw)
    problem = placement_problem(field, lj.windcube_v2(), mount, heights, region, **kw)[0]
    grid = _grid((90.0, 120.0), (96.0, 132.0), 50)
    values, ok = evaluate_placements(problem, grid)
    assert ok.sum() > 1000
    best = np.nanmin(values)
    print("optimiser", res.location, res.value, "grid", grid[np.nanargmin(values)], best,
          res.n_evaluations)
    assert res.feasible
    assert res.value <= 1.01 * best
    assert res.n_evaluations * 10 <= grid.shape[0]
    # on the roof: 38 m + 1 m (the grid's first fluid node above the roof is at 38 m)
    assert 38.5 <= res.location[2] <= 41.0
    # the reported gradient against finite differences; trilinear interpolation has kinks on
    # node lines (the optimum may sit on one, y = 132 here): there the reported derivative is
    # one of the one-sided ones, elsewhere it is the central difference
    # (the objective's own value, also where a step leaves the polygon: not `evaluate_placements`,
    # which gives infeasible candidates NaN)
    h = 1e-5
    f = lambda x: float(placement_objective(problem, x)[0])  # noqa: E731
    f0 = f(res.x)
    for i, e in enumerate(np.eye(2)):
        up, down = (f(res.x + h * e) - f0) / h, (f0 - f(res.x - h * e)) / h
        if abs(up - down) < 1e-6 * max(abs(up), 1e-3):
            np.testing.assert_allclose(res.gradient[i], 0.5 * (up + down), rtol=1e-4, atol=1e-9)
        else:  # a kink
            assert min(up, down) - 1e-7 <= res.gradient[i] <= max(up, down) + 1e-7


def test_float32_results_follow_the_field():
    """A float32 scene gives a float32 optimum (the default solver's tolerances follow it),
    feasible and no worse than its start."""
    scene = lj.scenes.hemisphere(radius=R, speed=10.0, dtype=np.float32)
    res = design_placement(scene, lj.windcube_v1(), lj.Mount([0.0, 0.0, 22.0]),
                           np.array([10.0, 40.0], np.float32),
                           RegionBox((-8.0, -8.0, 22.0), (8.0, 8.0, 22.0)),
                           directions=[0.0, 90.0, 180.0, 270.0], n_coarse=9, n_starts=2,
                           max_steps=10)
    assert res.x.dtype == np.float32 and res.feasible
    assert res.value <= res.start_value


def test_point_target_rms_equals_simulate():
    """``target="point"``, ``objective="rms"``: the weighted RMS over directions and heights
    of ``sqrt((cfp_U - 1)^2 + (0.01 cfp_th)^2)`` from `lidarjax.simulate` run direction by
    direction (an independent loop)."""
    scene = lj.scenes.hemisphere(radius=R, speed=10.0)
    dirs = np.array([0.0, 100.0, 230.0])
    w = np.array([1.0, 2.0, 3.0])
    problem = placement_problem(scene, lj.windcube_v1(), lj.Mount([0.0, 0.0, 21.0]), HEIGHTS,
                                RegionPolygon(SQUARE, height=1.0, surface=dome), directions=dirs,
                                weights=w, objective="rms", target="point")[0]
    x = np.array([5.0, -2.0])
    z = float(dome(5.0, -2.0)) + 1.0
    e2 = []
    for d in dirs:
        sim = lj.simulate(lj.scenes.hemisphere(radius=R, speed=10.0, direction=d),
                          lj.windcube_v1(), lj.Mount([5.0, -2.0, z]), HEIGHTS)
        e2.append(np.mean((np.asarray(sim.cfp_U) - 1) ** 2
                          + (0.01 * np.asarray(sim.cfp_th)) ** 2))
    want = np.sqrt(np.sum(w / w.sum() * np.array(e2)))
    value, ok = placement_objective(problem, x)
    assert bool(ok)
    np.testing.assert_allclose(float(value), want, rtol=1e-12)
