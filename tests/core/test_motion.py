"""Platform motion (`lidarjax.SinusoidalMotion`, `lidarjax.SampledMotion`): closed-form states
and velocities, a logged motion interpolated, NaN outside the log."""

import jax
import numpy as np
import pytest

from lidarjax.motion import SampledMotion, SinusoidalMotion


def test_sinusoidal_motion_state_and_velocity_closed_form():
    amp, period, phase = 1.5, 7.0, 0.3
    m = SinusoidalMotion.of(heave=(amp, period, phase))
    t = np.linspace(0.0, 20.0, 41)
    off, vel, att = (np.asarray(a) for a in jax.jit(lambda m, t: m.state(t))(m, t))
    w = 2 * np.pi / period
    np.testing.assert_allclose(off[:, 2], amp * np.sin(w * t + phase), atol=1e-12)
    np.testing.assert_allclose(vel[:, 2], amp * w * np.cos(w * t + phase), atol=1e-12)
    np.testing.assert_allclose(off[:, :2], 0.0)
    np.testing.assert_allclose(att, 0.0)


def test_sampled_motion_interpolates_a_log():
    """A logged sinusoid, linearly interpolated, gives the sinusoid's state (to the
    interpolation error), its velocity by central differences, and NaN outside the log."""
    amp, period = 2.0, 8.0
    exact = SinusoidalMotion.of(surge=(amp, period), pitch=(3.0, 5.0))
    tt = np.arange(0.0, 60.0, 0.02)
    state = jax.jit(lambda motion, t: motion.state(t))
    off, vel, att = (np.asarray(a) for a in state(exact, tt))
    logged = SampledMotion(tt, off, att)
    t = np.concatenate([np.linspace(1.0, 50.0, 777), [-1.0, 61.0]])
    got, want = state(logged, t), state(exact, t)
    for a, b, tol in zip(got, want, (1e-3, 4e-3, 2e-3), strict=True):
        np.testing.assert_allclose(np.asarray(a)[:-2], np.asarray(b)[:-2], atol=tol)
        assert np.all(np.isnan(np.asarray(a)[-2:]))
    with pytest.raises(ValueError, match="increasing"):
        SampledMotion([0.0, 0.0, 1.0])
