"""Unsteady CFD as one time-dependent field (issue 20, point 6): `SnapshotField` (snapshots on
one grid, linear in time) and `FieldSequence` (loaded a window at a time) through
`simulate_series`, against closed forms and an independent analytic field."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj
from lidarjax.field import AbstractField

X = np.linspace(-120.0, 120.0, 13)
Y = np.linspace(-120.0, 120.0, 13)
Z = np.linspace(0.0, 180.0, 7)
HEIGHTS = np.array([40.0, 80.0])
A = np.array([[0.01, 0.0, 0.02], [0.0, -0.005, 0.0], [0.0, 0.0, 0.0]])  # du_i/dx_j, 1/s


def linear_u(p, t):
    """A flow linear in space and time (trilinear and time-linear interpolation are exact)."""
    p = np.asarray(p, np.float64)
    t = np.asarray(t, np.float64)[..., None]
    u0 = np.array([8.0, 1.0, 0.0]) + np.array([0.05, -0.03, 0.002]) * t
    return u0 + p @ A.T


class LinearUnsteady(AbstractField):
    """The same flow sampled directly (an independent code path: no grid, no snapshots)."""

    origin: jax.Array
    origin_lo: jax.Array

    def __init__(self, origin):
        self.origin = jnp.asarray(origin, jnp.float64)
        self.origin_lo = jnp.zeros(3)

    def sample_local(self, points):
        return self.sample_local_at(points, 0.0)

    def sample_local_at(self, points, time):
        p = points + self.origin
        t = jnp.broadcast_to(jnp.asarray(time), p.shape[:-1])[..., None]
        u0 = jnp.array([8.0, 1.0, 0.0]) + jnp.array([0.05, -0.03, 0.002]) * t
        return u0 + p @ jnp.asarray(A).T


def grid_at(fn, t, dtype=np.float64):
    pts = np.stack(np.meshgrid(X, Y, Z, indexing="ij"), axis=-1)
    return lj.GridField(X, Y, Z, fn(pts, t).astype(dtype))


SNAP_TIMES = np.arange(0.0, 61.0, 4.0)


@pytest.fixture(scope="module")
def linear_snapshots():
    return lj.SnapshotField(SNAP_TIMES, [grid_at(linear_u, t) for t in SNAP_TIMES])


SCAN, MOUNT = lj.windcube_v2(), lj.Mount([0.0, 0.0, 0.0])


@jax.jit
def _sample_at(field, points, times):
    """`field.sample_local_at`, compiled (eagerly, each of its operations compiles alone)."""
    return field.sample_local_at(points, times)


def test_sampling_is_exact_for_a_flow_linear_in_space_and_time(linear_snapshots):
    f = linear_snapshots
    rng = np.random.default_rng(3)
    p = rng.uniform([-100, -100, 5], [100, 100, 110], (50, 3))
    t = rng.uniform(0.0, 60.0, 50)
    # one call: the 50 points, three of them outside the snapshots' span or inside it again,
    # and a point outside the grid (NaN outside the span or the grid)
    pts = np.concatenate([p, p[:3], [[500.0, 0, 50]]])
    times = np.concatenate([t, [-0.1, 60.5, 30.0], [3.0]])
    got = np.asarray(_sample_at(f, jnp.asarray(pts) - f.origin, jnp.asarray(times)))
    np.testing.assert_allclose(got[:50], linear_u(p, t), rtol=0, atol=1e-12)
    d = rng.normal(size=(50, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    los = np.asarray(jax.jit(lambda f, p, d, t: f.los_local_at(p, d, t))(
        f, jnp.asarray(p) - f.origin, jnp.asarray(d), jnp.asarray(t)))
    np.testing.assert_allclose(los, np.sum(linear_u(p, t) * d, axis=1), atol=1e-12)
    out = got[50:53]
    assert np.isnan(out[:2]).all() and np.isfinite(out[2]).all()
    assert np.isnan(got[53]).all()


def test_linear_interpolation_in_time_converges_at_second_order():
    """u = U0 + a sin(w t): the time interpolation's error is bounded by a w^2 dt^2 / 8 and
    falls fourfold when the snapshot interval halves."""
    a, w = 1.5, 0.2

    def wave(p, t):
        t = np.asarray(t, np.float64)[..., None]
        return np.broadcast_to(np.array([8.0, 0.0, 0.0]) + a * np.sin(w * t) * np.array([1.0, 0.5, 0.0]),
                               np.broadcast_shapes(np.shape(p), t.shape[:-1] + (3,)))

    t_q = np.linspace(0.0, 30.0, 301)
    p = np.array([[10.0, 5.0, 50.0]])
    errs = []
    for dt in (2.0, 1.0):
        ts = np.arange(0.0, 30.0 + 1e-9, dt)
        f = lj.SnapshotField(ts, [grid_at(wave, t) for t in ts])
        got = np.asarray(_sample_at(f, jnp.asarray(p) - f.origin, jnp.asarray(t_q[:, None])))[:, 0, 0]
        err = np.abs(got - (8.0 + a * np.sin(w * t_q))).max()
        assert err <= a * w**2 * dt**2 / 8 * (1 + 1e-9)
        errs.append(err)
    assert 3.5 < errs[0] / errs[1] < 4.5


def test_series_through_snapshots_equals_the_flow_sampled_directly(linear_snapshots):
    """simulate_series through the snapshots equals the analytic unsteady flow's own series
    (LOS, reconstructions, point sensors) to rounding; the pulsed probe's average of a
    linear flow is exact too."""
    probe = lj.PulsedProbe(n_nodes=9)
    a = lj.simulate_series(linear_snapshots, SCAN, MOUNT, HEIGHTS, (1.0, 50.0), probe=probe)
    b = lj.simulate_series(LinearUnsteady(linear_snapshots.origin), SCAN, MOUNT, HEIGHTS,
                           (1.0, 50.0), probe=probe)
    for name in ("los", "velocity", "point_velocity"):
        np.testing.assert_allclose(np.asarray(getattr(a, name)), np.asarray(getattr(b, name)),
                                   rtol=0, atol=1e-10, err_msg=name)
    assert not np.asarray(a.los_flags).any() and not np.asarray(a.point_flags).any()


def test_sequence_loads_a_window_at_a_time_and_equals_all_snapshots(linear_snapshots):
    loaded, live = [], []

    def load(k):
        loaded.append(k)
        return grid_at(linear_u, SNAP_TIMES[k])

    seq = lj.FieldSequence(SNAP_TIMES, load, max_snapshots=3, name="linear run")
    orig_window = seq.window

    def window(first, last, **kw):
        live.append(last - first + 1)
        return orig_window(first, last, **kw)

    seq.window = window
    span = (2.0, 50.0)
    a = lj.simulate_series(seq, SCAN, MOUNT, HEIGHTS, span)
    b = lj.simulate_series(linear_snapshots, SCAN, MOUNT, HEIGHTS, span)
    for name in ("los", "velocity", "point_velocity", "los_time", "time"):
        np.testing.assert_allclose(np.asarray(getattr(a, name)), np.asarray(getattr(b, name)),
                                   rtol=0, atol=1e-10, err_msg=name)
    assert max(live) <= 3
    # every window holds 3 snapshots (the last one reaches 56 s); each is read once, plus the
    # first window read before compiling (validation)
    needed = set(range(0, 15))
    assert set(loaded) <= needed and len(loaded) <= len(needed) + 3
    # a run late in the sequence reads only the snapshots around it
    loaded.clear()
    late = lj.FieldSequence(SNAP_TIMES, load, max_snapshots=3, name="linear run")
    lj.simulate_series(late, SCAN, MOUNT, HEIGHTS, (42.0, 10.0))
    assert min(loaded) >= 10 and len(set(loaded)) <= 5, loaded


def test_times_outside_the_snapshots_are_nan_and_flagged(linear_snapshots):
    s = lj.simulate_series(linear_snapshots, SCAN, MOUNT, np.array([40.0, 260.0]), (50.0, 20.0))
    los, flags = np.asarray(s.los), np.asarray(s.los_flags)
    late = np.asarray(s.los_time) > 60.0
    assert late.any() and (~late).any()
    assert np.all(flags[late] & int(lj.Flag.TIME_OUTSIDE)) and np.isnan(los[late]).all()
    # 260 m is above the grid: NaN and BEAM_OUTSIDE, not TIME_OUTSIDE
    early = ~late[:, 1, :]
    assert np.all(flags[:, 1, :][early] == int(lj.Flag.BEAM_OUTSIDE))
    assert np.isfinite(los[:, 0, :][~late[:, 0, :]]).all()
    assert np.all(flags[:, 0, :][~late[:, 0, :]] == 0)
    pf = np.asarray(s.point_flags)
    assert np.all(pf[np.asarray(s.point_time) > 60.0, 0] == int(lj.Flag.TIME_OUTSIDE))


def test_sequence_refuses_what_it_cannot_fly():
    with pytest.raises(ValueError, match="strictly increasing"):
        lj.FieldSequence([0.0, 2.0, 2.0], lambda k: None)
    with pytest.raises(ValueError, match="at least two"):
        lj.FieldSequence([0.0], lambda k: None)
    with pytest.raises(ValueError, match="snapshot 1 has other axes"):
        lj.SnapshotField([0.0, 1.0], [grid_at(linear_u, 0.0),
                                      lj.GridField(X + 1.0, Y, Z, np.zeros((13, 13, 7, 3)))])
    # a scan cycle longer than a window of snapshots: say so, name the sequence
    ts = np.arange(0.0, 20.0, 0.5)
    seq = lj.FieldSequence(ts, lambda k: grid_at(linear_u, ts[k]), max_snapshots=2, name="fast run")
    with pytest.raises(ValueError, match="fast run.*max_snapshots|max_snapshots"):
        lj.simulate_series(seq, SCAN, MOUNT, HEIGHTS, (0.0, 10.0))


def test_gradients_through_the_snapshots_match_finite_differences(linear_snapshots):
    f = linear_snapshots
    p = jnp.array([[12.0, -7.0, 33.0], [40.0, 25.0, 70.0]]) - f.origin
    d = jnp.array([0.6, 0.0, 0.8])

    @jax.jit
    def loss(field, t, pts):
        return jnp.sum(field.los_local_at(pts, d, t) ** 2)

    t0 = 13.3
    g_f, g_t, g_p = jax.jit(jax.grad(loss, argnums=(0, 1, 2)))(f, t0, p)
    eps = 1e-5
    fd_t = (loss(f, t0 + eps, p) - loss(f, t0 - eps, p)) / (2 * eps)
    np.testing.assert_allclose(g_t, fd_t, rtol=1e-6)
    e = jnp.zeros_like(p).at[1, 2].set(eps)
    fd_p = (loss(f, t0, p + e) - loss(f, t0, p - e)) / (2 * eps)
    np.testing.assert_allclose(g_p[1, 2], fd_p, rtol=1e-6)
    # a random direction in the snapshots' values
    v = jnp.asarray(np.random.default_rng(0).normal(size=f.grid.velocity.shape))
    bump = lambda s: eqx.tree_at(lambda m: m.grid.velocity, f, f.grid.velocity + s * v)  # noqa: E731
    fd_v = (loss(bump(eps), t0, p) - loss(bump(-eps), t0, p)) / (2 * eps)
    np.testing.assert_allclose(jnp.sum(g_f.grid.velocity * v), fd_v, rtol=1e-6)
    # NaN outside the grid keeps gradients finite for a masked loss
    q = jnp.concatenate([p, jnp.array([[900.0, 0.0, 10.0]])])
    masked = lambda field: jnp.nansum(field.los_local_at(q, d, t0))  # noqa: E731
    assert np.isfinite(np.asarray(jax.jit(jax.grad(masked))(f).grid.velocity)).all()


def test_float32_late_in_a_long_run_keeps_its_time_resolution():
    """Snapshots a day into a run, float32: the sequence rebases each window's times in
    float64, so the LOS match float64 to float32 rounding of the velocities."""
    ts = 86_400.0 + np.arange(0.0, 41.0, 4.0)

    def flow(p, t):
        return linear_u(p, t - 86_400.0)

    seq32 = lj.FieldSequence(ts, lambda k: grid_at(flow, ts[k], np.float32), max_snapshots=4)
    seq64 = lj.FieldSequence(ts, lambda k: grid_at(flow, ts[k]), max_snapshots=4)
    span = (86_401.0, 36.0)
    a = lj.simulate_series(seq32, SCAN, MOUNT, HEIGHTS, span)
    b = lj.simulate_series(seq64, SCAN, MOUNT, HEIGHTS, span)
    assert np.asarray(a.los).dtype == np.float32
    np.testing.assert_allclose(np.asarray(a.los), np.asarray(b.los), atol=2e-5)
    assert np.isfinite(np.asarray(a.los)).all()
