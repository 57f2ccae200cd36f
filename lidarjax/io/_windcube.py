"""The Windcube text layout shared by `.sta`/`.stdsta` and `.rtd` files (private).

V2 / V2.1 (WindCube v2, firmware WF 2.x):

```
HeaderSize=40                      <- N header lines follow: key=value, section titles,
Version=WF 2.1.6.16036                '****' rules
timezone=UTC+0                     <- instrument clock; 'UTC--3' means UTC-3
...
CNRThreshold=-24                   <- dB; samples below it are not used by the instrument
Altitudes (m)=\t40\t54\t...        <- tab-separated altitudes
********************
Timestamp (end of interval)\tInt Temp (°C)\t...\t40m Wind Speed (m/s)\t...
2020/10/07 00:10\t11.90\t...       <- data rows, tab separated, trailing tab
```

V1 (WLS7 v1): first line `HeaderLength=N`, `Altitudes(m)=` in the header, a column line
starting with `Date`, day-first stamps `dd/mm/yyyy hh:mm:ss` and per-altitude columns
numbered by gate: `Vhm1`, `dVh1`, `Azim1`, `wm1`, `CNRm1`, `Avail1` ... where gate `i` is
the `i`-th header altitude.

Encoding cp1252 (the degree sign is byte 0xB0); UTF-8 is accepted. Per-altitude columns are
mapped by parsing the altitude (or gate) and the normalised quantity name, never by
position. Rows are parsed in vectorised chunks (`numpy.loadtxt`); a chunk with a bad row
falls back to row-by-row parsing so that one corrupt row costs only itself.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import io
import re
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .._util import file_error, normalise_key, require_file
from ..progress import progress_meter
from ._common import (
    ends_with_line_end,
    is_number,
    offset_timedelta,
    parse_float,
    parse_times,
    parse_utc_offset,
    read_text,
)
from ._records import drop_cut_last_row, per_height_arrays, warn_corrupt_rows

__all__: list[str] = []

ENCODING = "cp1252"

TIME_FORMATS: tuple[str, ...] = (
    "%Y/%m/%d %H:%M",
    "%Y/%m/%d %H:%M:%S",
    "%Y/%m/%d %H:%M:%S.%f",
    "%d/%m/%Y %H:%M:%S",
    "%d/%m/%Y %H:%M",
    "%d/%m/%Y %H:%M:%S.%f",
    "%Y-%m-%d %H:%M:%S",
    "%Y-%m-%d %H:%M",
    "%Y-%m-%d %H:%M:%S.%f",
    "%Y-%m-%dT%H:%M:%S",
    "%Y-%m-%dT%H:%M:%S.%f",
)

NOMINAL_CONE: dict[str, float] = {"windcube_v1": 30.0, "windcube_v2": 28.0}
"""Cone angle (degrees from vertical) of each Windcube generation, used when the header's
`ScanAngle` is `NA` (V2 firmware writes NA; the real V2.1 `.rtd` reconstruction pins 28.00
degrees, see `lidarjax.io.rtd.instrument_reconstruction`)."""

_FIRST_LINE = re.compile(r"^\s*(HeaderSize|HeaderLength)\s*=\s*(\d+)\s*$", re.IGNORECASE)
_ALTITUDE_COLUMN = re.compile(r"^\s*(\d+(?:\.\d+)?)\s*m(?![a-z])\s*(.*)$", re.IGNORECASE)
_GATE_COLUMN = re.compile(r"^\s*([A-Za-z][A-Za-z_]*?)(\d+)\s*$")
_TIME_NAMES = ("timestamp", "date", "time", "datetime", "dateandtime", "timeanddate",
               "timestampendofinterval")
_DATE_ONLY = re.compile(r"^\s*\d{1,4}[/.-]\d{1,2}[/.-]\d{1,4}\s*$")
_TIME_ONLY = re.compile(r"^\s*\d{1,2}:\d{2}(:\d{2}(\.\d+)?)?\s*$")
CHUNK = 4096


class TimeParser:
    """`strptime` over a list of formats, trying the last one that worked first."""

    def __init__(self, formats: tuple[str, ...]) -> None:
        self.formats = list(formats)

    def __call__(self, text: str) -> _dt.datetime:
        t = text.strip()
        for i, fmt in enumerate(self.formats):
            try:
                value = _dt.datetime.strptime(t, fmt)
            except ValueError:
                continue
            if i:
                self.formats.insert(0, self.formats.pop(i))
            return value
        raise ValueError(f"unrecognised timestamp {t!r}")


def _is_time_name(name: str) -> bool:
    key = normalise_key(name)
    return key in _TIME_NAMES or key.startswith("timestamp")


@dataclasses.dataclass
class Parsed:
    """What `read_windcube` found; the public readers turn it into a record."""

    path: Path
    version: str  # "V1" (HeaderLength=) or "V2" (HeaderSize=)
    header: dict[str, str]
    heights: np.ndarray  # (k,)
    time: np.ndarray  # (t,) datetime64[ms], as written (instrument clock)
    time_ok: np.ndarray  # (t,) bool: the stamp was read
    row_ok: np.ndarray  # (t,) bool: every value was read
    quantities: dict[str, np.ndarray]  # mapped quantity -> (t, k)
    extra: dict[str, np.ndarray]  # unmapped per-altitude quantity -> (t, k)
    scalars: dict[str, list[str]]  # other columns -> raw text per row
    scalar_lines: int  # 1-based line of the column names (for messages)
    row_lines: np.ndarray  # (t,) 1-based line of each data row
    problems: list[tuple[int, str]]  # (line, why) of each corrupt row
    notes: list[str]  # other remarks (duplicate columns ...)
    columns: list[str]


def header_lookup(header: Mapping[str, str], *names: str) -> str | None:
    """The value of the first header key whose normalised form is one of `names`."""
    wanted = {normalise_key(n) for n in names}
    for key, value in header.items():
        if normalise_key(key) in wanted:
            return value
    return None


def header_angle(header: Mapping[str, str], path: Path, *names: str) -> float:
    """A header number (degrees, dB ...); NaN when absent or `NA`."""
    value = header_lookup(header, *names)
    if value is None:
        return float("nan")
    try:
        return parse_float(value)
    except ValueError:
        raise file_error(
            path, None, f"header {names[0]!r}: expected a number or NA, found {value!r}"
        ) from None


def _unique(columns: list[str], notes: list[str], path: Path, line: int) -> list[str]:
    """Rename repeated column names `name#2`, `name#3` ... so that none collapses."""
    seen: dict[str, int] = {}
    out = []
    for name in columns:
        key = name.strip()
        if not key:
            out.append(name)
            continue
        n = seen.get(key, 0) + 1
        seen[key] = n
        if n > 1:
            new = f"{key}#{n}"
            notes.append(f"{path}, line {line}: column {key!r} appears {n} times; the "
                         f"repeat is kept as {new!r}")
            out.append(new)
        else:
            out.append(name)
    return out


def _parse_block(lines: list[str], cols: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """Values of `cols` for each line: `(values (n, c), ok (n,))`; bad rows are NaN."""
    n = len(lines)
    out = np.full((n, len(cols)), np.nan)
    ok = np.ones(n, dtype=bool)
    if not cols or n == 0:
        return out, ok
    fast = _pandas_block(lines, cols)
    if fast is not None:
        return fast, ok
    for s in range(0, n, CHUNK):
        part = lines[s:s + CHUNK]
        try:
            out[s:s + len(part)] = np.loadtxt(
                part, delimiter="\t", usecols=cols, comments=None, dtype=np.float64, ndmin=2
            )
            continue
        except (ValueError, IndexError):
            pass
        for i, line in enumerate(part):
            fields = line.split("\t")
            try:
                out[s + i] = [parse_float(fields[c]) for c in cols]
            except (ValueError, IndexError):
                ok[s + i] = False
    return out, ok


def _pandas_block(lines: list[str], cols: list[int]) -> np.ndarray | None:
    """pandas' C parser on a clean block (about 10x faster than `numpy.loadtxt`), when the
    optional pandas is installed; None when it is not or when any cell is not a number (the
    caller then isolates the bad rows chunk by chunk)."""
    try:
        import pandas as pd
    except ImportError:
        return None

    out = np.empty((len(lines), len(cols)))
    step = 50_000  # bounded memory: one block of text at a time
    for s in range(0, len(lines), step):
        part = lines[s:s + step]
        try:
            buf = io.BytesIO("\n".join(part).encode("utf-8", errors="replace"))
            df = pd.read_csv(
                buf, sep="\t", header=None, usecols=cols, dtype=np.float64, engine="c",
                na_values=["NA", "N/A", "NaN", "nan", ""], keep_default_na=False,
                skip_blank_lines=False, quoting=3,
            )
        except (ValueError, TypeError, UnicodeError, pd.errors.ParserError):
            return None
        values = df[cols].to_numpy(dtype=np.float64)
        if values.shape != (len(part), len(cols)):
            return None
        out[s:s + len(part)] = values
    return out


def read_windcube(
    path: str | Path,
    quantities: Mapping[str, str],
    what: str,
    *,
    gate_quantities: Mapping[str, str] | None = None,
    progress: Any = None,
) -> Parsed:
    """Read a Windcube text file; per-altitude columns named in `quantities` are mapped.

    `quantities` maps normalised quantity names (`normalise_key("Wind Speed (m/s)")` is
    `"windspeed"`) to record field names; `gate_quantities` maps lower-case V1 gate-column
    prefixes (`"vhm"` for `Vhm1`) to field names. `progress` (`lidarjax.progress.progress_meter`:
    a bool, a meter or a `(done, total)` callable; True: a `TextProgress` line
    ``reading <file>: ...``) is told the rows parsed per chunk.
    """
    p = require_file(path, what)
    if progress is None or progress is False:
        progress = None
    else:
        progress = progress_meter(progress).callback(f"reading {p.name}")
    text = read_text(p)
    lines = text.split("\n")
    version, header, header_line_of, columns, column_line = _read_header(p, text, lines, what)
    notes: list[str] = []
    cut = drop_cut_last_row(p, lines, column_line, ends_with_line_end(text),
                            lambda ln: ln.split("\t"), stacklevel=3)
    if cut is not None:
        notes.append(cut)
    columns = _unique(columns, notes, p, column_line)
    header_heights, alt_value = _header_heights(p, header, header_line_of)
    data = [ln.rstrip("\r") for ln in lines[column_line:]]
    del lines, text  # keep the peak memory to one copy of the rows
    time_col = next(i for i, c in enumerate(columns) if _is_time_name(c))
    columns = _split_stamp_column(columns, data, time_col)
    mapped, scalar_cols = _map_columns(p, columns, time_col, column_line, header_heights,
                                       alt_value, gate_quantities, notes)
    altitudes = set(header_heights) if header_heights is not None else {a for _, a, _ in mapped}
    heights = np.array(sorted(altitudes), dtype=np.float64)
    row_lines, times, time_ok, row_ok, values, problems, scalars = _read_rows(
        data, columns, column_line, time_col, [i for i, _, _ in mapped], scalar_cols, progress)
    gq = {("v1:" + k.lower()): v for k, v in (gate_quantities or {}).items()}
    out, extra = per_height_arrays(mapped, values, heights,
                                   lambda key: quantities.get(key) or gq.get(key))
    return Parsed(
        path=p, version=version, header=header, heights=heights, time=times,
        time_ok=time_ok, row_ok=row_ok, quantities=out, extra=extra, scalars=scalars,
        scalar_lines=column_line, row_lines=np.array(row_lines, dtype=np.int64),
        problems=problems, notes=notes, columns=columns,
    )


def _read_header(p: Path, text: str, lines: list[str], what: str):
    """`(version, header, 1-based line of each header key, column names, their line)`: the
    first line (`HeaderSize=N` V2 or `HeaderLength=N` V1), the `key=value` lines after it
    and the column-names line (starting with a time column name)."""
    first = lines[0].rstrip("\r").lstrip("\ufeff")
    m = _FIRST_LINE.match(first)
    if not m:
        raise file_error(
            p, 1, "expected 'HeaderSize=N' (Windcube V2) or 'HeaderLength=N' (V1), "
            f"found {first.strip()[:60]!r}; is this a Windcube {what.split()[-2]} file?"
        )
    version = "V2" if m.group(1).lower() == "headersize" else "V1"
    header: dict[str, str] = {}
    header_line_of: dict[str, int] = {}
    for idx in range(1, len(lines)):
        line = lines[idx].rstrip("\r")
        stripped = line.strip()
        if not stripped or set(stripped) <= {"*"}:
            continue
        if _is_time_name(line.split("\t", 1)[0]) and ("\t" in line or "=" not in line):
            return version, header, header_line_of, line.split("\t"), idx + 1
        if "=" in stripped:
            key, _, value = stripped.partition("=")
            header[key.strip()] = value.strip()
            header_line_of[key.strip()] = idx + 1
            continue
        if idx > int(m.group(2)):
            raise file_error(
                p, idx + 1, "expected the column-names line starting with 'Timestamp' or "
                f"'Date', found {stripped[:60]!r}"
            )
    raise file_error(
        p, len(text.splitlines()), "no column-names line (starting with 'Timestamp' or 'Date') "
        "after the header; the file is cut or is not a Windcube record"
    )


_ALTITUDE_KEYS = ("Altitudes (m)", "Altitudes AGL (m)", "Altitude (m)", "Heights (m)")


def _header_heights(p: Path, header: dict[str, str], header_line_of: dict[str, int]):
    """`(altitudes in m or None, their header value as written or None)`."""
    alt_value = header_lookup(header, *_ALTITUDE_KEYS)
    if alt_value is None:
        return None, None
    wanted = {normalise_key(a) for a in _ALTITUDE_KEYS}
    alt_key = next(k for k in header if normalise_key(k) in wanted)
    try:
        return [float(a) for a in alt_value.replace(",", " ").split()], alt_value
    except ValueError:
        raise file_error(
            p, header_line_of[alt_key], f"'{alt_key}': expected altitudes in metres, "
            f"found {alt_value!r}"
        ) from None


def _split_stamp_column(columns: list[str], data: list[str], time_col: int) -> list[str]:
    """The column names with `__time_of_day` where V1 splits the stamp in two fields (date
    \\t time) under one 'Date' name, or names the second 'Time'."""
    first_row = next((ln for ln in data if ln.strip()), None)
    if first_row is not None:
        f = first_row.split("\t")
        if (len(f) > time_col + 1 and _DATE_ONLY.match(f[time_col])
                and _TIME_ONLY.match(f[time_col + 1])):
            if len(columns) > time_col + 1 and _is_time_name(columns[time_col + 1]):
                columns[time_col + 1] = "__time_of_day"  # 'Date' and 'Time' columns
            else:  # one 'Date' name over two fields
                columns = columns[: time_col + 1] + ["__time_of_day"] + columns[time_col + 1:]
    return columns


def _map_columns(p, columns, time_col, column_line, header_heights, alt_value,
                 gate_quantities, notes):
    """`(mapped, scalar columns)`: per-altitude columns as `(column, altitude, quantity
    key)` (V2 `40m Wind Speed (m/s)`, then V1 gate-numbered ones), every other column by
    name."""
    mapped: list[tuple[int, float, str]] = []  # (column, altitude, quantity key)
    scalar_cols: dict[str, int] = {}
    seen: dict[tuple[float, str], str] = {}
    gate_cols: list[tuple[int, str, int]] = []
    for i, name in enumerate(columns):
        if i == time_col or name == "__time_of_day" or not name.strip():
            continue
        am = _ALTITUDE_COLUMN.match(name)
        if am is None:
            gm = _GATE_COLUMN.match(name)
            if gm is not None and header_heights is not None:
                gate_cols.append((i, gm.group(1), int(gm.group(2))))
            scalar_cols[name.strip()] = i
            continue
        altitude = float(am.group(1))
        dup = re.search(r"#(\d+)$", am.group(2))
        key = normalise_key(am.group(2)[: dup.start()] if dup else am.group(2))
        if dup:
            key = f"{key}#{dup.group(1)}"
        if not key:
            raise file_error(p, column_line, f"column {name!r}: no quantity after the altitude")
        if (altitude, key) in seen:
            key = f"{key}#2"
            notes.append(f"{p}, line {column_line}: columns {seen[(altitude, key[:-2])]!r} "
                         f"and {name!r} give the same quantity at {am.group(1)} m; the "
                         f"second is kept as extra[{key!r}]")
        seen[(altitude, key)] = name
        if header_heights is not None and altitude not in header_heights:
            raise file_error(
                p, column_line, f"column {name!r}: altitude {am.group(1)} m is not in the "
                f"header's altitudes {' '.join(alt_value.split()) if alt_value else ''}"
            )
        mapped.append((i, altitude, key))
    if gate_cols and header_heights is not None:
        _map_gate_columns(columns, gate_cols, header_heights, gate_quantities, mapped,
                          scalar_cols)
    if not mapped:
        raise file_error(
            p, column_line, "no per-altitude columns ('40m Wind Speed (m/s)' in V2, or "
            "gate-numbered 'Vhm1' with 'Altitudes(m)=' in the header in V1)"
        )
    return mapped, scalar_cols


def _map_gate_columns(columns, gate_cols, header_heights, gate_quantities, mapped,
                      scalar_cols) -> None:
    """Gate-numbered (V1) columns into `mapped` (key `v1:<prefix>`), out of `scalar_cols`: a
    prefix counts when its gates are distinct, within 1..len(altitudes), and the prefix is
    known or present for at least 2 gates."""
    by_prefix: dict[str, list[tuple[int, int]]] = {}
    for i, prefix, gate in gate_cols:
        by_prefix.setdefault(prefix, []).append((i, gate))
    n_alt = len(header_heights)
    gq = {k.lower(): v for k, v in (gate_quantities or {}).items()}
    for prefix, items in by_prefix.items():
        gates = [g for _, g in items]
        known = prefix.lower() in gq
        if not all(1 <= g <= n_alt for g in gates) or len(set(gates)) != len(gates):
            continue
        if not known and len(items) < min(2, n_alt):
            continue
        for i, gate in items:
            key = f"v1:{prefix.lower()}"
            mapped.append((i, header_heights[gate - 1], key))
            scalar_cols.pop(columns[i].strip(), None)


def _read_rows(data, columns, column_line, time_col, value_cols, scalar_cols, progress):
    """The data rows: `(1-based lines, times, time_ok, row_ok, values (t, len(value_cols)),
    problems, scalar columns' text)`; a bad row's values are NaN and `problems` says why."""
    n_fields = len(columns)
    needed = max([time_col, *value_cols, *scalar_cols.values()]) + 1
    two_part_time = "__time_of_day" in columns
    row_lines = []  # data rows: drop blank lines, keep the 1-based line numbers
    rows = []
    for j, ln in enumerate(data):
        if ln.strip():
            rows.append(ln)
            row_lines.append(column_line + 1 + j)
    counts = np.array([r.count("\t") + 1 for r in rows], dtype=np.int64)
    count_ok = counts >= needed
    # Extra non-empty fields beyond the header's columns mean a shifted row.
    over = np.zeros(len(rows), dtype=bool)
    for i in np.flatnonzero(counts > n_fields):  # trailing empty fields are fine
        over[i] = rows[i].rstrip("\t\r ").count("\t") + 1 > n_fields
    head = time_col + (2 if two_part_time else 1)
    if scalar_cols:
        head = max(head, max(scalar_cols.values()) + 1)
    split = [r.split("\t", head)[:head] for r in rows]  # only the leading fields are kept
    stamps = [(f[time_col] + (" " + f[time_col + 1] if two_part_time and len(f) > time_col + 1
                              else "")) if len(f) > time_col else "" for f in split]
    times, time_ok = parse_times(stamps)
    values, vals_ok = _parse_values(rows, np.flatnonzero(count_ok & ~over), value_cols, progress)
    row_ok = count_ok & ~over & vals_ok & time_ok
    problems: list[tuple[int, str]] = []
    for i in np.flatnonzero(~row_ok):
        if not count_ok[i]:
            why = (f"cut row: expected at least {needed} tab-separated fields, found "
                   f"{counts[i]}")
        elif over[i]:
            why = f"more fields than the {n_fields} columns (shifted row)"
        elif not time_ok[i]:
            why = f"unreadable time stamp {stamps[i].strip()[:40]!r}"
        else:
            why = _bad_cell(rows[i], columns, value_cols)
        problems.append((row_lines[i], why))
        values[i] = np.nan
    scalars: dict[str, list[str]] = {
        name: [f[col].strip() if len(f) > col and col < head else "" for f in split]
        for name, col in scalar_cols.items()
    }
    return row_lines, times, time_ok, row_ok, values, problems, scalars


