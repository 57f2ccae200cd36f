"""Windcube real-time line-of-sight files (`.rtd`, `.stdrtd`): `read_rtd`, `group_rtd`.

Same header layout as `.sta` (see `lidarjax.io.sta`). Each row is one line of sight:
a timestamp (fractional seconds allowed), the beam `Position` (azimuth in degrees,
`0`, `90`, `180`, `270`, relative to the instrument, or `V` for the vertical beam),
then per altitude `<alt>m Radial Wind Speed (m/s)`, `<alt>m CNR (dB)` and optionally
`<alt>m Radial Wind Speed Dispersion (m/s)` and reconstructed quantities (kept in
`extra`).

## Sign conventions (pinned on the real V2.1 file, see `instrument_reconstruction`)

- The file's radial wind speed (RWS) is positive **towards** the lidar. lidarjax's
  line-of-sight speed is positive **away** from it, so `read_rtd` returns `los = -rws`
  and keeps the file's column as `rws`.
- The instrument's per-line reconstruction is, with `s = sin(28 deg)` and the latest
  sample of each beam: `X-wind = (RWS_0 - RWS_180) / (2 s)`, `Y-wind = (RWS_90 - RWS_270)
  / (2 s)`, `Z-wind = RWS_V`, `Wind Speed = hypot(X, Y)`, `Wind Direction = atan2(Y, X)`
  (degrees, + `DirectionOffset`). Since the reported direction is meteorological (where
  the wind comes **from**), `(X, Y)` points upwind: `X = -v_north`, `Y = -u_east` in the
  instrument frame, and **`Z-wind` is positive down** (`w = -Z-wind`). Neither pitch nor
  roll enters the per-line reconstruction (the fit leaves no residual beyond rounding).

## Time

Stamps are sample times in the instrument clock (header `timezone`, e.g. `UTC--3` = UTC-3);
`RtdRecord.time` is UTC. `group_rtd` labels intervals by their **end**, in UTC.
"""

from __future__ import annotations

import dataclasses
import re
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
from jaxtyping import Bool, Float, Int, Shaped

from .._util import PathLike, file_error, freeze, import_optional, normalise_key
from ..flags import MIN_AVAILABILITY, RecordFlag
from ..progress import AbstractProgress
from ._records import present_fields
from ._windcube import header_facts, read_windcube, report, scalar_arrays, to_utc
from .record_set import RecordSet, reader_flags

__all__ = ["BEAM_AZIMUTHS", "InstrumentReconstruction", "RtdBeams", "RtdRecord", "group_rtd",
           "instrument_reconstruction", "read_rtd"]

BEAM_AZIMUTHS: tuple[float, ...] = (0.0, 90.0, 180.0, 270.0, float("nan"))
"""Beam order of `RtdBeams` (degrees, instrument frame); NaN is the vertical beam `V`."""

_RTD_NAMES: dict[str, tuple[str, ...]] = {
    "rws": ("Radial Wind Speed", "RWS"),
    "rws_std": ("Radial Wind Speed Dispersion", "RWS Dispersion", "RWSD"),
    "cnr": ("CNR",),
}
RTD_QUANTITIES: dict[str, str] = {
    normalise_key(name): field for field, names in _RTD_NAMES.items() for name in names
}
RTD_GATE_QUANTITIES: dict[str, str] = {"rws": "rws", "vr": "rws", "drws": "rws_std",
                                       "rwsd": "rws_std", "cnr": "cnr", "cnrm": "cnr"}
"""Windcube V1 gate-numbered prefixes (`RWS1`, `CNR1` ...) -> `RtdRecord` field."""


