"""A mesh field that is exact at the points `simulate` will ask for: OpenFOAM's cellPoint there.

A CFD mesh is resampled onto a graded grid (`lidarjax.io.openfoam.resample_openfoam`) so
that `simulate` can sample it anywhere; trilinear interpolation on that grid differs from the
mesh's own cellPoint interpolation where the flow shears across a few cells (0.1 m/s of lidar
speed for a pulsed probe whose nodes sit in a roof's shear layer). The points `simulate`
samples are fixed by the scan, the mount, the heights and the probe, so they can be prepared
on the host: for each one, the cellPoint tetrahedron holding it (`lidarjax.io._cells`: the
cell centre and three face points, with the cell value and `volPointInterpolation`'s point
values). `CellPointField` then answers a query at one of those points with the barycentric
mix in its tetrahedron (exactly what OpenFOAM's `probes` with `interpolationScheme cellPoint`
report there) and any other query from the graded grid it wraps.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from .._precision import host_array
from .._util import compiled
from ..beam import simulate_points
from ..field import (
    AbstractField,
    GridField,
    IndexedPoints,
    OnGrid,
    PointIndex,
    SnapshotField,
    _lerp_in_time,
    axes_resolution,
    axes_spacing_at,
)
from ._cells import CellPointSampler

__all__ = ["CellPointField", "CellPointSnapshots", "CellPointTets", "cellpoint_field",
           "simulate_points"]


class CellPointTets(eqx.Module):
    """The geometry of prepared points: each one's cellPoint tetrahedron, as the barycentric
    weights of a query near it. Built once per mesh and point set; `CellPointField` (one
    field) and `CellPointSnapshots` (a sequence of snapshots) hold it with their own vertex
    values.

    **Arguments:**

    - `grid`: the field the points are relative to (its `origin`, `origin_lo` and dtype).
    - `points`: ``(n, 3)`` the prepared points, absolute CFD metres.
    - `vertices`: ``(n, 4, 3)`` absolute CFD metres: the cellPoint tetrahedron holding each
      point (cell centre, then three face points); NaN rows for a point in no cell.
    - `tolerance`: how far (metres) a query may lie from a prepared point and still be
      answered from its tetrahedron; default ``1e-9`` (float64) or ``2e-5`` (float32) times
      the largest distance of a point from the origin (at least that times one metre), which
      covers the rounding of `simulate`'s own points in the grid's dtype.

    Fields: `index` (a `lidarjax.field.PointIndex` of the points relative to `origin`,
    O(log n) per query), `anchor` ``(n, 3)`` (the tetrahedron's cell centre relative to its
    point), `inverse` ``(n, 3, 3)`` (the inverse edge matrix) and `found` ``(n,)`` (the point
    lies in a cell whose tetrahedron is not degenerate).
    """

    origin: Float[Array, 3]
    origin_lo: Float[Array, 3]
    index: PointIndex
    anchor: Float[Array, "n 3"]
    inverse: Float[Array, "n 3 3"]
    found: Bool[Array, " n"]

    def __init__(self, grid: AbstractField, points: Any, vertices: Any, *,
                 tolerance: float | None = None, caller: str = "CellPointTets"):
        pts = np.asarray(points, np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] == 0 or not np.isfinite(pts).all():
            raise ValueError(f"{caller}: `points` must be finite (n, 3) CFD metres, n >= 1; "
                             f"got shape {pts.shape}")
        n = pts.shape[0]
        vert = np.asarray(vertices, np.float64)
        if vert.shape != (n, 4, 3):
            raise ValueError(f"{caller}: `vertices` must have shape ({n}, 4, 3), got {vert.shape}")
        dtype = grid.dtype
        self.origin, self.origin_lo = grid.origin, grid.origin_lo
        o64 = np.asarray(grid.origin, np.float64) + np.asarray(grid.origin_lo, np.float64)
        local = (pts - o64).astype(dtype)
        stored = o64 + local.astype(np.float64)  # the points as kept, rounded to the dtype
        # barycentric coordinates relative to each point: lam(1..3) = inverse @ (q - p - anchor)
        found = np.isfinite(vert).all(axis=(1, 2))
        rel = np.where(found[:, None, None], vert - stored[:, None, :], 0.0)
        edges = np.stack([rel[:, k] - rel[:, 0] for k in (1, 2, 3)], axis=2)  # columns
        det = np.linalg.det(edges)
        scale = np.max(np.abs(edges), axis=(1, 2)) ** 3
        found &= np.abs(det) > 1e-12 * np.maximum(scale, 1e-300)
        inv = np.zeros_like(edges)
        if found.any():
            inv[found] = np.linalg.inv(edges[found])
        self.index = PointIndex.build(pts - o64, dtype, tolerance, caller=caller)
        self.anchor, self.inverse, self.found = host_array(
            (np.where(found[:, None], rel[:, 0], 0.0).astype(dtype), inv.astype(dtype), found))

    @property
    def n_points(self) -> int:
        return self.index.n_points

    @property
    def nbytes(self) -> int:
        """Bytes held by the index and the tetrahedra."""
        return sum(int(a.size * a.dtype.itemsize) for a in (
            self.index.points, self.index.projection, self.index.order, self.anchor,
            self.inverse, self.found))

    def check_grid(self, grid: AbstractField, caller: str) -> CellPointTets:
        """Itself, if built for a grid of `grid`'s origin and dtype (else a ValueError)."""
        same = (grid.dtype == self.anchor.dtype and np.array_equal(
            np.asarray(grid.origin), np.asarray(self.origin)) and np.array_equal(
            np.asarray(grid.origin_lo), np.asarray(self.origin_lo)))
        if not same:
            raise ValueError(f"{caller}: the prepared points' CellPointTets were built for "
                             f"another grid (origin or dtype differ); build them for this one")
        return self

    def check_values(self, values: Any, lead: tuple[int, ...], caller: str):
        """``(values, valid)``: vertex values ``(*lead, n, 4, 3)`` (m/s, CFD frame) in the
        grid's dtype with their non-finite rows and points in no cell zeroed, and ``(*lead,
        n)`` where they are defined (a one-line ValueError naming `caller` for a bad shape)."""
        val = np.asarray(values, np.float64)
        shape = (*lead, self.n_points, 4, 3)
        if val.shape != shape:
            raise ValueError(f"{caller}: `values` must have shape {shape}, got {val.shape}")
        valid = np.isfinite(val).all(axis=(-2, -1)) & np.asarray(self.found)
        return host_array((np.where(valid[..., None, None], val, 0.0).astype(self.anchor.dtype),
                           valid))

    def weights(self, points: Float[Array, "... 3"]):
        """``(best, hit, lam)``: the prepared point nearest each query (local metres; its
        index under `stop_gradient`), whether it is within tolerance, and the query's
        barycentric coordinates ``(..., 4)`` (cell centre, base, A, B) in that point's
        tetrahedron: differentiable in the query position."""
        best, hit = self.index.match(jax.lax.stop_gradient(points))
        d = points - self.index.points[best] - self.anchor[best]
        lam = jnp.sum(self.inverse[best] * d[..., None, :], axis=-1)
        lam = jnp.concatenate([1 - jnp.sum(lam, axis=-1, keepdims=True), lam], axis=-1)
        return best, hit, lam


