"""float32 against float64 at UTM coordinates: gridding a scene, the forward model on the grid
and the response table built from it agree to float32 rounding of the *local* coordinates,
not of the absolute ones (a 0.03 m grid in easting at 5e5 m, 0.5 m in northing at 6e6 m)."""

import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj
from lidarjax.angles import heading

E0 = np.array([512_345.678, 6_123_456.789, 0.0])  # a UTM corner (easting, northing, datum)
AXES = (E0[0] + np.linspace(-100.0, 100.0, 41), E0[1] + np.linspace(-100.0, 100.0, 41),
        np.linspace(0.0, 120.0, 25))
MOUNT = lj.Mount(E0 + np.array([1.234, -2.345, 21.0]), epsilon=5.0)
HEIGHTS = np.array([5.0, 20.0, 60.0])
DIRECTIONS = (10.0, 130.0, 250.0)


def scene(direction):
    return lj.scenes.hemisphere(20.0, 10.0, direction, centre=E0)


@pytest.fixture(scope="module")
def runs():
    out = {}
    for dtype in (np.float64, np.float32):
        fields = [lj.GridField.from_function(scene(d).sample, *AXES, dtype=dtype)
                  for d in DIRECTIONS]
        sims = lj.simulate_rotations(fields, lj.windcube_v2(), MOUNT, jnp.asarray(HEIGHTS, dtype),
                                   u_refs=jnp.stack([10.0 * heading(d) for d in DIRECTIONS]))
        table = lj.ResponseTable.from_simulations(sims, mount=MOUNT, fields=fields)
        out[np.dtype(dtype).name] = (fields, sims, table)
    return out


def test_gridding_a_scene_in_float32_at_utm_coordinates(runs):
    """`GridField.from_function` hands the scene float64 coordinates: before, it rounded them
    to float32 first and gridded the flow up to 0.5 m off (5e-3 of the speed here)."""
    (f64, _, _), (f32, _, _) = runs["float64"], runs["float32"]
    for a, b in zip(f64, f32, strict=True):
        assert b.velocity.dtype == jnp.float32
        np.testing.assert_allclose(b.velocity, a.velocity, rtol=0, atol=1e-5)  # 10 m/s flow
    # and a scene sampled directly at host coordinates
    p = np.stack([E0 + np.array([3.3, -7.7, 25.0]), E0 + np.array([-40.1, 2.9, 5.0])])
    s64 = scene(250.0).sample(p)
    s32 = lj.scenes.hemisphere(20.0, 10.0, 250.0, centre=E0, dtype=jnp.float32).sample(p)
    assert s32.dtype == jnp.float32
    np.testing.assert_allclose(s32, s64, atol=1e-5)


def test_forward_model_float32_matches_float64_at_utm_coordinates(runs):
    (_, a, _), (_, b, _) = runs["float64"], runs["float32"]
    assert b.los.dtype == jnp.float32 and np.all(b.flags & lj.Flag.BEAM_OUTSIDE == 0)
    np.testing.assert_allclose(b.los, a.los, atol=2e-5)  # m/s, for a 10 m/s wind
    np.testing.assert_allclose(b.lidar_speed, a.lidar_speed, atol=2e-5)
    np.testing.assert_allclose(lj.wrap180(b.lidar_direction - a.lidar_direction), 0.0, atol=2e-4)
    np.testing.assert_allclose(b.cff_U, a.cff_U, atol=3e-6)
    np.testing.assert_array_equal(b.flags, a.flags)


def test_response_table_beam_velocity_float32_at_utm_coordinates(runs):
    """The table samples the beam velocity at float64 beam points from the mount: before, it
    used `Simulation.points`, rounded to float32 (0.5 m at this northing), and the velocity
    projected on the beams disagreed with the LOS response by 1e-2 per unit speed."""
    (_, _, a), (_, _, b) = runs["float64"], runs["float32"]
    assert b.beam_velocity.dtype == jnp.float32
    for t, tol in ((a, 1e-12), (b, 1e-6)):
        proj = np.einsum("shbk,bk->shb", np.asarray(t.beam_velocity, np.float64),
                         np.asarray(t.beam_vectors, np.float64))
        np.testing.assert_allclose(proj, t.response, atol=tol)
    np.testing.assert_allclose(b.beam_velocity, a.beam_velocity, atol=1e-6)
