"""The Windcube text layout shared by `.sta`/`.stdsta` and `.rtd` files (private).

```
HeaderSize=40                      <- V2; V1 writes HeaderLength=N
Version=WF 2.1.6.16036             <- N header lines follow: key=value, section titles,
...                                   '****' rules
Altitudes (m)=\t40\t54\t...        <- tab-separated altitudes
********************               <- may close the header
Timestamp (end of interval)\tInt Temp (°C)\t...\t40m Wind Speed (m/s)\t...
2020/10/07 00:10\t11.90\t...       <- data rows, tab separated
```

Encoding cp1252 (the degree sign is byte 0xB0). Per-altitude columns are named
`<altitude>m <quantity> (<unit>)`; they are mapped by parsing the altitude and the
normalised quantity name, never by position.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import re
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ._common import file_error, normalise_key, parse_float, parse_row, require_file

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

_FIRST_LINE = re.compile(r"^\s*(HeaderSize|HeaderLength)\s*=\s*(\d+)\s*$", re.IGNORECASE)
_ALTITUDE_COLUMN = re.compile(r"^\s*(\d+(?:\.\d+)?)\s*m(?![a-z])\s*(.*)$", re.IGNORECASE)
_TIME_NAMES = ("timestamp", "date", "time", "datetime", "dateandtime", "timeanddate")


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
    return normalise_key(name) in _TIME_NAMES


@dataclasses.dataclass
class Parsed:
    """What `read_windcube` found; the public readers turn it into a record."""

    path: Path
    version: str
    header: dict[str, str]
    heights: np.ndarray  # (k,)
    time: list[_dt.datetime]
    quantities: dict[str, np.ndarray]  # mapped quantity -> (t, k)
    extra: dict[str, np.ndarray]  # unmapped per-altitude quantity -> (t, k)
    scalars: dict[str, list[str]]  # other columns -> raw text per row
    scalar_lines: int  # 1-based line of the column names (for messages)
    row_lines: list[int]  # 1-based line of each data row


def header_lookup(header: Mapping[str, str], *names: str) -> str | None:
    """The value of the first header key whose normalised form is one of `names`."""
    wanted = {normalise_key(n) for n in names}
    for key, value in header.items():
        if normalise_key(key) in wanted:
            return value
    return None


def header_angle(header: Mapping[str, str], path: Path, *names: str) -> float:
    """A header angle in degrees; NaN when absent or `NA`."""
    value = header_lookup(header, *names)
    if value is None:
        return float("nan")
    try:
        return parse_float(value)
    except ValueError:
        raise file_error(
            path, None, f"header {names[0]!r}: expected a number or NA, found {value!r}"
        ) from None


def read_windcube(path: str | Path, quantities: Mapping[str, str], what: str) -> Parsed:
    """Stream a Windcube text file; per-altitude columns named in `quantities` are mapped.

    `quantities` maps normalised quantity names (`normalise_key("Wind Speed (m/s)")`
    is `"windspeed"`) to record field names.
    """
    p = require_file(path, what)
    header: dict[str, str] = {}
    header_line_of: dict[str, int] = {}
    with open(p, encoding=ENCODING, errors="replace", newline=None) as fh:
        first = fh.readline()
        m = _FIRST_LINE.match(first.rstrip("\r\n"))
        if not m:
            raise file_error(
                p, 1, "expected 'HeaderSize=N' (Windcube V2) or 'HeaderLength=N' (V1), "
                f"found {first.strip()[:60]!r}"
            )
        version = "V2" if m.group(1).lower() == "headersize" else "V1"
        n_header = int(m.group(2))
        number = 1
        columns: list[str] | None = None

        def take_header_line(text: str, line_no: int) -> bool:
            """Record a header line; True if it is the column-names line instead."""
            stripped = text.strip()
            if not stripped or set(stripped) <= {"*"}:
                return False
            if "=" in stripped:
                key, _, value = stripped.partition("=")
                header[key.strip()] = value.strip()
                header_line_of[key.strip()] = line_no
                return False
            return _is_time_name(text.split("\t", 1)[0])

        for _ in range(n_header):
            raw = fh.readline()
            if raw == "":
                raise file_error(
                    p, number, f"the header announced {n_header} lines but the file ends"
                )
            number += 1
            line = raw.rstrip("\r\n")
            if take_header_line(line, number):  # header shorter than announced
                columns = line.split("\t")
                break
        while columns is None:
            raw = fh.readline()
            if raw == "":
                raise file_error(p, number, "expected the column-names line; the file ends")
            number += 1
            line = raw.rstrip("\r\n")
            if take_header_line(line, number):
                columns = line.split("\t")
            elif line.strip() and "=" not in line and set(line.strip()) - {"*"}:
                raise file_error(
                    p, number, "expected the column-names line starting with 'Timestamp' "
                    f"or 'Date', found {line.strip()[:60]!r}"
                )
        column_line = number

        # Heights: from the header when given, else from the columns.
        header_heights: list[float] | None = None
        alt_value = header_lookup(header, "Altitudes (m)")
        if alt_value is not None:
            alt_key = next(k for k in header if normalise_key(k) == "altitudes")
            try:
                header_heights = [float(a) for a in alt_value.split()]
            except ValueError:
                raise file_error(
                    p, header_line_of[alt_key], f"'{alt_key}': expected altitudes in metres, "
                    f"found {alt_value!r}"
                ) from None

        time_col = next((i for i, c in enumerate(columns) if _is_time_name(c)), None)
        if time_col is None:
            raise file_error(p, column_line, "no timestamp column ('Timestamp' or 'Date')")
        mapped: list[tuple[int, float, str]] = []  # (column, altitude, quantity key)
        scalar_cols: dict[str, int] = {}
        seen: dict[tuple[float, str], str] = {}
        for i, name in enumerate(columns):
            if i == time_col or not name.strip():
                continue
            am = _ALTITUDE_COLUMN.match(name)
            if am is None:
                scalar_cols[name.strip()] = i
                continue
            altitude = float(am.group(1))
            key = normalise_key(am.group(2))
            if not key:
                raise file_error(p, column_line, f"column {name!r}: no quantity after the altitude")
            if (altitude, key) in seen:
                raise file_error(
                    p, column_line, f"columns {seen[(altitude, key)]!r} and {name!r} give the "
                    "same quantity at the same altitude"
                )
            seen[(altitude, key)] = name
            if header_heights is not None and altitude not in header_heights:
                raise file_error(
                    p, column_line, f"column {name!r}: altitude {am.group(1)} m is not in the "
                    f"header's altitudes {' '.join(alt_value.split()) if alt_value else ''}"
                )
            mapped.append((i, altitude, key))

        altitudes = set(header_heights) if header_heights is not None else {a for _, a, _ in mapped}
        heights = np.array(sorted(altitudes), dtype=np.float64)
        value_cols = [i for i, _, _ in mapped]
        value_names = [columns[i] for i in value_cols]
        scalar_items = list(scalar_cols.items())
        needed = max([time_col, *value_cols, *scalar_cols.values()]) + 1

        parse_time = TimeParser(TIME_FORMATS)
        times: list[_dt.datetime] = []
        row_lines: list[int] = []
        rows: list[np.ndarray] = []
        scalars: dict[str, list[str]] = {name: [] for name in scalar_cols}
        for raw in fh:
            number += 1
            line = raw.rstrip("\r\n")
            if not line.strip():
                continue
            fields = line.split("\t")
            if len(fields) < needed:
                raise file_error(
                    p, number, f"expected at least {needed} tab-separated fields, "
                    f"found {len(fields)}"
                )
            try:
                times.append(parse_time(fields[time_col]))
            except ValueError as err:
                raise file_error(p, number, f"column {columns[time_col]!r}: {err}") from None
            rows.append(parse_row(fields, value_cols, value_names, p, number))
            for name, col in scalar_items:
                scalars[name].append(fields[col].strip())
            row_lines.append(number)

    table = np.array(rows, dtype=np.float64).reshape(len(rows), len(value_cols))
    index = {h: j for j, h in enumerate(heights.tolist())}
    out: dict[str, np.ndarray] = {}
    extra: dict[str, np.ndarray] = {}
    for c, (_, altitude, key) in enumerate(mapped):
        target = out if key in quantities else extra
        name = quantities.get(key, key)
        if name not in target:
            target[name] = np.full((len(rows), heights.size), np.nan)
        target[name][:, index[altitude]] = table[:, c]
    return Parsed(
        path=p,
        version=version,
        header=header,
        heights=heights,
        time=times,
        quantities=out,
        extra=extra,
        scalars=scalars,
        scalar_lines=column_line,
        row_lines=row_lines,
    )


def scalar_arrays(scalars: Mapping[str, list[str]]) -> dict[str, np.ndarray]:
    """Numeric columns as float64 `(t,)` (empty/NA -> NaN); any other column as text."""
    out: dict[str, np.ndarray] = {}
    for name, values in scalars.items():
        try:
            out[name] = np.array([parse_float(v) for v in values], dtype=np.float64)
        except ValueError:
            out[name] = np.array(values, dtype=str)
    return out
