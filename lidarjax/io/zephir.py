"""ZephIR 10-minute CSV exports: `read_zephir_csv` and `ZephirRecord`.

Two dialects are read, detected from the header line:

- `;`-separated with decimal commas (`12,34`), typical of European locale exports;
- `,`-separated with decimal points.

(Tab-separated exports are accepted too.) Optional preamble lines before the header are
kept. The header names a time column (`Time and Date`, `Timestamp`, `Date and Time`;
formats `%d/%m/%Y %H:%M:%S`, `%Y-%m-%d %H:%M:%S`, with or without seconds) and per-height
columns such as `Horizontal Wind Speed (m/s) at 38m`, `Wind Direction (deg) at 38m`,
`Vertical Wind Speed (m/s) at 38m`: the height is found with the regular expression
`(\\d+(\\.\\d+)?)\\s*m` (the last such match not followed by a letter), the quantity
is the rest of the name, normalised. ZephIR writes 9998 and 9999 for missing data (and
other error codes near them); these, empty fields, `NaN` and `NA` become NaN.

Wind direction is as exported: meteorological (from, degrees clockwise from north);
vertical wind speed positive up.
"""

from __future__ import annotations

import csv
import dataclasses
import datetime as _dt
import re
from typing import Any

import numpy as np
from jaxtyping import Float, Shaped

from ._common import (
    PathLike,
    file_error,
    freeze,
    import_optional,
    normalise_key,
    require_file,
)
from ._windcube import TimeParser

__all__ = ["ZEPHIR_MISSING", "ZephirRecord", "read_zephir_csv"]

ZEPHIR_MISSING: tuple[float, ...] = (9998.0, 9999.0)
"""Values ZephIR writes for missing data; read as NaN."""

TIME_FORMATS: tuple[str, ...] = (
    "%d/%m/%Y %H:%M:%S",
    "%Y-%m-%d %H:%M:%S",
    "%d/%m/%Y %H:%M",
    "%Y-%m-%d %H:%M",
    "%Y/%m/%d %H:%M:%S",
    "%Y/%m/%d %H:%M",
    "%Y-%m-%dT%H:%M:%S",
    "%d.%m.%Y %H:%M:%S",
    "%d.%m.%Y %H:%M",
)

_TIME_NAMES = ("timeanddate", "timestamp", "dateandtime", "datetime", "date", "time")
_HEIGHT = re.compile(r"(\d+(\.\d+)?)\s*m(?![a-z/])", re.IGNORECASE)
_ZEPHIR_NAMES: dict[str, tuple[str, ...]] = {
    "speed": ("Horizontal Wind Speed", "Wind Speed", "Hub Wind Speed"),
    "direction": ("Wind Direction", "Direction"),
    "w": ("Vertical Wind Speed", "Vertical Wind", "Z Wind Speed"),
}
ZEPHIR_QUANTITIES: dict[str, str] = {
    normalise_key(n): field for field, names in _ZEPHIR_NAMES.items() for n in names
}
ZEPHIR_FIELDS: tuple[str, ...] = ("speed", "direction", "w")


