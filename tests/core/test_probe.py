"""Probe volumes: weightings, quadrature, symmetry, truncation, scaling, retracing."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate

import lidarjax as lj
from lidarjax.beam import beam_los
from lidarjax.forward import _simulate_jit
from lidarjax.probe import SPEED_OF_LIGHT

PULSED = lj.PulsedProbe()
CW = lj.CWProbe()
HIGH = np.array([120.0, 180.0])  # no truncation behind the lidar for the defaults


def quad(fn, lo, hi):
    return integrate.quad(fn, lo, hi, limit=400, epsabs=1e-13, epsrel=1e-12)[0]


def test_defaults_are_the_documented_instrument_values():
    assert float(PULSED.pulse_fwhm) == pytest.approx(SPEED_OF_LIGHT * 175e-9 / 2)
    assert float(PULSED.pulse_fwhm) == pytest.approx(26.2, abs=0.05)
    assert float(PULSED.gate_length) == 25.0
    assert float(CW.wavelength) == 1.565e-6 and float(CW.aperture_radius) == 28e-3
    assert float(CW.hwhm(100.0)) == pytest.approx(6.354, abs=1e-3)
    assert PULSED.n_nodes == 9 and CW.n_nodes == 17
    assert PULSED.auto_nodes and CW.auto_nodes  # chosen for the field by simulate
    assert not lj.PulsedProbe(n_nodes=9).auto_nodes and not CW.with_nodes(33).auto_nodes


@pytest.mark.parametrize(
    "probe, f",
    [(PULSED, 100.0), (lj.PulsedProbe(10.0, 60.0), 100.0), (lj.PulsedProbe(40.0, 5.0), 100.0),
     (CW, 60.0), (CW, 150.0), (lj.CWProbe(1.0e-6, 10e-3), 30.0)],
)
def test_weight_integrates_to_one(probe, f):
    w = lambda o: float(probe.weight(o, f))  # noqa: E731
    total = quad(w, -np.inf, -1.0) + quad(w, -1.0, 1.0) + quad(w, 1.0, np.inf)
    assert total == pytest.approx(1.0, abs=1e-9)


def _numpy_weight(probe, f):
    """The weighting written out in numpy (independent of the library's jax code)."""
    from scipy.special import erf

    if isinstance(probe, lj.PulsedProbe):
        rp = float(probe.pulse_fwhm) / (2 * np.sqrt(np.log(2)))
        dp = float(probe.gate_length)
        return lambda o: (erf((o + dp / 2) / rp) - erf((o - dp / 2) / rp)) / (2 * dp)
    g = float(probe.wavelength) * f**2 / (np.pi * float(probe.aperture_radius) ** 2)
    return lambda o: g / (np.pi * (o * o + g * g))


def _kept(probe, f):
    """Weight of the (untruncated) weighting within the nodes' span, by quadrature."""
    half = min(float(probe.support(f)), f)
    return quad(_numpy_weight(probe, f), -half, half)


@pytest.mark.parametrize("probe", [PULSED, CW, lj.PulsedProbe(n_nodes=4), lj.CWProbe(n_nodes=6),
                                   CW.with_nodes(41, resolution=3.0)])
def test_nodes_are_symmetric_and_weigh_what_the_cut_keeps(probe):
    f = jnp.array([20.0, 50.0, 100.0, 260.0])
    offsets, weights = (np.asarray(a, np.float64) for a in probe.nodes(f))
    offsets = np.broadcast_to(offsets, (4, probe.n_nodes))
    weights = np.broadcast_to(weights, offsets.shape)
    np.testing.assert_allclose(offsets, -offsets[..., ::-1], atol=1e-12 * 260)
    np.testing.assert_allclose(weights, weights[..., ::-1], rtol=1e-12)
    assert np.all(weights > 0)
    # every node ahead of the lidar and inside the support: the cut is built into the rule
    assert np.all(np.abs(offsets) < np.minimum(np.asarray(probe.support(f))[:, None], f[:, None]))
    # the weights sum to the weighting's weight inside the cut support (what simulate reports)
    kept = [_kept(probe, float(r)) for r in f]
    np.testing.assert_allclose(weights.sum(-1), kept, rtol=1e-9)
    if isinstance(probe, lj.CWProbe):
        np.testing.assert_allclose(kept, probe.kept_weight(f), rtol=1e-9)


@pytest.mark.parametrize("probe, f, rel2, rel4",
                         [(lj.PulsedProbe(n_nodes=17), 80.0, 5e-4, 2e-3),
                          (lj.PulsedProbe(10.0, 40.0, n_nodes=33), 80.0, 5e-4, 2e-3),
                          (lj.PulsedProbe(n_nodes=17), 30.0, 2e-2, 3e-2),
                          (CW, 150.0, 2e-3, 5e-2), (CW.with_nodes(65), 150.0, 2e-4, 5e-3),
                          (CW.with_nodes(129, resolution=2.0), 60.0, 5e-4, 5e-3)])
def test_quadrature_moments_match_the_cut_weight(probe, f, rel2, rel4):
    """Second and fourth moments of the rule against those of the weighting over the cut
    support (the second sets the bias in a curved profile)."""
    offsets, weights = (np.asarray(a, np.float64) for a in probe.nodes(jnp.array(f)))
    half = min(float(probe.support(f)), f)
    mass = quad(lambda o: float(probe.weight(o, f)), -half, half)
    for k, rel in ((2, rel2), (4, rel4)):
        exact = quad(lambda o, k=k: o**k * float(probe.weight(o, f)), -half, half) / mass
        assert np.sum(weights * offsets**k) / np.sum(weights) == pytest.approx(exact, rel=rel)


class QuadraticAlongBeam(lj.AbstractField):
    """V = n * (a + b s + c s^2) with s the distance along the unit vector n (a test field)."""

    origin: jax.Array
    origin_lo: jax.Array
    n: jax.Array
    coef: jax.Array

    def sample_local(self, points):
        s = jnp.sum(points * self.n, axis=-1)
        a, b, c = self.coef
        return (a + b * s + c * s**2)[..., None] * self.n


@eqx.filter_jit  # one program per node count (static), not one per jax.numpy operation
def _beam_los_compiled(field, probe, ranges):
    return beam_los(field, jnp.zeros(3), field.n[None, :], ranges, probe)[0]


def _probe_los(field, probe, focus):
    return float(_beam_los_compiled(field, probe, jnp.array([[focus]]))[0, 0])


def test_pulsed_los_in_a_quadratic_field_converges_to_the_second_moment():
    n = jnp.array([0.3, 0.4, np.sqrt(0.75)])
    field = QuadraticAlongBeam(jnp.zeros(3), jnp.zeros(3), n, jnp.array([2.0, 0.05, 1e-3]))
    focus = 150.0
    point = 2.0 + 0.05 * focus + 1e-3 * focus**2
    errors = []
    for q in (3, 5, 9, 17, 33):
        probe = lj.PulsedProbe(n_nodes=q, tail=1e-10)
        moment = (_probe_los(field, probe, focus) - point) / 1e-3
        errors.append(abs(moment / float(probe.variance()) - 1))
    assert all(b <= a for a, b in zip(errors[:-1], errors[1:], strict=True))
    assert errors[-1] < 1e-9
    # with the default tail the documented 0.17 % deficit of the second moment
    probe = lj.PulsedProbe(n_nodes=33)
    deficit = 1 - (_probe_los(field, probe, focus) - point) / 1e-3 / float(probe.variance())
    assert 0.0 < deficit < 2e-3


def test_cw_width_follows_focus_squared():
    lam, a = 1.565e-6, 28e-3
    for f in (20.0, 50.0, 100.0, 200.0):
        hwhm = lam * f**2 / (np.pi * a**2)
        assert float(CW.hwhm(f)) == pytest.approx(hwhm, rel=1e-14)
        peak = float(CW.weight(0.0, f))
        assert float(CW.weight(hwhm, f)) == pytest.approx(peak / 2, rel=1e-12)
        assert float(CW.weight(-hwhm, f)) == pytest.approx(peak / 2, rel=1e-12)
        # the cut keeps (2/pi) atan(f / G): 0.96 at 100 m, flagged (tail 0.1) beyond 249 m
        assert float(CW.kept_weight(f)) == pytest.approx(2 / np.pi * np.arctan(f / hwhm), rel=1e-12)
    assert float(CW.kept_weight(100.0)) == pytest.approx(0.9596, abs=1e-4)
    assert float(CW.kept_weight(249.0)) > 0.9 > float(CW.kept_weight(250.0))


def test_scaled_probe_is_geometrically_similar():
    s = 300.0
    p, c = PULSED.scaled(s), CW.scaled(s)
    assert float(p.pulse_fwhm) == pytest.approx(float(PULSED.pulse_fwhm) / s)
    assert float(p.support()) == pytest.approx(float(PULSED.support()) / s)
    for f in (40.0, 120.0):
        assert float(c.hwhm(f / s)) == pytest.approx(float(CW.hwhm(f)) / s, rel=1e-13)
        np.testing.assert_allclose(c.nodes(jnp.array(f / s))[0], CW.nodes(jnp.array(f))[0] / s,
                                   rtol=1e-13)
    assert lj.PointProbe().scaled(s) == lj.PointProbe()


LINEAR = lj.scenes.linear([8.0, -3.0, 0.4], [[0.01, 0.004, 0.02], [-0.003, 0.015, 0.01],
                                            [0.002, -0.001, -0.005]], point=[5.0, -2.0, 0.0])
MOUNT = lj.Mount([1.0, 2.0, 0.0], beta=20.0)


@pytest.mark.parametrize("probe", [PULSED, lj.PulsedProbe(n_nodes=4), CW])
def test_constant_gradient_field_any_symmetric_probe_equals_the_point(probe):
    scan = lj.windcube_v2()
    point = lj.simulate(LINEAR, scan, MOUNT, HIGH)
    volume = lj.simulate(LINEAR, scan, MOUNT, HIGH, probe=probe)
    np.testing.assert_allclose(volume.los, point.los, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(volume.lidar_velocity, point.lidar_velocity, rtol=1e-12, atol=1e-12)
    assert np.all(volume.flags == 0)


def test_nodes_behind_the_lidar_are_dropped_and_flagged():
    scan = lj.windcube_v2()
    heights = np.array([20.0, 120.0])
    sim = lj.simulate(LINEAR, scan, MOUNT, heights, probe=PULSED)
    assert sim.flags[0] & lj.Flag.PROBE_TRUNCATED and sim.flags[1] == 0
    assert np.all(np.isfinite(sim.los))
    # by hand: the vertical beam at range 20 uses nodes over |offset| < 20, renormalised
    offsets, weights = (np.asarray(a) for a in PULSED.nodes(jnp.array(20.0)))
    assert np.all(np.abs(offsets) < 20.0) and offsets.shape == (PULSED.n_nodes,)
    assert 1 - weights.sum() > float(PULSED.tail)  # what the flag reports
    n = np.asarray(sim.directions[4])
    loc = np.array([1.0, 2.0, 0.0])
    pts = loc + (20.0 + offsets)[:, None] * n
    los_q = np.asarray(LINEAR.sample(pts)) @ n
    expected = np.sum(weights * los_q) / np.sum(weights)
    assert float(sim.los[0, 4]) == pytest.approx(expected, rel=1e-12)
    # the cut is symmetric, so a linear field still gives the point LOS
    point = lj.simulate(LINEAR, scan, MOUNT, heights)
    np.testing.assert_allclose(sim.los, point.los, rtol=1e-12, atol=1e-12)
    # the CW probe is cut at long range (its support grows as f^2), flagged when > tail
    far = lj.simulate(LINEAR, scan, MOUNT, np.array([100.0, 150.0, 400.0]), probe=CW)
    assert [bool(f & lj.Flag.PROBE_TRUNCATED) for f in far.flags] == [False, False, True]


def test_float32_follows_the_field():
    scene32 = lj.scenes.linear([8.0, -3.0, 0.4], np.eye(3) * 0.01, dtype=jnp.float32)
    for probe in (PULSED, CW):
        sim = lj.simulate(scene32, lj.windcube_v1(), MOUNT, HIGH, probe=probe)
        assert sim.los.dtype == jnp.float32 and sim.lidar_velocity.dtype == jnp.float32


def test_no_retrace_when_probe_numbers_change():
    scan = lj.windcube_v1()
    lj.simulate(LINEAR, scan, MOUNT, HIGH, probe=PULSED)
    lj.simulate(LINEAR, scan, MOUNT, HIGH, probe=CW)
    before = _simulate_jit._cache_size()
    for k in range(3):
        lj.simulate(LINEAR, scan, MOUNT, HIGH + k,
                    probe=lj.PulsedProbe(20.0 + k, 30.0 - k, tail=10.0 ** (-3 - k)))
        lj.simulate(LINEAR, scan, MOUNT, HIGH + k,
                    probe=lj.CWProbe(1.5e-6 + k * 1e-8, 25e-3 + k * 1e-3, tail=0.05 + 0.01 * k))
        lj.simulate(LINEAR, scan, MOUNT, HIGH, probe=PULSED.scaled(1.0 + k))
    assert _simulate_jit._cache_size() == before


@pytest.mark.parametrize(
    "make, message",
    [(lambda: lj.PulsedProbe(-1.0, 25.0), "pulse_fwhm"),
     (lambda: lj.PulsedProbe(26.0, 0.0), "gate_length"),
     (lambda: lj.PulsedProbe(n_nodes=0), "n_nodes"),
     (lambda: lj.CWProbe(tail=1.5), "tail"),
     (lambda: lj.CWProbe(aperture_radius=np.nan), "aperture_radius"),
     (lambda: lj.CWProbe(resolution=-2.0), "resolution"),
     (lambda: PULSED.scaled(np.nan), "factor"),
     (lambda: PULSED.scaled(0.0), "factor"),
     (lambda: CW.scaled(-1.0), "factor"),
     (lambda: CW.scaled([2.0, 3.0]), "factor")],
)
def test_bad_probe_parameters_raise(make, message):
    with pytest.raises(ValueError, match=message):
        make()


# -- node rules against the closed forms (issue: probe volumes exact to the field's resolution) --

def _pulsed_closed_form(k, fwhm=SPEED_OF_LIGHT * 175e-9 / 2, gate=25.0):
    """Independent: Gaussian pulse (rp = FWHM / (2 sqrt(ln 2))) convolved with the gate."""
    rp = fwhm / (2 * np.sqrt(np.log(2)))
    return np.exp(-(k * rp) ** 2 / 4) * np.sinc(k * gate / (2 * np.pi))


def _cut_lorentzian(k, g, r):
    """Independent: the Lorentzian of half width g cut to |o| < r and renormalised, by
    adaptive quadrature in theta = atan(o / g) (where its density is uniform)."""
    a = np.arctan(r / g)
    out = []
    for kk in np.atleast_1d(k):
        val = integrate.quad(lambda t, kk=kk: np.cos(kk * g * np.tan(t)), 0.0, a, limit=2000,
                             epsabs=1e-12)[0]
        out.append(val / a)
    return np.array(out)


def _rule_transfer(probe, k, r):
    o, w = (np.asarray(a, np.float64) for a in probe.nodes(jnp.array(r)))
    return np.cos(np.multiply.outer(k, o)) @ (w / w.sum())


@pytest.mark.parametrize("dx", [2.0, 4.0, 8.0])
def test_pulsed_nodes_for_a_resolution_agree_with_the_closed_form(dx):
    ranges = [40.0, 100.0, 250.0]
    probe = lj.probe_for_spacing(PULSED, dx, ranges)
    k = np.linspace(0.0, np.pi / dx, 400)
    for r in ranges:
        err = np.max(np.abs(_rule_transfer(probe, k, r) - _pulsed_closed_form(k)))
        assert err < 0.01, (dx, r, err)
    # the fewest nodes: two fewer miss the tolerance somewhere
    fewer = probe.with_nodes(probe.n_nodes - 2)
    assert max(np.max(np.abs(_rule_transfer(fewer, k, r) - _pulsed_closed_form(k)))
               for r in ranges[1:]) > 0.01
    # the default 9 nodes alias a 4 m or 2 m field
    if dx < 8:
        assert np.max(np.abs(_rule_transfer(PULSED, k, 100.0) - _pulsed_closed_form(k))) > 0.05


@pytest.mark.parametrize("dx", [2.0, 4.0, 8.0])
def test_cw_nodes_for_a_resolution_agree_with_the_lorentzian(dx):
    ranges = [10.0, 40.0, 100.0, 250.0]
    probe = lj.probe_for_spacing(CW, dx, ranges)
    k = np.linspace(0.0, np.pi / dx, 120)
    for r in ranges:
        g = float(CW.hwhm(r))
        cut = _cut_lorentzian(k, g, r)
        assert np.max(np.abs(_rule_transfer(probe, k, r) - cut)) < 0.01, (dx, r)
        # the closed form of the cut weighting (exponential integrals) is exact
        np.testing.assert_allclose(lj.probe_transfer(CW, k, r, model="truncated"), cut, atol=1e-8)
        # the cut itself moves the transfer function from exp(-G|k|) by at most 2 (1 - P) / P
        # (the kept weight P renormalised, the dropped tails' own transfer at most 1 - P)
        p = float(CW.kept_weight(r))
        assert np.max(np.abs(cut - np.exp(-g * k))) <= 2 * (1 - p) / p + 1e-9
    # the old rule (17 Gauss nodes of a 5 %-truncated Lorentzian) returned 0.8 of a wave the
    # Lorentzian removes at 100 m; the fixed 17-node rule without a resolution aliases too
    k = np.linspace(0.0, np.pi / 4, 200)
    g = float(CW.hwhm(100.0))
    assert np.max(np.abs(_rule_transfer(CW, k, 100.0) - _cut_lorentzian(k, g, 100.0))) > 0.05


def test_cw_default_filters_a_smooth_field_like_the_whole_lorentzian():
    """Without a resolution (smooth field), the default 17 nodes give the cut Lorentzian's
    response to long waves within 1e-3 (the old truncated rule kept 5 % less weight)."""
    for r in (50.0, 100.0, 200.0):
        g = float(CW.hwhm(r))
        k = np.linspace(0.0, 2 * np.pi / (4 * r), 50)  # wavelengths of 4 focus ranges and more
        assert np.max(np.abs(_rule_transfer(CW, k, r) - _cut_lorentzian(k, g, r))) < 1e-3


class PlaneWave(lj.AbstractField):
    """w = amplitude * cos(k z): a vertical wave, stating its resolution pi / k."""

    origin: jax.Array
    origin_lo: jax.Array
    k: jax.Array

    @property
    def resolution(self):
        return float(np.pi / self.k)

    def sample_local(self, points):
        w = jnp.cos(self.k * points[..., 2])
        return jnp.stack([jnp.zeros_like(w), jnp.zeros_like(w), w], axis=-1)


@pytest.mark.parametrize("probe", [PULSED, CW], ids=["pulsed", "cw"])
def test_simulate_chooses_nodes_for_the_field(probe):
    """The vertical beam in a wave at the field's Nyquist wavenumber: simulate's LOS is the
    weighting's transfer function times the wave (within 0.01), where the default nodes
    alias; an explicit node count is used as given; the choice compiles once per field."""
    scan = lj.windcube_v2()
    heights = np.array([60.0, 150.0])
    mount = lj.Mount([0.0, 0.0, 0.0])
    field = PlaneWave(jnp.zeros(3), jnp.zeros(3), jnp.asarray(np.pi / 3.0))  # 3 m
    k = np.pi / 3.0
    sim = lj.simulate(field, scan, mount, heights, probe=probe)
    expected = [float(lj.probe_transfer(probe, np.array([k]), h, model="truncated")[0]) * np.cos(k * h)
                for h in heights]
    np.testing.assert_allclose(np.asarray(sim.los[:, 4]), expected, atol=0.01)
    chosen = lj.probe_for_field(field, scan, heights, probe)
    assert chosen.n_nodes > probe.n_nodes
    explicit = lj.simulate(field, scan, mount, heights, probe=chosen)
    np.testing.assert_array_equal(np.asarray(explicit.los), np.asarray(sim.los))
    fixed = probe.with_nodes(probe.n_nodes)  # explicit: wins, and aliases here
    assert lj.probe_for_field(field, scan, heights, fixed) is fixed
    coarse = lj.simulate(field, scan, mount, heights, probe=fixed)
    assert np.max(np.abs(np.asarray(coarse.los[:, 4]) - expected)) > 0.02
    before = _simulate_jit._cache_size()
    lj.simulate(field, scan, mount, heights, probe=probe)
    lj.simulate(eqx.tree_at(lambda f: f.k, field, jnp.asarray(np.pi / 3.0)), scan, mount, heights,
                probe=probe)
    assert _simulate_jit._cache_size() == before


def test_cw_nodes_are_differentiable_and_float32_safe():
    probe = CW.with_nodes(41, resolution=3.0)

    def second_moment(lam, r):
        p = eqx.tree_at(lambda q: q.wavelength, probe, lam)
        o, w = p.nodes(r)
        return jnp.sum(w * o**2) / jnp.sum(w)

    lam, r = 1.565e-6, 120.0
    second_moment = jax.jit(second_moment)  # compiled once: FD calls it four times
    g_lam, g_r = jax.jit(jax.grad(second_moment, argnums=(0, 1)))(jnp.asarray(lam), jnp.asarray(r))
    h = 1e-6
    sm = lambda a, b: float(second_moment(jnp.asarray(a), jnp.asarray(b)))  # noqa: E731
    fd_lam = (sm(lam * (1 + h), r) - sm(lam * (1 - h), r)) / (2 * lam * h)
    fd_r = (sm(lam, r + 1e-4) - sm(lam, r - 1e-4)) / 2e-4
    assert float(g_lam) == pytest.approx(float(fd_lam), rel=1e-5)
    assert float(g_r) == pytest.approx(float(fd_r), rel=1e-5)
    o32, w32 = probe.nodes(jnp.asarray([15.0, 120.0, 290.0], jnp.float32))
    o64, w64 = probe.nodes(jnp.asarray([15.0, 120.0, 290.0]))
    assert o32.dtype == jnp.float32 and np.all(np.isfinite(o32)) and np.all(np.isfinite(w32))
    np.testing.assert_allclose(o32, o64, rtol=2e-5, atol=1e-5)
    np.testing.assert_allclose(w32, w64, rtol=2e-5, atol=1e-8)


def test_scan_bounds_hold_the_nodes_simulate_chooses():
    scan = lj.windcube_v2()
    heights = np.array([40.0, 120.0])
    for probe in (PULSED, CW):
        lo, hi = (np.asarray(b) for b in lj.scan_bounds(scan, lj.Mount([0.0, 0.0, 0.0]), heights,
                                                         probe=probe))
        refined = lj.probe_for_spacing(probe, 2.0, heights[:, None] / np.cos(np.radians(28.0)))
        for r in (40.0, 120.0 / np.cos(np.radians(28.0))):
            o, _ = refined.nodes(jnp.array(r))
            assert r + float(np.max(o)) <= np.linalg.norm(np.maximum(np.abs(lo), np.abs(hi))) + 1e-9


def test_a_grid_states_a_coarser_resolution_for_a_smooth_field():
    """A smooth field on a fine grid: the stated resolution, not the spacing, sets the nodes
    (and survives crop); nonsense is refused in one line."""
    x = np.linspace(-200.0, 200.0, 81)  # 5 m
    z = np.linspace(0.0, 300.0, 121)  # 2.5 m
    fine = lj.GridField.from_function(LINEAR.sample, x, x, z)
    smooth = lj.GridField(x, x, z, fine.velocity, resolution=20.0)
    scan, heights = lj.windcube_v2(), np.array([60.0, 120.0])
    assert fine.resolution == pytest.approx(2.5) and smooth.resolution == 20.0
    many = lj.probe_for_field(fine, scan, heights, PULSED).n_nodes
    few = lj.probe_for_field(smooth, scan, heights, PULSED).n_nodes
    assert few < many
    lo, hi = lj.scan_bounds(scan, MOUNT, heights, probe=PULSED)
    assert smooth.crop(lo, hi).resolution == 20.0
    for bad in (0.0, -1.0, np.nan, [1.0, 2.0]):
        with pytest.raises(ValueError, match="resolution"):
            lj.GridField(x, x, z, fine.velocity, resolution=bad)
