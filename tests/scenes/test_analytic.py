"""Analytic scenes obey their physics: boundary conditions, continuity, irrotationality."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj

RNG = np.random.default_rng(1)


def jacobian_at(scene, pts):
    return jax.vmap(jax.jacfwd(scene.sample))(jnp.asarray(pts))


def test_hemisphere_potential_flow():
    scene = lj.scenes.hemisphere(radius=20.0, speed=10.0, direction=235.0, centre=[5.0, -3.0, 0.0])
    c = np.array([5.0, -3.0, 0.0])
    # no flow through the body surface, no flow through the ground
    th, ph = RNG.uniform(0.05, np.pi / 2 - 0.05, 50), RNG.uniform(0, 2 * np.pi, 50)
    nrm = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)
    v = np.asarray(scene.sample(c + 20.0 * (1 + 1e-12) * nrm))
    np.testing.assert_allclose(np.sum(v * nrm, -1), 0.0, atol=1e-9)
    ground = c + np.stack([RNG.uniform(-80, 80, 20), RNG.uniform(-80, 80, 20), np.zeros(20)], -1)
    ground = ground[np.linalg.norm(ground - c, axis=-1) > 21]
    np.testing.assert_allclose(np.asarray(scene.sample(ground))[:, 2], 0.0, atol=1e-12)
    # 1.5 x speed-up at the top, free stream far away
    top = np.asarray(scene.sample(c + [0.0, 0.0, 20.0 + 1e-9]))
    assert np.hypot(*top[:2]) == pytest.approx(15.0, rel=1e-8)
    far = np.asarray(scene.sample(c + [0.0, 0.0, 1e5]))
    np.testing.assert_allclose(far, 10.0 * np.asarray(lj.heading(235.0)), atol=1e-9)
    # divergence- and curl-free
    pts = c + RNG.uniform([-60, -60, 1], [60, 60, 60], size=(30, 3))
    pts = pts[np.linalg.norm(pts - c, axis=-1) > 21]
    jac = np.asarray(jacobian_at(scene, pts))
    np.testing.assert_allclose(np.trace(jac, axis1=1, axis2=2), 0.0, atol=1e-12)
    np.testing.assert_allclose(jac, np.transpose(jac, (0, 2, 1)), atol=1e-12)
    # NaN inside the body and below ground
    assert np.all(np.isnan(scene.sample(np.array([c + [0, 0, 19.0], c + [30.0, 0, -1.0]]))))


def test_hill_linear_theory():
    h, lh = 40.0, 300.0
    scene = lj.scenes.hill(height=h, half_width=lh, speed=10.0, direction=270.0, ridge_normal=90.0)
    n = RNG.uniform(-900, 900, 40)
    zs = h / (1 + (n / lh) ** 2)
    surface = np.stack([n, RNG.uniform(-50, 50, 40), zs], -1)
    v = np.asarray(scene.sample(surface))
    # flow follows the terrain to first order in the slope: the tangency error, relative to
    # the largest slope, shrinks linearly with H/L (linear theory applies the boundary
    # condition at the datum z = 0)
    n_line = np.linspace(-900, 900, 401)

    def tangency_error(height):
        n = n_line
        sc = lj.scenes.hill(height=height, half_width=lh, speed=10.0, direction=270.0,
                            ridge_normal=90.0)
        z_s = height / (1 + (n / lh) ** 2)
        vv = np.asarray(sc.sample(np.stack([n, 0 * n, z_s], -1)))
        slope = -2 * height * lh**2 * n / (lh**2 + n**2) ** 2
        return np.max(np.abs(vv[:, 2] / vv[:, 0] - slope)) / np.max(np.abs(slope))

    e1, e2 = tangency_error(10.0), tangency_error(5.0)
    assert e1 < 0.1 and e2 / e1 == pytest.approx(0.5, rel=0.1)
    assert np.all(np.isfinite(v))
    pts = np.stack([RNG.uniform(-900, 900, 30), RNG.uniform(-50, 50, 30),
                    RNG.uniform(45, 300, 30)], -1)
    jac = np.asarray(jacobian_at(scene, pts))
    np.testing.assert_allclose(np.trace(jac, axis1=1, axis2=2), 0.0, atol=1e-12)
    np.testing.assert_allclose(jac, np.transpose(jac, (0, 2, 1)), atol=1e-12)
    assert np.isnan(scene.sample(np.array([0.0, 0.0, h - 1.0]))).all()


def test_hill_surface_value_matches_formula():
    h, lh, u = 30.0, 200.0, 8.0
    scene = lj.scenes.hill(height=h, half_width=lh, speed=u, direction=270.0, ridge_normal=90.0)
    n = np.linspace(-600, 600, 13)
    v = np.asarray(scene.sample(np.stack([n, 0 * n, 0 * n + h + 1.0], -1)))  # above the crest
    zeta = n + 1j * (h + 1.0)
    w = u * h * lh / (lh - 1j * zeta) ** 2
    np.testing.assert_allclose(v[:, 0], u + w.real, rtol=1e-12)
    np.testing.assert_allclose(v[:, 2], -w.imag, atol=1e-12)


def test_power_law_and_veer():
    scene = lj.scenes.power_law(speed_ref=10.0, z_ref=100.0, alpha=0.2, direction=180.0, veer=0.1)
    z = np.array([25.0, 100.0, 200.0])
    v = scene.sample(np.stack([0 * z, 0 * z, z], -1))
    np.testing.assert_allclose(lj.horizontal_speed(v), 10.0 * (z / 100.0) ** 0.2, rtol=1e-12)
    np.testing.assert_allclose(lj.wind_direction(v), 180.0 + 0.1 * (z - 100.0), rtol=1e-12)
    assert np.isnan(scene.sample(jnp.array([0.0, 0.0, -1.0]))).all()
    np.testing.assert_array_equal(scene.sample(jnp.array([0.0, 0.0, 0.0])), 0.0)


def test_uniform_direction_convention():
    v = lj.scenes.uniform(5.0, 270.0, 0.3).sample(jnp.zeros((2, 3)))
    np.testing.assert_allclose(v, [[5.0, 0.0, 0.3]] * 2, atol=1e-12)
