"""Shared helpers of the readers and writers: error messages, atomic writes, optional imports.

Private to `lidarjax.io`; nothing here is public API.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import enum
import importlib
import math
import os
import re
import uuid
from collections.abc import Iterator, Sequence
from pathlib import Path
from types import ModuleType

import numpy as np

__all__: list[str] = []

PathLike = str | os.PathLike[str]


def file_error(path: PathLike, line: int | None, message: str) -> ValueError:
    """A `ValueError` whose message starts with the file and, when known, the 1-based line."""
    where = f"{os.fspath(path)}, line {line}" if line is not None else os.fspath(path)
    return ValueError(f"{where}: {message}")


def require_file(path: PathLike, what: str) -> Path:
    """Return `path` as a `Path`, raising `FileNotFoundError` naming it when it is not a file."""
    p = Path(path)
    if not p.is_file():
        if p.exists():
            raise FileNotFoundError(f"{what} {os.fspath(p)!s} is not a regular file")
        raise FileNotFoundError(f"{what} not found: {os.fspath(p)!s}")
    return p


def import_optional(module: str, extra: str, purpose: str) -> ModuleType:
    """Import an optional dependency, or raise an `ImportError` that names the pip extra."""
    try:
        return importlib.import_module(module)
    except ImportError as err:
        raise ImportError(
            f"{purpose} needs the optional package '{module}', which is not installed: "
            f"pip install lidarjax[{extra}]"
        ) from err


def have_module(module: str) -> bool:
    """Whether `module` can be imported (without raising)."""
    try:
        importlib.import_module(module)
    except ImportError:
        return False
    return True


def netcdf_engine() -> str:
    """`h5netcdf` (NetCDF4) when it and h5py are installed, else scipy's NetCDF3 writer."""
    return "h5netcdf" if have_module("h5netcdf") and have_module("h5py") else "scipy"


@contextlib.contextmanager
def atomic_path(path: PathLike) -> Iterator[Path]:
    """Yield a fresh temporary path beside `path`; on success move it onto `path` atomically.

    The temporary file lives in the same directory (so `os.replace` is atomic on POSIX
    and Windows) and keeps the final suffix (some writers dispatch on it). On any
    exception the temporary file is removed and `path` is left untouched.
    """
    target = Path(path)
    if not target.parent.is_dir():
        raise FileNotFoundError(f"directory not found: {os.fspath(target.parent)}")
    tmp = target.with_name(f".{target.name}.{uuid.uuid4().hex[:12]}.tmp{target.suffix}")
    try:
        yield tmp
        with open(tmp, "rb") as fh:  # flush the data to disk before the rename
            os.fsync(fh.fileno())
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def atomic_write_text(path: PathLike, text: str, *, encoding: str = "utf-8") -> Path:
    """Write `text` to `path` atomically (temporary file in the same directory, then rename)."""
    target = Path(path)
    with atomic_path(target) as tmp, open(tmp, "x", encoding=encoding, newline="\n") as fh:
        fh.write(text)
    return target


_UNIT_RE = re.compile(r"\([^)]*\)|\[[^\]]*\]")
_NON_ALNUM_RE = re.compile(r"[^0-9a-z]+")


def normalise_key(key: str) -> str:
    """Lower-case `key`, drop bracketed units and every non-alphanumeric character.

    `"ScanAngle (°)"`, `"Scan Angle(°)"` and `"scan_angle"` all become `"scanangle"`.
    """
    return _NON_ALNUM_RE.sub("", _UNIT_RE.sub("", key.lower()))


def parse_float(text: str) -> float:
    """`float(text)`, with empty fields and `NA`/`N/A` read as NaN. Raises `ValueError`."""
    t = text.strip()
    if t == "" or t.upper() in ("NA", "N/A"):
        return math.nan
    return float(t)


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


def parse_timestamp(text: str, formats: Sequence[str]) -> _dt.datetime:
    """Parse `text` with the first matching `strptime` format; `ValueError` if none does."""
    t = text.strip()
    for fmt in formats:
        try:
            return _dt.datetime.strptime(t, fmt)
        except ValueError:
            continue
    raise ValueError(f"unrecognised timestamp {t!r} (expected one of {', '.join(formats)})")


def freeze(a: np.ndarray) -> np.ndarray:
    """Mark an array read-only (records are immutable) and return it."""
    a.setflags(write=False)
    return a


def format_number(x: float) -> str:
    """Shortest text that reads back to the same float; integral values without '.0'."""
    xf = float(x)
    if math.isfinite(xf) and xf.is_integer() and abs(xf) < 1e15:
        return str(int(xf))
    return repr(xf)


class RecordFlag(enum.IntFlag):
    """Why a value of a lidar record read from a file is NaN (or doubtful). ``OK`` is 0.

    Readers (`read_sta`, `read_zephir_csv`, `group_rtd`) return a ``flags`` integer array
    holding the bitwise OR of these bits; test one with ``(rec.flags & RecordFlag.X) != 0``.
    """

    OK = 0
    #: The file's row could not be read (cut mid-row, unreadable time stamp, non-numeric
    #: cell, wrong field count): every value of the record is NaN. A warning names the line.
    CORRUPT_ROW = 1
    #: The row's time stamp was unreadable and was inferred from its neighbours (regular
    #: spacing); the values are still NaN (`CORRUPT_ROW` is set too).
    TIME_INFERRED = 2
    #: The interval is only partly covered by the file (first or last interval of a `.rtd`
    #: file that starts or stops inside it).
    PARTIAL_INTERVAL = 4
    #: Data availability below the reader's minimum (`MIN_AVAILABILITY` percent by default):
    #: the value is not used (NaN).
    LOW_AVAILABILITY = 8
    #: A physically impossible value in the file (negative speed, dispersion or
    #: availability, direction outside [0, 360], availability above 100 %): kept out (NaN),
    #: never reinterpreted.
    IMPOSSIBLE_VALUE = 16
    #: A beam of a `.rtd` interval has no sample at or above the CNR threshold.
    BELOW_CNR_THRESHOLD = 32
    #: The row repeats an earlier row's time stamp.
    DUPLICATE_TIME = 64
    #: CNR above 0 dB: no clear-air aerosol return is that strong (Windcube CNR is typically
    #: -30 to -5 dB); a cloud, fog or a hard target is in the probe volume. The wind value
    #: is kept (the real `.sta` files show plausible speeds there) but is doubtful.
    HIGH_CNR = 128


BLOCKING_FLAGS = (RecordFlag.CORRUPT_ROW | RecordFlag.LOW_AVAILABILITY
                  | RecordFlag.IMPOSSIBLE_VALUE | RecordFlag.BELOW_CNR_THRESHOLD)
"""The `RecordFlag` bits whose values are NaN and must not be used; the others are advisory."""


MIN_AVAILABILITY = 80.0
"""Minimum data availability (percent) for a record to be used (`RecordFlag.LOW_AVAILABILITY`).

80 % is the usual filter of wind-resource practice for 10-minute lidar statistics (a
record built from fewer than 4 in 5 expected line-of-sight samples, or reconstructions, is
discarded). Every reader takes a `min_availability` argument to change it.
"""


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
    out = np.full(len(iso), np.datetime64("NaT"), dtype="datetime64[ms]")
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


def summarise_lines(lines: Sequence[int], limit: int = 8) -> str:
    """`'12, 40, 41'` or `'12, 40, ... (25 lines)'`."""
    shown = ", ".join(str(n) for n in lines[:limit])
    return shown if len(lines) <= limit else f"{shown}, ... ({len(lines)} lines)"
