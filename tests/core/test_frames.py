"""The one frame chain (`lidarjax.frames`): CFD, lidar (platform yaw beta, gamma, psi), body
(tilt) and north (epsilon) frames, for positions and velocities alike."""

import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj
from lidarjax import frames

SCANS = {"v1": lj.windcube_v1(30.0)}


def rz(deg):
    t = np.radians(deg)
    return np.array([[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1]])


@pytest.mark.parametrize("psi", [0.0, 180.0, 90.0, 37.0])
def test_beam_points_frame_chain(psi):
    """Points: p_cfd = R(beta + gamma - psi) p_lidar + location; the seed's R(beta+gamma) R(psi)
    agrees only for psi = 0 or 180."""
    beta, gamma = 50.0, 8.0
    loc = np.array([10.0, 20.0, 5.0])
    mount = lj.Mount(loc, beta=beta, gamma=gamma, psi=psi)
    sim = lj.simulate(lj.scenes.uniform(), SCANS["v1"], mount, [20.0], point_reference=False)
    c = np.radians(30.0)
    az = np.radians([0, 90, 180, 270])
    p = 20.0 * np.stack([np.tan(c) * np.sin(az), np.tan(c) * np.cos(az), np.ones(4) / 1.0], -1)
    ours = p @ rz(beta + gamma - psi).T + loc
    udf = p @ (rz(beta + gamma) @ rz(psi)).T + loc
    np.testing.assert_allclose(sim.points[0], ours, atol=1e-12)
    assert np.allclose(ours, udf, atol=1e-9) == (psi in (0.0, 180.0))


@pytest.mark.parametrize("beta, gamma, psi, eps, pitch, roll", [
    (0.0, 0.0, 0.0, 0.0, 0.0, 0.0), (81.0, -12.0, 180.0, 21.0, 3.0, -2.0),
    (200.0, 30.0, 90.0, -45.0, -90.0, 10.0)])
def test_rotations_are_orthonormal_and_compose(beta, gamma, psi, eps, pitch, roll):
    mount = lj.Mount([1.0, 2.0, 3.0], beta, gamma, psi, eps, pitch=pitch, roll=roll)
    to_cfd = np.asarray(frames.lidar_to_cfd_rotation(mount))
    to_lidar = np.asarray(frames.cfd_to_lidar_rotation(mount))
    to_north = np.asarray(frames.lidar_to_north_rotation(mount))
    cfd_north = np.asarray(frames.cfd_to_north_rotation(mount))
    for r in (to_cfd, to_lidar, to_north, cfd_north):
        np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-14)
        assert np.linalg.det(r) == pytest.approx(1.0, abs=1e-14)
    np.testing.assert_allclose(to_lidar @ to_cfd, np.eye(3), atol=1e-14)
    np.testing.assert_allclose(cfd_north, to_north @ to_lidar, atol=1e-14)
    # the written convention: R(beta + gamma - psi) to CFD, R(-epsilon) to north
    np.testing.assert_allclose(to_cfd, rz(beta + gamma - psi), atol=1e-14)
    np.testing.assert_allclose(to_north, rz(-eps), atol=1e-14)


def test_rotate_is_the_matrix_product_over_any_batch():
    rng = np.random.default_rng(0)
    r = np.asarray(frames.rotation_z(37.0)) @ np.asarray(frames.rotation_x(-12.0))
    v = rng.normal(size=(4, 5, 3))
    np.testing.assert_allclose(np.asarray(frames.rotate(jnp.asarray(r), jnp.asarray(v))), v @ r.T,
                               atol=1e-14)
    np.testing.assert_allclose(np.asarray(frames.rotation_y(90.0)) @ [1.0, 0.0, 0.0],
                               [0.0, 0.0, -1.0], atol=1e-15)
