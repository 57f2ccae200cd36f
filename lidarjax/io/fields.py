"""CFD velocity fields from files: `.npz`, NetCDF and Fluent ASCII exports.

All readers return node coordinates in metres (CFD frame, 1-D, strictly increasing) and
velocities `(nx, ny, nz, 3)` = `(u, v, w)` in m/s in the CFD frame, the arguments of
`lidarjax.GridField`. NaN velocities mark solid nodes (and, for resampled scattered
data, nodes outside the data's convex hull).

- `.npz` (numpy): arrays `x (nx,)`, `y (ny,)`, `z (nz,)` and `u`, `v`, `w` each
  `(nx, ny, nz)`, or one `velocity (nx, ny, nz, 3)`;
- `.nc`, `.nc4`, `.cdf` (NetCDF): variables `u`, `v`, `w` on coordinates `x`, `y`, `z`
  in any dimension order; needs xarray (`pip install lidarjax[netcdf]`);
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

from ._common import (
    PathLike,
    atomic_path,
    file_error,
    have_module,
    import_optional,
    netcdf_engine,
    normalise_key,
    require_file,
)

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
    """

    path: str
    format: str
    shape: tuple[int, int, int]
    n_points: int
    outside_fraction: float
    nan_fraction: float


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


def _read_npz(path: Path) -> FieldArrays:
    with open(path, "rb") as fh:  # our handle: closed even when numpy gives up half-way
        try:
            archive = np.load(fh, allow_pickle=False)
        except (ValueError, OSError, EOFError, zipfile.BadZipFile) as err:
            raise ValueError(f"{os.fspath(path)}: not a readable .npz archive ({err})") from None
        if not hasattr(archive, "files"):
            raise ValueError(f"{os.fspath(path)}: a single array (.npy), not an .npz archive "
                             "with x, y, z and velocity")
        try:
            with archive as data:
                names = set(data.files)
                missing = [n for n in "xyz" if n not in names]
                wanted = ["x", "y", "z", "velocity"] if not missing and "velocity" in names \
                    else ["x", "y", "z", "u", "v", "w"]
                missing = [n for n in wanted if n not in names]
                if missing:
                    raise ValueError(
                        f"{os.fspath(path)}: missing arrays {', '.join(missing)}; expected x, "
                        f"y, z and u, v, w (or velocity), found "
                        f"{', '.join(sorted(names)) or 'none'}"
                    )
                arrays = {n: data[n] for n in wanted}
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
        missing = [n for n in ("x", "y", "z", "u", "v", "w") if n not in ds.variables]
        if missing:
            raise ValueError(
                f"{os.fspath(path)}: missing variables {', '.join(missing)}; expected u, v, w "
                "on coordinates x, y, z"
            )
        comps = []
        for n in "uvw":
            da = ds[n]
            if set(da.dims) != {"x", "y", "z"}:
                raise ValueError(
                    f"{os.fspath(path)}: variable {n} must have dimensions (x, y, z), got "
                    f"{da.dims}"
                )
            _check_real(path, n, np.empty(0, da.dtype))
            comps.append(np.asarray(da.transpose("x", "y", "z").values, dtype=np.float64))
        x, y, z = (np.asarray(ds[c].values, dtype=np.float64) for c in "xyz")
    return _gridded(path, "netcdf", x, y, z, np.stack(comps, axis=-1))


def _fluent_header(line: str, path: Path, number: int) -> tuple[str | None, list[int]]:
    delimiter = "," if "," in line else None
    names = [n.strip() for n in (line.split(",") if delimiter else line.split())]
    while names and not names[-1]:
        names.pop()
    cols = [-1] * 6
    for i, name in enumerate(names):
        slot = _FLUENT_NAMES.get(normalise_key(name))
        if slot is not None:
            if cols[slot] >= 0:
                raise file_error(path, number, f"column {_FLUENT_REQUIRED[slot]!r} appears twice")
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


def _progress_bar(total: int, enabled: bool, label: str) -> Any:
    if enabled and have_module("tqdm"):
        import tqdm

        return tqdm.tqdm(total=total, unit="B", unit_scale=True, desc=label, leave=False)
    return None


