"""Windcube .rtd reader: sign flip, beam positions, 10-minute grouping per beam."""

import numpy as np
import pytest

from lidarjax.io import BEAM_AZIMUTHS, group_rtd, read_rtd

HEADER = [
    "Version=WF 2.1.6",
    "ID System=WLS71072",
    "ScanAngle (\u00b0)=28",
    "DirectionOffset (\u00b0)=-37",
    "Altitudes (m)=\t40\t60",
    "********************",
]
COLUMNS = ["Timestamp", "Position", "Temperature (\u00b0C)", "Wiper"]
for _alt in (40, 60):
    COLUMNS += [f"{_alt}m CNR (dB)", f"{_alt}m Radial Wind Speed (m/s)",
                f"{_alt}m Radial Wind Speed Dispersion (m/s)", f"{_alt}m Wind Speed (m/s)"]


def row(stamp, position, rws40, rws60, cnr40=-10.0, cnr60=-12.0):
    return "\t".join([stamp, position, "21.0", "Off",
                      f"{cnr40}", f"{rws40}", "0.1", "8.0",
                      f"{cnr60}", f"{rws60}", "0.2", "9.0", ""])


# Two 10-minute intervals. Interval (00:00, 00:10]: beam 0 twice (the second stamped exactly
# 00:10:00.000), 90, 180, 270 once, V once. Interval (00:10, 00:20]: 0, 90, 180, V, and no
# 270 sample; one beam-0 sample at 60 m is NaN, one beam-90 sample has a low CNR.
ROWS = [
    row("2013/09/25 00:09:55.12", "0", 1.0, 2.0),
    row("2013/09/25 00:09:56.10", "90", -3.0, -4.0),
    row("2013/09/25 00:09:57.09", "180", 5.0, 6.0),
    row("2013/09/25 00:09:58.11", "270", -7.0, -8.0),
    row("2013/09/25 00:09:59.20", "V", 0.5, 0.25),
    row("2013/09/25 00:10:00.000", "0", 3.0, 4.0),
    row("2013/09/25 00:10:01.50", "0", 10.0, "NaN"),
    row("2013/09/25 00:10:02.50", "90", 2.0, 2.0),
    row("2013/09/25 00:10:03.50", "90", 4.0, 4.0, cnr40=-30.0),
    row("2013/09/25 00:10:04.50", "180", -1.0, -1.0),
    row("2013/09/25 00:10:05.50", "v", -0.5, -0.5),
]


def rtd_text(rows=ROWS, columns=COLUMNS, header=HEADER):
    return "\n".join([f"HeaderSize={len(header)}", *header, "\t".join(columns), *rows]) + "\n"


def write(tmp_path, text, name="wls7.rtd"):
    path = tmp_path / name
    path.write_bytes(text.encode("cp1252"))
    return path


def test_read_rtd_sign_flip_and_positions(tmp_path):
    r = read_rtd(write(tmp_path, rtd_text()))
    assert r.version == "V2" and r.scan_angle == 28.0 and r.direction_offset == -37.0
    assert r.time.dtype == np.dtype("datetime64[ms]") and r.time.shape == (11,)
    assert r.time[0] == np.datetime64("2013-09-25T00:09:55.120")
    assert r.time[5] == np.datetime64("2013-09-25T00:10:00.000")
    np.testing.assert_array_equal(r.heights, [40.0, 60.0])
    # Windcube RWS is positive towards the lidar; lidarjax's los is positive away from it.
    np.testing.assert_array_equal(r.rws[:2], [[1.0, 2.0], [-3.0, -4.0]])
    np.testing.assert_array_equal(r.los[:2], [[-1.0, -2.0], [3.0, 4.0]])
    np.testing.assert_array_equal(r.los, -r.rws)
    assert np.isnan(r.los[6, 1])
    np.testing.assert_array_equal(r.vertical, [0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 1])
    np.testing.assert_array_equal(r.position[:4], [0.0, 90.0, 180.0, 270.0])
    assert np.isnan(r.position[4]) and np.isnan(r.position[10])
    np.testing.assert_array_equal(r.cnr[8], [-30.0, -12.0])
    np.testing.assert_array_equal(r.rws_std[0], [0.1, 0.2])
    assert r.missing == ()
    np.testing.assert_array_equal(r.extra["windspeed"][0], [8.0, 9.0])
    assert r.scalars["Temperature (\u00b0C)"][0] == 21.0
    assert "Position" not in r.scalars


def test_group_rtd_ten_minutes(tmp_path):
    r = read_rtd(write(tmp_path, rtd_text()))
    g = group_rtd(r, min_availability=0)  # a few samples only: keep every mean
    assert g.los.shape == (2, 2, 5) and g.count.shape == (2, 2, 5)
    np.testing.assert_array_equal(
        g.time, np.array(["2013-09-25T00:10:00", "2013-09-25T00:20:00"], dtype="datetime64[ms]"))
    assert g.period == np.timedelta64(600_000, "ms")
    np.testing.assert_array_equal(g.azimuths[:4], [0.0, 90.0, 180.0, 270.0])
    assert np.isnan(g.azimuths[4]) and len(BEAM_AZIMUTHS) == 5
    # first interval, 40 m: beam 0 = mean(-1, -3) (the 00:10:00.000 sample belongs here)
    np.testing.assert_array_equal(g.los[0, 0], [-2.0, 3.0, -5.0, 7.0, -0.5])
    np.testing.assert_array_equal(g.los[0, 1], [-3.0, 4.0, -6.0, 8.0, -0.25])
    np.testing.assert_array_equal(g.count[0, 0], [2, 1, 1, 1, 1])
    # second interval: no 270 sample -> NaN, count 0; NaN sample skipped at 60 m
    np.testing.assert_array_equal(g.los[1, 0], [-10.0, -3.0, 1.0, np.nan, 0.5])
    np.testing.assert_array_equal(g.los[1, 1], [np.nan, -3.0, 1.0, np.nan, 0.5])
    np.testing.assert_array_equal(g.count[1, 0], [1, 2, 1, 0, 1])
    np.testing.assert_array_equal(g.count[1, 1], [0, 2, 1, 0, 1])
    np.testing.assert_array_equal(g.cnr[1, 0, :2], [-10.0, -20.0])
    # the method form is the same
    np.testing.assert_array_equal(r.to_beams("600s", min_availability=0).los, g.los, strict=True)


