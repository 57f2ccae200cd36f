"""The seed's ten correction factors (`lidarjax.correction_factors`, seed 000 section 3.4):
their definitions, NaN (never inf) for small denominators and calm, and the flag."""

import jax.numpy as jnp
import numpy as np

import lidarjax as lj

HEIGHTS = np.array([10.0, 40.0, 80.0])
SCANS = {"v1": lj.windcube_v1(30.0), "v2": lj.windcube_v2(28.0)}


def test_correction_factor_definitions():
    scene = lj.scenes.hemisphere(radius=20.0, speed=12.0, direction=250.0)
    u_ref = 12.0 * np.asarray(lj.heading(250.0))
    mount = lj.Mount([4.0, -3.0, 20.5], beta=20.0, gamma=5.0, psi=180.0, epsilon=-7.0)
    sim = lj.simulate(scene, SCANS["v2"], mount, HEIGHTS, u_ref=u_ref)
    L, P, F = (np.asarray(a) for a in (sim.lidar_velocity, sim.point_velocity, sim.free_velocity))
    hs = lambda v: np.hypot(v[..., 0], v[..., 1])  # noqa: E731
    np.testing.assert_allclose(sim.cff_u, F[0] / L[:, 0])
    np.testing.assert_allclose(sim.cff_v, F[1] / L[:, 1])
    np.testing.assert_allclose(sim.cff_w, (F[2] - L[:, 2]) / hs(F))
    np.testing.assert_allclose(sim.cff_U, hs(F) / hs(L))
    np.testing.assert_allclose(sim.cfp_u, P[:, 0] / L[:, 0])
    np.testing.assert_allclose(sim.cfp_w, P[:, 2] / L[:, 2])
    np.testing.assert_allclose(sim.cfp_U, hs(P) / hs(L))
    np.testing.assert_allclose(lj.wrap180(sim.lidar_direction + sim.cff_th - sim.free_direction), 0,
                               atol=1e-9)
    np.testing.assert_allclose(lj.wrap180(sim.lidar_direction + sim.cfp_th - sim.point_direction), 0,
                               atol=1e-9)
    # close above the body the lidar's beams reach outside the speed-up region, so it sees the
    # free-stream speed better than the point above the deck (seed 003, figure 4)
    assert abs(sim.cff_U[0] - 1) < 0.1 * abs(sim.cff_U[0] / sim.cfp_U[0] - 1)


def test_small_denominators_give_nan_not_inf():
    # wind exactly along lidar -y: u_lidar = 0, w_lidar = 0
    scene = lj.scenes.uniform(10.0, 0.0)
    sim = lj.simulate(scene, SCANS["v1"], lj.Mount([0.0, 0.0, 0.0]), HEIGHTS, u_ref=[0.0, -10.0, 0.0])
    assert np.all(np.isnan(sim.cff_u)) and np.all(np.isnan(sim.cfp_w))
    np.testing.assert_allclose(sim.cff_v, 1.0)
    np.testing.assert_allclose(sim.cff_w, 0.0)
    assert np.all(sim.flags & lj.Flag.RATIO_UNDEFINED)
    # calm: no direction, no ratios, flagged, nothing infinite
    calm = lj.simulate(lj.scenes.uniform(0.0), SCANS["v2"], lj.Mount([0.0, 0.0, 0.0]), HEIGHTS,
                       u_ref=[0.0, 0.0, 0.0])
    for name in ("cff_u", "cff_U", "cff_th", "cff_w", "cfp_U", "cfp_th"):
        assert np.all(np.isnan(getattr(calm, name))), name
    assert np.all(calm.flags & lj.Flag.CALM)
    assert not np.any(np.isinf(np.asarray(calm.lidar_velocity)))


def test_correction_factors_closed_form_and_ratio_tolerance():
    """Called directly on (h, 3) north-frame vectors: each factor is its formula; a
    denominator below `ratio_tol` gives NaN."""
    lidar = jnp.array([[8.0, -3.0, 0.4], [1e-9, 5.0, 0.0]])
    point = jnp.array([[8.5, -3.2, 0.3], [0.5, 5.5, 0.1]])
    free = jnp.array([9.0, -2.5, 0.0])
    f = lj.correction_factors(lidar, point, free, ratio_tol=1e-6)
    hs = lambda v: np.hypot(v[..., 0], v[..., 1])  # noqa: E731
    L, P, F = (np.asarray(a) for a in (lidar, point, free))
    np.testing.assert_allclose(f["cff_u"][0], F[0] / L[0, 0])
    np.testing.assert_allclose(f["cff_U"], hs(F) / hs(L))
    np.testing.assert_allclose(f["cfp_U"], hs(P) / hs(L))
    np.testing.assert_allclose(f["cff_w"], (F[2] - L[:, 2]) / hs(F))
    assert np.isnan(f["cff_u"][1]) and np.isnan(f["cfp_u"][1])  # u_lidar below ratio_tol
    assert np.isfinite(f["cff_v"][1])
