"""Catalogue of malformed record files: each gives one error line, or flags its bad rows and
returns every good row untouched (Windcube .sta / .rtd, ZephIR CSV)."""

from __future__ import annotations

import numpy as np
import pytest

from lidarjax.flags import RecordFlag
from lidarjax.io import read_rtd, read_sta, read_zephir_csv  # noqa: E402

from . import record_samples as S

STA = S.sta_v2_text()
RTD = S.rtd_v2_text()
ZPH = S.zephir_300_text()
STA_FIRST_ROW = STA.splitlines().index(next(ln for ln in STA.splitlines()
                                            if ln.startswith("2020/"))) + 1
ZPH_FIRST_ROW = 7


def lines_of(text):
    return text.split("\n")


def edit_line(text, line, fn):
    """Apply `fn` to the 1-based `line` of `text`."""
    sep = "\r\n" if "\r\n" in text else "\n"
    parts = text.split(sep)
    parts[line - 1] = fn(parts[line - 1])
    return sep.join(parts)


def replace_cell(line, col, value, sep="\t"):
    cells = line.split(sep)
    cells[col] = value
    return sep.join(cells)


READERS = {"sta": (read_sta, ".sta"), "rtd": (read_rtd, ".rtd"), "zph": (read_zephir_csv, ".csv")}

# (id, reader, content (str or bytes), 1-based line or None, fragment of the message)
ERRORS = [
    ("sta-empty", "sta", "", None, "the file is empty"),
    ("sta-blank", "sta", "\n\n  \n", None, "the file is empty"),
    ("sta-utf16", "sta", STA.encode("utf-16"), 1, "UTF-16 or binary"),
    ("sta-binary", "sta", b"\x00\x01\x02HeaderSize=3", 1, "UTF-16 or binary"),
    ("sta-no-headersize", "sta", STA.split("\n", 1)[1], 1, "expected 'HeaderSize=N'"),
    ("sta-headersize-text", "sta", "HeaderSize=forty\n" + STA.split("\n", 1)[1], 1,
     "expected 'HeaderSize=N'"),
    ("sta-cut-in-header", "sta", "\n".join(lines_of(STA)[:6]) + "\n", 6, "no column-names line"),
    ("sta-garbage-after-header", "sta",
     STA.replace("Timestamp (end of interval)", "Horodatage"), STA_FIRST_ROW - 1,
     "expected the column-names line starting with 'Timestamp' or 'Date'"),
    ("sta-bad-altitudes", "sta", STA.replace("Altitudes (m)=\t40\t60", "Altitudes (m)=\t40\tsixty"),
     11, "'Altitudes (m)': expected altitudes in metres"),
    ("sta-column-altitude-unknown", "sta", STA.replace("60m Wind Speed (m/s)", "80m Wind Speed (m/s)"),
     STA_FIRST_ROW - 1, "altitude 80 m is not in the header's altitudes 40 60"),
    ("sta-no-height-columns", "sta",
     "HeaderSize=1\nVersion=x\nTimestamp\tTemp\n2020/01/01 00:10\t1\n", 3,
     "no per-altitude columns"),
    ("sta-no-speed", "sta", STA.replace("Wind Speed (m/s)", "Wind Sped (m/s)"),
     STA_FIRST_ROW - 1, "no speed columns"),
    ("sta-rtd-given", "sta", RTD, 11, "no speed columns"),
    ("sta-bad-scan-angle", "sta", STA.replace(f"ScanAngle ({S.DEG})=NA", f"ScanAngle ({S.DEG})=x"),
     None, "header 'ScanAngle': expected a number or NA"),
    ("sta-bad-timezone", "sta", STA.replace("timezone=UTC+0", "timezone=Paris"), None,
     "header 'timezone': expected e.g. 'UTC+1'"),
    ("sta-bad-cnr-threshold", "sta", STA.replace("CNRThreshold=-24", "CNRThreshold=low"), None,
     "header 'CNRThreshold': expected a number"),
    ("rtd-no-position", "rtd", RTD.replace("\tPosition\t", "\tBeam\t"), 11, "no 'Position' column"),
    ("rtd-no-rws", "rtd", RTD.replace("Radial Wind Speed (m/s)", "Radial Wind (m/s)"), 11,
     "no '<altitude>m Radial Wind Speed (m/s)' columns"),
    ("rtd-sta-given", "rtd", STA, STA_FIRST_ROW - 1, "no '<altitude>m Radial Wind Speed"),
    ("rtd-empty", "rtd", "", None, "the file is empty"),
    ("zph-empty", "zph", "", None, "the file is empty"),
    ("zph-utf16", "zph", ZPH.encode("utf-16"), 1, "UTF-16 or binary"),
    ("zph-no-header", "zph", "a;b\n1;2\n", None, "no header line naming a time column"),
    ("zph-no-heights", "zph", "Timestamp,Tilt (deg),Batt\n2021-09-01 00:10:00,1,2\n", 1,
     "no per-height columns"),
    ("zph-sta-given", "zph", STA, 1, "this is a Windcube file"),
]


