"""The exact cellPoint field behind the native path (`lidarjax.io.CellPointField`): OpenFOAM's
cellPoint at prepared points, the grid elsewhere, its gradients, the points `simulate` and a
scanning lidar sample (split from tests/io/test_openfoam_exact.py so that `--dist loadfile`
can run the two halves on different workers)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj
from lidarjax.io import CellPointField, cellpoint_field, simulate_points
from lidarjax.io.openfoam import read_openfoam_field, resample_openfoam, sample_openfoam

from ..helpers import DATA

FOAM = DATA / "openfoam"


@eqx.filter_jit
def _sample_local(field, points):
    return field.sample_local(points)


def _sample(field, points):
    """`field.sample` at absolute float64 points, compiled once per field type."""
    o64 = np.asarray(field.origin, np.float64) + np.asarray(field.origin_lo, np.float64)
    return _sample_local(field, jnp.asarray(np.asarray(points, np.float64) - o64))

WAB = FOAM / "windAroundBuildings_cut"
ROOF = np.array([96.0, 126.0, 39.0])


@pytest.fixture(scope="module")
def small():
    """The roof lidar's nodes at 5 and 10 m (9-node pulsed probe) on a small grid."""
    of = read_openfoam_field(WAB)
    scan, probe = lj.windcube_v2(), lj.PulsedProbe(n_nodes=9)
    mount = lj.Mount(ROOF, beta=0.0, gamma=0.0, psi=0.0, epsilon=0.0)
    h = np.array([5.0, 10.0])
    axes, vel, _ = resample_openfoam(of, lj.scan_bounds(scan, mount, h, probe=probe), check_points=0)
    grid = lj.GridField(*axes, vel)
    pts = lj.monitor_points(scan, mount, h, probe).points
    return of, grid, pts, scan, probe, mount, h


def test_exact_at_the_points_grid_elsewhere(small):
    """At the prepared points: OpenFOAM's cellPoint (lidarjax's reproduction, itself equal to
    OpenFOAM's probes to 5e-11 m/s); anywhere else: the grid, to rounding."""
    of, grid, pts, *_ = small
    f = cellpoint_field(of, grid, pts)
    assert isinstance(f, CellPointField) and f.resolution == grid.resolution
    ref = sample_openfoam(of, pts)
    got = np.asarray(_sample(f, pts))
    np.testing.assert_array_equal(np.isfinite(got), np.isfinite(ref))
    ok = np.isfinite(ref).all(axis=1)
    assert ok.sum() > 50
    np.testing.assert_allclose(got[ok], ref[ok], rtol=0, atol=1e-12)
    other = pts[ok][:20] + np.array([0.013, -0.021, 0.017])
    # the grid's own interpolation; two compiled programs may round a fused a*b+c differently
    # (XLA's legacy CPU emitter does, by 1 ulp): to 2 ulp
    np.testing.assert_array_max_ulp(np.asarray(_sample(f, other)), np.asarray(_sample(grid, other)),
                                    maxulp=2)
    assert np.abs(np.asarray(_sample(grid, pts[ok])) - ref[ok]).max() > 1e-3  # the grid is not exact


