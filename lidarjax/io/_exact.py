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

from ..beam import simulate_points
from ..field import AbstractField, GridField, IndexedPoints, PointIndex, SnapshotField, _lerp_in_time
from ._cells import CellPointSampler

__all__ = ["CellPointField", "CellPointSnapshots", "cellpoint_field", "simulate_points"]



class CellPointField(IndexedPoints, AbstractField):
    """A graded `GridField` made exact at prepared points by the mesh's own cellPoint tets.

    **Arguments:**

    - `grid`: the `GridField` resampled from the mesh (its `origin` and `resolution` are this
      field's; it answers every query that is not a prepared point).
    - `points`: ``(n, 3)`` the prepared points, absolute CFD metres (e.g. `simulate_points`
      of the mount to be simulated).
    - `vertices`: ``(n, 4, 3)`` absolute CFD metres: the cellPoint tetrahedron holding each
      point (cell centre, then three face points); NaN rows for a point in no cell.
    - `values`: ``(n, 4, 3)`` m/s, CFD frame: the cell value and the three point values at
      those vertices; NaN rows for a point in no cell. Stored in the grid's dtype.
    - `tolerance`: how far (metres) a query may lie from a prepared point and still be
      answered from its tetrahedron; default ``1e-9`` (float64) or ``2e-5`` (float32) times
      the largest distance of a point from the origin (at least that times one metre), which
      covers the rounding of `simulate`'s own points in the grid's dtype.

    `sample_local` at a query within `tolerance` of a prepared point returns the barycentric
    mix of that tetrahedron's vertex values at the query (the tetrahedron found by nearest
    point, its index under `stop_gradient`): exact cellPoint there, NaN where the point is in
    no cell (a solid, as OpenFOAM's "Not Found"), differentiable in `values` and in the query
    position (the barycentric coordinates). Any other query: the grid's trilinear value.
    The lookup is a `lidarjax.field.PointIndex` (O(log n) per query).
    """

    grid: GridField
    origin: Float[Array, 3]
    origin_lo: Float[Array, 3]
    index: PointIndex
    anchor: Float[Array, "n 3"]
    inverse: Float[Array, "n 3 3"]
    values: Float[Array, "n 4 3"]
    found: Bool[Array, " n"]

    def __init__(self, grid: GridField, points: Any, vertices: Any, values: Any, *,
                 tolerance: float | None = None):
        if not isinstance(grid, GridField):
            raise ValueError(f"CellPointField: `grid` must be a lidarjax.GridField, got {type(grid).__name__}")
        pts = np.asarray(points, np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] == 0 or not np.isfinite(pts).all():
            raise ValueError(f"CellPointField: `points` must be finite (n, 3) CFD metres, n >= 1; "
                             f"got shape {pts.shape}")
        n = pts.shape[0]
        vert = np.asarray(vertices, np.float64)
        val = np.asarray(values, np.float64)
        for name, a in (("vertices", vert), ("values", val)):
            if a.shape != (n, 4, 3):
                raise ValueError(f"CellPointField: `{name}` must have shape ({n}, 4, 3), got {a.shape}")
        dtype = grid.dtype
        self.grid = grid
        self.origin, self.origin_lo = grid.origin, grid.origin_lo
        o64 = np.asarray(grid.origin, np.float64) + np.asarray(grid.origin_lo, np.float64)
        local = (pts - o64).astype(dtype)
        stored = o64 + local.astype(np.float64)  # the points as kept, rounded to the dtype
        # barycentric coordinates relative to each point: lam(1..3) = inverse @ (q - p - anchor)
        found = np.isfinite(vert).all(axis=(1, 2)) & np.isfinite(val).all(axis=(1, 2))
        rel = np.where(found[:, None, None], vert - stored[:, None, :], 0.0)
        edges = np.stack([rel[:, k] - rel[:, 0] for k in (1, 2, 3)], axis=2)  # columns
        det = np.linalg.det(edges)
        scale = np.max(np.abs(edges), axis=(1, 2)) ** 3
        found &= np.abs(det) > 1e-12 * np.maximum(scale, 1e-300)
        inv = np.zeros_like(edges)
        if found.any():
            inv[found] = np.linalg.inv(edges[found])
        self.index = PointIndex.build(pts - o64, dtype, tolerance, caller="CellPointField")
        self.anchor = jnp.asarray(np.where(found[:, None], rel[:, 0], 0.0).astype(dtype))
        self.inverse = jnp.asarray(inv.astype(dtype))
        self.values = jnp.asarray(np.where(found[:, None, None], val, 0.0).astype(dtype))
        self.found = jnp.asarray(found)

    @property
    def resolution(self) -> float | None:
        """The grid's resolution (m): probe nodes are chosen for it, as for the grid alone."""
        return self.grid.resolution

    def spacing_at(self, points):
        """The grid's spacing at `points` (`GridField.spacing_at`)."""
        return self.grid.spacing_at(points)

    @property
    def nbytes(self) -> int:
        """Bytes held by the grid and the prepared tetrahedra."""
        extra = sum(int(a.size * a.dtype.itemsize) for a in (
            self.index.points, self.anchor, self.inverse, self.values, self.index.projection,
            self.index.order))
        return self.grid.nbytes + extra

    def _match(self, points):
        """Index of the nearest prepared point `(...)` and whether it is within tolerance."""
        return self.index.match(points)

    def sample_local(self, points: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
        """Velocity (m/s, CFD frame) at points relative to `origin` (metres): cellPoint at the
        prepared points (NaN there in no cell), the grid's trilinear value elsewhere."""
        points = jnp.asarray(points).astype(self.dtype)
        best, hit, lam = _barycentric(self, points)
        exact = jnp.sum(lam[..., None] * self.values[best], axis=-2)
        found = self.found[best]
        exact = jnp.where(found[..., None], exact, jnp.nan)  # values are finite: NaN put in last
        return jnp.where(hit[..., None], exact, self.grid.sample_local(points))


def _barycentric(field, points):
    """``(best, hit, lam)``: the prepared point nearest each query (index under
    `stop_gradient`), whether it is within tolerance, and the query's barycentric coordinates
    ``(..., 4)`` (cell centre, base, A, B) in that point's tetrahedron: differentiable in the
    query position."""
    best, hit = field.index.match(jax.lax.stop_gradient(points))
    d = points - field.index.points[best] - field.anchor[best]
    lam = jnp.sum(field.inverse[best] * d[..., None, :], axis=-1)
    lam = jnp.concatenate([1 - jnp.sum(lam, axis=-1, keepdims=True), lam], axis=-1)
    return best, hit, lam


class CellPointSnapshots(AbstractField):
    """Snapshots of an unsteady mesh run, exact (the mesh's cellPoint) at prepared points:
    the time-dependent `CellPointField` (`lidarjax.io.load_field_sequence` with `exact_at`).

    At a query within tolerance of a prepared point, each snapshot's value is the barycentric
    mix in that point's cellPoint tetrahedron (the same tetrahedra for every snapshot: the
    geometry is prepared once, only the vertex values change), linear in time between
    consecutive snapshots, NaN outside their span (as `lidarjax.SnapshotField`), in no cell,
    or where a snapshot's values there are not finite. Any other query: the graded grid's
    snapshots (`grid`, a `SnapshotField`; a sequence read with ``grid_fallback=False``
    holds a NaN grid of two nodes per axis there, so any other query is NaN, flagged, and
    `resolution` is the graded grid's all the same). Differentiable in the vertex values,
    the query position (barycentric coordinates) and the time.

    **Arguments:**

    - `grid`: the graded grid's snapshots (`lidarjax.SnapshotField`, times in seconds).
    - `geometry`: a `CellPointField` of the prepared points (absolute CFD metres): its index,
      tetrahedra and tolerance are shared by every snapshot (its own values are not used).
    - `values`: ``(t, n, 4, 3)`` m/s, CFD frame: each snapshot's vertex values (cell
      centre, base, A, B) of each point's tetrahedron; non-finite rows are NaN queries.
    - `resolution`: metres, the graded grid's resolution where `grid` is a placeholder
      (``grid_fallback=False``); default `grid`'s.

    Built on the host, per window of a `lidarjax.FieldSequence`, by
    `lidarjax.io.load_field_sequence` with `exact_at`.
    """

    grid: SnapshotField
    origin: Float[Array, 3]
    origin_lo: Float[Array, 3]
    index: PointIndex
    anchor: Float[Array, "n 3"]
    inverse: Float[Array, "n 3 3"]
    values: Float[Array, "t n 4 3"]
    valid: Bool[Array, "t n"]
    grid_resolution: float | None = eqx.field(static=True)

    def __init__(self, grid: SnapshotField, geometry: CellPointField, values: Any, *,
                 resolution: float | None = None):
        if not isinstance(grid, SnapshotField) or not isinstance(geometry, CellPointField):
            raise ValueError("CellPointSnapshots: needs a SnapshotField and a CellPointField "
                             "(the prepared points' geometry)")
        val = np.asarray(values, np.float64)
        t, n = grid.n_snapshots, geometry.n_points
        if val.shape != (t, n, 4, 3):
            raise ValueError(f"CellPointSnapshots: `values` must have shape ({t}, {n}, 4, 3), "
                             f"got {val.shape}")
        valid = np.isfinite(val).all(axis=(2, 3)) & np.asarray(geometry.found)[None]
        self.grid = grid
        self.origin, self.origin_lo = grid.origin, grid.origin_lo
        self.index, self.anchor, self.inverse = geometry.index, geometry.anchor, geometry.inverse
        self.values = jnp.asarray(np.where(valid[..., None, None], val, 0.0).astype(grid.dtype))
        self.valid = jnp.asarray(valid)
        self.grid_resolution = None if resolution is None else float(resolution)

    @property
    def resolution(self) -> float | None:
        """The graded grid's resolution (m): probe nodes are chosen for it (`resolution`
        where the window holds no grid, only the prepared points)."""
        return self.grid.resolution if self.grid_resolution is None else self.grid_resolution

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
        """Bytes held by the grid's snapshots and the prepared values."""
        return self.grid.nbytes + int(self.values.size * self.values.dtype.itemsize)

    def _exact(self, points, time):
        """Exact snapshot values at the bracketing snapshots, the time fraction, whether the
        exact value is defined, and which queries are prepared points."""
        best, hit, lam = _barycentric(self, points)
        i, s, inside = self.grid._locate(time)
        e0 = jnp.sum(lam[..., None] * self.values[i, best], axis=-2)
        e1 = jnp.sum(lam[..., None] * self.values[i + 1, best], axis=-2)
        # at a snapshot's own time only its values count (a bad neighbour does not spoil it)
        ok = inside & self.valid[i, best] & (self.valid[i + 1, best] | (s == 0))
        return e0, e1, s, ok, hit

    def sample_local(self, points: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
        """The first snapshot's velocity (m/s, CFD frame) at local points (metres)."""
        return self.sample_local_at(points, self.grid.times[0])

    def sample_local_at(self, points, time):
        """Velocity (m/s, CFD frame) at local points (metres) and times (s): cellPoint at the
        prepared points, the grid's snapshots elsewhere; linear in time."""
        points, time = self.grid._broadcast(points, time)
        e0, e1, s, ok, hit = self._exact(points, time)
        exact = _lerp_in_time(e0, e1, s[..., None], ok[..., None])
        return jnp.where(hit[..., None], exact, self.grid.sample_local_at(points, time))

    def los_local_at(self, points, directions, time):
        """Velocity along unit `directions` (m/s) at local points and times, as
        `sample_local_at`."""
        points, time = self.grid._broadcast(points, time)
        d = jnp.broadcast_to(jnp.asarray(directions).astype(self.dtype), points.shape)
        e0, e1, s, ok, hit = self._exact(points, time)
        exact = _lerp_in_time(jnp.sum(e0 * d, axis=-1), jnp.sum(e1 * d, axis=-1), s, ok)
        return jnp.where(hit, exact, self.grid.los_local_at(points, d, time))


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
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    if pts.shape[0] == 0 or not np.isfinite(pts).all():
        raise ValueError("cellpoint_field: `points` must be finite (n, 3) CFD metres, n >= 1")
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