class _Prepared(IndexedPoints):
    """The accessors of a field holding a `CellPointTets` as `tets`."""

    @property
    def index(self) -> PointIndex:
        return self.tets.index


class CellPointField(OnGrid, _Prepared, AbstractField):
    """A graded `GridField` made exact at prepared points by the mesh's own cellPoint tets.

    **Arguments:**

    - `grid`: the `GridField` resampled from the mesh (its `origin` and `resolution` are this
      field's; it answers every query that is not a prepared point).
    - `points`: ``(n, 3)`` the prepared points, absolute CFD metres (e.g. `simulate_points`
      of the mount to be simulated), or their geometry already built (a `CellPointTets` for
      `grid`; then `vertices` is None).
    - `vertices`: ``(n, 4, 3)`` absolute CFD metres: the cellPoint tetrahedron holding each
      point (cell centre, then three face points); NaN rows for a point in no cell.
    - `values`: ``(n, 4, 3)`` m/s, CFD frame: the cell value and the three point values at
      those vertices; NaN rows for a point in no cell. Stored in the grid's dtype.
    - `tolerance`: see `CellPointTets`.

    `sample_local` at a query within `tolerance` of a prepared point returns the barycentric
    mix of that tetrahedron's vertex values at the query (the tetrahedron found by nearest
    point, its index under `stop_gradient`; `CellPointTets.weights`): exact cellPoint there,
    NaN where the point is in no cell (a solid, as OpenFOAM's "Not Found"), differentiable
    in `values` and in the query position (the barycentric coordinates). Any other query:
    the grid's trilinear value.
    """

    grid: GridField
    origin: Float[Array, 3]
    origin_lo: Float[Array, 3]
    tets: CellPointTets
    values: Float[Array, "n 4 3"]
    found: Bool[Array, " n"]  # in a cell, with finite values

    def __init__(self, grid: GridField, points: Any, vertices: Any, values: Any, *,
                 tolerance: float | None = None):
        if not isinstance(grid, GridField):
            raise ValueError(f"CellPointField: `grid` must be a lidarjax.GridField, got {type(grid).__name__}")
        if isinstance(points, CellPointTets):
            tets = points.check_grid(grid, "CellPointField")
        else:
            tets = CellPointTets(grid, points, vertices, tolerance=tolerance, caller="CellPointField")
        self.grid, self.tets = grid, tets
        self.origin, self.origin_lo = grid.origin, grid.origin_lo
        self.values, self.found = tets.check_values(values, (), "CellPointField")

    @property
    def nbytes(self) -> int:
        """Bytes held by the grid, the prepared tetrahedra and their values."""
        return self.grid.nbytes + self.tets.nbytes + int(self.values.size * self.values.dtype.itemsize)

    def _match(self, points):
        """Index of the nearest prepared point `(...)` and whether it is within tolerance."""
        return self.index.match(points)

    @compiled  # one program from the host (inlined inside a trace)
    def sample_local(self, points: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
        """Velocity (m/s, CFD frame) at points relative to `origin` (metres): cellPoint at the
        prepared points (NaN there in no cell), the grid's trilinear value elsewhere."""
        points = jnp.asarray(points).astype(self.dtype)
        best, hit, lam = self.tets.weights(points)
        exact = jnp.sum(lam[..., None] * self.values[best], axis=-2)
        exact = jnp.where(self.found[best][..., None], exact, jnp.nan)  # NaN put in last
        return jnp.where(hit[..., None], exact, self.grid.sample_local(points))


class CellPointSnapshots(_Prepared, AbstractField):
    """Snapshots of an unsteady mesh run, exact (the mesh's cellPoint) at prepared points:
    the time-dependent `CellPointField` (`lidarjax.io.load_field_sequence` with `exact_at`).

    At a query within tolerance of a prepared point, each snapshot's value is the barycentric
    mix in that point's cellPoint tetrahedron (the same `CellPointTets` for every snapshot:
    the geometry is prepared once, only the vertex values change), linear in time between
    consecutive snapshots, NaN outside their span (as `lidarjax.SnapshotField`), in no cell,
    or where a snapshot's values there are not finite. Any other query: the graded grid's
    snapshots (`grid`, a `SnapshotField`; a sequence read with ``grid_fallback=False``
    holds a NaN grid of two nodes per axis there, so any other query is NaN, flagged, and
    `resolution` and `spacing_at` are the graded grid's all the same: `axes`).
    Differentiable in the vertex values, the query position (barycentric coordinates) and
    the time.

    **Arguments:**

    - `grid`: the graded grid's snapshots (`lidarjax.SnapshotField`, times in seconds).
    - `tets`: the prepared points' `CellPointTets` (built for a grid of the same origin and
      dtype), shared by every snapshot and every window.
    - `values`: ``(t, n, 4, 3)`` m/s, CFD frame: each snapshot's vertex values (cell
      centre, base, A, B) of each point's tetrahedron; non-finite rows are NaN queries.
    - `axes`: the graded grid's axes (relative to `grid`'s origin, its dtype: a
      `GridField`'s ``(x_local, y_local, z_local)``) where `grid` is a placeholder
      (``grid_fallback=False``): `resolution` and `spacing_at` are theirs, so
      `lidarjax.probe_for_field` chooses the nodes it chose for the graded grid the points
      were prepared from. Default: `grid`'s.

    Built on the host, per window of a `lidarjax.FieldSequence`, by
    `lidarjax.io.load_field_sequence` with `exact_at`.
    """

    grid: SnapshotField
    origin: Float[Array, 3]
    origin_lo: Float[Array, 3]
    tets: CellPointTets
    values: Float[Array, "t n 4 3"]
    valid: Bool[Array, "t n"]
    axes: tuple[Array, Array, Array] | None

    def __init__(self, grid: SnapshotField, tets: CellPointTets, values: Any, *,
                 axes: Any = None):
        if not isinstance(grid, SnapshotField) or not isinstance(tets, CellPointTets):
            raise ValueError("CellPointSnapshots: needs a SnapshotField and a CellPointTets "
                             "(the prepared points' geometry)")
        self.grid, self.tets = grid, tets.check_grid(grid, "CellPointSnapshots")
        self.origin, self.origin_lo = grid.origin, grid.origin_lo
        self.values, self.valid = tets.check_values(values, (grid.n_snapshots,), "CellPointSnapshots")
        self.axes = None if axes is None else tuple(jnp.asarray(a) for a in axes)

    @property
    def resolution(self) -> float | None:
        """The graded grid's resolution (m): probe nodes are chosen for it (`axes`' where the
        window holds no grid, only the prepared points)."""
        return self.grid.resolution if self.axes is None else axes_resolution(self.axes)

    def spacing_at(self, points):
        """The graded grid's spacing at `points` (`GridField.spacing_at`; `axes`' where the
        window holds no grid)."""
        if self.axes is None:
            return self.grid.spacing_at(points)
        return axes_spacing_at(self.axes, self.origin, self.origin_lo, None, points)

    @property
    def time_span(self):
        return self.grid.time_span

    @property
    def times(self):
        """``(t,)`` snapshot times, s."""
        return self.grid.times

    @property
    def n_snapshots(self) -> int:
        return self.grid.n_snapshots

    @property
    def nbytes(self) -> int:
        """Bytes held by the grid's snapshots, the prepared tetrahedra and their values."""
        return self.grid.nbytes + self.tets.nbytes + int(self.values.size * self.values.dtype.itemsize)

    def _exact(self, points, time):
        """Exact snapshot values at the bracketing snapshots, the time fraction, whether the
        exact value is defined, and which queries are prepared points."""
        best, hit, lam = self.tets.weights(points)
        i, s, inside = self.grid._locate(time)
        e0 = jnp.sum(lam[..., None] * self.values[i, best], axis=-2)
        e1 = jnp.sum(lam[..., None] * self.values[i + 1, best], axis=-2)
        # at a snapshot's own time only its values count (a bad neighbour does not spoil it)
        ok = inside & self.valid[i, best] & (self.valid[i + 1, best] | (s == 0))
        return e0, e1, s, ok, hit

    def sample_local(self, points: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
        """The first snapshot's velocity (m/s, CFD frame) at local points (metres)."""
        return self.sample_local_at(points, self.grid.times[0])

    @compiled  # one program from the host (inlined inside a trace)
    def sample_local_at(self, points, time):
        """Velocity (m/s, CFD frame) at local points (metres) and times (s): cellPoint at the
        prepared points, the grid's snapshots elsewhere; linear in time."""
        points, time = self.grid._broadcast(points, time)
        e0, e1, s, ok, hit = self._exact(points, time)
        exact = _lerp_in_time(e0, e1, s[..., None], ok[..., None])
        return jnp.where(hit[..., None], exact, self.grid.sample_local_at(points, time))

    @compiled  # one program from the host (inlined inside a trace)
    def los_local_at(self, points, directions, time):
        """Velocity along unit `directions` (m/s) at local points and times, as
        `sample_local_at`."""
        points, time = self.grid._broadcast(points, time)
        d = jnp.broadcast_to(jnp.asarray(directions).astype(self.dtype), points.shape)
        e0, e1, s, ok, hit = self._exact(points, time)
        exact = _lerp_in_time(jnp.sum(e0 * d, axis=-1), jnp.sum(e1 * d, axis=-1), s, ok)
        return jnp.where(hit, exact, self.grid.los_local_at(points, d, time))


def finite_points(points, what: str) -> np.ndarray:
    """`points` as finite ``(n, 3)`` float64 CFD metres, n >= 1, else a one-line ValueError
    naming `what` and the fix."""
    try:
        pts = np.asarray(points, np.float64).reshape(-1, 3)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be (n, 3) CFD metres (or a function of the first "
                         f"snapshot's GridField returning them)") from None
    if pts.shape[0] == 0:
        raise ValueError(f"{what} must give finite (n, 3) CFD metres, n >= 1; got none")
    bad = ~np.isfinite(pts).all(axis=1)
    if bad.any():
        raise ValueError(f"{what}: {int(bad.sum())} of {pts.shape[0]} points are not finite "
                         f"(first: row {int(np.argmax(bad))}); give finite CFD metres (drop "
                         f"or fix those rows)")
    return pts


def cellpoint_field(
    source: Any,
    grid: GridField,
    points: Float[ArrayLike, "n 3"],
    *,
    tolerance: float | None = None,
) -> CellPointField:
    """`grid` made exact (OpenFOAM's cellPoint) at `points`.

    **Arguments:**

    - `source`: the mesh field (`lidarjax.io.read_openfoam_field`, a VTK mesh from
      `lidarjax.io.vtk.read_vtk_field`) or a `CellPointSampler` built from it over cells that
      hold the points.
    - `grid`: the `GridField` resampled from it (`resample_openfoam`), answering every other
      query.
    - `points`: ``(n, 3)`` absolute CFD metres: the points `simulate` will sample, e.g.
      ``lidarjax.beam_points(grid, scan, mount, heights, probe)`` (several mounts: their
      points stacked).
    - `tolerance`: see `CellPointField`.

    **Returns:** a `CellPointField`.
    """
    pts = finite_points(points, "cellpoint_field: `points`")
    if isinstance(source, CellPointSampler):
        sampler = source
    else:
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        pad = 1e-6 * np.maximum(1.0, np.abs(np.concatenate([lo, hi])).max())
        sampler = source.sampler(source.cells_in_box(lo - pad, hi + pad))
    tets, _ = sampler.locate(pts)
    found = tets >= 0
    vertices = np.full((pts.shape[0], 4, 3), np.nan)
    values = np.full((pts.shape[0], 4, 3), np.nan)
    if found.any():
        vertices[found], values[found] = sampler.tet_vertices(tets[found])
    return CellPointField(grid, pts, vertices, values, tolerance=tolerance)