@dataclasses.dataclass(frozen=True, eq=False)
class RtdRecord:
    """Windcube line-of-sight samples (`read_rtd`). Arrays are read-only.

    Dimensions: `t` lines of sight, `k` altitudes.

    **Fields:**

    - `path`, `version` (`"V2"`/`"V1"`), `header` (`key=value` as written).
    - `time`: `(t,)` `datetime64[ms]`, sample time, **UTC** (`time_local` minus the
      header's zone offset).
    - `heights`: `(k,)` metres above the instrument, ascending.
    - `position`: `(t,)` beam azimuth in degrees as written (instrument frame, clockwise);
      NaN for the vertical beam.
    - `vertical`: `(t,)` True for the vertical beam (`V`).
    - `los`: `(t, k)` line-of-sight speed, m/s, **positive away from the lidar**
      (`-rws`).
    - `rws`: `(t, k)` the file's radial wind speed, m/s, positive towards the lidar.
    - `rws_std`: `(t, k)` radial wind speed dispersion, m/s (NaN when absent).
    - `cnr`: `(t, k)` carrier-to-noise ratio, dB.
    - `missing`: which of `rws_std`, `cnr` the file lacks (NaN-filled).
    - `extra`: other per-altitude quantities, normalised name -> `(t, k)`; V2 files carry
      the instrument's reconstruction `windspeed`, `winddirection`, `xwind`, `ywind`,
      `zwind` (Z-wind positive down; see the module docstring).
    - `scalars`: other columns (temperature, wiper ...), name -> `(t,)`.
    - `scan_angle`: degrees from vertical (header `ScanAngle`); NaN when `NA` or absent.
    - `direction_offset`: degrees (header `DirectionOffset`); NaN when absent.
    - `instrument` (`"windcube_v1"`/`"windcube_v2"`), `cone_angle` (header, else nominal:
      30 deg V1, 28 deg V2), `beam_azimuths` (the positions present, degrees; NaN = V),
      `pitch`, `roll` (degrees), `cnr_threshold` (dB, header `CNRThreshold`; NaN when
      absent), `timezone` (as written), `utc_offset_hours`, `time_local`.
    - `row_lines`: `(t,)` 1-based line of each sample; `dropped_lines`: lines of corrupt
      rows left out (a warning names them); `warnings`: the messages.
    """

    path: str
    version: str
    header: dict[str, str]
    time: Shaped[np.ndarray, " t"]
    heights: Float[np.ndarray, " k"]
    position: Float[np.ndarray, " t"]
    vertical: Bool[np.ndarray, " t"]
    los: Float[np.ndarray, "t k"]
    rws: Float[np.ndarray, "t k"]
    rws_std: Float[np.ndarray, "t k"]
    cnr: Float[np.ndarray, "t k"]
    missing: tuple[str, ...]
    extra: dict[str, Float[np.ndarray, "t k"]]
    scalars: dict[str, Shaped[np.ndarray, " t"]]
    scan_angle: float
    direction_offset: float
    instrument: str = "windcube_v2"
    cone_angle: float = 28.0
    beam_azimuths: tuple[float, ...] = BEAM_AZIMUTHS
    pitch: float = float("nan")
    roll: float = float("nan")
    cnr_threshold: float = float("nan")
    timezone: str = ""
    utc_offset_hours: float = 0.0
    time_local: Any = None
    row_lines: Any = None
    dropped_lines: tuple[int, ...] = ()
    warnings: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        t, k = self.time.shape[0], self.heights.shape[0]
        for name in ("position", "vertical"):
            if getattr(self, name).shape != (t,):
                raise ValueError(f"{name} must have shape (t,) = ({t},)")
        for name in ("los", "rws", "rws_std", "cnr"):
            if getattr(self, name).shape != (t, k):
                raise ValueError(f"{name} must have shape (t, k) = ({t}, {k})")

    def to_beams(
        self, period: str | np.timedelta64 = "10min", *, min_cnr: float | None = None,
        **kwargs: Any,
    ) -> RtdBeams:
        """Per-interval mean line-of-sight speed per beam; see `group_rtd` (same keywords)."""
        return group_rtd(self, period=period, min_cnr=min_cnr, **kwargs)

    def to_record_set(
        self, period: str | np.timedelta64 = "10min", *,
        cnr_threshold: float | str | None = "header", min_availability: float = MIN_AVAILABILITY,
    ) -> RecordSet:
        """Per-interval beam means as a `lidarjax.io.RecordSet`:
        ``group_rtd(self, period, cnr_threshold=..., min_availability=...).to_record_set()``
        (`RtdBeams.to_record_set`)."""
        return group_rtd(self, period, cnr_threshold=cnr_threshold,
                         min_availability=min_availability).to_record_set()

    def to_pandas(self) -> Any:
        """A **long** `pandas.DataFrame`: one row per (line of sight, altitude).

        Columns `time` (UTC), `position` (deg, NaN for vertical), `vertical`, `height` (m),
        `los` (m/s, positive away), `rws` (m/s, positive towards), `rws_std`, `cnr` (dB).
        Needs pandas (`pip install lidarjax[pandas]`).
        """
        pd = import_optional("pandas", "pandas", "RtdRecord.to_pandas")
        t, k = self.los.shape
        data: dict[str, Any] = {
            "time": np.repeat(self.time, k),
            "position": np.repeat(self.position, k),
            "vertical": np.repeat(self.vertical, k),
            "height": np.tile(self.heights, t),
        }
        for name in ("los", "rws", "rws_std", "cnr"):
            data[name] = getattr(self, name).reshape(-1)
        return pd.DataFrame(data)


