"""Windcube 10-minute statistics files (`.sta`, `.stdsta`): `read_sta` and `StaRecord`.

Layout (Leosphere Windcube V2; V1 differs in the first line and some key spellings):

- line 1 `HeaderSize=N` (V2) or `HeaderLength=N` (V1), then N header lines of
  `key=value` (section titles and `****` rules are skipped). Keys are matched after
  normalising case, spaces and units, so `ScanAngle (°)`, `Scan Angle(°)` and
  `scanangle` are the same key;
- a `****` line may close the header; the next line names the tab-separated columns;
- rows: timestamp (`%Y/%m/%d %H:%M`, seconds accepted, V1's `%d/%m/%Y %H:%M:%S`
  too), the **end** of the 10-minute interval, in the instrument clock (header key
  `timezone`); then the columns. `NaN` marks missing values.

Per-altitude columns are named `<altitude>m <quantity> (<unit>)`, for example
`40m Wind Speed (m/s)`, and are mapped by parsing the altitude and the quantity name
(see `STA_QUANTITIES`), not by position. Wind direction is as the instrument reports it:
meteorological (where the wind comes from, degrees clockwise from north), with the
header's `DirectionOffset` already applied by the instrument.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from jaxtyping import Bool, Float, Shaped

from .._util import PathLike, atomic_path, file_error, freeze, import_optional, normalise_key
from ..flags import BLOCKING_FLAGS, MIN_AVAILABILITY, RecordFlag
from ..progress import AbstractProgress
from ..scan import Scan
from ..series import SeriesStatistics
from ._records import duplicate_times, infer_bad_times, present_fields, regular_step, row_flags
from ._windcube import header_facts, read_windcube, report, scalar_arrays, to_utc
from .record_set import DIRECTION_STD_KEYS, RecordSet, extra_column

__all__ = ["STA_FIELDS", "STA_GATE_QUANTITIES", "STA_QUANTITIES", "StaRecord", "read_sta",
           "write_sta", "write_series_sta"]

STA_FIELDS: tuple[str, ...] = (
    "speed",
    "speed_std",
    "speed_min",
    "speed_max",
    "direction",
    "w",
    "w_std",
    "cnr",
    "cnr_min",
    "spectral_broadening",
    "availability",
)
"""The per-altitude fields of a `StaRecord`, each `(t, k)`."""

_STA_NAMES: dict[str, tuple[str, ...]] = {
    "speed": ("Wind Speed", "Horizontal Wind Speed"),
    "speed_std": ("Wind Speed Dispersion", "Wind Speed Std", "Wind Speed Standard Deviation"),
    "speed_min": ("Wind Speed min", "Wind Speed Minimum"),
    "speed_max": ("Wind Speed max", "Wind Speed Maximum"),
    "direction": ("Wind Direction",),
    "w": ("Z-wind", "Z wind", "Vertical Wind Speed", "Z-wind speed"),
    "w_std": ("Z-wind Dispersion", "Z-wind Std", "Vertical Wind Speed Dispersion"),
    "cnr": ("CNR",),
    "cnr_min": ("CNR min", "CNR Minimum"),
    "spectral_broadening": (
        "Dopp Spect Broad",
        "Doppler Spectrum Broadening",
        "Doppler Spectral Broadening",
        "Spectral Broadening",
    ),
    "availability": ("Data Availability", "Availability"),
}

STA_QUANTITIES: dict[str, str] = {
    normalise_key(name): field for field, names in _STA_NAMES.items() for name in names
}
"""Normalised quantity name (`normalise_key`) -> `StaRecord` field."""

STA_GATE_QUANTITIES: dict[str, str] = {
    "vhm": "speed",
    "dvh": "speed_std",
    "vhmax": "speed_max",
    "vhmin": "speed_min",
    "azim": "direction",
    "dir": "direction",
    "wm": "w",
    "dw": "w_std",
    "cnrm": "cnr",
    "cnrmin": "cnr_min",
    "avail": "availability",
}
"""Windcube V1 gate-numbered column prefix (lower case; `Vhm1` is gate 1) -> field. Other
gate-numbered columns (`um`, `vm`, `dCNR`, `sigmafreqm` ...) go to `extra` under their
lower-case prefix."""

_WIND_FIELDS = ("speed", "speed_std", "speed_min", "speed_max", "direction", "w", "w_std")

_UNITS = {
    "speed": "m/s",
    "speed_std": "m/s",
    "speed_min": "m/s",
    "speed_max": "m/s",
    "direction": "deg",
    "w": "m/s",
    "w_std": "m/s",
    "cnr": "dB",
    "cnr_min": "dB",
    "spectral_broadening": "m/s",
    "availability": "%",
}


@dataclasses.dataclass(frozen=True, eq=False)
class StaRecord:
    """A Windcube 10-minute (or 1-minute) statistics record (`read_sta`). Read-only arrays.

    Dimensions: `t` intervals, `k` altitudes.

    **Fields:**

    - `path`: the file read.
    - `version`: `"V2"` (`HeaderSize=`, V2 and V2.1) or `"V1"` (`HeaderLength=`).
    - `header`: every `key=value` of the header, keys and values as written.
    - `time`: `(t,)` `datetime64[s]`, **UTC, end of each interval** (the instrument clock
      `time_local` minus the header's zone offset).
    - `heights`: `(k,)` metres above the instrument, ascending (the header's altitudes).
    - `speed`, `speed_std`, `speed_min`, `speed_max`: `(t, k)` horizontal wind speed
      mean, standard deviation ("dispersion"), minimum and maximum, m/s.
    - `direction`: `(t, k)` mean wind direction, degrees, meteorological (from,
      clockwise from north), as reported (the instrument has applied `DirectionOffset`).
    - `w`, `w_std`: `(t, k)` vertical wind, **positive up**, and its dispersion, m/s.
      `w = -z_wind`: the file's `Z-wind` is positive **down** (towards the lidar), like its
      radial speeds (see `lidarjax.io.rtd`, where the real V2.1 file pins this sign).
    - `cnr`, `cnr_min`: `(t, k)` carrier-to-noise ratio mean and minimum, dB.
    - `spectral_broadening`: `(t, k)` Doppler spectrum broadening, m/s.
    - `availability`: `(t, k)` data availability, percent.
    - `missing`: the fields above that the file lacks (NaN-filled).
    - `extra`: other per-altitude quantities, normalised name -> `(t, k)` (V1: lower-case
      gate prefix, e.g. `um`, `vm`); a repeated column is kept as `name#2`.
    - `scalars`: the other columns (temperatures, pressure, wiper count ...), name as
      written -> `(t,)` float64, or text when not numeric; a repeated name gets `#2`.
    - `scan_angle`: degrees from vertical (header `ScanAngle`); NaN when `NA` or absent.
    - `direction_offset`: degrees (header `DirectionOffset`); NaN when absent.
    - `instrument`: `"windcube_v1"` or `"windcube_v2"`.
    - `cone_angle`: `scan_angle` when given, else the instrument's nominal cone (30 deg V1,
      28 deg V2); `beam_azimuths`: the beams' azimuths in the instrument frame, degrees
      (NaN: the vertical beam of V2).
    - `pitch`, `roll`: installation tilt from the header, degrees (NaN when absent).
    - `cnr_threshold`: the header's `CNRThreshold`, dB (NaN when absent).
    - `timezone`: the header's zone as written; `utc_offset_hours`: hours east of UTC.
    - `time_local`: `(t,)` the stamps as written; `time_convention`: `"end"`.
    - `period`: the averaging period (`timedelta64[s]`, the rows' median spacing).
    - `flags`: `(t, k)` `RecordFlag` bits (corrupt row, low availability, impossible
      value, duplicate time); the wind fields of a flagged record are NaN.
    - `row_lines`: `(t,)` the 1-based line of each row in the file.
    - `warnings`: messages about corrupt rows (file and line) and renamed columns.
    - `min_availability`: the availability threshold applied, percent.
    """

    path: str
    version: str
    header: dict[str, str]
    time: Shaped[np.ndarray, " t"]
    heights: Float[np.ndarray, " k"]
    speed: Float[np.ndarray, "t k"]
    speed_std: Float[np.ndarray, "t k"]
    speed_min: Float[np.ndarray, "t k"]
    speed_max: Float[np.ndarray, "t k"]
    direction: Float[np.ndarray, "t k"]
    w: Float[np.ndarray, "t k"]
    w_std: Float[np.ndarray, "t k"]
    cnr: Float[np.ndarray, "t k"]
    cnr_min: Float[np.ndarray, "t k"]
    spectral_broadening: Float[np.ndarray, "t k"]
    availability: Float[np.ndarray, "t k"]
    missing: tuple[str, ...]
    extra: dict[str, Float[np.ndarray, "t k"]]
    scalars: dict[str, Shaped[np.ndarray, " t"]]
    scan_angle: float
    direction_offset: float
    instrument: str = "windcube_v2"
    cone_angle: float = 28.0
    beam_azimuths: tuple[float, ...] = (0.0, 90.0, 180.0, 270.0, float("nan"))
    pitch: float = float("nan")
    roll: float = float("nan")
    cnr_threshold: float = float("nan")
    timezone: str = ""
    utc_offset_hours: float = 0.0
    time_local: Any = None
    time_convention: str = "end"
    period: Any = None
    flags: Any = None
    z_wind: Any = None
    row_lines: Any = None
    warnings: tuple[str, ...] = ()
    min_availability: float = MIN_AVAILABILITY

    def __post_init__(self) -> None:
        if self.time.ndim != 1 or self.heights.ndim != 1:
            raise ValueError("time and heights must be 1-D")
        t, k = self.time.shape[0], self.heights.shape[0]
        for name in STA_FIELDS:
            if getattr(self, name).shape != (t, k):
                raise ValueError(
                    f"{name} must have shape (t, k) = ({t}, {k}), got {getattr(self, name).shape}"
                )
        if self.flags is None:
            object.__setattr__(self, "flags", freeze(np.zeros((t, k), np.int32)))

    @property
    def valid(self) -> Bool[np.ndarray, "t k"]:
        """`(t, k)` True where speed and direction are finite and no blocking flag is set."""
        return (np.isfinite(self.speed) & np.isfinite(self.direction)
                & ((self.flags & int(BLOCKING_FLAGS)) == 0))

    def to_pandas(self) -> Any:
        """A **long** `pandas.DataFrame`: one row per (interval, altitude).

        Columns `time` (UTC, end of interval), `height` (m), then `STA_FIELDS` and `flags`;
        rows ordered by time, then height. Needs pandas (`pip install lidarjax[pandas]`).
        """
        pd = import_optional("pandas", "pandas", "StaRecord.to_pandas")
        t, k = self.speed.shape
        data: dict[str, Any] = {
            "time": np.repeat(self.time, k),
            "height": np.tile(self.heights, t),
        }
        for name in STA_FIELDS:
            data[name] = getattr(self, name).reshape(-1)
        data["flags"] = np.asarray(self.flags).reshape(-1)
        return pd.DataFrame(data)

    @staticmethod
    def units() -> dict[str, str]:
        """Unit of each per-altitude field."""
        return dict(_UNITS)

    def to_record_set(self) -> RecordSet:
        """This record as a `lidarjax.io.RecordSet` (kind ``"sta"``), for correction.

        Speed, direction, dispersion and availability as read (the availability minimum was
        applied by `read_sta`), the direction dispersion from `extra` when the file has one,
        the header's angles and CNR threshold, `period` and `warnings`.
        """
        return RecordSet.reported(
            "sta", self.path, self.instrument, self.time, self.heights, self.speed,
            self.direction, self.flags, period=self.period,
            speed_std=np.array(self.speed_std, np.float64),
            direction_std=extra_column(self.extra, *DIRECTION_STD_KEYS),
            availability=np.array(self.availability, np.float64),
            scan_angle=float(self.scan_angle), direction_offset=float(self.direction_offset),
            pitch=float(self.pitch), roll=float(self.roll),
            cnr_threshold=float(self.cnr_threshold), warnings=tuple(self.warnings))


def read_sta(
    path: PathLike,
    *,
    min_availability: float = MIN_AVAILABILITY,
    progress: bool | AbstractProgress | Callable[[int, int], None] | None = None,
) -> StaRecord:
    """Read a Windcube `.sta` / `.stdsta` statistics file: V1 (gate-numbered), V2, V2.1,
    10-minute or 1-minute.

    Parsing is vectorised (about 0.5 s for a year of 10-minute rows at 12 heights). See the
    module docstring for the format and `StaRecord` for fields and conventions.

    **Arguments:**

    - `path`: the file.
    - `min_availability`: percent; records whose `Data Availability` is below it are
      flagged `RecordFlag.LOW_AVAILABILITY` and their wind fields set NaN (default
      `MIN_AVAILABILITY` = 80). Use 0 to keep every record.
    - `progress`: rows parsed so far: ``True`` draws a line on stderr (`lidarjax.TextProgress`),
      or give a meter (`lidarjax.TqdmProgress()` ...) or a `progress(rows_done, rows_total)`
      callback; ``False``/``None``: silent.

    **Returns:** a `StaRecord`; times in UTC, end of interval.

    **Bad rows** do not stop the read: a row cut short, with an unreadable time stamp or a
    non-numeric cell becomes a record of NaN flagged `RecordFlag.CORRUPT_ROW` (its time
    inferred from regular neighbours, `TIME_INFERRED`, or the row dropped when it cannot
    be placed), and one `UserWarning` names the file and lines (`StaRecord.warnings` lists
    each). Physically impossible values (negative speed or availability, direction outside
    [0, 360], availability outside [0, 100]) are flagged `IMPOSSIBLE_VALUE` and set NaN,
    never reinterpreted; CNR above 0 dB is flagged `HIGH_CNR` (advisory: cloud or fog).

    **A last row cut inside its last field** (no line end after it and that field in another
    format than the column above: ``100.00`` cut to ``10``; a writer interrupted) is left
    out with its own one-line `UserWarning` naming the file and line; a file that only
    lacks its final line end reads whole.

    Raises `FileNotFoundError` naming a missing path, and a one-line `ValueError` naming the
    file, the line and the fix for: an empty or binary/UTF-16 file, a first line that is
    not `HeaderSize=N` / `HeaderLength=N`, a missing column-names line, non-numeric
    altitudes, a column whose altitude is not in the header, no per-altitude column, a file
    without speed or direction columns, and a bad `min_availability`.
    """
    if not np.isfinite(min_availability) or not 0.0 <= min_availability <= 100.0:
        raise ValueError(f"min_availability must be a percentage in [0, 100], got "
                         f"{min_availability!r}")
    parsed = read_windcube(path, STA_QUANTITIES, "Windcube .sta file",
                           gate_quantities=STA_GATE_QUANTITIES, progress=progress)
    p = parsed.path
    for need in ("speed", "direction"):
        if need not in parsed.quantities:
            raise file_error(
                p, parsed.scalar_lines, f"no {need} columns ('40m Wind Speed (m/s)' / "
                "'40m Wind Direction (°)' in V2, 'Vhm1' / 'Azim1' in V1): is this a "
                "statistics (.sta) file?"
            )
    facts = header_facts(parsed)
    step = regular_step(parsed.time, parsed.time_ok)
    t_local, inferred, keep = infer_bad_times(parsed.time, parsed.time_ok, step)
    messages = report(parsed, "record")
    for i in np.flatnonzero(~keep):
        messages.append(f"{p}, line {parsed.row_lines[i]}: left out: its time stamp is "
                        "unreadable and the neighbouring rows are not regular enough to infer it")
    t, k = int(keep.sum()), parsed.heights.size
    fields, missing = present_fields(parsed.quantities, STA_FIELDS, (t, k), keep)
    z_wind = fields["w"].copy()
    fields["w"] = -fields["w"]  # file: positive down (towards the lidar); lidarjax: up
    times = t_local[keep]
    flags = row_flags(parsed.row_ok, inferred, keep, k)
    impossible = _flag_values(fields, flags, min_availability)
    flags[duplicate_times(times)] |= int(RecordFlag.DUPLICATE_TIME)
    bad = (flags & int(RecordFlag.CORRUPT_ROW | RecordFlag.IMPOSSIBLE_VALUE
                       | RecordFlag.LOW_AVAILABILITY)) != 0
    for name in _WIND_FIELDS:
        fields[name][bad] = np.nan
    if impossible.any():
        messages.append(f"{p}: {int(impossible.sum())} impossible value(s) (negative speed, "
                        "direction outside [0, 360] ...) flagged and set NaN")
    utc = to_utc(times, facts.utc_offset_hours)
    period = (step if step is not None else np.timedelta64(600_000, "ms")).astype(
        "timedelta64[s]")
    azimuths = (0.0, 90.0, 180.0, 270.0) + ((float("nan"),) if parsed.version == "V2" else ())
    return StaRecord(
        path=str(p),
        version=parsed.version,
        header=parsed.header,
        time=freeze(utc.astype("datetime64[s]")),
        heights=freeze(parsed.heights),
        **{n: freeze(a) for n, a in fields.items()},
        missing=tuple(missing),
        extra={n: freeze(a[keep]) for n, a in parsed.extra.items()},
        scalars={n: freeze(a[keep]) for n, a in scalar_arrays(parsed.scalars).items()},
        **dataclasses.asdict(facts),  # the header's convention facts
        beam_azimuths=azimuths,
        time_local=freeze(times.astype("datetime64[s]")),
        time_convention="end",
        period=period,
        flags=freeze(flags),
        z_wind=freeze(z_wind),
        row_lines=freeze(parsed.row_lines[keep]),
        warnings=tuple(messages),
        min_availability=float(min_availability),
    )


def _flag_values(fields: dict[str, np.ndarray], flags: np.ndarray,
                 min_availability: float) -> np.ndarray:
    """Flag (in `flags`) impossible values (`IMPOSSIBLE_VALUE`: negative speed, dispersion or
    availability, direction outside [0, 360], availability above 100 %), availability below
    `min_availability` percent (`LOW_AVAILABILITY`) and CNR above 0 dB (`HIGH_CNR`); returns
    the impossible ones `(t, k)`."""
    with np.errstate(invalid="ignore"):
        impossible = (
            (fields["speed"] < 0) | (fields["speed_min"] < 0) | (fields["speed_std"] < 0)
            | (fields["direction"] < 0) | (fields["direction"] > 360)
            | (fields["availability"] < 0) | (fields["availability"] > 100)
        )
        high_cnr = fields["cnr"] > 0
        low = fields["availability"] < min_availability
    flags[impossible] |= int(RecordFlag.IMPOSSIBLE_VALUE)
    flags[low] |= int(RecordFlag.LOW_AVAILABILITY)
    flags[high_cnr] |= int(RecordFlag.HIGH_CNR)
    return impossible


def write_sta(
    path: PathLike,
    time,
    heights,
    speed,
    direction,
    *,
    w=None,
    speed_std=None,
    availability=None,
    speed_min=None,
    speed_max=None,
    w_std=None,
    scan_angle: float | None = None,
    direction_offset: float = 0.0,
    system: str = "lidarjax synthetic",
) -> Any:
    """Write a Windcube V2-layout `.sta` file (cp1252, tab separated), atomically.

    Meant for synthetic records and fixtures: it writes the header keys `read_sta` uses and
    per-altitude speed, dispersion, direction, Z-wind and availability columns.

    **Arguments:** `time` ``(t,)`` datetime64 (end of interval); `heights` ``(k,)`` m;
    `speed`, `direction` ``(t, k)`` (m/s; meteorological degrees); optional `w` (positive
    up; written as the file's `Z-wind`, positive down), `speed_std` (m/s) and
    `availability` (percent) ``(t, k)``; optional `speed_min`, `speed_max` and `w_std`
    (m/s) ``(t, k)`` add the min, max and Z-wind dispersion columns (absent when not
    given); `scan_angle` and
    `direction_offset` in degrees. NaN is written as ``NaN``.

    **Returns:** the path written.
    """

    time = np.asarray(time, dtype="datetime64[s]")
    heights = np.asarray(heights, dtype=np.float64)
    t, k = time.size, heights.size
    cols = {"Wind Speed (m/s)": speed, "Wind Speed Dispersion (m/s)": speed_std,
            "Wind Direction (\u00b0)": direction,
            "Z-wind (m/s)": None if w is None else -np.asarray(w, dtype=np.float64),
            "Data Availability (%)": availability}
    optional = {"Wind Speed min (m/s)": speed_min, "Wind Speed max (m/s)": speed_max,
                "Z-wind Dispersion (m/s)": w_std}
    cols.update({name: value for name, value in optional.items() if value is not None})
    arrays = {}
    for name, value in cols.items():
        a = np.full((t, k), np.nan) if value is None else np.asarray(value, dtype=np.float64)
        if a.shape != (t, k):
            raise ValueError(f"write_sta: {name} must be shaped (time, heights) = {(t, k)}, got "
                             f"{a.shape}")
        arrays[name] = a
    fmt_h = [f"{h:g}" for h in heights]
    header = [
        "Version=lidarjax",
        f"ID System={system}",
        "timezone=UTC+0",
        "********************",
        f"ScanAngle (\u00b0)={'NA' if scan_angle is None else f'{scan_angle:g}'}",
        f"DirectionOffset (\u00b0)={direction_offset:g}",
        "Altitudes (m)=\t" + "\t".join(fmt_h),
    ]
    lines = [f"HeaderSize={len(header)}", *header, "********************"]
    names = ["Timestamp (end of interval)"]
    for h in fmt_h:
        names += [f"{h}m {q}" for q in cols]
    lines.append("\t".join(names))

    # vectorised formatting: one (t, k * q) block of text, NaN written as ``NaN``
    block = np.stack([arrays[q] for q in cols], axis=-1).reshape(t, -1)
    text = np.char.mod("%.4f", block)
    text[~np.isfinite(block)] = "NaN"
    stamps = np.datetime_as_string(time.astype("datetime64[m]"), unit="m")
    stamps = np.char.replace(np.char.replace(stamps, "-", "/"), "T", " ")
    for i in range(t):
        lines.append(stamps[i] + "\t" + "\t".join(text[i].tolist()) + "\t")
    target = Path(path)
    with atomic_path(target) as tmp, open(tmp, "x", encoding="cp1252", newline="\n") as fh:
        fh.write("\n".join(lines) + "\n")
    return target


def write_series_sta(path, stats: SeriesStatistics, heights, record_ends, *,
                     scan: Scan | None = None, direction_offset: float = 0.0,
                     system: str = "lidarjax simulated series"):
    """Write `SeriesStatistics` ``(r, h)`` as a Windcube ``.sta`` (`lidarjax.io.write_sta`).

    `record_ends`: ``(r,)`` datetime64 (end of each 10-minute interval, as ``.sta`` stamps
    them). Writes speed, dispersion, min, max, direction, Z-wind, its dispersion and
    availability. Returns the path written."""
    return write_sta(path, np.asarray(record_ends, dtype="datetime64[s]"), np.asarray(heights),
                     np.asarray(stats.speed), np.asarray(stats.direction), w=np.asarray(stats.w),
                     speed_std=np.asarray(stats.speed_std), availability=np.asarray(stats.availability),
                     speed_min=np.asarray(stats.speed_min), speed_max=np.asarray(stats.speed_max),
                     w_std=np.asarray(stats.w_std),
                     scan_angle=None if scan is None else float(scan.cone_angle),
                     direction_offset=direction_offset, system=system)


