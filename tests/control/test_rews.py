"""The REWS of a field and the lidar's estimate of it (Task 52's processing) in flows whose
answer is known: uniform (aligned and yawed), power-law shear, and frozen turbulence, where
an on-axis beam previews the hub's wind exactly ``x / U`` ahead."""

import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj
from lidarjax import control as lc

HUB = np.array([0.0, 0.0, 150.0])


@pytest.fixture(scope="module")
def setup():
    rotor = lc.rotor_disc(120.0, spacing=20.0)
    focus = lc.cone_points(160.0, 19.176, 4, azimuth_offset=45.0)
    samples = lc.lidar_samples(focus, offsets=np.linspace(-30, 30, 5), offset_weights=[1, 2, 3, 2, 1],
                               times=[0.25, 0.5, 0.75, 1.0])
    return rotor, samples


@pytest.mark.parametrize("misalignment", [0.0, 10.0])
def test_uniform_flow(setup, misalignment):
    """12 m/s from 270: the REWS is 12 cos(misalignment), and the symmetric beams' estimate too
    (the lateral components of opposite beams cancel)."""
    rotor, samples = setup
    field = lj.scenes.uniform(12.0, 270.0)
    t = jnp.array([0.0, 5.0])
    expected = 12 * np.cos(np.deg2rad(misalignment))
    yaw = 270 + misalignment
    np.testing.assert_allclose(lc.rotor_rews(field, rotor, hub=HUB, yaw=yaw, times=t), expected, rtol=1e-12)
    np.testing.assert_allclose(lc.lidar_rews(field, samples, hub=HUB, yaw=yaw, times=t), expected, rtol=1e-12)


def test_shear_disc_mean(setup):
    """Power-law shear: the disc mean of U(z) over the points at hub height 150 m."""
    rotor, _ = setup
    field = lj.scenes.power_law(10.0, 150.0, 0.2, 270.0)
    z = HUB[2] + np.asarray(rotor.points[:, 1])
    expected = np.mean(10.0 * (z / 150.0) ** 0.2)
    got = lc.rotor_rews(field, rotor, hub=HUB, yaw=270.0, times=jnp.zeros(3))
    assert got.shape == (3,)  # one value per time, also for a steady field
    got = float(got[0])
    assert got == pytest.approx(expected, rel=1e-12)
    assert got < 10.0  # the concave profile's mean lies below its hub value


def test_frozen_turbulence_preview():
    """An on-axis point beam 100 m upstream sees in frozen turbulence what reaches the hub 100/U later."""
    box = lj.synthesize_box((64, 16, 16), (8.0, 8.0, 8.0), 0.5, 30.0, 3.0, seed=3)
    speed = 10.0
    field = lj.scenes.frozen_turbulence(lj.scenes.uniform(speed, 270.0), box, speed, 270.0,
                                        anchor=(0.0, 0.0, 90.0))
    hub_point = lc.rotor_disc(8.0, spacing=8.0, weighting=lambda r: (r == 0).astype(float))
    samples = lc.lidar_samples(np.array([[100.0, 0.0, 0.0]]))
    t = jnp.linspace(0.0, 20.0, 9)
    lidar = lc.lidar_rews(field, samples, hub=HUB, yaw=270.0, times=t)
    rotor = lc.rotor_rews(field, hub_point, hub=HUB, yaw=270.0, times=t + 100.0 / speed)
    np.testing.assert_allclose(lidar, rotor, rtol=1e-9)
    assert float(jnp.std(lidar)) > 0.1  # a turbulent signal, not a constant
