"""CFD velocity fields from files: `.npz`, NetCDF, Fluent ASCII exports, OpenFOAM cases.

All readers return node coordinates in metres (CFD frame, 1-D, strictly increasing) and
velocities `(nx, ny, nz, 3)` = `(u, v, w)` in m/s in the CFD frame, the arguments of
`lidarjax.GridField`. NaN velocities mark solid nodes (and, for resampled scattered
data, nodes outside the data's convex hull).

- `.npz` (numpy): arrays `x (nx,)`, `y (ny,)`, `z (nz,)` and `u`, `v`, `w` each
  `(nx, ny, nz)`, or one `velocity (nx, ny, nz, 3)`;
- `.nc`, `.nc4`, `.cdf` (NetCDF): variables `u`, `v`, `w` on coordinates `x`, `y`, `z`
  in any dimension order; needs xarray (`pip install lidarjax[netcdf]`);
- a directory (or `format="openfoam"`): an OpenFOAM case (`constant/polyMesh` plus a
  time directory's `U`, ASCII or binary, plain or gzipped), sampled with the mesh's own
  cellPoint interpolation onto a grid resolving its cells (see `lidarjax.io.openfoam`);
- `.vtu`, `.vtk`, `.vtm` (VTK unstructured grids, e.g. from `foamToVTK` or ParaView; cell
  and/or point data): sampled inside their own cells like OpenFOAM cases (see
  `lidarjax.io.vtk`; needs meshio: `pip install lidarjax[meshio]`);
- anything else (`.csv`, `.txt`, `.dat`, `.ascii`): a Fluent ASCII export, whose header
  names `x-coordinate`, `y-coordinate`, `z-coordinate`, `x-velocity`, `y-velocity`,
  `z-velocity` in any order among other columns (`nodenumber`, `pressure` ...), comma or
  whitespace separated; rows are scattered nodes or cell centres.

Scattered Fluent points are resampled onto a regular grid spanning their bounding box by
piecewise-linear interpolation on their Delaunay triangulation (the scheme of
`scipy.interpolate.griddata(method="linear")`); nodes outside the convex hull are NaN and
their fraction is reported in `FieldLoadReport.outside_fraction`. Linear fields are
reproduced exactly (to rounding) inside the hull.
"""

from __future__ import annotations

import dataclasses
import math
import os
import zipfile
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from jaxtyping import Float
from scipy.spatial import Delaunay, QhullError

from .._util import (
    PathLike,
    atomic_path,
    file_error,
    have_module,
    import_optional,
    netcdf_engine,
    normalise_key,
    require_file,
)
from ..beam import register_mesh_grid
from ..field import GridField
from ..progress import AbstractProgress, NoProgress, TqdmProgress, progress_meter
from ._exact import cellpoint_field, finite_points
from .openfoam import is_openfoam_case, read_openfoam_field, resample_with_sampler
from .vtk import read_vtk_field

__all__ = [
    "FieldArrays",
    "FieldLoadReport",
    "load_field",
    "read_field_arrays",
    "read_fluent_points",
    "resample_to_grid",
    "save_field_netcdf",
    "save_field_npz",
]

DEFAULT_MAX_NODES_PER_AXIS = 128
"""Upper bound of the default grid size per axis for scattered data."""

DEFAULT_MAX_EDGE_FACTOR = 4.0
"""Scattered data: simplices whose longest edge exceeds this many local node spacings are
taken as bridging a solid and masked (see `resample_to_grid`)."""

_NETCDF_SUFFIXES = (".nc", ".nc4", ".cdf", ".netcdf")
_FLUENT_NAMES = {
    "xcoordinate": 0,
    "ycoordinate": 1,
    "zcoordinate": 2,
    "xvelocity": 3,
    "yvelocity": 4,
    "zvelocity": 5,
}
_FLUENT_REQUIRED = (
    "x-coordinate",
    "y-coordinate",
    "z-coordinate",
    "x-velocity",
    "y-velocity",
    "z-velocity",
)


@dataclasses.dataclass(frozen=True)
class FieldLoadReport:
    """What a field reader did.

    **Fields:**

    - `path`: the file (or `"<arrays>"` for `resample_to_grid`).
    - `format`: `"npz"`, `"netcdf"`, `"fluent"` or `"scattered"`.
    - `shape`: `(nx, ny, nz)` of the grid returned.
    - `n_points`: scattered points read (Fluent), else the number of grid nodes.
    - `outside_fraction`: fraction of grid nodes outside the convex hull of the scattered
      points, NaN-filled (0 for gridded formats).
    - `nan_fraction`: fraction of grid nodes whose velocity has a NaN component (solid
      nodes, or outside the hull).
    - `spacing_min`, `spacing_max`: smallest and largest node spacing per axis (metres) of
      a resampled grid (OpenFOAM cases; None otherwise).
    - `n_cells`, `n_cells_used`: cells in the mesh, and cells located and sampled (those
      overlapping the grid) (OpenFOAM cases).
    - `time`: the time directory read (OpenFOAM cases).
    - `resample_error_rms`, `resample_error_max`: |velocity| difference (m/s) between the
      grid's trilinear interpolation and the mesh's own cellPoint interpolation at random
      points of the region (OpenFOAM cases; NaN otherwise). Near walls, where the velocity
      drops to zero across one cell, the maximum is dominated by the first cell layer.
    - `notes`: anything else worth knowing (a coarsened automatic grid ...).
    - `masked_fraction`: scattered data: fraction of grid nodes inside the hull made NaN
      because their Delaunay simplex bridged a gap (a solid) wider than the local spacing.
    """

    path: str
    format: str
    shape: tuple[int, int, int]
    n_points: int
    outside_fraction: float
    nan_fraction: float
    spacing_min: tuple[float, float, float] | None = None
    spacing_max: tuple[float, float, float] | None = None
    n_cells: int = 0
    n_cells_used: int = 0
    time: str | None = None
    resample_error_rms: float = math.nan
    resample_error_max: float = math.nan
    notes: tuple[str, ...] = ()
    masked_fraction: float = 0.0


