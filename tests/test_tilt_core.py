"""Installation tilt (pitch, roll) in the frame chain: convention, focus ranges, compensated
and uncompensated reconstruction, the nacelle limit, gradients and the scan footprint."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import assert_grad_matches_fd

import lidarjax as lj
from lidarjax.frames import tilt_rotation

HEIGHTS = np.array([10.0, 40.0, 100.0])
SCANS = {"v1": lj.windcube_v1(), "v2": lj.windcube_v2(), "zephir": lj.zephir(n_los=12)}


def _t(pitch, roll):
    """The convention written out independently: T = R_x(pitch) R_y(roll)."""
    a, b = np.deg2rad(pitch), np.deg2rad(roll)
    rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    return rx @ ry


@pytest.mark.parametrize("pitch,roll", [(0.0, 0.0), (3.0, -2.0), (-25.0, 40.0), (-90.0, 0.0)])
def test_tilt_rotation_is_the_documented_convention(pitch, roll):
    np.testing.assert_allclose(np.asarray(tilt_rotation(pitch, roll)), _t(pitch, roll), atol=1e-15)


def test_positive_pitch_raises_s0_positive_roll_lowers_s1():
    scan, mount = lj.windcube_v1(), lj.Mount([0.0, 0.0, 0.0])
    scene = lj.scenes.uniform(10.0, 270.0)
    level = lj.simulate(scene, scan, mount, [50.0])
    pitched = lj.simulate(scene, scan, lj.Mount([0.0, 0.0, 0.0], pitch=5.0), [50.0])
    rolled = lj.simulate(scene, scan, lj.Mount([0.0, 0.0, 0.0], roll=5.0), [50.0])
    assert pitched.points[0, 0, 2] > level.points[0, 0, 2]  # S0 (+y) side up
    assert pitched.points[0, 2, 2] < level.points[0, 2, 2]  # S2 down
    assert rolled.points[0, 1, 2] < level.points[0, 1, 2]  # S1 (+x) side down
    assert rolled.points[0, 3, 2] > level.points[0, 3, 2]


@pytest.mark.parametrize("name", list(SCANS))
def test_uniform_flow_compensated_exact_uncompensated_body_frame(name):
    rng = np.random.default_rng(7)
    scan = SCANS[name]
    comp = lj.Scan(scan.azimuths, scan.cone_angle, vertical=scan.vertical, method=scan.method,
                   tilt_compensation=True)
    for _ in range(3):
        pitch, roll = rng.uniform(-20, 20, 2)
        beta, gamma, psi, eps = rng.uniform(-180, 180, 4)
        vel = rng.normal(size=3) * np.array([8.0, 8.0, 1.0])
        scene = lj.scenes.linear(vel, np.zeros((3, 3)))
        mount = lj.Mount([1.0, 2.0, 3.0], beta, gamma, psi, eps, pitch=pitch, roll=roll)
        sim_u = lj.simulate(scene, scan, mount, HEIGHTS)
        sim_c = lj.simulate(scene, comp, mount, HEIGHTS)
        # the true wind in the (level) lidar frame, then north
        r_lidar = np.asarray(lj.frames.cfd_to_lidar_rotation(mount))
        r_north = np.asarray(lj.frames.lidar_to_north_rotation(mount))
        v_level = r_lidar @ vel
        t = _t(pitch, roll)
        np.testing.assert_allclose(np.asarray(sim_c.lidar_velocity), np.broadcast_to(
            r_north @ v_level, (3, 3)), atol=1e-11)
        np.testing.assert_allclose(np.asarray(sim_u.lidar_velocity), np.broadcast_to(
            r_north @ (t.T @ v_level), (3, 3)), atol=1e-11)
        # the point reference stays level
        np.testing.assert_allclose(np.asarray(sim_u.point_velocity),
                                   np.broadcast_to(r_north @ v_level, (3, 3)), atol=1e-11)


def test_focus_ranges_and_beam_directions_follow_the_tilt():
    scan = lj.windcube_v2()
    mount = lj.Mount([10.0, -4.0, 2.0], beta=30.0, gamma=5.0, psi=180.0, pitch=7.0, roll=-3.0)
    sim = lj.simulate(lj.scenes.uniform(), scan, mount, HEIGHTS)
    n_body = np.asarray(scan.directions())
    rot = np.asarray(lj.frames.lidar_to_cfd_rotation(mount)) @ _t(7.0, -3.0)
    np.testing.assert_allclose(np.asarray(sim.directions), n_body @ rot.T, atol=1e-14)
    want_range = HEIGHTS[:, None] / n_body[None, :, 2]
    np.testing.assert_allclose(np.asarray(sim.ranges), want_range, rtol=1e-14)
    dist = np.linalg.norm(np.asarray(sim.points) - np.array([10.0, -4.0, 2.0]), axis=-1)
    np.testing.assert_allclose(dist, want_range, rtol=1e-12)


@pytest.mark.parametrize("compensated", [False, True])
def test_nacelle_pitch_minus_90_looks_along_lidar_y(compensated):
    """A forward-looking nacelle lidar: the instrument axis along the lidar's +y. In uniform
    flow the 'vertical' beam measures the axial component, and a compensating instrument
    reconstructs the level wind exactly."""
    scan = lj.windcube_v2(15.0, tilt_compensation=compensated)
    mount = lj.Mount([0.0, 0.0, 90.0], beta=0.0, pitch=-90.0)
    vel = np.array([1.5, 9.0, 0.3])  # CFD frame = lidar frame here
    sim = lj.simulate(lj.scenes.linear(vel, np.zeros((3, 3))), scan, mount, [50.0, 100.0])
    np.testing.assert_allclose(np.asarray(sim.directions[-1]), [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(np.asarray(sim.points[:, -1]), [[0, 50, 90], [0, 100, 90]],
                               atol=1e-12)
    np.testing.assert_allclose(np.asarray(sim.los[:, -1]), [9.0, 9.0], atol=1e-12)
    body = _t(-90.0, 0.0).T @ vel  # what an uncompensated instrument believes
    want = vel if compensated else body
    np.testing.assert_allclose(np.asarray(sim.lidar_velocity), [want, want], atol=1e-11)


def test_tilt_gradients_match_finite_differences():
    scene = lj.scenes.power_law(speed_ref=10.0, direction=250.0, alpha=0.2, veer=0.1,
                                z_ground=-5.0)
    scan = lj.windcube_v2()

    def speed(angles):
        m = lj.Mount([40.0, 10.0, 0.5], pitch=angles[0], roll=angles[1])
        return lj.simulate(scene, scan, m, [60.0]).lidar_speed[0]

    assert_grad_matches_fd(speed, jnp.array([1.2, -0.7]), eps=1e-5, rtol=1e-5, atol=1e-9)
    g0 = jax.grad(speed)(jnp.zeros(2))
    assert np.all(np.isfinite(np.asarray(g0)))


def test_scan_bounds_cover_tilted_beams_and_crop_is_exact():
    scan = lj.windcube_v2()
    probe = lj.PulsedProbe()
    mount = lj.Mount([0.0, 0.0, 1.0], pitch=12.0, roll=-8.0)
    heights = np.array([20.0, 60.0])
    lo, hi = lj.scan_bounds(scan, mount, heights, probe=probe)
    sim = lj.simulate(lj.scenes.uniform(), scan, mount, heights)
    pts = np.asarray(sim.points).reshape(-1, 3)
    assert np.all(pts >= lo - 1e-9) and np.all(pts <= hi + 1e-9)
    x = np.linspace(-60, 60, 25)
    z = np.linspace(0, 140, 15)
    field = lj.GridField.from_function(
        lj.scenes.power_law(speed_ref=10.0, direction=200.0, alpha=0.2, z_ground=-5.0).sample, x, x, z)
    full = lj.simulate(field, scan, mount, heights, probe=probe)
    crop = lj.simulate(field.crop(lo, hi), scan, mount, heights, probe=probe)
    np.testing.assert_array_equal(np.asarray(full.los), np.asarray(crop.los))


def test_tilt_follows_float32():
    mount = lj.Mount(np.array([1.0, 2.0, 3.0], np.float32), pitch=np.float32(2.0),
                     roll=np.float32(1.0))
    scene = lj.scenes.uniform(10.0, 270.0, dtype=jnp.float32)
    sim = lj.simulate(scene, lj.windcube_v1(), mount, np.array([50.0], np.float32))
    assert sim.los.dtype == jnp.float32
    assert np.all(np.isfinite(np.asarray(sim.lidar_velocity)))
