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

import copy
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
from ._exact import CellPointSnapshots, CellPointTets, finite_points
from .fields import FieldArrays, FieldLoadReport, _crop_arrays, _region_box, load_field
from .openfoam import (
    OpenFOAMField,
    _case_dir,
    _decomposed_mesh,
    _is_decomposed,
    _is_time_name,
    _read_decomposed,
    _read_vector_field,
    is_openfoam_case,
    openfoam_times,
    read_openfoam_mesh,
    resample_openfoam,
)

__all__ = ["load_field_sequence"]


def _time_bounds(time_range, name: str) -> tuple[float, float] | None:
    """`time_range` as ``(first, last)`` seconds (None: all), else a one-line ValueError."""
    if time_range is None:
        return None
    try:
        t0, t1 = (float(v) for v in time_range)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: `time_range` must be (first, last) seconds, got "
                         f"{time_range!r}.") from None
    return t0, t1


def _time_window(times: np.ndarray, time_range, name: str) -> np.ndarray:
    """Indices of `times` within `time_range` = (first, last) seconds, or all."""
    bounds = _time_bounds(time_range, name)
    if bounds is None:
        keep = np.arange(times.size)
    else:
        keep = np.flatnonzero((times >= bounds[0]) & (times <= bounds[1]))
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


def _absent_times(p: Path, field: str, names: list[str]) -> list[str]:
    """The time directories between the first and the last holding `field` that lack it (a
    decomposed case: those of processor0), in increasing time order."""
    root = p / "processor0" if _is_decomposed(p) else p
    t0, t1, have = float(names[0]), float(names[-1]), set(names)
    return sorted((d.name for d in root.iterdir() if d.is_dir() and _is_time_name(d.name)
                   and d.name not in have and t0 < float(d.name) < t1), key=float)


def _snapshot_names(p: Path, field: str, time_range, name: str):
    """``(names, times, absent)``: the snapshots' time directories (within `time_range`),
    their times (s), and those among them that lack `field` (NaN snapshots). A time
    directory without `field` between others is named in one warning: skipped (the series
    interpolates across it), or, within a `time_range` the caller gave, kept as a NaN
    snapshot (the LOS next to it NaN, flagged ``BEAM_OUTSIDE``)."""
    names = openfoam_times(p, field)
    if not names:
        raise ValueError(f"{name}: no time directory holds `{field}`.")
    absent = _absent_times(p, field, names)
    bounds = _time_bounds(time_range, name)
    kept = [] if bounds is None else [n for n in absent if bounds[0] <= float(n) <= bounds[1]]
    skipped = [n for n in absent if n not in kept]
    if skipped:
        warnings.warn(f"{name}: time {', '.join(skipped)} holds no `{field}` (skipped: the "
                      f"series interpolates across the gap)", stacklevel=4)
    if kept:
        warnings.warn(f"{name}: time {', '.join(kept)} within `time_range` holds no `{field}`: "
                      f"NaN snapshot (the LOS next to it NaN, flagged BEAM_OUTSIDE)",
                      stacklevel=4)
    names = sorted(names + kept, key=float)
    times = np.array([float(n) for n in names])
    keep = _time_window(times, time_range, name)
    return [names[k] for k in keep], times[keep], frozenset(kept)