@dataclasses.dataclass(frozen=True, eq=False)
class FieldArrays:
    """A gridded field as numpy arrays plus the `FieldLoadReport`.

    Unpacks as the four `GridField` arguments: `x, y, z, velocity = read_field_arrays(p)`;
    the report is `.report`.

    - `x`, `y`, `z`: `(nx,)`, `(ny,)`, `(nz,)` metres, CFD frame, strictly increasing.
    - `velocity`: `(nx, ny, nz, 3)` m/s, CFD frame; NaN for solid or outside nodes.
    """

    x: Float[np.ndarray, " nx"]
    y: Float[np.ndarray, " ny"]
    z: Float[np.ndarray, " nz"]
    velocity: Float[np.ndarray, "nx ny nz 3"]
    report: FieldLoadReport

    def __iter__(self) -> Iterator[np.ndarray]:
        return iter((self.x, self.y, self.z, self.velocity))


def _check_real(path, name: str, a: Any) -> None:
    """Refuse complex, float16, boolean and non-numeric velocity arrays (naming the file)."""
    dt = np.asarray(a).dtype
    if np.issubdtype(dt, np.complexfloating):
        raise ValueError(f"{os.fspath(path)}: {name} is complex ({dt}); a velocity field must be "
                         "real (float32 or float64)")
    if dt == np.float16:
        raise ValueError(f"{os.fspath(path)}: {name} is float16 (3 significant digits); save the "
                         "field as float32 or float64")
    if not (np.issubdtype(dt, np.floating) or np.issubdtype(dt, np.integer)) or dt == np.bool_:
        raise ValueError(f"{os.fspath(path)}: {name} has dtype {dt}; expected real numbers "
                         "(float32 or float64)")


def _check_grid(
    x: Any, y: Any, z: Any, velocity: Any, where: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    axes = []
    for name, a in zip("xyz", (x, y, z), strict=True):
        arr = np.asarray(a, dtype=np.float64)
        if arr.ndim != 1 or arr.size < 2:
            raise ValueError(f"{where}: {name} must be 1-D with at least 2 nodes, got shape "
                             f"{arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{where}: {name} contains NaN or infinite coordinates")
        if np.any(np.diff(arr) <= 0):
            k = int(np.argmax(np.diff(arr) <= 0))
            raise ValueError(
                f"{where}: {name} must be strictly increasing; {name}[{k}] = {float(arr[k])!r} "
                f">= {name}[{k + 1}] = {float(arr[k + 1])!r}"
            )
        axes.append(arr)
    vel = np.asarray(velocity, dtype=np.float64)
    shape = tuple(a.size for a in axes)
    if vel.shape != (*shape, 3):
        raise ValueError(
            f"{where}: velocity must have shape (nx, ny, nz, 3) = {(*shape, 3)}, got {vel.shape}"
        )
    return axes[0], axes[1], axes[2], vel


def _nan_fraction(velocity: np.ndarray) -> float:
    n = velocity.shape[0] * velocity.shape[1] * velocity.shape[2]
    return float(np.count_nonzero(np.isnan(velocity).any(axis=-1))) / n if n else 0.0


def _gridded(path: Path, fmt: str, x, y, z, velocity) -> FieldArrays:
    x, y, z, vel = _check_grid(x, y, z, velocity, os.fspath(path))
    report = FieldLoadReport(
        path=os.fspath(path),
        format=fmt,
        shape=(x.size, y.size, z.size),
        n_points=x.size * y.size * z.size,
        outside_fraction=0.0,
        nan_fraction=_nan_fraction(vel),
    )
    return FieldArrays(x, y, z, vel, report)


def check_field_file(path: PathLike) -> None:
    """Cheap checks of a CFD field file before any computation, without reading its data:
    for ``.npz`` archives the members (x, y, z and velocity or u, v, w) and their dtypes from
    the array headers (complex, float16 and non-numeric velocities refused). Other formats
    are checked when they are read. Raises `ValueError` naming the file."""
    path = Path(path)
    if path.suffix.lower() != ".npz" or not path.is_file():
        return
    with open(path, "rb") as fh:
        with _open_npz(fh, path) as data:
            wanted = _npz_members(path, data.files)
            try:
                for n in wanted:
                    with data.zip.open(f"{n}.npy") as member:
                        version = np.lib.format.read_magic(member)
                        read = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                                else np.lib.format.read_array_header_2_0)
                        _, _, dtype = read(member)
                    _check_real(path, n, np.empty(0, dtype))
            except (OSError, EOFError, zipfile.BadZipFile, KeyError) as err:
                raise ValueError(f"{os.fspath(path)}: corrupt .npz archive ({err}); write the "
                                 "field again") from None
            except ValueError as err:
                if str(err).startswith(os.fspath(path)):
                    raise
                raise ValueError(f"{os.fspath(path)}: corrupt .npz archive ({err}); write the "
                                 "field again") from None


