"""ZephIR 10-minute CSV exports: `read_zephir_csv` and `ZephirRecord`.

Two dialects are read, detected from the header line:

- `;`-separated with decimal commas (`12,34`), typical of European locale exports;
- `,`-separated with decimal points.

(Tab-separated exports are accepted too.) Preamble lines before the header are kept and
read for the time conventions:

- **time-stamp position**: ZephIR 300 and ZX exports stamp the **start** of the averaging
  period (the default); a preamble or time-column text such as `end of period` /
  `Timestamp (end of interval)` switches to end-stamped;
- **time zone**: `UTC+01:00`, `GMT-3`, `Time Zone: UTC-05:00` ... in the preamble or in the
  time column's name (`Timestamp (UTC+1)`); none found means UTC (a note says so);
- **averaging period**: `Averaging period: 10 min` / `... 60 s`; else the rows' median
  spacing; else 10 minutes.

`ZephirRecord.time` is always **UTC, end of interval** (start-stamped rows shifted by the
period, the zone offset removed); `time_local` keeps the stamps as written.

The header names a time column (`Time and Date`, `Timestamp`, `Date and Time`;
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
import re
import warnings
from typing import Any

import numpy as np
from jaxtyping import Float, Shaped

from .._util import PathLike, file_error, freeze, import_optional, normalise_key, require_file
from ..flags import BLOCKING_FLAGS, MIN_AVAILABILITY, RecordFlag
from ._common import ends_with_line_end, offset_timedelta, parse_times, parse_utc_offset, read_text
from ._records import (
    drop_cut_last_row,
    duplicate_times,
    infer_bad_times,
    per_height_arrays,
    present_fields,
    regular_step,
    row_flags,
    warn_corrupt_rows,
)
from .record_set import DIRECTION_STD_KEYS, RecordSet, extra_column, reader_flags

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

_TIME_NAMES = ("timeanddate", "timestamp", "dateandtime", "datetime", "date", "time",
               "timestampendofinterval", "timestampstartofinterval")
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
    - `time`: `(t,)` `datetime64[s]`, **UTC, end of interval** (see the module docstring).
    - `heights`: `(k,)` metres above the instrument, ascending.
    - `speed`: `(t, k)` horizontal wind speed, m/s.
    - `direction`: `(t, k)` wind direction, degrees, meteorological (from, clockwise from
      north).
    - `w`: `(t, k)` vertical wind speed, m/s, positive up.
    - `missing`: which of these the file lacks (NaN-filled).
    - `extra`: other per-height numeric quantities, normalised name -> `(t, k)`.
    - `scalars`: other columns, name as written -> `(t,)` float64 (9998/9999 -> NaN), or
      text when not numeric.
    - `instrument`: `"zephir"`; `model`: `"zx"` / `"zephir_300"` / `""` from the preamble.
    - `time_convention`: how the **file** stamps rows (`"start"` or `"end"`; `time` is
      always end); `timezone`: the zone text found; `utc_offset_hours`: hours east of UTC.
    - `time_local`: `(t,)` the stamps as written; `period`: the averaging period.
    - `flags`: `(t, k)` `RecordFlag` bits (corrupt row, impossible value, duplicate time);
      flagged values are NaN. `row_lines`: `(t,)` 1-based lines; `warnings`: messages.
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
    instrument: str = "zephir"
    model: str = ""
    time_convention: str = "start"
    timezone: str = ""
    utc_offset_hours: float = 0.0
    time_local: Any = None
    period: Any = None
    flags: Any = None
    row_lines: Any = None
    warnings: tuple[str, ...] = ()

    @property
    def valid(self) -> Any:
        """`(t, k)` True where speed and direction are finite and no blocking flag is set."""
        flags = 0 if self.flags is None else self.flags
        return (np.isfinite(self.speed) & np.isfinite(self.direction)
                & ((flags & int(BLOCKING_FLAGS)) == 0))

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

    def to_record_set(self, *, min_availability: float = MIN_AVAILABILITY) -> RecordSet:
        """This record as a `lidarjax.io.RecordSet` (kind ``"zephir"``), for correction.

        From the exported per-height columns (`extra`), when present: `speed_std` from a
        speed standard deviation, else ``TI * speed`` (TI as a fraction, or in percent when
        above 1); `direction_std` from a direction dispersion; `n_samples` from ``Packets in
        Average``; `availability` (percent) from a data availability column, records below
        `min_availability` percent flagged LOW_AVAILABILITY (and NaN).
        """
        speed_std = extra_column(self.extra, "horizontalwindspeedstd", "windspeedstd",
                                 "horizontalwindspeedsd")
        ti = extra_column(self.extra, "ti", "turbulenceintensity", "horizontalti")
        if speed_std is None and ti is not None:
            frac = ti if np.nanmax(np.abs(ti), initial=0.0) <= 1.0 else ti / 100.0
            speed_std = frac * np.asarray(self.speed, np.float64)
        availability = extra_column(self.extra, "dataavailability", "availability")
        flags = reader_flags(self.flags, np.shape(self.speed))
        if availability is not None:
            flags |= np.where(availability < min_availability,
                              int(RecordFlag.LOW_AVAILABILITY), 0)
        return RecordSet.reported(
            "zephir", self.path, self.instrument, self.time, self.heights, self.speed,
            self.direction, flags, period=self.period, speed_std=speed_std,
            direction_std=extra_column(self.extra, *DIRECTION_STD_KEYS),
            availability=availability,
            n_samples=extra_column(self.extra, "packetsinaverage", "packets", "validpackets"),
            warnings=tuple(self.warnings))


def _plain(name: str) -> str:
    """Lower-case alphanumerics, units dropped ('Timestamp (UTC+1)' -> 'timestamp') except a
    seconds unit, which marks a numeric column ('Timestamp (seconds)' -> 'timestampseconds')."""
    if re.search(r"\(\s*(s|sec|secs|seconds)\s*\)", name, re.IGNORECASE):
        return re.sub(r"[^0-9a-z]", "", name.lower())
    return normalise_key(name)


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


def _is_missing(text: str, decimal: str) -> bool:
    """Whether `text` is one of ZephIR's missing-data codes (9998, 9999, ...)."""
    try:
        return float(text.strip().replace(decimal, ".")) in ZEPHIR_MISSING
    except ValueError:
        return False


