"""Reconstruction near its limits: the beam matrix's condition number against the cone angle
(closed forms), the ILL_CONDITIONED flag at exactly its threshold, Scan's refusal past
MAX_CONDITION, and LOS noise amplified like the condition number."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj
from lidarjax.scan import ILL_CONDITIONED, MAX_CONDITION

CONES = np.array([0.01, 0.1, 0.5, 1.0, 5.0, 15.0, 28.0, 30.0, 45.0, 54.0, 60.0, 80.0])


def cond_tilted(c):
    """K >= 3 evenly spaced tilted beams (DBS, sine fit): sqrt(2)/tan(c), or its inverse."""
    t = np.tan(np.radians(c))
    return np.maximum(np.sqrt(2) / t, t / np.sqrt(2))


def cond_v2(c):
    """Four tilted beams plus a vertical one: sqrt((4 cos^2 c + 1) / (2 sin^2 c)), or inverse."""
    r = (4 * np.cos(np.radians(c)) ** 2 + 1) / (2 * np.sin(np.radians(c)) ** 2)
    return np.sqrt(np.maximum(r, 1 / r))


@pytest.mark.parametrize(
    "make, formula",
    [(lj.windcube_v1, cond_tilted), (lambda c: lj.zephir(c, 50), cond_tilted),
     (lambda c: lj.Scan([10.0, 130.0, 250.0], c), cond_tilted), (lj.windcube_v2, cond_v2)],
    ids=["dbs", "sine_fit_50", "three_beams", "v2"],
)
def test_condition_number_closed_forms(make, formula):
    got = np.array([float(make(c).condition_number()) for c in CONES])
    np.testing.assert_allclose(got, formula(CONES), rtol=1e-9)
    # the documented landmarks: 2.45 at 30 degrees (V2: 3.06 at 28), at most 18.1 over the
    # supported cone angles 5 to 60 degrees
    assert {cond_tilted: formula(30.0), cond_v2: formula(28.0)}[formula] == pytest.approx(
        {cond_tilted: 2.449, cond_v2: 3.057}[formula], abs=1e-3)
    assert max(formula(np.linspace(5.0, 60.0, 56))) < 18.1


@jax.jit
def _v1_flags(cones):
    scene = lj.scenes.uniform(10.0, 200.0, 0.3)

    def one(c):
        return lj.simulate(scene, lj.windcube_v1(c), lj.Mount([0.0, 0.0, 0.0]),
                           jnp.array([40.0]), point_reference=False)

    sims = jax.vmap(one)(cones)
    return sims.flags[:, 0], sims.condition_number, sims.lidar_velocity[:, 0]


def test_ill_conditioned_flag_fires_exactly_where_the_condition_number_crosses():
    c_star = np.degrees(np.arctan(np.sqrt(2) / ILL_CONDITIONED))  # 0.8102 degrees
    assert c_star == pytest.approx(0.8102, abs=1e-4)
    cones = jnp.array([c_star * (1 - 1e-9), c_star * (1 + 1e-9), 5.0, 30.0])
    flags, cond, velocity = _v1_flags(cones)
    ill = (np.asarray(flags) & lj.Flag.ILL_CONDITIONED) != 0
    assert ill.tolist() == [True, False, False, False]
    np.testing.assert_allclose(cond, cond_tilted(np.asarray(cones)), rtol=1e-9)
    # the values are still computed (the flag marks their sensitivity to LOS errors)
    np.testing.assert_allclose(velocity, np.broadcast_to(velocity[-1], velocity.shape),
                               atol=1e-10)


@pytest.mark.parametrize(
    "make, cone, limit",
    [(lj.windcube_v1, 0.008, 0.0082), (lj.windcube_v2, 0.009, 0.0091),
     (lambda c: lj.zephir(c, 50), 0.001, 0.0082)],
)
def test_scan_refuses_past_max_condition_naming_the_condition_number_and_cone(make, cone, limit):
    with pytest.raises(ValueError) as info:
        make(cone)
    msg = str(info.value)
    cond = float(cond_tilted(cone) if make is not lj.windcube_v2 else cond_v2(cone))
    assert cond > MAX_CONDITION
    assert f"cone angle {cone:.3g} degrees" in msg
    assert f"condition number is {cond:.3g}" in msg
    assert f"at least {limit:.2g} degrees" in msg
    assert float(make(limit).condition_number()) <= MAX_CONDITION  # the advice works
    if make is not lj.windcube_v2:  # a vertical beam keeps w determined at any cone angle
        with pytest.raises(ValueError, match="too close to the horizontal"):
            make(89.9999)


def test_degenerate_azimuths_are_named_as_such():
    with pytest.raises(ValueError, match="three distinct directions"):
        lj.Scan([0.0, 1e-4, 2e-4], 30.0)


@pytest.mark.parametrize("make, k", [(lj.windcube_v1, 4), (lambda c: lj.zephir(c, 12), 12)],
                         ids=["dbs", "sine_fit_12"])
def test_los_noise_reaches_the_horizontal_wind_amplified_like_the_condition_number(make, k):
    """Measured: the rms horizontal error under LOS noise sigma is cond sigma / (sqrt(K) cos c)
    (sigma sqrt(2/K) / sin c), so it grows like the condition number as the cone closes."""
    sigma, n = 0.1, 20_000
    wind = np.array([7.0, -4.0, 0.5])
    rng = np.random.default_rng(0)
    cones = np.array([0.1, 0.5, 2.0, 10.0, 30.0, 50.0])
    conds, rms = [], []
    for c in cones:
        scan = make(c)
        los = np.asarray(scan.directions()) @ wind
        noisy = los + sigma * rng.standard_normal((n, los.size))
        err = np.asarray(lj.reconstruct(scan, jnp.asarray(noisy)))[:, :2] - wind[:2]
        conds.append(float(scan.condition_number()))
        rms.append(np.sqrt(np.mean(err**2 / 1.0, axis=0)).mean())
    conds, rms = np.array(conds), np.array(rms)
    predicted = conds * sigma / (np.sqrt(k) * np.cos(np.radians(cones)))
    np.testing.assert_allclose(rms, predicted, rtol=0.03)
    slope = np.polyfit(np.log(conds[:3]), np.log(rms[:3]), 1)[0]
    assert slope == pytest.approx(1.0, abs=0.02)