def _parse_values(rows, good_idx, value_cols, progress):
    """`(values (n, c), ok (n,))` of the `value_cols` of the rows `good_idx`, in blocks
    (NaN and False elsewhere); `progress` is told the rows done."""
    n = len(rows)
    values = np.full((n, len(value_cols)), np.nan)
    vals_ok = np.zeros(n, dtype=bool)
    for s in range(0, good_idx.size, CHUNK * 4):
        part = good_idx[s:s + CHUNK * 4]
        v, ok = _parse_block([rows[i] for i in part], value_cols)
        values[part] = v
        vals_ok[part] = ok
        if progress is not None:
            progress(min(s + part.size, good_idx.size), good_idx.size)
    return values, vals_ok


def _bad_cell(row: str, columns: list[str], value_cols: list[int]) -> str:
    """Why a row of the right shape and a good stamp was not read: its first non-number."""
    bad = next((columns[c] for c in value_cols
                if not is_number(row.split("\t")[c], parse_float)), "?")
    cell = row.split("\t")[columns.index(bad)] if bad in columns else ""
    return f"column {bad!r}: expected a number, found {cell.strip()[:30]!r}"


def scalar_arrays(scalars: Mapping[str, list[str]]) -> dict[str, np.ndarray]:
    """Numeric columns as float64 `(t,)` (empty/NA -> NaN); any other column as text."""
    out: dict[str, np.ndarray] = {}
    for name, values in scalars.items():
        try:
            out[name] = np.array([parse_float(v) for v in values], dtype=np.float64)
        except ValueError:
            out[name] = np.array(values, dtype=str)
    return out


