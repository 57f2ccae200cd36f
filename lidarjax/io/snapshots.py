"""Unsteady CFD (LES, URANS) as one time-dependent field: snapshot sequences on disk.

`load_field_sequence` turns the snapshots of a run into a `lidarjax.FieldSequence`, which
`lidarjax.simulate_series` flies the scan through a window of snapshots at a time (linear in
time between snapshots, NaN and `lidarjax.Flag.TIME_OUTSIDE` outside their span). Sources:

- an **OpenFOAM case** (plain or decomposed): its time directories holding `U` (optionally
  only those within `time_range`); the mesh is read once and every snapshot is sampled with
  the mesh's own cellPoint interpolation onto one grid (the same nodes for every snapshot:
  `spacing`, or the automatic graded grid of `lidarjax.io.load_field`), cropped to `region`;
- a **NetCDF file with a time axis**: ``u, v, w`` on dimensions ``(time, x, y, z)`` (any
  order, any case), coordinate ``time`` in seconds (datetimes are turned into seconds from
  the first); extra ``netcdf`` (xarray). One snapshot is read from disk per load;
- a **list of gridded field files** (`.npz`, NetCDF, one snapshot each) or a glob pattern,
  with their `times`.

Nothing is read beyond the time directories' names (or the NetCDF's coordinates) until
`simulate_series` asks for a window; at most `max_snapshots` snapshots are held.
"""

from __future__ import annotations

import glob
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .._util import PathLike, import_optional
from ..field import FieldSequence, GridField
from ._cells import build_sampler_and_values
from .fields import FieldArrays, FieldLoadReport, _crop_arrays, _region_box, load_field
from .openfoam import (
    OpenFOAMField,
    _case_dir,
    _is_decomposed,
    _read_vector_field,
    is_openfoam_case,
    openfoam_times,
    read_openfoam_field,
    read_openfoam_mesh,
    resample_openfoam,
)

__all__ = ["load_field_sequence"]


def _time_window(times: np.ndarray, time_range, name: str) -> np.ndarray:
    """Indices of `times` within `time_range` = (first, last) seconds, or all."""
    if time_range is None:
        keep = np.arange(times.size)
    else:
        try:
            t0, t1 = (float(v) for v in time_range)
        except (TypeError, ValueError):
            raise ValueError(f"{name}: `time_range` must be (first, last) seconds, got "
                             f"{time_range!r}.") from None
        keep = np.flatnonzero((times >= t0) & (times <= t1))
    if keep.size < 2:
        raise ValueError(f"{name}: needs at least two snapshots to interpolate in time; found "
                         f"{keep.size} (times {times.tolist()[:8]}{' ...' if times.size > 8 else ''}"
                         f"{'' if time_range is None else f', time_range {time_range!r}'}).")
    return keep


def cells_covering(bounds, axes) -> np.ndarray:
    """Global numbers of the cells whose bounding boxes (`OpenFOAMField.bounds`) overlap the
    grid of `axes` (a relative margin of 1e-6 keeps the nodes on its faces)."""
    clo, chi = bounds
    lo, hi = np.array([a[0] for a in axes]), np.array([a[-1] for a in axes])
    pad = np.maximum(1e-6 * np.maximum(np.abs(lo), np.abs(hi)), 1e-9)
    return np.flatnonzero(((chi >= lo - pad) & (clo <= hi + pad)).all(axis=1))


