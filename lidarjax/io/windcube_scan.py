"""Windcube 200S / 400S scanning NetCDF files (Leosphere "Windcube data", CF/Radial 2.0).

`read_windcube_scan` (optional extra ``netcdf``: xarray, h5netcdf). A file holds
one or more sweeps, each a group named in the root variable ``sweep_group_name``, with per
ray ``time`` (seconds since ``time_reference``, the end of the ray), ``azimuth`` (degrees from
true north) and ``elevation`` (degrees above the horizon), per ray and gate ``range`` (m),
``radial_wind_speed`` (m/s, positive away from the instrument), ``cnr`` (dB) and
``radial_wind_speed_status`` (1 accepted, 0 rejected), plus ``range_gate_length`` (m),
``ray_accumulation_time`` (ms) and ``sweep_mode`` (ppi, rhi, dbs, fixed, ...). The rays of
all sweeps are concatenated in time order. A file without these is refused in one line
naming it and what is missing. When present, the instrument's own products are read too
(per ray and gate, NaN where absent): ``measurement_height`` (m above the instrument),
``horizontal_wind_speed`` (m/s), ``wind_direction`` (degrees, where the wind comes from,
clockwise from true north), ``vertical_wind_speed`` (m/s, up) and ``wind_speed_status``.

**Ray times.** ``time`` is the *end* of each ray's accumulation. The evidence is the
instrument's software, which says so in every file it writes (real 200S DBS, server 3.3.0):
``time`` is "Number of seconds between time_reference and the end of each ray
measurement", ``timestamp`` is the "Timestamp at the end of each ray measurement", and
``azimuth``/``elevation`` are the head's angles "when each measurement finished". That the
first ray's time equals the time in the file's name (``..._2021-07-01_13-03-28_...``,
first ray 13:03:28.088) does not make it a start: the name is that first end time cut to
the second. The first ray began ``ray_accumulation_time`` (2000 ms) earlier; the rays are
2.95 to 5.46 s apart, more than an accumulation. `WindcubeScan.pattern` starts every ray
one accumulation before its time (tests/io/test_windcube_scan.py).

Angles and ranges are read as stored: ``azimuth``/``elevation`` are the scanning head's
encoder angles at the end of each ray, ``range`` the gate centres the processing used. The
two need not agree. In the committed Windcube 200S DBS (server 3.3.0, rays N, vertical, S, W,
E) the processing gated and reconstructed the rays as if their elevations were
``(75, 75, 75, 75, 90)`` while the head reported ``(75, 90, 75, 75, 75)``: `range_elevation()`
recovers the processing's elevation, ``arcsin(measurement_height / range)``. The encoder
angles are the physical ones (over the source's 69 sweeps the vertical-labelled ray sees a
mean of -0.05 m/s and the east ray +1.98 m/s, antisymmetric to the west ray's -2.02 m/s),
so fit the LOS with `azimuth`/`elevation`; the file's ``horizontal_wind_speed``
is the least-squares DBS fit with `range_elevation()` (the east ray taken as vertical),
reproduced to the 0.01 m/s the file stores, and over-reads a uniform wind by
``1 + s / (2 s^2 + 1) = 1.337`` (``s = sin 75 deg``). See docs/scanning.md, "Real files".
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .._util import PathLike, file_error, import_optional, netcdf_engine, require_file
from ..scanning import ScanPattern

__all__ = ["WindcubeScan", "read_windcube_scan"]

_RAY_VARS = ("time", "azimuth", "elevation")
_GATE_VARS = ("range", "radial_wind_speed")


@dataclasses.dataclass(frozen=True)
class WindcubeScan:
    """A Windcube scanning file (``r`` rays of all sweeps, ``g`` gates; numpy arrays).

    `time` ``(r,)`` ``datetime64[us]``, end of each ray; `azimuth` (clockwise from true
    north), `elevation` (above the horizon) ``(r,)`` degrees, the head's encoder angles;
    `ranges` ``(r, g)`` m, the gate centres the processing used; `radial_wind_speed` (m/s,
    positive away from the lidar), `cnr` (dB), `status` (bool, accepted) ``(r, g)``; `sweep`
    ``(r,)`` sweep number; `gate_length` (m); `accumulation` (s per ray); `sweep_mode`;
    `instrument`; `path`. The instrument's products ``(r, g)``, NaN (False) where the file
    has none: `measurement_height` (m above the instrument), `horizontal_wind_speed` (m/s),
    `wind_direction` (degrees, from, clockwise from true north), `vertical_wind_speed` (m/s,
    up), `wind_status` (bool, accepted).
    """

    path: str
    instrument: str
    sweep_mode: str
    gate_length: float
    accumulation: float
    time: np.ndarray
    azimuth: np.ndarray
    elevation: np.ndarray
    ranges: np.ndarray
    radial_wind_speed: np.ndarray
    cnr: np.ndarray
    status: np.ndarray
    sweep: np.ndarray
    measurement_height: np.ndarray
    horizontal_wind_speed: np.ndarray
    wind_direction: np.ndarray
    vertical_wind_speed: np.ndarray
    wind_status: np.ndarray

    def radial_velocity(self, *, cnr_threshold: float | None = None,
                        use_status: bool = True) -> np.ndarray:
        """LOS ``(r, g)`` m/s, NaN where the instrument rejected it (`use_status`) or the CNR
        is below `cnr_threshold` dB."""
        keep = np.isfinite(self.radial_wind_speed)
        if use_status:
            keep &= self.status
        if cnr_threshold is not None:
            keep &= self.cnr >= cnr_threshold
        return np.where(keep, self.radial_wind_speed, np.nan)

    def range_elevation(self) -> np.ndarray:
        """Elevation ``(r,)`` degrees that the processing used for each ray: ``arcsin`` of the
        least-squares ratio ``sum(h r) / sum(r^2)`` of `measurement_height` ``h`` to `ranges`
        ``r`` over the ray's gates where both are finite (ranges are stored in whole metres:
        good to about 0.01 degree at 75 degrees over 20 gates); NaN for a ray without
        ``measurement_height``. Where it differs from `elevation`, the file's gates and wind
        products were computed for another elevation than the head's (module docs)."""
        h, r = self.measurement_height, self.ranges
        ok = np.isfinite(h) & np.isfinite(r)
        num = np.sum(np.where(ok, h * r, 0.0), axis=1)
        den = np.sum(np.where(ok, r * r, 0.0), axis=1)
        ratio = num / np.where(den > 0, den, np.nan)
        return np.degrees(np.arcsin(np.clip(ratio, -1.0, 1.0)))

    def seconds(self) -> np.ndarray:
        """Ray end times in seconds from the first ray's end ``(r,)``."""
        return (self.time - self.time[0]) / np.timedelta64(1, "us") * 1e-6

    def pattern(self) -> ScanPattern:
        """The file's layout as a `ScanPattern` (rays at its angles, accumulations ending at
        its times; seconds from the first ray's start, one accumulation before its time).
        Needs the same ranges on every ray (the committed 200S DBS gives two of its rays
        other ranges, module docs: use rays of one elevation and ranges)."""
        r0 = self.ranges[0]
        if not np.allclose(self.ranges, r0[None], atol=1e-6):
            raise ValueError(f"{self.path}: rays have different gate ranges; a ScanPattern needs the "
                             "same gates on every ray (select rays of one elevation).")
        # times from the first ray's start: ray k ends at its time, after one accumulation
        start = np.maximum.accumulate(self.seconds())
        return ScanPattern(self.azimuth, self.elevation, r0, ray_start=start,
                           accumulation=self.accumulation,
                           period=float(start[-1] + self.accumulation),
                           kind=self.sweep_mode if self.sweep_mode in ("ppi", "rhi") else "custom")


