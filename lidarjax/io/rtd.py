"""Windcube real-time line-of-sight files (`.rtd`, `.stdrtd`): `read_rtd`, `group_rtd`.

Same header layout as `.sta` (see `lidarjax.io.sta`). Each row is one line of sight:
a timestamp (fractional seconds allowed), the beam `Position` (azimuth in degrees,
`0`, `90`, `180`, `270`, relative to the instrument, or `V` for the vertical beam),
then per altitude `<alt>m Radial Wind Speed (m/s)`, `<alt>m CNR (dB)` and optionally
`<alt>m Radial Wind Speed Dispersion (m/s)` and reconstructed quantities (kept in
`extra`).

## Sign convention

In Windcube files the radial wind speed (RWS) is positive **towards** the lidar
(Leosphere: RWS > 0 when the wind approaches the instrument). lidarjax's line-of-sight
speed is positive **away** from the lidar (the velocity projected on the outward beam
unit vector). `read_rtd` therefore returns `los = -rws` and keeps the file's column as
`rws`.
"""

from __future__ import annotations

import dataclasses
import re
from typing import Any

import numpy as np
from jaxtyping import Bool, Float, Int, Shaped

from ._common import PathLike, file_error, freeze, import_optional, normalise_key
from ._windcube import header_angle, read_windcube, scalar_arrays

__all__ = ["BEAM_AZIMUTHS", "RtdBeams", "RtdRecord", "group_rtd", "read_rtd"]

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


@dataclasses.dataclass(frozen=True, eq=False)
class RtdRecord:
    """Windcube line-of-sight samples (`read_rtd`). Arrays are read-only.

    Dimensions: `t` lines of sight, `k` altitudes.

    **Fields:**

    - `path`, `version` (`"V2"`/`"V1"`), `header` (`key=value` as written).
    - `time`: `(t,)` `datetime64[ms]`, sample time in the instrument clock (rtd stamps
      carry fractional seconds, hence milliseconds rather than the `.sta` seconds).
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
    - `extra`: other per-altitude quantities, normalised name -> `(t, k)`.
    - `scalars`: other columns (temperature, wiper ...), name -> `(t,)`.
    - `scan_angle`: degrees from vertical (header `ScanAngle`); NaN when `NA` or absent.
    - `direction_offset`: degrees (header `DirectionOffset`); NaN when absent.
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

    def __post_init__(self) -> None:
        t, k = self.time.shape[0], self.heights.shape[0]
        for name in ("position", "vertical"):
            if getattr(self, name).shape != (t,):
                raise ValueError(f"{name} must have shape (t,) = ({t},)")
        for name in ("los", "rws", "rws_std", "cnr"):
            if getattr(self, name).shape != (t, k):
                raise ValueError(f"{name} must have shape (t, k) = ({t}, {k})")

    def to_beams(
        self, period: str | np.timedelta64 = "10min", *, min_cnr: float | None = None
    ) -> RtdBeams:
        """Per-interval mean line-of-sight speed per beam; see `group_rtd`."""
        return group_rtd(self, period=period, min_cnr=min_cnr)

    def to_pandas(self) -> Any:
        """A **long** `pandas.DataFrame`: one row per (line of sight, altitude).

        Columns `time`, `position` (deg, NaN for vertical), `vertical`, `height` (m),
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
    return next((n for n in scalars if normalise_key(n) in ("position", "beamposition")), None)


def read_rtd(path: PathLike) -> RtdRecord:
    """Read a Windcube `.rtd` / `.stdrtd` real-time line-of-sight file.

    Streams the file (cp1252). The header layout is that of `.sta` (`HeaderSize=N` or
    `HeaderLength=N`, `key=value` lines, optional `****`, then the column names).

    **Returns:** an `RtdRecord` with `los = -rws` (lidarjax: positive away from the lidar;
    Windcube files: positive towards it).

    Raises `FileNotFoundError` for a missing path, and `ValueError` naming the file, line
    and problem for the header errors of `read_sta`, a missing `Position` or radial wind
    speed column, a position that is neither a number nor `V`, a short row, a bad
    timestamp or a non-numeric value.
    """
    parsed = read_windcube(path, RTD_QUANTITIES, "Windcube .rtd file")
    p = parsed.path
    if "rws" not in parsed.quantities:
        raise file_error(
            p, parsed.scalar_lines, "no '<altitude>m Radial Wind Speed (m/s)' columns found"
        )
    pos_name = _position_column(parsed.scalars)
    if pos_name is None:
        raise file_error(p, parsed.scalar_lines, "no 'Position' column (beam azimuth or V)")
    raw_positions = parsed.scalars.pop(pos_name)
    t, k = len(parsed.time), parsed.heights.size
    vertical = np.zeros(t, dtype=bool)
    position = np.full(t, np.nan)
    for i, text in enumerate(raw_positions):
        if text.upper() == "V":
            vertical[i] = True
            continue
        try:
            position[i] = float(text)
        except ValueError:
            raise file_error(
                p, parsed.row_lines[i], f"column {pos_name!r}: expected a beam azimuth in "
                f"degrees or 'V', found {text!r}"
            ) from None
    rws = parsed.quantities["rws"]
    fields = {}
    missing = []
    for name in ("rws_std", "cnr"):
        if name in parsed.quantities:
            fields[name] = freeze(parsed.quantities[name])
        else:
            fields[name] = freeze(np.full((t, k), np.nan))
            missing.append(name)
    return RtdRecord(
        path=str(p),
        version=parsed.version,
        header=parsed.header,
        time=freeze(np.array(parsed.time, dtype="datetime64[ms]").reshape(t)),
        heights=freeze(parsed.heights),
        position=freeze(position),
        vertical=freeze(vertical),
        los=freeze(-rws),
        rws=freeze(rws),
        **fields,
        missing=tuple(missing),
        extra={n: freeze(a) for n, a in parsed.extra.items()},
        scalars={n: freeze(a) for n, a in scalar_arrays(parsed.scalars).items()},
        scan_angle=header_angle(parsed.header, p, "ScanAngle"),
        direction_offset=header_angle(parsed.header, p, "DirectionOffset"),
    )


