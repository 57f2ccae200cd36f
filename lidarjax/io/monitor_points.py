"""CFD probe files: the lidar's sample points out, the CFD code's samples back in.

Out (`lidarjax.MonitorPoints`, from `lidarjax.monitor_points`):

- `write_openfoam_probes`: an OpenFOAM ``probes`` function-object dictionary
  (``type probes; libs ("libsampling.so"); interpolationScheme cellPoint; fields (U);
  probeLocations (...)``), one named sub-dictionary, so it works both as
  ``postProcess -func <name>`` (file in ``system/``) and inside ``controlDict``'s
  ``functions { #include "<name>" }``. Each location carries its name as a comment.
- `write_zcfd_probes`: a zCFD probe file (Python) in the ``turb_probe`` layout of zCFD's
  wind-farm utility: ``turb_probe = {'report': {'frequency': F, 'monitor': {'MR_1':
  {'name': ..., 'point': [x, y, z], 'variables': ['V']}, ...}}}``.
- `write_monitor_points_csv`: CSV ``name, mount, x, y, z, beta, height, beam, node, weight`` (read
  back with `read_monitor_points_csv`).

In:

- `read_openfoam_probes`: ``postProcessing/<name>/<startTime>/U`` as OpenFOAM writes it
  (``# Probe i (x y z)`` header lines, ``# Not Found`` marks, rows ``time (u v w) ...``,
  ``-1e+300`` for probes outside the mesh, read as NaN). Given the function object's folder
  it reads every start-time folder (restarts): rows are merged by time, a later start
  folder replacing an earlier one's rows at the same times.
- `read_monitor_values_csv`: CSV ``name, u, v, w`` (any other columns ignored).

Coordinates are absolute CFD metres; velocities ``(u, v, w)`` m/s in the CFD frame. Every
write is atomic.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
from pathlib import Path

import numpy as np

from .._util import PathLike, atomic_write_text, file_error, format_number, normalise_key, require_file
from ._common import parse_float

__all__ = [
    "OpenFoamProbes",
    "read_openfoam_probes",
    "read_monitor_points_csv",
    "read_monitor_values_csv",
    "write_openfoam_probes",
    "write_monitor_points_csv",
    "write_zcfd_probes",
]

_CSV_COLUMNS = ("name", "mount", "x", "y", "z", "beta", "height", "beam", "node", "weight")
#: OpenFOAM writes -VGREAT (-1e+300) for a probe found in no cell.
_UNSET = -1e299


#: Node index of the point-reference rows (the column above the lidar).
POINT_REFERENCE = -1


#: Node index of a beam's focus sampled in place of an even-count probe whose nodes all
#: fall behind the lidar (the limit `simulate` takes then).
FOCUS_FALLBACK = -2


@dataclasses.dataclass(frozen=True, eq=False)
class MonitorPoints:
    """Named CFD probe points of one or more lidar mounts (``n`` rows).

    - `names`: ``(n,)`` unique names ``<mount>_h<height>_beam<b>_q<node>`` or
      ``<mount>_h<height>_point``.
    - `mount`: ``(n,)`` the mount label of each row (default ``b<beta>``).
    - `points`: ``(n, 3)`` absolute CFD coordinates, metres, float64.
    - `beta`: ``(n,)`` the mount's platform rotation, degrees.
    - `height`: ``(n,)`` measurement height above the lidar, metres.
    - `beam`: ``(n,)`` beam index in the scan's order; -1 for the point reference.
    - `node`: ``(n,)`` quadrature node index (0 for the point probe); -1 for the point
      reference, -2 for a focus sampled because every node of an even-count probe fell
      behind the lidar.
    - `weight`: ``(n,)`` the node's weight in its beam's LOS after the cut at the lidar
      (the weights of one beam and height sum to one); NaN for the point reference.

    Row order is the order written to files (OpenFOAM numbers its probes by it).
    """

    names: tuple[str, ...]
    mount: tuple[str, ...]
    points: np.ndarray
    beta: np.ndarray
    height: np.ndarray
    beam: np.ndarray
    node: np.ndarray
    weight: np.ndarray

    def __post_init__(self):
        n = len(self.names)
        pts = np.asarray(self.points, np.float64)
        if pts.shape != (n, 3):
            raise ValueError(f"MonitorPoints: points must have shape ({n}, 3), got {pts.shape}")
        for field in ("beta", "height", "beam", "node", "weight"):
            if np.shape(getattr(self, field)) != (n,):
                raise ValueError(f"MonitorPoints: {field} must have shape ({n},)")
        if len(self.mount) != n:
            raise ValueError(f"MonitorPoints: mount must have {n} labels")
        if len(set(self.names)) != n:
            seen, dup = set(), []
            for name in self.names:
                if name in seen:
                    dup.append(name)
                seen.add(name)
            raise ValueError(f"MonitorPoints: probe names must be unique; repeated: {dup[:5]}")
        if not np.all(np.isfinite(pts)):
            raise ValueError("MonitorPoints: points must be finite")

    def __len__(self) -> int:
        return len(self.names)

    @property
    def labels(self) -> tuple[str, ...]:
        """The mount labels in order of first appearance."""
        return tuple(dict.fromkeys(self.mount))

    def rows(self, label: str) -> np.ndarray:
        """Row indices of mount `label`."""
        return np.flatnonzero(np.asarray(self.mount) == label)


def _check_locations(locations, where: str):
    if not isinstance(locations, MonitorPoints):
        raise ValueError(f"{where}: expected lidarjax.MonitorPoints (lidarjax.monitor_points), "
                         f"got {type(locations).__name__}")
    if len(locations) == 0:
        raise ValueError(f"{where}: no probe locations to write")


def _r(x: float) -> str:
    return repr(float(x))


def _header_lines(metadata: dict | None, comment: str) -> list[str]:
    return [f"{comment} {k}: {v}" for k, v in (metadata or {}).items()]


# -- writers ----------------------------------------------------------------------------
def write_openfoam_probes(
    path: PathLike,
    locations,
    *,
    name: str | None = None,
    fields: tuple[str, ...] = ("U",),
    interpolation: str = "cellPoint",
    write_control: str = "writeTime",
    metadata: dict | None = None,
) -> Path:
    """Write an OpenFOAM ``probes`` function-object dictionary for `locations`.

    **Arguments:**

    - `path`: the file (e.g. ``system/lidarProbes``); its name is the function object's name
      unless `name` is given (OpenFOAM then writes ``postProcessing/<name>/<time>/U``).
    - `fields`: fields to sample (default the velocity ``U``).
    - `interpolation`: ``cellPoint`` (default: linear inside the cell from the cell value
      and the interpolated point values) or ``cell`` (the containing cell's value).
    - `write_control`: ``writeTime`` (sample when the solver writes; default) or
      ``timeStep`` (every step). Ignored by ``postProcess``.

    Usage: copy the file to the case's ``system/`` and run ``postProcess -func lidarProbes
    -latestTime`` (or the solver's ``-postProcess`` option), or add ``#include "lidarProbes"``
    inside ``functions { }`` in ``controlDict``. Probe ``i`` is row ``i`` of `locations`.
    """
    _check_locations(locations, "write_openfoam_probes")
    target = Path(path)
    name = name or target.name
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.:-]*", name):
        raise ValueError(f"write_openfoam_probes: {name!r} is not a valid OpenFOAM word")
    lines = [
        "/*--------------------------------*- C++ -*----------------------------------*\\",
        "  lidarjax: the lidar's sample points as an OpenFOAM probes function object",
        "\\*---------------------------------------------------------------------------*/",
        *_header_lines(metadata, "//"),
        f"FoamFile {{ version 2.0; format ascii; class dictionary; object {name}; }}",
        "",
        name,
        "{",
        "    type                probes;",
        '    libs                ("libsampling.so");',
        f"    writeControl        {write_control};",
        "    writeInterval       1;",
        f"    interpolationScheme {interpolation};",
        f"    fields              ({' '.join(fields)});",
        f"    // {len(locations)} probes: <mount>_h<height>_beam<b>_q<node> (_point: above the lidar)",
        "    probeLocations",
        "    (",
    ]
    for i, (n, p) in enumerate(zip(locations.names, locations.points, strict=True)):
        lines.append(f"        ({_r(p[0])} {_r(p[1])} {_r(p[2])})  // {i} {n}")
    lines += ["    );", "}", ""]
    return atomic_write_text(target, "\n".join(lines))


def write_zcfd_probes(
    path: PathLike,
    locations,
    *,
    frequency: int = 100,
    variables: tuple[str, ...] = ("V",),
    metadata: dict | None = None,
) -> Path:
    """Write a zCFD probe file: a Python module defining ``turb_probe`` in the layout of
    zCFD's wind-farm utility (``report`` -> ``frequency``, ``monitor`` -> ``MR_1`` ... with
    ``name``, ``point`` and ``variables``).

    Merge it into the zCFD parameters as the wind-farm utility's probes are::

        p = zutil.get_zone_info('lidar_probes')
        for key, value in p.turb_probe.items():
            parameters[key] = value

    (zCFD then reports the monitors in ``<case>_report.csv``). `frequency` is the number of
    solver cycles between reports; `variables` the reported variables (``V``: velocity).
    """
    _check_locations(locations, "write_zcfd_probes")
    if int(frequency) < 1:
        raise ValueError(f"write_zcfd_probes: frequency must be >= 1 cycles, got {frequency}")
    var = "[" + ", ".join(repr(str(v)) for v in variables) + "]"
    lines = ['"""lidarjax: the lidar\'s sample points as zCFD monitor probes."""',
             *_header_lines(metadata, "#"),
             "turb_probe = {",
             "    'report': {",
             f"        'frequency': {int(frequency)},",
             "        'monitor': {"]
    for i, (n, p) in enumerate(zip(locations.names, locations.points, strict=True)):
        lines += [f"            'MR_{i + 1}': {{",
                  f"                'name': {n!r},",
                  f"                'point': [{_r(p[0])}, {_r(p[1])}, {_r(p[2])}],",
                  f"                'variables': {var},",
                  "            },"]
    lines += ["        },", "    },", "}", ""]
    return atomic_write_text(path, "\n".join(lines))