def test_gradients_against_finite_differences(small):
    """d(lidar speed)/d(vertex values) through `simulate` against central differences; the
    field's Jacobian in position (barycentric coordinates) against central differences of
    OpenFOAM's cellPoint (`sample_openfoam`, numpy) at points inside their tetrahedra."""
    of, grid, pts, scan, probe, mount, h = small
    f = cellpoint_field(of, grid, pts)

    def speed(values):  # the 9-node probe's middle node is the focus: the point probe's point
        g = eqx.tree_at(lambda g: g.values, f, values)
        return jnp.sum(lj.simulate(g, scan, mount, h).lidar_speed)

    assert np.isfinite(np.asarray(speed(f.values)))
    grad = np.asarray(jax.jit(jax.grad(speed))(f.values))  # one compiled gradient
    assert np.isfinite(grad).all() and np.abs(grad).max() > 0
    rng = np.random.default_rng(0)
    direction = rng.standard_normal(f.values.shape) * np.asarray(f.found)[:, None, None]
    eps = 1e-4
    fd = (float(speed(f.values + eps * direction)) - float(speed(f.values - eps * direction))) / (2 * eps)
    np.testing.assert_allclose(np.sum(grad * direction), fd, rtol=1e-7)

    # position: Jacobian (3 x 3) of the velocity at interior points of their tetrahedra
    sampler = of.sampler(of.cells_in_box(pts.min(0) - 1, pts.max(0) + 1))
    tets, w = sampler.locate(pts)
    inner = np.flatnonzero((tets >= 0) & (np.nan_to_num(w, nan=-1).min(axis=1) > 1e-3))[:6]
    assert inner.size == 6
    loose = cellpoint_field(sampler, grid, pts, tolerance=1e-3)
    o64 = np.asarray(grid.origin, np.float64) + np.asarray(grid.origin_lo, np.float64)
    q = jnp.asarray(pts[inner] - o64)
    jac = np.asarray(eqx.filter_jit(lambda f, q: jax.vmap(jax.jacfwd(f.sample_local))(q))(loose, q))
    jac_rev = np.asarray(eqx.filter_jit(lambda f, q: jax.vmap(jax.jacrev(f.sample_local))(q))(loose, q))
    np.testing.assert_allclose(jac, jac_rev, rtol=1e-12, atol=1e-12)
    step = 1e-5
    for k in range(3):
        e = np.zeros(3)
        e[k] = step
        fd = (sample_openfoam(of, pts[inner] + e) - sample_openfoam(of, pts[inner] - e)) / (2 * step)
        np.testing.assert_allclose(jac[:, :, k], fd, rtol=1e-6, atol=1e-6)


def test_simulate_points_hold_every_point_simulate_samples(small):
    """`simulate_points` (one compiled call) holds every point `monitor_points` lists (taken
    from `simulate` itself), plus the nodes behind the lidar, which `simulate` also samples."""
    _of, _grid, pts, scan, probe, mount, h = small
    sp = simulate_points(scan, mount, h, probe)
    assert sp.shape == (h.size * 5 * (probe.n_nodes + 1) + h.size, 3)
    d = np.linalg.norm(pts[:, None, :] - sp[None, :, :], axis=-1).min(axis=1)
    assert d.max() < 1e-9
    tilted = lj.Mount(ROOF, beta=10.0, gamma=5.0, psi=-3.0, epsilon=0.0, pitch=4.0, roll=-2.0)
    mp = lj.monitor_points(scan, tilted, h, probe).points
    sp = simulate_points(scan, tilted, h, probe)
    assert np.linalg.norm(mp[:, None, :] - sp[None, :, :], axis=-1).min(axis=1).max() < 1e-9


def test_refuses_bad_input(small):
    of, grid, pts, *_ = small
    with pytest.raises(ValueError, match="points"):
        cellpoint_field(of, grid, np.full((2, 3), np.nan))
    with pytest.raises(ValueError, match="grid"):
        CellPointField(object(), pts, np.zeros((len(pts), 4, 3)), np.zeros((len(pts), 4, 3)))
    with pytest.raises(ValueError, match="vertices"):
        CellPointField(grid, pts, np.zeros((1, 4, 3)), np.zeros((len(pts), 4, 3)))