def _text(value) -> str:
    value = np.asarray(value).reshape(-1)[0] if np.size(value) else ""
    return value.decode() if isinstance(value, bytes) else str(value)


def read_windcube_scan(path: PathLike) -> WindcubeScan:
    """Read a Windcube 200S/400S scanning NetCDF file (module docs)."""
    p = require_file(path, "Windcube scan file")
    xr = import_optional("xarray", "netcdf", "Reading Windcube scan NetCDF")
    engine = netcdf_engine()
    try:
        root = xr.open_dataset(p, engine=engine, decode_times=False)
    except (OSError, ValueError) as err:
        raise file_error(p, None, f"not a readable NetCDF file ({type(err).__name__})") from None
    with root:
        if "sweep_group_name" not in root:
            raise file_error(p, None, "no 'sweep_group_name' variable: not a Windcube scan file")
        groups = [_text(g) for g in np.atleast_1d(root["sweep_group_name"].values)]
        instrument = str(root.attrs.get("instrument_name", ""))
    parts = []
    for k, name in enumerate(groups):
        try:
            ds = xr.open_dataset(p, engine=engine, group=name, decode_times=False)
        except (OSError, ValueError, KeyError):
            raise file_error(p, None, f"sweep group {name!r} named in sweep_group_name is "
                             f"missing") from None
        with ds:
            missing = [v for v in (*_RAY_VARS, *_GATE_VARS) if v not in ds]
            if missing:
                raise file_error(p, None, f"sweep {name!r} lacks {', '.join(missing)}")
            ref = _text(ds["time_reference"].values) if "time_reference" in ds else "1970-01-01T00:00:00Z"
            base = np.datetime64(ref.rstrip("Z"), "us")
            secs = np.asarray(ds["time"].values, np.float64)
            n = secs.size
            rng = np.broadcast_to(np.asarray(ds["range"].values, np.float64), ds["radial_wind_speed"].shape)
            status = (np.asarray(ds["radial_wind_speed_status"].values) == 1 if
                      "radial_wind_speed_status" in ds else np.ones(rng.shape, bool))
            cnr = (np.asarray(ds["cnr"].values, np.float64) if "cnr" in ds
                   else np.full(rng.shape, np.nan))
            products = {}
            for key, var in (("measurement_height", "measurement_height"),
                             ("horizontal_wind_speed", "horizontal_wind_speed"),
                             ("wind_direction", "wind_direction"),
                             ("vertical_wind_speed", "vertical_wind_speed")):
                products[key] = (np.broadcast_to(np.asarray(ds[var].values, np.float64), rng.shape)
                                 if var in ds else np.full(rng.shape, np.nan))
            products["wind_status"] = (np.asarray(ds["wind_speed_status"].values) == 1
                                       if "wind_speed_status" in ds else np.zeros(rng.shape, bool))
            parts.append(dict(
                time=base + np.round(secs * 1e6).astype("timedelta64[us]"),
                azimuth=np.asarray(ds["azimuth"].values, np.float64),
                elevation=np.asarray(ds["elevation"].values, np.float64), ranges=rng,
                radial_wind_speed=np.asarray(ds["radial_wind_speed"].values, np.float64),
                cnr=cnr, status=status, sweep=np.full(n, k), **products,
                gate_length=float(ds["range_gate_length"].values) if "range_gate_length" in ds else np.nan,
                accumulation=(float(ds["ray_accumulation_time"].values) * 1e-3
                              if "ray_accumulation_time" in ds else np.nan),
                mode=_text(ds["sweep_mode"].values) if "sweep_mode" in ds else ""))
    shapes = {q["ranges"].shape[1] for q in parts}
    if len(shapes) > 1:
        raise file_error(p, None, f"sweeps have different gate counts {sorted(shapes)}")
    cat = {k: np.concatenate([q[k] for q in parts]) for k in
           ("time", "azimuth", "elevation", "ranges", "radial_wind_speed", "cnr", "status", "sweep",
            "measurement_height", "horizontal_wind_speed", "wind_direction", "vertical_wind_speed",
            "wind_status")}
    order = np.argsort(cat["time"], kind="stable")
    cat = {k: v[order] for k, v in cat.items()}
    return WindcubeScan(path=str(p), instrument=instrument, sweep_mode=parts[0]["mode"],
                        gate_length=parts[0]["gate_length"], accumulation=parts[0]["accumulation"],
                        **cat)