@dataclasses.dataclass
class HeaderFacts:
    """Convention facts from a Windcube header (all angles in degrees)."""

    instrument: str
    scan_angle: float
    cone_angle: float
    direction_offset: float
    pitch: float
    roll: float
    cnr_threshold: float
    timezone: str
    utc_offset_hours: float


def header_facts(parsed: Parsed) -> HeaderFacts:
    """Instrument kind, angles, CNR threshold and clock zone of a parsed Windcube file.

    A header without `timezone` is taken as UTC (a note says so).
    """
    h, p = parsed.header, parsed.path
    instrument = "windcube_v1" if parsed.version == "V1" else "windcube_v2"
    scan = header_angle(h, p, "ScanAngle", "Scan Angle", "ConeAngle")
    tz = header_lookup(h, "timezone", "time zone", "TimeZone", "UTC offset") or ""
    off = parse_utc_offset(tz) if tz else None
    if off is None:
        if tz:
            try:
                off = float(tz)
            except ValueError:
                raise file_error(
                    p, None, f"header 'timezone': expected e.g. 'UTC+1' or 'UTC--3', found "
                    f"{tz!r}"
                ) from None
        else:
            off = 0.0
            parsed.notes.append(f"{p}: no 'timezone' in the header; times taken as UTC")
    return HeaderFacts(
        instrument=instrument,
        scan_angle=scan,
        cone_angle=scan if np.isfinite(scan) else NOMINAL_CONE[instrument],
        direction_offset=header_angle(h, p, "DirectionOffset", "Direction Offset"),
        pitch=header_angle(h, p, "PitchAngle", "Pitch"),
        roll=header_angle(h, p, "RollAngle", "Roll"),
        cnr_threshold=header_angle(h, p, "CNRThreshold", "CNR Threshold"),
        timezone=tz,
        utc_offset_hours=float(off),
    )


def to_utc(local: np.ndarray, hours: float) -> np.ndarray:
    """Instrument-clock `datetime64[ms]` to UTC (`local - offset`)."""
    return local - offset_timedelta(hours)


def report(parsed: Parsed, kind: str) -> list[str]:
    """Warn once (naming file and lines) about corrupt rows and renamed columns."""
    msgs = warn_corrupt_rows(parsed.path, parsed.problems, kind, stacklevel=3)
    for note in parsed.notes:
        if "appears" in note or "same quantity" in note:
            warnings.warn(note, stacklevel=3)
    return msgs + list(parsed.notes)
