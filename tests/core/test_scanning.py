"""Scanning lidars: patterns, presets, the steady and time-resolved forward model, checked
against closed forms and an independent numpy implementation of the geometry."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj
from lidarjax import scanning as sc
from lidarjax.field import AbstractField

from ..helpers import assert_grad_matches_fd

RANGES = sc.gate_ranges(12, 30.0, first=75.0)


# -- presets and timing ------------------------------------------------------------------------
def test_continuous_ppi_timing_and_arcs():
    p = sc.ppi(5.0, RANGES, n_rays=36, accumulation=0.5, sweeps=2)
    az = np.asarray(p.azimuth)
    np.testing.assert_allclose(az[:36], 5.0 + 10.0 * np.arange(36))
    np.testing.assert_allclose(np.asarray(p.azimuth_rate), 20.0)  # 10 degrees per 0.5 s
    np.testing.assert_allclose(np.asarray(p.ray_start), 0.5 * np.arange(72))
    assert float(p.period) == pytest.approx(36.0)
    np.testing.assert_allclose(np.asarray(p.swept()), 10.0 * np.cos(np.deg2rad(5.0)))


def test_step_sector_alternates_and_rhi_returns():
    p = sc.ppi(2.0, RANGES, azimuth_start=30.0, azimuth_stop=90.0, n_rays=4, mode="step",
               accumulation=1.0, head_speed=20.0, sweeps=2)
    np.testing.assert_allclose(np.asarray(p.azimuth), [30, 50, 70, 90, 90, 70, 50, 30])
    np.testing.assert_allclose(np.asarray(p.azimuth_rate), 0.0)
    # step 20 degrees at 20 deg/s: 1 s move + 1 s accumulation per ray, no return
    np.testing.assert_allclose(np.asarray(p.ray_start), [0, 2, 4, 6, 7, 9, 11, 13])
    r = sc.rhi(45.0, RANGES, elevation_start=0.0, elevation_stop=180.0, n_rays=6,
               accumulation=1.0, head_speed=45.0, sweeps=2, alternate=False)
    np.testing.assert_allclose(np.asarray(r.elevation)[:6], 15.0 + 30.0 * np.arange(6))
    np.testing.assert_allclose(np.asarray(r.ray_start)[6], 6.0 + 4.0)  # 180 degrees back at 45/s
    u = np.asarray(r.directions())
    assert u[-1, 1] < 0 and u[0, 1] > 0  # over the top to the opposite horizon


def test_stare_vad_and_rosette():
    s = sc.stare(10.0, 90.0, RANGES, n_rays=3, accumulation=2.0, gap=0.5)
    np.testing.assert_allclose(np.asarray(s.ray_times()), [1.0, 3.5, 6.0])
    v = sc.vad(75.0, RANGES, n_rays=6)
    np.testing.assert_allclose(np.asarray(v.azimuth), 60.0 * np.arange(6))
    assert v.kind == "vad"
    ro = sc.spinner_rosette(RANGES, n_points=200, half_angle=30.0)
    theta = 90.0 - np.asarray(ro.elevation)
    assert theta.max() == pytest.approx(30.0, abs=0.1) and theta.min() < 3.0
    # rates integrate the curve: start + rate * T reaches the next ray's start angles
    th_end = 90.0 - (np.asarray(ro.elevation) + np.asarray(ro.elevation_rate) * np.asarray(ro.accumulation) / 2)
    th_next, _ = sc.rosette_angles(np.asarray(ro.ray_start) + np.asarray(ro.accumulation))
    np.testing.assert_allclose(th_end, th_next, atol=1e-9)


@pytest.mark.parametrize("bad", [
    lambda: sc.ppi(5.0, [-1.0, 10.0]),
    lambda: sc.ppi(5.0, RANGES, mode="spiral"),
    lambda: sc.ppi(5.0, RANGES, azimuth_start=10.0, azimuth_stop=10.0),
    lambda: sc.stare(0.0, 90.0, RANGES, accumulation=0.0),
    lambda: sc.ScanPattern([0.0, 1.0], 0.0, RANGES, ray_start=[1.0, 0.0], accumulation=1.0),
    lambda: sc.ScanPattern([0.0], 0.0, RANGES, ray_start=0.0, accumulation=1.0, n_sub=0),
    lambda: sc.instrument_probe("galion"),
])
def test_bad_patterns_refused_in_one_line(bad):
    with pytest.raises(ValueError) as err:
        bad()
    assert "\n" not in str(err.value)


# -- steady closed forms -------------------------------------------------------------------------
@pytest.fixture(scope="module")
def uniform_field():
    return lj.scenes.uniform(8.0, 250.0, w=0.3)


def test_uniform_flow_swept_arc_closed_form(uniform_field):
    """A continuous sweep averaging n_sub sub-rays over its arc D: the horizontal LOS is the
    centre ray's times ``sin(D/2) / (n sin(D/(2n)))`` (midpoint rule of a cosine), w's share
    unchanged; per-gate pulsed averaging of a uniform flow changes nothing."""
    f = uniform_field
    vel = np.asarray(f.sample(np.zeros(3)))
    for n_sub in (1, 4):
        p = sc.ppi(15.0, RANGES, n_rays=24, accumulation=1.0, n_sub=n_sub)
        res = sc.simulate_scan(f, p, lj.Mount([0.0, 0.0, 0.0]), probe=sc.instrument_probe())
        a, e = np.deg2rad(np.asarray(p.azimuth)), np.deg2rad(15.0)
        d = np.deg2rad(15.0)  # 360 / 24
        factor = np.sin(d / 2) / (n_sub * np.sin(d / (2 * n_sub)))
        expect = factor * np.cos(e) * (vel[0] * np.sin(a) + vel[1] * np.cos(a)) + vel[2] * np.sin(e)
        np.testing.assert_allclose(np.asarray(res.los), np.broadcast_to(expect[:, None], (24, 12)),
                                   rtol=0, atol=1e-12)
        assert np.all(np.asarray(res.flags) == 0)


def test_linear_shear_along_the_beam_is_exact_per_gate():
    """A field whose LOS grows linearly along every beam: the symmetric pulsed weighting per
    gate returns the gate centre's LOS exactly (far from the lidar, where nothing is cut)."""
    grad = np.array([[0.02, 0.0, 0.01], [0.0, -0.01, 0.0], [0.005, 0.0, 0.0]])
    f = lj.scenes.linear([6.0, -2.0, 0.2], grad)
    mount = lj.Mount([10.0, -5.0, 2.0], beta=20.0, pitch=3.0, roll=-2.0)
    p = sc.rhi(60.0, RANGES, elevation_start=5.0, elevation_stop=60.0, n_rays=8)
    pulsed = sc.simulate_scan(f, p, mount, probe=sc.instrument_probe(n_nodes=9))
    point = sc.simulate_scan(f, p, mount)
    pts = np.asarray(point.points)
    n = np.asarray(point.directions)
    v = np.asarray([6.0, -2.0, 0.2]) + pts @ grad.T
    expect = np.einsum("rgi,ri->rg", v, n)
    np.testing.assert_allclose(np.asarray(point.los), expect, atol=1e-11)
    np.testing.assert_allclose(np.asarray(pulsed.los), expect, atol=1e-10)