@pytest.mark.parametrize(("reader", "content", "line", "fragment"),
                         [e[1:] for e in ERRORS], ids=[e[0] for e in ERRORS])
def test_malformed_file_one_line_error(tmp_path, reader, content, line, fragment):
    fn, suffix = READERS[reader]
    path = tmp_path / f"bad{suffix}"
    path.write_bytes(content if isinstance(content, bytes) else content.encode("cp1252"))
    with pytest.raises(ValueError) as err:
        fn(path)
    msg = str(err.value)
    assert "\n" not in msg, msg
    where = f"{path}, line {line}: " if line is not None else f"{path}"
    assert msg.startswith(where), msg
    assert fragment in msg, msg


# Flagged rows: (id, reader, edited content, bad line, expected flag bits, kept?)
R = STA_FIRST_ROW  # first data row of the .sta sample
FLAGGED = [
    ("sta-last-row-cut", "sta", STA.rstrip("\n")[:-40] + "\n", R + 5, RecordFlag.CORRUPT_ROW),
    ("sta-bad-stamp", "sta", edit_line(STA, R + 2, lambda s: replace_cell(s, 0, "2020/10/07 0O:30")),
     R + 2, RecordFlag.CORRUPT_ROW | RecordFlag.TIME_INFERRED),
    ("sta-month-13", "sta", edit_line(STA, R + 1, lambda s: replace_cell(s, 0, "2020/13/07 00:20")),
     R + 1, RecordFlag.CORRUPT_ROW | RecordFlag.TIME_INFERRED),
    ("sta-non-numeric", "sta", edit_line(STA, R + 3, lambda s: replace_cell(s, 5, "fast")), R + 3,
     RecordFlag.CORRUPT_ROW),
    ("sta-extra-fields", "sta", edit_line(STA, R + 4, lambda s: s + "\t1.0\t2.0"), R + 4,
     RecordFlag.CORRUPT_ROW),
    ("sta-first-row-cut", "sta", edit_line(STA, R, lambda s: s[:30]), R, RecordFlag.CORRUPT_ROW),
    ("zph-bad-stamp", "zph", edit_line(ZPH, ZPH_FIRST_ROW + 1,
                                       lambda s: replace_cell(s, 0, "01/09/2021 25:10:00", ";")),
     ZPH_FIRST_ROW + 1, RecordFlag.CORRUPT_ROW | RecordFlag.TIME_INFERRED),
    ("zph-non-numeric", "zph", edit_line(ZPH, ZPH_FIRST_ROW + 2,
                                         lambda s: replace_cell(s, 3, "n/a!", ";")),
     ZPH_FIRST_ROW + 2, RecordFlag.CORRUPT_ROW),
    ("zph-short-row", "zph", edit_line(ZPH, ZPH_FIRST_ROW + 4, lambda s: s[:25]), ZPH_FIRST_ROW + 4,
     RecordFlag.CORRUPT_ROW),
]


@pytest.mark.parametrize(("reader", "content", "line", "bits"), [f[1:] for f in FLAGGED],
                         ids=[f[0] for f in FLAGGED])
def test_corrupt_row_flagged_good_rows_untouched(tmp_path, reader, content, line, bits):
    fn, suffix = READERS[reader]
    clean_path = tmp_path / f"clean{suffix}"
    clean_path.write_bytes((STA if reader == "sta" else ZPH).encode("cp1252"))
    clean = fn(clean_path)
    path = tmp_path / f"bad{suffix}"
    path.write_bytes(content.encode("cp1252"))
    with pytest.warns(UserWarning, match=rf"^{path}: 1 corrupt row\(s\) at line\(s\) {line} "):
        rec = fn(path)
    assert any(f"line {line}:" in w for w in rec.warnings)
    i = int(np.flatnonzero(rec.row_lines == line)[0])
    assert np.all(rec.flags[i] == int(bits))
    assert np.all(np.isnan(rec.speed[i]))
    np.testing.assert_array_equal(rec.time, clean.time)  # the bad row keeps its place
    good = np.arange(rec.time.size) != i
    for name in ("speed", "direction", "w"):
        np.testing.assert_array_equal(getattr(rec, name)[good], getattr(clean, name)[good])
    assert np.all(rec.flags[good] == 0) and np.all(rec.valid[good]) and not rec.valid[i].any()


def test_unplaceable_bad_stamp_is_left_out(tmp_path):
    # two bad stamps followed by an irregular one: they cannot be placed, so they are left out
    text = edit_line(STA, R + 1, lambda s: replace_cell(s, 0, "yesterday"))
    text = edit_line(text, R + 3, lambda s: replace_cell(s, 0, "2020/10/07 00:45"))  # irregular
    text = edit_line(text, R + 2, lambda s: replace_cell(s, 0, "???"))
    path = tmp_path / "x.sta"
    path.write_bytes(text.encode("cp1252"))
    with pytest.warns(UserWarning, match="2 corrupt row"):
        rec = read_sta(path)
    assert rec.time.size == 4
    assert sum("left out" in w for w in rec.warnings) == 2
    assert np.all(rec.flags[rec.row_lines == R] == 0)


