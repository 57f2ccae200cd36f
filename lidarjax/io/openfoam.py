"""OpenFOAM case directories: the mesh (`constant/polyMesh`) and a time directory's `U`.

Read natively (numpy; no OpenFOAM installation or third-party package needed): ASCII and
binary files (label and scalar widths from the header's `arch`), gzip-compressed files
(`points.gz` ...), `faceList` and `faceCompactList` faces, polyhedral cells,
`internalField uniform (...)` and `nonuniform List<vector>`, and the boundary values of
every patch. The latest time directory holding the field is used unless `time` is given.
A decomposed case (only `processor*/` directories, as `decomposePar` writes them) is read
without `reconstructPar`: each processor's mesh and field are merged into the undecomposed
mesh through `decomposePar`'s `pointProcAddressing`, `faceProcAddressing` and
`cellProcAddressing`, so the result is the original mesh, point values on processor
boundaries included (exact, as if reconstructed).

Sampling follows OpenFOAM's own `cellPoint` interpolation (see `lidarjax.io._cells`): the
values lidarjax sees are those that OpenFOAM's `probes` function object with
`interpolationScheme cellPoint` writes, to rounding. Points inside solids (buildings,
terrain) or outside the domain are NaN.

Coordinates are the case's own (metres, CFD frame, usually `x` east, `y` north, `z` up);
velocities in m/s in the same frame.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from jaxtyping import Float
from scipy.interpolate import RegularGridInterpolator

from .._util import PathLike, file_error
from ._cells import BoundaryValues, CellPointSampler, PolyMesh, build_sampler, cell_bounds
from ._foamfile import Cursor, open_file, resolve_file

__all__ = [
    "OpenFOAMField",
    "is_openfoam_case",
    "openfoam_times",
    "read_openfoam_field",
    "read_openfoam_mesh",
    "resample_openfoam",
    "sample_openfoam",
]

DEFAULT_RESOLUTION = 2.0
"""Grid nodes per cell width (per axis) of the automatic resampling grid."""

DEFAULT_MAX_NODES = 20_000_000
"""Upper bound of the automatic resampling grid's node count (about 480 MB in float64)."""

_ZERO_GRADIENT_TYPES = ("zeroGradient", "calculated", "extrapolatedCalculated", "fixedGradient",
                        "outletInlet")
_SLIP_TYPES = ("slip", "symmetry", "symmetryPlane", "partialSlip", "wedge")


def _has_mesh(p: Path) -> bool:
    return p.is_dir() and ((p / "constant" / "polyMesh").is_dir()
                           or (p / "processor0" / "constant" / "polyMesh").is_dir())


def case_and_time(path: PathLike) -> tuple[Path, str | None]:
    """The case directory of `path` and the time `path` names, if any: a case directory
    (plain or decomposed), its ``system/controlDict`` or a ``case.foam`` in it give
    ``(case, None)``; a time directory of the case (``CASE/400``) gives ``(CASE, "400")``.
    The path is returned as given when it is none of these (the readers then say why)."""
    p = Path(path)
    if p.is_file() and (p.suffix in (".foam", ".OpenFOAM") or p.name == "controlDict"):
        return (p.parent.parent if p.name == "controlDict" else p.parent), None
    if p.is_dir() and not _has_mesh(p) and _is_time_name(p.name) and _has_mesh(p.parent):
        return p.parent, p.name
    return p, None


def is_openfoam_case(path: PathLike) -> bool:
    """Whether `path` is an OpenFOAM case directory (has `constant/polyMesh` or
    `processor0/constant/polyMesh`), a file inside one's root (`system/controlDict`,
    `case.foam`), or one of its time directories (`CASE/400`)."""
    return _has_mesh(case_and_time(path)[0])


def _case_dir(path: PathLike) -> Path:
    p = case_and_time(path)[0]
    if p.is_file() and p.name == "controlDict":
        p = p.parent.parent
    elif p.is_file():
        p = p.parent
    if not p.is_dir():
        raise FileNotFoundError(f"OpenFOAM case directory not found: {os.fspath(path)}")
    mesh = p / "constant" / "polyMesh"
    if not mesh.is_dir():
        if (p / "processor0" / "constant" / "polyMesh").is_dir():
            return p
        raise ValueError(f"{os.fspath(p)}: not an OpenFOAM case (no constant/polyMesh directory)")
    return p