def _numpy_ppi_points(az, el, ranges, loc, beta, gamma, psi, pitch, roll):
    """PPI gate centres from the frame chain of lidarjax.frames written out in numpy."""
    a, e = np.deg2rad(az), np.deg2rad(el)
    body = np.stack([np.cos(e) * np.sin(a), np.cos(e) * np.cos(a), np.sin(e) * np.ones_like(a)], -1)
    p, r = np.deg2rad(pitch), np.deg2rad(roll)
    rx = np.array([[1, 0, 0], [0, np.cos(p), -np.sin(p)], [0, np.sin(p), np.cos(p)]])
    ry = np.array([[np.cos(r), 0, np.sin(r)], [0, 1, 0], [-np.sin(r), 0, np.cos(r)]])
    t = np.deg2rad(beta + gamma - psi)
    rz = np.array([[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1]])
    n = body @ (rz @ rx @ ry).T
    return np.asarray(loc) + ranges[None, :, None] * n[:, None, :], n


def test_ppi_geometry_matches_independent_numpy():
    f = lj.scenes.uniform(5.0, 200.0)
    p = sc.ppi(7.5, RANGES, azimuth_start=40.0, azimuth_stop=160.0, n_rays=13, mode="step")
    angles = dict(beta=12.0, gamma=-7.0, psi=180.0, pitch=1.5, roll=-0.7)
    loc = [1234.5, -987.25, 41.0]
    res = sc.simulate_scan(f, p, lj.Mount(loc, **angles))
    pts, n = _numpy_ppi_points(np.asarray(p.azimuth), 7.5, np.asarray(RANGES), loc, **angles)
    np.testing.assert_allclose(np.asarray(res.points), pts, rtol=0, atol=1e-10)
    np.testing.assert_allclose(np.asarray(res.directions), n, rtol=0, atol=1e-12)
    vel = np.asarray(f.sample(np.zeros(3)))
    np.testing.assert_allclose(np.asarray(res.los), (n @ vel)[:, None] * np.ones(12), atol=1e-12)