@dataclasses.dataclass(frozen=True, eq=False)
class RtdBeams:
    """Line-of-sight speeds averaged per interval and beam (`group_rtd`). Read-only arrays.

    Dimensions: `r` intervals (records), `k` altitudes, `b` = 5 beams ordered
    `BEAM_AZIMUTHS` = `[0, 90, 180, 270, V]` (degrees, instrument frame).

    **Fields:**

    - `time`: `(r,)` `datetime64[ms]`, **end** of each interval (the `.sta` convention);
      an interval is `(time - period, time]`.
    - `period`: the interval length.
    - `heights`: `(k,)` metres.
    - `azimuths`: `(b,)` the beam azimuths, NaN for the vertical beam.
    - `los`: `(r, k, b)` mean line-of-sight speed, m/s, positive away from the lidar;
      NaN where the beam has no valid sample in the interval.
    - `count`: `(r, k, b)` number of valid samples averaged.
    - `cnr`: `(r, k, b)` mean CNR of those samples, dB.
    """

    time: Shaped[np.ndarray, " r"]
    period: np.timedelta64
    heights: Float[np.ndarray, " k"]
    azimuths: Float[np.ndarray, " b"]
    los: Float[np.ndarray, "r k b"]
    count: Int[np.ndarray, "r k b"]
    cnr: Float[np.ndarray, "r k b"]


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


def group_rtd(
    record: RtdRecord,
    period: str | np.timedelta64 = "10min",
    *,
    min_cnr: float | None = None,
    tolerance_deg: float = 1.0,
) -> RtdBeams:
    """Average line-of-sight speeds per interval and beam: what the inverse model needs.

    Samples are assigned to the interval that **ends** at the next multiple of `period`
    (counted from the Unix epoch) at or after their time, so a sample stamped exactly
    00:10:00 belongs to the interval (00:00, 00:10], labelled 00:10 like the `.sta`
    files. Each beam's mean is taken over its finite samples (and, with `min_cnr`, only
    those with CNR >= `min_cnr` dB). Intervals with no sample at all are not listed;
    beams with no valid sample are NaN with `count` 0.

    **Arguments:**

    - `record`: from `read_rtd`.
    - `period`: interval length, e.g. `"10min"`, `"600s"`, `"1h"`, or a `numpy.timedelta64`.
    - `min_cnr`: optional CNR threshold in dB.
    - `tolerance_deg`: how far (degrees, modulo 360) a position may be from 0/90/180/270;
      in [0, 45).

    **Returns:** `RtdBeams` with `los` shaped `(r, k, b)`, beams `[0, 90, 180, 270, V]`.

    Raises `ValueError` for a position that is none of the four azimuths.
    """
    if not 0.0 <= tolerance_deg < 45.0:
        raise ValueError(
            f"tolerance_deg must be in [0, 45) so that each position matches one beam, got "
            f"{tolerance_deg!r}"
        )
    ms = _period_ms(period)
    t_ms = record.time.astype("datetime64[ms]").astype(np.int64)
    ends = -(-t_ms // ms) * ms
    interval_ends, r_index = np.unique(ends, return_inverse=True)
    r_index = r_index.reshape(-1)

    beam = np.full(record.position.shape, -1, dtype=np.int64)
    beam[record.vertical] = 4
    for b, az in enumerate(BEAM_AZIMUTHS[:4]):
        gap = np.abs((record.position - az + 180.0) % 360.0 - 180.0)
        beam[~record.vertical & (gap <= tolerance_deg)] = b
    if np.any(beam < 0):
        bad = np.unique(record.position[beam < 0])
        raise ValueError(
            f"{record.path}: beam positions {', '.join(f'{v:g}' for v in bad)} are not "
            f"0/90/180/270 (within {tolerance_deg:g} deg) or V"
        )

    n_r, k = interval_ends.size, record.heights.size
    valid = np.isfinite(record.los)
    if min_cnr is not None:
        valid &= record.cnr >= min_cnr
    los = np.where(valid, record.los, 0.0)
    cnr = np.where(valid & np.isfinite(record.cnr), record.cnr, 0.0)
    cnr_n = (valid & np.isfinite(record.cnr)).astype(np.int64)
    sums = np.zeros((n_r, k, 5))
    counts = np.zeros((n_r, k, 5), dtype=np.int64)
    cnr_sums = np.zeros((n_r, k, 5))
    cnr_counts = np.zeros((n_r, k, 5), dtype=np.int64)
    idx = (r_index[:, None], np.arange(k)[None, :], beam[:, None])
    np.add.at(sums, idx, los)
    np.add.at(counts, idx, valid.astype(np.int64))
    np.add.at(cnr_sums, idx, cnr)
    np.add.at(cnr_counts, idx, cnr_n)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)
        cnr_mean = np.where(cnr_counts > 0, cnr_sums / np.maximum(cnr_counts, 1), np.nan)
    return RtdBeams(
        time=freeze(interval_ends.astype("datetime64[ms]")),
        period=np.timedelta64(ms, "ms"),
        heights=record.heights,
        azimuths=freeze(np.array(BEAM_AZIMUTHS)),
        los=freeze(mean),
        count=freeze(counts),
        cnr=freeze(cnr_mean),
    )