def _open_npz(fh, path: Path):
    """``np.load`` of an open ``.npz`` file, refusing what is not a readable archive."""
    try:
        archive = np.load(fh, allow_pickle=False)
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as err:
        raise ValueError(f"{os.fspath(path)}: not a readable .npz archive ({err})") from None
    if not hasattr(archive, "files"):
        raise ValueError(f"{os.fspath(path)}: a single array (.npy), not an .npz archive "
                         "with x, y, z and velocity")
    return archive


def _npz_members(path: Path, files) -> list[str]:
    """The members a field archive is read from: x, y, z and velocity, or x, y, z and u, v,
    w; raises naming the missing ones and what was found."""
    names = set(files)
    wanted = (["x", "y", "z", "velocity"] if {"x", "y", "z", "velocity"} <= names
              else ["x", "y", "z", "u", "v", "w"])
    missing = [n for n in wanted if n not in names]
    if missing:
        raise ValueError(
            f"{os.fspath(path)}: missing arrays {', '.join(missing)}; expected x, y, z and u, "
            f"v, w (or velocity), found {', '.join(sorted(names)) or 'none'}")
    return wanted


def _read_npz(path: Path) -> FieldArrays:
    with open(path, "rb") as fh:  # our handle: closed even when numpy gives up half-way
        archive = _open_npz(fh, path)
        try:
            with archive as data:
                arrays = {n: data[n] for n in _npz_members(path, data.files)}
        except (OSError, EOFError, zipfile.BadZipFile, ValueError) as err:  # a cut member
            if isinstance(err, ValueError) and str(err).startswith(os.fspath(path)):
                raise
            raise ValueError(f"{os.fspath(path)}: corrupt .npz archive ({err}); write the "
                             "field again") from None
    for n, a in arrays.items():
        _check_real(path, n, a)
    if "velocity" in arrays:
        return _gridded(path, "npz", arrays["x"], arrays["y"], arrays["z"], arrays["velocity"])
    comps = [np.asarray(arrays[n], dtype=np.float64) for n in "uvw"]
    shapes = {c.shape for c in comps}
    if len(shapes) != 1:
        raise ValueError(
            f"{os.fspath(path)}: u, v, w must have the same shape (nx, ny, nz), got "
            f"{', '.join(str(c.shape) for c in comps)}"
        )
    return _gridded(path, "npz", arrays["x"], arrays["y"], arrays["z"], np.stack(comps, axis=-1))


def _read_netcdf(path: Path) -> FieldArrays:
    xr = import_optional("xarray", "netcdf", "Reading NetCDF fields")
    with xr.open_dataset(path) as ds:
        # names are matched case-insensitively (U, V, W on X, Y, Z work too)
        by_lower: dict[str, list[str]] = {}
        for name in ds.variables:
            by_lower.setdefault(str(name).lower(), []).append(str(name))
        names, missing, ambiguous = {}, [], []
        for n in ("x", "y", "z", "u", "v", "w"):
            hits = by_lower.get(n, [])
            if not hits:
                missing.append(n)
            elif len(hits) > 1 and n not in hits:
                ambiguous.append(" / ".join(hits))
            else:
                names[n] = n if n in hits else hits[0]
        if missing or ambiguous:
            found = ", ".join(sorted(str(v) for v in ds.variables)) or "none"
            what = (f"missing variables {', '.join(missing)}" if missing
                    else f"ambiguous variables {', '.join(ambiguous)}")
            raise ValueError(
                f"{os.fspath(path)}: {what}; expected u, v, w on coordinates x, y, z (any case); "
                f"found {found}"
            )
        dims = [names[c] for c in "xyz"]
        comps = []
        for n in "uvw":
            da = ds[names[n]]
            if {str(d).lower() for d in da.dims} != {"x", "y", "z"} or len(da.dims) != 3:
                raise ValueError(
                    f"{os.fspath(path)}: variable {names[n]} must have dimensions (x, y, z), got "
                    f"{da.dims}"
                )
            _check_real(path, n, np.empty(0, da.dtype))
            order = [next(d for d in da.dims if str(d).lower() == c) for c in "xyz"]
            comps.append(np.asarray(da.transpose(*order).values, dtype=np.float64))
        x, y, z = (np.asarray(ds[c].values, dtype=np.float64) for c in dims)
    return _gridded(path, "netcdf", x, y, z, np.stack(comps, axis=-1))


def _fluent_header(line: str, path: Path, number: int) -> tuple[str | None, list[int]]:
    delimiter = "," if "," in line else None
    names = [n.strip() for n in (line.split(",") if delimiter else line.split())]
    while names and not names[-1]:
        names.pop()
    cols = [-1] * 6
    for i, name in enumerate(names):
        slot = _FLUENT_NAMES.get(normalise_key(name))
        if slot is not None and cols[slot] < 0:  # a repeated column: the first one is used
            cols[slot] = i
    missing = [_FLUENT_REQUIRED[s] for s in range(6) if cols[s] < 0]
    if missing:
        raise file_error(
            path, number, f"header lacks {', '.join(missing)}; expected a Fluent ASCII export "
            f"naming {', '.join(_FLUENT_REQUIRED)}, found {', '.join(names) or 'nothing'}"
        )
    return delimiter, cols


