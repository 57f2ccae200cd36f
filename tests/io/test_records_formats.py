"""Record formats written by the tests: Windcube V1 gate-numbered and V2.1 1-minute `.sta`,
a V2.1 `.rtd` (UTC-3, CNR threshold), ZephIR 300 and ZX CSV exports (time conventions)."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from lidarjax.flags import RecordFlag
from lidarjax.io import group_rtd, read_rtd, read_sta, read_zephir_csv  # noqa: E402
from lidarjax.io.rtd import instrument_reconstruction  # noqa: E402

from . import record_samples as S


def write(tmp_path, name, text):
    path = tmp_path / name
    path.write_bytes(text.encode("cp1252"))
    return path


@pytest.mark.parametrize("split_date", [False, True], ids=["one-field-stamp", "date-tab-time"])
def test_windcube_v1_gate_numbered_sta(tmp_path, split_date):
    r = read_sta(write(tmp_path, "v1.sta", S.sta_v1_text(split_date=split_date)))
    assert r.version == "V1" and r.instrument == "windcube_v1"
    assert r.scan_angle == 30.0 and r.cone_angle == 30.0 and r.direction_offset == 12.5
    assert r.beam_azimuths == (0.0, 90.0, 180.0, 270.0)  # no vertical beam on V1
    np.testing.assert_array_equal(r.heights, S.V1_HEIGHTS)
    # day-first stamps in UTC+1 -> UTC: one hour earlier
    np.testing.assert_array_equal(r.time_local[:2], np.array(
        ["2012-09-01T00:10", "2012-09-01T00:20"], dtype="datetime64[s]"))
    np.testing.assert_array_equal(r.time[:2], np.array(
        ["2012-08-31T23:10", "2012-08-31T23:20"], dtype="datetime64[s]"))
    assert r.utc_offset_hours == 1.0
    for i in range(4):
        for j in range(3):
            v = S.v1_values(i, j)
            assert r.speed[i, j] == v[0] and r.speed_std[i, j] == v[1]
            assert r.speed_max[i, j] == v[2] and r.speed_min[i, j] == v[3]
            assert r.direction[i, j] == v[4] and r.cnr[i, j] == v[9]
            assert r.availability[i, j] == v[11]
            assert r.w[i, j] == -v[7] and r.z_wind[i, j] == v[7]
            assert r.extra["um"][i, j] == v[5] and r.extra["vm"][i, j] == v[6]
    assert r.missing == ("cnr_min", "spectral_broadening")
    assert set(r.scalars) == {"Wiper", "Vbatt", "Tint"}
    assert np.all(r.flags == 0) and r.valid.all()


def test_windcube_v21_one_minute_sta(tmp_path):
    r = read_sta(write(tmp_path, "m.sta", S.sta_v2_text(n=30, step_min=1, timezone="UTC+2")))
    assert r.period == np.timedelta64(60, "s") and r.time.size == 30
    assert r.time[0] == np.datetime64("2020-10-06T22:01:00")  # 00:01 at UTC+2
    assert r.cone_angle == 28.0 and np.isnan(r.scan_angle)  # header NA -> nominal V2 cone
    assert r.cnr_threshold == -24.0 and r.pitch == 0.08 and r.roll == -0.819
    # availability 100 - i: rows 21.. fall below the 80 % minimum and are not used
    assert np.all(r.flags[:21] == 0)
    assert np.all(r.flags[21:] == int(RecordFlag.LOW_AVAILABILITY))
    assert np.isnan(r.speed[21:]).all() and np.isfinite(r.availability[21:]).all()
    assert np.isfinite(read_sta(r.path, min_availability=0).speed).all()


def test_rtd_utc_cnr_threshold_availability(tmp_path):
    rec = read_rtd(write(tmp_path, "c.rtd", S.rtd_v2_text(n_cycles=3)))
    assert rec.utc_offset_hours == -3.0 and rec.timezone == "UTC--3"
    assert rec.time[0] == np.datetime64("2024-08-03T02:59:50.000")  # 23:59:50 at UTC-3
    assert rec.cnr_threshold == -23.0 and rec.cone_angle == 28.0
    assert rec.pitch == 0.379 and rec.roll == 0.262
    g = group_rtd(rec, min_availability=0)
    # 15 lines of sight from 02:59:50 UTC: two intervals, both partial
    np.testing.assert_array_equal(g.time, np.array(["2024-08-03T03:00", "2024-08-03T03:10"],
                                                   dtype="datetime64[ms]"))
    assert g.partial.all() and g.cycle == np.timedelta64(4000, "ms")
    # vertical beam at -30 dB < -23 dB: not used, flagged
    assert np.isnan(g.los[:, :, 4]).all() and g.n_samples[1, 4] == 0  # no V after 00:00
    assert np.all(g.flags[0, :, 4] & int(RecordFlag.BELOW_CNR_THRESHOLD))
    np.testing.assert_allclose(g.los[0, 0, :4], [0.5, -3.4, -0.5, 3.4])  # los = -rws
    # the threshold can be overridden (or switched off)
    h = group_rtd(rec, cnr_threshold=None, min_availability=0)
    np.testing.assert_allclose(h.los[0, :, 4], [-0.1, -0.2])
    assert group_rtd(rec, cnr_threshold=-40.0, min_availability=0).count[0, 0, 4] > 0
    # default minimum availability: a few seconds of data are not a 10-minute record
    d = group_rtd(rec)
    assert np.isnan(d.los).all() and np.all(d.flags & int(RecordFlag.LOW_AVAILABILITY))
    assert np.all(d.availability[:, :, :4] < 5)


def test_rtd_instrument_reconstruction_synthetic(tmp_path):
    rec = read_rtd(write(tmp_path, "c.rtd", S.rtd_v2_text(n_cycles=2)))
    out = instrument_reconstruction(rec)
    s2 = 2 * np.sin(np.radians(28.0))
    # order V, 0, 90, 180, 270: X needs 0 and 180 (row 3), Y needs 90 and 270 (row 4)
    assert np.isnan(out.x_wind[:3]).all() and np.isnan(out.y_wind[:4]).all()
    np.testing.assert_allclose(out.x_wind[3:, 0], (-0.5 - 0.5) / s2)
    np.testing.assert_allclose(out.y_wind[4:, 0], (3.4 + 3.4) / s2)
    np.testing.assert_allclose(out.z_wind[:, 0], 0.1)
    np.testing.assert_allclose(out.w[:, 0], -0.1)
    np.testing.assert_allclose(out.speed[4:, 0], np.hypot(1.0, 6.8) / s2)
    np.testing.assert_allclose(out.direction[4:, 0],
                               np.degrees(np.arctan2(6.8, -1.0)) % 360)
    with pytest.raises(ValueError, match=r"cone_angle must be in \(0, 90\)"):
        instrument_reconstruction(rec, cone_angle=0.0)


def test_zephir_300_start_stamped_utc_plus_one(tmp_path):
    r = read_zephir_csv(write(tmp_path, "z.csv", S.zephir_300_text()))
    assert r.instrument == "zephir" and r.model == "zephir_300"
    assert (r.delimiter, r.decimal) == (";", ",")
    assert r.time_convention == "start" and r.utc_offset_hours == 1.0
    assert r.period == np.timedelta64(600, "s")
    # stamp 01/09/2021 00:00 local = start of (00:00, 00:10] at UTC+1 -> end 23:10 UTC
    assert r.time_local[0] == np.datetime64("2021-09-01T00:00:00")
    assert r.time[0] == np.datetime64("2021-08-31T23:10:00")
    np.testing.assert_array_equal(np.diff(r.time), np.timedelta64(600, "s"))
    np.testing.assert_array_equal(r.heights, [38.0, 100.0])
    for i in range(5):
        v = S.zephir_values(i)
        np.testing.assert_array_equal(r.speed[i], [v[0], v[3]])
        np.testing.assert_array_equal(r.direction[i], [v[1], v[4]])
        np.testing.assert_array_equal(r.w[i], [v[2], v[5]])
    assert np.all(r.flags == 0) and r.valid.all()
    # overrides: an end-stamped UTC export
    e = read_zephir_csv(r.path, time_convention="end", utc_offset_hours=0.0)
    assert e.time[0] == np.datetime64("2021-09-01T00:00:00")


def test_zx_comma_zone_in_time_column(tmp_path):
    r = read_zephir_csv(write(tmp_path, "zx.csv", S.zx_text()))
    assert r.model == "zx" and (r.delimiter, r.decimal) == (",", ".")
    assert r.utc_offset_hours == -5.0 and r.time_convention == "start"
    assert r.period == np.timedelta64(600, "s")  # 'Averaging period (s),600'
    assert r.time[0] == np.datetime64("2022-03-04T15:10:00")  # 10:00 at UTC-5, + 10 min
    np.testing.assert_array_equal(r.speed[:, 0], [7.0, 8.0, 9.0, 10.0, 11.0])


def test_zephir_end_of_period_preamble(tmp_path):
    text = S.zephir_300_text().replace("Start of averaging period", "End of averaging period")
    r = read_zephir_csv(write(tmp_path, "e.csv", text))
    assert r.time_convention == "end" and r.time[0] == np.datetime64("2021-08-31T23:00:00")


def test_zephir_without_zone_is_utc_with_a_note(tmp_path):
    r = read_zephir_csv(write(tmp_path, "n.csv", S.zephir_300_text(zone_line="Site id;7")))
    assert r.utc_offset_hours == 0.0 and any("times taken as UTC" in w for w in r.warnings)
    assert r.time[0] == np.datetime64("2021-09-01T00:10:00")


def test_large_sta_reads_fast_and_every_row(tmp_path):
    """A month of 10-minute rows at 12 heights (the year benchmark is benchmarks/read_records)."""
    import time

    from lidarjax.io import write_sta

    n, k = 4320, 12
    t = np.datetime64("2023-01-01T00:10") + np.arange(n) * np.timedelta64(10, "m")
    speed = 5 + (np.arange(n * k) % 97).reshape(n, k) / 10
    path = write_sta(tmp_path / "month.sta", t, 40 + 20 * np.arange(k), speed,
                     np.full((n, k), 200.0), availability=np.full((n, k), 100.0))
    t0 = time.perf_counter()
    r = read_sta(path)
    elapsed = time.perf_counter() - t0
    assert r.time.size == n and np.abs(r.speed - speed).max() < 1e-4
    assert elapsed < 5.0  # about 0.1 s on an idle core; generous for a loaded CI machine


def test_rtd_los_id_column(tmp_path):
    text = S.rtd_v2_text(n_cycles=1).replace("\tPosition\t", "\tLOS ID\t")
    for pos, los_id in (("\tV\t", "\t4\t"), ("\t90\t", "\t1\t"), ("\t180\t", "\t2\t"),
                        ("\t270\t", "\t3\t")):
        text = text.replace(pos, los_id)
    rec = read_rtd(write(tmp_path, "id.rtd", text))
    np.testing.assert_array_equal(rec.vertical, [True, False, False, False, False])
    np.testing.assert_array_equal(rec.position[1:], [0.0, 90.0, 180.0, 270.0])


def test_without_pandas_same_values(tmp_path, monkeypatch):
    """pandas is only an optional fast path: the numpy path reads the same numbers."""
    path = write(tmp_path, "p.sta", S.sta_v2_text(n=8))
    with_pandas = read_sta(path)
    monkeypatch.setitem(sys.modules, "pandas", None)
    without = read_sta(path)
    for name in ("speed", "direction", "w", "cnr", "availability"):
        np.testing.assert_array_equal(getattr(with_pandas, name), getattr(without, name))
    np.testing.assert_array_equal(with_pandas.time, without.time)


def test_v1_separate_date_and_time_columns(tmp_path):
    text = S.sta_v1_text(split_date=True).replace("Date\tWiper", "Date\tTime\tWiper")
    r = read_sta(write(tmp_path, "dt.sta", text))
    assert r.time_local[1] == np.datetime64("2012-09-01T00:20:00") and r.speed[1, 0] == 7.0
    assert "Time" not in r.scalars and np.all(r.flags == 0)