def _is_time_name(name: str) -> bool:
    try:
        v = float(name)
    except ValueError:
        return False
    return math.isfinite(v)


def openfoam_times(case: PathLike, field: str = "U") -> list[str]:
    """Names of the case's time directories that hold `field` (plain or `.gz`), in
    increasing time order."""
    p = _case_dir(case)
    if _is_decomposed(p):
        p = p / "processor0"
    times = [d.name for d in p.iterdir() if d.is_dir() and _is_time_name(d.name)
             and resolve_file(d / field) is not None]
    return sorted(times, key=float)


def read_openfoam_mesh(case: PathLike) -> PolyMesh:
    """Read `constant/polyMesh` (points, faces, owner, neighbour, boundary) of a case
    (of a decomposed case: the undecomposed mesh, merged from the processors)."""
    p = _case_dir(case)
    if _is_decomposed(p):
        return _merge_meshes(p, *_processor_meshes(p))[0]
    d = p / "constant" / "polyMesh"
    cur = open_file(d / "points")
    points = cur.read_list(3, np.float64, "point")
    cur = open_file(d / "faces")
    offsets, labels = cur.read_face_list()
    cur = open_file(d / "owner")
    owner = cur.read_list(1, np.int64, "owner")
    own_note = cur.header.note if cur.header else ""
    cur = open_file(d / "neighbour")
    neighbour = cur.read_list(1, np.int64, "neighbour")
    n_faces = offsets.size - 1
    where = os.fspath(d)
    if owner.size != n_faces:
        raise ValueError(f"{where}: owner has {owner.size} entries but faces has {n_faces} faces")
    if neighbour.size > n_faces:
        raise ValueError(f"{where}: neighbour has more entries ({neighbour.size}) than faces ({n_faces})")
    if labels.size and (labels.min() < 0 or labels.max() >= points.shape[0]):
        raise ValueError(f"{where}: faces reference points outside 0..{points.shape[0] - 1}")
    n_cells = int(owner.max()) + 1 if owner.size else 0
    if neighbour.size:
        n_cells = max(n_cells, int(neighbour.max()) + 1)
    m = re.search(r"nCells:\s*(\d+)", own_note)
    if m:
        n_cells = max(n_cells, int(m.group(1)))
    if owner.size and owner.min() < 0 or neighbour.size and neighbour.min() < 0:
        raise ValueError(f"{where}: negative cell labels in owner/neighbour")
    patches = _read_boundary(d / "boundary", n_faces, neighbour.size)
    return PolyMesh(points=points, face_offsets=offsets, face_labels=labels, owner=owner,
                    neighbour=neighbour, n_cells=n_cells, patches=patches)


def _read_boundary(path: Path, n_faces: int, n_internal: int) -> tuple[tuple[str, str, int, int], ...]:
    cur = open_file(path)
    n = cur.read_size("patch")
    cur.expect(b"(", "opening the patch list")
    out = []
    for _ in range(n):
        start_pos = cur.pos
        name = cur.token().decode(errors="replace").strip('"')
        entries = cur.read_dict()
        try:
            ptype = str(entries["type"])
            n_f = int(float(entries["nFaces"]))
            start = int(float(entries["startFace"]))
        except (KeyError, ValueError):
            raise cur.error(f"patch {name!r} needs type, nFaces and startFace", start_pos) from None
        if start < n_internal or start + n_f > n_faces:
            raise cur.error(f"patch {name!r}: faces {start}..{start + n_f - 1} are not boundary faces "
                            f"({n_internal}..{n_faces - 1})", start_pos)
        out.append((name, ptype, start, n_f))
    cur.expect(b")", "closing the patch list")
    return tuple(out)