def read_fluent_points(
    path: PathLike, *, progress: bool = False, chunk_rows: int = 200_000
) -> tuple[Float[np.ndarray, "n 3"], Float[np.ndarray, "n 3"]]:
    """Read the scattered points of a Fluent ASCII export, streaming in chunks.

    **Arguments:**

    - `path`: the export. First non-blank line: the column names (comma or whitespace
      separated; the six coordinate and velocity columns in any order, others ignored).
    - `progress`: show a tqdm progress bar (if tqdm is installed; silent otherwise).
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
    bar = _progress_bar(p.stat().st_size, progress, p.name)
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
                    if bar is not None:
                        bar.update(done - bar.n)
            if lines:
                blocks.append(_parse_chunk(lines, numbers, delimiter, cols, p))
            if bar is not None:
                bar.update(done - bar.n)
    finally:
        if bar is not None:
            bar.close()
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

    **Returns:** `FieldArrays`; `report.outside_fraction` is the fraction of nodes
    outside the hull.
    """
    from scipy.spatial import Delaunay, QhullError

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
    )
    return FieldArrays(axes[0], axes[1], axes[2], grid, report)


def _format_of(path: Path, fmt: str | None) -> str:
    if fmt is not None:
        if fmt not in ("npz", "netcdf", "fluent"):
            raise ValueError(f"format must be 'npz', 'netcdf' or 'fluent', got {fmt!r}")
        return fmt
    suffix = path.suffix.lower()
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
    progress: bool = False,
    format: str | None = None,
    chunk_rows: int = 200_000,
) -> FieldArrays:
    """Read a velocity field as numpy arrays (see the module docstring for the formats).

    **Arguments:**

    - `path`: the file; the format follows the suffix unless `format` is given
      (`"npz"`, `"netcdf"`, `"fluent"`).
    - `spacing`, `shape`: grid for scattered Fluent data (see `resample_to_grid`); an
      error for gridded formats.
    - `progress`: progress bar while reading a Fluent export (tqdm, if installed).
    - `chunk_rows`: rows per parsing chunk for Fluent exports.

    **Returns:** `FieldArrays` (unpacks as `x, y, z, velocity`; `.report` is a
    `FieldLoadReport` with the fraction of nodes outside the data's hull).
    """
    p = require_file(path, "field file")
    kind = _format_of(p, format)
    if kind != "fluent":
        if spacing is not None or shape is not None:
            raise ValueError(
                f"{os.fspath(p)}: spacing and shape apply to scattered Fluent exports only; "
                f"this {kind} file is already gridded"
            )
        return _read_npz(p) if kind == "npz" else _read_netcdf(p)
    points, velocity = read_fluent_points(p, progress=progress, chunk_rows=chunk_rows)
    try:
        arrays = resample_to_grid(points, velocity, spacing=spacing, shape=shape)
    except ValueError as err:
        raise ValueError(f"{os.fspath(p)}: {err}") from None
    report = dataclasses.replace(arrays.report, path=os.fspath(p), format="fluent")
    return dataclasses.replace(arrays, report=report)


def load_field(
    path: PathLike,
    *,
    spacing: float | Sequence[float] | None = None,
    shape: Sequence[int] | None = None,
    progress: bool = False,
    format: str | None = None,
    dtype: Any = None,
    return_report: bool = False,
) -> Any:
    """Load a velocity field file as a `lidarjax.GridField`.

    Arguments as `read_field_arrays`, plus `dtype` (the field's working float dtype;
    default: JAX's default float, float64 only with x64 enabled) and `return_report`.

    **Returns:** the `GridField`, or `(GridField, FieldLoadReport)` with
    `return_report=True` (the report gives e.g. the fraction of grid nodes outside the
    convex hull of scattered Fluent data, which are NaN).
    """
    from ..field import GridField

    arrays = read_field_arrays(
        path, spacing=spacing, shape=shape, progress=progress, format=format
    )
    velocity = arrays.velocity if dtype is None else arrays.velocity.astype(dtype)
    field = GridField(arrays.x, arrays.y, arrays.z, velocity)
    return (field, arrays.report) if return_report else field


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