@dataclasses.dataclass(frozen=True, eq=False)
class ZephirRecord:
    """A ZephIR 10-minute record (`read_zephir_csv`). Arrays are read-only.

    Dimensions: `t` intervals, `k` heights.

    **Fields:**

    - `path`; `delimiter` (`;`, `,` or tab) and `decimal` (`,` or `.`) as detected;
      `preamble`: lines before the header.
    - `time`: `(t,)` `datetime64[s]`, as exported (ZephIR stamps usually the interval end).
    - `heights`: `(k,)` metres above the instrument, ascending.
    - `speed`: `(t, k)` horizontal wind speed, m/s.
    - `direction`: `(t, k)` wind direction, degrees, meteorological (from, clockwise from
      north).
    - `w`: `(t, k)` vertical wind speed, m/s, positive up.
    - `missing`: which of these the file lacks (NaN-filled).
    - `extra`: other per-height numeric quantities, normalised name -> `(t, k)`.
    - `scalars`: other columns, name as written -> `(t,)` float64 (9998/9999 -> NaN), or
      text when not numeric.
    """

    path: str
    delimiter: str
    decimal: str
    preamble: tuple[str, ...]
    time: Shaped[np.ndarray, " t"]
    heights: Float[np.ndarray, " k"]
    speed: Float[np.ndarray, "t k"]
    direction: Float[np.ndarray, "t k"]
    w: Float[np.ndarray, "t k"]
    missing: tuple[str, ...]
    extra: dict[str, Float[np.ndarray, "t k"]]
    scalars: dict[str, Shaped[np.ndarray, " t"]]

    def __post_init__(self) -> None:
        t, k = self.time.shape[0], self.heights.shape[0]
        for name in ZEPHIR_FIELDS:
            if getattr(self, name).shape != (t, k):
                raise ValueError(f"{name} must have shape (t, k) = ({t}, {k})")

    def to_pandas(self) -> Any:
        """A **long** `pandas.DataFrame`: one row per (interval, height).

        Columns `time`, `height` (m), `speed` (m/s), `direction` (deg), `w` (m/s); rows
        ordered by time then height. Needs pandas (`pip install lidarjax[pandas]`).
        """
        pd = import_optional("pandas", "pandas", "ZephirRecord.to_pandas")
        t, k = self.speed.shape
        data: dict[str, Any] = {
            "time": np.repeat(self.time, k),
            "height": np.tile(self.heights, t),
        }
        for name in ZEPHIR_FIELDS:
            data[name] = getattr(self, name).reshape(-1)
        return pd.DataFrame(data)


def _plain(name: str) -> str:
    """Lower-case alphanumerics only, units kept: 'Timestamp (seconds)' -> 'timestampseconds'."""
    return re.sub(r"[^0-9a-z]", "", name.lower())


def _height_of(name: str) -> tuple[float, str] | None:
    matches = list(_HEIGHT.finditer(name))
    if not matches:
        return None
    m = matches[-1]
    rest = (name[: m.start()] + " " + name[m.end():]).strip()
    rest = re.sub(r"\s+at\s*$", "", rest, flags=re.IGNORECASE)  # "... at 38m"
    return float(m.group(1)), normalise_key(rest)


def _value(text: str, decimal: str) -> float:
    t = text.strip()
    if t == "" or t.upper() in ("NA", "N/A", "NAN"):
        return float("nan")
    if decimal == ",":
        t = t.replace(",", ".")
    v = float(t)
    return float("nan") if v in ZEPHIR_MISSING else v


def _detect(header_line: str) -> tuple[str, str]:
    if "\t" in header_line:
        return "\t", "."
    if header_line.count(";") > 0:
        return ";", ","
    return ",", "."


