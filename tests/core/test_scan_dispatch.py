"""`simulate` and `simulate_series` take a scanning pattern (issue 22): the calls are those of
`simulate_scan` / `simulate_scan_series`, and profiling arguments are refused."""

from __future__ import annotations

import numpy as np
import pytest

import lidarjax as lj
from lidarjax.scenes import uniform

FIELD = uniform(10.0, 270.0)
MOUNT = lj.Mount([0.0, 0.0, 0.0])
PPI = lj.ppi(10.0, np.arange(100.0, 401.0, 100.0), n_rays=12, accumulation=1.0)


def test_simulate_dispatches_a_scanning_pattern():
    a = lj.simulate(FIELD, PPI, MOUNT)
    b = lj.simulate_scan(FIELD, PPI, MOUNT)
    np.testing.assert_array_equal(np.asarray(a.los), np.asarray(b.los))
    # uniform 10 m/s from the west: LOS = 10 cos(el) sin(az) (+x east, beam away from lidar)
    az, el = np.deg2rad(np.asarray(a.azimuth)), np.deg2rad(np.asarray(a.elevation))
    expect = 10.0 * np.cos(el) * np.sin(az)
    np.testing.assert_allclose(np.asarray(a.los), np.broadcast_to(expect[:, None], a.los.shape),
                               atol=1e-9)
    with pytest.raises(ValueError, match="drop `heights`"):
        lj.simulate(FIELD, PPI, MOUNT, [40.0])
    with pytest.raises(ValueError, match="`heights`"):
        lj.simulate(FIELD, lj.windcube_v2(), MOUNT)


def test_simulate_series_dispatches_a_scanning_pattern():
    period = float(np.asarray(PPI.period))
    a = lj.simulate_series(FIELD, PPI, MOUNT, None, (5.0, 2.5 * period))
    b = lj.simulate_scan_series(FIELD, PPI, MOUNT, n_scans=2, start=5.0)
    np.testing.assert_array_equal(np.asarray(a.los), np.asarray(b.los))
    np.testing.assert_array_equal(np.asarray(a.times), np.asarray(b.times))
    with pytest.raises(ValueError, match="heights=None"):
        lj.simulate_series(FIELD, PPI, MOUNT, [40.0], (0.0, period))
    with pytest.raises(ValueError, match="at least one repetition"):
        lj.simulate_series(FIELD, PPI, MOUNT, None, (0.0, 0.5 * period))


def test_scanning_pattern_through_an_unsteady_sequence():
    """A PPI repeated through snapshots of a flow linear in time, loaded a window at a time:
    the LOS equal the closed form at each sub-ray's time; beyond the snapshots NaN and
    TIME_OUTSIDE."""
    x = np.linspace(-600.0, 600.0, 5)
    z = np.linspace(0.0, 200.0, 3)
    times = np.arange(0.0, 61.0, 5.0)

    def snap(t):
        vel = np.zeros((5, 5, 3, 3))
        vel[..., 0] = 8.0 + 0.1 * t
        return lj.GridField(x, x, z, vel)

    seq = lj.FieldSequence(times, lambda k: snap(times[k]), max_snapshots=6)
    ppi = lj.ppi(0.0, np.array([100.0, 300.0]), n_rays=6, accumulation=1.0, mode="step")
    period = float(np.asarray(ppi.period))
    n = int(70.0 // period)
    res = lj.simulate_series(seq, ppi, MOUNT, None, (0.0, n * period))
    t = np.asarray(res.times)
    az = np.deg2rad(np.asarray(res.azimuth))
    expect = np.broadcast_to((8.0 + 0.1 * t)[..., None] * np.sin(az)[None, :, None], res.los.shape)
    inside = t <= 60.0
    np.testing.assert_allclose(np.asarray(res.los)[inside], expect[inside], atol=1e-9)
    assert np.isnan(np.asarray(res.los)[~inside]).all()
    assert np.all(np.asarray(res.flags)[~inside] == int(lj.Flag.TIME_OUTSIDE))