def _position_column(scalars: dict[str, list[str]]) -> str | None:
    return next((n for n in scalars if normalise_key(n) in ("position", "beamposition",
                                                            "azimuth", "los", "losid")), None)


def read_rtd(
    path: PathLike, *, progress: bool | AbstractProgress | Callable[[int, int], None] | None = None
) -> RtdRecord:
    """Read a Windcube `.rtd` / `.stdrtd` real-time line-of-sight file (V1, V2, V2.1).

    Vectorised (cp1252 or UTF-8). The header layout is that of `.sta` (`HeaderSize=N` or
    `HeaderLength=N`, `key=value` lines, optional `****`, then the column names).

    **Returns:** an `RtdRecord` with `los = -rws` (lidarjax: positive away from the lidar;
    Windcube files: positive towards it) and times in UTC.

    `progress`: rows parsed so far: ``True`` draws a line on stderr (`lidarjax.TextProgress`),
    or give a meter or a `progress(rows_done, rows_total)` callback; ``False``/``None``: silent.

    A corrupt row (cut short, unreadable time stamp, non-numeric cell, a position that is
    neither a number nor `V`) is left out with one `UserWarning` naming the file and lines
    (`RtdRecord.dropped_lines`); every good row is read. A last row cut inside its last field
    (no line end after it, that field in another format than the column above) is left out
    with its own one-line warning. Raises `FileNotFoundError` for a
    missing path, and a one-line `ValueError` naming the file, line and fix for the header
    errors of `read_sta` and a missing `Position` or radial wind speed column.
    """
    parsed = read_windcube(path, RTD_QUANTITIES, "Windcube .rtd file",
                           gate_quantities=RTD_GATE_QUANTITIES, progress=progress)
    p = parsed.path
    if "rws" not in parsed.quantities:
        raise file_error(
            p, parsed.scalar_lines, "no '<altitude>m Radial Wind Speed (m/s)' columns found; "
            "is this a real-time (.rtd) file rather than statistics (.sta)?"
        )
    pos_name = _position_column(parsed.scalars)
    if pos_name is None:
        raise file_error(p, parsed.scalar_lines, "no 'Position' column (beam azimuth or V); "
                         "the file cannot say which beam each row measured")
    raw_positions = parsed.scalars.pop(pos_name)
    if normalise_key(pos_name) == "losid":  # LOS ID 0..4: 0/90/180/270 degrees, 4 = vertical
        los_id = {"0": "0", "1": "90", "2": "180", "3": "270", "4": "V"}
        raw_positions = [los_id.get(v.strip().split(".")[0], v) for v in raw_positions]
    n = len(raw_positions)
    vertical = np.array([t.strip().upper() == "V" for t in raw_positions], dtype=bool)
    position = np.full(n, np.nan)
    pos_ok = vertical.copy()
    for i, text in enumerate(raw_positions):
        if vertical[i]:
            continue
        try:
            position[i] = float(text)
            pos_ok[i] = np.isfinite(position[i])
        except ValueError:
            pass
    for i in np.flatnonzero(~pos_ok & parsed.row_ok):
        parsed.problems.append((int(parsed.row_lines[i]), f"column {pos_name!r}: expected a "
                                f"beam azimuth in degrees or 'V', found {raw_positions[i]!r}"))
    parsed.problems.sort()
    keep = parsed.row_ok & pos_ok
    messages = report(parsed, "sample (left out)")
    facts = header_facts(parsed)
    t, k = int(keep.sum()), parsed.heights.size
    rws = parsed.quantities["rws"][keep]
    fields, missing = present_fields(parsed.quantities, ("rws_std", "cnr"), (t, k), keep)
    present = sorted({float(a) for a in position[keep] if np.isfinite(a)})
    azimuths = tuple(present) + ((float("nan"),) if vertical[keep].any() else ())
    local = parsed.time[keep]
    return RtdRecord(
        path=str(p),
        version=parsed.version,
        header=parsed.header,
        time=freeze(to_utc(local, facts.utc_offset_hours)),
        heights=freeze(parsed.heights),
        position=freeze(position[keep]),
        vertical=freeze(vertical[keep]),
        los=freeze(-rws),
        rws=freeze(rws),
        **{n_: freeze(a) for n_, a in fields.items()},
        missing=tuple(missing),
        extra={n_: freeze(a[keep]) for n_, a in parsed.extra.items()},
        scalars={n_: freeze(a[keep]) for n_, a in scalar_arrays(parsed.scalars).items()},
        **dataclasses.asdict(facts),  # the header's convention facts
        beam_azimuths=azimuths,
        time_local=freeze(local),
        row_lines=freeze(parsed.row_lines[keep]),
        dropped_lines=tuple(int(ln) for ln, _ in parsed.problems),
        warnings=tuple(messages),
    )


