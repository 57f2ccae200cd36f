"""`RecordSet`: the common record type of every lidar record reader.

Each reader's result builds one from its own fields with ``to_record_set()``:
`lidarjax.io.StaRecord` (Windcube ``.sta``/``.stdsta``), `lidarjax.io.RtdBeams` (a Windcube
``.rtd`` averaged per interval and beam by `lidarjax.io.group_rtd`; `RtdRecord.to_record_set`
groups and converts in one call) and `lidarjax.io.ZephirRecord` (ZephIR ``.csv``).
`lidarjax.load_records` picks the reader by file type and returns it; the correction
workflow (`lidarjax.correct_records`) reads nothing else.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..flags import BLOCKING_FLAGS, RecordFlag

__all__ = ["RecordSet"]

#: `extra` keys (normalised column names) of a direction dispersion, degrees.
DIRECTION_STD_KEYS = ("winddirectiondispersion", "winddirectionstd", "directiondispersion",
                      "directionstd")


@dataclasses.dataclass(frozen=True, eq=False)
class RecordSet:
    """A record file, normalised for correction. Arrays ``(r, k)`` unless noted.

    - `kind`: 'sta', 'rtd' or 'zephir'; `path`; `instrument`: 'windcube_v1',
      'windcube_v2', 'zephir' or '' when the file does not say.
    - `time`: ``(r,)`` datetime64[s], end of interval (UTC when the reader knows the zone).
    - `heights`: ``(k,)`` m above the instrument.
    - reported records: `speed` (m/s), `direction` (meteorological degrees), `speed_std`
      (m/s), `direction_std` (deg), `availability` (percent), `n_samples` (ZephIR packets);
    - raw records: `los` ``(r, k, b)`` m/s positive away from the lidar, beams
      [0, 90, 180, 270, V]; `availability` (percent, the worst beam's);
    - `flags`: ``(r, k)`` `RecordFlag` bits; `warnings`: lines about skipped rows;
    - `scan_angle`, `direction_offset`, `pitch`, `roll`, `cnr_threshold`: header facts in
      degrees / dB, NaN when the file does not say (`cnr_threshold` of a ``.rtd``: the
      threshold applied); `period_s`: interval in seconds.

    Values under a blocking flag (`lidarjax.BLOCKING_FLAGS`) are NaN.
    """

    kind: str
    path: str
    instrument: str
    time: np.ndarray
    heights: np.ndarray
    flags: np.ndarray
    speed: np.ndarray | None = None
    direction: np.ndarray | None = None
    speed_std: np.ndarray | None = None
    direction_std: np.ndarray | None = None
    availability: np.ndarray | None = None
    n_samples: np.ndarray | None = None
    los: np.ndarray | None = None
    scan_angle: float = math.nan
    direction_offset: float = math.nan
    pitch: float = math.nan
    roll: float = math.nan
    cnr_threshold: float = math.nan
    period_s: float = 600.0
    warnings: tuple[str, ...] = ()

    @classmethod
    def reported(cls, kind: str, path: str, instrument: str, time, heights, speed, direction,
                 flags, *, period: Any = None, **fields: Any) -> RecordSet:
        """A set of reported (10-minute mean) records, from a reader's arrays.

        `speed`, `direction` ``(r, k)`` are copied; `flags` the reader's `RecordFlag` bits
        (None: none). Speeds below 0 and directions outside [0, 360] are flagged
        IMPOSSIBLE_VALUE (the readers flag these already: a guard), and speed and direction
        under a blocking flag are set NaN. `period`: the interval (timedelta64; None: the
        median spacing of `time`, else 600 s). The other `fields` are passed on.
        """
        speed = np.array(speed, np.float64)
        direction = np.array(direction, np.float64)
        bits = reader_flags(flags, speed.shape)
        bad = (speed < 0) | (direction < 0) | (direction > 360)
        bits |= np.where(bad, int(RecordFlag.IMPOSSIBLE_VALUE), 0)
        unusable = (bits & int(BLOCKING_FLAGS)) != 0
        speed[unusable] = np.nan
        direction[unusable] = np.nan
        time = np.asarray(time, "datetime64[s]")
        return cls(kind=kind, path=str(path), instrument=instrument, time=time,
                   heights=np.asarray(heights, float), flags=bits, speed=speed,
                   direction=direction, period_s=period_seconds(period, time), **fields)


def reader_flags(flags, shape) -> np.ndarray:
    """A reader's `RecordFlag` bits as a fresh int64 array of `shape` (zeros for None)."""
    if flags is None:
        return np.zeros(shape, np.int64)
    return np.broadcast_to(np.asarray(flags).astype(np.int64), shape).copy()


def extra_column(extra: Mapping[str, Any] | None, *keys: str) -> np.ndarray | None:
    """The first of `keys` in a reader's `extra` (normalised column names) as float64, or
    None."""
    extra = extra or {}
    for k in keys:
        if k in extra:
            return np.asarray(extra[k], np.float64)
    return None


def period_seconds(period: Any, time: np.ndarray) -> float:
    """`period` (a timedelta64) in seconds; without one, the median positive spacing of
    `time`, else 600."""
    if period is not None:
        try:
            return float(np.timedelta64(period) / np.timedelta64(1, "s"))
        except (TypeError, ValueError):
            pass
    if time.size > 1:
        steps = np.diff(time).astype("timedelta64[s]").astype(np.int64)
        steps = steps[steps > 0]
        if steps.size:
            return float(np.median(steps))
    return 600.0