def write_monitor_points_csv(path: PathLike, locations, *, metadata: dict | None = None) -> Path:
    """Write `locations` as CSV: ``name, mount, x, y, z [m], beta [deg], height [m], beam,
    node, weight``, one row per probe in order (``#`` comment lines carry `metadata`).
    ``beam = node = -1`` marks the point reference above the lidar (weight empty)."""
    _check_locations(locations, "write_monitor_points_csv")
    loc = locations
    lines = _header_lines(metadata, "#")
    lines.append("name,mount,x [m],y [m],z [m],beta [deg],height [m],beam,node,weight")
    for i, n in enumerate(loc.names):
        p = loc.points[i]
        w = "" if not np.isfinite(loc.weight[i]) else _r(loc.weight[i])
        lines.append(",".join([n, loc.mount[i], _r(p[0]), _r(p[1]), _r(p[2]),
                               format_number(loc.beta[i]), format_number(loc.height[i]),
                               str(int(loc.beam[i])), str(int(loc.node[i])), w]))
    return atomic_write_text(path, "\n".join(lines) + "\n")


# -- readers ----------------------------------------------------------------------------
def _csv_rows(path: Path):
    """(line number, fields) of the non-comment, non-blank lines."""
    with open(path, encoding="utf-8", errors="replace") as fh:
        for number, raw in enumerate(fh, 1):
            s = raw.strip()
            if s and not s.startswith("#"):
                yield number, [f.strip() for f in s.split(",")]


