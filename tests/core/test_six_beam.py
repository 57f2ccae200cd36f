"""The 6-beam scan and its Reynolds-stress retrieval (lidarjax.six_beam,
lidarjax.reynolds_stresses; Sathe et al. 2015): closed forms in a frozen field of Fourier
modes whose covariance is set (point probe exact, pulsed probe attenuated by its transfer
function), mounts (north offset, tilt with and without compensation), a Mann box against
direct sampling, lidarwind's formula, NaN records and gradients."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax
from lidarjax.field import AbstractField
from lidarjax.frames import cfd_to_north_rotation, rotation_x, rotation_y
from lidarjax.probe import probe_transfer
from lidarjax.scenes import FrozenTurbulence
from lidarjax.series import simulate_series
from lidarjax.stresses import STRESS_COMPONENTS, reynolds_stresses, stress_matrix
from lidarjax.timing import schedule_for
from lidarjax.turbulence import TurbulenceBox, fft_mann_box

SPEED, PERIOD, CYCLES = 4.0, 6.0, 100  # m/s; the 6-beam cycle (s); cycles in a 600 s record
HEIGHTS = [60.0, 100.0]
#: mode numbers q: wavenumber k = 2 pi q / (SPEED * PERIOD * CYCLES), i.e. q periods per
#: record as seen by every beam; distinct, with no q_m + q_n = CYCLES (exact orthogonality)
MODES = np.array([3, 11, 19, 26, 37, 44])
K = 2 * np.pi * MODES / (SPEED * PERIOD * CYCLES)  # rad/m: wavelengths 55-800 m


def _amplitudes():
    rng = np.random.default_rng(7)
    scale = np.array([1.0, 0.7, 0.5])  # m/s: u, v, w amplitudes
    return rng.normal(size=(MODES.size, 3)) * scale, rng.normal(size=(MODES.size, 3)) * scale


def _six(c):
    return np.array([c[0, 0], c[1, 1], c[2, 2], c[0, 1], c[0, 2], c[1, 2]])


class FrozenModes(AbstractField):
    """Wind ``SPEED`` towards ``e`` plus frozen Fourier modes along ``e``:
    ``V = SPEED e + sum_m a_m cos(k_m xi) + b_m sin(k_m xi)``, ``xi = p . e - SPEED t``
    (CFD frame); NaN for ``t`` in ``[gap0, gap1)``. Over a record of whole mode periods
    sampled evenly, every point's velocity covariance is exactly
    ``C = sum_m (a_m a_m^T + b_m b_m^T) / 2``."""

    origin: jax.Array
    origin_lo: jax.Array
    e: jax.Array
    k: jax.Array
    a: jax.Array
    b: jax.Array
    gap0: jax.Array
    gap1: jax.Array

    def sample_local(self, p):
        return self.sample_local_at(p, 0.0)

    def sample_local_at(self, p, t):
        t = jnp.broadcast_to(jnp.asarray(t, self.dtype), p.shape[:-1])
        xi = jnp.sum(p * self.e, -1) - SPEED * t
        ph = xi[..., None] * self.k
        v = SPEED * self.e + jnp.cos(ph) @ self.a + jnp.sin(ph) @ self.b
        gap = (t >= self.gap0) & (t < self.gap1)
        return jnp.where(gap[..., None], jnp.nan, v)


def modes_field(direction=250.0, scale=1.0, gap=(-2.0, -1.0)):
    """The field blowing from meteorological `direction` (degrees from CFD +y)."""
    a, b = _amplitudes()
    towards = np.deg2rad(direction + 180.0)
    e = np.array([np.sin(towards), np.cos(towards), 0.0])
    f = lambda x: jnp.asarray(x, jnp.float64)  # noqa: E731
    return FrozenModes(f(np.zeros(3)), f(np.zeros(3)), f(e), f(K), f(scale * a), f(scale * b),
                       f(gap[0]), f(gap[1])), e


def modes_covariance(scale=1.0):
    a, b = _amplitudes()
    return scale**2 * (a.T @ a + b.T @ b) / 2


SCAN = lidarjax.six_beam()
LEVEL = lidarjax.Mount([0.0, 0.0, 0.0])


@pytest.fixture(scope="module")
def point_series():
    field, _ = modes_field()
    return simulate_series(field, SCAN, LEVEL, HEIGHTS, (0.0, 600.0))


def test_six_beam_preset_schedule_and_conditioning(point_series):
    """Five beams 45 degrees from the vertical 72 degrees apart, then the vertical; 1 s per
    LOS, 6 s per cycle; the mean-wind least squares and the 6 x 6 stress matrix have the
    closed-form / numpy condition numbers (independent of the azimuth offset)."""
    n = np.asarray(SCAN.directions())
    az = np.deg2rad(np.arange(5) * 72.0)
    s = np.sqrt(0.5)
    ref = np.vstack([np.stack([s * np.sin(az), s * np.cos(az), np.full(5, s)], -1), [0, 0, 1]])
    np.testing.assert_allclose(n, ref, atol=1e-15)
    sched = schedule_for(SCAN)
    np.testing.assert_allclose(sched.beam_times, np.arange(6.0))
    np.testing.assert_allclose(sched.period, 6.0)
    assert sched.update == "each_los" and not sched.heights_sequential
    for cone in (30.0, 45.0, 60.0):
        c = np.deg2rad(cone)
        scan = lidarjax.six_beam(cone, azimuth0=17.0)
        np.testing.assert_allclose(scan.condition_number(),
                                   np.sqrt((5 * np.cos(c) ** 2 + 1) / (2.5 * np.sin(c) ** 2)),
                                   rtol=1e-12)
    # the stress matrix, written out with lidarwind's (elevation, azimuth) formula
    m = _lidarwind_matrix(45.0, np.arange(5) * 72.0)
    np.testing.assert_allclose(stress_matrix(n), m, atol=1e-15)
    assert abs(np.linalg.cond(m) - 3.3369439) < 1e-6
    np.testing.assert_allclose(np.linalg.cond(_lidarwind_matrix(45.0, np.arange(5) * 72.0 + 17)),
                               np.linalg.cond(m), rtol=1e-10)
    # a single cone cannot separate w'w' from (u'u' + v'v') / 2: refused before compiling
    with pytest.raises(ValueError, match="single cone"):
        reynolds_stresses(point_series, lidarjax.zephir(n_los=6), LEVEL)
    with pytest.raises(ValueError, match="cannot determine the six"):
        reynolds_stresses(point_series, lidarjax.windcube_v2(), LEVEL)
    with pytest.raises(ValueError, match="the scan 7"):
        reynolds_stresses(point_series, lidarjax.zephir(n_los=7), LEVEL)


def test_point_probe_recovers_the_set_covariance_exactly(point_series):
    """Point probe: each beam's LOS variance is n^T C n and the 6-beam retrieval is C, to
    rounding (the modes complete whole periods in the record at every beam); the mean wind
    is the least squares over six beams; the mean-wind frame rotates C by the direction.
    The instrument's reconstructed vectors (DBS-style) mix beams taken up to 5 s and 120 m
    apart and miss C."""
    c = modes_covariance()
    r = reynolds_stresses(point_series, SCAN, LEVEL)
    n = np.asarray(SCAN.directions())
    np.testing.assert_allclose(r.los_variance[0], np.broadcast_to(
        np.einsum("bi,ij,bj->b", n, c, n), (2, 6)), rtol=1e-10)
    np.testing.assert_allclose(r.stress[0], np.broadcast_to(_six(c), (2, 6)), rtol=1e-9,
                               atol=1e-11)
    np.testing.assert_array_equal(r.los_count[0], CYCLES)
    _, e = modes_field()
    np.testing.assert_allclose(r.mean_velocity[0], np.broadcast_to(SPEED * e, (2, 3)), atol=1e-11)
    ey = np.array([-e[1], e[0], 0.0])
    rot = np.stack([e, ey, [0, 0, 1]])
    np.testing.assert_allclose(r.stress_wind[0], np.broadcast_to(_six(rot @ c @ rot.T), (2, 6)),
                               rtol=1e-9, atol=1e-11)
    np.testing.assert_allclose(r.condition_number, 3.3369439, rtol=1e-7)
    # DBS-style: the covariance of the reconstructed vectors, recomputed in numpy
    v = np.asarray(point_series.velocity)
    for ih in range(2):
        cov = np.cov(v[:, ih].T, bias=True)
        np.testing.assert_allclose(r.vector_stress[0, ih], _six(cov), rtol=1e-10, atol=1e-12)
    assert np.max(np.abs(np.asarray(r.vector_stress[0]) - _six(c))) > 0.1 * c[0, 0]
    # the .sta statistics of the same series: the mean wind of the sliding reconstructions
    st = lidarjax.statistics(point_series)
    np.testing.assert_allclose(st.direction[0], 250.0, atol=0.5)
    np.testing.assert_allclose(st.availability[0], 100.0)
    np.testing.assert_allclose(st.w_std[0] ** 2, r.vector_stress[0, :, 2], rtol=1e-9)


@pytest.mark.parametrize("angles, compensated", [
    (dict(epsilon=12.0, gamma=-30.0), False),
    (dict(pitch=3.0, roll=-2.0, epsilon=5.0), False),
    (dict(pitch=3.0, roll=-2.0, epsilon=5.0), True),
])
def test_mount_north_offset_and_tilt(angles, compensated):
    """The beams are turned as the instrument turns its wind vector: north offset (and
    heading gamma) give C in the north frame, R C R^T with R = cfd_to_north_rotation; an
    uncompensated tilt T gives what the instrument believes, R(-eps) T^T C_lidar T R(eps);
    compensated, the north-frame C."""
    mount = lidarjax.Mount([0.0, 0.0, 0.0], **angles)
    scan = lidarjax.six_beam(tilt_compensation=compensated)
    field, _ = modes_field()
    r = reynolds_stresses(simulate_series(field, scan, mount, HEIGHTS, (0.0, 600.0)), scan, mount)
    to_north = np.asarray(cfd_to_north_rotation(mount))
    c_north = to_north @ modes_covariance() @ to_north.T
    if not compensated and ("pitch" in angles):
        t = np.asarray(rotation_x(angles["pitch"]) @ rotation_y(angles["roll"]))
        r_eps = np.asarray(lidarjax.frames.rotation_z(-angles["epsilon"]))
        c_lidar = r_eps.T @ c_north @ r_eps
        want = r_eps @ t.T @ c_lidar @ t @ r_eps.T
    else:
        want = c_north
    np.testing.assert_allclose(r.stress[0], np.broadcast_to(_six(want), (2, 6)), rtol=1e-9,
                               atol=1e-11)


def test_pulsed_probe_attenuates_by_its_transfer_function():
    """Pulsed probe: a mode k along the wind is seen along beam b through the weighting's
    transform at kappa = k (n_b . e): each beam's variance is
    sum_m W(k_m n_b.e)^2 ((n_b.a_m)^2 + (n_b.b_m)^2) / 2 (the simulator's nodes:
    probe_transfer(model="nodes")), the retrieval is M^-1 of those; the vertical beam sees
    no attenuation (n . e = 0)."""
    probe = lidarjax.PulsedProbe(n_nodes=33)
    field, e = modes_field()
    s = simulate_series(field, SCAN, LEVEL, HEIGHTS, (0.0, 600.0), probe=probe, refine_probe=False)
    r = reynolds_stresses(s, SCAN, LEVEL)
    a, b = _amplitudes()
    n = np.asarray(SCAN.directions())
    m_inv = np.linalg.inv(np.asarray(stress_matrix(n)))
    c = _six(modes_covariance())
    for ih, h in enumerate(HEIGHTS):
        w = np.stack([probe_transfer(probe, K * (n[j] @ e), h / n[j, 2], model="nodes")
                      for j in range(6)])  # (b, m)
        var = np.sum(w**2 * ((n @ a.T) ** 2 + (n @ b.T) ** 2) / 2, axis=1)
        np.testing.assert_allclose(r.los_variance[0, ih], var, rtol=1e-9)
        np.testing.assert_allclose(r.stress[0, ih], m_inv @ var, rtol=1e-8, atol=1e-10)
        np.testing.assert_allclose(w[5], 1.0, atol=1e-14)
        # the attenuation is real: every inclined beam loses variance (u'u' about a third)
        point = np.einsum("bi,ij,bj->b", n, modes_covariance(), n)
        assert np.all((var[:5] < point[:5]) & (var[:5] > 0.7 * point[:5])), var / point
        assert 0.6 < r.stress[0, ih, 0] / c[0] < 0.8


def _lidarwind_matrix(elevation, azimuths):
    """lidarwind 1.0.1 `SixBeamMethod.get_m_matrix`, written out: elevation phi and azimuth
    theta (degrees) of the five slanted beams, then phi = 90 (theta = 0) for the vertical
    one; row ``(cos^2 phi sin^2 theta, cos^2 phi cos^2 theta, sin^2 phi,
    2 cos^2 phi cos theta sin theta, 2 cos phi sin phi sin theta, 2 cos phi sin phi
    cos theta)`` for ``(var_u, var_v, var_w, var_uv, var_uw, var_vw)``."""
    phi = np.deg2rad(np.append(np.full(len(azimuths), elevation), 90.0))
    th = np.deg2rad(np.append(azimuths, 0.0))
    cp, sp, ct, st = np.cos(phi), np.sin(phi), np.cos(th), np.sin(th)
    return np.stack([cp**2 * st**2, cp**2 * ct**2, sp**2, 2 * cp**2 * ct * st, 2 * cp * sp * st,
                     2 * cp * sp * ct], -1)


def _lidarwind_pipeline(los, t, azimuths):
    """lidarwind's data path for one record: the slanted beams taken at the vertical beam's
    times by nearest-time interpolation (`xarray.interp(method="nearest")`, pandas' rule:
    ties go to the later time), the vertical LOS
    negated (its sign convention; irrelevant to a variance), population variances (`var()`
    of a rolling window spanning the record), sigma = M^-1 S."""
    tv = t[:, 5]
    slanted = np.empty((tv.size, 5))
    for j in range(5):
        dist = np.abs(t[:, j][None, :] - tv[:, None])
        idx = t.shape[0] - 1 - dist[:, ::-1].argmin(axis=1)  # ties: the later LOS (pandas)
        slanted[:, j] = los[idx, j]
    s = np.append(slanted.var(axis=0), (-los[:, 5]).var())
    return np.linalg.inv(_lidarwind_matrix(45.0, azimuths)) @ s


def test_agrees_with_lidarwind_formula(point_series):
    """lidarwind (Windcube 200s 6-beam retrieval) uses the same matrix in (elevation,
    azimuth) form and u east, v north: on our beam variances it gives our stresses to
    rounding. Its data path aligns the slanted beams to the vertical beam's times (nearest
    LOS): for the 6 s cycle beams 0-1 come from the next cycle and beam 2 (a tie) too, so at
    the record's edges one LOS is dropped and one repeated: a 1/N difference in each beam
    variance, amplified by M^-1 (absolute row sums up to 4), within 5 % of the largest
    stress here. With the beams taken at once (a schedule of equal beam times) the
    alignment is the identity and the whole pipeline agrees to rounding."""
    r = reynolds_stresses(point_series, SCAN, LEVEL)
    m_inv = np.linalg.inv(_lidarwind_matrix(45.0, np.arange(5) * 72.0))
    los, t = np.asarray(point_series.los), np.asarray(point_series.los_time)
    for ih in range(2):
        np.testing.assert_allclose(m_inv @ np.asarray(r.los_variance[0, ih]), r.stress[0, ih],
                                   rtol=1e-12, atol=1e-14)
        lw = _lidarwind_pipeline(los[:, ih], t[:, ih], np.arange(5) * 72.0)
        scale = np.max(np.abs(np.asarray(r.stress[0, ih])))
        np.testing.assert_allclose(lw, r.stress[0, ih], atol=0.05 * scale)
    field, _ = modes_field()
    together = simulate_series(field, SCAN, LEVEL, HEIGHTS, (0.0, 600.0),
                               schedule=lidarjax.Schedule(np.zeros(6), 6.0))
    r = reynolds_stresses(together, SCAN, LEVEL)
    los, t = np.asarray(together.los), np.asarray(together.los_time)
    for ih in range(2):
        lw = _lidarwind_pipeline(los[:, ih], t[:, ih], np.arange(5) * 72.0)
        np.testing.assert_allclose(lw, r.stress[0, ih], rtol=1e-10, atol=1e-12)


def test_records_gaps_and_jit(point_series):
    """Two records of 300 s: the per-record LOS statistics equal numpy's; a data gap
    removes its LOS from the counts, and a record whose beams all fall in the gap is NaN;
    the function traces under jit."""
    los, t = np.asarray(point_series.los), np.asarray(point_series.los_time)
    r = reynolds_stresses(point_series, SCAN, LEVEL, starts=[0.0, 300.0], record_length=300.0)
    n = np.asarray(SCAN.directions())
    m_inv = np.linalg.inv(np.asarray(stress_matrix(n)))
    for k, s0 in enumerate((0.0, 300.0)):
        sel = (t[:, 0, 0] >= s0) & (t[:, 0, 0] < s0 + 300.0)
        var = los[sel].var(axis=0)
        np.testing.assert_allclose(r.los_variance[k], var, rtol=1e-10)
        np.testing.assert_allclose(r.stress[k], var @ m_inv.T, rtol=1e-9, atol=1e-12)
    jitted = jax.jit(lambda s: reynolds_stresses(s, SCAN, LEVEL).stress)(point_series)
    np.testing.assert_allclose(jitted, reynolds_stresses(point_series, SCAN, LEVEL).stress,
                               rtol=1e-12)
    field, _ = modes_field(gap=(300.0, 600.0))
    g = simulate_series(field, SCAN, LEVEL, HEIGHTS, (0.0, 600.0))
    rg = reynolds_stresses(g, SCAN, LEVEL, starts=[0.0, 300.0], record_length=300.0)
    np.testing.assert_array_equal(rg.los_count[0], 50)
    np.testing.assert_array_equal(rg.los_count[1], 0)
    np.testing.assert_allclose(rg.stress[0], r.stress[0], rtol=1e-12)
    assert np.all(np.isnan(rg.stress[1])) and np.all(np.isnan(rg.stress_wind[1]))
    assert np.all(np.isnan(rg.vector_stress[1]))
    # min_los is dynamic: 51 valid LOS per beam needed, record 0 has 50
    r51 = reynolds_stresses(g, SCAN, LEVEL, starts=[0.0, 300.0], record_length=300.0, min_los=51)
    assert np.all(np.isnan(r51.stress)) and np.all(np.isfinite(r51.los_variance[0]))
    assert STRESS_COMPONENTS == ("uu", "vv", "ww", "uv", "uw", "vw")


def test_float32_follows_the_input_dtype(point_series):
    """A float32 series gives float32 stresses within float32 rounding of the float64 ones
    (the variances are two-pass, and M^-1 amplifies rounding at most 3.34 times)."""
    s32 = jax.tree_util.tree_map(
        lambda a: a.astype(jnp.float32) if jnp.issubdtype(a.dtype, jnp.floating) else a,
        point_series)
    r32 = reynolds_stresses(s32, SCAN, LEVEL)
    r64 = reynolds_stresses(point_series, SCAN, LEVEL)
    assert r32.stress.dtype == jnp.float32
    scale = float(np.max(np.abs(np.asarray(r64.stress))))
    np.testing.assert_allclose(r32.stress, r64.stress, atol=2e-6 * scale)
    np.testing.assert_allclose(r32.stress_wind, r64.stress_wind, atol=2e-6 * scale)


def test_gradient_matches_finite_differences(point_series):
    """d(stresses)/d(LOS) and d/d(north offset) through the retrieval, against centred
    differences."""
    def loss(los, eps):
        s = eqx.tree_at(lambda x: x.los, point_series, los)
        m = lidarjax.Mount([0.0, 0.0, 0.0], epsilon=eps)
        r = reynolds_stresses(s, SCAN, m)
        return jnp.sum(r.stress_wind[0, 0] * jnp.arange(1.0, 7.0)) + jnp.sum(r.stress[0, 1, 3:])

    loss = jax.jit(loss)  # compiled once for the four differences
    los0 = point_series.los
    g_los, g_eps = jax.jit(jax.grad(loss, argnums=(0, 1)))(los0, 10.0)
    d = np.random.default_rng(0).normal(size=los0.shape)
    h = 1e-6
    fd = (loss(los0 + h * d, 10.0) - loss(los0 - h * d, 10.0)) / (2 * h)
    np.testing.assert_allclose(np.sum(np.asarray(g_los) * d), fd, rtol=1e-6)
    fd_eps = (loss(los0, 10.0 + 1e-4) - loss(los0, 10.0 - 1e-4)) / 2e-4
    np.testing.assert_allclose(g_eps, fd_eps, rtol=1e-6, atol=1e-9)


# ------------------------------------------------------------------------------------------
# a Mann box: the retrieval against the box sampled directly at the beams' points
# ------------------------------------------------------------------------------------------
MANN_SHAPE, MANN_DX, MANN_U, MANN_SEEDS = (128, 16, 16), 8.0, 9.73, 24
MANN_HEIGHTS = [40.0, 80.0]


@eqx.filter_jit
def _sample_at(field, points, times):
    """The field's velocity (CFD frame) sampled directly at points and times."""
    return field.sample_local_at(points, times)


