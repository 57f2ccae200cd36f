"""Tables over direction x a profile parameter (`lidarjax.ProfileTable`) and the joint
inversion across heights (`lidarjax.invert_joint`), against synthetic campaigns generated in
plain numpy (tests/_campaign.py)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj
from lidarjax.io import load_table, save_table

from .. import _campaign as cp

HEIGHTS = np.array([40.0, 60.0, 80.0, 100.0, 130.0, 160.0])
Z_REF = 100.0
ALPHAS = np.array([0.0, 0.1, 0.2, 0.3])
DIRECTIONS = np.arange(0.0, 360.0, 10.0)


def _dbs(los):
    """The Windcube's reconstruction from its beams (lidar frame = north frame here):
    ``u = (S1 - S3) / (2 sin c)``, ``v = (S0 - S2) / (2 sin c)``, ``w`` the vertical beam."""
    s = 2.0 * np.sin(np.deg2rad(cp.CONE))
    return np.stack([(los[..., 1] - los[..., 3]) / s, (los[..., 0] - los[..., 2]) / s,
                     los[..., 4]], -1)


def _tables(alphas=ALPHAS):
    out = []
    for a in alphas:
        resp, vel, beams = cp.table_runs(DIRECTIONS, HEIGHTS, a, Z_REF)
        out.append(lj.ResponseTable(DIRECTIONS, resp, beam_velocity=vel, beam_vectors=beams,
                                    reconstructed=_dbs(resp), heights=HEIGHTS))
    return out


@pytest.fixture(scope="module")
def table():
    # runs normalised by the reference-height free stream, as from_simulations gives them;
    # with the Windcube's reconstruction for `invert_joint_reconstructed`
    return lj.ProfileTable("alpha", ALPHAS, _tables(), profile=lj.PowerLawProfile(Z_REF),
                           per_reference_speed=True)


def test_profile_table_holds_the_local_response_and_interpolates_in_alpha(table):
    # dividing by the profile leaves the distortion per unit local speed, linear in alpha in
    # this flow: the natural cubic spline reproduces it exactly between the runs
    d, a = np.array([17.0, 123.0, 301.0]), np.array([0.05, 0.17, 0.26])
    got = np.asarray(table.response_at(d, a))
    vel = cp.flow(np.broadcast_to(d[:, None], (3, HEIGHTS.size)), HEIGHTS,
                  np.broadcast_to(a[:, None], (3, HEIGHTS.size)))
    want = np.einsum("nhbk,bk->nhb", vel, cp.body_beams())
    # the remaining error is the periodic spline's in direction (10 degree runs)
    np.testing.assert_allclose(got, want, atol=2e-5)
    # at a run's parameter the table is that run's table
    np.testing.assert_allclose(table.response_at(d, 0.2), table.tables[2].response_at(d),
                               atol=1e-12)
    np.testing.assert_allclose(table.at(0.17).response_at(d), table.response_at(d, 0.17),
                               atol=1e-12)


def test_profile_table_is_c2_in_the_parameter_and_nan_outside():
    # a response that is not linear in alpha: derivatives continuous across the interior runs
    resp = [np.cos(np.deg2rad(DIRECTIONS))[:, None, None] * np.ones((1, 2, 3)) * np.exp(3 * a)
            for a in ALPHAS]
    t = lj.ProfileTable("alpha", ALPHAS, [lj.ResponseTable(DIRECTIONS, r) for r in resp])

    @jax.jit
    def f(a):
        return t.response_at(20.0, a)[0, 0]

    d1, d2 = jax.jit(jax.grad(f)), jax.jit(jax.grad(jax.grad(f)))
    for knot in ALPHAS[1:-1]:
        lo, hi = knot - 1e-9, knot + 1e-9
        assert abs(float(d1(lo)) - float(d1(hi))) < 1e-6
        assert abs(float(d2(lo)) - float(d2(hi))) < 1e-4
    assert np.isnan(float(f(0.31))) and np.isnan(float(f(-0.01)))
    # linear continuation outside with the end slope
    ext = float(t.response_at(20.0, 0.35, extrapolate=True)[0, 0])
    np.testing.assert_allclose(ext, float(f(0.3)) + 0.05 * float(d1(0.3 - 1e-12)), rtol=1e-9)
    with pytest.raises(ValueError, match="increasing"):
        lj.ProfileTable("alpha", [0.0, 0.0], [t.tables[0], t.tables[1]])
    with pytest.raises(ValueError, match="outside"):
        t.at(0.5)


def test_profile_table_file_round_trip(table, tmp_path):
    path = save_table(tmp_path / "pt.npz", table, {"note": "x"})
    back, meta = load_table(path, return_metadata=True)
    assert isinstance(back, lj.ProfileTable) and back.name == "alpha"
    assert meta["profile"] == {"kind": "power_law", "reference_height_m": Z_REF}
    assert float(back.profile.reference_height) == Z_REF
    np.testing.assert_array_equal(np.asarray(back.response), np.asarray(table.response))
    np.testing.assert_array_equal(back.tables[1].beam_velocity, table.tables[1].beam_velocity)
    np.testing.assert_allclose(back.response_at(33.0, 0.12), table.response_at(33.0, 0.12),
                               atol=0)
    # a one-parameter table still loads as a ResponseTable
    one = save_table(tmp_path / "one.npz", table.tables[0])
    assert type(load_table(one)) is lj.ResponseTable


@pytest.fixture(scope="module")
def noisy(table):
    rng = np.random.default_rng(11)
    los, truth = cp.campaign(rng, 400, HEIGHTS, Z_REF, alpha=(0.02, 0.28), sigma=0.1)
    return los, truth, lj.invert_joint(table, los, noise=0.1)


def test_invert_joint_recovers_the_truth_within_its_standard_errors(noisy):
    los, truth, out = noisy
    assert np.all(np.asarray(out.converged))
    # alpha drawn in [0.02, 0.28]: only estimates past the runs' [0, 0.3] carry a flag
    flags = np.asarray(out.flags)
    outside = (np.asarray(out.parameter) < 0) | (np.asarray(out.parameter) > 0.3)
    np.testing.assert_array_equal(flags, np.where(outside, lj.InverseFlag.PARAMETER_EXTRAPOLATED,
                                                  0))
    z = {
        "speed": (np.asarray(out.speed) - truth["speed_ref"]) / np.asarray(out.speed_std),
        "direction": ((np.asarray(out.direction) - truth["direction"] + 180) % 360 - 180)
        / np.asarray(out.direction_std),
        "alpha": (np.asarray(out.parameter) - truth["alpha"]) / np.asarray(out.parameter_std),
    }
    for name, v in z.items():
        cover = np.mean(np.abs(v) < 1.96)
        assert 0.92 <= cover <= 0.98, (name, cover)
    hz = (np.asarray(out.height_speed) - truth["speed"]) / np.asarray(out.height_speed_std)
    assert 0.92 <= np.mean(np.abs(hz) < 1.96) <= 0.98
    corr = np.asarray(out.correlation)
    np.testing.assert_allclose(np.diagonal(corr, axis1=-2, axis2=-1), 1.0, atol=1e-9)


def test_invert_joint_beats_per_height_inversion_when_the_profile_varies(table, noisy):
    los, truth, out = noisy
    per_height = lj.invert(table.at(0.15), los)  # one table at the typical profile
    err_joint = np.asarray(out.height_speed) - truth["speed"]
    err_ph = np.asarray(per_height.speed) - truth["speed"]
    rms_joint, rms_ph = np.sqrt(np.mean(err_joint**2)), np.sqrt(np.nanmean(err_ph**2))
    assert rms_joint < 0.6 * rms_ph, (rms_joint, rms_ph)
    dd = lambda x: (x - truth["direction"][:, None] + 180) % 360 - 180  # noqa: E731
    assert np.sqrt(np.mean(dd(np.asarray(out.direction)[:, None]) ** 2)) < np.sqrt(
        np.nanmean(dd(np.asarray(per_height.direction)) ** 2))


def test_invert_joint_refuses_bad_records_and_keeps_the_good(table, noisy):
    # the campaign's shape: the compiled solver is shared with the other tests
    los = np.array(noisy[0])
    los[1] = np.nan  # nothing measured
    los[2, :, 1:] = np.nan  # one beam per height: too few for min_beams=8 ...
    los[2, :2, :] = noisy[0][2, :2, :]  # ... no: two full heights and 4 single beams: 14
    los[3, :, :] = np.nan
    los[3, 0, :3] = noisy[0][3, 0, :3]  # three beams: fewer than the default min_beams=4
    out = lj.invert_joint(table, los, noise=0.1)
    ref = noisy[2]
    conv = np.asarray(out.converged)
    for k in (1, 3):
        assert not conv[k] and np.isnan(float(out.speed[k])) and np.isnan(float(out.parameter[k]))
        assert int(out.flags[k]) & lj.InverseFlag.TOO_FEW_BEAMS
    assert conv[2]  # fewer beams, still enough: a wider but honest answer
    assert float(out.speed_std[2]) > float(ref.speed_std[2])
    good = np.ones(len(los), bool)
    good[[1, 2, 3]] = False
    assert np.all(conv[good])  # the others are exactly what they were
    np.testing.assert_array_equal(np.asarray(out.speed)[good], np.asarray(ref.speed)[good])
    with pytest.raises(ValueError, match="no profile axis"):
        lj.invert_joint(table.tables[0], los)
    with pytest.raises(ValueError, match=r"\(h, b\)"):
        lj.invert_joint(table, los[:, :3])
    with pytest.raises(ValueError, match="noise"):
        lj.invert_joint(table, los, noise=-1.0)


def test_invert_joint_extrapolates_with_a_flag(table, noisy):
    rng = np.random.default_rng(2)
    los, truth = cp.campaign(rng, len(noisy[0]), HEIGHTS, Z_REF, alpha=0.4, sigma=0.0)
    out = lj.invert_joint(table, los, noise=0.1)
    assert np.all(np.asarray(out.flags) & lj.InverseFlag.PARAMETER_EXTRAPOLATED)
    np.testing.assert_allclose(out.parameter, 0.4, atol=0.02)


def test_invert_joint_derivatives_match_finite_differences(table, noisy):
    # forward mode through the solver (implicit differentiation of the optimum): three
    # records, each with its own random LOS direction, against central differences
    los = np.asarray(noisy[0])
    rng = np.random.default_rng(0)
    v = rng.standard_normal((3,) + los.shape[1:])

    def solve(x):
        out = lj.invert_joint(table, x, noise=0.1)
        return jnp.stack([out.speed, out.direction, out.parameter])

    _, tangent = jax.jit(lambda x, t: jax.jvp(solve, (x,), (t,)))(jnp.asarray(los[:3]),
                                                                  jnp.asarray(v))
    # central differences, all in one call of the compiled campaign-shaped solver
    eps = 1e-5
    batch = np.array(los)
    batch[:3] = los[:3] + eps * v
    batch[3:6] = los[:3] - eps * v
    out = lj.invert_joint(table, batch, noise=0.1)
    got = np.stack([np.asarray(out.speed), np.asarray(out.direction),
                    np.asarray(out.parameter)])
    fd = (got[:, :3] - got[:, 3:6]) / (2 * eps)
    np.testing.assert_allclose(np.asarray(tangent), fd, rtol=1e-5, atol=1e-7)


def test_invert_joint_reconstructed_recovers_reported_winds(table):
    rng = np.random.default_rng(9)
    los, truth = cp.campaign(rng, 24, HEIGHTS, Z_REF, alpha=(0.02, 0.28), sigma=0.0)
    rec = _dbs(los)  # what a .sta file reports, per height
    speed = np.hypot(rec[..., 0], rec[..., 1])
    direction = np.rad2deg(np.arctan2(-rec[..., 0], -rec[..., 1])) % 360
    speed[5, 2] = -1.0  # impossible: that height is dropped and the record flagged
    speed[7] = np.nan  # nothing reported: the record is refused, the others not
    out = lj.invert_joint_reconstructed(table, speed, direction, noise=0.05)
    flags = np.asarray(out.flags)
    assert flags[5] == lj.InverseFlag.IMPOSSIBLE_INPUT and bool(out.converged[5])
    assert not bool(out.converged[7]) and flags[7] & lj.InverseFlag.TOO_FEW_BEAMS
    ok = np.ones(24, bool)
    ok[7] = False
    assert np.all(np.asarray(out.converged)[ok]) and np.all(flags[ok & (np.arange(24) != 5)] == 0)
    # the remaining error is the direction spline's (runs every 10 degrees)
    np.testing.assert_allclose(np.asarray(out.speed)[ok], truth["speed_ref"][ok], rtol=2e-4)
    np.testing.assert_allclose(np.asarray(out.parameter)[ok], truth["alpha"][ok], atol=2e-3)
    dd = (np.asarray(out.direction) - truth["direction"] + 180) % 360 - 180
    assert np.max(np.abs(dd[ok])) < 0.02
