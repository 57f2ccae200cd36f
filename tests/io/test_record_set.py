"""`to_record_set()` of each reader's result: the common `RecordSet` built from the reader's
own fields (the sample files of `record_samples`), and `load_records` returning it."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import lidarjax as lj
from lidarjax.flags import BLOCKING_FLAGS, RecordFlag
from lidarjax.io import RecordSet, group_rtd, read_rtd, read_sta, read_zephir_csv
from lidarjax.workflows.records import load_records

from . import record_samples as S


def write(tmp_path, name, text):
    path = tmp_path / name
    path.write_bytes(text.encode("cp1252"))
    return path


def same(a: RecordSet, b: RecordSet) -> None:
    """Every field equal (NaN equal to NaN)."""
    for name in RecordSet.__dataclass_fields__:
        x, y = getattr(a, name), getattr(b, name)
        if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            assert x is not None and y is not None, name
            np.testing.assert_array_equal(x, y, err_msg=name)
        elif isinstance(x, float):
            assert x == y or (np.isnan(x) and np.isnan(y)), name
        else:
            assert x == y, name


def test_record_set_is_exported_from_io_and_the_workflow():
    from lidarjax.workflows import records

    assert lj.io.RecordSet is RecordSet is records.RecordSet


def test_sta_v2(tmp_path):
    path = write(tmp_path, "m.sta", S.sta_v2_text(n=30, step_min=1, timezone="UTC+2"))
    rec = read_sta(path)
    rs = rec.to_record_set()
    assert isinstance(rs, RecordSet)
    assert (rs.kind, rs.path, rs.instrument) == ("sta", str(path), "windcube_v2")
    np.testing.assert_array_equal(rs.time, rec.time)
    assert rs.time.dtype == np.dtype("datetime64[s]")
    np.testing.assert_array_equal(rs.heights, S.V2_HEIGHTS)
    assert rs.period_s == 60.0
    # header facts: ScanAngle=NA, DirectionOffset=-37, tilt, CNRThreshold=-24
    assert np.isnan(rs.scan_angle) and rs.direction_offset == -37.0
    assert (rs.pitch, rs.roll, rs.cnr_threshold) == (0.08, -0.819, -24.0)
    for i in (0, 5, 20):
        for j in range(2):
            speed, std, direction, _, _, avail = S.sta_values(i, j)
            assert rs.speed[i, j] == speed and rs.speed_std[i, j] == std
            assert rs.direction[i, j] == direction and rs.availability[i, j] == avail
    # availability 100 - i: rows 21.. below the 80 % minimum, flagged and NaN
    assert rs.flags.dtype == np.int64 and rs.flags.shape == (30, 2)
    assert np.all(rs.flags[:21] == 0)
    assert np.all(rs.flags[21:] == int(RecordFlag.LOW_AVAILABILITY))
    assert np.isnan(rs.speed[21:]).all() and np.isnan(rs.direction[21:]).all()
    assert rs.los is None and rs.n_samples is None and rs.direction_std is None
    assert rs.warnings == rec.warnings


def test_sta_v1(tmp_path):
    rs = read_sta(write(tmp_path, "v1.sta", S.sta_v1_text())).to_record_set()
    assert (rs.kind, rs.instrument) == ("sta", "windcube_v1")
    assert (rs.scan_angle, rs.direction_offset) == (30.0, 12.5)
    assert np.isnan(rs.pitch) and np.isnan(rs.roll) and np.isnan(rs.cnr_threshold)
    assert rs.period_s == 600.0
    v = S.v1_values(2, 1)
    assert rs.speed[2, 1] == v[0] and rs.speed_std[2, 1] == v[1] and rs.direction[2, 1] == v[4]
    assert np.all(rs.flags == 0)


def test_sta_direction_dispersion_and_impossible_values(tmp_path):
    time = np.arange(np.datetime64("2021-01-01T00:10"), np.datetime64("2021-01-01T01:10"),
                     np.timedelta64(10, "m"))
    speed = np.full((6, 2), 8.0)
    direction = np.full((6, 2), 270.0)
    direction[2, 1] = 400.0  # impossible: flagged by the reader, NaN in the set
    path = lj.io.write_sta(tmp_path / "w.sta", time, [40, 60], speed, direction,
                           speed_std=np.full((6, 2), 0.5), availability=np.full((6, 2), 95.0),
                           scan_angle=28.0, direction_offset=5.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rs = read_sta(path).to_record_set()
    assert (rs.scan_angle, rs.direction_offset) == (28.0, 5.0)
    assert rs.flags[2, 1] & int(RecordFlag.IMPOSSIBLE_VALUE)
    assert np.isnan(rs.direction[2, 1]) and np.isnan(rs.speed[2, 1])
    assert np.isfinite(np.delete(rs.speed.ravel(), 5)).all()
    assert any("impossible" in w for w in rs.warnings)


def test_rtd_beams(tmp_path):
    path = write(tmp_path, "c.rtd", S.rtd_v2_text(n_cycles=3))
    rec = read_rtd(path)
    beams = group_rtd(rec, min_availability=0)
    rs = beams.to_record_set()
    assert (rs.kind, rs.path, rs.instrument) == ("rtd", str(path), "windcube_v2")
    np.testing.assert_array_equal(rs.time, np.array(["2024-08-03T03:00", "2024-08-03T03:10"],
                                                    dtype="datetime64[s]"))
    assert rs.los.shape == (2, 2, 5)
    np.testing.assert_allclose(rs.los[0, 0, :4], [0.5, -3.4, -0.5, 3.4])  # los = -rws
    assert np.isnan(rs.los[:, :, 4]).all()  # vertical beam below the CNR threshold
    # flags: every beam's bits OR-ed; both intervals partial; V below the threshold
    assert np.all(rs.flags & int(RecordFlag.PARTIAL_INTERVAL))
    assert np.all(rs.flags[0] & int(RecordFlag.BELOW_CNR_THRESHOLD))
    # availability: the worst tilted beam's
    np.testing.assert_array_equal(rs.availability, np.min(beams.availability[..., :4], axis=-1))
    assert rs.cnr_threshold == -23.0 and rs.period_s == 600.0
    assert np.isnan(rs.scan_angle) and rs.direction_offset == 0.0
    assert (rs.pitch, rs.roll) == (0.379, 0.262)
    assert rs.speed is None and rs.direction is None and rs.speed_std is None
    assert rs.warnings == rec.warnings


def test_rtd_record_groups_then_converts(tmp_path):
    rec = read_rtd(write(tmp_path, "c.rtd", S.rtd_v2_text(n_cycles=30)))
    same(rec.to_record_set("1min", cnr_threshold=-40.0, min_availability=0),
         group_rtd(rec, "1min", cnr_threshold=-40.0, min_availability=0).to_record_set())
    rs = rec.to_record_set("1min", cnr_threshold=-40.0, min_availability=0)
    assert rs.cnr_threshold == -40.0 and rs.period_s == 60.0
    assert np.isfinite(rs.los[..., 4]).any()  # the vertical beam passes -40 dB
    # default: header threshold and 80 % minimum: seconds of data are not a record
    d = rec.to_record_set()
    assert np.isnan(d.los).all() and np.all(d.flags & int(RecordFlag.LOW_AVAILABILITY))


@pytest.mark.parametrize("kind", ["zephir_300", "zx"])
def test_zephir(tmp_path, kind):
    text = S.zephir_300_text() if kind == "zephir_300" else S.zx_text()
    path = write(tmp_path, "z.csv", text)
    rec = read_zephir_csv(path)
    rs = rec.to_record_set()
    assert (rs.kind, rs.path, rs.instrument) == ("zephir", str(path), "zephir")
    np.testing.assert_array_equal(rs.time, rec.time)
    np.testing.assert_array_equal(rs.heights, [38.0, 100.0])
    assert rs.period_s == 600.0
    for i in range(5):
        v = S.zephir_values(i)
        assert (rs.speed[i, 0], rs.direction[i, 0]) == (v[0], v[1])
        assert (rs.speed[i, 1], rs.direction[i, 1]) == (v[3], v[4])
    # "Packets in Average at 38m": the number of scans averaged
    assert rs.n_samples[0, 0] == 60.0 and np.isnan(rs.n_samples[0, 1])
    assert rs.speed_std is None and rs.availability is None and rs.direction_std is None
    for name in ("scan_angle", "direction_offset", "pitch", "roll", "cnr_threshold"):
        assert np.isnan(getattr(rs, name))
    assert np.all(rs.flags == 0)


def test_zephir_ti_availability_and_direction_std(tmp_path):
    lines = S.zx_text().splitlines()
    lines[2] += ",TI at 38m,Data Availability at 38m,Wind Direction Std at 100m"
    for r in range(3, len(lines)):
        lines[r] += f",{0.1 + 0.01 * r},{70 + 5 * r},{3.0 + r}"
    rec = read_zephir_csv(write(tmp_path, "z.csv", "\n".join(lines) + "\n"))
    rs = rec.to_record_set()
    # TI as a fraction: speed_std = TI * speed (before the availability NaN)
    ti = 0.1 + 0.01 * np.arange(3, 8)
    np.testing.assert_allclose(rs.speed_std[:, 0], ti * np.asarray(rec.speed[:, 0]))
    np.testing.assert_array_equal(rs.direction_std[:, 1], 3.0 + np.arange(3, 8))
    avail = 70 + 5 * np.arange(3, 8)
    np.testing.assert_array_equal(rs.availability[:, 0], avail)
    low = avail < 80
    assert np.all(rs.flags[low, 0] == int(RecordFlag.LOW_AVAILABILITY))
    assert np.isnan(rs.speed[low, 0]).all() and np.isfinite(rs.speed[~low, 0]).all()
    # the minimum is an argument of the conversion
    assert np.all(rec.to_record_set(min_availability=0.0).flags == 0)
    # TI in percent
    lines = S.zx_text().splitlines()
    lines[2] += ",TI at 38m"
    for r in range(3, len(lines)):
        lines[r] += ",12.5"
    rec = read_zephir_csv(write(tmp_path, "p.csv", "\n".join(lines) + "\n"))
    np.testing.assert_allclose(rec.to_record_set().speed_std[:, 0], 0.125 * rec.speed[:, 0])


def test_blocked_reported_values_are_nan(tmp_path):
    lines = S.zx_text().splitlines()
    lines[2] += ",Data Availability at 100m"
    for r in range(3, len(lines)):
        lines[r] += f",{60 + 10 * (r - 3)}"
    sets = [read_sta(write(tmp_path, "a.sta", S.sta_v2_text(n=30))).to_record_set(),
            read_zephir_csv(write(tmp_path, "c.csv", "\n".join(lines) + "\n")).to_record_set()]
    for rs in sets:
        blocked = (rs.flags & int(BLOCKING_FLAGS)) != 0
        assert blocked.any() and (~blocked).any()
        assert np.isnan(rs.speed[blocked]).all() and np.isnan(rs.direction[blocked]).all()
        assert np.isfinite(rs.speed[~blocked]).all()


@pytest.mark.parametrize("name, text, kw", [
    ("a.sta", S.sta_v2_text(n=30), {}),
    ("b.stdsta", S.sta_v1_text(), {}),
    ("c.rtd", S.rtd_v2_text(n_cycles=30), dict(period="1min", min_availability=0)),
    ("d.csv", S.zephir_300_text(), dict(min_availability=50.0)),
])
def test_load_records_is_read_then_to_record_set(tmp_path, name, text, kw):
    path = write(tmp_path, name, text)
    got = load_records(path, **kw)
    if name.endswith(".rtd"):
        want = read_rtd(path).to_record_set("1min", min_availability=0)
    elif name.endswith(".csv"):
        want = read_zephir_csv(path).to_record_set(min_availability=50.0)
    else:
        want = read_sta(path).to_record_set()
    same(got, want)


def test_a_table_that_knows_its_instrument_refuses_another(tmp_path):
    """A V1 record file (ScanAngle 30, DirectionOffset 12.5) against tables whose own
    `lidarjax.Instrument` says otherwise: every mismatch is named, with no file metadata."""
    import lidarjax as lj
    from lidarjax.response import Instrument
    from lidarjax.workflows.records import check_instrument, load_records

    path = tmp_path / "v1.sta"
    path.write_text(S.sta_v1_text())
    rec = load_records(path)
    d = np.array([0.0, 120.0, 240.0])
    resp = np.ones((3, len(rec.heights), 4))
    same = lj.ResponseTable(d, resp, instrument=Instrument(
        scan="windcube_v1", cone_angle_deg=30.0, n_beams=4, epsilon_deg=12.5))
    assert check_instrument({}, same, rec) == []
    other = lj.ResponseTable(d, resp, instrument=Instrument(
        scan="windcube_v1", cone_angle_deg=15.0, n_beams=4, epsilon_deg=40.0))
    bad = check_instrument({}, other, rec)
    assert any("cone angle: table 15 deg, record header ScanAngle=30 deg" in b for b in bad)
    assert any("direction offset" in b for b in bad)
    # explicit file metadata still wins over the table's own facts
    assert not any("cone angle" in b for b in check_instrument({"cone_angle_deg": 30.0}, other, rec))