def _pick_time(p: Path, field: str, time: Any) -> str:
    if _is_decomposed(p):
        p = p / "processor0"
    times = openfoam_times(p, field)
    if time is None or time == "latestTime":
        if not times:
            present = sorted(d.name for d in p.iterdir() if d.is_dir() and _is_time_name(d.name))
            if present:
                raise ValueError(
                    f"{os.fspath(p)}: no time directory holds the field {field!r} (time directories: "
                    f"{', '.join(present)})")
            raise ValueError(f"{os.fspath(p)}: no time directories (0, 100, ...) in the case")
        return times[-1]
    if isinstance(time, str) and (p / time).is_dir():
        name = time
    else:
        try:
            tv = float(time)
        except (TypeError, ValueError):
            raise ValueError(f"time must be a number, a time directory name or 'latestTime', got {time!r}") \
                from None
        match = [t for t in times if math.isclose(float(t), tv, rel_tol=1e-9, abs_tol=1e-12)]
        if not match:
            raise ValueError(f"{os.fspath(p)}: no time {time!r} holding {field!r}; available: "
                             f"{', '.join(times) or 'none'}")
        name = match[0]
    if resolve_file(p / name / field) is None:
        raise ValueError(f"{os.fspath(p / name)}: no field file {field!r} in this time directory; "
                         f"times holding it: {', '.join(times) or 'none'}")
    return name


def _as_vectors(value: Any, n: int, cur: Cursor, what: str) -> np.ndarray:
    """`('uniform', (3,))` or `('nonuniform', (n, 3))` to an `(n, 3)` array."""
    if not (isinstance(value, tuple) and len(value) == 2 and value[0] in ("uniform", "nonuniform")):
        raise cur.error(f"{what}: expected 'uniform (x y z)' or 'nonuniform List<vector> N (...)'")
    try:
        arr = np.asarray(value[1], dtype=np.float64)
    except (TypeError, ValueError):
        raise cur.error(f"{what}: not a list of numbers: {str(value[1])[:60]}") from None
    if arr.size == 0 and n == 0:
        return np.zeros((0, 3))
    if value[0] == "uniform":
        if arr.shape != (3,):
            raise cur.error(f"{what}: uniform value must be a vector (x y z), got shape {arr.shape}")
        return np.broadcast_to(arr, (n, 3))
    if arr.shape != (n, 3):
        raise cur.error(f"{what}: expected {n} vectors, found {arr.shape[0] if arr.ndim else 0}"
                        + ("" if arr.ndim == 2 and arr.shape[1] == 3 else " (not a vector field?)"))
    return arr


def _read_vector_field(path: Path, mesh: PolyMesh) -> tuple[np.ndarray, BoundaryValues]:
    cur = open_file(path)
    internal = None
    boundary: dict[str, Any] | None = None
    bpos = 0
    while not cur.at_end():
        pos = cur.pos
        key = cur.token()
        if key == b"internalField":
            internal = _as_vectors(cur.read_value(), mesh.n_cells, cur, "internalField")
        elif key == b"boundaryField":
            bpos = cur.pos
            boundary = cur.read_dict()
        elif key in (b"{", b"}", b"(", b")", b";"):
            raise cur.error(f"unexpected {key.decode()!r} at the top level", pos)
        elif cur.peek() == b"{":
            cur.read_dict()
        else:
            cur.read_value()
    if internal is None:
        raise file_error(cur.path, None, "no internalField entry")
    values: dict[str, np.ndarray | str] = {}
    for name, ptype, _start, n in mesh.patches:
        entry = _patch_entry(boundary or {}, name, ptype)
        if entry is None:
            raise file_error(cur.path, cur.line(bpos) if boundary is not None else None,
                             f"boundaryField has no entry for patch {name!r}")
        btype = str(entry.get("type", ""))
        if btype == "noSlip":  # fixed zero velocity; OpenFOAM writes no `value` for it
            values[name] = np.zeros((n, 3))
        elif "value" in entry and btype not in _SLIP_TYPES:
            values[name] = _as_vectors(entry["value"], n, cur, f"boundaryField {name} value")
        elif btype in _SLIP_TYPES:
            values[name] = "slip"
        else:
            values[name] = "cell"
    return np.ascontiguousarray(internal), BoundaryValues(values)


def _patch_entry(boundary: dict[str, Any], name: str, ptype: str) -> dict[str, Any] | None:
    if name in boundary and isinstance(boundary[name], dict):
        return boundary[name]
    for key, val in boundary.items():  # regular-expression keys ("(inlet|outlet)", ".*")
        if isinstance(val, dict) and (key.startswith('"') or any(c in key for c in "|*.()")):
            try:
                if re.fullmatch(key.strip('"'), name) and isinstance(val, dict):
                    return val
            except re.error:
                continue
    if ptype in ("empty", "processor", "cyclic", "symmetryPlane", "symmetry", "wedge"):
        return {"type": ptype}
    return None


