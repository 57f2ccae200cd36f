"""Lidar–rotor spectra under the Mann tensor (`MannInflow`) against references that share no
code with them: the closed forms of isotropic von Karman turbulence (``gamma = 0``: the
one-point spectra of u, v, w and the lateral cross-spectrum of u in modified Bessel functions
K_5/6, K_1/6), and the time domain: the REWS and its lidar estimate read through
`rotor_rews` / `lidar_rews` from frozen Mann boxes (`lidarjax.synthesize_box`), whose Welch
coherence lies in its 95 % band about the analytic one up to the bandwidth."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import special

import lidarjax as lj
from lidarjax import control as lc
from lidarjax.turbulence import eddy_lifetime_jax, mann_eddy_lifetime, mann_tensor, mann_tensor_jax

AE, L, U = 0.1, 30.0, 10.0  # alpha eps^(2/3) (m^(4/3)/s^2), Mann's L (m), mean speed (m/s)
FREQ = np.logspace(-3, -1, 9)  # Hz: k1 L from 0.02 to 1.9 (coherence bandwidths lie in 0.02-0.1 Hz)
K1 = 2 * np.pi * FREQ / U


def _one_point(k1):
    """Mann (1994) eqs. 27-28, two-sided in k1 ((m/s)^2 / (rad/m)): F_11 and F_22 = F_33."""
    a2 = L**-2 + k1**2
    return 9 / 55 * AE / a2 ** (5 / 6), 3 / 110 * AE * (3 * L**-2 + 8 * k1**2) / a2 ** (11 / 6)


def _lateral_coherence(k1, d):
    """Von Karman coherence of u between points a distance d apart across k1:
    ``2^(1/6) / G(5/6) (xi^(5/6) K_5/6(xi) - xi^(11/6) K_1/6(xi) / 2)``, ``xi = d sqrt(L^-2 + k1^2)``."""
    xi = d * np.sqrt(L**-2 + k1**2)
    return 2 ** (1 / 6) / special.gamma(5 / 6) * (xi ** (5 / 6) * special.kv(5 / 6, xi)
                                                 - xi ** (11 / 6) * special.kv(1 / 6, xi) / 2)


def _points(yz, weights=None):
    yz = jnp.asarray(yz, jnp.float64)
    w = jnp.full(yz.shape[0], 1 / yz.shape[0]) if weights is None else jnp.asarray(weights)
    return lc.RotorDisc(points=yz, weights=w, pair_distance=jnp.zeros(1), pair_weight=jnp.ones(1),
                        radius=jnp.asarray(1.0))


@pytest.fixture(scope="module")
def isotropic():
    return lc.MannInflow(U, AE, L, 0.0, n_nodes=256)


def test_eddy_lifetime_and_tensor_in_jax_are_scipys():
    kl = np.logspace(-4, 4, 2001)
    np.testing.assert_allclose(np.asarray(jax.jit(eddy_lifetime_jax)(kl)), mann_eddy_lifetime(kl), rtol=1e-13)
    k = np.random.default_rng(0).standard_normal((500, 3)) * np.logspace(-3, 1, 500)[:, None]
    ref = mann_tensor(k, AE, L, 3.9)
    got = np.asarray(jax.jit(mann_tensor_jax)(k, AE, L, 3.9))
    # the same formulas; XLA contracts and reorders, so cancellations differ in the last digits
    scale = np.abs(ref).max(axis=(1, 2), keepdims=True)
    np.testing.assert_allclose(got / scale, ref / scale, rtol=1e-10, atol=1e-10)


def test_one_point_spectra_are_von_karmans(isotropic):
    """A one-point rotor at the hub and one lidar node 100 m upstream on the axis, its beam
    tilted (the lidar off the axis): S_RR = (4 pi / U) F_11, S_LL adds (ny/nx)^2 F_22 +
    (nz/nx)^2 F_33, and S_RL is S_RR delayed by the node's lead x / U."""
    n = np.array([0.9, 0.3, -0.2])
    n /= np.linalg.norm(n)
    node = np.array([[100.0, 0.0, 0.0]])
    samples = lc.lidar_samples(node, lidar_position=node[0] - 100.0 * n)
    sp = lc.lac_spectra(samples, _points([[0.0, 0.0]]), isotropic, FREQ)
    f11, f22 = _one_point(K1)
    s_u = 4 * np.pi / U * f11
    s_l = 4 * np.pi / U * (f11 + ((n[1] ** 2 + n[2] ** 2) / n[0] ** 2) * f22)
    np.testing.assert_allclose(np.asarray(sp.S_RR), s_u, rtol=1e-5)
    np.testing.assert_allclose(np.asarray(sp.S_LL), s_l, rtol=1e-5)
    np.testing.assert_allclose(np.asarray(sp.S_RL), s_u * np.exp(-2j * np.pi * FREQ * 100.0 / U), rtol=1e-5)


@pytest.mark.parametrize("d", [10.0, 30.0, 60.0])
def test_two_point_rotor_is_the_von_karman_coherence(isotropic, d):
    """R = (u(y) + u(y + d)) / 2: S_RR = (4 pi / U) F_11 (1 + coh(d)) / 2."""
    samples = lc.lidar_samples(np.array([[100.0, 0.0, 0.0]]))
    sp = lc.lac_spectra(samples, _points([[d / 2, 0.0], [-d / 2, 0.0]]), isotropic, FREQ)
    expected = 4 * np.pi / U * _one_point(K1)[0] * (1 + _lateral_coherence(K1, d)) / 2
    np.testing.assert_allclose(np.asarray(sp.S_RR), expected, rtol=5e-3)