def read_monitor_points_csv(path: PathLike):
    """Read probe locations written by `write_monitor_points_csv` as `lidarjax.MonitorPoints`."""

    p = require_file(path, "probe CSV")
    rows = _csv_rows(p)
    try:
        number, header = next(rows)
    except StopIteration:
        raise file_error(p, None, "empty file; expected a header " + ",".join(_CSV_COLUMNS)) from None
    keys = [normalise_key(h) for h in header]
    missing = [c for c in _CSV_COLUMNS if c not in keys]
    if missing:
        raise file_error(p, number, f"header lacks {', '.join(missing)}; expected "
                                    f"{', '.join(_CSV_COLUMNS)}")
    col = {c: keys.index(c) for c in _CSV_COLUMNS}
    data: dict[str, list] = {c: [] for c in _CSV_COLUMNS}
    for number, fields in rows:
        if len(fields) < len(keys):
            raise file_error(p, number, f"expected {len(keys)} fields, found {len(fields)}")
        for c in _CSV_COLUMNS:
            text = fields[col[c]]
            if c in ("name", "mount"):
                data[c].append(text)
                continue
            try:
                data[c].append(math.nan if (c == "weight" and text == "") else float(text))
            except ValueError:
                raise file_error(p, number, f"column {c!r}: expected a number, found {text!r}") from None
    if not data["name"]:
        raise file_error(p, None, "no probe rows after the header")
    try:
        return MonitorPoints(
            names=tuple(data["name"]), mount=tuple(data["mount"]),
            points=np.array([data["x"], data["y"], data["z"]], np.float64).T,
            beta=np.array(data["beta"]), height=np.array(data["height"]),
            beam=np.array(data["beam"], np.int64), node=np.array(data["node"], np.int64),
            weight=np.array(data["weight"]))
    except ValueError as err:
        raise file_error(p, None, str(err)) from None


