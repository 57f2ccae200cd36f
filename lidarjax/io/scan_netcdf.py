"""CF NetCDF of scanning-lidar scans (simulated or read), dimensions time x beam x range.

`write_scan_netcdf` writes CF-1.8 NetCDF (optional extra ``netcdf``: xarray, h5netcdf) with
dimensions ``time`` (scan repetitions), ``beam`` (rays of one repetition) and ``range``
(gates): ``radial_velocity`` (``time, beam, range``; standard name
``radial_velocity_of_scatterers_away_from_instrument``, m s-1), ``ray_time`` (``time, beam``,
seconds since the start), ``azimuth`` and ``elevation`` (``beam``, degrees), ``range`` (m) and
``flags``; written atomically (a temporary file, then renamed). `read_scan_netcdf` reads it
back.
"""

from __future__ import annotations

import numpy as np

from .._util import PathLike, atomic_path, import_optional, netcdf_engine, require_file

__all__ = ["write_scan_netcdf", "read_scan_netcdf"]


def write_scan_netcdf(path: PathLike, los, *, azimuth, elevation, ranges, ray_time,
                      flags=None, title: str = "lidarjax scan", attrs: dict | None = None):
    """Write scans as CF NetCDF ``time x beam x range`` (module docs).

    **Arguments:** `los` ``(n, r, g)`` or ``(r, g)`` m/s (positive away); `azimuth`,
    `elevation` ``(r,)`` degrees; `ranges` ``(g,)`` m; `ray_time` ``(n, r)`` or ``(r,)`` s
    since the start; `flags` like `los` (int, optional); `attrs` extra global attributes.
    A `lidarjax.scanning.ScanResult` gives all of them: ``write_scan_netcdf(path, res.los,
    azimuth=res.azimuth, elevation=res.elevation, ranges=res.ranges, ray_time=res.times,
    flags=res.flags)``. Returns the path written."""
    xr = import_optional("xarray", "netcdf", "write_scan_netcdf")
    los = np.asarray(los, np.float64)
    if los.ndim == 2:
        los = los[None]
    n, r, g = los.shape if los.ndim == 3 else (0, 0, 0)
    if los.ndim != 3:
        raise ValueError(f"write_scan_netcdf: `los` must be (time, beam, range) or (beam, range), "
                         f"got shape {np.shape(los)}.")
    az, el = np.broadcast_to(np.asarray(azimuth, np.float64), (r,)), np.broadcast_to(
        np.asarray(elevation, np.float64), (r,))
    rng = np.asarray(ranges, np.float64)
    t = np.asarray(ray_time, np.float64).reshape(-1, r) if np.size(ray_time) else None
    if rng.shape != (g,) or t is None or t.shape != (n, r):
        raise ValueError(f"write_scan_netcdf: shapes disagree: los {los.shape}, ranges {rng.shape}, "
                         f"ray_time {np.shape(ray_time)}; need (g,) ranges and (time, beam) times.")
    data = {
        "radial_velocity": (("time", "beam", "range"), los, {
            "standard_name": "radial_velocity_of_scatterers_away_from_instrument",
            "units": "m s-1", "long_name": "line-of-sight velocity, positive away from the lidar"}),
        "ray_time": (("time", "beam"), t, {"units": "s", "long_name": "mid-accumulation time of "
                                           "each ray, seconds since the start"}),
        "azimuth": (("beam",), az, {"standard_name": "sensor_azimuth_angle", "units": "degree",
                                    "long_name": "ray azimuth, clockwise from north (mount frame)"}),
        "elevation": (("beam",), el, {"units": "degree", "long_name": "ray elevation above the "
                                      "horizon (mount frame)"}),
    }
    if flags is not None:
        data["flags"] = (("time", "beam", "range"),
                         np.broadcast_to(np.asarray(flags, np.int32), los.shape),
                         {"long_name": "lidarjax.Flag bitmask", "flag_masks": np.int32([1, 32]),
                          "flag_meanings": "beam_outside probe_truncated"})
    ds = xr.Dataset(
        {k: xr.Variable(dims, np.asarray(v), a) for k, (dims, v, a) in data.items()},
        coords={"time": ("time", t[:, 0], {"units": "s", "long_name": "start of each scan "
                                                  "repetition (its first ray), s since the start"}),
                "range": ("range", rng, {"units": "m", "long_name": "gate-centre range along "
                                         "the beam"})},
        attrs={"Conventions": "CF-1.8", "title": title, "source": "lidarjax", **(attrs or {})})
    with atomic_path(path) as tmp:
        ds.to_netcdf(tmp, engine=netcdf_engine())
    return path


def read_scan_netcdf(path: PathLike) -> dict:
    """A file of `write_scan_netcdf` as a dict of numpy arrays: ``radial_velocity`` ``(n, r,
    g)``, ``ray_time`` ``(n, r)``, ``azimuth``, ``elevation`` ``(r,)``, ``range`` ``(g,)``,
    ``flags`` (when written) and ``attrs``."""
    p = require_file(path, "scan NetCDF file")
    xr = import_optional("xarray", "netcdf", "read_scan_netcdf")
    with xr.open_dataset(p, engine=netcdf_engine(), decode_times=False) as ds:
        out = {k: np.asarray(ds[k].values) for k in ("radial_velocity", "ray_time", "azimuth",
                                                      "elevation", "range", "flags") if k in ds}
        out["attrs"] = dict(ds.attrs)
    return out
