"""`lidarjax.calibrate`: installation offsets recovered from synthetic campaigns generated in
plain numpy (tests/_campaign.py) from a lidar with known north offset and tilt errors.

The campaigns' flow is a platform's: its distortion is written in the lidar frame and turns
with the lidar's north offset, which is ``north_offset="site"``; a lidar turned on a fixed
site (the default, ``"instrument"``) is tested against `lidarjax.simulate` in
tests/core/test_calibrate_displacement.py."""

from types import SimpleNamespace

import jax
import numpy as np
import pytest

import lidarjax as lj
from lidarjax.calibrate import _model_and_jacobian, _model_of

from .. import _campaign as cp

HEIGHTS = np.array([40.0, 80.0, 120.0])
Z_REF = 100.0
ALPHA = 0.14
EPS0 = 10.0  # the table's (nominal) north offset
DIRECTIONS = np.arange(0.0, 360.0, 10.0)
N = 200

# the plain-numpy campaigns have no spatial gradient to give (tests/_campaign.py): tables
# without `beam_gradient` warn, as they should (test_calibrate_displacement tests it)
pytestmark = pytest.mark.filterwarnings("ignore:calibrate. the table has no beam_gradient")


@pytest.fixture(scope="module")
def table():
    resp, vel, beams = cp.table_runs(DIRECTIONS, HEIGHTS, ALPHA, Z_REF, epsilon=EPS0)
    inst = lj.Instrument(scan="windcube_v2", cone_angle_deg=cp.CONE, n_beams=5,
                         vertical_beam=True, epsilon_deg=EPS0, pitch_deg=0.0, roll_deg=0.0)
    return lj.ResponseTable(DIRECTIONS, resp, beam_velocity=vel, beam_vectors=beams,
                            heights=HEIGHTS, instrument=inst)


def _campaigns(k, seed):
    rng = np.random.default_rng(seed)
    for _ in range(k):
        true = np.array([rng.normal(0, 3), rng.normal(0, 0.7), rng.normal(0, 0.7)])
        los, truth = cp.campaign(rng, N, HEIGHTS, Z_REF, alpha=ALPHA, epsilon=EPS0,
                                 offsets=true, sigma=0.1)
        yield true, los, truth


def test_calibrate_with_a_reference_recovers_offsets_within_their_errors(table):
    z = []
    for true, los, truth in _campaigns(40, 1):
        ref = (truth["speed"], np.broadcast_to(truth["direction"][:, None], truth["speed"].shape))
        c = lj.calibrate(los, table, reference=ref, north_offset="site")
        assert c.converged and np.all(np.asarray(c.identifiable)) and c.names == (
            "epsilon", "pitch", "roll")
        z.append((np.asarray(c.offset) - true) / np.asarray(c.std))
        np.testing.assert_allclose(c.value, np.asarray(c.nominal) + np.asarray(c.offset))
    z = np.array(z)
    cover = np.mean(np.abs(z) < 1.96, axis=0)
    assert np.all(cover >= 0.85), cover  # 40 campaigns: 95 % +- 3.4 % (one sigma)
    assert np.all(np.abs(np.mean(z, axis=0)) < 0.5)  # no bias beyond its standard error
    assert np.nanstd(z) < 1.3  # the errors are what the standard errors say
    assert np.asarray(c.nominal)[0] == EPS0
    np.testing.assert_allclose(np.diagonal(np.asarray(c.correlation)), 1.0)


def test_calibrate_without_a_reference_gives_tilt_and_refuses_epsilon(table):
    z = []
    for true, los, _ in _campaigns(20, 2):
        c = lj.calibrate(SimpleNamespace(los=los, pitch=0.379, roll=float("nan")), table,
                         north_offset="site")
        assert np.isnan(float(c.offset[0])) and not bool(c.identifiable[0])
        assert any("epsilon" in n and "not identifiable without a reference" in n
                   for n in c.notes)
        assert bool(c.identifiable[1]) and bool(c.identifiable[2])
        z.append((np.asarray(c.offset)[1:] - true[1:]) / np.asarray(c.std)[1:])
    z = np.array(z)
    assert np.mean(np.abs(z) < 1.96) >= 0.85 and np.all(np.abs(np.mean(z, axis=0)) < 0.6)
    # the header's tilt is carried along for comparison
    assert float(c.header[1]) == 0.379 and np.isnan(float(c.header[2]))
    assert any("header 0.379" in line for line in c.summary())


def test_calibrate_of_a_level_true_installation_finds_nothing(table):
    rng = np.random.default_rng(7)
    los, truth = cp.campaign(rng, N, HEIGHTS, Z_REF, alpha=ALPHA, epsilon=EPS0, sigma=0.0)
    ref = (truth["speed"], np.broadcast_to(truth["direction"][:, None], truth["speed"].shape))
    c = lj.calibrate(los, table, reference=ref, north_offset="site")
    np.testing.assert_allclose(c.offset, 0.0, atol=1e-6)


def test_calibrate_refuses_bad_arguments(table):
    los = np.zeros((3, 3, 5))
    with pytest.raises(ValueError, match="wrt"):
        lj.calibrate(los, table, wrt=("yaw",))
    with pytest.raises(ValueError, match=r"\(h, b\)"):
        lj.calibrate(los[:, :2], table)
    bare = lj.ResponseTable(DIRECTIONS, np.asarray(table.response))
    with pytest.raises(ValueError, match="beam_vectors"):
        lj.calibrate(los, bare)
    with pytest.raises(ValueError, match="reference"):
        lj.calibrate(los, table, reference=(np.zeros((2, 3)), np.zeros((2, 3))))


@pytest.mark.parametrize(("with_reference", "north_offset"),
                         [(False, "site"), (True, "site"), (True, "instrument")])
def test_calibration_model_jacobians_match_central_differences(table, with_reference,
                                                               north_offset):
    # the closed-form Jacobians the Gauss-Newton passes use, in the nuisances and the
    # offsets, against central differences of the same model (direction, tilt and north
    # offset all away from zero)
    rng = np.random.default_rng(5)
    n = 6
    hidx = np.arange(n) % HEIGHTS.size
    ref_dir = rng.uniform(0, 360, n)
    nuisance = rng.uniform(4, 12, (n, 1)) if with_reference else rng.uniform(-9, 9, (n, 2))
    beta = nuisance
    theta = np.array([2.0, 0.7, -0.4])
    model, _ = _model_of(table, np.float64, north_offset)
    # compiled once for the model, its Jacobians and every difference (eagerly, each call
    # dispatched its operations one by one)
    model_jac = jax.jit(lambda b, t: _model_and_jacobian(model, b, t, ref_dir, hidx))
    model, jb, jt = model_jac(beta, theta)
    eps = 1e-6
    for k in range(beta.shape[1]):
        e = np.zeros_like(beta)
        e[:, k] = eps
        fd = (model_jac(beta + e, theta)[0] - model_jac(beta - e, theta)[0]) / (2 * eps)
        np.testing.assert_allclose(jb[..., k], fd, rtol=1e-6, atol=1e-7)
    for k in range(3):
        e = np.zeros(3)
        e[k] = eps
        fd = (model_jac(beta, theta + e)[0] - model_jac(beta, theta - e)[0]) / (2 * eps)
        np.testing.assert_allclose(jt[..., k], fd, rtol=1e-6, atol=1e-7)