@pytest.fixture(scope="module")
def mann_ensemble():
    """Per box and height: the 6-beam retrieval with the point and the pulsed probe, and
    the beams' own covariances from direct sampling of the field (north frame)."""
    n = np.asarray(SCAN.directions())
    out = []
    for seed in range(MANN_SEEDS):
        vel = fft_mann_box(MANN_SHAPE, (MANN_DX,) * 3, sigma_u=1.0, seed=seed)
        box = TurbulenceBox(vel, (MANN_DX,) * 3, periodic=(True, True))
        f = FrozenTurbulence(lidarjax.scenes.uniform(MANN_U, 270.0), box, MANN_U, 270.0)
        s = simulate_series(f, SCAN, LEVEL, MANN_HEIGHTS, (0.0, 600.0))
        sp = simulate_series(f, SCAN, LEVEL, MANN_HEIGHTS, (0.0, 600.0),
                             probe=lidarjax.PulsedProbe())
        r, rp = reynolds_stresses(s, SCAN, LEVEL), reynolds_stresses(sp, SCAN, LEVEL)
        t = np.asarray(s.los_time)  # (m, h, b)
        pts = np.asarray(MANN_HEIGHTS)[:, None, None] / n[None, :, 2:3] * n[None]  # (h, b, 3)
        v = np.asarray(_sample_at(f, jnp.broadcast_to(jnp.asarray(pts), t.shape + (3,)),
                                  jnp.asarray(t)))  # (m, h, b, 3), CFD = north here
        dv = v - v.mean(axis=0)
        cov = np.einsum("mhbi,mhbj->hbij", dv, dv) / v.shape[0]
        out.append((np.asarray(r.stress[0]), np.asarray(rp.stress[0]),
                    np.asarray(r.los_variance[0]), cov, np.asarray(r.vector_stress[0])))
    return out


