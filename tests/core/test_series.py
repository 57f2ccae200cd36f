"""Time series (lidarjax.timing, lidarjax.series, lidarjax.motion): scan timing, the
instrument's reconstructions from beams taken at different times, the 10-minute statistics,
platform motion against closed forms, streaming and sharding."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import special

import lidarjax
from lidarjax._precision import split
from lidarjax.field import AbstractField
from lidarjax.io.sta import write_series_sta
from lidarjax.motion import SinusoidalMotion
from lidarjax.series import simulate_series, simulate_statistics, statistics
from lidarjax.timing import Schedule, schedule_for

from ..helpers import REPO

U, A_GUST, T_GUST = 10.0, 1.0, 60.0


class Gust(AbstractField):
    """Uniform wind towards ``+x`` (direction 270) of ``U + a sin(2 pi t / T)``, NaN during
    ``[gap0, gap1)`` (a data gap)."""

    origin: jax.Array
    origin_lo: jax.Array
    speed: jax.Array
    amp: jax.Array
    period: jax.Array
    gap0: jax.Array
    gap1: jax.Array

    def sample_local(self, p):
        return self.sample_local_at(p, 0.0)

    def sample_local_at(self, p, t):
        t = jnp.broadcast_to(jnp.asarray(t, self.dtype), p.shape[:-1])
        u = self.speed + self.amp * jnp.sin(2 * jnp.pi * t / self.period) + 0 * p[..., 0]
        v = jnp.stack([u, jnp.zeros_like(u), jnp.zeros_like(u)], -1)
        gap = (t >= self.gap0) & (t < self.gap1)
        return jnp.where(gap[..., None], jnp.nan, v)


def gust(amp=A_GUST, gap=(-2.0, -1.0), speed=U):
    o, lo = split([0.0, 0.0, 0.0], jnp.float64)
    f = lambda x: jnp.asarray(x, jnp.float64)  # noqa: E731
    return Gust(o, lo, f(speed), f(amp), f(T_GUST), f(gap[0]), f(gap[1]))


def u_at(t, amp=A_GUST):
    return U + amp * np.sin(2 * np.pi * np.asarray(t) / T_GUST)


MOUNT = lidarjax.Mount([0.0, 0.0, 0.0])
HEIGHTS = [40.0, 100.0]


def test_series_refuses_a_schedule_that_does_not_fit_the_scan():
    with pytest.raises(ValueError, match="one time per beam"):
        simulate_series(gust(), lidarjax.windcube_v2(), MOUNT, HEIGHTS, (0.0, 60.0),
                        schedule=Schedule([0, 1, 2, 3], 4.0))
    with pytest.raises(ValueError, match="at least one scan cycle"):
        simulate_series(gust(), lidarjax.windcube_v2(), MOUNT, HEIGHTS, (0.0, 3.0))


def _sliding_reference(beam_of_los, t_los, n_beams):
    """Independent reference of the sliding window: after LOS k (once every beam has been
    seen), the latest LOS index of every beam."""
    latest = {}
    windows = []
    for k, j in enumerate(beam_of_los):
        latest[j] = k
        if len(latest) == n_beams:
            windows.append([latest[i] for i in range(n_beams)])
    return np.asarray(windows)


@pytest.mark.parametrize("make, dt", [(lidarjax.windcube_v1, 1.5), (lidarjax.windcube_v2, 1.0)])
def test_windcube_sliding_reconstruction_closed_form(make, dt):
    """Each new LOS updates the vector from the latest LOS of every beam: with a uniform gust
    along x, u = (u(t_S1) + u(t_S3)) / 2 at the times those two beams were taken."""
    scan = make()
    s = simulate_series(gust(), scan, MOUNT, HEIGHTS, (0.0, 600.0))
    b = scan.n_beams
    n_los = int(600 / (b * dt)) * b
    t = np.arange(n_los) * dt
    win = _sliding_reference(np.arange(n_los) % b, t, b)
    np.testing.assert_allclose(s.los_time[:, 0, :].reshape(-1), t)
    u_ref = 0.5 * (u_at(t[win[:, 1]]) + u_at(t[win[:, 3]]))
    assert s.velocity.shape == (len(win), 2, 3)
    np.testing.assert_allclose(s.time[:, 0], t[win.max(axis=1)])
    np.testing.assert_allclose(s.speed[:, 0], u_ref, rtol=1e-12)
    np.testing.assert_allclose(s.speed[:, 1], u_ref, rtol=1e-12)
    np.testing.assert_allclose(s.direction, 270.0, atol=1e-9)
    # the V1's w uses S0 and S2 (no x component) and the V2's vertical beam: both 0 here
    np.testing.assert_allclose(s.velocity[..., 2], 0.0, atol=1e-12)
    st = statistics(s)
    np.testing.assert_allclose(st.speed[0], u_ref.mean(), rtol=1e-12)
    np.testing.assert_allclose(st.speed_std[0], u_ref.std(), rtol=1e-10)
    np.testing.assert_allclose(st.speed_min[0], u_ref.min(), rtol=1e-12)
    np.testing.assert_allclose(st.speed_max[0], u_ref.max(), rtol=1e-12)
    # beams 2 LOS apart average the gust: the lidar's dispersion is below the point's
    # a/sqrt(2) by cos(pi * 2 dt / T) up to the record's edges
    np.testing.assert_allclose(st.speed_std[0], A_GUST / np.sqrt(2) * np.cos(np.pi * 2 * dt / T_GUST),
                               rtol=5e-3)
    np.testing.assert_allclose(st.cup_speed[0], U, rtol=1e-12)
    np.testing.assert_allclose(st.cup_std[0], A_GUST / np.sqrt(2), rtol=1e-12)
    np.testing.assert_allclose(st.sonic_std[0], A_GUST / np.sqrt(2), rtol=1e-12)
    np.testing.assert_allclose(st.sonic_direction[0], 270.0, atol=1e-9)
    np.testing.assert_allclose(st.ti[0], st.speed_std[0] / st.speed[0])
    np.testing.assert_allclose(st.availability[0], 100.0)


def test_zephir_sequential_heights_closed_form():
    """ZephIR: 50 LOS per 1 s rotation, 3 rotations per height, heights in turn; one sine
    fit per visit from the rotation-averaged LOS: u = (2/N) sum sin^2(a_j) mean_r u(t_rj)."""
    scan = lidarjax.zephir()
    s = simulate_series(gust(), scan, MOUNT, HEIGHTS, (0.0, 60.0))
    n, a = 50, np.deg2rad(np.arange(50) * 7.2)
    cycles = 10  # 60 s / (2 heights * 3 s)
    t = (np.arange(cycles)[:, None, None, None] * 6.0 + np.arange(2)[None, :, None, None] * 3.0
         + np.arange(3)[None, None, :, None] * 1.0 + np.arange(n)[None, None, None, :] / n)
    np.testing.assert_allclose(s.los_time.reshape(cycles, 3, 2, n).transpose(0, 2, 1, 3), t)
    ub = u_at(t).mean(axis=2)  # (c, h, j)
    u = 2 / n * np.sum(np.sin(a) ** 2 * ub, -1)
    v = 2 / n * np.sum(np.sin(a) * np.cos(a) * ub, -1)
    w = np.tan(np.deg2rad(30.0)) / n * np.sum(np.sin(a) * ub, -1)
    np.testing.assert_allclose(s.velocity[..., 0], u, rtol=1e-10)
    np.testing.assert_allclose(s.velocity[..., 1], v, atol=1e-10)
    np.testing.assert_allclose(s.velocity[..., 2], w, atol=1e-10)
    np.testing.assert_allclose(s.time, t.max(axis=(2, 3)))


def test_availability_and_sta_roundtrip(tmp_path):
    """A data gap removes exactly the reconstructions that use a LOS inside it; the .sta
    written holds the statistics."""
    scan = lidarjax.windcube_v2()
    gap = (100.0, 130.0)
    s = simulate_series(gust(gap=gap), scan, MOUNT, HEIGHTS, (0.0, 600.0))
    t = np.arange(600) * 1.0
    win = _sliding_reference(np.arange(600) % 5, t, 5)
    bad = np.any((t[win] >= gap[0]) & (t[win] < gap[1]), axis=1)
    np.testing.assert_array_equal(np.isnan(s.velocity[:, 0, 0]), bad)
    st = statistics(s)
    np.testing.assert_allclose(st.availability[0], 100.0 * (~bad).sum() / bad.size)
    u_ref = 0.5 * (u_at(t[win[:, 1]]) + u_at(t[win[:, 3]]))[~bad]
    np.testing.assert_allclose(st.speed[0], u_ref.mean(), rtol=1e-12)
    ends = np.array(["2024-01-01T00:10"], dtype="datetime64[s]")
    path = write_series_sta(tmp_path / "sim.sta", st, HEIGHTS, ends, scan=scan)
    rec = lidarjax.io.read_sta(path)
    np.testing.assert_allclose(rec.heights, HEIGHTS)
    for name in ("speed", "speed_std", "speed_min", "speed_max", "direction", "w_std",
                 "availability"):
        np.testing.assert_allclose(getattr(rec, name), np.asarray(getattr(st, name)), atol=6e-5,
                                   err_msg=name)


def _tilt_series(scan, motion):
    sched = Schedule(np.zeros(scan.n_beams), 1.0, update="each_visit")  # beams simultaneous
    field = lidarjax.scenes.uniform(U, 270.0)
    return simulate_series(field, scan, MOUNT, HEIGHTS, (0.0, 600.0), schedule=sched,
                           motion=motion, point_dt=1.0)


def test_tilting_lidar_closed_form_bias_and_variance():
    """Roll phi(t) = A sin(2 pi t / T) in a uniform wind U along the roll axis' normal (x).

    The uncompensated instrument reports the body-frame wind R_y(phi)^T (U, 0, 0) =
    (U cos phi, 0, U sin phi). Over whole periods, with J_n the Bessel functions (A in
    radians):

    - mean speed U J0(A): bias U (J0(A) - 1) ~ -U A^2 / 4;
    - added speed variance U^2 ((1 + J0(2A)) / 2 - J0(A)^2) ~ U^2 A^4 / 32;
    - Z-wind mean 0 and variance U^2 (1 - J0(2A)) / 2 ~ U^2 A^2 / 2.

    With tilt compensation the instrument reports U exactly (no bias, no variance)."""
    amp_deg, period = 5.0, 10.0
    motion = SinusoidalMotion.of(roll=(amp_deg, period))
    a = np.deg2rad(amp_deg)
    st = statistics(_tilt_series(lidarjax.windcube_v1(), motion))
    np.testing.assert_allclose(st.speed[0], U * special.j0(a), rtol=1e-12)
    np.testing.assert_allclose(st.speed_std[0] ** 2, U**2 * ((1 + special.j0(2 * a)) / 2
                                                              - special.j0(a) ** 2), rtol=1e-8)
    np.testing.assert_allclose(st.w[0], 0.0, atol=1e-12)
    np.testing.assert_allclose(st.w_std[0] ** 2, U**2 * (1 - special.j0(2 * a)) / 2, rtol=1e-10)
    assert abs(st.speed[0, 0] - U - (-U * a**2 / 4)) < 1e-3 * U * a**2
    comp = statistics(_tilt_series(lidarjax.windcube_v1(tilt_compensation=True), motion))
    np.testing.assert_allclose(comp.speed[0], U, rtol=1e-12)
    np.testing.assert_allclose(comp.speed_std[0], 0.0, atol=1e-9)
    np.testing.assert_allclose(comp.w_std[0], 0.0, atol=1e-9)
    # the point sensors do not move
    np.testing.assert_allclose(st.cup_speed[0], U)


def test_surging_lidar_adds_its_velocity_variance():
    """Surge x(t) = a sin(w t) along the wind: every LOS sees n . (V - x'(t)), so the
    reconstructed speed is U - a w cos(w t): mean U, dispersion a w / sqrt(2)."""
    amp, period = 2.0, 8.0
    scan = lidarjax.windcube_v2()
    sched = Schedule(np.zeros(5), 1.0, update="each_visit")
    field = lidarjax.scenes.uniform(U, 180.0)  # towards +y = the surge axis
    s = simulate_series(field, scan, MOUNT, HEIGHTS, (0.0, 600.0), schedule=sched,
                        motion=SinusoidalMotion.of(surge=(amp, period)))
    st = statistics(s)
    np.testing.assert_allclose(st.speed[0], U, rtol=1e-12)
    np.testing.assert_allclose(st.speed_std[0], amp * 2 * np.pi / period / np.sqrt(2), rtol=1e-10)


def test_gradient_of_statistics_matches_finite_difference():
    scan = lidarjax.windcube_v2()
    sched = schedule_for(scan)  # concrete: it sets the number of LOS

    @jax.jit
    def loss(amp):
        st = statistics(simulate_series(gust(amp=amp), scan, MOUNT, [100.0], (0.0, 60.0),
                                        schedule=sched))
        return st.speed_std[0, 0] + st.speed[0, 0]

    g = jax.jit(jax.grad(loss))(1.0)
    fd = (loss(1.0 + 1e-5) - loss(1.0 - 1e-5)) / 2e-5
    np.testing.assert_allclose(g, fd, rtol=1e-6)


def test_streamed_statistics_match_series_in_chunks():
    """simulate_statistics (vmapped chunks, padded) equals statistics of each record's own
    series, whatever the chunk size; an ensemble adds a leading axis."""
    scan = lidarjax.windcube_v2()
    starts = np.array([0.0, 600.0, 1200.0])
    st = simulate_statistics(gust(), scan, MOUNT, HEIGHTS, starts, chunk=2)
    for r, s0 in enumerate(starts):
        ref = statistics(simulate_series(gust(), scan, MOUNT, HEIGHTS, (s0, 600.0)))
        for name in ("speed", "speed_std", "ti", "cup_ti", "sonic_std", "availability"):
            np.testing.assert_allclose(getattr(st, name)[r], np.asarray(getattr(ref, name))[0],
                                       rtol=1e-10, err_msg=name)
    ens = lidarjax.stack_fields([gust(amp=0.5), gust(amp=2.0)])
    st_e = simulate_statistics(ens, scan, MOUNT, HEIGHTS, starts[:2], ensemble=True, chunk=4)
    assert st_e.speed.shape == (2, 2, 2)
    np.testing.assert_allclose(st_e.cup_std[:, 0, 0], np.array([0.5, 2.0]) / np.sqrt(2), rtol=1e-12)


def test_sharded_over_forced_host_devices():
    """Two forced CPU devices: each chunk's records (3, padded to 4) are sharded over a 1-D
    mesh and give the closed-form result (run in a subprocess: XLA_FLAGS must be set before
    JAX initialises)."""
    code = textwrap.dedent("""
        import jax, numpy as np
        jax.config.update("jax_enable_x64", True)
        assert len(jax.devices()) == 2, jax.devices()
        import lidarjax
        from lidarjax.series import simulate_statistics
        f = lidarjax.scenes.power_law(10.0, 100.0, 0.2, 270.0)
        m = lidarjax.Mount([0.0, 0.0, 0.0])
        st = simulate_statistics(f, lidarjax.windcube_v2(), m, [50.0, 100.0],
                                 np.arange(3) * 600.0, chunk=3, record_length=60.0)
        # a steady power law: every record reports the profile, no dispersion
        np.testing.assert_allclose(st.speed, np.broadcast_to([10.0 * 0.5**0.2, 10.0], (3, 2)),
                                   rtol=1e-9)
        np.testing.assert_allclose(st.speed_std, 0.0, atol=1e-9)
        print("OK", st.speed.shape)
    """)
    # the suite's quick CPU compilation flags (tests/conftest.py) kept, two devices added
    flags = os.environ.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2"
    env = dict(os.environ, XLA_FLAGS=flags.strip(), JAX_PLATFORMS="cpu")
    root = str(REPO)
    env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "OK (3, 2)" in out.stdout


def test_float32_year_long_records_keep_their_time_resolution():
    """A record a year in, in float32, matches the float64 simulation of that record (float32
    times of 3e7 s alone would be rounded to 2 s): FrozenTurbulence is advanced per chunk on
    the host."""
    from lidarjax.scenes import FrozenTurbulence
    from lidarjax.turbulence import TurbulenceBox, fft_mann_box

    vel = fft_mann_box((64, 8, 8), (8.0, 8.0, 8.0), sigma_u=1.0, seed=0)

    def field(dtype):
        box = TurbulenceBox(jnp.asarray(vel, dtype), jnp.asarray([8.0, 8.0, 8.0], dtype),
                            periodic=(True, True))
        return FrozenTurbulence(lidarjax.scenes.uniform(10.0, 270.0, dtype=dtype), box, 10.0, 270.0)

    year = 365.25 * 86400.0 + 123.4
    kw = dict(record_length=60.0, chunk=1)
    st_far = simulate_statistics(field(jnp.float32), lidarjax.windcube_v1(), MOUNT, [30.0], [year],
                                 **kw)
    st_ref = simulate_statistics(field(jnp.float64), lidarjax.windcube_v1(), MOUNT, [30.0], [year],
                                 **kw)
    assert st_far.speed.dtype == np.float32
    np.testing.assert_allclose(st_far.speed_std, st_ref.speed_std, rtol=1e-4)
    np.testing.assert_allclose(st_far.speed, st_ref.speed, rtol=1e-6)


def test_probe_refined_to_the_box_resolution():
    """A box holding one wave of 11 m along the east beam (0.56 rad/m, which the pulsed
    weighting filters to |W| < 1e-6), the series refines the rule to the 4 m box (17
    nodes) and agrees with a dense 129-node integration of the same interpolated field; a
    longer wave (0.10 rad/m, |W| = 0.41) is filtered as the dense rule filters it. The CW
    probe far out needs many nodes but gets them (no warning up to 1025)."""
    from lidarjax.probe import probe_for_spacing
    from lidarjax.scenes import FrozenTurbulence
    from lidarjax.turbulence import TurbulenceBox

    n, dx, u = (64, 4, 8), 4.0, 9.73
    sin_c = np.sin(np.deg2rad(28.0))
    scan = lidarjax.windcube_v2()
    assert probe_for_spacing(lidarjax.PulsedProbe(), dx, [45.0, 226.0]).n_nodes == 17
    for m1, tol in ((23, 0.004), (9, 0.02)):
        k1 = 2 * np.pi * m1 / (n[0] * dx)
        vel = np.zeros(n + (3,))
        vel[..., 0] = np.cos(k1 * np.arange(n[0]) * dx)[:, None, None]
        box = TurbulenceBox(jnp.asarray(vel), jnp.asarray((dx, dx, dx)), periodic=(True, True))
        f = FrozenTurbulence(lidarjax.scenes.uniform(u, 270.0), box, u, 270.0)

        def var(probe, refine, f=f):
            s = simulate_series(f, scan, MOUNT, [40.0], (0.0, 600.0), probe=probe,
                                refine_probe=refine)
            return float(np.var(np.asarray(s.los)[:, 0, 1]))  # the east beam

        unfiltered = sin_c**2 / 2
        dense = var(lidarjax.PulsedProbe(n_nodes=129), False) / unfiltered
        refined = var(lidarjax.PulsedProbe(), True) / unfiltered
        assert abs(refined - dense) < tol, (m1, refined, dense)
        if m1 == 23:
            assert dense < 1e-5
    # the CW probe far out: many nodes (the Lorentzian widens as f^2), within the tolerance
    cw = lidarjax.probe_for_field(f, lidarjax.zephir(), [200.0], lidarjax.CWProbe())
    assert 60 < cw.n_nodes < 200
    # an impossible tolerance (more than MAX_NODES) warns, naming the caller
    with pytest.warns(UserWarning, match="CWProbe cannot integrate"):
        lidarjax.probe.probe_for_ranges(lidarjax.CWProbe(), 0.05, [[300.0]], caller="test")
