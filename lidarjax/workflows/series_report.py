"""The report of a simulated lidar series: its `.sta`, a CSV of every statistic and a figure."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..angles import wind_direction
from ..io.seed_output import write_table_csv
from ..io.sta import write_series_sta
from ..plots import plot_series_ti
from ..scan import Scan
from ..series import RECORD_LENGTH, Series, SeriesStatistics

__all__ = ["write_series_report", "write_series_csv"]


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




def write_series_csv(out, series: Series, *, metadata: dict | None = None) -> dict:
    """Write a simulated series (`lidarjax.simulate_series`, e.g. through an unsteady CFD
    run's snapshots) under folder `out`, one row per sample:

    - ``series_los.csv``: every LOS, its time (s, the run's clock), height (m above the
      lidar), beam (index in the scan), LOS (m/s, positive away from the lidar; NaN outside)
      and `lidarjax.Flag` bits;
    - ``series_wind.csv``: every reconstruction as the instrument builds it, its time,
      height, horizontal speed (m/s), direction (degrees, meteorological), vertical wind
      ``w`` (m/s, up), and the true wind above the lidar at the nearest point sample
      (``point_speed``, ``point_direction``, ``point_w``).

    Returns ``{"los": path, "wind": path}``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    meta = metadata or {}
    t = np.asarray(series.los_time, np.float64)
    m, h, b = t.shape
    heights = np.asarray(series.heights, np.float64)
    los = write_table_csv(out / "series_los.csv", {
        "time": t.reshape(-1), "height": np.broadcast_to(heights[None, :, None], t.shape).reshape(-1),
        "beam": np.broadcast_to(np.arange(b), t.shape).reshape(-1),
        "los": np.asarray(series.los, np.float64).reshape(-1),
        "flags": np.asarray(series.los_flags).reshape(-1)},
        {"time": "s", "height": "m", "beam": "-", "los": "m/s", "flags": "lidarjax.Flag bits"}, meta)
    tr = np.asarray(series.time, np.float64)  # (n, h)
    v = np.asarray(series.velocity, np.float64)
    tp = np.asarray(series.point_time, np.float64)
    vp = np.asarray(series.point_velocity, np.float64)  # (p, h, 3)
    near = np.clip(np.searchsorted(tp, tr - 1e-9), 0, tp.size - 1)  # (n, h)
    prev = np.clip(near - 1, 0, tp.size - 1)
    near = np.where(np.abs(tp[prev] - tr) < np.abs(tp[near] - tr), prev, near)
    pv = vp[near, np.arange(h)[None, :]]  # (n, h, 3)
    wind = write_table_csv(out / "series_wind.csv", {
        "time": tr.reshape(-1), "height": np.broadcast_to(heights, tr.shape).reshape(-1),
        "speed": np.asarray(series.speed, np.float64).reshape(-1),
        "direction": np.asarray(series.direction, np.float64).reshape(-1),
        "w": v[..., 2].reshape(-1),
        "point_speed": np.hypot(pv[..., 0], pv[..., 1]).reshape(-1),
        "point_direction": np.asarray(wind_direction(pv), np.float64).reshape(-1),
        "point_w": pv[..., 2].reshape(-1)},
        {"time": "s", "height": "m", "speed": "m/s", "direction": "deg", "w": "m/s",
         "point_speed": "m/s", "point_direction": "deg", "point_w": "m/s"}, meta)
    return {"los": los, "wind": wind}
