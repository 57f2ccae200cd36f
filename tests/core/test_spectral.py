"""The spectral model (lidarjax.spectral) against closed forms, hipersim, and the simulator.

- The Mann tensor: divergence-free, symmetric positive semi-definite, isotropic von Karman for
  Gamma = 0, and equal to hipersim's implementation.
- Probe transfer functions: closed forms against a direct Fourier transform of the weighting.
- Probe-volume filtering and reconstruction in a periodic box of exact Fourier modes: the
  simulated LOS and reconstructed-u variances equal ``sum_k |A(k) . a_k|^2 / 2``.
- A Mann ensemble: lidar and point variances within the ensemble's statistical uncertainty.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate, special

import lidarjax
import lidarjax as lj
from lidarjax import scenes, spectral
from lidarjax.scenes import FrozenTurbulence
from lidarjax.turbulence import TurbulenceBox

RNG = np.random.default_rng(7)
K = RNG.normal(size=(400, 3)) * np.exp(RNG.uniform(-5, 1, size=(400, 1)))
K[:8, 0] = 0.0
K[8:12, :2] = 0.0


def test_mann_tensor_structure():
    phi = lj.mann_tensor(K, 0.7, 33.6, 3.9)
    assert np.all(np.isfinite(phi))
    np.testing.assert_allclose(phi, np.swapaxes(phi, -1, -2), rtol=0, atol=0)
    scale = phi.max()
    assert np.linalg.eigvalsh(phi).min() > -1e-12 * scale
    # incompressible: k . Phi = 0
    assert np.abs(np.einsum("nij,nj->ni", phi, K)).max() < 1e-12 * scale * np.abs(K).max()
    # Gamma = 0: isotropic von Karman, E(k) / (4 pi k^4) (k^2 delta - k k)
    iso = lj.mann_tensor(K, 0.7, 33.6, 0.0)
    k2 = np.sum(K * K, -1)
    kl = np.sqrt(k2) * 33.6
    e = 0.7 * 33.6 ** (5 / 3) * kl**4 / (1 + kl**2) ** (17 / 6)
    want = e[:, None, None] / (4 * np.pi * k2[:, None, None] ** 2) * (
        k2[:, None, None] * np.eye(3) - K[:, :, None] * K[:, None, :])
    np.testing.assert_allclose(iso, want, rtol=1e-12, atol=1e-14 * scale)
    assert np.all(lj.mann_tensor(np.zeros(3), 1.0, 30.0, 3.0) == 0)
    # eddy lifetime: (kL)^(-2/3) at large kL, (kL)^-1 at small kL (Mann 1994)
    assert lj.mann_eddy_lifetime(1e4) * 1e4 ** (2 / 3) == pytest.approx(1.0, rel=1e-6)
    c = special.gamma(4 / 3) * special.gamma(5 / 2) / special.gamma(17 / 6)  # 2F1 ~ c (kL)^(2/3)
    assert lj.mann_eddy_lifetime(1e-5) * 1e-5 == pytest.approx(c**-0.5, rel=1e-5)


def test_mann_tensor_matches_hipersim():
    from hipersim.turbgen import manntensor
    phi = lj.mann_tensor(K, 0.7, 33.6, 3.9)
    ref = manntensor.manntensorcomponents(K[:, 0], K[:, 1], K[:, 2], 3.9, 33.6, 0.7, 2)
    mine = [phi[:, 0, 0], phi[:, 1, 1], phi[:, 2, 2], phi[:, 0, 1], phi[:, 0, 2], phi[:, 1, 2]]
    # hipersim uses a rational approximation of the eddy lifetime (1e-3 relative)
    for a, b in zip(mine, ref, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-2, atol=1e-2 * np.abs(phi[:, 0, 0]).max())


@pytest.mark.parametrize("probe", [lidarjax.PulsedProbe(), lidarjax.CWProbe()], ids=["pulsed", "cw"])
def test_probe_transfer_closed_forms(probe):
    focus = 115.0
    kappa = np.array([0.0, 0.01, 0.05, 0.1, 0.3])
    closed = lj.probe_transfer(probe, kappa, focus, model="weight")
    assert closed[0] == pytest.approx(1.0)

    # the weighting's Fourier transform by the trapezoid rule on a wide, fine grid (the
    # Lorentzian's tail beyond 20 km holds G / (pi 2e4) ~ 1.3e-4 of its weight)
    o = np.linspace(0.0, 2e4, 400_001)
    phi = np.asarray(probe.weight(jnp.asarray(o), focus))
    direct = [2 * integrate.trapezoid(phi * np.cos(k * o), o) for k in kappa]
    np.testing.assert_allclose(closed, direct, rtol=0, atol=3e-4)
    trunc = lj.probe_transfer(probe, kappa, focus, model="truncated")
    nodes = lj.probe_transfer(probe, kappa, focus, model="nodes")
    tail = float(probe.tail)
    assert np.max(np.abs(trunc - closed)) < 2 * tail  # truncation changes W by ~ the tail
    np.testing.assert_allclose(nodes[:3], trunc[:3], atol=2e-3)  # the quadrature resolves kappa <= 0.05


# -- exact Fourier modes: probe filtering and reconstruction -----------------------------------
SHAPE, SPACING, U = (512, 64, 64), (1.0, 1.0, 1.0), 10.0
# distinct |m1| (uncorrelated in time); wavelengths of 51 to 128 m, 51 cells or more: the
# trilinear error (h^2, see test_turbulence) stays below 0.4 per cent of the variance
MODES = [(4, 0, 1), (6, 1, 1), (8, -1, 1), (10, 1, -1)]
AMPS = RNG.normal(size=(len(MODES), 3))
PHASES = RNG.uniform(0, 2 * np.pi, size=len(MODES))
M_TIMES = 48


def mode_box():
    n, s = np.asarray(SHAPE), np.asarray(SPACING)
    x = np.arange(n[0]) * s[0]
    y = (np.arange(n[1]) - (n[1] - 1) / 2) * s[1]
    z = np.arange(n[2]) * s[2]
    X, Y, Z = np.meshgrid(x, y, z, indexing="ij")
    vel = np.zeros(SHAPE + (3,))
    ks = []
    for m, a, ph in zip(MODES, AMPS, PHASES, strict=True):
        k = 2 * np.pi * np.asarray(m) / (n * s)
        ks.append(k)
        vel += np.cos(k[0] * X + k[1] * Y + k[2] * Z + ph)[..., None] * a
    return TurbulenceBox(jnp.asarray(vel), jnp.asarray(SPACING), periodic=True), np.array(ks)


@eqx.filter_jit
def _series(box, scan, probe, heights, offset=0.0):
    f = FrozenTurbulence(scenes.uniform(U, 270.0), box, U, 270.0)
    mount = lidarjax.Mount(jnp.zeros(3))
    period = box.length / U
    ts = jnp.arange(M_TIMES) * (period / M_TIMES) + offset

    def one(t):
        sim = lidarjax.simulate(f.advanced(t), scan, mount, heights, probe=probe)
        return sim.los, sim.lidar_velocity, sim.point_velocity, sim.flags

    return jax.vmap(one)(ts)


@pytest.fixture(scope="module")
def modes():
    return mode_box()


@pytest.mark.parametrize("kind", ["windcube_v2", "zephir"])
def test_fourier_modes_probe_filtering_and_reconstruction(modes, kind):
    box, ks = modes
    if kind == "windcube_v2":
        scan, probe = lidarjax.windcube_v2(), lidarjax.PulsedProbe()
    else:
        scan, probe = lidarjax.zephir(n_los=12), lidarjax.CWProbe()
    h = 100.0
    # the nodes simulate chooses for the box's 1 m resolution (outside the jit: host numbers)
    probe = lidarjax.probe_for_field(FrozenTurbulence(scenes.uniform(U, 270.0), box, U, 270.0),
                                     scan, [h], probe)
    los, lid, pnt, flags = (np.asarray(a) for a in _series(box, scan, probe, jnp.asarray([h])))
    assert np.all(flags == 0)
    geo = spectral.lidar_geometry(scan, h, direction=270.0)
    # LOS variance of every beam: sum_k (n . a_k)^2 W(k . n)^2 / 2
    var_los = np.var(los[:, 0, :], axis=0)
    # "nodes": what the simulator computes, exactly; "truncated": the weighting as simulated
    # (truncated, cut at the lidar and renormalised); "weight": the ideal weighting, which the
    # pulsed probe's 1e-3 tail follows; the CW probe's cut at the lidar (4 % of the
    # Lorentzian at 100 m, the rest renormalised) passes 5-12 % more LOS variance of these
    # 51-128 m waves than the ideal Lorentzian
    models = (("nodes", 6e-3), ("truncated", 2e-2),
              ("weight", 2e-2 if kind == "windcube_v2" else 0.15))
    for model, rtol in models:
        w = np.stack([lj.probe_transfer(probe, ks @ n, r, model=model)
                      for n, r in zip(geo.directions, geo.ranges, strict=True)])  # (b, modes)
        want = np.sum((geo.directions @ AMPS.T) ** 2 * w**2, axis=1) / 2
        np.testing.assert_allclose(var_los, want, rtol=rtol)
    unfiltered = np.sum((geo.directions @ AMPS.T) ** 2, axis=1) / 2
    assert want.sum() < 0.7 * unfiltered.sum()  # the probe removes a good share: the test is sharp
    # reconstructed along-wind u and the point sensor: sum_k |A(k) . a_k|^2 / 2
    amp = spectral.lidar_response(geo, probe, ks, speed=U, probe_model="nodes")
    want_u = np.sum(np.abs(np.sum(amp * AMPS, -1)) ** 2) / 2
    np.testing.assert_allclose(np.var(lid[:, 0, 0]), want_u, rtol=6e-3)
    np.testing.assert_allclose(np.var(pnt[:, 0, 0]), np.sum(AMPS[:, 0] ** 2) / 2, rtol=6e-3)
    if kind != "windcube_v2":
        return
    # beams taken one after the other (1.1 s apart, as a Windcube's scan): the instrument
    # reconstructs from LOS of different times, the model's beam_times phase exp(-i k1 U t_b)
    times = 1.1 * np.arange(scan.n_beams)
    staggered = np.stack([np.asarray(_series(box, scan, probe, jnp.asarray([h]), t)[0])[:, 0, b]
                          for b, t in enumerate(times)], axis=-1)
    u_stag = np.asarray(lidarjax.reconstruct(scan, jnp.asarray(staggered)))[:, 0]
    geo_t = spectral.lidar_geometry(scan, h, direction=270.0, beam_times=times)
    amp_t = spectral.lidar_response(geo_t, probe, ks, speed=U, probe_model="nodes")
    want_t = np.sum(np.abs(np.sum(amp_t * AMPS, -1)) ** 2) / 2
    np.testing.assert_allclose(np.var(u_stag), want_t, rtol=6e-3)
    assert abs(want_t / want_u - 1) > 0.02  # the timing changes the variance: the check is sharp


# -- Mann turbulence: a small ensemble ----------------------------------------------------------
def test_mann_ensemble_variances_within_uncertainty():
    """Synthesised Mann boxes (exact discrete spectrum): the ensemble means of a Windcube V2's
    and a ZephIR's reconstructed-u variance, of their ratio to the point sensor's, and of the
    point sensor's agree with the spectral model within 3 standard errors of the ensemble (the
    large validation is benchmarks/turbulence_spectral.py)."""
    shape, spacing, L, gamma, h = (128, 32, 32), (4.0, 4.0, 4.0), 20.0, 3.2, 60.0
    instruments = {"v2": (lidarjax.windcube_v2(), lidarjax.PulsedProbe().scaled(2.0)),
                   "zephir": (lidarjax.zephir(), lidarjax.CWProbe())}
    lid = {name: [] for name in instruments}
    pnt = []
    for seed in range(4):
        box = lj.synthesize_box(shape, spacing, 1.0, L, gamma, seed=seed)
        for name, (scan, probe) in instruments.items():
            _, lv, pv, flags = _series(box, scan, probe, jnp.asarray([h]))
            assert not np.any(np.asarray(flags) & int(lidarjax.Flag.PROBE_TRUNCATED))
            lid[name].append(np.var(np.asarray(lv)[:, 0, 0]))
        pnt.append(np.var(np.asarray(pv)[:, 0, 0]))
    pnt = np.asarray(pnt)
    for name, (scan, probe) in instruments.items():
        model = spectral.lidar_variance(scan, probe, h, L, gamma, box_shape=shape, box_spacing=spacing,
                                        speed=U, record_length=shape[0] * spacing[0] / U,
                                        probe_model="nodes", interpolation="trilinear")
        sample = np.asarray(lid[name])
        ratio = sample / pnt
        for values, want in ((sample, model.lidar), (pnt, model.point), (ratio, model.ratio)):
            err = values.std(ddof=1) / np.sqrt(values.size)
            assert abs(values.mean() - want) < 3 * err, (name, values, want)
    assert 0.2 < model.ratio < 0.6  # the ZephIR reports well under half the point variance


def test_node_interpolation_model_limits():
    """``interpolation="nodes"`` (every probe node interpolated between the box's nodes as the
    simulator does): the point sensor on a node column loses exactly the uniform-cell factor
    ``(2 + cos(k1 dx)) / 3`` (the aliases' ``sinc^4`` sum), and on a box refined 4x the
    lidar's variance tends to the continuous field's as ``dx^(2/3)``."""
    scan, probe = lidarjax.windcube_v2(), lidarjax.PulsedProbe()
    common = dict(direction=270.0, speed=9.73, record_length=600.0, probe_model="nodes")
    coarse = dict(box_shape=(64, 16, 16), box_spacing=(8.0, 8.0, 8.0), **common)
    nodes = spectral.lidar_variance(scan, probe, 64.0, 30.0, 3.9, interpolation="nodes",
                                    n_alias=4, **coarse)
    cells = spectral.lidar_variance(scan, probe, 64.0, 30.0, 3.9, interpolation="trilinear", **coarse)
    np.testing.assert_allclose(nodes.point, cells.point, rtol=2e-4)
    # interpolation loses variance: both below the continuous field's
    cont = spectral.lidar_variance(scan, probe, 64.0, 30.0, 3.9, **coarse)
    assert nodes.lidar < cont.lidar and nodes.point < cont.point
    # the same physical box refined 4x along each axis: the lost variance shrinks as
    # dx^(2/3) (the loss sum_k Phi (k dx)^2 of a k^(-5/3) spectrum is set by the grid's own
    # Nyquist scales), 4^(2/3) = 2.5x
    fine = dict(box_shape=(256, 64, 64), box_spacing=(2.0, 2.0, 2.0), **common)
    f_nodes = spectral.lidar_variance(scan, probe, 64.0, 30.0, 3.9, interpolation="nodes", **fine)
    f_cont = spectral.lidar_variance(scan, probe, 64.0, 30.0, 3.9, **fine)
    lost_coarse = 1 - nodes.lidar / cont.lidar
    lost_fine = 1 - f_nodes.lidar / f_cont.lidar
    assert 0 < lost_fine and 2.0 < lost_coarse / lost_fine < 3.2
    # several beam-time patterns average; refused without the node model
    pats = np.asarray([[[0, 1, 2, 3, 4]], [[-4, -3, -2, -1, 0]]], float)
    both = spectral.lidar_variance(scan, probe, 64.0, 30.0, 3.9, interpolation="nodes",
                                   beam_times=pats, **coarse)
    each = [spectral.lidar_variance(scan, probe, 64.0, 30.0, 3.9, interpolation="nodes",
                                    beam_times=p[0], **coarse).lidar for p in pats]
    np.testing.assert_allclose(both.lidar, np.mean(each), rtol=1e-10)
    with pytest.raises(ValueError, match="interpolation='nodes'"):
        spectral.lidar_variance(scan, probe, 64.0, 30.0, 3.9, beam_times=pats, **coarse)
    with pytest.raises(ValueError, match="probe_model='nodes'"):
        spectral.lidar_variance(scan, probe, 64.0, 30.0, 3.9, interpolation="nodes",
                                **{**coarse, "probe_model": "weight"})
