"""Steps shared by the record readers (Windcube `.sta`/`.rtd`, ZephIR CSV): per-height
arrays from mapped columns, missing fields, row flags, bad time stamps, one warning for the
corrupt rows.

Private to `lidarjax.io`; nothing here is public API.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping, Sequence

import numpy as np

from .._util import summarise_lines
from ..flags import RecordFlag
from ._common import field_cut

__all__: list[str] = []


def per_height_arrays(
    columns: Sequence[tuple[int, float, str]],
    values: np.ndarray,
    heights: np.ndarray,
    field_of: Callable[[str], str | None],
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Scatter the value columns `(t, c)` of `columns` (`(column, height, quantity key)`)
    into `(t, k)` arrays at their heights: `(fields, extra)`, a key that `field_of` names
    going to `fields` under that name, any other to `extra` under its key (less a `v1:`
    prefix). Heights a column does not cover stay NaN."""
    index = {h: j for j, h in enumerate(heights.tolist())}
    fields: dict[str, np.ndarray] = {}
    extra: dict[str, np.ndarray] = {}
    for c, (_, height, key) in enumerate(columns):
        field = field_of(key)
        target = fields if field else extra
        name = field or key.removeprefix("v1:")
        if name not in target:
            target[name] = np.full((values.shape[0], heights.size), np.nan)
        target[name][:, index[height]] = values[:, c]
    return fields, extra


def present_fields(
    quantities: Mapping[str, np.ndarray],
    names: Sequence[str],
    shape: tuple[int, int],
    rows: np.ndarray | None = None,
) -> tuple[dict[str, np.ndarray], list[str]]:
    """`({name: array}, missing)`: each of `names` from `quantities` (its `rows` when given),
    NaN-filled `shape` where the file lacks it (then listed in `missing`)."""
    fields: dict[str, np.ndarray] = {}
    missing: list[str] = []
    for name in names:
        if name in quantities:
            fields[name] = quantities[name] if rows is None else quantities[name][rows]
        else:
            fields[name] = np.full(shape, np.nan)
            missing.append(name)
    return fields, missing


def row_flags(row_ok: np.ndarray, inferred: np.ndarray, keep: np.ndarray, k: int) -> np.ndarray:
    """`(t, k)` int32 flags of the rows kept: `CORRUPT_ROW` where a row was not read,
    `TIME_INFERRED` where its time stamp was inferred."""
    flags = np.zeros((int(keep.sum()), k), dtype=np.int32)
    flags[~row_ok[keep]] |= int(RecordFlag.CORRUPT_ROW)
    flags[inferred[keep]] |= int(RecordFlag.TIME_INFERRED)
    return flags


def duplicate_times(times: np.ndarray) -> np.ndarray:
    """`(t,)` True for every repeat of an earlier time (the first occurrence is False)."""
    dup = np.zeros(times.size, dtype=bool)
    if times.size > 1:
        order = np.argsort(times, kind="stable")
        same = times[order][1:] == times[order][:-1]
        dup[order[1:][same]] = True
    return dup


def warn_corrupt_rows(path, problems: Sequence[tuple[int, str]], kind: str,
                      stacklevel: int) -> list[str]:
    """One `UserWarning` (at `stacklevel` from this function) naming the file and the lines of
    the corrupt rows `problems` (`(line, why)`); returns a message per row."""
    msgs = [f"{path}, line {ln}: {why}; read as a flagged missing {kind}" for ln, why in problems]
    if problems:
        warnings.warn(
            f"{path}: {len(problems)} corrupt row(s) at line(s) "
            f"{summarise_lines([ln for ln, _ in problems])} read as flagged missing "
            f"{kind}s (first: line {problems[0][0]}: {problems[0][1]}); every "
            "other row was read",
            stacklevel=stacklevel + 1,
        )
    return msgs


#: Rows above the last whose fields give its last column's format (`drop_cut_last_row`).
FORMAT_ROWS = 50


def drop_cut_last_row(path, lines: list[str], start: int, newline_end: bool,
                      split: Callable[[str], list[str]], *, stacklevel: int,
                      missing: Callable[[str], bool] = lambda f: False) -> str | None:
    """Blank the file's last line in `lines` (0-based; data rows from index `start`) when
    the writer was interrupted inside its last field: the file does not end with a line end
    (`newline_end` False), the line does not end with a delimiter, and its last field does
    not have the format of the same column on the rows above (`field_cut`; `missing` codes
    are taken as written). Then one `UserWarning` (at `stacklevel` from this function) names
    the file and line, and the message is returned (None when the line was written whole)."""
    if newline_end:
        return None
    rows = (i for i in range(len(lines) - 1, start - 1, -1) if lines[i].strip(" \t,;\r"))
    last = next(rows, None)
    if last is None:
        return None
    fields = split(lines[last].rstrip("\r"))
    if not fields or not fields[-1].strip():  # a delimiter closes the last field
        return None
    k = len(fields) - 1
    above = []
    for i in rows:
        f = split(lines[i].rstrip("\r"))
        if len(f) > k:
            above.append(f[k])
        if len(above) >= FORMAT_ROWS:
            break
    why = field_cut(fields[-1], above, missing)
    if why is None:
        return None
    message = (f"{path}, line {last + 1}: truncated file (no line end after the last line, and "
               f"{why}); that row is left out")
    warnings.warn(message, UserWarning, stacklevel=stacklevel + 1)
    lines[last] = ""
    return message


def infer_bad_times(time: np.ndarray, ok: np.ndarray, step: np.timedelta64 | None):
    """Fill unreadable stamps from regular neighbours; returns `(time, inferred, keep)`.

    A bad stamp between good ones whose spacing is an exact multiple of `step` gets the
    stamp its position implies; a bad stamp that cannot be placed is dropped (`keep` False).
    """
    t = time.copy()
    inferred = np.zeros(t.size, dtype=bool)
    keep = ok.copy()
    if step is None or ok.all():
        return t, inferred, keep | ok
    good = np.flatnonzero(ok)
    for i in np.flatnonzero(~ok):
        before = good[good < i]
        after = good[good > i]
        guess = None
        if before.size:
            g = time[before[-1]] + (i - before[-1]) * step
            if not after.size or time[after[0]] - g == (after[0] - i) * step:
                guess = g
        elif after.size:
            guess = time[after[0]] - (after[0] - i) * step
        if guess is not None:
            t[i] = guess
            inferred[i] = True
            keep[i] = True
    return t, inferred, keep


def regular_step(time: np.ndarray, ok: np.ndarray) -> np.timedelta64 | None:
    """The median spacing of the readable stamps (None with fewer than 2)."""
    good = time[ok]
    if good.size < 2:
        return None
    d = np.diff(good)
    d = d[d > np.timedelta64(0, "ms")]
    if d.size == 0:
        return None
    return np.median(d.astype(np.int64)).astype(np.int64).astype("timedelta64[ms]")
