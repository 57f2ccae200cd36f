"""The seed UDF's output table, its azimuth convention, and self-describing table writers.

## The seed output file

The seed Fluent UDF writes `windcube simulation <beta> degrees.dat` (beta printed
with C's `%d`), one row per height with 21 columns (`SEED_COLUMNS`), each number
printed as C's `" %6.3f"`. With `verbose = 1` a header line naming the columns comes
first; with `verbose = 0` there is none.

| column | meaning | unit |
|---|---|---|
| `h` | height above the lidar | m |
| `U_mag_lidar` | lidar-reconstructed horizontal speed | m/s |
| `U_lidar`, `V_lidar`, `W_lidar` | lidar-reconstructed components | m/s |
| `Th_lidar` | lidar flow azimuth, seed convention | deg |
| `U_mag_point` ... `W_point` | the same at the point above the lidar | m/s |
| `th_point` | point flow azimuth, seed convention | deg |
| `cff_u`, `cff_v`, `cff_U` | ratio corrections to the free stream | 1 |
| `cff_w` | additive correction to w, in units of the free-stream speed | 1 |
| `cff_th` | additive azimuth correction to the free stream | deg |
| `cfp_u`, `cfp_v`, `cfp_w`, `cfp_U` | ratio corrections to the point | 1 |
| `cfp_th` | additive azimuth correction to the point | deg |

The components are in the seed's rig frame rotated by `-epsilon` towards north:
`u` along +x (east after the rotation), `v` along +y (north).

## Two azimuth conventions

- **Seed azimuth** (the C code's `thl`, `thp`; columns `Th_lidar`, `th_point`): the
  heading the flow goes *towards*, in degrees measured **clockwise from +x (east)**:
  `theta = (-atan2(v, u)) mod 360`. The C code builds it from `atan(v/u)` by quadrant:
  `u > 0, v > 0: 360 - atan(v/u)`; `u > 0, v < 0: -atan(v/u)`; `u < 0: 180 - atan(v/u)`,
  all equal to `-atan2(v, u)` modulo 360.
- **Meteorological direction** (used everywhere else in lidarjax): where the wind comes
  *from*, in degrees **clockwise from north (+y)**: `d = atan2(-u, -v) mod 360`.

Derivation of the link: a flow heading clockwise angle `theta` from east heads
clockwise angle `theta + 90` from north; it comes from the opposite side,
`theta + 90 + 180`. Hence `d = (theta + 270) mod 360` and `theta = (d + 90) mod 360`.

Example, the seed's table 1: `(u, v) = (2.25, -15.06)` m/s flows towards the south,
slightly east. Seed azimuth `-atan2(-15.06, 2.25) = 81.5` deg; meteorological direction
`81.5 + 270 - 360 = 351.5` deg (from the north, slightly west).
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from jaxtyping import Float

from .._util import (
    PathLike,
    atomic_path,
    atomic_write_text,
    file_error,
    format_number,
    import_optional,
    netcdf_engine,
    require_file,
)
from ._common import float_row, is_number

__all__ = [
    "SEED_COLUMNS",
    "SEED_UNITS",
    "CsvTable",
    "meteorological_from_seed",
    "read_seed_output",
    "read_table_csv",
    "seed_from_meteorological",
    "seed_output_filename",
    "write_netcdf",
    "write_seed_output",
    "write_table_csv",
]

SEED_COLUMNS: tuple[str, ...] = (
    "h",
    "U_mag_lidar",
    "U_lidar",
    "V_lidar",
    "W_lidar",
    "Th_lidar",
    "U_mag_point",
    "U_point",
    "V_point",
    "W_point",
    "th_point",
    "cff_u",
    "cff_v",
    "cff_w",
    "cff_U",
    "cff_th",
    "cfp_u",
    "cfp_v",
    "cfp_w",
    "cfp_U",
    "cfp_th",
)
"""The 21 columns of the seed output file, in file order."""

SEED_UNITS: dict[str, str] = {
    "h": "m",
    "U_mag_lidar": "m/s",
    "U_lidar": "m/s",
    "V_lidar": "m/s",
    "W_lidar": "m/s",
    "Th_lidar": "deg, seed azimuth",
    "U_mag_point": "m/s",
    "U_point": "m/s",
    "V_point": "m/s",
    "W_point": "m/s",
    "th_point": "deg, seed azimuth",
    "cff_u": "1",
    "cff_v": "1",
    "cff_w": "1",
    "cff_U": "1",
    "cff_th": "deg",
    "cfp_u": "1",
    "cfp_v": "1",
    "cfp_w": "1",
    "cfp_U": "1",
    "cfp_th": "deg",
}
"""Units of the seed columns, as written in CSV headers and NetCDF `units` attributes."""


def _wrap360(deg: np.ndarray) -> np.ndarray:
    out = np.mod(deg, 360.0)
    # np.mod(-1e-15, 360) rounds to 360.0; keep the result in [0, 360).
    return np.where(out >= 360.0, out - 360.0, out)


def _seed_azimuth_uv(
    u: Float[np.ndarray, "*shape"] | float, v: Float[np.ndarray, "*shape"] | float
) -> Float[np.ndarray, "*shape"]:
    """Seed flow azimuth in degrees: `(-atan2(v, u)) mod 360`, in [0, 360).

    The heading the flow goes towards, clockwise from +x (east); see the module
    docstring. `u`, `v` in m/s (any common shape). Calm points (`u = v = 0`) have no
    direction and give NaN.

    This is the numpy twin, on separate components, of the JAX `lidarjax.seed_azimuth`,
    which takes `(..., 3)` velocity vectors; both give the same angles.
    """
    u_ = np.asarray(u, dtype=np.float64)
    v_ = np.asarray(v, dtype=np.float64)
    theta = _wrap360(-np.degrees(np.arctan2(v_, u_)))
    return np.where((u_ == 0.0) & (v_ == 0.0), np.nan, theta)


def meteorological_from_seed(
    theta: Float[np.ndarray, "*shape"] | float,
) -> Float[np.ndarray, "*shape"]:
    """Meteorological direction (from, clockwise from north) from seed azimuth, degrees.

    `d = (theta + 270) mod 360`, in [0, 360). NaN stays NaN.
    """
    return _wrap360(np.asarray(theta, dtype=np.float64) + 270.0)


def seed_from_meteorological(d: Float[np.ndarray, "*shape"] | float) -> Float[np.ndarray, "*shape"]:
    """Seed azimuth (towards, clockwise from east) from meteorological direction, degrees.

    `theta = (d + 90) mod 360`, in [0, 360); the inverse of `meteorological_from_seed`.
    """
    return _wrap360(np.asarray(d, dtype=np.float64) + 90.0)


def seed_output_filename(beta: float) -> str:
    """`windcube simulation <beta> degrees.dat`, beta as an integer when integral.

    The C code printed `(int) beta` with `%d`; a non-integral beta (e.g. 22.5 for a
    16-sector study) is written as given instead of being truncated.
    """
    b = float(beta)
    if not math.isfinite(b):
        raise ValueError(f"beta must be finite, got {beta!r}")
    return f"windcube simulation {format_number(b)} degrees.dat"


def _check_columns(
    columns: Mapping[str, Any], required: tuple[str, ...] | None
) -> dict[str, np.ndarray]:
    if required is not None:
        missing = [c for c in required if c not in columns]
        unknown = [c for c in columns if c not in required]
        if missing:
            raise ValueError(f"missing seed columns: {', '.join(missing)}")
        if unknown:
            raise ValueError(
                f"unknown columns {', '.join(map(repr, unknown))}; the seed columns are "
                + " ".join(required)
            )
        names = list(required)
    else:
        names = list(columns)
        if not names:
            raise ValueError("no columns to write")
    arrays: dict[str, np.ndarray] = {}
    length: int | None = None
    for name in names:
        a = np.asarray(columns[name], dtype=np.float64)
        if a.ndim != 1:
            raise ValueError(f"column {name!r} must be 1-D, got shape {a.shape}")
        if length is None:
            length = a.shape[0]
        elif a.shape[0] != length:
            raise ValueError(
                f"column {name!r} has length {a.shape[0]}, expected {length} like "
                f"column {names[0]!r}"
            )
        arrays[name] = a
    return arrays


def write_seed_output(
    directory: PathLike,
    beta: float,
    columns: Mapping[str, Any],
    *,
    verbose: int | bool,
    flags: Any = None,
) -> Path:
    """Write a seed-format output file `windcube simulation <beta> degrees.dat`.

    **Arguments:**

    - `directory`: where to write (created if missing).
    - `beta`: platform rotation, degrees; names the file (`seed_output_filename`).
    - `columns`: a mapping from each of the 21 `SEED_COLUMNS` to a 1-D array of length
      `nh`. Angles in the seed azimuth convention (`lidarjax.seed_azimuth`). Missing or unknown
      names raise `ValueError`.
    - `verbose`: 1 (or `True`) writes the header line of column names; 0 writes none.
    - `flags`: optional `(nh,)` integer `lidarjax.Flag` bits per height, written as a 22nd
      column `flags` (after the seed's 21) that explains each NaN. The seed C code never
      wrote it; leave it out for files that must match the UDF's byte for byte.

    **Returns:** the path written. Numbers are formatted like the C `" %6.3f"` (NaN as
    `nan`); the write is atomic.
    """
    if verbose not in (0, 1):
        raise ValueError(f"verbose must be 0 or 1, got {verbose!r}")
    arrays = _check_columns(columns, SEED_COLUMNS)
    table = np.column_stack([arrays[c] for c in SEED_COLUMNS])
    names = SEED_COLUMNS
    bits = None
    if flags is not None:
        bits = np.asarray(flags).astype(np.int64).reshape(-1)
        if bits.shape != (table.shape[0],):
            raise ValueError(f"flags must have one value per height ({table.shape[0]}), got "
                             f"shape {np.shape(flags)}")
        names = SEED_COLUMNS + ("flags",)
    parts: list[str] = []
    if verbose:
        parts.append(" ".join(names) + "\n")
    for i, row in enumerate(table):
        tail = "" if bits is None else f" {int(bits[i]):6d}"
        parts.append("".join(f" {v:6.3f}" for v in row) + tail + " \n")
    folder = Path(directory)
    folder.mkdir(parents=True, exist_ok=True)
    return atomic_write_text(folder / seed_output_filename(beta), "".join(parts))


def read_seed_output(path: PathLike) -> dict[str, Float[np.ndarray, " h"]]:
    """Read a seed-format output file, with or without its header line.

    **Returns:** a dict from each of `SEED_COLUMNS` to a float64 array `(h,)`, in file
    order. Values carry the file's 3 decimals. A file written with `flags` (22 columns)
    also gives `"flags"`.

    Raises `ValueError` naming the line for a header that is not the 21 seed names, a
    row without 21 fields, or a non-numeric field.
    """
    p = require_file(path, "seed output file")
    rows: list[list[float]] = []
    columns = SEED_COLUMNS
    with open(p, encoding="utf-8") as fh:
        for number, raw in enumerate(fh, start=1):
            toks = raw.split()
            if not toks:
                continue
            if not rows and not is_number(toks[0]):
                if tuple(toks) == SEED_COLUMNS + ("flags",):
                    columns = SEED_COLUMNS + ("flags",)
                    continue
                if tuple(toks) != SEED_COLUMNS:
                    raise file_error(
                        p, number, "expected the seed header (" + " ".join(SEED_COLUMNS)
                        + f") or numbers, found {' '.join(toks[:4])} ..."
                    )
                continue
            if not rows and len(toks) == len(SEED_COLUMNS) + 1:
                columns = SEED_COLUMNS + ("flags",)
            if len(toks) != len(columns):
                raise file_error(
                    p, number, f"expected {len(columns)} numbers, found {len(toks)} fields"
                )
            rows.append(float_row(toks, columns, p, number))
    table = np.array(rows, dtype=np.float64).reshape(-1, len(columns))
    return {name: table[:, i].copy() for i, name in enumerate(columns)}


_BAD_NAME = re.compile(r"[,\[\]\r\n#]")


def _units_for(names: list[str], units: Mapping[str, str] | None) -> dict[str, str]:
    table = SEED_UNITS if units is None else units
    missing = [n for n in names if n not in table]
    if missing:
        raise ValueError(
            f"no unit given for columns {', '.join(missing)}; pass units={{name: unit}} "
            "(use '1' for dimensionless)"
        )
    return {n: str(table[n]) for n in names}


def _check_metadata(metadata: Mapping[str, Any] | None) -> dict[str, str]:
    out: dict[str, str] = {}
    for key, value in (metadata or {}).items():
        k, v = str(key), str(value)
        if ":" in k or "\n" in k or "\r" in k or not k.strip():
            raise ValueError(f"metadata key {k!r} must be non-empty without ':' or newlines")
        if "\n" in v or "\r" in v:
            raise ValueError(f"metadata value for {k!r} must be a single line")
        out[k.strip()] = v.strip()
    return out


def write_table_csv(
    path: PathLike,
    columns: Mapping[str, Any],
    units: Mapping[str, str] | None = None,
    metadata: Mapping[str, Any] | None = None,
) -> Path:
    """Write columns as a self-describing CSV, atomically.

    Layout: one `# key: value` line per metadata item, then a header naming each column
    with its unit in brackets (`U_lidar [m/s]`, `Th_lidar [deg, seed azimuth]`; the
    comma inside the brackets is part of the unit, readers split on `,` outside
    brackets), then comma-separated rows in shortest exact float form (`nan` for NaN).

    **Arguments:**

    - `columns`: name -> 1-D array, all the same length; written in mapping order.
    - `units`: name -> unit text for every column; defaults to `SEED_UNITS`.
    - `metadata`: key -> value, written as comment lines (single-line values).

    **Returns:** the path written. `read_table_csv` reads it back.
    """
    arrays = _check_columns(columns, None)
    names = list(arrays)
    for n in names:
        if _BAD_NAME.search(n) or n != n.strip() or not n:
            raise ValueError(f"column name {n!r} must not contain , [ ] # or newlines")
    unit_of = _units_for(names, units)
    for n, u in unit_of.items():
        if "]" in u or "\n" in u:
            raise ValueError(f"unit {u!r} of column {n!r} must not contain ']' or newlines")
    lines = [f"# {k}: {v}" for k, v in _check_metadata(metadata).items()]
    lines.append(",".join(f"{n} [{unit_of[n]}]" for n in names))
    table = np.column_stack([arrays[n] for n in names])
    lines.extend(",".join(repr(float(v)) for v in row) for row in table)
    return atomic_write_text(path, "\n".join(lines) + "\n")


@dataclass(frozen=True, eq=False)
class CsvTable:
    """A table read by `read_table_csv`: `columns` name -> `(n,)` float64, `units`, `metadata`."""

    columns: dict[str, Float[np.ndarray, " n"]]
    units: dict[str, str]
    metadata: dict[str, str]


_CELL = r"\s*([^,\[\]#]+?)\s*\[([^\]]*)\]\s*"
_CELL_NC = r"\s*[^,\[\]#]+?\s*\[[^\]]*\]\s*"
_HEADER_CELL = re.compile(_CELL + r"(?:,|$)")
_HEADER_LINE = re.compile(_CELL_NC + r"(?:," + _CELL_NC + r")*")


def read_table_csv(path: PathLike) -> CsvTable:
    """Read a CSV written by `write_table_csv` (comment metadata, `name [unit]` header)."""
    p = require_file(path, "CSV table")
    metadata: dict[str, str] = {}
    names: list[str] | None = None
    units: dict[str, str] = {}
    rows: list[list[float]] = []
    with open(p, encoding="utf-8") as fh:
        for number, raw in enumerate(fh, start=1):
            line = raw.rstrip("\r\n")
            if not line.strip():
                continue
            if names is None and line.startswith("#"):
                key, sep, value = line[1:].partition(":")
                if not sep:
                    raise file_error(p, number, "expected a '# key: value' metadata line")
                metadata[key.strip()] = value.strip()
                continue
            if names is None:
                if not _HEADER_LINE.fullmatch(line):
                    raise file_error(p, number, "expected a header of 'name [unit]' cells")
                cells = _HEADER_CELL.findall(line)
                names = [n for n, _ in cells]
                units = {n: u for n, u in cells}
                continue
            fields = line.split(",")
            if len(fields) != len(names):
                raise file_error(
                    p, number, f"expected {len(names)} comma-separated values, "
                    f"found {len(fields)}"
                )
            rows.append(float_row(fields, names, p, number))
    if names is None:
        raise file_error(p, None, "no header line found")
    table = np.array(rows, dtype=np.float64).reshape(-1, len(names))
    return CsvTable(
        columns={n: table[:, i].copy() for i, n in enumerate(names)},
        units=units,
        metadata=metadata,
    )


def _netcdf_attr(value: Any) -> Any:
    if isinstance(value, bool):
        return int(value)
    if isinstance(value, (int, float, str, np.integer, np.floating)):
        return value
    return str(value)


def write_netcdf(
    path: PathLike,
    columns: Mapping[str, Any],
    attrs: Mapping[str, Any] | None = None,
    *,
    units: Mapping[str, str] | None = None,
    dim: str = "h",
) -> Path:
    """Write columns as a NetCDF file with xarray (optional extra `netcdf`), atomically.

    Each column becomes a variable along dimension `dim`; if a column is named `dim`
    (the seed's `h`) it becomes the coordinate. Each variable carries a `units`
    attribute (from `units`, default `SEED_UNITS`); `attrs` become global attributes
    (values other than numbers and strings are stored as text).

    The engine is `h5netcdf` (NetCDF4) when installed, else scipy's NetCDF3 writer,
    which needs nothing beyond xarray and scipy.

    Raises `ImportError` naming `pip install lidarjax[netcdf]` when xarray is missing.
    """
    xr = import_optional("xarray", "netcdf", "write_netcdf")
    arrays = _check_columns(columns, None)
    unit_of = _units_for(list(arrays), units)
    coords = {}
    if dim in arrays:
        coords[dim] = (dim, arrays[dim], {"units": unit_of[dim]})
    data_vars = {
        n: (dim, a, {"units": unit_of[n]}) for n, a in arrays.items() if n != dim
    }
    ds = xr.Dataset(
        data_vars=data_vars,
        coords=coords,
        attrs={str(k): _netcdf_attr(v) for k, v in (attrs or {}).items()},
    )
    target = Path(path)
    with atomic_path(target) as tmp:
        ds.to_netcdf(os.fspath(tmp), engine=netcdf_engine())
    return target