def _detect(header_line: str) -> tuple[str, str]:
    if "\t" in header_line:
        return "\t", "."
    if header_line.count(";") > 0:
        return ";", ","
    return ",", "."


_START = re.compile(r"(start|beginning)\s+of\s+(the\s+)?(averag\w*\s+)?(period|interval|"
                    r"averag)", re.IGNORECASE)
_END = re.compile(r"end\s+of\s+(the\s+)?(averag\w*\s+)?(period|interval|averag)",
                  re.IGNORECASE)
_AVERAGING = re.compile(r"averag\w*[^0-9\n]{0,30}?(\d+(?:\.\d+)?)\s*(s|sec|seconds|min|"
                        r"minutes|mins)\b", re.IGNORECASE)

_AVERAGING_UNIT_FIRST = re.compile(r"averag\w*[^0-9\n(]{0,30}\(\s*(s|sec|seconds|min|minutes)"
                                   r"\s*\)[^0-9\n]{0,5}(\d+(?:\.\d+)?)", re.IGNORECASE)


def _conventions(texts: list[str], path) -> tuple[str, str, float, float | None, list[str]]:
    """(convention, zone text, offset hours, period seconds or None, notes) from texts."""
    notes: list[str] = []
    joined = "\n".join(texts)
    convention = "start"
    if _END.search(joined) and not _START.search(joined):
        convention = "end"
    zone, offset = "", None
    for t in texts:
        if re.search(r"UTC|GMT|time\s*zone", t, re.IGNORECASE):
            off = parse_utc_offset(t)
            if off is not None:
                zone, offset = t.strip()[:80], off
                break
    if offset is None:
        offset = 0.0
        notes.append(f"{path}: no time zone (e.g. 'UTC+01:00') in the preamble or the time "
                     "column; times taken as UTC")
    period = None
    m = _AVERAGING.search(joined)
    u = _AVERAGING_UNIT_FIRST.search(joined)
    if u:
        period = float(u.group(2)) * (60.0 if u.group(1).lower().startswith("m") else 1.0)
    elif m:
        period = float(m.group(1)) * (60.0 if m.group(2).lower().startswith("m") else 1.0)
    return convention, zone, offset, period, notes