def read_monitor_values_csv(path: PathLike) -> dict[str, np.ndarray]:
    """Read sampled velocities from CSV with columns ``name, u, v, w`` (m/s, CFD frame;
    header names case-insensitive, units in brackets and other columns ignored; empty or
    ``nan`` values are NaN). Returns ``{name: (3,) float64}``."""

    p = require_file(path, "probe values CSV")
    rows = _csv_rows(p)
    try:
        number, header = next(rows)
    except StopIteration:
        raise file_error(p, None, "empty file; expected a header name,u,v,w") from None
    keys = [normalise_key(h) for h in header]
    missing = [c for c in ("name", "u", "v", "w") if c not in keys]
    if missing:
        raise file_error(p, number, f"header lacks {', '.join(missing)}; expected name,u,v,w, "
                                    f"found {','.join(header)}")
    ci = [keys.index(c) for c in ("name", "u", "v", "w")]
    out: dict[str, np.ndarray] = {}
    for number, fields in rows:
        if len(fields) <= max(ci):
            raise file_error(p, number, f"expected at least {max(ci) + 1} fields, found {len(fields)}")
        name = fields[ci[0]]
        if name in out:
            raise file_error(p, number, f"probe {name!r} appears twice")
        try:
            out[name] = np.array([parse_float(fields[c]) for c in ci[1:]])
        except ValueError:
            raise file_error(p, number, "u, v, w must be numbers (m/s)") from None
    if not out:
        raise file_error(p, None, "no rows after the header")
    return out