def test_batched_mounts_and_outside_flags():
    x = np.linspace(-300.0, 300.0, 31)
    z = np.linspace(0.0, 200.0, 11)
    g = lj.GridField.from_function(lambda q: np.stack([0.02 * q[..., 2] + 5, 0 * q[..., 0],
                                                        0 * q[..., 0]], -1), x, x, z)
    p = sc.ppi(10.0, sc.gate_ranges(10, 40.0), n_rays=8, mode="step")
    mounts = lj.Mount([[0.0, 0.0, 1.0], [150.0, 0.0, 1.0]])
    res = sc.simulate_scan(g, p, mounts, probe=lj.PulsedProbe(20.0, 20.0, n_nodes=5))
    assert res.los.shape == (2, 8, 10)
    one = sc.simulate_scan(g, p, mounts[1], probe=lj.PulsedProbe(20.0, 20.0, n_nodes=5))
    np.testing.assert_allclose(np.asarray(res.los[1]), np.asarray(one.los), rtol=1e-14)
    out = np.asarray(one.flags & int(lj.Flag.BEAM_OUTSIDE)) != 0
    assert out.any() and np.array_equal(out, ~np.isfinite(np.asarray(one.los)))


def test_gradients_match_finite_differences():
    """d LOS / d (elevation, azimuth rate, mount pitch) in a gridded shear field, pulsed."""
    x = np.linspace(-200.0, 200.0, 21)
    z = np.linspace(0.0, 150.0, 16)
    g = lj.GridField.from_function(
        lambda q: np.stack([4 + 0.03 * q[..., 2] + 0.002 * q[..., 0] ** 2 / 100, 1 + 0.01 * q[..., 1],
                            0.002 * q[..., 0]], -1), x, x, z)
    ranges = jnp.asarray([60.0, 90.0, 120.0])
    probe = lj.PulsedProbe(20.0, 20.0, n_nodes=7)

    def loss(theta):
        p = sc.ScanPattern(jnp.array([20.0, 70.0, 110.0]), theta[0], ranges, ray_start=jnp.arange(3.0),
                           accumulation=1.0, azimuth_rate=theta[1], n_sub=3)
        m = lj.Mount(jnp.array([0.0, 0.0, 2.0]), pitch=theta[2])
        return jnp.sum(sc.simulate_scan(g, p, m, probe=probe).los ** 2)

    assert_grad_matches_fd(loss, np.array([12.0, 7.0, 1.0]), eps=1e-5, rtol=1e-5, atol=1e-7)


# -- through time ------------------------------------------------------------------------------
class TravellingWave(AbstractField):
    """``V = U + A cos(k . x - omega t) e``: one Fourier mode moving through the domain."""

    origin: jax.Array
    origin_lo: jax.Array
    mean: jax.Array
    amplitude: jax.Array
    wavevector: jax.Array
    omega: jax.Array

    def sample_local_at(self, points, time):
        phase = jnp.einsum("...i,i->...", points, self.wavevector) - self.omega * time
        return self.mean + (self.amplitude * jnp.cos(phase))[..., None] * jnp.array([0.0, 1.0, 0.0])

    def sample_local(self, points):
        return self.sample_local_at(points, 0.0)


@pytest.fixture(scope="module")
def wave():
    z = jnp.zeros(3)
    return TravellingWave(z, z, jnp.array([3.0, 7.0, 0.0]), jnp.asarray(1.5),
                          jnp.array([0.02, 0.015, 0.01]), jnp.asarray(0.4))