def test_derivatives_are_central_differences():
    """Forward-mode derivative of the summed coherence along a direction in (focus distance,
    half-cone angle) against a central difference (the quadrature is the same on both sides)."""
    inflow = lc.MannInflow(U, AE, L, 3.9, n_nodes=16)
    rotor = lc.rotor_disc(40.0, spacing=20.0)
    f = jnp.asarray(FREQ[::4])

    def coherence(x):
        focus = lc.cone_points(x[0], x[1], 3, azimuth_offset=90.0)
        sp = lc.lac_spectra(lc.lidar_samples(focus, offsets=[-10.0, 0.0, 10.0]), rotor, inflow, f)
        return jnp.sum(sp.coherence)

    x, v = jnp.array([80.0, 15.0]), jnp.array([1.0, 0.2])
    # compiled whole (eagerly, each operation and its tangent compiled on its own)
    _, slope = jax.jit(lambda x, v: jax.jvp(coherence, (x,), (v,)))(x, v)
    h = 1e-3
    value = jax.jit(coherence)
    fd = (value(x + h * v) - value(x - h * v)) / (2 * h)
    assert abs(float(slope)) > 1e-4
    np.testing.assert_allclose(float(slope), float(fd), rtol=1e-5)


# --- the time domain: frozen Mann boxes read by rotor_rews / lidar_rews ---------------------

SHAPE, D, GAMMA, LB = (512, 32, 32), 8.0, 3.9, 29.4
DT = D / U  # one box node per sample: every rotor point and lidar node is read on a node
N_BOXES, NPERSEG = 9, 128  # 9 x 409.6 s = 61 min; 36 Welch segments


@pytest.fixture(scope="module")
def mann_run():
    rotor = lc.rotor_disc(63.0, spacing=D)  # the NREL 5 MW on the box's lateral-vertical lattice
    # three point beams, not symmetric in z (the sheared tensor's u-w covariance counts)
    samples = lc.lidar_samples(np.array([[96.0, 24.0, 16.0], [96.0, -24.0, 16.0], [96.0, 0.0, -32.0]]))
    hub = jnp.array([0.0, D / 2, 16 * D])  # on a node column of the even-sized box
    t = jnp.arange(SHAPE[0]) * DT
    rews, est = [], []
    for seed in range(N_BOXES):
        box = lj.synthesize_box(SHAPE, (D, D, D), AE, LB, GAMMA, seed=seed)
        field = lj.scenes.frozen_turbulence(lj.scenes.uniform(U, 270.0), box, U, 270.0)
        rews.append(np.asarray(lc.rotor_rews(field, rotor, hub=hub, yaw=270.0, times=t)) - U)
        # the estimate formed 96 / U earlier: aligned with the REWS it previews
        est.append(np.asarray(lc.lidar_rews(field, samples, hub=hub, yaw=270.0, times=t - 96.0 / U)) - U)
    return np.concatenate(rews), np.concatenate(est), samples, rotor


def test_welch_coherence_in_mann_boxes_is_the_mann_coherence(mann_run):
    """The analytic model on the box's (k2, k3) lattice (its finite lateral and vertical
    domain; every point read on a node, so no interpolation) against Welch's estimate."""
    rews, est, samples, rotor = mann_run
    f, c, n = lc.welch_coherence(rews, est, DT, nperseg=NPERSEG)
    box = lc.MannInflow(U, AE, LB, GAMMA, box=SHAPE[1:], box_spacing=(D, D))
    sp = lc.lac_spectra(samples, rotor, box, f)
    f_b = float(lc.coherence_bandwidth(sp)[0])
    sel = f <= f_b
    g2 = np.asarray(sp.coherence)[sel]
    lo, hi = lc.coherence_band(g2, n, n_bins=int(sel.sum()))
    assert n == 36 and sel.sum() >= 3
    assert np.all((lo <= c[sel]) & (c[sel] <= hi)), (f[sel], c[sel], g2)
    # the check can fail: the model at half the speed (every wavenumber doubled) does not pass
    slow = lc.MannInflow(U / 2, AE, LB, GAMMA, box=SHAPE[1:], box_spacing=(D, D))
    lo, hi = lc.coherence_band(np.asarray(lc.lac_spectra(samples, rotor, slow, f).coherence)[sel], n,
                               n_bins=int(sel.sum()))
    assert not np.all((lo <= c[sel]) & (c[sel] <= hi))


@pytest.mark.parametrize("kwargs, match", [
    (dict(alphaepsilon=None), "exactly one of alphaepsilon"),
    (dict(sigma_u=1.0), "exactly one of alphaepsilon"),
    (dict(n_nodes=3), "n_nodes must be an integer >= 4"),
    (dict(box=(8, 8)), "box \\(ny, nz\\) and box_spacing"),
    (dict(box=(8,), box_spacing=(4.0, 4.0)), "box must be \\(ny, nz\\)"),
    (dict(box=(8, 8), box_spacing=(4.0, 4.0, 4.0)), "box_spacing must be \\(dy, dz\\)"),
    (dict(length_scale=-1.0), "length_scale"),
])
def test_bad_input_is_refused_in_one_line(kwargs, match):
    args = dict(alphaepsilon=AE, length_scale=L, gamma=3.9) | kwargs
    with pytest.raises(ValueError, match=match):
        lc.MannInflow(U, **args)
    assert lc.MannInflow(U, sigma_u=1.5, length_scale=L, gamma=3.9).alphaepsilon > 0  # sigma_u alone