def _openfoam_sequence(case, *, field, region, spacing, time_range, dtype, max_snapshots):
    p = _case_dir(case)
    name = os.fspath(p)
    names = openfoam_times(p, field)
    times = np.array([float(n) for n in names])
    if times.size == 0:
        raise ValueError(f"{name}: no time directory holds `{field}`.")
    keep = _time_window(times, time_range, name)
    names = [names[k] for k in keep]
    times = times[keep]
    decomposed = _is_decomposed(p)
    mesh = None if decomposed else read_openfoam_mesh(p)
    axes: list[np.ndarray] = []
    cells: list[np.ndarray] = []
    bounds: list[Any] = []
    prepared: list[Any] = []  # (sampler, its PointValues, the grid nodes' tets and weights)

    def load(k: int) -> GridField:
        if decomposed:
            of = read_openfoam_field(p, field=field, time=names[k])
        else:
            values, boundary = _read_vector_field(p / names[k] / field, mesh)
            of = OpenFOAMField(case=p, time=names[k], field=field, mesh=mesh,
                               cell_values=values, boundary=boundary)
        # the first snapshot fixes the nodes (and the cells around them); every later one is
        # sampled by cellPoint at the same nodes. The mesh is the same in every snapshot, so
        # the cells' tetrahedra, the point-value weights and each node's tetrahedron are
        # found once (at the second snapshot) and every later snapshot only mixes its values
        if not axes:
            grid, velocity, _ = resample_openfoam(of, region, spacing, check_points=0)
            axes.extend(grid)
            cells.append(cells_covering(of.bounds, grid))
        elif not prepared:
            sampler, refill = build_sampler_and_values(of.mesh, of.cell_values, of.boundary, cells[0],
                                                       bounds[0])
            prepared.extend((sampler, refill, sampler.grid_locations(axes)))
            velocity = sampler.values_at(*prepared[2])
        else:
            sampler, refill, located = prepared
            velocity = sampler.with_values(*refill(of.cell_values, of.boundary)).values_at(*located)
        if not bounds:
            bounds.append(of.bounds)
        grid = axes
        if dtype is not None:
            velocity = velocity.astype(dtype)
        return GridField(*grid, velocity)

    return FieldSequence(times, load, max_snapshots=max_snapshots, name=name)


def _netcdf_sequence(path: Path, *, region, time_range, dtype, max_snapshots):
    xr = import_optional("xarray", "netcdf", "Reading NetCDF snapshot sequences")
    name = os.fspath(path)
    with xr.open_dataset(path) as ds:
        tvar = next((v for v in ds.variables if str(v).lower() == "time"), None)
        if tvar is None:
            raise ValueError(f"{name}: no `time` coordinate; a snapshot sequence needs u, v, w "
                             f"on (time, x, y, z).")
        raw = np.asarray(ds[tvar].values)
    if np.issubdtype(raw.dtype, np.datetime64):
        times = (raw - raw[0]) / np.timedelta64(1, "ns") * 1e-9
    else:
        times = raw.astype(np.float64)
    keep = _time_window(times, time_range, name)

    def load(k: int) -> GridField:
        with xr.open_dataset(path) as ds:
            tdim = next(d for d in ds.dims if str(d).lower() == "time")
            comps, coords = [], None
            for c in "uvw":
                var = next((v for v in ds.data_vars if str(v).lower() == c), None)
                if var is None:
                    raise ValueError(f"{name}: missing variable {c} (u, v, w on time, x, y, z).")
                da = ds[var].isel({tdim: int(keep[k])})
                dims = [next((d for d in da.dims if str(d).lower() == a), None) for a in "xyz"]
                if None in dims or len(da.dims) != 3:
                    raise ValueError(f"{name}: variable {var} must have dimensions (time, x, y, "
                                     f"z), got {ds[var].dims}.")
                comps.append(np.asarray(da.transpose(*dims).values, np.float64))
                coords = [np.asarray(ds[d].values, np.float64) for d in dims]
        velocity = np.stack(comps, axis=-1)
        if region is not None:
            report = FieldLoadReport(path=name, format="netcdf", shape=velocity.shape[:3],
                                     n_points=int(np.prod(velocity.shape[:3])),
                                     outside_fraction=0.0, nan_fraction=0.0)
            arrays = _crop_arrays(FieldArrays(*coords, velocity, report), region)
            coords, velocity = [arrays.x, arrays.y, arrays.z], arrays.velocity
        if dtype is not None:
            velocity = velocity.astype(dtype)
        return GridField(*coords, velocity)

    return FieldSequence(times[keep], load, max_snapshots=max_snapshots, name=name)