@dataclasses.dataclass(frozen=True, eq=False)
class RtdBeams:
    """Line-of-sight speeds averaged per interval and beam (`group_rtd`). Read-only arrays.

    Dimensions: `r` intervals (records), `k` altitudes, `b` = 5 beams ordered
    `BEAM_AZIMUTHS` = `[0, 90, 180, 270, V]` (degrees, instrument frame).

    **Fields:**

    - `time`: `(r,)` `datetime64[ms]`, **UTC, end** of each interval (the `.sta`
      convention); an interval is `(time - period, time]`.
    - `period`: the interval length.
    - `heights`: `(k,)` metres.
    - `azimuths`: `(b,)` the beam azimuths, NaN for the vertical beam.
    - `los`: `(r, k, b)` mean line-of-sight speed, m/s, positive away from the lidar, over
      the samples at or above the CNR threshold; NaN where a blocking `RecordFlag` is set
      (no valid sample, availability below `min_availability`).
    - `count`: `(r, k, b)` number of valid samples averaged.
    - `cnr`: `(r, k, b)` mean CNR of those samples, dB.
    - `n_samples`: `(r, b)` samples of each beam in the interval (valid or not).
    - `availability`: `(r, k, b)` percent: valid samples over the samples a full interval
      holds (`period` / the scan's cycle time); NaN for a beam the scan lacks.
    - `flags`: `(r, k, b)` `RecordFlag` bits: `LOW_AVAILABILITY`, `BELOW_CNR_THRESHOLD`,
      `PARTIAL_INTERVAL`.
    - `partial`: `(r,)` True for a first/last interval the file covers only in part.
    - `cnr_threshold`: the threshold applied, dB (NaN: none); `min_availability`: percent.
    - `cycle`: the scan's cycle time (median spacing of one beam's samples).
    - `path`, `instrument`, `scan_angle`, `direction_offset`, `pitch`, `roll`, `warnings`:
      those of the `RtdRecord` grouped (header facts, degrees; NaN when absent).
    """

    time: Shaped[np.ndarray, " r"]
    period: np.timedelta64
    heights: Float[np.ndarray, " k"]
    azimuths: Float[np.ndarray, " b"]
    los: Float[np.ndarray, "r k b"]
    count: Int[np.ndarray, "r k b"]
    cnr: Float[np.ndarray, "r k b"]
    n_samples: Any = None
    availability: Any = None
    flags: Any = None
    partial: Any = None
    cnr_threshold: float = float("nan")
    min_availability: float = MIN_AVAILABILITY
    cycle: Any = None
    path: str = ""
    instrument: str = ""
    scan_angle: float = float("nan")
    direction_offset: float = float("nan")
    pitch: float = float("nan")
    roll: float = float("nan")
    warnings: tuple[str, ...] = ()

    @property
    def usable(self) -> Bool[np.ndarray, "r k b"]:
        """`(r, k, b)` True where `los` is finite (no blocking flag)."""
        return np.isfinite(self.los)

    def to_record_set(self) -> RecordSet:
        """These beam means as a `lidarjax.io.RecordSet` (kind ``"rtd"``), for correction.

        `los` ``(r, k, 5)`` as averaged; `flags` the bits of every beam OR-ed per record and
        height (with PARTIAL_INTERVAL for a `partial` interval); `availability` the worst
        tilted beam's; `cnr_threshold` the threshold applied; `period_s` the interval; the
        header facts and warnings of the record grouped.
        """
        los = np.array(self.los, np.float64)
        shape = los.shape[:2]
        flags = np.zeros(shape, np.int64)
        if self.flags is not None:
            flags = reader_flags(np.bitwise_or.reduce(np.asarray(self.flags, np.int64),
                                                      axis=-1), shape)
        if self.partial is not None:
            flags[np.asarray(self.partial, bool)] |= int(RecordFlag.PARTIAL_INTERVAL)
        availability = None
        if self.availability is not None:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # a beam-less height: NaN
                availability = np.nanmin(np.asarray(self.availability, np.float64)[..., :4],
                                         axis=-1)
        return RecordSet(
            kind="rtd", path=self.path, instrument=self.instrument,
            time=np.asarray(self.time, "datetime64[s]"), heights=np.asarray(self.heights, float),
            flags=flags, los=los, availability=availability,
            scan_angle=float(self.scan_angle), direction_offset=float(self.direction_offset),
            pitch=float(self.pitch), roll=float(self.roll),
            cnr_threshold=float(self.cnr_threshold),
            period_s=float(self.period / np.timedelta64(1, "s")), warnings=tuple(self.warnings))


