"""Issue 29 point 4: `invert` and `invert_joint` with a tilted and turned table
installation. Both fit the tabulated responses of the runs, which `simulate` made with the
tilted beams at their moved points, so nothing in them assumes a level instrument; checked
here against records that `simulate` writes with the same installation, at a direction
(and shear exponent) between the table's knots. A level table (the neglect these tests
would catch: an inversion or table that took the beams as untilted) misses by far more."""

import numpy as np
import pytest

import lidarjax as lj

SCAN = lj.windcube_v2()
HEIGHTS = np.array([40.0, 80.0, 120.0])
DIRECTIONS = np.arange(0.0, 360.0, 10.0)
TILTED = dict(gamma=20.0, epsilon=10.0, pitch=3.0, roll=-2.0)


def _ridge(direction, speed=1.0):
    return lj.scenes.hill(height=40.0, half_width=200.0, speed=speed, direction=direction)


def _ridge_table(mount):
    fields = [_ridge(d) for d in DIRECTIONS]
    sims = [lj.simulate(f, SCAN, mount, HEIGHTS, u_ref=np.asarray(lj.heading(d)))
            for f, d in zip(fields, DIRECTIONS, strict=True)]
    return lj.ResponseTable.from_simulations(sims, mount=mount, scan=SCAN)


def test_invert_with_a_tilted_turned_table_over_a_ridge():
    loc = (60.0, 0.0, 40.0 / (1.0 + (60.0 / 200.0) ** 2))
    tilted = lj.Mount(loc, **TILTED)
    table = _ridge_table(tilted)
    assert (table.instrument.pitch_deg, table.instrument.roll_deg,
            table.instrument.epsilon_deg) == (3.0, -2.0, 10.0)
    sim = lj.simulate(_ridge(123.4, 8.3), SCAN, tilted, HEIGHTS,
                      u_ref=8.3 * np.asarray(lj.heading(123.4)))
    truth_d = float(sim.free_direction)  # the north frame of the installation
    inv = lj.invert(table, sim.los)
    assert np.all(np.asarray(inv.converged))
    err_u = np.max(np.abs(np.asarray(inv.speed) - 8.3))
    err_d = np.max(np.abs(lj.wrap180(np.asarray(inv.direction) - truth_d)))
    assert err_u < 1e-3 and err_d < 1e-3  # measured 1.6e-5 m/s, 6e-6 deg (the splines)
    # a table of the level instrument (same north frame) is off by much more
    level = _ridge_table(lj.Mount(loc, gamma=20.0, epsilon=10.0))
    inv0 = lj.invert(level, sim.los)
    # measured 0.045 m/s and 0.19 deg
    assert np.max(np.abs(np.asarray(inv0.speed) - 8.3)) > 0.02
    assert np.max(np.abs(lj.wrap180(np.asarray(inv0.direction) - truth_d))) > 0.05


@pytest.mark.parametrize("pitch_roll", [(3.0, -2.0), (0.0, 0.0)], ids=["tilted", "level"])
def test_invert_joint_with_a_tilted_turned_profile_table(pitch_roll):
    pitch, roll = pitch_roll
    mount = lj.Mount((0.0, 0.0, 2.0), gamma=20.0, epsilon=10.0, pitch=pitch, roll=roll)
    alphas = (0.0, 0.15, 0.3)
    tables = []
    for a in alphas:
        fields = [lj.scenes.power_law(1.0, 100.0, a, d) for d in DIRECTIONS]
        sims = [lj.simulate(f, SCAN, mount, HEIGHTS, u_ref=np.asarray(lj.heading(d)))
                for f, d in zip(fields, DIRECTIONS, strict=True)]
        tables.append(lj.ResponseTable.from_simulations(sims, mount=mount, scan=SCAN))
    # the free stream at the lidar's reference height 98 m above it (100 m above ground)
    table = lj.ProfileTable("alpha", alphas, tables, profile=lj.PowerLawProfile(98.0),
                            per_reference_speed=True)
    field = lj.scenes.power_law(8.3, 100.0, 0.11, 123.4)
    sim = lj.simulate(field, SCAN, mount, HEIGHTS, u_ref=8.3 * np.asarray(lj.heading(123.4)))
    out = lj.invert_joint(table, sim.los)
    assert bool(out.converged)
    # the power law's speed at the lidar's reference height, (98 + 2) m above ground
    # measured 1.6e-5 m/s, 6e-6 deg, 2e-7 (the splines in direction and alpha)
    np.testing.assert_allclose(float(out.speed), 8.3, atol=1e-3)
    assert abs(float(lj.wrap180(out.direction - sim.free_direction))) < 1e-3
    np.testing.assert_allclose(float(out.parameter), 0.11, atol=1e-4)
    if pitch:
        # a level table of the same north frame misreads the tilted records
        level = [lj.ResponseTable.from_simulations(
            [lj.simulate(lj.scenes.power_law(1.0, 100.0, a, d), SCAN,
                         lj.Mount((0.0, 0.0, 2.0), gamma=20.0, epsilon=10.0), HEIGHTS,
                         u_ref=np.asarray(lj.heading(d))) for d in DIRECTIONS],
            mount=lj.Mount((0.0, 0.0, 2.0), gamma=20.0, epsilon=10.0), scan=SCAN)
            for a in alphas]
        out0 = lj.invert_joint(lj.ProfileTable("alpha", alphas, level,
                                               profile=lj.PowerLawProfile(98.0),
                                               per_reference_speed=True), sim.los)
        # measured: direction 0.097 deg, speed 0.004 m/s off
        assert abs(float(lj.wrap180(out0.direction - sim.free_direction))) > 0.05
        assert abs(float(out0.speed) - 8.3) > 2e-3
