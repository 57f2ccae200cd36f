"""Analytic lidar–rotor spectra against IEA Wind Task 52's published analytic model (its
``LidarRotorSpectra_IEA15MW_*.mat`` and the ``FFP_v1_*.IN`` filter designed from them, MIT,
in tests/data/lac), the continuous-disc limit of ``S_RR`` and gradients against central
differences."""

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.io
from scipy import integrate

import lidarjax as lj
from lidarjax import control as lc
from lidarjax.control import spectra as spectra_module

DATA = Path(__file__).resolve().parents[1] / "data" / "lac"
FFP_CUTOFF = {"4BeamPulsed": 0.1232, "CircularCW": 0.3268}  # FFP_v1_*.IN, rad/s
FFP_BUFFER = {"4BeamPulsed": 1.3889, "CircularCW": 6.1111}  # FFP_v1_*.IN, s


def _ffp(name, key):
    for line in (DATA / f"FFP_v1_{name}.IN").read_text().splitlines():
        if f"! {key}" in line:
            return float(line.split()[0])
    raise KeyError(key)


N_NODES = 440  # the CW file's nodes (40 scan points x 11 offsets); the 4-beam file's 44 are padded to it
N_CLASSES = 72  # symmetry classes, padded likewise: one compiled program serves both files


def _load(name):
    m = scipy.io.loadmat(DATA / f"LidarRotorSpectra_IEA15MW_{name}.mat", squeeze_me=True,
                         struct_as_record=False)
    p, t = m["Parameter"], m["Trajectory"]
    focus = np.stack([np.atleast_1d(getattr(t, f"{c}_L_AllDistances")) for c in "xyz"], 1).astype(float)
    samples = lc.lidar_samples(focus, offsets=p.Lidar.a, offset_weights=p.Lidar.f_L_d)
    rotor = lc.rotor_disc(p.Turbine.RotorDiameter / 2, spacing=8.0)  # Task 52's 8 m grid: 709 points
    inflow = lc.KaimalInflow(p.TurbSim.URef, p.TurbSim.IECturbc)
    return m, samples, rotor, inflow, focus


def _padded(samples, rotor):
    """`samples` padded to `N_NODES` nodes with zero-weight copies of its first node, and its
    symmetry classes (`lac_spectra`'s) padded to `N_CLASSES` with copies of the first
    representative: exactly the same sums, one shape for both files."""
    n = samples.points.shape[0]

    def pad(a):
        return jnp.concatenate([a, jnp.repeat(a[:1], N_NODES - n, axis=0)])

    padded = lc.LidarSamples(points=pad(samples.points), directions=pad(samples.directions),
                             weights=jnp.concatenate([samples.weights, jnp.zeros(N_NODES - n)]),
                             delays=pad(samples.delays))
    rep, inverse = spectra_module._symmetry_classes(samples, rotor)
    assert rep.size <= N_CLASSES
    rep = jnp.concatenate([rep, jnp.repeat(rep[:1], N_CLASSES - rep.size)])
    return padded, (rep, jnp.concatenate([inverse, jnp.zeros(N_NODES - n, inverse.dtype)]))


# every frequency to 0.07 Hz (cut-offs, bandwidths), then every 32nd (all 1024 of both files are
# checked in benchmarks/lac.py)
IDX = np.concatenate([np.arange(72), np.arange(72, 1024, 32)])


@pytest.fixture(scope="module", params=["4BeamPulsed", "CircularCW"])
def task52(request):
    name = request.param
    m, samples, rotor, inflow, focus = _load(name)
    padded, classes = _padded(samples, rotor)
    spectra = spectra_module._spectra(padded, rotor, inflow, jnp.asarray(m["f"][IDX]), classes)
    return name, m, IDX, spectra, focus


def test_rotor_grid_is_task52s():
    rotor = lc.rotor_disc(120.0, spacing=8.0)
    assert rotor.points.shape == (709, 2)
    np.testing.assert_allclose(float(jnp.sum(rotor.pair_weight)), 1.0, rtol=1e-13)


def test_spectra_match_task52(task52):
    name, m, idx, spectra, _ = task52
    np.testing.assert_allclose(spectra.S_RR, m["S_RR"][idx], rtol=1e-10)
    np.testing.assert_allclose(spectra.S_LL, m["S_LL"][idx], rtol=1e-10)
    np.testing.assert_allclose(np.abs(spectra.S_RL), np.abs(m["S_RL"][idx]), rtol=1e-10)
    # S_RR is S_u times the double sum of the disc's coherences (brute force over 709^2 pairs)
    rotor = lc.rotor_disc(120.0, spacing=8.0)
    yz = np.asarray(rotor.points)
    r = np.hypot(*(yz[:, None, :] - yz[None]).transpose(2, 0, 1))
    sigma, scale = float(m["Parameter"].TurbSim.IECturbc) * 18.0, 8.1 * 42.0  # IEC Kaimal, U = 18 m/s
    for i in (0, 30, 80):
        f = m["f"][idx[i]]
        rate = 12 * np.sqrt((f / 18.0) ** 2 + (0.12 / scale) ** 2)
        s_u = 4 * sigma**2 * scale / 18.0 / (1 + 6 * f * scale / 18.0) ** (5 / 3)
        assert spectra.S_RR[i] == pytest.approx(s_u * np.mean(np.exp(-rate * r)), rel=1e-10)
    # the phase: the rotor lags the lidar by about x/U (Task 52's file lags it by half a scan less)
    lag = -np.unwrap(np.angle(spectra.S_RL[:20])) / (2 * np.pi * spectra.frequency[:20])
    assert np.all(np.abs(lag - m["Trajectory"].x_L_AllDistances.flat[0] / 18.0) < 0.2)