def _files_sequence(paths: list[Path], times, *, region, dtype, max_snapshots, name):
    if times is None:
        raise ValueError(f"{name}: give `times` (seconds, one per file) for a list of field "
                         f"files.")
    t = np.asarray(times, np.float64).reshape(-1)
    if t.size != len(paths):
        raise ValueError(f"{name}: {len(paths)} files but {t.size} times; give one time per "
                         f"file (seconds).")
    for p in paths:
        if not p.is_file():
            raise FileNotFoundError(f"field file not found: {os.fspath(p)}")

    def load(k: int) -> GridField:
        return load_field(paths[k], region=region, dtype=dtype)

    return FieldSequence(t, load, max_snapshots=max_snapshots, name=name)


def load_field_sequence(
    source: PathLike | Sequence[PathLike],
    *,
    times: Sequence[float] | None = None,
    region: tuple[Any, Any] | None = None,
    spacing: float | Sequence[float] | None = None,
    time_range: tuple[float, float] | None = None,
    field: str = "U",
    dtype: Any = None,
    max_snapshots: int = 8,
) -> FieldSequence:
    """The snapshots of an unsteady CFD run as one time-dependent field (`FieldSequence`).

    **Arguments:**

    - `source`: an OpenFOAM case directory (its time directories are the snapshots), a
      NetCDF file with a ``time`` axis, or a list (or glob pattern) of gridded field files.
    - `times`: seconds, one per file (a list of files only; a glob's matches are sorted by
      name first).
    - `region`: ``(lo, hi)`` CFD metres, e.g. `lidarjax.scan_bounds(...)`: each snapshot is
      read (OpenFOAM: sampled) there only, plus one node of margin.
    - `spacing`: OpenFOAM only: grid spacing, metres (default the automatic graded grid).
    - `time_range`: ``(first, last)`` seconds: the snapshots within it only.
    - `field`: OpenFOAM's vector field name (default ``U``).
    - `dtype`: the working float dtype of every snapshot (default JAX's default float).
    - `max_snapshots`: the most snapshots held at once (a window; at least 2).

    **Returns:** a `lidarjax.FieldSequence` (pass it to `lidarjax.simulate_series` as the
    field). Raises `ValueError` naming the file for fewer than two snapshots, times that do
    not increase, or snapshots on different grids (when they are loaded).
    """
    if region is not None:
        _region_box(region)  # validates
    if isinstance(source, (list, tuple)):
        paths = [Path(p) for p in source]
        return _files_sequence(paths, times, region=region, dtype=dtype,
                               max_snapshots=max_snapshots, name=f"{len(paths)} field files")
    text = os.fspath(source)
    if any(ch in text for ch in "*?["):
        paths = [Path(p) for p in sorted(glob.glob(text))]
        if not paths:
            raise FileNotFoundError(f"no field file matches {text!r}")
        return _files_sequence(paths, times, region=region, dtype=dtype,
                               max_snapshots=max_snapshots, name=text)
    p = Path(source)
    if not p.exists():
        raise FileNotFoundError(f"snapshot source not found: {text}")
    if is_openfoam_case(p):
        if times is not None:
            raise ValueError(f"{text}: an OpenFOAM case's times are its time directories; "
                             f"use `time_range` to select them.")
        return _openfoam_sequence(p, field=field, region=region, spacing=spacing,
                                  time_range=time_range, dtype=dtype,
                                  max_snapshots=max_snapshots)
    if p.suffix.lower() in (".nc", ".nc4", ".netcdf", ".cdf", ".h5", ".hdf5"):
        if spacing is not None or times is not None:
            raise ValueError(f"{text}: a NetCDF sequence takes its grid and times from the file;"
                             f" drop `spacing`/`times`.")
        return _netcdf_sequence(p, region=region, time_range=time_range, dtype=dtype,
                                max_snapshots=max_snapshots)
    raise ValueError(f"{text}: not an OpenFOAM case or a NetCDF file with a time axis; for "
                     f"one file per snapshot give a list of files (or a glob) and `times`.")