# Values flagged (not errors, not reinterpreted)
VALUE_CASES = [
    ("negative-speed", 5, "-3.00", RecordFlag.IMPOSSIBLE_VALUE),
    ("direction-400", 7, "400.00", RecordFlag.IMPOSSIBLE_VALUE),
    ("direction-negative", 7, "-5.00", RecordFlag.IMPOSSIBLE_VALUE),
    ("negative-dispersion", 6, "-0.50", RecordFlag.IMPOSSIBLE_VALUE),
    ("availability-150", 10, "150.00", RecordFlag.IMPOSSIBLE_VALUE),
    ("availability-50", 10, "50.00", RecordFlag.LOW_AVAILABILITY),
    ("cnr-above-0", 9, "3.50", RecordFlag.HIGH_CNR),
]


@pytest.mark.parametrize(("col", "value", "bit"), [c[1:] for c in VALUE_CASES],
                         ids=[c[0] for c in VALUE_CASES])
def test_impossible_values_flagged_not_reinterpreted(tmp_path, col, value, bit):
    path = tmp_path / "v.sta"
    path.write_bytes(edit_line(STA, R + 2, lambda s: replace_cell(s, col - 2, value))
                     .encode("cp1252"))
    rec = read_sta(path)
    assert rec.flags[2, 0] == int(bit) and np.all(rec.flags[:, 1] == 0)
    assert np.all(np.delete(rec.flags[:, 0], 2) == 0)
    if bit == RecordFlag.HIGH_CNR:  # advisory: the wind is kept
        assert rec.speed[2, 0] == 7.0 and rec.valid[2, 0]
    else:  # never a positive speed with the direction turned round: NaN and a flag
        assert np.isnan(rec.speed[2, 0]) and np.isnan(rec.direction[2, 0])
        assert not rec.valid[2, 0]
    assert rec.speed[2, 1] == 8.0


def test_duplicate_columns_kept_apart(tmp_path):
    text = STA.replace("Int Temp (\u00b0C)\tWiper count", "Wiper count\tWiper count")
    text = text.replace("\t40m CNR (dB)\t", "\t40m Wind Speed (m/s)\t")
    path = tmp_path / "d.sta"
    path.write_bytes(text.encode("cp1252"))
    with pytest.warns(UserWarning, match="appears 2 times|same quantity"):
        rec = read_sta(path)
    assert "Wiper count" in rec.scalars and "Wiper count#2" in rec.scalars
    np.testing.assert_array_equal(rec.scalars["Wiper count"], np.full(6, 11.9))
    np.testing.assert_array_equal(rec.extra["windspeed#2"][:, 0], [-12.0] * 6)
    assert rec.speed[0, 0] == 5.0


def test_duplicate_time_flagged(tmp_path):
    text = edit_line(STA, R + 1, lambda s: replace_cell(s, 0, "2020/10/07 00:10"))
    path = tmp_path / "t.sta"
    path.write_bytes(text.encode("cp1252"))
    rec = read_sta(path)
    assert np.all(rec.flags[1] == int(RecordFlag.DUPLICATE_TIME)) and np.all(rec.flags[0] == 0)
    assert rec.speed[1, 0] == 6.0  # values kept, the repeat is pointed out


def test_rtd_corrupt_rows_left_out(tmp_path):
    lines = RTD.split("\n")
    first = next(i for i, ln in enumerate(lines) if ln.startswith("2024/")) + 1
    text = edit_line(RTD, first + 2, lambda s: replace_cell(s, 1, "NE"))
    text = edit_line(text, first + 4, lambda s: s[:20])
    text = edit_line(text, first + 6, lambda s: replace_cell(s, 0, "2024/08/02 24:61:00.00"))
    path = tmp_path / "c.rtd"
    path.write_bytes(text.encode("cp1252"))
    with pytest.warns(UserWarning, match=rf"3 corrupt row\(s\) at line\(s\) {first + 2}, "
                                         rf"{first + 4}, {first + 6} "):
        rec = read_rtd(path)
    assert rec.dropped_lines == (first + 2, first + 4, first + 6)
    assert rec.time.size == 15 - 3
    assert first + 2 not in rec.row_lines.tolist() and first + 1 in rec.row_lines.tolist()


def test_bad_overrides():
    with pytest.raises(ValueError, match="time_convention must be 'start' or 'end'"):
        read_zephir_csv("x.csv", time_convention="middle")
    with pytest.raises(ValueError, match="utc_offset_hours must be finite"):
        read_zephir_csv("x.csv", utc_offset_hours=float("nan"))
    with pytest.raises(ValueError, match=r"min_availability must be a percentage in \[0, 100\]"):
        read_sta("x.sta", min_availability=120)


def test_crlf_and_utf8_read_like_cp1252(tmp_path):
    a = tmp_path / "a.sta"
    a.write_bytes(STA.encode("cp1252"))
    b = tmp_path / "b.sta"
    b.write_bytes(STA.replace("\n", "\r\n").encode("utf-8"))
    ra, rb = read_sta(a), read_sta(b)
    np.testing.assert_array_equal(ra.speed, rb.speed)
    assert ra.header == rb.header and "Int Temp (\u00b0C)" in rb.scalars
