"""The real Windcube V2.1 `.rtd` in ../shared/data/windcube (skipped when absent): header
facts, UTC, the instrument's CNR filter, and the instrument's own per-line reconstruction
reproduced to the precision its file prints."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lidarjax.flags import RecordFlag
from lidarjax.io import group_rtd, read_rtd
from lidarjax.io.rtd import instrument_reconstruction

from ..helpers import windcube_file

NAME = "WLS866-104_2024_08_02__23_44_55.rtd"


def real_rtd() -> Path:
    return windcube_file(NAME)


@pytest.fixture(scope="module")
def rec():
    return read_rtd(real_rtd())


def test_header_facts_and_utc(rec):
    assert rec.version == "V2" and rec.instrument == "windcube_v2"
    assert rec.time.size == 1131 and rec.dropped_lines == ()
    np.testing.assert_array_equal(rec.heights, [40, 50, 60, 70, 100, 120, 150])
    assert rec.cnr_threshold == -23.0 and rec.pitch == 0.379 and rec.roll == 0.262
    assert rec.direction_offset == 0.0 and np.isnan(rec.scan_angle) and rec.cone_angle == 28.0
    assert rec.timezone == "UTC--3" and rec.utc_offset_hours == -3.0
    assert rec.time_local[0] == np.datetime64("2024-08-02T23:44:55.380")
    assert rec.time[0] == np.datetime64("2024-08-03T02:44:55.380")  # UTC-3 -> +3 h
    assert rec.beam_azimuths[:4] == (0.0, 90.0, 180.0, 270.0) and np.isnan(rec.beam_azimuths[4])


def test_instrument_cnr_filter_and_partial_interval(rec):
    g = group_rtd(rec)
    np.testing.assert_array_equal(g.time, np.array(["2024-08-03T02:50", "2024-08-03T03:00"],
                                                   dtype="datetime64[ms]"))
    # the file starts at 23:44:55 local: the first interval is partial and not used
    np.testing.assert_array_equal(g.partial, [True, False])
    assert np.isnan(g.los[0]).all()
    assert np.all(g.flags[0] & int(RecordFlag.PARTIAL_INTERVAL | RecordFlag.LOW_AVAILABILITY))
    # every vertical sample is below CNRThreshold=-23 dB: the vertical beam is not used
    assert np.all(rec.cnr[rec.vertical] < -23)
    assert np.isnan(g.los[:, :, 4]).all() and (g.count[:, :, 4] == 0).all()
    assert np.all(g.flags[1, :, 4] & int(RecordFlag.BELOW_CNR_THRESHOLD))
    # the full interval: the four tilted beams are complete (150 samples each, 4 s cycle)
    assert g.cycle == np.timedelta64(4000, "ms")
    np.testing.assert_array_equal(g.availability[1, :, :4], 100.0)
    assert np.isfinite(g.los[1, :, :4]).all()
    # the 10-minute wind from the beam means matches the instrument's own per-line values
    rws = -g.los[1, :, :4]
    s2 = 2 * np.sin(np.radians(28.0))
    x, y = (rws[:, 0] - rws[:, 2]) / s2, (rws[:, 1] - rws[:, 3]) / s2
    in_interval = (rec.time > g.time[0]) & (rec.time <= g.time[1])
    inst_speed = np.nanmean(rec.extra["windspeed"][in_interval], axis=0)
    d = np.radians(rec.extra["winddirection"][in_interval])
    inst_dir = np.degrees(np.arctan2(np.nanmean(np.sin(d), 0), np.nanmean(np.cos(d), 0)))
    np.testing.assert_allclose(np.hypot(x, y), inst_speed, rtol=0.01)
    np.testing.assert_allclose(np.degrees(np.arctan2(y, x)) % 360, inst_dir % 360, atol=0.3)
    # without the filter, the noise of the vertical beam (about 16 m/s) would come back
    raw = group_rtd(rec, cnr_threshold=None, min_availability=0)
    assert np.nanmean(np.abs(raw.los[1, :, 4])) > 5


def test_instrument_reconstruction_reproduces_the_file(rec):
    out = instrument_reconstruction(rec)
    s2 = 2 * np.sin(np.radians(28.0))
    # The file prints RWS to 0.01 m/s and X/Y/Z to 0.001: the difference of two rounded RWS
    # is off by up to 0.01 m/s, hence the bound on X and Y; Z copies one RWS (0.005).
    bound_xy = 0.01 / s2 + 0.0005 + 1e-9
    ref = rec.extra
    seen = np.isfinite(out.x_wind) & np.isfinite(out.y_wind)  # after one full cycle
    assert seen[10:].all()
    for name, key, bound in (("x_wind", "xwind", bound_xy), ("y_wind", "ywind", bound_xy),
                             ("z_wind", "zwind", 0.005 + 0.0005 + 1e-9)):
        got, want = getattr(out, name)[10:], ref[key][10:]
        m = np.isfinite(want)
        assert m.sum() > 6000
        err = np.abs(got[m] - want[m])
        assert err.max() <= bound, (name, err.max(), bound)
        assert np.isfinite(got[m]).all()
    # speed and direction printed to 0.01: bounded by the X/Y error plus the rounding
    m = np.isfinite(ref["windspeed"][10:])
    speed_err = np.abs(out.speed[10:][m] - ref["windspeed"][10:][m])
    assert speed_err.max() <= np.sqrt(2) * bound_xy + 0.005
    dir_err = np.abs((out.direction[10:][m] - ref["winddirection"][10:][m] + 180) % 360 - 180)
    allowed = np.degrees(np.sqrt(2) * bound_xy / out.speed[10:][m]) + 0.005
    assert np.all(dir_err <= allowed)
    # the vertical wind, positive up, is minus the file's Z-wind
    np.testing.assert_array_equal(out.w, -out.z_wind)
    # the cone that fits best is 28 degrees (the header says NA)
    fit = instrument_reconstruction(rec, cone_angle=28.5)
    assert np.nanmax(np.abs(fit.y_wind[10:] - ref["ywind"][10:])) > 5 * bound_xy