def _parse_chunk(
    lines: list[str], line_numbers: list[int], delimiter: str | None, cols: list[int],
    path: Path,
) -> np.ndarray:
    try:
        block = np.loadtxt(
            lines, delimiter=delimiter, usecols=cols, dtype=np.float64, ndmin=2, comments=None
        )
    except ValueError:
        block = None
    if block is not None and block.shape == (len(lines), 6):
        return block
    need = max(cols) + 1
    for raw, number in zip(lines, line_numbers, strict=True):
        fields = raw.split(",") if delimiter else raw.split()
        if len(fields) < need:
            raise file_error(path, number, f"expected at least {need} fields, found {len(fields)}")
        for slot, c in enumerate(cols):
            try:
                float(fields[c])
            except ValueError:
                raise file_error(
                    path, number, f"column {_FLUENT_REQUIRED[slot]!r}: expected a number, found "
                    f"{fields[c].strip()!r}"
                ) from None
    raise file_error(path, line_numbers[0], "could not parse this block of rows")


def _default_meter() -> AbstractProgress:
    """`progress=True` while reading a Fluent export: a tqdm bar if tqdm is installed,
    silent otherwise."""
    return TqdmProgress() if have_module("tqdm") else NoProgress()


def read_fluent_points(
    path: PathLike, *, progress: bool | AbstractProgress = False, chunk_rows: int = 200_000
) -> tuple[Float[np.ndarray, "n 3"], Float[np.ndarray, "n 3"]]:
    """Read the scattered points of a Fluent ASCII export, streaming in chunks.

    **Arguments:**

    - `path`: the export. First non-blank line: the column names (comma or whitespace
      separated; the six coordinate and velocity columns in any order, others ignored).
    - `progress`: bytes read so far: ``True`` shows a tqdm bar (if tqdm is installed;
      silent otherwise), or give a `lidarjax.progress` meter.
    - `chunk_rows`: rows parsed per `numpy.loadtxt` call (bounds the memory of text).

    **Returns:** `(points, velocity)`, each `(n, 3)` float64: CFD coordinates in metres and
    `(u, v, w)` in m/s.

    Raises `ValueError` naming the file and line for a header without the six columns, a
    short row, a non-numeric value, or a file with no data row.
    """
    if chunk_rows < 1:
        raise ValueError(f"chunk_rows must be >= 1, got {chunk_rows}")
    p = require_file(path, "Fluent export")
    blocks: list[np.ndarray] = []
    meter = progress_meter(progress, _default_meter)
    bar = meter.start(p.stat().st_size, p.name, unit="B")
    try:
        with open(p, encoding="utf-8", errors="replace") as fh:
            number = 0
            header: str | None = None
            for raw in fh:
                number += 1
                if raw.strip():
                    header = raw
                    break
            if header is None:
                raise file_error(p, None, "empty file; expected a header naming "
                                 + ", ".join(_FLUENT_REQUIRED))
            delimiter, cols = _fluent_header(header, p, number)
            lines: list[str] = []
            numbers: list[int] = []
            done = len(header)
            for raw in fh:
                number += 1
                done += len(raw)
                if not raw.strip():
                    continue
                lines.append(raw)
                numbers.append(number)
                if len(lines) >= chunk_rows:
                    blocks.append(_parse_chunk(lines, numbers, delimiter, cols, p))
                    lines, numbers = [], []
                    meter.update(bar, done)
            if lines:
                blocks.append(_parse_chunk(lines, numbers, delimiter, cols, p))
            meter.update(bar, done)
    finally:
        meter.close(bar)
    if not blocks:
        raise file_error(p, None, "no data rows after the header")
    table = np.concatenate(blocks, axis=0)
    return table[:, :3].copy(), table[:, 3:].copy()


def _grid_axes(
    lo: np.ndarray, hi: np.ndarray, n_points: int, spacing: Any, shape: Any
) -> list[np.ndarray]:
    if spacing is not None and shape is not None:
        raise ValueError("give either spacing or shape, not both")
    if spacing is not None:
        s = np.broadcast_to(np.asarray(spacing, dtype=np.float64), (3,))
        if not np.all(np.isfinite(s)) or np.any(s <= 0):
            raise ValueError(f"spacing must be positive metres, got {spacing!r}")
        axes = []
        for a in range(3):
            # a node within 1e-6 step of the data's maximum still counts (rounding of
            # large coordinates); it is then at most 1e-6 step outside the points
            n = int(math.floor((hi[a] - lo[a]) / s[a] + 1e-6)) + 1
            if n < 2:
                raise ValueError(
                    f"spacing {s[a]:g} m exceeds the data extent {hi[a] - lo[a]:g} m along "
                    f"{'xyz'[a]}; use a smaller spacing"
                )
            axes.append(lo[a] + s[a] * np.arange(n, dtype=np.float64))
        return axes
    if shape is not None:
        dims = tuple(int(n) for n in shape)
        if len(dims) != 3 or any(n < 2 for n in dims) or any(
            int(n) != n for n in shape
        ):
            raise ValueError(f"shape must be 3 integers >= 2, got {shape!r}")
    else:
        n = int(np.clip(round(n_points ** (1 / 3)), 2, DEFAULT_MAX_NODES_PER_AXIS))
        dims = (n, n, n)
    return [np.linspace(lo[a], hi[a], dims[a]) for a in range(3)]