def read_zephir_csv(
    path: PathLike,
    *,
    time_convention: str | None = None,
    utc_offset_hours: float | None = None,
) -> ZephirRecord:
    """Read a ZephIR 300 / ZX 10-minute CSV export (`;` + decimal comma, or `,` + point).

    UTF-8 (with or without BOM) or cp1252. See the module docstring for the accepted
    columns and the time conventions read from the preamble.

    **Arguments:**

    - `path`: the file.
    - `time_convention`: `"start"` or `"end"` to override what the file says.
    - `utc_offset_hours`: hours east of UTC to override the file's zone.

    **Returns:** a `ZephirRecord`: times UTC, end of interval.

    A corrupt row (wrong field count, unreadable time stamp, non-numeric per-height cell)
    becomes a record of NaN flagged `RecordFlag.CORRUPT_ROW` (time inferred from regular
    neighbours, or the row left out) with one `UserWarning` naming the file and lines;
    negative speeds and directions outside [0, 360] are flagged `IMPOSSIBLE_VALUE` and set
    NaN. A last row cut inside its last field (no line end after it, that field in another
    format than the column above; a missing code such as 9999 is taken as whole) is left out
    with its own one-line warning. Raises `FileNotFoundError` for a missing path, and a
    one-line `ValueError` naming the file, the line and the fix for: an empty, binary or
    UTF-16 file, no header line with a time column, no per-height columns, or a bad override.
    """
    _check_overrides(time_convention, utc_offset_hours)
    p = require_file(path, "ZephIR CSV file")
    text = read_text(p)
    lines = text.splitlines()
    if re.match(r"^\s*(HeaderSize|HeaderLength)\s*=", lines[0].lstrip("\ufeff"), re.IGNORECASE):
        raise file_error(p, 1, "this is a Windcube file (HeaderSize=/HeaderLength=), not a "
                         "ZephIR CSV export; read it with read_sta or read_rtd")
    preamble, header, header_line, delimiter, decimal = _find_header(p, lines)
    time_col, second_col, per_height, scalar_cols, notes = _map_columns(p, header, header_line)
    cut = drop_cut_last_row(p, lines, header_line, ends_with_line_end(text),
                            lambda ln: next(csv.reader([ln], delimiter=delimiter), []),
                            stacklevel=2, missing=lambda f: _is_missing(f, decimal))
    del text
    convention, zone, offset, period_s, notes = _time_conventions(
        p, preamble, header[time_col], notes, time_convention, utc_offset_hours)
    heights = np.array(sorted({h for _, h, _ in per_height}), dtype=np.float64)
    cells_list, row_lines, local, time_ok, values, row_ok, problems = _read_rows(
        lines[header_line:], header_line, header, delimiter, decimal, time_col, second_col,
        per_height)
    step = regular_step(local, time_ok)
    local, inferred, keep = infer_bad_times(local, time_ok, step)
    if period_s is None:
        period = step if step is not None else np.timedelta64(600_000, "ms")
    else:
        period = np.timedelta64(int(round(period_s * 1000)), "ms")
    t, k = int(keep.sum()), heights.size
    quantities, extra = per_height_arrays(per_height, values[keep], heights,
                                          ZEPHIR_QUANTITIES.get)
    fields, missing = present_fields(quantities, ZEPHIR_FIELDS, (t, k))
    local = local[keep]
    flags = _flag_values(fields, row_flags(row_ok, inferred, keep, k), local)
    utc_end = local - offset_timedelta(offset)
    if convention == "start":
        utc_end = utc_end + period
    messages = warn_corrupt_rows(p, problems, "record", stacklevel=2) + ([cut] if cut else [])
    for note in notes:
        if "same quantity" in note:
            warnings.warn(note, stacklevel=2)
    return ZephirRecord(
        path=str(p),
        delimiter=delimiter,
        decimal=decimal,
        preamble=tuple(preamble),
        time=freeze(utc_end.astype("datetime64[s]")),
        heights=freeze(heights),
        **{n_: freeze(a) for n_, a in fields.items()},
        missing=tuple(missing),
        extra={n_: freeze(a) for n_, a in extra.items()},
        scalars=_scalar_columns(header, scalar_cols, cells_list, keep, decimal),
        model=_model(preamble),
        time_convention=convention,
        timezone=zone,
        utc_offset_hours=float(offset),
        time_local=freeze(local.astype("datetime64[s]")),
        period=period.astype("timedelta64[s]"),
        flags=freeze(flags),
        row_lines=freeze(row_lines[keep]),
        warnings=tuple(messages + notes),
    )