@pytest.mark.parametrize("shared", [True, False])
def test_fourier_mode_stare_series_closed_form(wave, shared):
    """A stare: LOS_n(r) = n.U + A n_y W(k.n) cos(k.n r - omega t_n), with W the transfer
    function of the gate's quadrature at the beam-wise wavenumber (exact for the
    quadrature): the probe's own nodes per gate, ``lidarjax.probe_transfer(model="nodes")``,
    or the nodes the gates share, ``sum w cos(k o)`` over `gate_nodes`."""
    probe = lj.PulsedProbe(30.0, 30.0, n_nodes=9)
    p = sc.stare(30.0, 20.0, RANGES, n_rays=4, accumulation=1.0)
    res = sc.simulate_scan_series(wave, p, lj.Mount([0.0, 0.0, 0.0]), n_scans=3, start=2.0, probe=probe,
                                  shared_nodes=shared)
    n = np.asarray(sc.ray_unit_vectors(30.0, 20.0))
    kn = float(np.asarray(wave.wavevector) @ n)
    times = 2.0 + 4.0 * np.arange(3)[:, None] + 0.5 + np.arange(4)[None, :]
    np.testing.assert_allclose(np.asarray(res.times), times, atol=1e-12)
    if shared:
        offsets, weights = sc.gate_nodes(wave, p, probe)
        h = offsets[0, 1] - offsets[0, 0]  # a whole fraction of the 30 m gate spacing, at most
        assert 30.0 / h == pytest.approx(round(30.0 / h)) and h <= 2 * float(probe.support()) / 9
        w = np.sum(weights * np.cos(kn * offsets), axis=-1)
    else:
        w = np.array([lj.probe_transfer(probe, kn, r, model="nodes") for r in np.asarray(RANGES)])
    expect = (n @ np.asarray(wave.mean) + 1.5 * n[1] * w[None, None, :]
              * np.cos(kn * np.asarray(RANGES)[None, None, :] - 0.4 * times[..., None]))
    np.testing.assert_allclose(np.asarray(res.los), expect, atol=1e-12)


def test_fourier_mode_ppi_sweep_closed_form(wave):
    """A continuous PPI, point probe, one sub-ray: every ray sees the mode at its own
    azimuth, range and mid-accumulation time."""
    p = sc.ppi(10.0, RANGES, n_rays=18, accumulation=0.5)
    res = sc.simulate_scan_series(wave, p, lj.Mount([5.0, -3.0, 1.0]), n_scans=2)
    n = np.asarray(sc.ray_unit_vectors(np.asarray(p.azimuth), 10.0))
    x = np.array([5.0, -3.0, 1.0]) + np.asarray(RANGES)[None, :, None] * n[:, None, :]
    t = np.asarray(res.times)  # (2, 18)
    phase = x @ np.asarray(wave.wavevector) - 0.4 * t[..., None]
    expect = (n @ np.asarray(wave.mean))[None, :, None] + 1.5 * n[None, :, 1:2] * np.cos(phase)
    np.testing.assert_allclose(np.asarray(res.los), expect, atol=1e-12)
    np.testing.assert_allclose(t[1] - t[0], 9.0)


def test_series_through_frozen_turbulence_matches_direct_sampling():
    """The prepared sampler (lines along the wind) equals sampling the field directly at
    every sub-ray's point and time."""
    box = lj.synthesize_box((32, 16, 16), (8.0, 8.0, 8.0), 0.5, 20.0, 3.0, seed=2)
    f = lj.scenes.FrozenTurbulence(lj.scenes.uniform(8.0, 270.0), box, 8.0, 270.0,
                                   anchor=(-100.0, 0.0, 0.0))
    p = sc.ppi(20.0, sc.gate_ranges(5, 20.0, first=20.0), azimuth_start=60.0, azimuth_stop=120.0,
               n_rays=4, accumulation=1.0, n_sub=2)
    mount = lj.Mount([0.0, 0.0, 10.0])
    res = sc.simulate_scan_series(f, p, mount, n_scans=20)
    az, el = (np.asarray(a) for a in p.sub_angles())
    n = np.asarray(sc.ray_unit_vectors(az, el))  # (r, k, 3)
    pts = np.array([0.0, 0.0, 10.0]) + np.asarray(p.ranges)[None, None, :, None] * n[:, :, None, :]
    t = (np.arange(20) * float(p.period))[:, None, None] + np.asarray(p.sub_times())[None]  # (s, r, k)
    sample = jax.jit(lambda q, s: f.sample_local_at(q, s))
    v = np.asarray(sample(jnp.asarray(pts)[None], jnp.asarray(t)[..., None]))
    direct = np.einsum("srkgi,rki->srkg", v, n).mean(axis=2)
    np.testing.assert_allclose(np.asarray(res.los), direct, atol=1e-10)


