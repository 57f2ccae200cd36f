"""Shared helpers of the readers and writers: error messages, atomic writes, optional imports.

Private to `lidarjax.io`; nothing here is public API.
"""

from __future__ import annotations

import datetime as _dt
import math
import re
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from .._util import PathLike, file_error

__all__: list[str] = []


def parse_float(text: str) -> float:
    """`float(text)`, with empty fields and `NA`/`N/A` read as NaN. Raises `ValueError`."""
    t = text.strip()
    if t == "" or t.upper() in ("NA", "N/A"):
        return math.nan
    return float(t)


def is_number(text: str, parse: Callable[[str], float] = float) -> bool:
    """Whether `parse(text)` (default `float`) reads `text` without a `ValueError`."""
    try:
        parse(text)
    except ValueError:
        return False
    return True


def float_row(fields: Sequence[str], names: Sequence[str], path: PathLike,
              line: int) -> list[float]:
    """`float` of each of `fields`; on a bad one raise naming the line, its column in `names`
    and the text."""
    try:
        return [float(f) for f in fields]
    except ValueError:
        bad = next(i for i, f in enumerate(fields) if not is_number(f))
        raise file_error(
            path, line, f"column {names[bad]!r}: expected a number, found {fields[bad]!r}"
        ) from None


def parse_row(
    fields: Sequence[str],
    columns: Sequence[int],
    names: Sequence[str],
    path: PathLike,
    line: int,
) -> np.ndarray:
    """Convert `fields[columns]` to float64; on a bad field raise naming the line and column."""
    picked = [fields[c] for c in columns]
    try:
        return np.array(picked, dtype=np.float64)
    except ValueError:
        pass
    out = np.empty(len(picked), dtype=np.float64)
    for i, text in enumerate(picked):
        try:
            out[i] = parse_float(text)
        except ValueError:
            raise file_error(
                path, line, f"column {names[i]!r}: expected a number, found {text.strip()!r}"
            ) from None
    return out


_PLAIN_NUMBER = re.compile(r"^[-+]?(\d+([.,]\d*)?|[.,]\d+)([eE][-+]?(\d+))?$")


def ends_with_line_end(text: str) -> bool:
    """Whether `text` ends with a line end (spaces or tabs may follow it): its last line was
    written whole."""
    return text.rstrip(" \t").endswith(("\n", "\r"))


def number_format(field: str) -> tuple[int, int] | None:
    """``(decimals, exponent digits)`` of a number written as `field` (decimal mark ``.`` or
    ``,``), or None for any other text (``NaN`` included)."""
    m = _PLAIN_NUMBER.match(field.strip())
    if m is None:
        return None
    mantissa = re.split(r"[eE]", field.strip())[0]
    decimals = len(re.split(r"[.,]", mantissa)[-1]) if re.search(r"[.,]", mantissa) else 0
    return decimals, len(m.group(4) or "")


def field_cut(last: str, above: Sequence[str], missing: Callable[[str], bool] = lambda f: False) -> str | None:
    """Why `last`, the last field of a file's last line written without a line end, was cut
    while the file was written, or None: fixed formats write a column's numbers with the same
    decimals (and exponent digits), so a number in another format than the same column's
    numbers `above` (on rows before), or a text that is not a number where they are numbers
    or a beginning of one of their texts (``Na`` of ``NaN``), is cut. A column without
    numbers above, or a `missing` code (9999), is taken as written; a cut that keeps the
    format (an integer column, ``100`` cut to ``10``) cannot be told."""
    seen = {number_format(f) for f in above if f.strip() and not missing(f)}
    formats = seen - {None}
    fmt = number_format(last)
    if fmt is not None:
        if not formats or fmt in formats or missing(last):
            return None
        return (f"its last field {last.strip()!r} has {fmt[0]} decimals where the column has "
                f"{'/'.join(str(d) for d, _ in sorted(formats))}")
    texts = {f.strip() for f in above}
    if last.strip() in texts:
        return None
    if formats or any(t.startswith(last.strip()) for t in texts):
        return f"its last field {last.strip()!r} is not the column's number"
    return None