def test_cutoff_and_buffer_match_ffp(task52):
    name, m, idx, spectra, focus = task52
    cutoff = float(lc.filter_cutoff(spectra))
    assert cutoff == pytest.approx(_ffp(name, "f_cutoff"), rel=1e-3)
    assert _ffp(name, "f_cutoff") == FFP_CUTOFF[name]
    # T_buffer = x/U - T_scan/2 - T_filter - tau with Task 52's T_scan = 1 s, tau = 2 s; its T_filter
    # came from a time-domain cross-correlation (5.0 s, 2.5 s); ours is the analytic peak of it.
    t_filter = float(lc.filter_delay(spectra, cutoff))
    lags = np.linspace(0, 20, 200001)
    f = m["f"][idx]
    om = 2 * np.pi * f
    h = m["S_LL"][idx] * np.gradient(f) / (1 + 1j * om / cutoff)
    corr = [np.real(np.sum(h * np.exp(1j * om * t))) for t in lags[::100]]
    assert t_filter == pytest.approx(lags[::100][int(np.argmax(corr))], abs=0.01)
    task52_filter = {"4BeamPulsed": 5.0, "CircularCW": 2.5}[name]
    assert abs(t_filter - task52_filter) < 0.15
    buf = lc.buffer_time(focus[0, 0], 18.0, scan_time=1.0, filter_delay=task52_filter, prediction_time=2.0)
    assert float(buf) == pytest.approx(_ffp(name, "T_buffer"), abs=1e-4)


def test_bandwidth_is_the_half_coherence_crossing(task52):
    _, m, idx, spectra, _ = task52
    f_b, k_b = lc.coherence_bandwidth(spectra)
    g2 = np.abs(m["S_RL"]) ** 2 / m["S_RR"] / m["S_LL"]
    i = int(np.argmax(g2 < 0.5))
    assert m["f"][i - 1] <= float(f_b) <= m["f"][i]
    assert float(k_b) == pytest.approx(2 * np.pi * float(f_b) / 18.0, rel=1e-12)
    assert float(np.interp(float(f_b), m["f"], g2)) == pytest.approx(0.5, abs=2e-3)


def test_disc_limit():
    """S_RR of the grid approaches the continuous disc's, ``S_u int p(r) coh(r) dr`` with ``p``
    the distance density of two random points in a disc, as the grid is refined (the spectra
    sum the same folded pairs: `test_spectra_match_task52` checks them against the brute-force
    double sum)."""
    radius, inflow = 63.0, lc.KaimalInflow(11.4, 0.18)
    f = np.array([0.005, 0.02, 0.05, 0.1, 0.3])

    def density(r):
        q = r / (2 * radius)
        return 4 * r / (np.pi * radius**2) * (np.arccos(q) - q * np.sqrt(1 - q * q))

    rate = np.asarray(inflow.decay_rate(f))
    exact = np.array([integrate.quad(lambda r, s=s: density(r) * np.exp(-s * r), 0, 2 * radius,
                                     epsabs=1e-13, limit=200)[0] for s in rate])
    errors = []
    for spacing in (12.0, 6.0, 3.0):
        rotor = lc.rotor_disc(radius, spacing=spacing)
        folded = np.exp(-rate[:, None] * np.asarray(rotor.pair_distance)) @ np.asarray(rotor.pair_weight)
        errors.append(np.abs(folded / exact - 1))
    worst = [e.max() for e in errors]
    assert worst[0] > worst[1] > worst[2]
    assert worst[2] < 0.05 and errors[2][f <= 0.1].max() < 0.01


@pytest.fixture(scope="module")
def small():
    return lc.rotor_disc(63.0, spacing=14.0), lc.KaimalInflow(12.0, 0.16), jnp.linspace(0.005, 0.3, 40)