@dataclasses.dataclass(frozen=True, eq=False)
class OpenFOAMField:
    """A case's mesh and one vector field at one time, ready for cellPoint sampling.

    - `case`: the case directory; `time`: the time directory used; `field`: e.g. `"U"`.
    - `mesh`: the `polyMesh`; `cell_values (n_cells, 3)`: the field at cell centres (m/s);
    - `boundary`: boundary face values per patch.
    """

    case: Path
    time: str
    field: str
    mesh: PolyMesh
    cell_values: np.ndarray
    boundary: BoundaryValues

    def sampler(self, cells: np.ndarray | None = None) -> CellPointSampler:
        """The cellPoint interpolant over `cells` (global numbers; default every cell)."""
        if cells is None:
            cells = np.arange(self.mesh.n_cells)
        return build_sampler(self.mesh, self.cell_values, self.boundary, np.asarray(cells, np.int64),
                             self.bounds)

    def cells_in_box(self, lo: Any, hi: Any) -> np.ndarray:
        """Global numbers of the cells whose bounding boxes overlap the box `[lo, hi]` (m)."""
        clo, chi = self.bounds
        lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        return np.flatnonzero(((chi >= lo) & (clo <= hi)).all(axis=1))

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounding boxes `(lo, hi)` of every cell, `(n_cells, 3)` each (computed once)."""
        cached = self.__dict__.get("_bounds")
        if cached is None:
            cached = cell_bounds(self.mesh)
            object.__setattr__(self, "_bounds", cached)
        return cached


def read_openfoam_field(case: PathLike, *, field: str = "U", time: Any = None) -> OpenFOAMField:
    """Read a case's mesh and the vector `field` (default `U`) at `time`.

    **Arguments:**

    - `case`: the case directory (plain or decomposed), its `system/controlDict`, a
      `case.foam` file in it, or one of its time directories (`CASE/400`: that time).
    - `field`: the volVectorField's file name.
    - `time`: a time (number) or time-directory name; default the time directory `case`
      names, else the latest holding `field`.

    Raises `ValueError` naming the file (and line) for a missing field, no time directory,
    a corrupt or truncated file, or a decomposed case without `decomposePar`'s addressing.
    A decomposed case (`processor*/` only) is merged into the undecomposed mesh.
    """
    p = _case_dir(case)
    if time is None:
        time = case_and_time(case)[1]
    if _is_decomposed(p):
        for what in ("pointProcAddressing", "faceProcAddressing", "cellProcAddressing"):
            if resolve_file(p / "processor0" / "constant" / "polyMesh" / what) is None:
                _read_labels(p / "processor0" / "constant" / "polyMesh" / what, what)  # raises
    name = _pick_time(p, field, time)
    if _is_decomposed(p):
        mesh, values, boundary = _read_decomposed(p, name, field)
    else:
        mesh = read_openfoam_mesh(p)
        values, boundary = _read_vector_field(p / name / field, mesh)
    return OpenFOAMField(case=p, time=name, field=field, mesh=mesh, cell_values=values,
                         boundary=boundary)


def sample_openfoam(
    case: PathLike | OpenFOAMField,
    points: Float[np.ndarray, "n 3"],
    *,
    field: str = "U",
    time: Any = None,
) -> Float[np.ndarray, "n 3"]:
    """The field at arbitrary points by OpenFOAM's cellPoint interpolation (what `probes`
    with `interpolationScheme cellPoint` reports). NaN for points in no cell.

    **Arguments:** `case` (a directory or an `OpenFOAMField` already read), `points (n, 3)`
    CFD metres; `field`, `time` as `read_openfoam_field`.

    **Returns:** `(n, 3)` float64, m/s in the CFD frame.
    """
    f = case if isinstance(case, OpenFOAMField) else read_openfoam_field(case, field=field, time=time)
    q = np.asarray(points, np.float64).reshape(-1, 3)
    if q.size == 0:
        return np.zeros((0, 3))
    lo, hi = q.min(axis=0), q.max(axis=0)
    cells = f.cells_in_box(lo, hi)
    if cells.size == 0:
        return np.full(q.shape, np.nan)
    return f.sampler(cells).sample_points(q)


# ---------------------------------------------------------------------------------------
# resampling onto a regular (tensor) grid


def _axis_nodes(lo: float, hi: float, c_lo: np.ndarray, c_hi: np.ndarray, r: float) -> np.ndarray:
    """Nodes from `lo` to `hi` whose local spacing is at most (cell width / r) of every
    cell spanning that coordinate (`c_lo`, `c_hi`: the cells' extents on this axis)."""
    width = np.maximum(c_hi - c_lo, 1e-9)
    h_cell = width / r
    h_max = float(h_cell.max())
    level = np.ceil(np.log2(h_max / h_cell) - 1e-9).astype(np.int64)
    level = np.clip(level, 0, 40)
    h_fine = h_max / 2.0 ** int(level.max())
    n_bins = int(math.ceil((hi - lo) / h_fine)) + 1
    if n_bins > 50_000_000:
        raise ValueError("the cells here are too small for an automatic grid; give `spacing`")
    bins_lo = np.clip(np.floor((c_lo - lo) / h_fine).astype(np.int64), 0, n_bins)
    bins_hi = np.clip(np.ceil((c_hi - lo) / h_fine).astype(np.int64) + 1, 0, n_bins)
    need = np.zeros(n_bins, np.int64)  # finest level covering each bin
    for k in np.unique(level):
        sel = level == k
        diff = np.zeros(n_bins + 1, np.int64)
        np.add.at(diff, bins_lo[sel], 1)
        np.add.at(diff, bins_hi[sel], -1)
        covered = np.cumsum(diff[:-1]) > 0
        need[covered] = np.maximum(need[covered], k)
    h_bin = h_max / 2.0 ** need
    nodes = [lo]
    s = lo
    while s < hi - 1e-9 * (hi - lo):
        b = min(int((s - lo) / h_fine), n_bins - 1)
        h = float(h_bin[b])
        # the finest requirement over the step
        b2 = min(int((s + h - lo) / h_fine) + 1, n_bins)
        h = float(h_bin[b:b2].min()) if b2 > b else h
        s = min(s + h, hi) if hi - (s + h) > 0.25 * h else hi
        nodes.append(s)
    return np.asarray(nodes)


def resample_openfoam(
    of: OpenFOAMField,
    region: tuple[Any, Any] | None,
    spacing: float | Sequence[float] | None = None,
    *,
    resolution: float = DEFAULT_RESOLUTION,
    max_nodes: int = DEFAULT_MAX_NODES,
    check_points: int = 2000,
    seed: int = 0,
) -> tuple[list[np.ndarray], np.ndarray, dict[str, Any]]:
    """Resample the cellPoint interpolant of `of` onto a tensor grid covering `region`.

    **Arguments:**

    - `region`: `(lo, hi)` CFD metres (e.g. `lidarjax.scan_bounds(...)`), or None for the
      whole mesh. The grid reaches one node beyond it on every side where the mesh does.
    - `spacing`: metres (scalar or per axis) for a uniform grid; default automatic: per
      axis, nodes `resolution` per cell width of the finest cell spanning each coordinate
      (a graded grid, fine only where the cells are fine).
    - `max_nodes`: the automatic grid is coarsened (with a warning) beyond this.
    - `check_points`: random points in the region where the grid's trilinear values are
      compared with the cellPoint values (the resampling error reported).

    **Returns:** `(axes, velocity (nx, ny, nz, 3), info)`; NaN nodes are in no cell.
    """
    axes, velocity, info, _ = resample_with_sampler(
        of, region, spacing, resolution=resolution, max_nodes=max_nodes,
        check_points=check_points, seed=seed)
    return axes, velocity, info


def resample_with_sampler(of: OpenFOAMField, region, spacing=None, *, resolution=DEFAULT_RESOLUTION,
                          max_nodes=DEFAULT_MAX_NODES, check_points=2000, seed=0
                          ) -> tuple[list[np.ndarray], np.ndarray, dict[str, Any], CellPointSampler]:
    """`resample_openfoam`, also returning the cellPoint sampler over the cells the grid
    covers (to prepare exact points there without building it twice:
    `lidarjax.io._exact.cellpoint_field`)."""
    mesh = of.mesh
    clo, chi = of.bounds
    if region is None:
        lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
    else:
        lo = np.asarray(region[0], np.float64).reshape(3)
        hi = np.asarray(region[1], np.float64).reshape(3)
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(hi >= lo)):
            raise ValueError(f"region must be (lo, hi) with finite lo <= hi (metres), got {region!r}")
    mlo, mhi = mesh.points.min(axis=0), mesh.points.max(axis=0)
    if np.any(hi < mlo) or np.any(lo > mhi):
        raise ValueError(
            f"{os.fspath(of.case)}: region {lo.tolist()} .. {hi.tolist()} lies outside the mesh "
            f"{mlo.tolist()} .. {mhi.tolist()}; are the region and the case in the same coordinates?")
    pad = np.maximum(1e-6 * np.maximum(np.abs(lo), np.abs(hi)), 1e-9)
    sel = np.flatnonzero(((chi >= lo - pad) & (clo <= hi + pad)).all(axis=1))
    if sel.size == 0:
        raise ValueError(f"{os.fspath(of.case)}: no cell overlaps the region")
    notes: list[str] = []
    if spacing is not None:
        s = np.broadcast_to(np.asarray(spacing, np.float64), (3,))
        if not np.all(np.isfinite(s)) or np.any(s <= 0):
            raise ValueError(f"spacing must be positive metres, got {spacing!r}")
        axes = []
        for a in range(3):
            n_lo = int(math.ceil((lo[a] - mlo[a]) / s[a] - 1e-9))
            start = lo[a] - min(1, max(n_lo, 0)) * s[a]
            n = int(math.floor((min(hi[a] + s[a], max(hi[a], mhi[a])) - start) / s[a] + 1e-9)) + 1
            axes.append(start + s[a] * np.arange(max(n, 2)))
        mode = "uniform"
    else:
        factor = 1.0
        while True:
            axes = []
            for a in range(3):
                ax = _axis_nodes(lo[a], hi[a], clo[sel, a], chi[sel, a], resolution / factor)
                if ax.size < 2:
                    ax = np.array([lo[a], hi[a] if hi[a] > lo[a] else lo[a] + 1e-3])
                # one more node beyond each end (inside the mesh) for trilinear margins
                h0, h1 = ax[1] - ax[0], ax[-1] - ax[-2]
                if ax[0] - h0 >= mlo[a] - 1e-9 * h0:
                    ax = np.concatenate([[ax[0] - h0], ax])
                if ax[-1] + h1 <= mhi[a] + 1e-9 * h1:
                    ax = np.concatenate([ax, [ax[-1] + h1]])
                axes.append(ax)
            n_nodes = int(np.prod([ax.size for ax in axes]))
            if n_nodes <= max_nodes:
                break
            factor *= (n_nodes / max_nodes) ** (1 / 3) * 1.05
        if factor > 1.0:
            msg = (f"the automatic grid was coarsened by {factor:.2f}x to stay within max_nodes="
                   f"{max_nodes} nodes: it resolves the finest cells here with "
                   f"{resolution / factor:.2f} instead of {resolution:g} nodes per cell width")
            notes.append(msg)
            warnings.warn(msg, stacklevel=3)
        mode = "graded"
    glo = np.array([ax[0] for ax in axes])
    ghi = np.array([ax[-1] for ax in axes])
    cells = np.flatnonzero(((chi >= glo - pad) & (clo <= ghi + pad)).all(axis=1))
    sampler = of.sampler(cells)
    velocity, n_tests = sampler.sample_grid(axes)
    info: dict[str, Any] = {"n_cells_total": mesh.n_cells, "n_cells_used": int(cells.size),
                            "grid": mode, "notes": notes, "point_in_tet_tests": n_tests}
    steps = [np.diff(ax) for ax in axes]
    info["spacing_min"] = tuple(float(s.min()) for s in steps)
    info["spacing_max"] = tuple(float(s.max()) for s in steps)
    # resampling error: trilinear on the grid against cellPoint at random points
    if check_points > 0:
        rng = np.random.default_rng(seed)
        q = lo + (hi - lo) * rng.random((check_points, 3))
        exact = sampler.sample_points(q)
        rgi = RegularGridInterpolator(tuple(axes), velocity, bounds_error=False, fill_value=np.nan)
        approx = rgi(q)
        ok = np.isfinite(exact).all(axis=1) & np.isfinite(approx).all(axis=1)
        err = np.linalg.norm(approx[ok] - exact[ok], axis=1)
        info["check_points"] = int(ok.sum())
        info["resample_error_rms"] = float(np.sqrt(np.mean(err ** 2))) if err.size else math.nan
        info["resample_error_max"] = float(err.max()) if err.size else math.nan
    return axes, velocity, info, sampler