class _FoamSnapshots:
    """The snapshots of one OpenFOAM case as a `FieldSequence`'s `load` and `assemble`: the
    mesh is read once; the first good snapshot fixes the geometry (`prepare`: the grid's
    nodes, the cells around them and, with `exact_at`, the prepared points' tetrahedra);
    every snapshot is then its velocity file read once and a sparse mix of its values."""

    def __init__(self, case, *, field, region, spacing, time_range, dtype, exact_at,
                 grid_fallback):
        self.p = _case_dir(case)
        self.name = os.fspath(self.p)
        self.field, self.region, self.spacing, self.dtype = field, region, spacing, dtype
        self.exact_at, self.grid_fallback = exact_at, grid_fallback
        self.names, self.times, self.absent = _snapshot_names(self.p, field, time_range,
                                                              self.name)
        self.decomposed = _is_decomposed(self.p)
        # the mesh is read once (a decomposed case: its processors merged once)
        self.merged = _decomposed_mesh(self.p) if self.decomposed else None
        self.mesh = self.merged[3] if self.decomposed else read_openfoam_mesh(self.p)
        self.prepared: dict[str, Any] = {}  # the geometry, from the first good snapshot

    def sequence(self, max_snapshots: int, can_be_exact: bool = True) -> FieldSequence:
        """The `FieldSequence` of these snapshots; without `exact_at` (and `can_be_exact`),
        one that `lidarjax.simulate_series` makes exact at a fixed lidar's points (its
        `made_exact`)."""
        exact = self.exact_at is not None
        return FieldSequence(self.times, self.load, max_snapshots=max_snapshots, name=self.name,
                             assemble=self.assemble if exact else None,
                             exact=self.with_exact if can_be_exact and not exact else None)

    def with_exact(self, exact_at, max_snapshots: int) -> FieldSequence:
        """The same snapshots (the mesh already read) prepared at `exact_at`."""
        twin = copy.copy(self)
        twin.exact_at, twin.prepared = exact_at, {}
        return twin.sequence(max_snapshots)

    def finite(self, values: np.ndarray, where: Path) -> None:
        """A one-line ValueError naming the file if any cell value is not finite."""
        if not np.isfinite(np.add.reduce(values, axis=None)):  # one pass; NaN/inf propagate
            bad = ~np.isfinite(values).all(axis=1)
            if bad.any():
                raise ValueError(f"{os.fspath(where / self.field)}: {int(bad.sum())} cell "
                                 f"values are not finite (first: cell {int(np.argmax(bad))})")

    def read(self, k: int, whole: bool = True) -> OpenFOAMField:
        """Snapshot `k`'s velocity, read once; a one-line ValueError naming its time
        directory for a changed mesh, a missing or unreadable file or (`whole`: anywhere in
        the mesh) non-finite values."""
        name, where = self.names[k], self.p / self.names[k]
        moved = _mesh_changes(self.p, name, self.decomposed)
        if moved is not None:
            raise ValueError(f"{os.fspath(moved)}: the mesh changes at time {name}; a "
                             f"sequence needs one mesh (select the times before it with "
                             f"`time_range`)")
        if name in self.absent:
            raise ValueError(f"{os.fspath(where / self.field)}: missing")
        try:
            if self.decomposed:
                _, values, boundary = _read_decomposed(self.p, name, self.field, self.merged)
            else:
                values, boundary = _read_vector_field(where / self.field, self.mesh)
        except (OSError, ValueError, EOFError) as err:
            text = str(err).splitlines()[0] if str(err) else type(err).__name__
            raise ValueError(text if os.fspath(where) in text else f"{os.fspath(where)}: {text}") from None
        if whole:
            self.finite(values, where)
        return OpenFOAMField(case=self.p, time=name, field=self.field, mesh=self.mesh,
                             cell_values=values, boundary=boundary)

    def prepare(self, of: OpenFOAMField) -> np.ndarray:
        """The geometry from snapshot `of` (the first good one): the graded grid's nodes and
        the cells around them, the sampler and its refill; returns `of`'s grid velocity."""
        axes, velocity, _ = resample_openfoam(of, self.region, self.spacing, check_points=0)
        cells = (cells_covering(of.bounds, axes) if self.grid_fallback
                 else np.zeros(0, np.int64))
        points = first = None
        if self.exact_at is not None:
            first = GridField(*axes, velocity if self.dtype is None else velocity.astype(self.dtype))
            points = self.exact_points(first)
            lo, hi = points.min(axis=0), points.max(axis=0)
            pad = 1e-6 * np.maximum(1.0, np.abs(np.concatenate([lo, hi])).max())
            cells = np.union1d(cells, of.cells_in_box(lo - pad, hi + pad))
        sampler, refill = build_sampler_and_values(of.mesh, of.cell_values, of.boundary, cells,
                                                   of.bounds)
        self.prepared.update(axes=axes, sampler=sampler, refill=refill)
        if self.grid_fallback:
            self.prepared["located"] = sampler.grid_locations(axes)
        else:  # no grid per snapshot: two NaN nodes per axis; the graded grid's axes kept
            self.prepared.update(axes=[np.array([a[0], a[-1]]) for a in axes])  # its spacing
        if points is not None:
            self.prepare_points(first, points)
        return velocity

    def exact_points(self, first: GridField) -> np.ndarray:
        """The `exact_at` points for the first snapshot's grid, checked."""
        at = self.exact_at
        return finite_points(at(first) if callable(at) else at, f"{self.name}: `exact_at`")

    def prepare_points(self, first: GridField, points: np.ndarray) -> None:
        """The prepared points' tetrahedra and vertex-value weights (`PointValues`)."""
        sampler, refill = self.prepared["sampler"], self.prepared["refill"]
        tets, _ = sampler.locate(points)
        found = tets >= 0
        vertices = np.full((points.shape[0], 4, 3), np.nan)
        if found.any():
            vertices[found] = sampler.tet_vertices(tets[found])[0]
        self.prepared.update(mix=refill.vertex_values(sampler, tets),
                             tets=CellPointTets(first, points, vertices, caller=self.name))
        if not self.grid_fallback:
            self.prepared["graded"] = (first.x_local, first.y_local, first.z_local)

    def exact_values(self, k: int, of: OpenFOAMField) -> np.ndarray:
        """The prepared points' vertex values from snapshot `k` (one sparse product); with
        no grid, only these values are used, so only these are checked (a ValueError naming
        the file if one is not finite)."""
        mix = self.prepared["mix"]
        exact = mix(of.cell_values, of.boundary)
        if not self.grid_fallback and not np.isfinite(np.add.reduce(exact[mix.found], axis=None)):
            where = self.p / self.names[k]
            self.finite(of.cell_values, where)  # names the cells
            raise ValueError(f"{os.fspath(where / self.field)}: boundary values the prepared "
                             f"points use are not finite")
        return exact

    def load(self, k: int):
        """Snapshot `k`: its grid (and with `exact_at` its prepared points' vertex values);
        NaN with a one-line warning where it cannot be read."""
        of, exact = self.read_for_load(k)
        velocity = self.ensure_prepared(of)
        grid = self.grid_of(of, velocity)
        if "mix" not in self.prepared:
            return grid
        if of is None:
            exact = np.full((self.prepared["tets"].n_points, 4, 3), np.nan)
        elif exact is None:
            exact = self.prepared["mix"](of.cell_values, of.boundary)
        return grid, exact

    def read_for_load(self, k: int):
        """``(of, exact)``: snapshot `k` read (None where it cannot be: a one-line warning,
        the other snapshots kept) and, with no grid after the first, its points' values."""
        lean = bool(self.prepared) and not self.grid_fallback
        try:
            # the first snapshot fixes the geometry and the graded grid: checked whole; with
            # no grid, a later one is checked where the prepared points use it
            of = self.read(k, whole=not lean)
            return of, self.exact_values(k, of) if lean else None
        except ValueError as err:  # a flagged window, the other snapshots kept
            if self.names[k] not in self.absent:  # those were named when the case was read
                warnings.warn(f"{err}; snapshot t = {self.times[k]:g} s is NaN (its LOS "
                              f"flagged BEAM_OUTSIDE)", stacklevel=2)
            return None, None

    def ensure_prepared(self, of: OpenFOAMField | None) -> np.ndarray | None:
        """The geometry, prepared from `of` or (it is None) the first good snapshot; the
        grid velocity of `of` where preparing resampled it."""
        if self.prepared:
            return None
        if of is not None:
            return self.prepare(of)
        for j in range(len(self.names)):  # the geometry from the next good snapshot
            try:
                self.prepare(self.read(j))
                return None
            except ValueError:
                continue
        raise ValueError(f"{self.name}: no snapshot of `{self.field}` could be read")

    def grid_of(self, of: OpenFOAMField | None, velocity: np.ndarray | None) -> GridField:
        """The snapshot's graded grid (NaN where it could not be read); with no grid, one
        NaN grid of two nodes per axis shared by every snapshot."""
        axes, dtype = self.prepared["axes"], self.dtype
        if not self.grid_fallback:
            if "nan_grid" not in self.prepared:
                nan = np.full((2, 2, 2, 3), np.nan, dtype or np.float64)
                self.prepared["nan_grid"] = GridField(*axes, nan)
            return self.prepared["nan_grid"]
        if of is None:
            velocity = np.full(tuple(a.size for a in axes) + (3,), np.nan)
        elif velocity is None:
            sampler, refill = self.prepared["sampler"], self.prepared["refill"]
            velocity = sampler.with_values(*refill(of.cell_values, of.boundary)).values_at(
                *self.prepared["located"])
        return GridField(*axes, velocity if dtype is None else velocity.astype(dtype))

    def assemble(self, window_times, snaps):
        """A window's `CellPointSnapshots` from what `load` returned for its snapshots."""
        grid = SnapshotField(window_times, [g for g, _ in snaps])
        return CellPointSnapshots(grid, self.prepared["tets"], np.stack([e for _, e in snaps]),
                                  axes=self.prepared.get("graded"))


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
      its velocity file read once and a sparse matrix product. Non-finite points are refused
      (a ValueError) before the mesh is read. Without `exact_at` (None, the default) an
      OpenFOAM sequence is made exact by `lidarjax.simulate_series` itself at the points a
      fixed lidar samples (``FieldSequence.made_exact``, `lidarjax.ExactPoints`), and a run
      that cannot be (a moving lidar) warns in one line; ``exact_at=False``: the graded grid
      only, never made exact, no warning.
    - `grid_fallback`: with `exact_at`: False skips the graded grid of every snapshot (its
      resampling costs several times the read of a binary velocity file): a query at a point
      not prepared is then NaN (a LOS flagged ``BEAM_OUTSIDE``). For a run that samples only
      its prepared points (a fixed lidar); the probe's nodes are still chosen for the graded
      grid's resolution.

    A time directory without `field` between others is named in a one-line warning: skipped
    (the series interpolates across the gap), or, within a `time_range` given, kept as a NaN
    snapshot (the LOS next to it NaN, flagged ``BEAM_OUTSIDE``). A snapshot whose time
    directory holds a changed mesh (`polyMesh`), whose velocity cannot be read (missing on
    a processor, truncated, corrupt) or has non-finite values is NaN, with a one-line
    warning naming the time directory: the LOS whose times fall next to it
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
    graded_only = exact_at is False  # the graded grid only: never made exact, no warning
    exact_at = None if graded_only else exact_at
    if exact_at is not None and not callable(exact_at):  # before any mesh work
        exact_at = finite_points(exact_at, "load_field_sequence: `exact_at`")
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
        snaps = _FoamSnapshots(p, field=field, region=region, spacing=spacing,
                               time_range=time_range, dtype=dtype, exact_at=exact_at,
                               grid_fallback=grid_fallback)
        return snaps.sequence(max_snapshots, can_be_exact=not graded_only)
    if p.suffix.lower() in (".nc", ".nc4", ".netcdf", ".cdf", ".h5", ".hdf5"):
        if spacing is not None or times is not None:
            raise ValueError(f"{text}: a NetCDF sequence takes its grid and times from the file;"
                             f" drop `spacing`/`times`.")
        return _netcdf_sequence(p, region=region, time_range=time_range, dtype=dtype,
                                max_snapshots=max_snapshots)
    raise ValueError(f"{text}: not an OpenFOAM case or a NetCDF file with a time axis; for "
                     f"one file per snapshot give a list of files (or a glob) and `times`.")