def test_mann_box_point_probe_recovers_stresses_to_sampling_error(mann_ensemble):
    """Point probe in Mann boxes (L = 30 m, Gamma = 3.9, 128 x 16 x 16 nodes of 8 m): each
    beam's LOS variance is n^T C_b n with C_b the covariance of the box sampled at that
    beam's points and times (to rounding). The 6-beam retrieval assumes every beam sees the
    same stresses; in one record the six beams' lines through the box differ by the
    sampling error of a 1 km line (each beam's own variance scatters by about 15 % of
    sigma_u^2), which M^-1 (absolute row sums up to 4) carries into each record: rms
    errors of 0.1-0.3 sigma_u^2 per record. Over the ensemble the retrieval error
    against the beams' mean covariance has no bias: every component's mean error is
    within 4 standard errors of 0."""
    n = np.asarray(SCAN.directions())
    errors = []
    for stress, _, los_var, cov, _ in mann_ensemble:
        np.testing.assert_allclose(los_var, np.einsum("bi,hbij,bj->hb", n, cov, n), rtol=1e-9)
        for ih in range(len(MANN_HEIGHTS)):
            errors.append(stress[ih] - _six(cov[ih].mean(axis=0)))
    errors = np.asarray(errors)  # (records, 6), sigma_u = 1 m/s
    mean, sem = errors.mean(axis=0), errors.std(axis=0, ddof=1) / np.sqrt(len(errors))
    assert np.all(np.abs(mean) < 4 * sem), (mean, sem)
    # the per-record scatter is that sampling error (rms 0.11-0.32 sigma_u^2 by component)
    assert np.all(np.sqrt(np.mean(errors**2, axis=0)) < 0.5), np.sqrt(np.mean(errors**2, axis=0))


def test_mann_box_pulsed_probe_attenuates_the_stresses(mann_ensemble):
    """The pulsed probe (Windcube weighting, 8 m box nodes) averages each beam over tens of
    metres: the 6-beam variances are 40-97 % of the point probe's over the ensemble (the
    transfer function's loss at the box's wavenumbers). The DBS-style u'u' of the point
    probe's own reconstructed vectors (beams 2 s and 80-160 m apart mixed) loses more than
    the pulsed 6-beam retrieval does."""
    point = np.mean([m[0] for m in mann_ensemble], axis=0)
    pulsed = np.mean([m[1] for m in mann_ensemble], axis=0)
    dbs = np.mean([m[4] for m in mann_ensemble], axis=0)
    ratio = pulsed[:, :3] / point[:, :3]
    assert np.all((ratio > 0.4) & (ratio < 0.97)), ratio
    assert np.all(dbs[:, 0] < pulsed[:, 0]), (dbs[:, 0], pulsed[:, 0])