def resample_to_grid(
    points: Float[np.ndarray, "n 3"],
    values: Float[np.ndarray, "n 3"],
    *,
    spacing: float | Sequence[float] | None = None,
    shape: Sequence[int] | None = None,
    block_nodes: int = 1_000_000,
    max_edge_factor: float = DEFAULT_MAX_EDGE_FACTOR,
) -> FieldArrays:
    """Piecewise-linear resampling of scattered velocities onto a regular grid.

    The grid spans the points' bounding box: with `spacing` (metres, scalar or per axis)
    nodes are `min + spacing * i` up to the maximum; with `shape` `(nx, ny, nz)` they are
    `linspace(min, max, n)`; by default `n = round(cbrt(n_points))` per axis, clipped to
    `[2, DEFAULT_MAX_NODES_PER_AXIS]`. Values are interpolated linearly inside the
    simplices of the points' Delaunay triangulation (as `scipy.interpolate.griddata`
    `method="linear"`); nodes outside the convex hull are NaN.

    **Arguments:**

    - `points`: `(n, 3)` CFD coordinates, metres (at least 4 points not in a plane).
    - `values`: `(n, 3)` velocities `(u, v, w)`, m/s.
    - `spacing`, `shape`: grid definition (at most one).
    - `block_nodes`: grid nodes evaluated per block (bounds memory).
    - `max_edge_factor`: scattered data carry no connectivity, so the triangulation also
      spans the holes the solids leave (buildings, a platform, terrain steps). A simplex
      whose longest edge exceeds `max_edge_factor` times the local node spacing is refused:
      grid nodes in it are NaN, never interpolated across a solid. A node's spacing is the
      shortest of the longest edges of the simplices around it (its ordinary neighbourhood:
      stretched cells keep their long edge, the rim of a hole its fluid-side size); a
      simplex uses the largest of its four nodes' (2:1 refinement interfaces pass).
      ``inf`` keeps every simplex. The
      longest edge is used rather than the circumradius, which is unbounded for the flat
      slivers a Delaunay triangulation of a regular lattice contains.

    **Returns:** `FieldArrays`; `report.outside_fraction` is the fraction of nodes
    outside the hull, and `report.notes` says how many simplices and grid nodes were
    masked as bridging a gap.
    """
    pts = np.asarray(points, dtype=np.float64)
    vals = np.asarray(values, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or vals.shape != pts.shape:
        raise ValueError(
            f"points and values must both have shape (n, 3), got {pts.shape} and {vals.shape}"
        )
    if pts.shape[0] < 4:
        raise ValueError(f"need at least 4 scattered points, got {pts.shape[0]}")
    if not np.all(np.isfinite(pts)):
        raise ValueError("points contain NaN or infinite coordinates")
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    flat = [a for a in range(3) if not hi[a] > lo[a]]
    if flat:
        raise ValueError(
            f"the points have no extent along {', '.join('xyz'[a] for a in flat)}; a 3-D field "
            "needs scattered points spanning a volume"
        )
    axes = _grid_axes(lo, hi, pts.shape[0], spacing, shape)
    try:
        tri = Delaunay(pts - lo)  # shift to the box corner: better conditioned at UTM offsets
    except QhullError as err:
        raise ValueError(f"cannot triangulate the points (all in a plane?): {err}") from None
    bridge = None
    masked_nodes = 0
    if not max_edge_factor > 0:
        raise ValueError(f"max_edge_factor must be positive, got {max_edge_factor!r}")
    if np.isfinite(max_edge_factor):
        simp = tri.simplices
        longest = np.zeros(simp.shape[0])
        for a in range(4):
            for b in range(a + 1, 4):
                edge = np.linalg.norm(pts[simp[:, a]] - pts[simp[:, b]], axis=1)
                np.maximum(longest, edge, out=longest)
        # a node's spacing: the shortest of the longest edges of its simplices (its finest
        # ordinary neighbourhood; stretched cells keep their long edge, the rim of a hole
        # keeps its fluid-side size); a simplex takes the largest of its four nodes' (so
        # simplices across a 2:1 refinement interface pass)
        node_size = np.full(pts.shape[0], np.inf)
        np.minimum.at(node_size, simp.ravel(), np.repeat(longest, 4))
        bridge = longest > max_edge_factor * node_size[simp].max(axis=1)
    shape3 = tuple(a.size for a in axes)
    grid = np.full((*shape3, 3), np.nan)
    out = grid.reshape(-1, 3)
    rel = [a - lo[i] for i, a in enumerate(axes)]
    n_nodes = out.shape[0]
    inside_total = 0
    idx = np.arange(n_nodes)
    for start in range(0, n_nodes, max(1, int(block_nodes))):
        ids = idx[start: start + block_nodes]
        i, j, k = np.unravel_index(ids, shape3)
        q = np.stack([rel[0][i], rel[1][j], rel[2][k]], axis=-1)
        simplex = tri.find_simplex(q)
        inside = simplex >= 0
        inside_total += int(np.count_nonzero(inside))
        if not np.any(inside):
            continue
        if bridge is not None:
            inside &= ~bridge[np.where(inside, simplex, 0)]
            masked_nodes += int(np.count_nonzero((simplex >= 0) & ~inside))
            if not np.any(inside):
                continue
        s = simplex[inside]
        transform = tri.transform[s]
        b = np.einsum("mij,mj->mi", transform[:, :3, :], q[inside] - transform[:, 3, :])
        bary = np.concatenate([b, 1.0 - b.sum(axis=1, keepdims=True)], axis=1)
        out[ids[inside]] = np.einsum("mi,mic->mc", bary, vals[tri.simplices[s]])
    report = FieldLoadReport(
        path="<arrays>",
        format="scattered",
        shape=shape3,  # type: ignore[arg-type]
        n_points=int(pts.shape[0]),
        outside_fraction=1.0 - inside_total / n_nodes,
        nan_fraction=_nan_fraction(grid),
        notes=() if bridge is None else (
            f"{int(bridge.sum())} of {bridge.size} Delaunay simplices bridge a gap (longest edge > "
            f"{max_edge_factor:g} x local spacing) and were masked: {masked_nodes} grid nodes "
            f"({masked_nodes / n_nodes:.2%}) NaN",),
        masked_fraction=masked_nodes / n_nodes,
    )
    return FieldArrays(axes[0], axes[1], axes[2], grid, report)


def _format_of(path: Path, fmt: str | None) -> str:
    if fmt is not None:
        if fmt not in ("npz", "netcdf", "fluent", "openfoam", "vtk"):
            raise ValueError(f"format must be 'npz', 'netcdf' or 'fluent', or 'openfoam' for a case directory, "
                             f"or 'vtk' for .vtu/.vtk/.vtm; got {fmt!r}")
        return fmt

    if path.is_dir() or is_openfoam_case(path):
        return "openfoam"
    suffix = path.suffix.lower()
    if suffix in (".vtu", ".vtk", ".vtm"):
        return "vtk"
    if suffix == ".npz":
        return "npz"
    if suffix in _NETCDF_SUFFIXES:
        return "netcdf"
    return "fluent"


def read_field_arrays(
    path: PathLike,
    *,
    spacing: float | Sequence[float] | None = None,
    shape: Sequence[int] | None = None,
    progress: bool | AbstractProgress = False,
    format: str | None = None,
    chunk_rows: int = 200_000,
    region: tuple[Any, Any] | None = None,
    time: Any = None,
    max_edge_factor: float = DEFAULT_MAX_EDGE_FACTOR,
) -> FieldArrays:
    """Read a velocity field as numpy arrays (see the module docstring for the formats).

    **Arguments:**

    - `path`: the file, or an OpenFOAM case directory; the format follows the suffix (a
      directory is an OpenFOAM case) unless `format` is given (`"npz"`, `"netcdf"`,
      `"fluent"`, `"openfoam"`).
    - `spacing`: grid spacing (metres, scalar or per axis) for scattered Fluent data (see
      `resample_to_grid`) and OpenFOAM cases (default automatic: see below); an error for
      gridded formats. `shape`: grid shape for Fluent data only.
    - `region`: `(lo, hi)` CFD metres, e.g. `lidarjax.scan_bounds(scan, mounts, heights,
      probe)`: only the data there is read and resampled (OpenFOAM: only the cells
      overlapping it are located and sampled; Fluent: only the points inside it, plus a
      10 % margin, are triangulated; gridded files are cropped to it plus one node).
    - `time`: OpenFOAM time (number or directory name); default the latest holding `U`.
    - `progress`: progress bar while reading a Fluent export (``True``: tqdm, if installed;
      or a `lidarjax.progress` meter).
    - `chunk_rows`: rows per parsing chunk for Fluent exports.
    - `max_edge_factor`: Fluent exports: Delaunay simplices longer than this many local
      node spacings are taken as bridging a solid and masked (see `resample_to_grid`).

    OpenFOAM cases are sampled with the mesh's own cellPoint interpolation (the values that
    OpenFOAM's `probes` function object reports; see `lidarjax.io.openfoam`), at the nodes of
    a grid that resolves the finest cells of the region: per axis, two nodes per width of the
    finest cell spanning each coordinate (graded axes), at most
    `lidarjax.io.openfoam.DEFAULT_MAX_NODES` nodes. Nodes inside solids (terrain,
    buildings) are NaN. The report gives the spacing and the resampling error.

    **Returns:** `FieldArrays` (unpacks as `x, y, z, velocity`; `.report` is a
    `FieldLoadReport`).
    """
    return _read_field_arrays(
        path, spacing=spacing, shape=shape, progress=progress, format=format,
        chunk_rows=chunk_rows, region=region, time=time, max_edge_factor=max_edge_factor)[0]


def _read_field_arrays(path, *, spacing, shape, progress, format, chunk_rows, region, time,
                       max_edge_factor) -> tuple[FieldArrays, Any]:
    """`read_field_arrays`, plus the cellPoint sampler of a mesh (OpenFOAM, VTK; else None)."""
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"field file not found: {os.fspath(p)}")
    kind = _format_of(p, format)
    if kind == "openfoam":
        if shape is not None:
            raise ValueError("shape applies to scattered Fluent exports; give spacing (metres) for "
                             "an OpenFOAM case, or nothing for the automatic grid")
        return _read_openfoam_arrays(p, region, spacing, time)
    p = require_file(path, "field file")
    if kind == "vtk":
        if shape is not None or time is not None:
            raise ValueError(f"{os.fspath(p)}: a VTK file takes spacing (metres) and region, "
                             "not shape or time")
        return _read_openfoam_arrays(p, region, spacing, None, vtk=True)
    if time is not None:
        raise ValueError(f"{os.fspath(p)}: time applies to OpenFOAM cases only")
    if kind != "fluent":
        if spacing is not None or shape is not None:
            raise ValueError(
                f"{os.fspath(p)}: spacing and shape apply to scattered Fluent exports only; "
                f"this {kind} file is already gridded"
            )
        arrays = _read_npz(p) if kind == "npz" else _read_netcdf(p)
        return (arrays if region is None else _crop_arrays(arrays, region)), None
    points, velocity = read_fluent_points(p, progress=progress, chunk_rows=chunk_rows)
    if region is not None:
        lo, hi = _region_box(region)
        margin = 0.1 * (hi - lo) + 1e-9
        keep = np.all((points >= lo - margin) & (points <= hi + margin), axis=1)
        points, velocity = points[keep], velocity[keep]
    try:
        arrays = resample_to_grid(points, velocity, spacing=spacing, shape=shape,
                                  max_edge_factor=max_edge_factor)
    except ValueError as err:
        raise ValueError(f"{os.fspath(p)}: {err}") from None
    report = dataclasses.replace(arrays.report, path=os.fspath(p), format="fluent")
    return dataclasses.replace(arrays, report=report), None


