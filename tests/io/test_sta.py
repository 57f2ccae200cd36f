"""Windcube .sta reader: the two real V2 files in shared/, a V1 fixture, and error paths."""

import sys
from pathlib import Path

import numpy as np
import pytest

from lidarjax.io import STA_FIELDS, read_sta

from ..helpers import windcube_file


def real_file(name: str) -> Path:
    return windcube_file(name)


DAY1 = "wls7_abc_2020_10_07__00_10_00.sta"
DAY2 = "wls7_abc_2020_10_08__00_10_00.sta"


def test_real_file_2020_10_07():
    r = read_sta(real_file(DAY1))
    assert r.version == "V2"
    assert r.time.dtype == np.dtype("datetime64[s]") and r.time.shape == (144,)
    assert r.time[0] == np.datetime64("2020-10-07T00:10:00")
    assert r.time[-1] == np.datetime64("2020-10-08T00:00:00")
    assert np.all(np.diff(r.time) == np.timedelta64(600, "s"))
    np.testing.assert_array_equal(
        r.heights, [40, 54, 74, 84, 94, 110, 115, 134, 154, 174, 194, 220])
    assert r.direction_offset == -37.0
    assert np.isnan(r.scan_angle)
    assert r.missing == () and r.extra == {}
    for name in STA_FIELDS:
        assert getattr(r, name).shape == (144, 12)
    # first row, read by eye from the file
    assert r.speed[0, 0] == 5.67 and r.speed_std[0, 0] == 0.49
    assert r.speed_min[0, 0] == 4.26 and r.speed_max[0, 0] == 7.01
    assert r.direction[0, 0] == 207.74 and r.w[0, 0] == 0.0 and r.w_std[0, 0] == 0.24
    assert r.z_wind[0, 1] == 0.02 and r.w[0, 1] == -0.02  # Z-wind is positive down
    assert r.cnr[0, 0] == -10.94 and r.cnr_min[0, 0] == -11.79
    assert r.spectral_broadening[0, 0] == 0.05 and r.availability[0, 0] == 100.0
    assert r.speed[0, 1] == 6.38 and r.direction[0, 2] == 212.03
    assert r.speed[0, -1] == 10.59 and r.cnr[0, -1] == -4.48  # 220 m
    assert r.speed_max[1, 0] == 8.89  # second row
    assert r.speed[-1, -1] == 14.05 and r.direction[-1, -1] == 236.77  # last row, 220 m
    assert r.header["ID System"] == "WLS71072"
    assert r.header["GPS Location"] == "Lat:53.502127\u00b0N, Long:8.578038\u00b0E"  # cp1252
    assert r.scalars["Int Temp (\u00b0C)"][0] == 11.9
    assert np.all(np.isnan(r.scalars["Vbatt (V)"]))  # the file's only NaN column
    assert r.scalars["Wiper count"][-1] == 1.0
    # CNR above 0 dB at the top gates (cloud/fog): advisory flag, the wind is kept
    assert np.all(r.valid[r.availability >= 80])
    assert r.instrument == "windcube_v2" and r.cone_angle == 28.0 and r.cnr_threshold == -24
    assert r.pitch == 0.08 and r.roll == -0.819 and r.utc_offset_hours == 0.0
    assert r.period == np.timedelta64(600, "s") and r.time_convention == "end"
    with pytest.raises(ValueError):
        r.speed[0, 0] = 0.0  # read-only


def test_real_file_2020_10_08():
    r = read_sta(real_file(DAY2))
    assert r.time.shape == (54,) and r.speed.shape == (54, 12)
    assert r.time[0] == np.datetime64("2020-10-08T00:10:00")
    assert r.time[-1] == np.datetime64("2020-10-08T09:00:00")
    assert r.speed[0, 0] == 6.28 and r.direction[0, 0] == 218.65


def test_real_file_to_pandas():
    import pandas  # noqa: F401  (the test extra brings it)
    r = read_sta(real_file(DAY1))
    df = r.to_pandas()
    assert df.shape == (144 * 12, 3 + len(STA_FIELDS))
    assert list(df.columns[:3]) == ["time", "height", "speed"]
    assert df["speed"].iloc[0] == 5.67 and df["height"].iloc[11] == 220.0
    assert df["time"].iloc[12] == np.datetime64("2020-10-07T00:20:00")


def test_to_pandas_needs_pandas(tmp_path, monkeypatch):
    path = tmp_path / "v1.sta"
    path.write_bytes(V1_TEXT.encode("cp1252"))
    r = read_sta(path)
    monkeypatch.setitem(sys.modules, "pandas", None)
    with pytest.raises(ImportError, match=r"pip install lidarjax\[pandas\]"):
        r.to_pandas()