# ---------------------------------------------------------------- decomposed cases


def _is_decomposed(p: Path) -> bool:
    return not (p / "constant" / "polyMesh").is_dir() and (p / "processor0" / "constant" / "polyMesh").is_dir()


def _processor_dirs(p: Path) -> list[Path]:
    procs = sorted((d for d in p.iterdir() if d.is_dir() and re.fullmatch(r"processor\d+", d.name)),
                   key=lambda d: int(d.name[9:]))
    if [int(d.name[9:]) for d in procs] != list(range(len(procs))):
        raise ValueError(f"{os.fspath(p)}: processor directories are not numbered 0..{len(procs) - 1}")
    return procs


def _read_labels(path: Path, what: str) -> np.ndarray:
    if resolve_file(path) is None:
        raise ValueError(
            f"{os.fspath(path)}: missing; a decomposed case is merged through decomposePar's "
            "*ProcAddressing files (a case meshed or run in parallel without them must be "
            "reconstructed: reconstructParMesh -constant && reconstructPar -latestTime)")
    return open_file(path).read_list(1, np.int64, what)


def _processor_meshes(p: Path):
    procs = _processor_dirs(p)
    meshes, addr = [], []
    for d in procs:
        m = read_openfoam_mesh(d)
        pm = d / "constant" / "polyMesh"
        pa = _read_labels(pm / "pointProcAddressing", "pointProcAddressing")
        fa = _read_labels(pm / "faceProcAddressing", "faceProcAddressing")
        ca = _read_labels(pm / "cellProcAddressing", "cellProcAddressing")
        if pa.size != m.points.shape[0] or fa.size != m.n_faces or ca.size != m.n_cells:
            raise ValueError(f"{os.fspath(pm)}: *ProcAddressing sizes ({pa.size}, {fa.size}, {ca.size}) "
                             f"do not match the processor mesh ({m.points.shape[0]} points, "
                             f"{m.n_faces} faces, {m.n_cells} cells)")
        meshes.append(m)
        addr.append((pa, fa, ca))
    return procs, meshes, addr