def test_gradients_match_central_differences(small):
    """Bandwidth and spectra are differentiable in focus distance, half-cone angle, the range
    weighting's width and the scan timing."""
    rotor, inflow, f = small

    def spectra(x):
        offsets = jnp.linspace(-2.0, 2.0, 5) * x[2]
        weights = jnp.exp(-0.5 * (offsets / x[2]) ** 2)
        focus = lc.cone_points(x[0], x[1], 4, azimuth_offset=45.0)
        times = jnp.arange(4) * x[3]
        return lc.lac_spectra(lc.lidar_samples(focus, offsets=offsets, offset_weights=weights, times=times),
                              rotor, inflow, f)

    def outputs(x):
        sp = spectra(x)
        return jnp.stack([lc.coherence_bandwidth(sp)[0], jnp.sum(sp.S_LL[::8]), jnp.sum(jnp.abs(sp.S_RL[::8]))])

    x = np.array([90.0, 18.0, 12.0, 0.25])
    eps = 1e-4
    # one compiled program, one call: the Jacobian at x and the values at x +- eps e_i
    points = np.concatenate([x[None], x + eps * np.eye(4), x - eps * np.eye(4)])
    values, jacs = jax.jit(jax.vmap(lambda y: (outputs(y), jax.jacrev(outputs)(y))))(points)
    values = np.asarray(values)
    fd = ((values[1:5] - values[5:]) / (2 * eps)).T
    got = np.asarray(jacs[0])
    assert np.all(np.isfinite(got)) and np.all(np.abs(got[0, :3]) > 0)
    np.testing.assert_allclose(got, fd, rtol=1e-4, atol=1e-9)


def test_probe_weighting_matches_its_nodes(small):
    """A lidarjax probe weights the beam as its own quadrature nodes tabulated."""
    rotor, inflow, f = small
    from lidarjax import PulsedProbe

    probe = PulsedProbe(30.0, 30.0, n_nodes=7)
    focus = lc.cone_points(120.0, 15.0, 4)
    with_probe = lc.lac_spectra(lc.lidar_samples(focus, probe=probe), rotor, inflow, f)
    o, w = probe.nodes(jnp.linalg.norm(focus[0]))
    tabulated = lc.lac_spectra(lc.lidar_samples(focus, offsets=o, offset_weights=w), rotor, inflow, f)
    np.testing.assert_allclose(with_probe.S_LL, tabulated.S_LL, rtol=1e-12)
    # a range-weighted beam averages more turbulence out than a point: less lidar variance (the
    # same sums without the symmetry folding, which has another shape for coincident nodes)
    point = spectra_module._spectra(lc.lidar_samples(focus, offsets=np.zeros(7)), rotor, inflow, f)
    np.testing.assert_allclose(spectra_module._spectra(lc.lidar_samples(focus, probe=probe), rotor, inflow,
                                                       f).S_LL, with_probe.S_LL, rtol=1e-12)
    assert np.all(np.asarray(with_probe.S_LL) < np.asarray(point.S_LL))


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="focus_points"):
        lc.lidar_samples(np.zeros((4, 2)))
    with pytest.raises(ValueError, match="radius"):
        lc.rotor_disc(-1.0)
    with pytest.raises(ValueError, match="turbulence_intensity"):
        lc.KaimalInflow(10.0, 0.0)
    with pytest.raises(ValueError, match="must be a scalar"):
        lc.KaimalInflow([10.0, 11.0], 0.1)
    with pytest.raises(ValueError, match="turbulence_class='D'"):
        lc.iec_turbulence_intensity(10.0, "D")
    with pytest.raises(ValueError, match="at most the radius"):
        lc.rotor_disc(10.0, spacing=20.0)
    with pytest.raises(ValueError, match="finite non-negative weights"):
        lc.rotor_disc(10.0, spacing=5.0, weighting=lambda r: -r)
    with pytest.raises(ValueError, match="n_points must be a positive integer"):
        lc.cone_points(100.0, 20.0, 0)
    focus = np.array([[100.0, 10.0, 0.0], [100.0, -10.0, 0.0]])
    with pytest.raises(ValueError, match="not both"):
        lc.lidar_samples(focus, probe=lj.CWProbe(), offsets=[0.0])
    with pytest.raises(ValueError, match="offset_weights needs offsets"):
        lc.lidar_samples(focus, offset_weights=[1.0])
    with pytest.raises(ValueError, match="of one length"):
        lc.lidar_samples(focus, offsets=[0.0, 1.0], offset_weights=[1.0])
    with pytest.raises(ValueError, match="one per focus point"):
        lc.lidar_samples(focus, times=[0.0])
    with pytest.raises(ValueError, match="KaimalInflow or a MannInflow"):
        lc.lac_spectra(lc.lidar_samples(focus), lc.rotor_disc(10.0, spacing=5.0), "IEC", np.array([0.1, 0.2]))
    with pytest.raises(ValueError, match="frequency"):
        lc.lac_spectra(lc.lidar_samples(np.ones((1, 3))), lc.rotor_disc(10.0, spacing=5.0),
                       lc.KaimalInflow(10.0, 0.1), np.array([-1.0, 1.0]))
    n = IDX.size  # the shape the Task 52 tests compiled coherence_bandwidth for
    assert jax.numpy.isnan(lc.coherence_bandwidth(lc.LacSpectra(
        jnp.linspace(1.0, 2.0, n), jnp.ones(n), jnp.ones(n), jnp.ones(n) * 0.1 + 0j, jnp.asarray(10.0)))[0])