_PERIOD = re.compile(r"^\s*(\d+(?:\.\d+)?)\s*(ms|s|sec|min|m|h|hour)s?\s*$", re.IGNORECASE)
_PERIOD_MS = {"ms": 1, "s": 1000, "sec": 1000, "min": 60_000, "m": 60_000, "h": 3_600_000,
              "hour": 3_600_000}


def _period_ms(period: str | np.timedelta64) -> int:
    if isinstance(period, np.timedelta64):
        ms = int(period / np.timedelta64(1, "ms"))
    else:
        m = _PERIOD.match(str(period))
        if not m:
            raise ValueError(
                f"period {period!r} not understood; use e.g. '10min', '600s', '1h' or a "
                "numpy.timedelta64"
            )
        value = float(m.group(1)) * _PERIOD_MS[m.group(2).lower()]
        if not value.is_integer():
            raise ValueError(f"period {period!r} must be a whole number of milliseconds")
        ms = int(value)
    if ms <= 0:
        raise ValueError(f"period must be positive, got {period!r}")
    return ms


def _beam_index(record: RtdRecord, tolerance_deg: float) -> np.ndarray:
    beam = np.full(record.position.shape, -1, dtype=np.int64)
    beam[record.vertical] = 4
    for b, az in enumerate(BEAM_AZIMUTHS[:4]):
        gap = np.abs((record.position - az + 180.0) % 360.0 - 180.0)
        beam[~record.vertical & (gap <= tolerance_deg)] = b
    if np.any(beam < 0):
        bad = np.unique(record.position[beam < 0])
        raise ValueError(
            f"{record.path}: beam positions {', '.join(f'{v:g}' for v in bad)} are not "
            f"0/90/180/270 (within {tolerance_deg:g} deg) or V; this reader knows the "
            "Windcube DBS scan only"
        )
    return beam


