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
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .._util import PathLike, import_optional
from ..field import FieldSequence, GridField, SnapshotField
from ._cells import build_sampler_and_values
from ._exact import CellPointSnapshots, CellPointTets
from .fields import FieldArrays, FieldLoadReport, _crop_arrays, _region_box, load_field
from .openfoam import (
    OpenFOAMField,
    _case_dir,
    _decomposed_mesh,
    _is_decomposed,
    _read_decomposed,
    _read_vector_field,
    is_openfoam_case,
    openfoam_times,
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


def _mesh_changes(p: Path, name: str, decomposed: bool) -> Path | None:
    """The `polyMesh` a time directory holds (a mesh that moves or changes there), or None."""
    for d in ([q for q in sorted(p.glob("processor*")) if q.is_dir()] if decomposed else [p]):
        if (d / name / "polyMesh").is_dir():
            return d / name / "polyMesh"
    return None


def _openfoam_sequence(case, *, field, region, spacing, time_range, dtype, max_snapshots,
                       exact_at=None, grid_fallback=True):
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
    # the mesh is read once (a decomposed case: its processors merged once)
    merged = _decomposed_mesh(p) if decomposed else None
    mesh = merged[3] if decomposed else read_openfoam_mesh(p)
    prepared: dict[str, Any] = {}  # the geometry, built once from the first good snapshot

    def finite(values: np.ndarray, where: Path) -> None:
        """A one-line ValueError naming the file if any cell value is not finite."""
        if not np.isfinite(np.add.reduce(values, axis=None)):  # one pass; NaN/inf propagate
            bad = ~np.isfinite(values).all(axis=1)
            if bad.any():
                raise ValueError(f"{os.fspath(where / field)}: {int(bad.sum())} cell values are "
                                 f"not finite (first: cell {int(np.argmax(bad))})")

    def read(k: int, whole: bool = True) -> OpenFOAMField:
        """Snapshot `k`'s velocity, read once; a one-line ValueError naming its time
        directory for a changed mesh, an unreadable file or (`whole`: anywhere in the mesh)
        non-finite values."""
        where = p / names[k]
        moved = _mesh_changes(p, names[k], decomposed)
        if moved is not None:
            raise ValueError(f"{os.fspath(moved)}: the mesh changes at time {names[k]}; a "
                             f"sequence needs one mesh (select the times before it with "
                             f"`time_range`)")
        try:
            if decomposed:
                _, values, boundary = _read_decomposed(p, names[k], field, merged)
            else:
                values, boundary = _read_vector_field(where / field, mesh)
        except (OSError, ValueError, EOFError) as err:
            text = str(err).splitlines()[0] if str(err) else type(err).__name__
            raise ValueError(text if os.fspath(where) in text else f"{os.fspath(where)}: {text}") from None
        if whole:
            finite(values, where)
        return OpenFOAMField(case=p, time=names[k], field=field, mesh=mesh, cell_values=values,
                             boundary=boundary)

    def prepare(of: OpenFOAMField):
        """The first good snapshot fixes the grid's nodes, the cells around them and (with
        `exact_at`) the tetrahedra of the prepared points; every snapshot is then the same
        sparse mix of its own values (`PointValues`, `VertexValues`)."""
        axes, velocity, _ = resample_openfoam(of, region, spacing, check_points=0)
        cells = cells_covering(of.bounds, axes) if grid_fallback else np.zeros(0, np.int64)
        points = None
        if exact_at is not None:
            first = GridField(*axes, velocity if dtype is None else velocity.astype(dtype))
            points = np.asarray(exact_at(first) if callable(exact_at) else exact_at,
                                np.float64).reshape(-1, 3)
            if points.shape[0] == 0 or not np.isfinite(points).all():
                raise ValueError(f"{name}: `exact_at` must give finite (n, 3) CFD metres, n >= 1")
            lo, hi = points.min(axis=0), points.max(axis=0)
            pad = 1e-6 * np.maximum(1.0, np.abs(np.concatenate([lo, hi])).max())
            cells = np.union1d(cells, of.cells_in_box(lo - pad, hi + pad))
        sampler, refill = build_sampler_and_values(of.mesh, of.cell_values, of.boundary, cells,
                                                   of.bounds)
        prepared.update(axes=axes, sampler=sampler, refill=refill)
        if grid_fallback:
            prepared["located"] = sampler.grid_locations(axes)
        else:  # no grid per snapshot: two NaN nodes per axis; the graded grid's axes kept
            prepared.update(axes=[np.array([a[0], a[-1]]) for a in axes])  # for its spacing
        if points is not None:
            tets, _ = sampler.locate(points)
            found = tets >= 0
            vertices = np.full((points.shape[0], 4, 3), np.nan)
            if found.any():
                vertices[found] = sampler.tet_vertices(tets[found])[0]
            prepared.update(mix=refill.vertex_values(sampler, tets),
                            tets=CellPointTets(first, points, vertices, caller=name))
            if not grid_fallback:
                prepared["graded"] = (first.x_local, first.y_local, first.z_local)
        return velocity

    def exact_values(k: int, of: OpenFOAMField) -> np.ndarray:
        """The prepared points' vertex values from snapshot `k` (one sparse product); with
        no grid, only these values are used, so only these are checked (a ValueError naming
        the file if one is not finite)."""
        mix = prepared["mix"]
        exact = mix(of.cell_values, of.boundary)
        if not grid_fallback and not np.isfinite(np.add.reduce(exact[mix.found], axis=None)):
            where = p / names[k]
            finite(of.cell_values, where)  # names the cells
            raise ValueError(f"{os.fspath(where / field)}: boundary values the prepared points "
                             f"use are not finite")
        return exact

    def load(k: int):
        exact = None
        try:
            # the first snapshot fixes the geometry and the graded grid: checked whole; with
            # no grid, a later one is checked where the prepared points use it
            of = read(k, whole=grid_fallback or not prepared)
            if prepared and not grid_fallback:
                exact = exact_values(k, of)
        except ValueError as err:  # a flagged window, the other snapshots kept
            warnings.warn(f"{err}; snapshot t = {times[k]:g} s is NaN (its LOS flagged "
                          f"BEAM_OUTSIDE)", stacklevel=2)
            of = None
        if not prepared:
            if of is None:  # the geometry from the next good snapshot
                for j in range(len(names)):
                    try:
                        prepare(read(j))
                        break
                    except ValueError:
                        continue
                else:
                    raise ValueError(f"{name}: no snapshot of `{field}` could be read")
                velocity = None
            else:
                velocity = prepare(of)
        elif of is not None:
            velocity = None
        axes, sampler = prepared["axes"], prepared["sampler"]
        if not grid_fallback:  # one NaN grid of two nodes per axis, shared by every snapshot
            if "nan_grid" not in prepared:
                nan = np.full((2, 2, 2, 3), np.nan, dtype or np.float64)
                prepared["nan_grid"] = GridField(*axes, nan)
            grid = prepared["nan_grid"]
        else:
            if of is None:
                velocity = np.full(tuple(a.size for a in axes) + (3,), np.nan)
            elif velocity is None:
                velocity = sampler.with_values(*prepared["refill"](of.cell_values, of.boundary)
                                               ).values_at(*prepared["located"])
            if dtype is not None:
                velocity = velocity.astype(dtype)
            grid = GridField(*axes, velocity)
        if "mix" not in prepared:
            return grid
        n = prepared["tets"].n_points
        if of is None:
            exact = np.full((n, 4, 3), np.nan)
        elif exact is None:
            exact = prepared["mix"](of.cell_values, of.boundary)
        return grid, exact

    def assemble(window_times, snaps):
        grid = SnapshotField(window_times, [g for g, _ in snaps])
        return CellPointSnapshots(grid, prepared["tets"], np.stack([e for _, e in snaps]),
                                  axes=prepared.get("graded"))

    return FieldSequence(times, load, max_snapshots=max_snapshots, name=name,
                         assemble=assemble if exact_at is not None else None)


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
    exact_at: Any = None,
    grid_fallback: bool = True,
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
    - `exact_at`: OpenFOAM only: the points the run will sample, ``(n, 3)`` absolute CFD
      metres, or a function of the first snapshot's `GridField` returning them (the probe's
      nodes depend on its spacing along the beams: ``lidarjax.ExactPoints(scan, mount,
      heights, probe)`` for a fixed profiler, the nodes `lidarjax.simulate_series` chooses).
      Each window is then a `lidarjax.io.CellPointSnapshots`: at those points every
      snapshot is the mesh's own cellPoint (what OpenFOAM's `probes` report), linear in time
      between snapshots; the graded grid answers any other point (a moving lidar's). The
      tetrahedra of the points, the cells around the grid's nodes and the point-value
      weights are found once (the mesh is the same in every snapshot); each snapshot is then
      its velocity file read once and a sparse matrix product.
    - `grid_fallback`: with `exact_at`: False skips the graded grid of every snapshot (its
      resampling costs several times the read of a binary velocity file): a query at a point
      not prepared is then NaN (a LOS flagged ``BEAM_OUTSIDE``). For a run that samples only
      its prepared points (a fixed lidar); the probe's nodes are still chosen for the graded
      grid's resolution.

    A snapshot whose time directory holds a changed mesh (`polyMesh`), whose velocity cannot
    be read (missing on a processor, truncated, corrupt) or has non-finite values is NaN,
    with a one-line warning naming the time directory: the LOS whose times fall next to it
    are NaN (flagged ``BEAM_OUTSIDE``), every other snapshot is kept. Non-finite values are
    looked for in the whole mesh, except with ``grid_fallback=False`` after the first good
    snapshot: there only the values the prepared points use are read into the run, and only
    those are checked (a non-finite value elsewhere in the mesh does not flag the snapshot).

    **Returns:** a `lidarjax.FieldSequence` (pass it to `lidarjax.simulate_series` as the
    field). Raises `ValueError` naming the file for fewer than two snapshots, times that do
    not increase, or snapshots on different grids (when they are loaded).
    """
    if region is not None:
        _region_box(region)  # validates
    if exact_at is not None and (isinstance(source, (list, tuple)) or not is_openfoam_case(
            Path(os.fspath(source)))):
        raise ValueError(f"{source!r}: `exact_at` applies to an OpenFOAM case (a mesh); "
                         "gridded snapshots are their own data.")
    if not grid_fallback and exact_at is None:
        raise ValueError("load_field_sequence: grid_fallback=False needs `exact_at` (the points "
                         "the run samples); without them every query needs the grid.")
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
                                  max_snapshots=max_snapshots, exact_at=exact_at,
                                  grid_fallback=grid_fallback)
    if p.suffix.lower() in (".nc", ".nc4", ".netcdf", ".cdf", ".h5", ".hdf5"):
        if spacing is not None or times is not None:
            raise ValueError(f"{text}: a NetCDF sequence takes its grid and times from the file;"
                             f" drop `spacing`/`times`.")
        return _netcdf_sequence(p, region=region, time_range=time_range, dtype=dtype,
                                max_snapshots=max_snapshots)
    raise ValueError(f"{text}: not an OpenFOAM case or a NetCDF file with a time axis; for "
                     f"one file per snapshot give a list of files (or a glob) and `times`.")