# A plausible V1 file: HeaderLength, keys without spaces, a Date column with day-first
# timestamps and seconds, quantity blocks in another order, no 'CNR min' / 'Dopp Spect
# Broad' columns, an X-wind column, altitudes listed in descending order, CRLF endings.
V1_HEADER = [
    "ID System=WLS7-0042",
    "Localisation=Test site",
    "Altitudes(m)=\t100\t60\t40",
    "Scan Angle(\u00b0)=30",
    "DirectionOffset(\u00b0)=12.5",
    "Wind Speed Threshold(m/s)=NA",
]
V1_COLUMNS = ["Date", "Int Temp(\u00b0C)", "Wiper"]
for _alt in (40, 60, 100):
    V1_COLUMNS += [
        f"{_alt}m Wind Direction(\u00b0)",
        f"{_alt}m Wind Speed(m/s)",
        f"{_alt}m Wind Speed Dispersion(m/s)",
        f"{_alt}m Wind Speed Min(m/s)",
        f"{_alt}m Wind Speed Max(m/s)",
        f"{_alt}m X-wind(m/s)",
        f"{_alt}m Z-wind(m/s)",
        f"{_alt}m Z-wind Dispersion(m/s)",
        f"{_alt}m CNR(dB)",
        f"{_alt}m Data Availability(%)",
    ]


def v1_row(stamp, base, nan_at=None):
    values = [stamp, "21.5", "On"]
    for j, _alt in enumerate((40, 60, 100)):
        block = [270 + j, base + j, 0.5, base - 1, base + 2, 1.5 + j, 0.1 * j, 0.2, -20 + j, 99.0]
        values += ["NaN" if (nan_at == j and i == 1) else f"{v}" for i, v in enumerate(block)]
    return "\t".join(values)


V1_ROWS = [
    v1_row("01/09/2012 00:10:00", 5.0),
    v1_row("01/09/2012 00:20:00", 6.0, nan_at=1),
    v1_row("01/09/2012 00:30:00", 7.0),
]
V1_TEXT = "\r\n".join(
    [f"HeaderLength={len(V1_HEADER)}", *V1_HEADER, "\t".join(V1_COLUMNS), *V1_ROWS]) + "\r\n"


def test_v1_fixture(tmp_path):
    path = tmp_path / "wls7_v1.sta"
    path.write_bytes(V1_TEXT.encode("cp1252"))
    r = read_sta(path)
    assert r.version == "V1"
    assert r.scan_angle == 30.0 and r.direction_offset == 12.5
    np.testing.assert_array_equal(r.heights, [40.0, 60.0, 100.0])  # sorted ascending
    np.testing.assert_array_equal(
        r.time, np.array(["2012-09-01T00:10", "2012-09-01T00:20", "2012-09-01T00:30"],
                         dtype="datetime64[s]"))
    np.testing.assert_array_equal(r.speed[0], [5.0, 6.0, 7.0])
    np.testing.assert_array_equal(r.direction[2], [270.0, 271.0, 272.0])
    np.testing.assert_array_equal(r.speed_min[:, 0], [4.0, 5.0, 6.0])
    np.testing.assert_array_equal(r.speed_max[:, 2], [7.0, 8.0, 9.0])
    assert np.isnan(r.speed[1, 1]) and r.speed[1, 0] == 6.0  # NaN stays NaN
    assert not r.valid[1, 1] and r.valid[1, 0]
    np.testing.assert_allclose(r.w[0], [0.0, -0.1, -0.2])  # Z-wind is positive down
    np.testing.assert_allclose(r.z_wind[0], [0.0, 0.1, 0.2])
    np.testing.assert_array_equal(r.cnr[0], [-20.0, -19.0, -18.0])
    assert r.missing == ("cnr_min", "spectral_broadening")
    assert np.all(np.isnan(r.cnr_min)) and np.all(np.isnan(r.spectral_broadening))
    np.testing.assert_array_equal(r.extra["xwind"][0], [1.5, 2.5, 3.5])
    assert r.scalars["Int Temp(\u00b0C)"][0] == 21.5
    assert list(r.scalars["Wiper"]) == ["On", "On", "On"]  # text column kept as text
    assert r.header["Localisation"] == "Test site"


def test_header_size_larger_than_real_header(tmp_path):
    # a header that announces one line too many still finds the column line
    text = V1_TEXT.replace(f"HeaderLength={len(V1_HEADER)}", f"HeaderLength={len(V1_HEADER) + 1}")
    path = tmp_path / "a.sta"
    path.write_bytes(text.encode("cp1252"))
    assert read_sta(path).time.shape == (3,)