def test_group_rtd_cnr_threshold_and_period(tmp_path):
    r = read_rtd(write(tmp_path, rtd_text()))
    g = group_rtd(r, min_cnr=-22.0, min_availability=0)
    np.testing.assert_array_equal(g.los[1, 0, 1], -2.0)  # the -30 dB sample is dropped
    assert g.count[1, 0, 1] == 1 and g.count[1, 1, 1] == 2
    h = group_rtd(r, period=np.timedelta64(1, "h"))
    assert h.time.shape == (1,) and h.time[0] == np.datetime64("2013-09-25T01:00")
    np.testing.assert_array_equal(h.count[0, 0], [3, 3, 2, 1, 2])
    one_second = group_rtd(r, period="1s")
    # 00:09:59.20 and 00:10:00.000 both fall in the second ending 00:10:00
    assert one_second.time.shape == (10,)
    np.testing.assert_array_equal(one_second.count[4, 0], [1, 0, 0, 0, 1])
    with pytest.raises(ValueError, match="period 'ten minutes' not understood"):
        group_rtd(r, period="ten minutes")
    with pytest.raises(ValueError, match="period must be positive"):
        group_rtd(r, period="0min")


def test_group_rtd_unknown_azimuth(tmp_path):
    rows = [*ROWS[:2], row("2013/09/25 00:09:56.50", "45", 1.0, 1.0),
            row("2013/09/25 00:09:57.50", "359.5", 1.0, 1.0)]
    r = read_rtd(write(tmp_path, rtd_text(rows)))
    with pytest.raises(ValueError, match=r"beam positions 45 are not 0/90/180/270 \(within 1"):
        group_rtd(r)
    with pytest.raises(ValueError, match=r"tolerance_deg must be in \[0, 45\)"):
        group_rtd(r, tolerance_deg=45.0)
    rows = [*ROWS[:2], row("2013/09/25 00:09:57.50", "359.5", 1.0, 1.0)]
    g = group_rtd(read_rtd(write(tmp_path, rtd_text(rows))), min_availability=0)  # 359.5 is beam 0, modulo 360
    assert g.count[0, 0, 0] == 2 and g.los[0, 0, 0] == -1.0


def test_to_pandas(tmp_path):
    import pandas  # noqa: F401  (the test extra brings it)
    df = read_rtd(write(tmp_path, rtd_text())).to_pandas()
    assert df.shape == (22, 8)
    assert list(df.columns) == ["time", "position", "vertical", "height", "los", "rws", "rws_std",
                                "cnr"]
    assert df["los"].iloc[0] == -1.0 and df["height"].iloc[1] == 60.0
    assert bool(df["vertical"].iloc[8])


def test_errors(tmp_path):
    bad_position = [*ROWS[:3], row("2013/09/25 00:09:58.11", "NE", 1.0, 1.0)]
    path = write(tmp_path, rtd_text(bad_position))
    with pytest.warns(UserWarning, match=rf"^{path}: 1 corrupt row\(s\) at line\(s\) 12 .*"
                                         "column 'Position': expected a beam azimuth"):
        r = read_rtd(path)
    assert r.time.shape == (3,) and r.dropped_lines == (12,)
    cols = [c for c in COLUMNS if "Radial Wind Speed (m/s)" not in c]
    rows = ["\t".join(["2013/09/25 00:09:55", "0", "1", "Off", "1", "2", "3", "4", "5", "6"])]
    path = write(tmp_path, rtd_text(rows, cols))
    with pytest.raises(ValueError, match="line 8: no '<altitude>m Radial Wind Speed"):
        read_rtd(path)
    cols = [c if c != "Position" else "Beam" for c in COLUMNS]
    path = write(tmp_path, rtd_text(ROWS[:1], cols))
    with pytest.raises(ValueError, match=r"line 8: no 'Position' column"):
        read_rtd(path)
    path = write(tmp_path, rtd_text([ROWS[0].replace("2013/09/25 00:09:55.12", "25-09-2013")]))
    with pytest.warns(UserWarning, match="line\\(s\\) 9 .*unreadable time stamp '25-09-2013"):
        assert read_rtd(path).time.shape == (0,)
    with pytest.raises(FileNotFoundError, match="rtd file not found"):
        read_rtd(tmp_path / "missing.rtd")


def test_cnr_missing_is_listed(tmp_path):
    cols = ["Timestamp", "Position", "40m Radial Wind Speed (m/s)"]
    rows = ["2013/09/25 00:09:55\tV\t-0.3"]
    r = read_rtd(write(tmp_path, rtd_text(rows, cols, ["Altitudes (m)=\t40"])))
    assert r.missing == ("rws_std", "cnr") and np.isnan(r.cnr).all()
    assert r.los[0, 0] == 0.3 and r.vertical[0] and np.isnan(r.scan_angle)