@dataclasses.dataclass(frozen=True, eq=False)
class OpenFoamProbes:
    """Samples of one field read from OpenFOAM ``probes`` output (``k`` probes, ``t`` times).

    - `path`: what was read; `field`: the field name (file name, e.g. ``U``).
    - `indices`: ``(k,)`` OpenFOAM probe numbers (row numbers of the written locations).
    - `header_points`: ``(k, 3)`` probe locations as printed in the header (only as precise
      as OpenFOAM's ``writePrecision``); `header_resolution`: ``(k, 3)`` the unit of the last
      printed digit of each coordinate.
    - `found`: ``(k,)`` False for probes OpenFOAM marked ``# Not Found`` (outside the mesh).
    - `times`: ``(t,)`` increasing; `values`: ``(t, k, c)`` (``c = 3`` for vectors, 1 for
      scalars), NaN where OpenFOAM wrote its "unset" value (-1e+300).
    - `start_times`: the start-time folders read, in order.
    """

    path: str
    field: str
    indices: np.ndarray
    header_points: np.ndarray
    header_resolution: np.ndarray
    found: np.ndarray
    times: np.ndarray
    values: np.ndarray
    start_times: tuple[str, ...]

    def at(self, time: float | None = None, window: tuple[float, float] | None = None) -> np.ndarray:
        """``(k, c)`` values at the latest time (default), at `time` (the row within 1e-9
        relative of it), or averaged over the rows with ``window[0] <= t <= window[1]``."""
        if time is not None and window is not None:
            raise ValueError("give either time or window, not both")
        if window is not None:
            t0, t1 = (float(w) for w in window)
            sel = (self.times >= t0) & (self.times <= t1)
            if not np.any(sel):
                raise ValueError(f"{self.path}: no sampled time in [{t0:g}, {t1:g}]; times run "
                                 f"from {self.times[0]:g} to {self.times[-1]:g}")
            return self.values[sel].mean(axis=0)
        if time is None:
            return self.values[-1]
        k = int(np.argmin(np.abs(self.times - float(time))))
        if abs(self.times[k] - float(time)) > 1e-9 * max(1.0, abs(float(time))):
            raise ValueError(f"{self.path}: time {float(time):g} was not sampled; nearest is "
                             f"{self.times[k]:g} (times {self.times[0]:g} to {self.times[-1]:g})")
        return self.values[k]

    def values_for(self, locations, *, time: float | None = None,
                   window: tuple[float, float] | None = None) -> np.ndarray:
        """``(n, c)`` values in the row order of `locations` (probe ``i`` = row ``i``), after
        checking that OpenFOAM's header places every probe where `locations` does (to the
        printed precision; to `FLOAT32_ULPS` float32 ulps of the coordinate when `locations`
        holds float32 points or the header was printed from float32 points: every
        coordinate a float32 number, printed with more digits than float32 holds). Probes
        missing from the output (``includeOutOfBounds false``) or not found are NaN."""
        _check_locations(locations, "values_for")
        n = len(locations)
        if self.indices.size and int(self.indices.max()) >= n:
            raise ValueError(f"{self.path}: holds probe {int(self.indices.max())} but only {n} "
                             "locations were given; these samples belong to other probes")
        expected = np.asarray(locations.points, np.float64)[self.indices]
        gap = np.abs(self.header_points - expected)
        tol = 1.01 * self.header_resolution + 1e-12 * np.abs(expected)
        if np.asarray(locations.points).dtype == np.float32 or _float32_header(self.header_points,
                                                                               self.header_resolution):
            # float32 points on either side: the probes agree to float32's rounding
            size = np.maximum(np.abs(expected), np.abs(self.header_points)).astype(np.float32)
            tol = np.maximum(tol, FLOAT32_ULPS * np.spacing(size).astype(np.float64))
        bad = np.flatnonzero(np.any(gap > tol, axis=1))
        if bad.size:
            k = bad[0]
            raise ValueError(
                f"{self.path}: probe {int(self.indices[k])} is at {self.header_points[k].tolist()} "
                f"but location {locations.names[self.indices[k]]} is "
                f"{expected[k].tolist()}; these samples were written for other probes")
        out = np.full((n, self.values.shape[-1]), np.nan)
        out[self.indices] = self.at(time, window)
        return out


#: Float32 ulps (of each coordinate's magnitude) by which probe locations may differ when
#: the points on either side of `OpenFoamProbes.values_for` are float32.
FLOAT32_ULPS = 4


def _float32_header(points: np.ndarray, resolution: np.ndarray) -> bool:
    """Whether header locations were printed from float32 points: every coordinate is a
    float32 number, and some nonzero one is printed finer than float32's spacing there (so
    that being a float32 number is no accident of a short print)."""
    if points.size == 0 or not np.array_equal(points.astype(np.float32).astype(np.float64), points):
        return False
    spacing = np.spacing(np.abs(points).astype(np.float32)).astype(np.float64)
    return bool(np.any((points != 0) & (resolution < spacing / 2)))


_PROBE_RE = re.compile(r"^#\s*Probe\s+(\d+)\s*\(([^)]*)\)(.*)$")


def _resolution(token: str) -> float:
    """The unit of the last printed digit of a number token ('1.23457e+06' -> 10)."""
    t = token.strip().lower()
    mant, _, exp = t.partition("e")
    e = int(exp) if exp else 0
    frac = mant.split(".")[1] if "." in mant else ""
    return 10.0 ** (e - len(frac))