def test_header_size_smaller_than_real_header(tmp_path):
    text = V1_TEXT.replace(f"HeaderLength={len(V1_HEADER)}", "HeaderLength=2")
    path = tmp_path / "a.sta"
    path.write_bytes(text.encode("cp1252"))
    r = read_sta(path)
    assert r.scan_angle == 30.0 and r.time.shape == (3,)


def v2_text(rows, columns=None, header=None, stars=True):
    header = header if header is not None else [
        "Version=WF 2.1", "ScanAngle (\u00b0)=28", "DirectionOffset (\u00b0)=0",
        "Altitudes (m)=\t40\t60"]
    if stars:
        header = [*header, "********************"]
    columns = columns if columns is not None else [
        "Timestamp (end of interval)", "40m Wind Speed (m/s)", "40m Wind Direction (\u00b0)",
        "", "60m Wind Speed (m/s)", "60m Wind Direction (\u00b0)", ""]
    lines = [f"HeaderSize={len(header)}", *header, "\t".join(columns), *rows]
    return "\n".join(lines) + "\n"


def write_v2(tmp_path, text, name="x.sta"):
    path = tmp_path / name
    path.write_bytes(text.encode("cp1252"))
    return path


def test_v2_minimal_with_seconds_and_blank_lines(tmp_path):
    rows = ["2021/01/02 03:10:30\t5.5\t10.0\t\t6.5\t20.0\t", "",
            "2021/01/02 03:20\tNaN\t11\t\t7\t21\t"]
    r = read_sta(write_v2(tmp_path, v2_text(rows)))
    assert r.time[0] == np.datetime64("2021-01-02T03:10:30") and r.scan_angle == 28.0
    np.testing.assert_array_equal(r.speed, [[5.5, 6.5], [np.nan, 7.0]])
    assert set(r.missing) == set(STA_FIELDS) - {"speed", "direction"}


def test_no_altitudes_header_uses_columns(tmp_path):
    text = v2_text(["2021/01/02 03:10\t1\t2\t\t3\t4\t"], header=["Version=x"])
    r = read_sta(write_v2(tmp_path, text))
    np.testing.assert_array_equal(r.heights, [40.0, 60.0])
    assert np.isnan(r.scan_angle) and np.isnan(r.direction_offset)


@pytest.mark.parametrize(
    ("text", "line", "fragment"),
    [
        ("Version=1\n", 1, "expected 'HeaderSize=N' (Windcube V2) or 'HeaderLength=N' (V1)"),
        ("HeaderSize=5\nA=1\nB=2\n", 3, "no column-names line"),
        ("HeaderSize=1\nA=1\n", 2, "no column-names line"),
        ("HeaderSize=1\nA=1\n2020/01/01 00:10\t1\n", 3,
         "expected the column-names line starting with 'Timestamp' or 'Date'"),
        (v2_text([], header=["Altitudes (m)=\t40\tsixty"]), 2,
         "'Altitudes (m)': expected altitudes in metres, found '40\\tsixty'"),
    ],
)
def test_errors_name_file_and_line(tmp_path, text, line, fragment):
    path = write_v2(tmp_path, text)
    with pytest.raises(ValueError) as err:
        read_sta(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}, line {line}: "), msg
    assert fragment in msg, msg


def test_column_errors(tmp_path):
    cols = ["Timestamp", "40m Wind Speed (m/s)", "80m Wind Speed (m/s)"]
    path = write_v2(tmp_path, v2_text([], columns=cols))
    with pytest.raises(ValueError, match=r"line 7: column '80m Wind Speed \(m/s\)': altitude 80 m "
                                         r"is not in the header's altitudes 40 60"):
        read_sta(path)
    path = write_v2(tmp_path, v2_text([], columns=["Position", "40m CNR (dB)"]))
    with pytest.raises(ValueError, match="line 7: expected the column-names line starting with "
                                         "'Timestamp' or 'Date', found 'Position"):
        read_sta(path)


def test_bad_header_angle(tmp_path):
    path = write_v2(tmp_path, v2_text([], header=["ScanAngle (\u00b0)=thirty"]))
    with pytest.raises(ValueError, match=r"header 'ScanAngle': expected a number or NA, found "
                                         r"'thirty'"):
        read_sta(path)


def test_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"Windcube \.sta file not found: .*nope\.sta"):
        read_sta(tmp_path / "nope.sta")
