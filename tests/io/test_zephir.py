"""ZephIR CSV reader: both dialects, 9998/9999 missing codes, heights by regex, errors."""

import numpy as np
import pytest

from lidarjax.io import read_zephir_csv

# European-locale export: ';' separated, decimal commas, day-first timestamps, a preamble,
# a numeric 'Timestamp (seconds)' column that must not be taken for the time column, heights
# in non-ascending column order, 9999 / 9998 / 9999,0 missing codes.
SEMICOLON_COLUMNS = [
    "Time and Date", "Timestamp (seconds)", "Reference", "Met Wind Speed (m/s)",
    "Horizontal Wind Speed (m/s) at 100m", "Wind Direction (deg) at 100m",
    "Vertical Wind Speed (m/s) at 100m", "Horizontal Wind Speed (m/s) at 38m",
    "Wind Direction (deg) at 38m", "Vertical Wind Speed (m/s) at 38m",
    "Packets in Average at 38m",
]
SEMICOLON = "\n".join([
    "\ufeffZephIR 300 export;Unit 1234",
    "Site;Test site",
    ";".join(SEMICOLON_COLUMNS),
    "01/09/2021 00:10:00;3713734200;A1;5,5;8,53;271,2;0,12;7,25;265,5;-0,05;55",
    "01/09/2021 00:20:00;3713734800;A2;9999;9999;9998;9999,0;7,5;266;0,01;56",
    "01/09/2021 00:30:00;3713735400;A3;6,0;8,75;270,0;0,1;9998,0;264,25;0;57",
]) + "\n"

# International export: ',' separated, decimal points, ISO timestamps, quoted names, a
# height written '200.5 m' and leading-height names, no vertical wind column.
COMMA_COLUMNS = [
    "Timestamp", "Hub Height Wind Speed Flag", "Horizontal Wind Speed (m/s) at 38m",
    "Wind Direction (deg) at 38m", "200.5 m Horizontal Wind Speed (m/s)",
    "200.5 m Wind Direction (deg)", "Tilt (deg)",
]
COMMA = "\n".join([
    ",".join(f'"{c}"' for c in COMMA_COLUMNS),
    "2022-03-04 10:00:00,0,7.25,265.5,11.0,270.0,0.5",
    "2022-03-04 10:10:00,1,9998.0,9999.0,12.5,272.5,0.4",
    "",
]) + "\n"


def write(tmp_path, text, name="zephir.csv"):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_semicolon_decimal_comma(tmp_path):
    r = read_zephir_csv(write(tmp_path, SEMICOLON))
    assert (r.delimiter, r.decimal) == (";", ",")
    assert r.preamble == ("ZephIR 300 export;Unit 1234", "Site;Test site")
    np.testing.assert_array_equal(
        r.time, np.array(["2021-09-01T00:20", "2021-09-01T00:30", "2021-09-01T00:40"],
                         dtype="datetime64[s]"))  # start-stamped: UTC end = stamp + 10 min
    assert r.time_convention == "start" and r.period == np.timedelta64(600, "s")
    np.testing.assert_array_equal(r.heights, [38.0, 100.0])
    np.testing.assert_array_equal(r.speed, [[7.25, 8.53], [7.5, np.nan], [np.nan, 8.75]])
    np.testing.assert_array_equal(r.direction, [[265.5, 271.2], [266.0, np.nan], [264.25, 270.0]])
    np.testing.assert_array_equal(r.w, [[-0.05, 0.12], [0.01, np.nan], [0.0, 0.1]])
    assert r.missing == ()
    np.testing.assert_array_equal(r.extra["packetsinaverage"][:, 0], [55.0, 56.0, 57.0])
    assert np.isnan(r.extra["packetsinaverage"][:, 1]).all()
    np.testing.assert_array_equal(r.scalars["Met Wind Speed (m/s)"], [5.5, np.nan, 6.0])
    assert r.scalars["Timestamp (seconds)"][0] == 3713734200.0
    assert list(r.scalars["Reference"]) == ["A1", "A2", "A3"]
    with pytest.raises(ValueError):
        r.speed[0, 0] = 1.0


def test_comma_decimal_point(tmp_path):
    r = read_zephir_csv(write(tmp_path, COMMA))
    assert (r.delimiter, r.decimal) == (",", ".")
    assert r.preamble == ()
    np.testing.assert_array_equal(r.time, np.array(["2022-03-04T10:10", "2022-03-04T10:20"],
                                                   dtype="datetime64[s]"))
    np.testing.assert_array_equal(
        r.time_local, np.array(["2022-03-04T10:00", "2022-03-04T10:10"], dtype="datetime64[s]"))
    np.testing.assert_array_equal(r.heights, [38.0, 200.5])
    np.testing.assert_array_equal(r.speed, [[7.25, 11.0], [np.nan, 12.5]])
    np.testing.assert_array_equal(r.direction, [[265.5, 270.0], [np.nan, 272.5]])
    assert r.missing == ("w",) and np.isnan(r.w).all()
    np.testing.assert_array_equal(r.scalars["Tilt (deg)"], [0.5, 0.4])
    np.testing.assert_array_equal(r.scalars["Hub Height Wind Speed Flag"], [0.0, 1.0])


def test_semicolon_with_decimal_points(tmp_path):
    text = "Timestamp;Horizontal Wind Speed (m/s) at 38m\n2021-09-01 00:10:00;7.5\n"
    r = read_zephir_csv(write(tmp_path, text))
    assert r.speed[0, 0] == 7.5 and r.heights[0] == 38.0


def test_to_pandas(tmp_path):
    import pandas  # noqa: F401  (the test extra brings it)
    df = read_zephir_csv(write(tmp_path, SEMICOLON)).to_pandas()
    assert list(df.columns) == ["time", "height", "speed", "direction", "w"]
    assert df.shape == (6, 5) and df["speed"].iloc[1] == 8.53 and df["height"].iloc[1] == 100.0


@pytest.mark.parametrize(
    ("text", "line", "fragment"),
    [
        ("Timestamp,Tilt (deg)\n2021-09-01 00:10:00,1\n", 1,
         "no per-height columns such as 'Horizontal Wind Speed (m/s) at 38m'"),
    ],
)
def test_errors_name_file_and_line(tmp_path, text, line, fragment):
    path = write(tmp_path, text)
    with pytest.raises(ValueError) as err:
        read_zephir_csv(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}, line {line}: "), msg
    assert fragment in msg, msg


def test_no_time_column(tmp_path):
    path = write(tmp_path, "When;Horizontal Wind Speed (m/s) at 38m\nx;1\n")
    with pytest.raises(ValueError, match=rf"^{path}: no header line naming a time column"):
        read_zephir_csv(path)
    with pytest.raises(FileNotFoundError, match="ZephIR CSV file not found"):
        read_zephir_csv(tmp_path / "absent.csv")
