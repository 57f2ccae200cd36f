"""Speed, direction and addend conventions, including the seed's own azimuth."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import lidarjax as lj


def udf_azimuth(u, v):
    """The seed listing's piecewise flow azimuth (defined for u != 0 and v != 0)."""
    if u > 0:
        if v > 0:
            return 360.0 - np.degrees(np.arctan(v / u))
        return -np.degrees(np.arctan(v / u))
    return 180.0 - np.degrees(np.arctan(v / u))


@pytest.mark.parametrize(
    "vec, expected",
    [((0, -1, 0), 0.0), ((-1, 0, 0), 90.0), ((0, 1, 0), 180.0), ((1, 0, 0), 270.0),
     ((-1, -1, 0), 45.0), ((1, 1, 5), 225.0)],
)
def test_wind_direction_cardinal(vec, expected):
    assert float(lj.wind_direction(jnp.array(vec, float))) == pytest.approx(expected, abs=1e-12)


def test_direction_range_and_calm():
    d = lj.wind_direction(jnp.array([[1e-300, -1.0, 0.0], [0.0, 0.0, 3.0]]))
    assert 0.0 <= float(d[0]) < 360.0
    assert np.isnan(float(d[1]))
    g = jax.grad(lambda v: jnp.nan_to_num(lj.wind_direction(v)))(jnp.zeros(3))
    assert np.all(np.isfinite(g))
    g = jax.grad(lj.horizontal_speed)(jnp.zeros(3))
    assert np.all(g == 0)


@settings(max_examples=200, deadline=None)
@given(st.floats(-50, 50).filter(lambda x: abs(x) > 1e-3),
       st.floats(-50, 50).filter(lambda x: abs(x) > 1e-3))
def test_seed_azimuth_matches_udf_and_meteorological(u, v):
    vec = jnp.array([u, v, 0.0])
    seed = float(lj.seed_azimuth(vec))
    assert seed == pytest.approx(udf_azimuth(u, v) % 360.0, abs=1e-9) or abs(seed - 360) < 1e-9
    met = float(lj.wind_direction(vec))
    assert np.isclose((seed + 270.0) % 360.0, met, atol=1e-9) or abs(abs(seed + 270 - 360 - met) - 360) < 1e-9


def test_seed_table1_azimuth():
    # seed 000, table 1: U = 2.25, V = -15.06 gives theta = 81.48 in the seed's azimuth
    vec = jnp.array([2.25, -15.06, 0.9])
    assert float(lj.seed_azimuth(vec)) == pytest.approx(81.503, abs=0.01)
    assert float(lj.wind_direction(vec)) == pytest.approx(351.503, abs=0.01)


@settings(max_examples=200, deadline=None)
@given(st.floats(0, 360), st.floats(-179.9, 179.9))
def test_direction_difference_wraps(d0, delta):
    def vec(d):
        r = np.radians(d)
        return jnp.array([-np.sin(r), -np.cos(r), 0.0]) * 7.0

    got = float(lj.direction_difference(vec(d0 + delta), vec(d0)))
    assert -180.0 < got <= 180.0
    assert got == pytest.approx(delta, abs=1e-9)


def test_wrap180_edges():
    np.testing.assert_allclose(lj.wrap180(jnp.array([-180.0, 180.0, 540.0, -190.0, 0.0])),
                               [180.0, 180.0, 180.0, 170.0, 0.0])
