"""Shared range-gate nodes (`lidarjax.scanning.gate_nodes`, `simulate_scan(shared_nodes=...)`):
a pulsed probe on equally spaced gates samples each beam once and weights the samples within
every gate's support. Checked against an independent numpy evaluation of the same
quadrature, against a fine per-gate reference in a random grid, and for NaN, flags, series
and gradients."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj
from lidarjax import scanning as sc

from ..helpers import assert_grad_matches_fd, central_difference

SPACING = 10.0


@pytest.fixture(scope="module")
def grid():
    rng = np.random.default_rng(3)
    x = np.arange(60) * SPACING - 300.0
    z = np.arange(12) * SPACING
    vel = rng.normal(size=(60, 60, 12, 3)) + np.array([6.0, -2.0, 0.3])
    return lj.GridField(x, x, z, vel), (x, z, vel)


@pytest.fixture(scope="module")
def ppi():
    # 25 m gates from 15 m: the first gates are cut at the lidar, the last ones leave the grid
    return sc.ppi(4.0, sc.gate_ranges(14, 25.0, first=15.0), n_rays=16, accumulation=0.2)


@pytest.fixture(scope="module")
def probe():
    return sc.instrument_probe("windcube_200s", gate_length=25.0, pulse_duration=100e-9)


MOUNT = lj.Mount([3.0, -4.0, 30.0], beta=10.0)


def numpy_trilinear_los(x, z, vel, pts, n):
    f = np.stack([(pts[..., 0] - x[0]) / SPACING, (pts[..., 1] - x[0]) / SPACING,
                  (pts[..., 2] - z[0]) / SPACING], -1)
    shape = np.array(vel.shape[:3])
    inside = np.all((f >= 0) & (f <= shape - 1), axis=-1)
    i0 = np.clip(np.floor(np.where(inside[..., None], f, 0)), 0, shape - 2).astype(int)
    t = f - i0
    out = 0.0
    for corner in np.ndindex(2, 2, 2):
        w = np.prod([t[..., a] if c else 1 - t[..., a] for a, c in enumerate(corner)], axis=0)
        v = vel[i0[..., 0] + corner[0], i0[..., 1] + corner[1], i0[..., 2] + corner[2]]
        out = out + w * np.sum(v * n, axis=-1)
    return np.where(inside, out, np.nan)


def test_shared_rule_layout(grid, ppi, probe):
    """Nodes a whole fraction h of the gate spacing apart, at most the probe's own spacing
    for the grid; symmetric; weights phi(o) summing to 1; cut at the lidar."""
    field = grid[0]
    offsets, weights = sc.gate_nodes(field, ppi, probe)
    own_o, _ = sc.gate_nodes(field, ppi, probe, shared_nodes=False)
    h = offsets[0, 1] - offsets[0, 0]
    own_h = own_o[-1, 1] - own_o[-1, 0]
    assert h <= own_h + 1e-12 and 25.0 / h == pytest.approx(round(25.0 / h))
    np.testing.assert_allclose(offsets, -offsets[:, ::-1], atol=1e-12)
    np.testing.assert_allclose(weights.sum(-1), 1.0, atol=1e-12)
    ranges = np.asarray(ppi.ranges)
    assert np.all(weights[np.abs(offsets) >= ranges[:, None]] == 0)
    assert np.all(weights[np.abs(offsets) < ranges[:, None]] > 0)
    # fewer field samples per beam than per-gate nodes
    m = round(25.0 / h)
    assert (ranges.size - 1) * m + offsets.shape[1] < ranges.size * own_o.shape[1]


def test_shared_nodes_equal_numpy_of_the_same_quadrature(grid, ppi, probe):
    """simulate_scan = sum_j w_j LOS(r + o_j) with `gate_nodes`, trilinear in numpy (NaN
    where a kept node leaves the grid)."""
    field, (x, z, vel) = grid
    res = sc.simulate_scan(field, ppi, MOUNT, probe=probe)
    offsets, weights = sc.gate_nodes(field, ppi, probe)
    n = np.asarray(res.directions)  # (r, 3)
    origin = np.asarray(res.points)[:, 0] - np.asarray(ppi.ranges)[0] * n
    node_r = np.asarray(ppi.ranges)[:, None] + offsets  # (g, q)
    pts = origin[:, None, None, :] + node_r[None, :, :, None] * n[:, None, None, :]
    los_q = numpy_trilinear_los(x, z, vel, pts, n[:, None, None, :])
    kept = weights > 0
    bad = np.any(np.isnan(los_q) & kept[None], axis=-1)
    expect = np.where(bad, np.nan, np.sum(np.where(kept[None], weights[None] * np.nan_to_num(los_q), 0), -1))
    got = np.asarray(res.los)
    assert np.array_equal(np.isnan(got), np.isnan(expect)) and np.isnan(got).any() and not np.isnan(got).all()
    np.testing.assert_allclose(got, expect, atol=1e-12)


def test_shared_and_own_nodes_both_integrate_the_probe(grid, ppi, probe):
    """In a random grid (white noise of 1 m/s: content up to its Nyquist wavenumber, the
    hardest case for a node rule), both rules agree with a per-gate rule of 201 nodes
    (within 0.05 and 0.08 m/s here), the shared one at least as well; flags agree."""
    field = grid[0]
    shared = sc.simulate_scan(field, ppi, MOUNT, probe=probe)
    own = sc.simulate_scan(field, ppi, MOUNT, probe=probe, shared_nodes=False)
    fine = sc.simulate_scan(field, ppi, MOUNT, probe=probe.with_nodes(201), shared_nodes=False)
    ok = np.isfinite(np.asarray(fine.los)) & np.isfinite(np.asarray(shared.los))
    assert ok.sum() > 150
    np.testing.assert_array_equal(np.asarray(shared.flags) & int(lj.Flag.PROBE_TRUNCATED),
                                  np.asarray(own.flags) & int(lj.Flag.PROBE_TRUNCATED))
    assert np.any(np.asarray(shared.flags) & int(lj.Flag.PROBE_TRUNCATED))
    err_shared = np.abs(np.asarray(shared.los) - np.asarray(fine.los))[ok]
    err_own = np.abs(np.asarray(own.los) - np.asarray(fine.los))[ok]
    assert err_shared.max() <= err_own.max() < 0.1
    assert np.sqrt(np.mean(err_shared**2)) < 0.02


def test_linear_field_is_exact_with_shared_nodes(probe):
    grad = np.array([[0.02, 0.0, 0.01], [0.0, -0.01, 0.0], [0.005, 0.0, 0.0]])
    f = lj.scenes.linear([6.0, -2.0, 0.2], grad)
    p = sc.ppi(7.0, sc.gate_ranges(10, 25.0, first=150.0), n_rays=6)
    res = sc.simulate_scan(f, p, MOUNT, probe=probe.with_nodes(9))
    assert sc.gate_nodes(f, p, probe.with_nodes(9))[0].shape[1] != 9  # the shared rule ran
    v = np.asarray([6.0, -2.0, 0.2]) + np.asarray(res.points) @ grad.T
    np.testing.assert_allclose(np.asarray(res.los), np.einsum("rgi,ri->rg", v, np.asarray(res.directions)),
                               atol=1e-10)


def test_unequal_gates_and_cw_keep_their_own_nodes(grid, probe):
    field = grid[0]
    p = sc.ppi(4.0, [40.0, 70.0, 95.0, 130.0], n_rays=4)
    o_shared, _ = sc.gate_nodes(field, p, probe)
    o_own, _ = sc.gate_nodes(field, p, probe, shared_nodes=False)
    np.testing.assert_array_equal(o_shared, o_own)
    cw = lj.CWProbe()
    q = sc.ppi(4.0, sc.gate_ranges(4, 25.0, first=50.0), n_rays=4)
    np.testing.assert_array_equal(sc.gate_nodes(field, q, cw)[0],
                                  sc.gate_nodes(field, q, cw, shared_nodes=False)[0])


def test_series_with_shared_nodes_matches_own_nodes():
    """Frozen turbulence through time: the shared and own rules both agree with a 301-node
    per-gate rule (0.013 and 0.036 m/s here, for LOS of 5.5 m/s spread)."""
    box = lj.synthesize_box((64, 16, 16), (4.0, 4.0, 4.0), 0.1, 20.0, 3.9, seed=2)
    field = lj.scenes.FrozenTurbulence(lj.scenes.uniform(8.0, 270.0), box, 8.0, 270.0,
                                       anchor=(-100.0, 0.0, 0.0))
    p = sc.ppi(3.0, sc.gate_ranges(12, 18.0, first=40.0), n_rays=5, mode="step", head_speed=1e9,
               accumulation=0.5)
    probe = sc.instrument_probe("halo_streamline", gate_length=18.0)
    mount = lj.Mount([0.0, 0.0, 20.0])
    shared = sc.simulate_scan_series(field, p, mount, n_scans=3, probe=probe)
    own = sc.simulate_scan_series(field, p, mount, n_scans=3, probe=probe, shared_nodes=False)
    fine = sc.simulate_scan_series(field, p, mount, n_scans=3, probe=probe.with_nodes(301),
                                   shared_nodes=False)
    assert np.isfinite(np.asarray(fine.los)).all()
    err_shared = np.abs(np.asarray(shared.los) - np.asarray(fine.los)).max()
    err_own = np.abs(np.asarray(own.los) - np.asarray(fine.los)).max()
    assert 1e-8 < err_shared <= err_own < 0.05  # two rules, both within the quadrature's error


def test_float32_shared_nodes(grid, ppi, probe):
    field64 = grid[0]
    _, (x, z, vel) = grid
    field32 = lj.GridField(x.astype(np.float32), x.astype(np.float32), z.astype(np.float32),
                           vel.astype(np.float32))
    a = np.asarray(sc.simulate_scan(field64, ppi, MOUNT, probe=probe).los)
    b = sc.simulate_scan(field32, ppi, MOUNT, probe=probe).los
    assert b.dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(b, np.float64), a, atol=2e-5, equal_nan=True)


def test_gradients_through_shared_nodes(grid, ppi, probe):
    """Derivatives with respect to the field's values and the mount (finite where the LOS
    is, FD-checked), with a loss that masks the NaN gates."""
    field, (x, z, vel) = grid
    ok = np.isfinite(np.asarray(sc.simulate_scan(field, ppi, MOUNT, probe=probe).los))

    def loss(v, loc):
        f = lj.GridField(x, x, z, v)
        los = sc.simulate_scan(f, ppi, lj.Mount(loc, beta=10.0), probe=probe).los
        return jnp.sum(jnp.where(ok, los, 0.0) ** 2)

    loc = jnp.asarray([3.0, -4.0, 30.0])
    # both reverse-mode derivatives from one pass (one forward and one transposed program),
    # then as `assert_grad_matches_fd` for the mount: forward mode and central differences
    g_v, g_loc = jax.grad(loss, argnums=(0, 1))(jnp.asarray(vel), loc)
    assert np.isfinite(np.asarray(g_v)).all() and np.abs(np.asarray(g_v)).max() > 0
    g_loc = np.asarray(g_loc)
    assert np.all(np.isfinite(g_loc)), g_loc
    at_loc = lambda at: loss(jnp.asarray(vel), at)  # noqa: E731
    np.testing.assert_allclose(g_loc, np.asarray(jax.jacfwd(at_loc)(loc)), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(g_loc, central_difference(at_loc, loc), rtol=1e-5, atol=1e-8)
    direction = jnp.asarray(np.random.default_rng(0).normal(size=vel.shape))
    v = jnp.asarray(vel)
    fd = (loss(v + 1e-6 * direction, loc) - loss(v - 1e-6 * direction, loc)) / 2e-6
    np.testing.assert_allclose(float(jnp.vdot(g_v, direction)), float(fd), rtol=1e-6)


def test_window_mean_numpy_nan_and_gradients():
    """`_window_mean` (the CPU's strided convolution): weighted means of windows ``i m ..
    i m + q - 1`` as numpy computes them, NaN exactly where a window holds a NaN sample, and
    derivatives (samples and weights) finite for a loss that masks the NaN windows, matching
    finite differences."""
    from lidarjax.beam import _window_mean as window_mean

    # compiled (m static): one program per transformation, not one per jax.numpy operation
    _window_mean = jax.jit(window_mean, static_argnums=2)
    rng = np.random.default_rng(5)
    m, q, g = 3, 7, 9
    samples = rng.normal(size=(2, 4, (g - 1) * m + q))
    samples[0, 1, 10] = np.nan
    samples[1, 3, 0] = np.nan
    phi = np.exp(-np.linspace(-1.5, 1.5, q) ** 2)
    window = np.arange(g)[:, None] * m + np.arange(q)
    expect = np.sum(samples[..., window] * phi, -1) / phi.sum()
    got = np.asarray(_window_mean(jnp.asarray(samples), jnp.asarray(phi), m))
    assert np.array_equal(np.isnan(got), np.isnan(expect)) and np.isnan(got).sum() == 3
    np.testing.assert_allclose(got, expect, atol=1e-14, equal_nan=True)
    ok = np.isfinite(expect)

    @jax.jit
    def loss(s, w):
        return jnp.sum(jnp.where(ok, window_mean(s, w, m), 0.0) ** 2)

    g_s, g_w = jax.jit(jax.grad(loss, argnums=(0, 1)))(jnp.asarray(samples), jnp.asarray(phi))
    assert np.isfinite(np.asarray(g_s)).all() and np.isfinite(np.asarray(g_w)).all()
    clean = jnp.asarray(np.nan_to_num(samples))
    assert_grad_matches_fd(lambda w: loss(jnp.asarray(samples), w), jnp.asarray(phi), rtol=1e-6,
                           jit=True)
    direction = jnp.asarray(rng.normal(size=samples.shape))
    w = jnp.asarray(phi)
    fd = (loss(clean + 1e-6 * direction, w) - loss(clean - 1e-6 * direction, w)) / 2e-6
    np.testing.assert_allclose(float(jnp.vdot(jnp.where(jnp.isnan(samples), 0, g_s), direction)),
                               float(fd), rtol=1e-6)
    # float32 follows the input dtype
    f32 = _window_mean(jnp.asarray(samples, jnp.float32), jnp.asarray(phi, jnp.float32), m)
    assert f32.dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(f32, np.float64), expect, atol=2e-6, equal_nan=True)


def test_convolution_and_gather_windows_agree(grid, probe):
    """The two ways `_gates_los` reads the gates' windows (a strided convolution on CPUs, an
    index gather on accelerators) give the same LOS, NaN and flags, also with the lidar at
    the grid's corner, where the nodes behind it are outside the grid (NaN) and the cut at
    the lidar must drop them from the near gates rather than make them NaN."""
    from lidarjax.beam import gates_los as _gates_los
    from lidarjax.beam import pattern_probe as _refine

    field = grid[0]
    p = sc.ppi(2.0, sc.gate_ranges(30, 10.0, first=6.0), n_rays=8, azimuth_start=10.0, azimuth_stop=80.0)
    chosen, rule = _refine(field, p, probe, "test", True)
    assert rule is not None and rule[1] // rule[0] >= 1  # more than one near gate
    n = np.stack([np.sin(np.deg2rad(p.azimuth)) * np.cos(np.deg2rad(2.0)),
                  np.cos(np.deg2rad(p.azimuth)) * np.cos(np.deg2rad(2.0)),
                  np.full(8, np.sin(np.deg2rad(2.0)))], -1)
    out = {}
    for corner in ([-300.0, -300.0, 40.0], [0.0, 0.0, 40.0]):
        for windows in ("convolution", "gather"):
            run = jax.jit(lambda o, w=windows: _gates_los(field, o, jnp.asarray(n), p.ranges, chosen, rule,
                                                          windows=w))
            out[windows] = [np.asarray(a) for a in run(jnp.asarray(corner))]
        (a, fa), (b, fb) = out["convolution"], out["gather"]
        assert np.array_equal(np.isnan(a), np.isnan(b)) and np.array_equal(fa, fb)
        np.testing.assert_allclose(a, b, atol=1e-12, equal_nan=True)
    # at the corner, every near gate is finite: the nodes behind the lidar (NaN) are cut
    assert np.isfinite(a[:3]).all() and fa[:3].any()
