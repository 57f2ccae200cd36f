"""Reconstructions from scanning lidars: VAD/DBS fits at any elevation and dual-Doppler
vectors, against closed forms, numpy least squares and finite differences."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj
from lidarjax import scanning as sc

from ..helpers import central_difference

RANGES = sc.gate_ranges(6, 30.0, first=60.0)
TRUE = np.array([6.0, -3.0, 0.4])  # u, v, w: wind from 296.6 degrees


@pytest.fixture(scope="module")
def field():
    return lj.scenes.linear(TRUE, np.zeros((3, 3)))


@pytest.mark.parametrize("elevation", [5.0, 35.0, 75.0])
def test_vad_recovers_uniform_wind_at_any_elevation(field, elevation):
    p = sc.vad(elevation, RANGES, n_rays=8)
    res = sc.simulate_scan(field, p, lj.Mount([0.0, 0.0, 0.0]), probe=sc.instrument_probe())
    prof = sc.vad_fit(res.los, p.azimuth, p.elevation, p.ranges)
    np.testing.assert_allclose(np.asarray(prof.velocity), np.broadcast_to(TRUE, (6, 3)), atol=1e-11)
    np.testing.assert_allclose(np.asarray(prof.heights), np.asarray(RANGES) * np.sin(np.deg2rad(elevation)))
    assert np.all(np.asarray(prof.flags) == 0) and np.all(np.asarray(prof.residual) < 1e-11)
    # evenly spaced azimuths: cond = max(sqrt(2) tan e, 1 / (sqrt(2) tan e)) ... of N^T N
    t = np.tan(np.deg2rad(elevation))
    expect = np.sqrt(max(2 * t**2, 1 / (2 * t**2)))
    np.testing.assert_allclose(np.asarray(prof.condition), expect, rtol=1e-9)


def test_vad_equals_numpy_least_squares_with_missing_rays():
    rng = np.random.default_rng(4)
    az = np.sort(rng.uniform(0, 360, 11))
    el = rng.uniform(10, 70, 11)
    los = rng.normal(size=(2, 11, 5))
    los[0, 3, 1] = np.nan
    los[1, :9, 4] = np.nan  # 2 rays left: too few
    prof = sc.vad_fit(los, az, el, np.arange(1.0, 6.0))
    n = np.asarray(sc.ray_unit_vectors(az, el))
    for b in range(2):
        for g in range(4):
            ok = np.isfinite(los[b, :, g])
            expect = np.linalg.lstsq(n[ok], los[b, ok, g], rcond=None)[0]
            np.testing.assert_allclose(np.asarray(prof.velocity[b, g]), expect, atol=1e-12)
    assert int(prof.n_rays[0, 1]) == 10
    assert np.all(np.isnan(np.asarray(prof.velocity[1, 4])))
    assert int(prof.flags[1, 4]) & int(lj.InverseFlag.TOO_FEW_BEAMS)


def test_narrow_sector_is_flagged_ill_conditioned():
    p = sc.ppi(3.0, RANGES, azimuth_start=10.0, azimuth_stop=10.5, n_rays=5, mode="step")
    los = np.asarray(sc.ray_unit_vectors(p.azimuth, p.elevation)) @ TRUE
    prof = sc.vad_fit(np.repeat(los[:, None], 6, 1), p.azimuth, p.elevation, p.ranges)
    assert np.all(np.asarray(prof.flags) & int(lj.InverseFlag.ILL_CONDITIONED))


def test_dual_doppler_exact_and_condition_closed_form(field):
    """Level beams crossing at beta: the 2x2 condition number is cot(beta/2) (beta < 90)."""
    a = lj.Mount([0.0, 0.0, 0.0])
    pts = np.array([[200.0 * np.sin(t), 200.0 * np.cos(t), 0.0] for t in np.deg2rad([10, 30, 60, 80])])
    for beta_deg in (20.0, 50.0, 90.0):
        # lidar b on the circle seen from each point at beta from lidar a's beam
        bpos = []
        for p in pts:
            back = -p[:2] / np.linalg.norm(p[:2])
            c, s = np.cos(np.deg2rad(beta_deg)), np.sin(np.deg2rad(beta_deg))
            d = np.array([c * back[0] - s * back[1], s * back[0] + c * back[1]])
            bpos.append(p + 150.0 * np.append(d, 0.0))
        for p, loc_b in zip(pts, bpos, strict=True):
            dd, geo = sc.simulate_dual_doppler(field, a, lj.Mount(loc_b), p[None])
            np.testing.assert_allclose(float(geo.crossing_angle[0]), beta_deg, atol=1e-9)
            # level beams: w does not reach the LOS
            np.testing.assert_allclose(np.asarray(dd.velocity[0, :2]), TRUE[:2], atol=1e-11)
            np.testing.assert_allclose(float(dd.condition[0]), 1 / np.tan(np.deg2rad(beta_deg) / 2),
                                       rtol=1e-9)
            flagged = int(dd.flags[0]) & int(lj.InverseFlag.ILL_CONDITIONED)
            assert bool(flagged) == (beta_deg < 30.0)


def test_crossing_geometry_steers_each_lidar_in_its_own_frame(field):
    a = lj.Mount([10.0, -20.0, 2.0], beta=30.0, pitch=2.0)
    b = lj.Mount([400.0, 50.0, 5.0], gamma=-15.0, roll=1.0)
    pts = np.array([[200.0, 150.0, 80.0], [250.0, -40.0, 60.0]])
    geo = sc.crossing_geometry(a, b, pts)
    for mount, az, el, rng in ((a, geo.azimuth_a, geo.elevation_a, geo.range_a),
                               (b, geo.azimuth_b, geo.elevation_b, geo.range_b)):
        p = sc.ScanPattern(az, el, jnp.asarray([1.0]), ray_start=jnp.arange(2.0), accumulation=1.0)
        res = sc.simulate_scan(field, p, mount)
        # the ray steered by these angles reaches the point at that range
        got = np.asarray(res.points[:, 0]) + (np.asarray(rng)[:, None] - 1.0) * np.asarray(res.directions)
        np.testing.assert_allclose(got, pts, atol=1e-9)


def test_dual_doppler_gradients_match_finite_differences():
    x = np.linspace(-50.0, 450.0, 26)
    z = np.linspace(0.0, 200.0, 11)
    g = lj.GridField.from_function(
        lambda q: np.stack([5 + 0.01 * q[..., 2] + 0.002 * q[..., 1], 2 - 0.003 * q[..., 0],
                            0 * q[..., 0]], -1), x, x, z)
    pts = jnp.array([[200.0, 180.0, 60.0], [150.0, 250.0, 40.0]])

    def loss(loc):
        dd, _ = sc.simulate_dual_doppler(g, lj.Mount(loc), lj.Mount(jnp.array([380.0, 20.0, 3.0])), pts)
        return jnp.sum(dd.velocity[:, :2] ** 2)

    # reverse mode against centred differences (the pulsed probe's derivatives are checked
    # in test_scanning.py; this is the 2x2 solve and the steering)
    x = np.array([10.0, 5.0, 2.0])
    loss = jax.jit(loss)  # compiled once for the six differences, and one compiled gradient
    np.testing.assert_allclose(np.asarray(jax.jit(jax.grad(loss))(jnp.asarray(x))),
                               central_difference(loss, x, 1e-4), rtol=1e-5, atol=1e-8)


def test_dual_condition_is_exact_near_one_and_differentiable():
    """Level beams at azimuths ``a`` and ``a + b`` (any ``a``: rounded entries):
    cond = cot(b/2) below 90 degrees,
    d cond / d b = -1 / (2 sin^2(b/2)) per radian; at 90 exactly 1 (the textbook
    sqrt(F^2 - 4 det^2) is 1.5e-8 off there, depending on the compiler's rounding) with a
    finite gradient (the condition number's kink: q = 0)."""

    def cond(b, a=0.7):
        na = jnp.array([[np.cos(a), np.sin(a), 0.0]])
        nb = jnp.stack([jnp.cos(a + b), jnp.sin(a + b), 0.0 * b])[None]
        return sc.dual_doppler(jnp.ones(1), jnp.ones(1), na, nb).condition[0]

    for deg in (5.0, 30.0, 60.0, 89.9, 90.0):
        b = np.deg2rad(deg)
        expect = 1 / np.tan(b / 2) if deg < 90 else 1.0
        np.testing.assert_allclose(float(cond(b)), expect, rtol=4e-16 if deg == 90 else 1e-13)
        g = float(jax.grad(cond)(jnp.asarray(b)))
        assert np.isfinite(g)
        if deg < 90:
            np.testing.assert_allclose(g, -1 / (2 * np.sin(b / 2) ** 2), rtol=1e-12)


def test_vad_gradients_match_finite_differences():
    az = jnp.arange(0.0, 360.0, 45.0)

    def loss(theta):
        el = theta[0]
        n = sc.ray_unit_vectors(az, el)
        los = (n @ theta[1:])[:, None] * jnp.array([1.0, 1.1])
        return jnp.sum(sc.vad_fit(los, az, el, jnp.array([50.0, 80.0])).velocity ** 2)

    x = np.array([20.0, 5.0, -2.0, 0.5])
    loss = jax.jit(loss)  # compiled once for the eight differences, and one compiled gradient
    # The loss does not depend on the elevation (the fit is exact at any): that derivative
    # is 0, and its centred difference is rounding noise, ~eps |loss| / h = 1.4e-8 here (a
    # compiler that rounds the fit differently, e.g. XLA's CPU emitters, moves it): atol 1e-7.
    np.testing.assert_allclose(np.asarray(jax.jit(jax.grad(loss))(jnp.asarray(x))),
                               central_difference(loss, x, 1e-6), rtol=1e-6, atol=1e-7)