def group_rtd(
    record: RtdRecord,
    period: str | np.timedelta64 = "10min",
    *,
    min_cnr: float | None = None,
    cnr_threshold: float | str | None = "header",
    min_availability: float = MIN_AVAILABILITY,
    tolerance_deg: float = 1.0,
) -> RtdBeams:
    """Average line-of-sight speeds per interval and beam, filtered like the instrument.

    Samples are assigned to the interval that **ends** at the next multiple of `period`
    (counted from the Unix epoch, in UTC) at or after their time, so a sample stamped
    exactly 00:10:00 belongs to (00:00, 00:10], labelled 00:10 like the `.sta` files.

    **Filtering (the instrument's rules):**

    1. CNR: only samples with CNR >= the threshold are used. By default the threshold is
       the header's `CNRThreshold` (the instrument's own, e.g. -23 dB); `cnr_threshold`
       (dB) or its alias `min_cnr` overrides it, `cnr_threshold=None` disables it.
    2. Availability: per interval, height and beam, valid samples / samples in a full
       interval (`period` over the scan cycle time). Below `min_availability` percent
       (default `MIN_AVAILABILITY` = 80) the mean is **not used**: NaN, flagged
       `LOW_AVAILABILITY`. A beam with samples but none above the threshold is also
       flagged `BELOW_CNR_THRESHOLD`.
    3. Partial intervals: the first and last intervals the file covers only in part
       (it starts or stops more than 1.5 scan cycles inside them) are flagged
       `PARTIAL_INTERVAL` (`partial`); their availability is counted against a full
       interval, so they usually fall below the minimum too.

    **Arguments:**

    - `record`: from `read_rtd`.
    - `period`: interval length, e.g. `"10min"`, `"600s"`, `"1h"`, or a `numpy.timedelta64`.
    - `min_cnr`, `cnr_threshold`: see 1.; `min_cnr` wins when both are given.
    - `min_availability`: percent in [0, 100].
    - `tolerance_deg`: how far (degrees, modulo 360) a position may be from 0/90/180/270;
      in [0, 45).

    **Returns:** `RtdBeams` with `los` shaped `(r, k, b)`, beams `[0, 90, 180, 270, V]`.

    Raises `ValueError` for a position that is none of the four azimuths, a bad period,
    threshold or availability.
    """
    threshold = _group_threshold(record, min_cnr, cnr_threshold, min_availability, tolerance_deg)
    ms = _period_ms(period)
    t_ms = record.time.astype("datetime64[ms]").astype(np.int64)
    ends = -(-t_ms // ms) * ms
    interval_ends, r_index = np.unique(ends, return_inverse=True)
    r_index = r_index.reshape(-1)
    beam = _beam_index(record, tolerance_deg)
    mean, cnr_mean, counts, finite_counts, n_samples = _beam_means(
        record, threshold, r_index, beam, interval_ends.size)
    cycle = _scan_cycle(t_ms, beam, ms)
    expected = max(ms / cycle, 1.0)
    in_scan = n_samples.sum(axis=0) > 0  # (b,)
    with np.errstate(invalid="ignore", divide="ignore"):
        availability = np.minimum(100.0 * counts / expected, 100.0)
    availability[:, :, ~in_scan] = np.nan
    flags = np.zeros(counts.shape, dtype=np.int32)
    with np.errstate(invalid="ignore"):
        low = in_scan[None, None, :] & (availability < min_availability)
    flags[low] |= int(RecordFlag.LOW_AVAILABILITY)
    flags[(counts == 0) & (finite_counts > 0)] |= int(RecordFlag.BELOW_CNR_THRESHOLD)
    partial = _partial_intervals(t_ms, interval_ends, ms, cycle)
    flags[partial] |= int(RecordFlag.PARTIAL_INTERVAL)
    mean[low] = np.nan
    return RtdBeams(
        time=freeze(interval_ends.astype("datetime64[ms]")),
        period=np.timedelta64(ms, "ms"),
        heights=record.heights,
        azimuths=freeze(np.array(BEAM_AZIMUTHS)),
        los=freeze(mean),
        count=freeze(counts),
        cnr=freeze(cnr_mean),
        n_samples=freeze(n_samples),
        availability=freeze(availability),
        flags=freeze(flags),
        partial=freeze(partial),
        cnr_threshold=threshold,
        min_availability=float(min_availability),
        cycle=np.timedelta64(cycle, "ms"),
        path=record.path,
        instrument=record.instrument,
        scan_angle=float(record.scan_angle),
        direction_offset=float(record.direction_offset),
        pitch=float(record.pitch),
        roll=float(record.roll),
        warnings=tuple(record.warnings),
    )


def _group_threshold(record: RtdRecord, min_cnr, cnr_threshold, min_availability,
                     tolerance_deg) -> float:
    """`group_rtd`'s arguments checked; the CNR threshold to apply (dB; NaN: none)."""
    if not 0.0 <= tolerance_deg < 45.0:
        raise ValueError(
            f"tolerance_deg must be in [0, 45) so that each position matches one beam, got "
            f"{tolerance_deg!r}"
        )
    if not np.isfinite(min_availability) or not 0.0 <= min_availability <= 100.0:
        raise ValueError(f"min_availability must be a percentage in [0, 100], got "
                         f"{min_availability!r}")
    if min_cnr is not None:
        return float(min_cnr)
    if isinstance(cnr_threshold, str):
        if cnr_threshold != "header":
            raise ValueError(f"cnr_threshold must be a number (dB), 'header' or None, got "
                             f"{cnr_threshold!r}")
        return float(record.cnr_threshold)
    if cnr_threshold is None:
        return float("nan")
    threshold = float(cnr_threshold)
    if not np.isfinite(threshold):
        raise ValueError(f"cnr_threshold must be finite (dB), got {cnr_threshold!r}")
    return threshold


def _beam_means(record: RtdRecord, threshold: float, r_index: np.ndarray, beam: np.ndarray,
                n_r: int) -> tuple[np.ndarray, ...]:
    """Per interval, height and beam: `(mean los, mean CNR, valid samples, finite samples)`
    `(n_r, k, 5)` over the samples at or above `threshold`, and the samples of each beam
    `(n_r, 5)`."""
    k = record.heights.size
    valid = np.isfinite(record.los)
    if np.isfinite(threshold) and "cnr" not in record.missing:
        with np.errstate(invalid="ignore"):
            valid &= record.cnr >= threshold
    los = np.where(valid, record.los, 0.0)
    cnr_ok = valid & np.isfinite(record.cnr)
    cnr = np.where(cnr_ok, record.cnr, 0.0)
    sums = np.zeros((n_r, k, 5))
    counts = np.zeros((n_r, k, 5), dtype=np.int64)
    finite_counts = np.zeros((n_r, k, 5), dtype=np.int64)
    cnr_sums = np.zeros((n_r, k, 5))
    cnr_counts = np.zeros((n_r, k, 5), dtype=np.int64)
    n_samples = np.zeros((n_r, 5), dtype=np.int64)
    idx = (r_index[:, None], np.arange(k)[None, :], beam[:, None])
    np.add.at(sums, idx, los)
    np.add.at(counts, idx, valid.astype(np.int64))
    np.add.at(finite_counts, idx, np.isfinite(record.los).astype(np.int64))
    np.add.at(cnr_sums, idx, cnr)
    np.add.at(cnr_counts, idx, cnr_ok.astype(np.int64))
    np.add.at(n_samples, (r_index, beam), 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)
        cnr_mean = np.where(cnr_counts > 0, cnr_sums / np.maximum(cnr_counts, 1), np.nan)
    return mean, cnr_mean, counts, finite_counts, n_samples


def _scan_cycle(t_ms: np.ndarray, beam: np.ndarray, ms: int) -> int:
    """The scan cycle (ms): the median spacing of one beam's consecutive samples."""
    gaps = []
    for b in range(5):
        tb = t_ms[beam == b]
        if tb.size > 1:
            gaps.append(np.diff(np.sort(tb)))
    all_gaps = np.concatenate(gaps) if gaps else np.zeros(0, np.int64)
    all_gaps = all_gaps[all_gaps > 0]
    if all_gaps.size:
        return int(np.median(all_gaps))
    # one sample per beam: the spacing of consecutive samples times the beam count
    steps = np.diff(np.sort(t_ms))
    steps = steps[steps > 0]
    n_beams = int(np.unique(beam).size)
    return int(np.median(steps)) * n_beams if steps.size else ms


def _partial_intervals(t_ms: np.ndarray, interval_ends: np.ndarray, ms: int,
                       cycle: int) -> np.ndarray:
    """`(r,)` True for a first or last interval the samples start or stop more than 1.5
    scan cycles inside."""
    partial = np.zeros(interval_ends.size, dtype=bool)
    if interval_ends.size:
        slack = 1.5 * cycle
        partial[0] = t_ms.min() - (interval_ends[0] - ms) > slack
        partial[-1] |= interval_ends[-1] - t_ms.max() > slack
    return partial


@dataclasses.dataclass(frozen=True, eq=False)
class InstrumentReconstruction:
    """The Windcube's own per-line wind, recomputed from a `.rtd`'s radial speeds.

    Every array is `(t, k)` (one value per line of sight and altitude), NaN until each
    beam it needs has been seen once.

    - `x_wind`, `y_wind`: m/s, the file's `X-wind`/`Y-wind`: the horizontal wind vector
      pointing **upwind** (where the wind comes from), X towards the 0-degree beam, Y
      towards the 90-degree beam.
    - `z_wind`: m/s, the file's `Z-wind`, **positive down** (towards the lidar).
    - `w`: m/s, vertical wind **positive up** (`-z_wind`).
    - `speed`: m/s, `hypot(x_wind, y_wind)` (the file's `Wind Speed`).
    - `direction`: degrees, meteorological (from, clockwise from north):
      `atan2(y_wind, x_wind)` + `direction_offset`, in [0, 360) (the file's
      `Wind Direction`).
    - `cone_angle`, `direction_offset`: the degrees used.
    """

    x_wind: Float[np.ndarray, "t k"]
    y_wind: Float[np.ndarray, "t k"]
    z_wind: Float[np.ndarray, "t k"]
    w: Float[np.ndarray, "t k"]
    speed: Float[np.ndarray, "t k"]
    direction: Float[np.ndarray, "t k"]
    cone_angle: float
    direction_offset: float


def instrument_reconstruction(
    record: RtdRecord, *, cone_angle: float | None = None, tolerance_deg: float = 1.0
) -> InstrumentReconstruction:
    """Reproduce the Windcube's per-line `Wind Speed`, `Wind Direction`, `X/Y/Z-wind`.

    Algorithm (found by fitting the real V2.1 file; it reproduces every printed value to
    the rounding of the printed radial speeds, see `tests/io/test_rtd_real.py`): at each
    line of sight, take the **latest** radial speed of each beam (a sliding window over the
    last 0/90/180/270 tilted beams and the last vertical beam, **no CNR filter**, no
    pitch/roll correction), with `s = sin(cone_angle)`:

        X-wind = (RWS_0 - RWS_180) / (2 s)      Y-wind = (RWS_90 - RWS_270) / (2 s)
        Z-wind = RWS_V                           speed  = hypot(X, Y)
        direction = atan2(Y, X) + DirectionOffset  (degrees, mod 360)

    RWS is the file's radial speed (positive towards the lidar), so `(X, Y)` points upwind
    and `Z-wind` is positive **down**; `w = -Z-wind` is positive up. The real file pins the
    cone at 28.00 deg (least-squares fit: 27.997 and 28.000 deg on X and Y) although its
    header says `ScanAngle=NA`. A file without vertical beam (V1) gives NaN `z_wind`.
    The direction offset's sign (added) is the natural reading; the real file has offset 0,
    so it is not verified.

    **Arguments:** `record` from `read_rtd`; `cone_angle` in degrees (default
    `record.cone_angle`); `tolerance_deg` as in `group_rtd`.

    **Returns:** an `InstrumentReconstruction`.
    """
    cone = float(record.cone_angle if cone_angle is None else cone_angle)
    if not np.isfinite(cone) or not 0.0 < cone < 90.0:
        raise ValueError(f"cone_angle must be in (0, 90) degrees, got {cone!r}")
    offset = 0.0 if not np.isfinite(record.direction_offset) else float(record.direction_offset)
    beam = _beam_index(record, tolerance_deg)
    t = beam.size
    latest = []
    ar = np.arange(t)
    for b in range(5):
        idx = np.maximum.accumulate(np.where(beam == b, ar, -1)) if t else ar
        vals = np.where((idx >= 0)[:, None], record.rws[np.maximum(idx, 0)], np.nan)
        latest.append(vals)
    s2 = 2.0 * np.sin(np.radians(cone))
    x = (latest[0] - latest[2]) / s2
    y = (latest[1] - latest[3]) / s2
    z = latest[4]
    speed = np.hypot(x, y)
    with np.errstate(invalid="ignore"):
        direction = np.where(np.isfinite(speed),
                             (np.degrees(np.arctan2(y, x)) + offset) % 360.0, np.nan)
    return InstrumentReconstruction(
        x_wind=freeze(x), y_wind=freeze(y), z_wind=freeze(z), w=freeze(-z),
        speed=freeze(speed), direction=freeze(direction), cone_angle=cone,
        direction_offset=offset,
    )