def test_scanning_lidar_exact_at_its_nodes(small):
    """A PPI from the roof with a pulsed probe per gate (shared nodes): prepared at
    `lidarjax.scan_points`, every gate is the `gate_nodes`-weighted mean of OpenFOAM's
    cellPoint at its nodes (numpy, `sample_openfoam`), to 1e-10; the graded grid alone is
    off by more than 1e-3 m/s."""
    of, _grid, _pts, _scan, _probe, mount, _h = small
    pattern = lj.ppi(40.0, lj.gate_ranges(6, 3.0, first=6.0), n_rays=8, accumulation=0.5)
    probe = lj.PulsedProbe(4.0, 3.0)
    pts_box = lj.scan_points(lj.scenes.uniform(1.0, 0.0), pattern, mount, probe.with_nodes(9))
    axes, vel, _ = resample_openfoam(of, (pts_box.min(0) - 10.0, pts_box.max(0) + 10.0), check_points=0)
    grid = lj.GridField(*axes, vel)
    pts = lj.scan_points(grid, pattern, mount, probe)
    f = cellpoint_field(of, grid, pts)
    res = lj.simulate_scan(f, pattern, mount, probe=probe)
    offsets, weights = lj.gate_nodes(f, pattern, probe)
    assert offsets.shape != lj.gate_nodes(f, pattern, probe, shared_nodes=False)[0].shape  # shared
    n = np.asarray(res.directions)
    node_r = np.asarray(pattern.ranges)[:, None] + offsets  # (g, q)
    nodes = np.asarray(mount.location)[None, None, None] + node_r[None, :, :, None] * n[:, None, None, :]
    v = sample_openfoam(of, nodes.reshape(-1, 3)).reshape(nodes.shape)
    los_q = np.einsum("rgqi,ri->rgq", v, n)
    kept = weights > 0
    bad = np.any(np.isnan(los_q) & kept[None], axis=-1)
    expect = np.where(bad, np.nan, np.sum(np.where(kept[None], weights[None] * np.nan_to_num(los_q), 0), -1))
    got = np.asarray(res.los)
    assert np.isfinite(expect).sum() > 30
    np.testing.assert_array_equal(np.isnan(got), np.isnan(expect))
    np.testing.assert_allclose(got, expect, rtol=0, atol=1e-10)
    graded = np.asarray(lj.simulate_scan(grid, pattern, mount, probe=probe).los)
    assert np.nanmax(np.abs(graded - expect)) > 1e-3


def test_sensitivity_on_a_mesh_matches_finite_differences_of_the_exact_path(small):
    """The Jacobian of the lidar speed w.r.t. the mount location (`lidarjax.sensitivity` on
    a `CellPointField`) against central differences of the exact path itself: the field
    prepared again, by the mesh's cellPoint, at the moved mount's own nodes; and w.r.t. the
    vertex values (linear: against a central difference of one value). A generic mount (off
    the mesh's planes, beams off the axes) keeps every node inside its tetrahedron."""
    of, _, _, scan, probe, _, h = small
    mount = lj.Mount([96.31, 125.73, 39.17], beta=7.0)
    region = lj.scan_bounds(scan, mount, h, probe=probe)
    lo, hi = region
    axes, vel, _ = resample_openfoam(of, (np.asarray(lo) - 1.0, np.asarray(hi) + 1.0),
                                     check_points=0)
    grid = lj.GridField(*axes, vel)
    sampler = of.sampler(of.cells_in_box(np.asarray(lo) - 2.0, np.asarray(hi) + 2.0))

    def exact(m):
        return cellpoint_field(sampler, grid, simulate_points(scan, m, h, probe))

    f = exact(mount)
    u_ref = jnp.array([10.0, 0.0, 0.0])
    sens = lj.sensitivity(f, scan, mount, h, u_ref=u_ref, probe=probe, wrt=("location",),
                          outputs=("lidar_speed",))
    jac = np.asarray(sens.jacobian["lidar_speed"])  # (h, 3)
    assert np.isfinite(jac).all()
    eps = 1e-4
    fd = np.zeros_like(jac)
    for a in range(3):
        speeds = []
        for sgn in (1.0, -1.0):
            loc = np.asarray(mount.location, np.float64).copy()
            loc[a] += sgn * eps
            m = lj.Mount(loc, beta=7.0)
            speeds.append(np.asarray(lj.simulate(exact(m), scan, m, h, u_ref=u_ref,
                                                 probe=probe).lidar_speed))
        fd[:, a] = (speeds[0] - speeds[1]) / (2 * eps)
    np.testing.assert_allclose(jac, fd, rtol=1e-5, atol=1e-7)
    assert np.abs(jac).max() > 1e-3  # the roof's shear: the location matters

    def speed(values):
        g = eqx.tree_at(lambda x: x.values, f, values)
        return lj.simulate(g, scan, mount, h, u_ref=u_ref, probe=probe).lidar_speed[0]

    grad = np.asarray(jax.grad(speed)(f.values))
    k = np.unravel_index(np.argmax(np.abs(grad)), grad.shape)
    bump = np.zeros(grad.shape)
    bump[k] = 1e-3
    fd_v = (float(speed(f.values + bump)) - float(speed(f.values - bump))) / 2e-3
    assert np.isclose(grad[k], fd_v, rtol=1e-6), (grad[k], fd_v)