def _merge_meshes(p: Path, procs, meshes, addr):
    """The undecomposed mesh from the processor meshes and decomposePar's addressing.

    `faceProcAddressing` holds ``±(global face + 1)``: positive where the processor face has
    the global face's orientation, negative where it is flipped (the neighbour side of a
    processor patch). Every global face appears once with a positive sign; its points are
    taken from there. Global patches are the processors' non-processor patches (same names and
    order on every processor); their global face ranges follow from the addressing."""
    where = os.fspath(p)
    n_points = 1 + max(int(a[0].max(initial=-1)) for a in addr)
    n_cells = 1 + max(int(a[2].max(initial=-1)) for a in addr)
    n_faces = max(int(np.abs(a[1]).max(initial=0)) for a in addr)
    points = np.full((n_points, 3), np.nan)
    owner = np.full(n_faces, -1, np.int64)
    neighbour_all = np.full(n_faces, -1, np.int64)
    sizes = np.zeros(n_faces, np.int64)
    seen = np.zeros(n_faces, np.int64)
    global_patches: list[tuple[str, str]] = []
    patch_faces: dict[str, list[np.ndarray]] = {}
    for d, m, (pa, fa, ca) in zip(procs, meshes, addr, strict=True):
        points[pa] = m.points
        g = np.abs(fa) - 1
        pos = fa > 0
        lo = np.arange(m.n_faces)
        own_g = ca[m.owner]
        owner[g[pos]] = own_g[pos]
        neighbour_all[g[~pos]] = own_g[~pos]
        ni = m.n_internal
        nb_g = ca[m.neighbour]
        neighbour_all[g[:ni][pos[:ni]]] = nb_g[pos[:ni]]
        owner[g[:ni][~pos[:ni]]] = nb_g[~pos[:ni]]
        sizes[g[pos]] = m.face_offsets[lo[pos] + 1] - m.face_offsets[lo[pos]]
        np.add.at(seen, g[pos], 1)
        names = []
        for name, ptype, start, n in m.patches:
            if ptype in ("processor", "processorCyclic"):
                continue
            names.append((name, ptype))
            patch_faces.setdefault(name, []).append(g[start:start + n])
        if not global_patches:
            global_patches = names
        elif [n for n, _ in names] != [n for n, _ in global_patches]:
            raise ValueError(f"{os.fspath(d)}: its patches differ from processor0's")
    if np.isnan(points).any() or (seen != 1).any() or (owner < 0).any():
        raise ValueError(f"{where}: the processors' *ProcAddressing do not describe one mesh "
                         "(reconstruct it: reconstructParMesh -constant && reconstructPar -latestTime)")
    offsets = np.zeros(n_faces + 1, np.int64)
    np.cumsum(sizes, out=offsets[1:])
    labels = np.empty(offsets[-1], np.int64)
    for m, (pa, fa, _ca) in zip(meshes, addr, strict=True):
        lf = np.flatnonzero(fa > 0)
        s = m.face_offsets[lf + 1] - m.face_offsets[lf]
        k = np.arange(s.sum()) - np.repeat(np.cumsum(s) - s, s)
        labels[np.repeat(offsets[fa[lf] - 1], s) + k] = pa[m.face_labels[np.repeat(m.face_offsets[lf], s) + k]]
    patches = []
    n_internal = n_faces
    for name, ptype in global_patches:
        gf = np.concatenate(patch_faces[name]) if patch_faces[name] else np.zeros(0, np.int64)
        start = int(gf.min()) if gf.size else -1
        if gf.size and (int(gf.max()) - start + 1 != gf.size):
            raise ValueError(f"{where}: the faces of patch {name!r} are not contiguous in the merged mesh")
        patches.append([name, ptype, start, int(gf.size)])
        if gf.size:
            n_internal = min(n_internal, start)
    nxt = n_internal  # empty patches: place them where the next one starts, as OpenFOAM does
    for pt in patches:
        if pt[3] == 0:
            pt[2] = nxt
        nxt = pt[2] + pt[3]
    neighbour = neighbour_all[:n_internal]
    if (neighbour < 0).any() or (neighbour_all[n_internal:] >= 0).any():
        raise ValueError(f"{where}: inconsistent internal/boundary faces in the merged mesh")
    mesh = PolyMesh(points=points, face_offsets=offsets, face_labels=labels, owner=owner,
                    neighbour=neighbour, n_cells=n_cells,
                    patches=tuple((a, b, c, e) for a, b, c, e in patches))
    return mesh, patch_faces