def load_field(
    path: PathLike,
    *,
    region: tuple[Any, Any] | None = None,
    spacing: float | Sequence[float] | None = None,
    shape: Sequence[int] | None = None,
    time: Any = None,
    max_edge_factor: float = DEFAULT_MAX_EDGE_FACTOR,
    progress: bool | AbstractProgress = False,
    format: str | None = None,
    dtype: Any = None,
    return_report: bool = False,
    exact_at: Any = None,
) -> Any:
    """Load a velocity field file (or an OpenFOAM case directory) as a `lidarjax.GridField`.

    Arguments as `read_field_arrays` (`region=(lo, hi)` in CFD metres restricts reading and
    resampling to where the beams look, e.g. `lidarjax.scan_bounds(...)`), plus `dtype` (the
    field's working float dtype; default: JAX's default float, float64 only with x64
    enabled), `return_report` and:

    - `exact_at`: meshes (OpenFOAM cases, VTK files) only: the points `simulate` will
      sample, `(n, 3)` absolute CFD metres, or a function of the resampled `GridField`
      returning them (the probe's nodes depend on the grid's spacing along the beams:
      ``lidarjax.ExactPoints(scan, mount, heights, probe)``, `simulate`'s own choice).
      The field returned is then
      a `lidarjax.io.CellPointField`: the mesh's own cellPoint interpolation (what OpenFOAM's
      `probes` report) at those points, the graded grid anywhere else. Gridded files and
      Fluent exports are returned as their `GridField` (their grid is their own data).
      Without it (None, the default) a mesh's grid is made exact by `lidarjax.simulate`
      itself at the points it samples from one concrete mount (the mesh's sampler over the
      grid's cells is kept with the grid for that); a batch or traced mount samples the grid
      with a one-line warning. ``exact_at=False``: the graded grid only, silently. Non-finite
      points are refused (a ValueError) before the file is read.

    **Returns:** the field, or `(field, FieldLoadReport)` with `return_report=True` (the
    report gives e.g. the fraction of grid nodes outside the convex hull of scattered Fluent
    data, or an OpenFOAM grid's spacing and resampling error).
    """
    graded_only = exact_at is False  # the graded grid only: never made exact, no warning
    exact_at = None if graded_only else exact_at
    if exact_at is not None and not callable(exact_at):  # before the file is read
        exact_at = finite_points(exact_at, "load_field: `exact_at`")
    arrays, sampler = _read_field_arrays(
        path, spacing=spacing, shape=shape, progress=progress, format=format, region=region,
        time=time, max_edge_factor=max_edge_factor, chunk_rows=200_000,
    )
    velocity = arrays.velocity if dtype is None else arrays.velocity.astype(dtype)
    field = GridField(arrays.x, arrays.y, arrays.z, velocity)
    if exact_at is None and sampler is not None and not graded_only:
        # the points are known when `lidarjax.simulate` samples it: exact there by default
        register_mesh_grid(field, lambda points, grid=field: cellpoint_field(sampler, grid, points),
                           arrays.report.path)
    if exact_at is not None and sampler is not None:
        points = exact_at(field) if callable(exact_at) else exact_at
        field = cellpoint_field(sampler, field, points)
        n_in = int(np.asarray(field.found).sum())
        note = (f"exact cellPoint at the {field.n_points} points simulate samples "
                f"({field.n_points - n_in} in no cell: NaN); the graded grid elsewhere")
        arrays = dataclasses.replace(arrays, report=dataclasses.replace(
            arrays.report, notes=arrays.report.notes + (note,)))
    return (field, arrays.report) if return_report else field


