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
from typing import Any

import numpy as np
from jaxtyping import Bool, Float, Shaped

from ._common import PathLike, freeze, import_optional, normalise_key
from ._windcube import header_angle, read_windcube, scalar_arrays

__all__ = ["STA_FIELDS", "STA_QUANTITIES", "StaRecord", "read_sta", "write_sta"]

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
    """A Windcube 10-minute statistics record (`read_sta`). Arrays are read-only.

    Dimensions: `t` intervals, `k` altitudes.

    **Fields:**

    - `path`: the file read.
    - `version`: `"V2"` (`HeaderSize=`) or `"V1"` (`HeaderLength=`).
    - `header`: every `key=value` of the header, keys and values as written.
    - `time`: `(t,)` `datetime64[s]`, end of each interval, instrument clock.
    - `heights`: `(k,)` metres above the instrument, ascending.
    - `speed`, `speed_std`, `speed_min`, `speed_max`: `(t, k)` horizontal wind speed
      mean, standard deviation ("dispersion"), minimum and maximum, m/s.
    - `direction`: `(t, k)` mean wind direction, degrees, meteorological (from,
      clockwise from north), as reported.
    - `w`, `w_std`: `(t, k)` vertical wind ("Z-wind", positive up) and its dispersion, m/s.
    - `cnr`, `cnr_min`: `(t, k)` carrier-to-noise ratio mean and minimum, dB.
    - `spectral_broadening`: `(t, k)` Doppler spectrum broadening, m/s.
    - `availability`: `(t, k)` data availability, percent.
    - `missing`: the fields above that the file lacks (NaN-filled).
    - `extra`: other per-altitude quantities, normalised name -> `(t, k)`.
    - `scalars`: the other columns (temperatures, pressure, wiper count ...), name as
      written -> `(t,)` float64, or text when not numeric.
    - `scan_angle`: degrees from vertical (header `ScanAngle`); NaN when `NA` or absent.
    - `direction_offset`: degrees (header `DirectionOffset`); NaN when absent.
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

    def __post_init__(self) -> None:
        if self.time.ndim != 1 or self.heights.ndim != 1:
            raise ValueError("time and heights must be 1-D")
        t, k = self.time.shape[0], self.heights.shape[0]
        for name in STA_FIELDS:
            if getattr(self, name).shape != (t, k):
                raise ValueError(
                    f"{name} must have shape (t, k) = ({t}, {k}), got {getattr(self, name).shape}"
                )

    @property
    def valid(self) -> Bool[np.ndarray, "t k"]:
        """`(t, k)` True where both speed and direction are finite."""
        return np.isfinite(self.speed) & np.isfinite(self.direction)

    def to_pandas(self) -> Any:
        """A **long** `pandas.DataFrame`: one row per (interval, altitude).

        Columns `time`, `height` (m), then `STA_FIELDS`; rows ordered by time, then
        height. Needs pandas (`pip install lidarjax[pandas]`).
        """
        pd = import_optional("pandas", "pandas", "StaRecord.to_pandas")
        t, k = self.speed.shape
        data: dict[str, Any] = {
            "time": np.repeat(self.time, k),
            "height": np.tile(self.heights, t),
        }
        for name in STA_FIELDS:
            data[name] = getattr(self, name).reshape(-1)
        return pd.DataFrame(data)

    @staticmethod
    def units() -> dict[str, str]:
        """Unit of each per-altitude field."""
        return dict(_UNITS)


def read_sta(path: PathLike) -> StaRecord:
    """Read a Windcube `.sta` / `.stdsta` 10-minute statistics file (V1 or V2 layout).

    The file is streamed line by line (cp1252). See the module docstring for the format.

    **Arguments:**

    - `path`: the file.

    **Returns:** a `StaRecord` (field meanings, units and conventions there).

    Raises `FileNotFoundError` naming a missing path, and `ValueError` naming the file,
    the line and the problem for: a first line that is not `HeaderSize=N` /
    `HeaderLength=N`, a file that ends inside the header, a missing column-names line,
    non-numeric altitudes, a column whose altitude is not in the header, duplicated
    columns, a short row, an unparseable timestamp or a non-numeric value (`NaN`,
    `NA` and empty fields are NaN).
    """
    parsed = read_windcube(path, STA_QUANTITIES, "Windcube .sta file")
    t, k = len(parsed.time), parsed.heights.size
    fields = {}
    missing = []
    for name in STA_FIELDS:
        if name in parsed.quantities:
            fields[name] = freeze(parsed.quantities[name])
        else:
            fields[name] = freeze(np.full((t, k), np.nan))
            missing.append(name)
    return StaRecord(
        path=str(parsed.path),
        version=parsed.version,
        header=parsed.header,
        time=freeze(np.array(parsed.time, dtype="datetime64[s]").reshape(t)),
        heights=freeze(parsed.heights),
        **fields,
        missing=tuple(missing),
        extra={n: freeze(a) for n, a in parsed.extra.items()},
        scalars={n: freeze(a) for n, a in scalar_arrays(parsed.scalars).items()},
        scan_angle=header_angle(parsed.header, parsed.path, "ScanAngle"),
        direction_offset=header_angle(parsed.header, parsed.path, "DirectionOffset"),
    )


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
    `speed`, `direction` ``(t, k)`` (m/s; meteorological degrees); optional `w`,
    `speed_std` (m/s) and `availability` (percent) ``(t, k)``; optional `speed_min`,
    `speed_max` and `w_std` (m/s) ``(t, k)`` add the min, max and Z-wind dispersion
    columns (absent when not given); `scan_angle` and
    `direction_offset` in degrees. NaN is written as ``NaN``.

    **Returns:** the path written.
    """
    from pathlib import Path

    from ._common import atomic_path

    time = np.asarray(time, dtype="datetime64[s]")
    heights = np.asarray(heights, dtype=np.float64)
    t, k = time.size, heights.size
    cols = {"Wind Speed (m/s)": speed, "Wind Speed Dispersion (m/s)": speed_std,
            "Wind Direction (\u00b0)": direction, "Z-wind (m/s)": w,
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

    def num(v):
        return "NaN" if not np.isfinite(v) else f"{v:.4f}"

    for i in range(t):
        stamp = str(time[i].astype("datetime64[m]")).replace("-", "/").replace("T", " ")
        row = [stamp]
        for j in range(k):
            row += [num(arrays[q][i, j]) for q in cols]
        lines.append("\t".join(row) + "\t")
    target = Path(path)
    with atomic_path(target) as tmp, open(tmp, "x", encoding="cp1252", newline="\n") as fh:
        fh.write("\n".join(lines) + "\n")
    return target