def test_no_recompilation_for_new_numbers_and_float32_accuracy():
    """Changing angles, rates, times or the mount never recompiles; a float32 field at
    UTM-sized coordinates gives float32 results within 1e-4 m/s of float64."""
    from lidarjax.scanning.simulate import _steady_jit

    x = 500_000.0 + np.linspace(-400.0, 400.0, 41)
    y = 6_000_000.0 + np.linspace(-400.0, 400.0, 41)
    z = np.linspace(0.0, 100.0, 11)

    def fn(q):
        return np.stack([5 + 0.03 * q[..., 2] + 0.002 * (q[..., 1] - 6e6), 1 + 0.001 * (q[..., 0] - 5e5),
                         0.0 * q[..., 2]], -1)

    f64 = lj.GridField.from_function(fn, x, y, z)
    f32 = lj.GridField.from_function(fn, x, y, z, dtype=np.float32)
    probe = lj.PulsedProbe(20.0, 20.0, n_nodes=5)
    loc = [500_010.3, 6_000_020.7, 1.0]
    p = sc.ppi(4.0, sc.gate_ranges(8, 40.0, first=60.0), n_rays=16, n_sub=2)
    before = None
    for k in range(3):
        q = sc.ppi(4.0 + k, sc.gate_ranges(8, 40.0, first=60.0), n_rays=16, n_sub=2, accumulation=1.0 + k)
        sc.simulate_scan(f64, q, lj.Mount(loc, beta=5.0 * k), probe=probe)
        size = _steady_jit._cache_size()
        before = size if before is None else before
    assert _steady_jit._cache_size() == before
    a = sc.simulate_scan(f64, p, lj.Mount(loc), probe=probe)
    b = sc.simulate_scan(f32, p, lj.Mount(loc), probe=probe)
    assert b.los.dtype == np.float32
    np.testing.assert_allclose(np.asarray(b.los), np.asarray(a.los), atol=1e-4)


def test_series_with_platform_motion_closed_form():
    """A stare north at elevation e on a platform pitching p(t) and surging s(t) northwards
    in a uniform northward wind V: the beam's elevation is e + p(t) and the LOS is
    ``cos(e + p(t)) (V - s'(t))`` at each sub-ray's time."""
    f = lj.scenes.uniform(9.0, 180.0)  # from the south: blows towards +y at 9 m/s
    motion = lj.SinusoidalMotion.of(pitch=(3.0, 8.0), surge=(0.5, 5.0))
    p = sc.stare(0.0, 10.0, RANGES[:3], n_rays=5, accumulation=0.8, gap=0.2)
    res = sc.simulate_scan_series(f, p, lj.Mount([0.0, 0.0, 0.0]), n_scans=2, motion=motion,
                                  probe=lj.PulsedProbe(20.0, 20.0, n_nodes=5))
    t = np.asarray(res.times)  # (2, 5) mid-accumulation, one sub-ray each
    pitch = 3.0 * np.sin(2 * np.pi * t / 8.0)
    surge_speed = 0.5 * (2 * np.pi / 5.0) * np.cos(2 * np.pi * t / 5.0)
    expect = np.cos(np.deg2rad(10.0 + pitch)) * (9.0 - surge_speed)
    np.testing.assert_allclose(np.asarray(res.los), np.repeat(expect[..., None], 3, -1), atol=1e-12)
    with pytest.raises(ValueError, match="motion"):
        sc.simulate_scan_series(f, p, lj.Mount([0.0, 0.0, 0.0]), motion="heave")