def _flag_values(fields: dict[str, np.ndarray], flags: np.ndarray,
                 local: np.ndarray) -> np.ndarray:
    """`flags` with `IMPOSSIBLE_VALUE` where a speed is negative or a direction outside
    [0, 360] (those values set NaN in `fields`) and `DUPLICATE_TIME` on a repeated stamp."""
    with np.errstate(invalid="ignore"):
        impossible = ((fields["speed"] < 0) | (fields["direction"] < 0)
                      | (fields["direction"] > 360))
    flags[impossible] |= int(RecordFlag.IMPOSSIBLE_VALUE)
    for name in ZEPHIR_FIELDS:
        fields[name][impossible] = np.nan
    flags[duplicate_times(local)] |= int(RecordFlag.DUPLICATE_TIME)
    return flags


def _check_overrides(time_convention: str | None, utc_offset_hours: float | None) -> None:
    if time_convention not in (None, "start", "end"):
        raise ValueError(f"time_convention must be 'start' or 'end', got {time_convention!r}")
    if utc_offset_hours is not None and not (np.isfinite(utc_offset_hours)
                                             and abs(utc_offset_hours) <= 14):
        raise ValueError(f"utc_offset_hours must be finite and within +-14 h, got "
                         f"{utc_offset_hours!r}")


def _find_header(p, lines: list[str]):
    """`(preamble lines, header cells, its 1-based line, delimiter, decimal)`: the first line
    (of 200) naming a time column and a per-height column, else the first naming a time
    column."""
    preamble: list[str] = []
    header: list[str] | None = None
    delimiter, decimal = ",", "."
    header_line = 0
    candidate = None  # a line naming a time column but no height: used if nothing better
    for number, line in enumerate(lines[:200], start=1):
        delimiter, decimal = _detect(line)
        cells = next(csv.reader([line], delimiter=delimiter), [])
        if any(_plain(c) in _TIME_NAMES for c in cells):
            if any(_height_of(c) for c in cells):
                header = [c.strip() for c in cells]
                header_line = number
                break
            if candidate is None:
                candidate = (number, delimiter, decimal, [c.strip() for c in cells])
        preamble.append(line)
    if header is None and candidate is not None:
        header_line, delimiter, decimal, header = candidate
        preamble = preamble[: header_line - 1]
    if header is None:
        raise file_error(
            p, None, "no header line naming a time column ('Time and Date' or "
            "'Timestamp') in the first 200 lines; is this a ZephIR 10-minute CSV export?"
        )
    return preamble, header, header_line, delimiter, decimal


def _map_columns(p, header: list[str], header_line: int):
    """`(time column, separate 'Time' column or None, per-height columns as (column, height,
    quantity key), other columns, notes)`."""
    keys = [_plain(c) for c in header]
    time_col = next(i for name in _TIME_NAMES for i, key in enumerate(keys) if key == name)
    second_col = None  # a separate 'Time' column beside 'Date'
    if keys[time_col] == "date" and "time" in keys:
        second_col = keys.index("time")
    per_height: list[tuple[int, float, str]] = []
    scalar_cols: list[int] = []
    seen: dict[tuple[float, str], str] = {}
    notes: list[str] = []
    for i, name in enumerate(header):
        if i in (time_col, second_col) or not name:
            continue
        hq = _height_of(name)
        if hq is None or not hq[1]:
            scalar_cols.append(i)
            continue
        if hq in seen:
            notes.append(f"{p}, line {header_line}: columns {seen[hq]!r} and {name!r} give "
                         f"the same quantity at {hq[0]:g} m; the second is kept as "
                         f"extra[{hq[1] + '#2'!r}]")
            hq = (hq[0], hq[1] + "#2")
        seen[hq] = name
        per_height.append((i, *hq))
    if not per_height:
        raise file_error(
            p, header_line, "no per-height columns such as 'Horizontal Wind Speed (m/s) "
            "at 38m'"
        )
    return time_col, second_col, per_height, scalar_cols, notes