def _region_box(region: Any) -> tuple[np.ndarray, np.ndarray]:
    try:
        lo = np.asarray(region[0], np.float64).reshape(3)
        hi = np.asarray(region[1], np.float64).reshape(3)
    except (TypeError, ValueError, IndexError):
        raise ValueError(f"region must be (lo, hi), two points (x, y, z) in metres, got {region!r}") from None
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(hi >= lo)):
        raise ValueError(f"region must be (lo, hi) with finite lo <= hi (metres), got {region!r}")
    return lo, hi


def _crop_arrays(arrays: FieldArrays, region: Any) -> FieldArrays:
    """The nodes covering `region` plus one node on each side (where the grid has them)."""
    lo, hi = _region_box(region)
    axes = (arrays.x, arrays.y, arrays.z)
    sl = []
    for a in range(3):
        ax = axes[a]
        i0 = max(int(np.searchsorted(ax, lo[a], "right")) - 2, 0)
        i1 = min(int(np.searchsorted(ax, hi[a], "left")) + 2, ax.size)
        if i1 - i0 < 2:
            raise ValueError(f"{arrays.report.path}: region {lo.tolist()} .. {hi.tolist()} lies outside "
                             f"the field's grid along {'xyz'[a]} ({ax[0]:g} .. {ax[-1]:g} m)")
        sl.append(slice(i0, i1))
    vel = arrays.velocity[sl[0], sl[1], sl[2]]
    report = dataclasses.replace(arrays.report, shape=vel.shape[:3], nan_fraction=_nan_fraction(vel))
    return FieldArrays(arrays.x[sl[0]], arrays.y[sl[1]], arrays.z[sl[2]], vel, report)