def parse_timestamp(text: str, formats: Sequence[str]) -> _dt.datetime:
    """Parse `text` with the first matching `strptime` format; `ValueError` if none does."""
    t = text.strip()
    for fmt in formats:
        try:
            return _dt.datetime.strptime(t, fmt)
        except ValueError:
            continue
    raise ValueError(f"unrecognised timestamp {t!r} (expected one of {', '.join(formats)})")


def read_text(path: Path) -> str:
    """The whole file as text: UTF-8 (BOM allowed) when it decodes, else cp1252.

    Raises a one-line `ValueError` naming the file for an empty file and for UTF-16 or
    binary content (NUL bytes).
    """
    raw = path.read_bytes()
    if not raw.strip():
        raise file_error(path, None, "the file is empty; export the records again")
    if raw[:2] in (b"\xff\xfe", b"\xfe\xff") or b"\x00" in raw[:65536]:
        raise file_error(
            path, 1, "the file is UTF-16 or binary (NUL bytes), not text; re-save it as "
            "UTF-8 or cp1252 text"
        )
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("cp1252", errors="replace")


_ISO_TIME = re.compile(
    r"^\d{4}-\d{2}-\d{2}[ T]\d{2}:\d{2}(:\d{2}(\.\d{1,6})?)?$"
)
_YMD = re.compile(r"^\d{4}[/.-]\d{2}[/.-]\d{2}[ T]")
_DMY = re.compile(r"^\d{2}[/.-]\d{2}[/.-]\d{4}[ T]")


def _to_iso(text: str) -> str:
    t = text.strip()
    if _DMY.match(t):
        t = f"{t[6:10]}-{t[3:5]}-{t[0:2]}T{t[11:]}"
    elif _YMD.match(t):
        t = f"{t[0:4]}-{t[5:7]}-{t[8:10]}T{t[11:]}"
    return t


def parse_times(texts: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Vectorised time-stamp parsing: `(datetime64[ms] array, ok mask)`.

    Accepts `YYYY/MM/DD hh:mm[:ss[.fff]]`, `YYYY-MM-DD...` (space or `T`) and day-first
    `DD/MM/YYYY hh:mm[:ss[.fff]]` (also with `.` or `-`). Unreadable stamps give NaT and
    `ok=False`.
    """
    iso = [_to_iso(t) for t in texts]
    ok = np.array([bool(_ISO_TIME.match(t)) for t in iso], dtype=bool)
    out = np.full(len(iso), np.datetime64("NaT", "ms"), dtype="datetime64[ms]")
    good = [t for t, g in zip(iso, ok, strict=True) if g]
    if good:
        try:
            out[ok] = np.array(good, dtype="datetime64[ms]")
        except ValueError:  # e.g. month 13: find the culprits one by one
            idx = np.flatnonzero(ok)
            for i in idx:
                try:
                    out[i] = np.datetime64(iso[i], "ms")
                except ValueError:
                    ok[i] = False
    return out, ok


_UTC = re.compile(r"(?:UTC|GMT)\s*([+\-\u2212]*)\s*(\d{1,2})(?:[:h.]?(\d{2}))?", re.IGNORECASE)


def parse_utc_offset(text: str) -> float | None:
    """Hours east of UTC from `UTC+1`, `UTC-03:00`, `GMT+5:30`, `UTC--3` (= UTC-3), `UTC`.

    Windcube writes a negative zone with a doubled sign (`timezone=UTC--3` on a Brazilian
    unit is UTC-3): any minus sign makes the offset negative. `None` when no zone is found.
    """
    m = _UTC.search(text)
    if m is None:
        if re.search(r"\b(UTC|GMT|Z)\b", text, re.IGNORECASE):
            return 0.0
        return None
    hours = int(m.group(2)) + (int(m.group(3)) / 60.0 if m.group(3) else 0.0)
    if hours > 14:
        return None
    return -hours if ("-" in m.group(1) or "\u2212" in m.group(1)) else hours


def offset_timedelta(hours: float) -> np.timedelta64:
    """`hours` as a `timedelta64[ms]`."""
    return np.timedelta64(int(round(hours * 3_600_000)), "ms")


