"""The report of a simulated lidar series: its `.sta`, a CSV of every statistic and a figure."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io.seed_output import write_table_csv
from ..io.sta import write_series_sta
from ..plots import plot_series_ti
from ..scan import Scan
from ..series import RECORD_LENGTH, SeriesStatistics

__all__ = ["write_series_report"]


_STAT_UNITS = {"speed": "m/s", "direction": "deg", "speed_std": "m/s", "speed_min": "m/s",
               "speed_max": "m/s", "w": "m/s", "w_std": "m/s", "availability": "%", "ti": "-",
               "cup_speed": "m/s", "cup_std": "m/s", "cup_ti": "-", "sonic_speed": "m/s",
               "sonic_direction": "deg", "sonic_std": "m/s", "sonic_ti": "-", "sonic_w": "m/s",
               "sonic_w_std": "m/s"}


def write_series_report(out, stats: SeriesStatistics, heights, starts, *, start_datetime,
                        scan: Scan | None = None, metadata: dict | None = None,
                        plots: bool = True, label: str = "lidar") -> dict:
    """Write a simulated series' statistics under folder `out`:

    - ``series.sta``: the ``.sta`` (`write_series_sta`), stamped at the end of each record
      from `start_datetime` (numpy datetime64 of time 0) plus `starts` (s) + 600 s;
    - ``series_statistics.csv``: every `SeriesStatistics` field per record and height
      (`record_end` in seconds after `start_datetime`);
    - ``series_ti.png``: lidar against point TI per height (needs matplotlib; skipped with a
      note in the returned dict when absent, or with ``plots=False``).

    Returns ``{"sta": path, "csv": path, "plot": path or None, "note": text}``."""

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    starts = np.asarray(starts, float)
    heights = np.asarray(heights, float)
    t0 = np.datetime64(start_datetime, "s")
    ends = t0 + np.round((starts + RECORD_LENGTH) * 1000).astype("timedelta64[ms]")
    sta = write_series_sta(out / "series.sta", stats, heights, ends.astype("datetime64[s]"),
                           scan=scan)
    r, h = np.asarray(stats.speed).shape
    cols = {"record_end": np.repeat(starts + RECORD_LENGTH, h), "height": np.tile(heights, r)}
    units = {"record_end": f"s after {t0}", "height": "m"}
    for name, unit in _STAT_UNITS.items():
        cols[name] = np.asarray(getattr(stats, name), float).reshape(-1)
        units[name] = unit
    csv = write_table_csv(out / "series_statistics.csv", cols, units, metadata or {})
    result = {"sta": sta, "csv": csv, "plot": None, "note": ""}
    if plots:
        try:
            result["plot"] = plot_series_ti(heights, stats.ti, stats.cup_ti, stats.sonic_ti,
                                            out / "series_ti.png", label=label)
        except ImportError as err:
            result["note"] = f"no figure: {err}"
    return result