def _read_one(path: Path):
    header: dict[int, tuple[np.ndarray, np.ndarray, bool]] = {}
    columns: list[int] | None = None
    times: list[float] = []
    rows: list[np.ndarray] = []
    width = None
    with open(path, encoding="utf-8", errors="replace") as fh:
        for number, raw in enumerate(fh, 1):
            s = raw.strip()
            if not s:
                continue
            if s.startswith("#"):
                m = _PROBE_RE.match(s)
                if m:
                    toks = m.group(2).split()
                    if len(toks) != 3:
                        raise file_error(path, number, "probe location needs three coordinates")
                    header[int(m.group(1))] = (np.array([float(t) for t in toks]),
                                               np.array([_resolution(t) for t in toks]),
                                               "not found" not in m.group(3).lower())
                    continue
                parts = s[1:].split()
                if parts and parts[0] == "Probe":
                    try:
                        columns = [int(x) for x in parts[1:]]
                    except ValueError:
                        raise file_error(path, number, "unreadable probe-number line") from None
                continue
            toks = s.replace("(", " ").replace(")", " ").split()
            try:
                vals = np.array([float(t) for t in toks])
            except ValueError:
                raise file_error(path, number, "expected a time followed by numbers") from None
            if columns is None:
                columns = sorted(header)
            if not columns:
                raise file_error(path, number, "data before any '# Probe' header line")
            if width is None:
                if (vals.size - 1) % len(columns):
                    raise file_error(path, number, f"{vals.size - 1} numbers for {len(columns)} probes")
                width = (vals.size - 1) // len(columns)
            if vals.size != 1 + width * len(columns):
                # the last row of a run that was stopped while writing: skip it
                if number == _line_count(path):
                    break
                raise file_error(path, number, f"expected {1 + width * len(columns)} numbers, "
                                               f"found {vals.size}")
            times.append(vals[0])
            rows.append(vals[1:].reshape(len(columns), width))
    if columns is None or not rows:
        raise file_error(path, None, "no samples: expected OpenFOAM probes output ('# Probe i "
                                     "(x y z)' lines, then rows 'time (u v w) ...')")
    missing = [c for c in columns if c not in header]
    if missing:
        raise file_error(path, None, f"probes {missing[:5]} have no '# Probe' header line")
    return columns, header, np.array(times), np.stack(rows)


def _line_count(path: Path) -> int:
    with open(path, "rb") as fh:
        return sum(1 for line in fh if line.strip())


def _time_key(name: str) -> float | None:
    try:
        return float(name)
    except ValueError:
        return None


def read_openfoam_probes(path: PathLike, *, field: str = "U") -> OpenFoamProbes:
    """Read OpenFOAM ``probes`` output of one field.

    `path` is the function object's folder (``postProcessing/<name>``: every start-time
    folder in it is read, rows merged by time with later start folders winning, as after a
    restart), one start-time folder, or the field file itself. Values written as -1e+300
    (probe in no cell) become NaN.
    """
    p = Path(path)
    if p.is_file():
        files = [p]
    elif p.is_dir():
        if (p / field).is_file():
            files = [p / field]
        else:
            starts = sorted((d for d in p.iterdir() if d.is_dir() and _time_key(d.name) is not None),
                            key=lambda d: _time_key(d.name))
            files = [d / field for d in starts if (d / field).is_file()]
            if not files:
                raise FileNotFoundError(
                    f"no OpenFOAM probe output for field {field!r} in {os.fspath(p)}; expected "
                    f"{os.fspath(p)}/<time>/{field} (postProcessing/<name> of a probes function object)")
    else:
        raise FileNotFoundError(f"OpenFOAM probe output not found: {os.fspath(p)}")
    columns = header = None
    merged: dict[float, np.ndarray] = {}
    for f in files:
        cols, head, times, vals = _read_one(f)
        if columns is None:
            columns, header = cols, head
        elif cols != columns:
            raise ValueError(f"{os.fspath(f)}: probes {cols[:5]}... differ from those of "
                             f"{os.fspath(files[0])}; one probe set per function object")
        for t, v in zip(times, vals, strict=True):
            merged[float(t)] = v  # later start folders (restarts) replace earlier rows
    times = np.array(sorted(merged))
    values = np.stack([merged[t] for t in times])
    values = np.where(values <= _UNSET, np.nan, values)
    idx = np.array(columns, np.int64)
    return OpenFoamProbes(
        path=os.fspath(p), field=field, indices=idx,
        header_points=np.array([header[c][0] for c in columns]).reshape(-1, 3),
        header_resolution=np.array([header[c][1] for c in columns]).reshape(-1, 3),
        found=np.array([header[c][2] for c in columns]),
        times=times, values=values,
        start_times=tuple(f.parent.name for f in files))