def _decomposed_mesh(p: Path):
    """``(procs, meshes, addr, mesh)``: the processors, their meshes and addressing, and the
    merged mesh (read once for a sequence of snapshots: `_read_decomposed`'s `merged`)."""
    procs, meshes, addr = _processor_meshes(p)
    return procs, meshes, addr, _merge_meshes(p, procs, meshes, addr)[0]


def _read_decomposed(p: Path, time: str, field: str, merged=None):
    procs, meshes, addr, mesh = _decomposed_mesh(p) if merged is None else merged
    values = np.full((mesh.n_cells, 3), np.nan)
    bvals: dict[str, Any] = {}
    starts = {name: (start, n) for name, _t, start, n in mesh.patches}
    for d, m, (_pa, fa, ca) in zip(procs, meshes, addr, strict=True):
        path = d / time / field
        if resolve_file(path) is None:
            raise ValueError(f"{os.fspath(path)}: missing (every processor needs the time {time!r})")
        internal, bv = _read_vector_field(path, m)
        values[ca] = internal
        for (name, ptype, start, n) in m.patches:
            if ptype in ("processor", "processorCyclic") or name not in starts:
                continue
            v = bv.values[name]
            gstart, gn = starts[name]
            if isinstance(v, str):
                bvals.setdefault(name, v)
                continue
            cur = bvals.get(name)
            if not isinstance(cur, np.ndarray):
                cur = bvals[name] = np.full((gn, 3), np.nan)
            cur[(np.abs(fa[start:start + n]) - 1) - gstart] = v
    for name, _t, _s, _n in mesh.patches:
        v = bvals.get(name, "cell")
        if isinstance(v, np.ndarray) and np.isnan(v).any():
            raise ValueError(f"{os.fspath(p)}: patch {name!r} of {field!r} has values on some processors only")
        bvals[name] = v
    if np.isnan(values).any():
        raise ValueError(f"{os.fspath(p)}: the processors' {field!r} do not cover every cell")
    return mesh, values, BoundaryValues(bvals)
