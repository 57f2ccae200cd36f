"""A record file whose writer was interrupted inside the last field of its last row (the
field count still complete: availability ``100.00`` cut to ``10``): the Windcube ``.sta`` and
``.rtd`` readers (copies of the real files cut at every offset inside the last field) and the
ZephIR CSV reader leave that row out with one warning naming the file and line, and read every
earlier row as the uncut file; a file that only lacks its final line end reads whole."""

import dataclasses
import warnings

import numpy as np
import pytest

from lidarjax.io import read_rtd, read_sta, read_zephir_csv

from ..helpers import windcube_file
from .record_samples import zephir_300_text, zx_text

REAL = [("wls7_abc_2020_10_07__00_10_00.sta", read_sta), ("wls7_abc_2020_10_08__00_10_00.sta", read_sta),
        ("WLS866-104_2024_08_02__23_44_55.rtd", read_rtd)]


def _quiet(reader, path):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return reader(path)


def _assert_earlier_rows(cut, whole):
    """Every per-row array of `cut` is `whole`'s without its last row."""
    n = whole.time.shape[0]
    assert cut.time.shape[0] == n - 1
    for f in dataclasses.fields(whole):
        a, b = getattr(cut, f.name), getattr(whole, f.name)
        if isinstance(b, dict):
            pairs = [(a[k], b[k]) for k in b if isinstance(b[k], np.ndarray)]
        else:
            pairs = [(a, b)] if isinstance(b, np.ndarray) else []
        for x, y in pairs:
            if y.ndim and y.shape[0] == n:
                np.testing.assert_array_equal(x, y[:-1], err_msg=f.name)
            else:
                np.testing.assert_array_equal(x, y, err_msg=f.name)


def _last_field(data: bytes) -> tuple[int, int]:
    """Byte span of the last line's last non-empty field (before its trailing tab/line end)."""
    end = len(data.rstrip(b"\r\n\t ;,"))
    start = max(data.rfind(sep, 0, end) for sep in (b"\t", b";", b",")) + 1
    return start, end


@pytest.mark.parametrize("name, reader", REAL, ids=[n for n, _ in REAL])
def test_real_windcube_cut_inside_last_field(tmp_path, name, reader):
    src = windcube_file(name)
    data = src.read_bytes()
    assert data.endswith(b"\n")  # the real files end with a line end
    whole = _quiet(reader, src)
    n_lines = data.count(b"\n")
    start, end = _last_field(data)
    assert end - start >= 4  # e.g. 100.00, -29.099
    for cut_at in range(start + 1, end):
        path = tmp_path / f"cut{cut_at}{src.suffix}"
        path.write_bytes(data[:cut_at])
        with pytest.warns(UserWarning, match=rf"{path.name}, line {n_lines}: truncated file") as rec:
            cut = reader(path)
        assert len(rec) == 1, [str(w.message) for w in rec]
        _assert_earlier_rows(cut, whole)
        assert any("truncated file" in m for m in cut.warnings)
    # a file that lacks only its final line end (the last field whole) reads fully, silently
    for cut_at in (len(data.rstrip(b"\r\n")), end):
        path = tmp_path / f"whole{cut_at}{src.suffix}"
        path.write_bytes(data[:cut_at])
        got = _quiet(reader, path)
        assert got.time.shape == whole.time.shape
        np.testing.assert_array_equal(got.row_lines, whole.row_lines)


@pytest.mark.parametrize("text", [zephir_300_text(6), zx_text(6)], ids=["semicolon", "comma"])
def test_zephir_cut_inside_last_field(tmp_path, text):
    """The last column (packets, ``60,00`` / ``60.00``) cut short: the row is left out."""
    data = text.encode()
    src = tmp_path / "whole.csv"
    src.write_bytes(data)
    whole = _quiet(read_zephir_csv, src)
    start, end = _last_field(data)
    n_lines = data.count(b"\n")
    for cut_at in range(start + 1, end):
        path = tmp_path / f"cut{cut_at}.csv"
        path.write_bytes(data[:cut_at])
        with pytest.warns(UserWarning, match=rf"{path.name}, line {n_lines}: truncated file") as rec:
            cut = read_zephir_csv(path)
        assert len(rec) == 1
        _assert_earlier_rows(cut, whole)
    path = tmp_path / "no_line_end.csv"
    path.write_bytes(data.rstrip(b"\r\n"))
    np.testing.assert_array_equal(_quiet(read_zephir_csv, path).speed, whole.speed)


def test_zephir_missing_code_last_is_whole(tmp_path):
    """A last field that is ZephIR's missing code (9999) is written whole, whatever its format."""
    text = zx_text(4).rstrip("\n")
    head, _, _ = text.rpartition(",")
    path = tmp_path / "code.csv"
    path.write_text(head + ",9999")
    assert _quiet(read_zephir_csv, path).time.shape == (4,)


def test_field_cut_rules():
    """The rule itself: another number format than the column's, a beginning of the column's
    text, or a text where the column holds numbers is cut; the column's own format or text,
    a missing code, or a column without numbers is written."""
    from lidarjax.io._common import field_cut, number_format

    assert number_format(" 1,50e-03 ") == (2, 2) and number_format("12") == (0, 0)
    assert number_format("NaN") is None and number_format("1.2.3") is None
    assert "has 0 decimals" in field_cut("10", ["100.00", "99.50"])
    assert field_cut("99.75", ["100.00", "99.50"]) is None
    assert field_cut("9999", ["12.5"], missing=lambda f: f.strip() == "9999") is None
    assert field_cut("12.5", ["9999", "9999"], missing=lambda f: f.strip() == "9999") is None
    assert "is not the column's number" in field_cut("Na", ["NaN", "NaN"])
    assert "is not the column's number" in field_cut("ab", ["12.5", "13.0"])
    assert field_cut("NaN", ["NaN", "12.5"]) is None
    assert field_cut("OK", ["FAIL", "OK"]) is None
    assert field_cut("xyz", ["abc"]) is None
