"""Frozen turbulence: Taylor advection of a turbulence box over a mean field.

Closed forms: a box made of one exact Fourier mode must give the advected cosine (apart from
the trilinear error, which falls as h^2), in float64 and float32 at hour-long advections."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax
from lidarjax import scenes
from lidarjax.scenes.turbulence import FrozenTurbulence, advected_distance
from lidarjax.turbulence import TurbulenceBox

from ..helpers import assert_grad_matches_fd


def mode_box(n=(32, 16, 8), spacing=(8.0, 6.0, 5.0), m=(3, 1, 1), amp=(1.0, 0.5, -0.3), phase=0.4,
             dtype=jnp.float64, periodic=True):
    """A periodic box holding one Fourier mode per component: ``a_c cos(k . x + phase)``."""
    n, s = np.asarray(n), np.asarray(spacing, float)
    k = 2 * np.pi * np.asarray(m) / (n * s)
    x = np.arange(n[0]) * s[0]
    y = (np.arange(n[1]) - (n[1] - 1) / 2) * s[1]
    z = np.arange(n[2]) * s[2]
    X, Y, Z = np.meshgrid(x, y, z, indexing="ij")
    c = np.cos(k[0] * X + k[1] * Y + k[2] * Z + phase)
    vel = np.stack([a * c for a in amp], axis=-1)
    return TurbulenceBox(jnp.asarray(vel, dtype), jnp.asarray(s, dtype), periodic=(periodic, periodic)), k


def mode_exact(points, t, k, amp, phase, speed, direction, anchor=(0.0, 0.0, 0.0)):
    """The closed form in the CFD frame (float64 numpy)."""
    d = np.deg2rad(direction)
    ex = np.array([-np.sin(d), -np.cos(d), 0.0])
    ey = np.array([-ex[1], ex[0], 0.0])
    ez = np.array([0.0, 0.0, 1.0])
    rel = np.asarray(points, float) - anchor
    xi = rel @ ex - speed * np.asarray(t, float)
    arg = k[0] * xi + k[1] * (rel @ ey) + k[2] * (rel @ ez) + phase
    c = np.cos(arg)[..., None]
    return c * (amp[0] * ex + amp[1] * ey + amp[2] * ez)


AMP, PHASE = (1.0, 0.5, -0.3), 0.4

# compiled once per shape and shared by the tests (eager dispatch of the kernel is slow)
sample_at = eqx.filter_jit(lambda f, p, t: f.sample_local_at(p, t))
fluct_at = eqx.filter_jit(lambda f, p, t: f.fluctuation_at(p, t))
los_at = eqx.filter_jit(lambda f, p, d, t: f.los_local_at(p, d, t))


def test_taylor_shift_and_nodes_exact():
    box, k = mode_box()
    mean = scenes.uniform(9.0, 250.0)
    f = FrozenTurbulence(mean, box, 9.0, 250.0)
    # at t = 0 the field equals the mean plus the box node values at the nodes
    ex = np.asarray(f.axes())
    nodes = np.array([[3 * 8.0, (2 - 7.5) * 6.0, 2 * 5.0]])  # box coordinates of node (3, 2, 2)
    p = nodes @ ex  # local point with those box coordinates (anchor 0)
    got = sample_at(f, jnp.asarray(p), 0.0) - sample_at(mean, jnp.asarray(p), 0.0)
    want = np.asarray(box.velocity[3, 2, 2]) @ ex
    np.testing.assert_allclose(got[0], want, atol=1e-12)
    # Taylor: the field at p + U t e_x and time t equals the field at p and time 0
    q = jnp.asarray([[12.0, -7.0, 13.0], [200.0, 40.0, 22.0]])
    for t in (1.7, 95.0, 600.0):
        later = sample_at(f, q + 9.0 * t * ex[0], t)
        np.testing.assert_allclose(later, sample_at(f, q, 0.0), atol=1e-9)


@pytest.mark.parametrize("direction", [270.0, 200.0])
def test_fourier_mode_closed_form_second_order(direction):
    """Error against the closed form falls as h^2 under grid refinement."""
    rng = np.random.default_rng(1)
    pts = rng.uniform([-300, -40, 2], [300, 40, 30], size=(200, 3))
    ts = rng.uniform(0, 600, size=200)
    errs = []
    for r in (1, 2, 4):
        box, k = mode_box(n=(32 * r, 16 * r, 8 * r), spacing=(8.0 / r, 6.0 / r, 5.0 / r))
        f = FrozenTurbulence(scenes.uniform(0.0, direction), box, 8.5, direction)
        got = np.asarray(fluct_at(f, jnp.asarray(pts), jnp.asarray(ts)))
        want = mode_exact(pts, ts, k, AMP, PHASE, 8.5, direction)
        errs.append(np.max(np.abs(got - want)))
    errs = np.array(errs)
    order = np.log2(errs[:-1] / errs[1:])
    assert errs[0] < 0.15  # modes 8 to 16 cells long: (k h)^2 / 8 per axis
    np.testing.assert_allclose(order, 2.0, atol=0.15)


def test_non_periodic_gives_nan_outside_and_periodic_wraps():
    box, k = mode_box(periodic=False)
    f = FrozenTurbulence(scenes.uniform(10.0, 270.0), box, 10.0, 270.0)
    half = 7.5 * 6.0
    inside = jnp.asarray([[5.0, half - 1e-6, 35.0], [5.0, -half, 0.0]])
    outside = jnp.asarray([[5.0, half + 0.1, 10.0], [5.0, 0.0, 35.1], [5.0, 0.0, -0.1]])
    assert np.all(np.isfinite(sample_at(f, inside, 3.0)))
    assert np.all(np.isnan(sample_at(f, outside, 3.0)))
    # gradient of a loss that masks the NaN out stays finite
    g = jax.grad(lambda a: jnp.nansum(fluct_at(f, outside * a, 3.0)) + 0 * a)(1.0)
    assert np.isfinite(g)
    boxp, _ = mode_box(periodic=True)
    fp = FrozenTurbulence(scenes.uniform(10.0, 270.0), boxp, 10.0, 270.0)
    wrap = jnp.asarray([[5.0, 16 * 6.0, 8 * 5.0]])
    np.testing.assert_allclose(sample_at(fp, wrap, 0.0),
                               sample_at(fp, jnp.asarray([[5.0, 0.0, 0.0]]), 0.0), atol=1e-12)


def long_advection_pair(n_points):
    """The same Fourier-mode box advected at 10.3 m/s in float32 and float64, and float32
    points: ``(u, points, f32, f64)``."""
    u = float(np.float32(10.3))
    rng = np.random.default_rng(2)
    pts = rng.uniform([-100, -40, 2], [100, 40, 30], size=(n_points, 3)).astype(np.float32)
    b64, _ = mode_box()
    b32, _ = mode_box(dtype=jnp.float32)
    f64 = FrozenTurbulence(scenes.uniform(0.0, 263.0), b64, u, 263.0)
    f32 = FrozenTurbulence(scenes.uniform(0.0, 263.0, dtype=jnp.float32), b32, np.float32(u),
                           np.float32(263.0))
    return u, pts, f32, f64


def test_float32_long_advection():
    """float32 stays accurate (to ~1e-5 of the amplitude) at 10 minutes, an hour and a day
    of advection, where the advected distance is 6 km to 900 km."""
    u, pts, f32, f64 = long_advection_pair(64)
    assert f32.dtype == jnp.float32
    for t in (600.0, 3600.0, 86400.0):
        tt = np.float32(t + 0.37)
        a = np.asarray(sample_at(f32, jnp.asarray(pts), tt))
        assert a.dtype == np.float32
        b = np.asarray(sample_at(f64, jnp.asarray(pts, jnp.float64), float(tt)))
        np.testing.assert_allclose(a, b, atol=2e-5)
    # the naive float32 product loses this: U t at a day is 0.06 m coarse
    assert abs(float(advected_distance(jnp.float32(u), jnp.float32(86400.37), jnp.float32(256.0)))
               - np.mod(u * float(np.float32(86400.37)), 256.0)) < 1e-4


def test_advanced_equals_later_time():
    box, _ = mode_box()
    f = FrozenTurbulence(scenes.uniform(10.0, 270.0), box, 10.0, 270.0)
    pts = jnp.asarray([[3.0, 4.0, 5.0], [-30.0, 10.0, 20.0]])
    year = 365.25 * 86400
    g = f.advanced(year)
    assert 0 <= float(g.shift) < float(box.length)
    np.testing.assert_allclose(sample_at(g, pts, 12.5), sample_at(f, pts, year + 12.5),
                               atol=1e-9)
    traced = jax.jit(lambda tt: f.advanced(tt).sample_local_at(pts, 1.0))(100.0)
    np.testing.assert_allclose(traced, sample_at(f, pts, 101.0), atol=1e-12)


def test_vmap_over_time_and_mean_grid():
    box, _ = mode_box()
    rng = np.random.default_rng(5)
    grid = lidarjax.GridField(np.linspace(-400, 400, 9) + 5e5, np.linspace(-200, 200, 5) + 6e6,
                              np.linspace(1, 41, 5), 8.0 + rng.normal(size=(9, 5, 5, 3)))
    f = FrozenTurbulence(grid, box, 8.0, 270.0, anchor=(0.0, 0.0, 1.0))
    pts = jnp.asarray([[3.0, 4.0, 5.0], [-30.0, 10.0, 20.0]])
    ts = jnp.linspace(0.0, 30.0, 7)
    many = jax.vmap(lambda t: sample_at(f, pts, t))(ts)
    one = sample_at(f, pts[None], ts[:, None])
    np.testing.assert_allclose(many, one, atol=1e-12)
    assert many.shape == (7, 2, 3)
    # the absolute-coordinate interface goes through the grid's origin
    absolute = eqx.filter_jit(lambda f, p: f.sample(p))
    np.testing.assert_allclose(absolute(f, grid.origin + pts), sample_at(f, pts, 0.0), atol=1e-9)


def assert_los_gradients_match_fd(los_at):
    """Gradients of a summed LOS with respect to time, speed, direction, anchor and the box
    values (through a scale factor) match finite differences; ``los_at(field, points,
    direction, t)`` samples the field."""
    box, _ = mode_box(n=(16, 8, 8))
    mean = scenes.uniform(10.0, 250.0)
    pts = jnp.asarray([[13.0, 4.0, 7.0], [-31.0, 10.0, 21.0]])
    dirn = jnp.asarray([0.3, -0.2, 0.9])

    def los(params):
        t, u, d, ax, scale = params
        f = FrozenTurbulence(mean, box.scaled(scale), u, d, anchor=jnp.stack([ax, 0.0, 0.0]))
        return jnp.sum(los_at(f, pts, dirn, t))

    assert_grad_matches_fd(jax.jit(los), jnp.asarray([123.4, 9.3, 251.0, 2.0, 1.3]), eps=1e-5,
                           rtol=1e-5, atol=1e-7)


def test_gradients_time_speed_direction_box():
    assert_los_gradients_match_fd(lambda f, p, d, t: f.los_local_at(p, d, t))


def test_bad_input():
    box, _ = mode_box()
    with pytest.raises(ValueError, match="shape"):
        TurbulenceBox(np.zeros((4, 4, 4)), (1.0, 1.0, 1.0))
    with pytest.raises(ValueError, match="spacing"):
        TurbulenceBox(np.zeros((4, 4, 4, 3)), (1.0, -1.0, 1.0))
    with pytest.raises(ValueError, match="NaN"):
        TurbulenceBox(np.full((4, 4, 4, 3), np.nan), (1.0, 1.0, 1.0))
    with pytest.raises(ValueError, match="mean"):
        FrozenTurbulence(box, box, 10.0, 270.0)
    with pytest.raises(ValueError, match="speed"):
        FrozenTurbulence(scenes.uniform(), box, np.nan, 270.0)


# ----------------------------------------------------------------------------------------
# fixed points sampled at many times (AbstractField.time_sampler): frozen turbulence builds
# one line along the wind per point; it must equal direct sampling
# ----------------------------------------------------------------------------------------
def _sampler_values(f, pts, dirs, ts, n_times):
    return eqx.filter_jit(lambda f, p, d, t: f.time_sampler(p, d, n_times=n_times)(t))(
        f, pts, dirs, ts)


@pytest.mark.parametrize("periodic", [True, False])
def test_time_sampler_lines_equal_direct_sampling(periodic):
    from lidarjax.scenes.turbulence import _LineSampler

    box, k = mode_box(periodic=periodic)
    rng = np.random.default_rng(11)
    grid = lidarjax.GridField(np.linspace(-400, 400, 9), np.linspace(-200, 200, 5),
                              np.linspace(0, 60, 5), 8.0 + rng.normal(size=(9, 5, 5, 3)))
    f = FrozenTurbulence(grid, box, 8.7, 241.0, anchor=(3.0, -2.0, 1.0), shift=17.0)
    # points (4, 5) including some outside a non-periodic box (laterally and above it)
    pts = jnp.asarray(rng.uniform([-150, -60, 2], [150, 60, 45], size=(4, 5, 3)))
    dirs = jnp.asarray(rng.normal(size=(5, 3)))
    dirs = dirs / jnp.linalg.norm(dirs, axis=-1, keepdims=True)
    ts = jnp.asarray(rng.uniform(0, 900, size=(7, 1, 1)))
    # which sampler is built (traced abstractly: building the lines eagerly compiles each op)
    kind = lambda n: type(eqx.filter_eval_shape(f.time_sampler, pts, dirs, n_times=n))  # noqa: E731
    assert issubclass(kind(1000), _LineSampler)
    assert not issubclass(kind(1), _LineSampler)
    for d in (dirs, None):
        lines = _sampler_values(f, pts, d, ts, 1000)
        direct = _sampler_values(f, pts, d, ts, 1)
        ref = (sample_at(f, jnp.broadcast_to(pts, (7, 4, 5, 3)), jnp.broadcast_to(ts, (7, 4, 5)))
               if d is None else los_at(f, jnp.broadcast_to(pts, (7, 4, 5, 3)), d,
                                        jnp.broadcast_to(ts, (7, 4, 5))))
        assert lines.shape == ref.shape == direct.shape
        np.testing.assert_array_equal(np.isnan(lines), np.isnan(ref))
        if not periodic:
            assert np.isnan(ref).any() and np.isfinite(ref).any()
        np.testing.assert_allclose(lines, ref, rtol=0, atol=1e-12, equal_nan=True)
        np.testing.assert_allclose(direct, ref, rtol=0, atol=1e-12, equal_nan=True)


def test_time_sampler_steady_field_and_budget():
    from lidarjax.field import SteadySampler
    from lidarjax.scenes import turbulence

    mean = scenes.uniform(9.0, 250.0)
    pts = jnp.asarray([[3.0, 4.0, 5.0], [-30.0, 10.0, 20.0]])
    s = mean.time_sampler(pts, n_times=100)
    assert isinstance(s, SteadySampler)
    out = s(jnp.zeros((6, 1)))
    assert out.shape == (6, 2, 3)
    np.testing.assert_allclose(out[3], mean.sample_local(pts))
    # too many numbers for the line budget: sampled directly, same values
    box, _ = mode_box()
    f = FrozenTurbulence(mean, box, 9.0, 250.0)
    big = jnp.zeros((turbulence.LINE_BUDGET // box.shape[0] + 1, 3))
    assert not isinstance(f.time_sampler(big, n_times=10**6), turbulence._LineSampler)


def test_time_sampler_float32_long_advection_and_gradients():
    """The lines keep the float32 accuracy of direct sampling over a day, and their
    gradients (time, speed, direction, anchor, box values) match finite differences."""
    _, pts, f32, f64 = long_advection_pair(16)
    ts = np.float32([600.37, 3600.37, 86400.37])[:, None]
    a = np.asarray(_sampler_values(f32, jnp.asarray(pts), None, jnp.asarray(ts), 1000))
    assert a.dtype == np.float32
    b = np.asarray(_sampler_values(f64, jnp.asarray(pts, jnp.float64), None,
                                   jnp.asarray(ts, jnp.float64), 1000))
    np.testing.assert_allclose(a, b, atol=2e-5)
    assert_los_gradients_match_fd(
        lambda f, p, d, t: f.time_sampler(p, d, n_times=64)(jnp.stack([t, t + 3.0])[:, None]))


def test_time_sampler_lines_built_in_chunks(monkeypatch):
    """Lines are built in chunks of points (a small chunk here): same values, gradients."""
    from lidarjax.scenes import turbulence

    box, _ = mode_box()
    f = FrozenTurbulence(scenes.uniform(9.0, 250.0), box, 9.0, 250.0)
    rng = np.random.default_rng(3)
    pts = jnp.asarray(rng.uniform([-150, -40, 2], [150, 40, 30], size=(3, 5, 3)))
    dirn = jnp.asarray([0.3, -0.2, 0.9])
    ts = jnp.asarray([[[1.0]], [[7.5]], [[300.0]]])
    whole = _sampler_values(f, pts, dirn, ts, 1000)
    monkeypatch.setattr(turbulence, "_LINE_CHUNK", 4)
    chunked = eqx.filter_jit(lambda f, p, t: f.time_sampler(p, dirn, n_times=1000)(t))(f, pts, ts)
    np.testing.assert_allclose(chunked, whole, rtol=0, atol=1e-13)
    vec = eqx.filter_jit(lambda f, p, t: f.time_sampler(p, n_times=1000)(t))(f, pts, ts)
    np.testing.assert_allclose(vec, sample_at(f, jnp.broadcast_to(pts, (3, 3, 5, 3)),
                                              jnp.broadcast_to(ts, (3, 3, 5))), atol=1e-12)
    g = jax.jit(jax.grad(lambda s: jnp.sum(f.time_sampler(pts * s, dirn, n_times=1000)(ts))))(1.0)
    assert np.isfinite(float(g))


@pytest.mark.parametrize("periodic", [False, True])
def test_los_projected_at_the_corners_equals_the_projected_velocity(periodic):
    """`FrozenTurbulence.los_local_at` (the box projected at its cells' corners) equals the
    interpolated velocity projected on the direction, NaN at the same points (a
    non-periodic box's sides), for per-point directions and broadcast times."""
    box, _ = mode_box(periodic=periodic)
    mean = lidarjax.GridField(np.linspace(-200, 200, 9), np.linspace(-200, 200, 9), np.linspace(0, 80, 5),
                              np.random.default_rng(1).normal(size=(9, 9, 5, 3)) + 6.0)
    # field-local points: the mean grid's first node is the origin
    f = FrozenTurbulence(mean, box, 9.0, 250.0, anchor=(203.0, 198.0, 0.0))
    rng = np.random.default_rng(4)
    pts = jnp.asarray(rng.uniform([50, 150, 2], [350, 250, 38], size=(7, 11, 3)))
    dirs = rng.normal(size=(7, 11, 3))
    dirs = jnp.asarray(dirs / np.linalg.norm(dirs, axis=-1, keepdims=True))
    t = jnp.asarray(rng.uniform(0, 3600, size=(5, 7, 1)))
    got = np.asarray(los_at(f, pts, dirs, t))
    want = np.sum(np.asarray(sample_at(f, pts, t)) * np.asarray(dirs), axis=-1)
    assert got.shape == (5, 7, 11)
    assert np.array_equal(np.isnan(got), np.isnan(want)) and 0.5 < np.isfinite(want).mean() <= 1
    np.testing.assert_allclose(got, want, atol=1e-12, equal_nan=True)
