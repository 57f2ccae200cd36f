"""Scan schedules (`lidarjax.Schedule`, `lidarjax.schedule_for`): the instruments' beam
timing, update rules and validation."""

import numpy as np
import pytest

import lidarjax as lj
from lidarjax.timing import Schedule, schedule_for


def test_schedule_defaults_of_the_instruments():
    v1, v2, zp = (schedule_for(s) for s in (lj.windcube_v1(), lj.windcube_v2(), lj.zephir()))
    np.testing.assert_allclose(v1.beam_times, [0, 1.5, 3.0, 4.5])
    assert float(v1.period) == 6.0 and v1.update == "each_los" and not v1.heights_sequential
    np.testing.assert_allclose(v2.beam_times, [0, 1, 2, 3, 4])
    assert float(v2.period) == 5.0
    assert zp.heights_sequential and zp.rotations_per_height == 3 and zp.update == "each_visit"
    np.testing.assert_allclose(float(zp.period), 1.0)
    assert float(zp.cycle_time(5)) == 15.0


def test_schedule_validation():
    with pytest.raises(ValueError, match="period"):
        Schedule([0, 1, 2], 1.5)
    with pytest.raises(ValueError, match="update"):
        Schedule([0, 1, 2], 3.0, update="sometimes")