def _read_openfoam_arrays(path: Path, region: Any, spacing: Any, time: Any, vtk: bool = False
                          ) -> tuple[FieldArrays, Any]:

    if vtk:  # VTK unstructured grids: the same cellPoint sampling (lidarjax.io.vtk)

        of = read_vtk_field(path)
    else:
        of = read_openfoam_field(path, time=time)
    box = None if region is None else _region_box(region)
    axes, vel, info, sampler = resample_with_sampler(of, box, spacing)
    report = FieldLoadReport(
        path=os.fspath(of.case), format="vtk" if vtk else "openfoam", shape=vel.shape[:3],  # type: ignore[arg-type]
        n_points=int(of.mesh.points.shape[0]), outside_fraction=0.0, nan_fraction=_nan_fraction(vel),
        spacing_min=info["spacing_min"], spacing_max=info["spacing_max"], n_cells=of.mesh.n_cells,
        n_cells_used=info["n_cells_used"], time=of.time,
        resample_error_rms=info.get("resample_error_rms", math.nan),
        resample_error_max=info.get("resample_error_max", math.nan), notes=tuple(info["notes"]),
    )
    return FieldArrays(axes[0], axes[1], axes[2], vel, report), sampler


def _as_arrays(field_or_arrays: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    f = field_or_arrays
    if hasattr(f, "x_local") and hasattr(f, "origin") and hasattr(f, "velocity"):
        # a GridField: rebuild absolute coordinates in float64 from origin (hi + lo) + local
        origin = np.asarray(f.origin, dtype=np.float64) + np.asarray(
            getattr(f, "origin_lo", np.zeros(3)), dtype=np.float64
        )
        locs = (f.x_local, f.y_local, f.z_local)
        x, y, z = (origin[a] + np.asarray(locs[a], dtype=np.float64) for a in range(3))
        return x, y, z, np.asarray(f.velocity, dtype=np.float64)
    x, y, z, velocity = f
    return x, y, z, velocity


def save_field_npz(path: PathLike, field_or_arrays: Any) -> Path:
    """Save a field as `.npz` with arrays `x, y, z` (m) and `u, v, w` `(nx, ny, nz)` (m/s).

    `field_or_arrays` is a `GridField`, a `FieldArrays` or a tuple `(x, y, z, velocity)`.
    The write is atomic. Returns the path written.
    """
    target = Path(path)
    x, y, z, vel = _check_grid(*_as_arrays(field_or_arrays), where=os.fspath(target))
    with atomic_path(target) as tmp, open(tmp, "xb") as fh:
        np.savez(fh, x=x, y=y, z=z, u=vel[..., 0], v=vel[..., 1], w=vel[..., 2])
    return target


def save_field_netcdf(
    path: PathLike, field_or_arrays: Any, attrs: dict[str, Any] | None = None
) -> Path:
    """Save a field as NetCDF (`u, v, w` on `x, y, z`, units attributes), atomically.

    Needs xarray (`pip install lidarjax[netcdf]`); uses h5netcdf when installed, else
    scipy's NetCDF3 writer. Returns the path written.
    """
    xr = import_optional("xarray", "netcdf", "save_field_netcdf")
    target = Path(path)
    x, y, z, vel = _check_grid(*_as_arrays(field_or_arrays), where=os.fspath(target))
    metres = {"units": "m"}
    ds = xr.Dataset(
        {
            name: (("x", "y", "z"), vel[..., a], {"units": "m/s"})
            for a, name in enumerate("uvw")
        },
        coords={"x": ("x", x, metres), "y": ("y", y, metres), "z": ("z", z, metres)},
        attrs={str(k): str(v) for k, v in (attrs or {}).items()},
    )
    with atomic_path(target) as tmp:
        ds.to_netcdf(os.fspath(tmp), engine=netcdf_engine())
    return target