def read_zephir_csv(path: PathLike) -> ZephirRecord:
    """Read a ZephIR 10-minute CSV export (`;` + decimal comma, or `,` + decimal point).

    The file is streamed (UTF-8, with or without BOM; undecodable bytes are replaced).
    See the module docstring for the accepted columns.

    **Returns:** a `ZephirRecord` (fields, units and conventions there).

    Raises `FileNotFoundError` for a missing path, and `ValueError` naming the file, the
    line and the problem for: no header line with a time column, no per-height columns,
    two columns with the same quantity and height, a row with the wrong number of
    fields, an unparseable timestamp, or a non-numeric per-height value. With `;` as
    delimiter, a `;`-decimal-`.` file is also read (points are accepted as decimals).
    """
    p = require_file(path, "ZephIR CSV file")
    preamble: list[str] = []
    with open(p, encoding="utf-8-sig", errors="replace", newline="") as fh:
        number = 0
        header: list[str] | None = None
        delimiter, decimal = ",", "."
        for raw in fh:
            number += 1
            line = raw.rstrip("\r\n")
            delimiter, decimal = _detect(line)
            cells = next(csv.reader([line], delimiter=delimiter))
            if any(_plain(c) in _TIME_NAMES for c in cells):
                header = [c.strip() for c in cells]
                break
            preamble.append(line)
            if number >= 200:
                break
        if header is None:
            raise file_error(
                p, None, "no header line naming a time column ('Time and Date' or "
                "'Timestamp') in the first 200 lines"
            )
        header_line = number
        keys = [_plain(c) for c in header]
        time_col = next(
            i for name in _TIME_NAMES for i, key in enumerate(keys) if key == name
        )
        per_height: list[tuple[int, float, str]] = []
        scalar_cols: list[int] = []
        seen: dict[tuple[float, str], str] = {}
        for i, name in enumerate(header):
            if i == time_col or not name:
                continue
            hq = _height_of(name)
            if hq is None or not hq[1]:
                scalar_cols.append(i)
                continue
            if hq in seen:
                raise file_error(
                    p, header_line, f"columns {seen[hq]!r} and {name!r} give the same "
                    "quantity at the same height"
                )
            seen[hq] = name
            per_height.append((i, *hq))
        if not per_height:
            raise file_error(
                p, header_line, "no per-height columns such as 'Horizontal Wind Speed (m/s) "
                "at 38m'"
            )
        heights = np.array(sorted({h for _, h, _ in per_height}), dtype=np.float64)
        parse_time = TimeParser(TIME_FORMATS)
        times: list[_dt.datetime] = []
        rows: list[list[float]] = []
        scalar_text: list[list[str]] = []
        reader = csv.reader(fh, delimiter=delimiter)
        for cells in reader:
            line_no = header_line + reader.line_num
            if not cells or all(not c.strip() for c in cells):
                continue
            if len(cells) < len(header):
                raise file_error(
                    p, line_no, f"expected {len(header)} fields separated by "
                    f"{delimiter!r}, found {len(cells)}"
                )
            try:
                times.append(parse_time(cells[time_col]))
            except ValueError as err:
                raise file_error(p, line_no, f"column {header[time_col]!r}: {err}") from None
            row = []
            for i, _, _ in per_height:
                try:
                    row.append(_value(cells[i], decimal))
                except ValueError:
                    # a ';' file written with decimal points still parses
                    try:
                        row.append(_value(cells[i], "."))
                    except ValueError:
                        raise file_error(
                            p, line_no, f"column {header[i]!r}: expected a number, "
                            f"found {cells[i].strip()!r}"
                        ) from None
            rows.append(row)
            scalar_text.append([cells[i] for i in scalar_cols])

    t, k = len(rows), heights.size
    table = np.array(rows, dtype=np.float64).reshape(t, len(per_height))
    index = {h: j for j, h in enumerate(heights.tolist())}
    quantities: dict[str, np.ndarray] = {}
    extra: dict[str, np.ndarray] = {}
    for c, (_, h, key) in enumerate(per_height):
        field = ZEPHIR_QUANTITIES.get(key)
        target, name = (quantities, field) if field else (extra, key)
        if name not in target:
            target[name] = np.full((t, k), np.nan)
        target[name][:, index[h]] = table[:, c]
    fields = {}
    missing = []
    for name in ZEPHIR_FIELDS:
        if name in quantities:
            fields[name] = freeze(quantities[name])
        else:
            fields[name] = freeze(np.full((t, k), np.nan))
            missing.append(name)
    scalars: dict[str, np.ndarray] = {}
    for j, col in enumerate(scalar_cols):
        values = [r[j] for r in scalar_text]
        try:
            arr = np.array([_value(v, decimal) for v in values], dtype=np.float64)
        except ValueError:
            arr = np.array([v.strip() for v in values], dtype=str)
        scalars[header[col]] = freeze(arr)
    return ZephirRecord(
        path=str(p),
        delimiter=delimiter,
        decimal=decimal,
        preamble=tuple(preamble),
        time=freeze(np.array(times, dtype="datetime64[s]").reshape(t)),
        heights=freeze(heights),
        **fields,
        missing=tuple(missing),
        extra={n: freeze(a) for n, a in extra.items()},
        scalars=scalars,
    )