def _time_conventions(p, preamble, time_name, notes, time_convention, utc_offset_hours):
    """`(convention, zone text, offset hours, period seconds or None, notes)` read from the
    preamble and the time column's name (`_conventions`), the overrides applied."""
    convention, zone, offset, period_s, conv_notes = _conventions([*preamble, time_name], p)
    notes = notes + conv_notes
    if time_convention is not None:
        convention = time_convention
    if utc_offset_hours is not None:
        offset, zone = float(utc_offset_hours), f"UTC{utc_offset_hours:+g} (given)"
        notes = [n for n in notes if "no time zone" not in n]
    return convention, zone, offset, period_s, notes


def _model(preamble: list[str]) -> str:
    """`"zx"`, `"zephir_300"` or `""`, from the preamble."""
    pre = "\n".join(preamble).lower()
    if "zx" in pre:
        return "zx"
    if "zephir" in pre or "z300" in pre:
        return "zephir_300"
    return ""


def _read_rows(body_lines, header_line, header, delimiter, decimal, time_col, second_col,
               per_height):
    """The data rows (blank ones skipped): `(cells, 1-based lines, local times, time_ok,
    per-height values, row_ok, problems)`; a bad row's values are NaN and `problems` says
    why."""
    body = [(n, ln) for n, ln in enumerate(body_lines, start=header_line + 1)
            if ln.strip(" \t,;")]
    cells_list = list(csv.reader([ln for _, ln in body], delimiter=delimiter))
    row_lines = np.array([ln for ln, _ in body], dtype=np.int64)
    stamps = []
    for cells in cells_list:
        stamp = cells[time_col] if len(cells) > time_col else ""
        if second_col is not None and len(cells) > second_col:
            stamp = f"{stamp} {cells[second_col]}"
        stamps.append(stamp)
    local, time_ok = parse_times(stamps)
    values = np.full((len(body), len(per_height)), np.nan)
    row_ok = time_ok.copy()
    problems: list[tuple[int, str]] = []
    for r, cells in enumerate(cells_list):
        if len(cells) < len(header):
            why = f"expected {len(header)} fields separated by {delimiter!r}, found {len(cells)}"
        elif len(cells) > len(header) and any(c.strip() for c in cells[len(header):]):
            why = f"more fields than the {len(header)} columns (shifted row)"
        elif not time_ok[r]:
            why = f"unreadable time stamp {stamps[r].strip()[:40]!r}"
        else:
            why = _row_values(values[r], cells, header, per_height, decimal)
        if why is not None:
            row_ok[r] = False
            values[r] = np.nan
            problems.append((int(row_lines[r]), why))
    return cells_list, row_lines, local, time_ok, values, row_ok, problems


def _row_values(out: np.ndarray, cells: list[str], header: list[str], per_height,
                decimal: str) -> str | None:
    """Fill `out` with the row's per-height values; None, or why a cell is not a number."""
    for c, (i, _, _) in enumerate(per_height):
        try:
            out[c] = _value(cells[i], decimal)
        except ValueError:
            try:  # a ';' file written with decimal points still parses
                out[c] = _value(cells[i], ".")
            except ValueError:
                return (f"column {header[i]!r}: expected a number, found "
                        f"{cells[i].strip()[:30]!r}")
    return None


def _scalar_columns(header, scalar_cols, cells_list, keep, decimal) -> dict[str, np.ndarray]:
    """The other columns of the rows kept: float64 (9998/9999 -> NaN), or text when not
    numeric; a repeated name gets `#2`."""
    scalars: dict[str, np.ndarray] = {}
    for col in scalar_cols:
        vals = [cells[col] if len(cells) > col else "" for cells, kk in zip(
            cells_list, keep, strict=True) if kk]
        try:
            arr = np.array([_value(v, decimal) for v in vals], dtype=np.float64)
        except ValueError:
            arr = np.array([v.strip() for v in vals], dtype=str)
        name = header[col]
        while name in scalars:
            name += "#2"
        scalars[name] = freeze(arr)
    return scalars
