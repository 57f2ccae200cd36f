"""Issue 29: a tilt or turn of the lidar moves its measurement points, and where the flow
varies in space that changes the LOS at first order in the offset.

Checked against `lidarjax.simulate` itself with truly turned and tilted `Mount`s (it moves
the beams and their probe nodes, and knows nothing of the gradient model): `beam_gradient`
predicts the first-order change of the simulated LOS, a table carries it through files, and
`calibrate` recovers the offsets over a ridge (beside its crest) to well within the errors
that leaving the displacement out makes."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj
from lidarjax.frames import cfd_to_north_rotation

HEIGHTS = np.array([40.0, 80.0, 120.0])
SCAN = lj.windcube_v2()
# beside the crest of a Witch-of-Agnesi ridge (H = 40 m, L = 200 m), on the ground
LOC = (60.0, 0.0, 40.0 / (1.0 + (60.0 / 200.0) ** 2))
DIRECTIONS = np.arange(0.0, 360.0, 10.0)


def _ridge(direction, speed):
    return lj.scenes.hill(height=40.0, half_width=200.0, speed=speed, direction=direction)


def _u_ref(direction, speed):
    r = jnp.deg2rad(direction)
    return jnp.stack([-speed * jnp.sin(r), -speed * jnp.cos(r), 0.0 * r])


@pytest.fixture(scope="module")
def tables():
    """The ridge's table for a level lidar with its north at the CFD's +y, with and without
    the gradient."""
    mount = lj.Mount(LOC)
    fields = [_ridge(d, 1.0) for d in DIRECTIONS]
    sims = [lj.simulate(f, SCAN, mount, HEIGHTS, u_ref=_u_ref(d, 1.0))
            for f, d in zip(fields, DIRECTIONS, strict=True)]
    with_g = lj.ResponseTable.from_simulations(sims, mount=mount, fields=fields, scan=SCAN)
    without = lj.ResponseTable(
        np.asarray(with_g.directions), np.asarray(with_g.response),
        beam_velocity=np.asarray(with_g.beam_velocity),
        beam_vectors=np.asarray(with_g.beam_vectors), heights=np.asarray(with_g.heights),
        instrument=with_g.instrument)
    return with_g, without


@jax.jit
def _records(direction, speed, d_eps, pitch, roll):
    """LOS of a lidar turned so that its beams' bearings grow by `d_eps` (gamma = -d_eps)
    and tilted by `pitch`, `roll`, one record per (direction, speed)."""
    mount = lj.Mount(LOC, gamma=-d_eps, pitch=pitch, roll=roll)
    return jax.vmap(lambda d, u: lj.simulate(_ridge(d, u), SCAN, mount, HEIGHTS).los)(
        direction, speed)


@pytest.mark.parametrize("probe", [lj.PointProbe(), lj.PulsedProbe()], ids=["point", "pulsed"])
def test_beam_gradient_predicts_the_first_order_change_of_simulate(probe):
    field = _ridge(250.0, 10.0)
    # a turned platform and north offset: the gradient comes back in the north frame
    turned = dict(beta=15.0, gamma=30.0, psi=180.0, epsilon=10.0)
    level = lj.Mount(LOC, **turned)
    q = np.asarray(cfd_to_north_rotation(level))
    base = lj.simulate(field, SCAN, level, HEIGHTS, probe=probe)
    g = np.asarray(lj.beam_gradient(field, SCAN, level, HEIGHTS, probe=probe))
    n = np.asarray(base.directions) @ q.T
    v = np.asarray(field.sample(base.points)) @ q.T
    rho = np.asarray(base.ranges)
    # the gradient itself: central differences of the scene at the focus (point probe)
    if isinstance(probe, lj.PointProbe):
        p = np.asarray(base.points)
        fd = np.stack([(np.asarray(field.sample(p + e)) - np.asarray(field.sample(p - e))) / 2e-3
                       for e in 1e-3 * np.eye(3)], -1)
        np.testing.assert_allclose(g, q @ fd @ q.T, rtol=1e-6, atol=1e-9)
    tilted = lj.simulate(field, SCAN, lj.Mount(LOC, pitch=-0.02, roll=0.03, **turned), HEIGHTS,
                         probe=probe)
    dn = np.asarray(tilted.directions) @ q.T - n
    turned_only = np.asarray(base.los) + np.einsum("bk,hbk->hb", dn, v)
    moved = turned_only + rho * np.einsum("bi,hbij,bj->hb", n, g, dn)
    err_turned = np.abs(np.asarray(tilted.los) - turned_only).max()
    err_moved = np.abs(np.asarray(tilted.los) - moved).max()
    # leaving the displacement out is a first-order error (r |grad V| / U of the change)...
    assert err_turned > 0.02 * np.abs(np.asarray(tilted.los) - np.asarray(base.los)).max()
    # ...with it, what is left is second order (point probe: of relative size
    # rho |dn| / L ~ 136 m * 6e-4 / 200 m ~ 4e-4), or the probe's averaging of V against the
    # focus velocity used for the turn (pulsed)
    assert err_moved < (2e-3 if isinstance(probe, lj.PointProbe) else 3e-2) * err_turned


def test_the_gradient_goes_through_table_files(tables, tmp_path):
    table = tables[0]
    assert table.beam_gradient.shape == (DIRECTIONS.size, HEIGHTS.size, 5, 3, 3)
    lj.io.save_table(tmp_path / "t.npz", table)
    back = lj.io.load_table(tmp_path / "t.npz")
    np.testing.assert_array_equal(back.beam_gradient, table.beam_gradient)
    # per unit free-stream speed: the gradient of the speed-10 ridge over 10
    level = lj.Mount(LOC)
    g = lj.beam_gradient(_ridge(DIRECTIONS[7], 10.0), SCAN, level, HEIGHTS)
    np.testing.assert_allclose(table.beam_gradient[7], np.asarray(g) / 10.0, rtol=1e-9,
                               atol=1e-12)


def test_calibrate_over_a_ridge_recovers_a_turn_and_tilt_with_the_displacement(tables):
    """Noise-free records of a lidar turned by 4 degrees and tilted by 1.5 and -2 degrees
    beside the ridge's crest: with the table's gradient the error is 1e-4 to 2e-3 degrees
    (the second-order curvature term); without it, 0.03-0.1 degrees, several times the standard
    errors of a campaign with 0.1 m/s noise (about 0.012 degrees), with a warning."""
    with_g, without = tables
    rng = np.random.default_rng(29)
    true = np.array([4.0, 1.5, -2.0])
    n = 200
    d, u = rng.uniform(0.0, 360.0, n), rng.uniform(4.0, 14.0, n)
    los = np.asarray(_records(d, u, *true))
    ref = (np.broadcast_to(u[:, None], (n, 3)), np.broadcast_to(d[:, None], (n, 3)))
    good = lj.calibrate(los, with_g, reference=ref)
    assert good.converged and int(good.flags) == 0
    assert any("first order" in x and "relinearised" in x for x in good.notes)
    # the curvature of the flow over the displacement (9 m for the turn at 136 m) is left
    assert np.all(np.abs(np.asarray(good.offset) - true) < [3e-3, 1.5e-3, 1.5e-3])
    with pytest.warns(UserWarning, match="no beam_gradient"):
        bad = lj.calibrate(los, without, reference=ref)
    assert any("no beam_gradient" in x for x in bad.notes)
    assert np.max(np.abs(np.asarray(bad.offset) - true)) > 0.02
    # without a reference: epsilon refused, but the displacement by the unknown turn is
    # fitted as a nuisance instead of going into the tilt
    tilt = lj.calibrate(los, with_g)
    assert np.isnan(float(tilt.offset[0])) and tilt.converged
    assert any("kept as a nuisance" in x for x in tilt.notes)
    np.testing.assert_allclose(tilt.offset[1:], true[1:], atol=2e-3)


def test_model_jacobian_with_the_gradient_matches_central_differences(tables):
    """With `beam_gradient` the sensitivity ``S`` turns with the beams; the Jacobian in the
    offsets includes that change (Gauss--Newton converges in a few passes even where an
    offset is barely identifiable), against central differences of the same model."""
    from lidarjax.calibrate import _model_and_jacobian, _model_of

    model, _ = _model_of(tables[0], np.float64)
    rng = np.random.default_rng(3)
    n = 6
    hidx = np.arange(n) % HEIGHTS.size
    ref_dir = rng.uniform(0, 360, n)
    nuisance = rng.uniform(4, 12, (n, 1))
    theta = np.array([6.0, 1.7, -1.9])
    model_jac = jax.jit(lambda b, t: _model_and_jacobian(model, b, t, ref_dir, hidx))
    _, _, jt = model_jac(nuisance, theta)
    for k in range(3):
        e = np.zeros(3)
        e[k] = 1e-5
        fd = (model_jac(nuisance, theta + e)[0] - model_jac(nuisance, theta - e)[0]) / 2e-5
        np.testing.assert_allclose(jt[..., k], fd, rtol=1e-6, atol=1e-8)
