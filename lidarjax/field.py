"""Velocity fields: the abstract interface and the gridded CFD field with trilinear sampling.

Every field (a `GridField` or an analytic scene from `lidarjax.scenes`) is an
`equinox.Module` with

- ``origin`` / ``origin_lo``: a reference point in CFD coordinates (metres), stored as a
  high part in the working dtype plus its rounding residual (see `lidarjax._precision`);
- ``sample_local(points)``: velocities (m/s, CFD frame) at points given *relative to the
  origin*; this is what the forward model calls, so float32 stays accurate at UTM-sized
  coordinates;
- ``sample(points)``: the same at absolute CFD points;
- ``los_local(points, directions)``: the velocity projected on unit vectors (m/s).

Points outside the field's domain, or inside a solid (NaN nodes, bodies in analytic scenes),
give NaN: never a clamped value. The NaN is put in by a final ``where`` over finite
intermediate values (the jax-md ``safe_mask`` pattern), so a loss that masks NaN results out
still has finite gradients with respect to the points, the directions and the field values.
A custom field should do the same: compute its values on safe (finite) stand-ins and insert
NaN last.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ._precision import default_float, difference, host_array, is_concrete, is_host, split
from ._util import compiled

__all__ = ["AbstractField", "GridField", "SnapshotField", "FieldSequence", "TimeSampler",
           "SteadySampler", "DirectSampler"]


class AbstractField(eqx.Module):
    """A velocity field in the CFD frame (m/s), sampled at points in metres.

    Subclasses define `origin`, `origin_lo` and `sample_local`.
    """

    origin: eqx.AbstractVar[Float[Array, 3]]
    origin_lo: eqx.AbstractVar[Float[Array, 3]]

    @property
    def dtype(self):
        """The working floating dtype of this field: results of `simulate` follow it."""
        return self.origin.dtype

    @property
    def resolution(self) -> float | None:
        """The field's smallest length scale (field length units): a grid's smallest node
        spacing, a turbulence box's, a scene's smallest feature; ``None`` where the field has
        none (uniform or linear flow) or it is not known on the host. Probe nodes are chosen
        for it (`lidarjax.probe_for_field`): content up to ``pi / resolution`` rad/m along
        the beam is integrated within 0.01 of the probe's transfer function."""
        return None

    def spacing_at(self, points: Float[ArrayLike, "n 3"]) -> np.ndarray | None:
        """The field's smallest length scale at each of `points` (absolute CFD metres, host):
        ``(n,)`` field length units, NaN outside the field; ``None`` where it is the same
        everywhere (`resolution`) or not known on the host. `lidarjax.probe_for_field`
        chooses each height's nodes from it along the beams' support."""
        return None

    @property
    def time_span(self) -> tuple[Float[Array, ""], Float[Array, ""]] | None:
        """``(first, last)`` time (s) at which the field is defined, or ``None`` where it is
        defined at every time (steady fields, frozen turbulence). Outside the span
        `sample_local_at` gives NaN and `lidarjax.simulate_series` flags
        `lidarjax.Flag.TIME_OUTSIDE`."""
        return None

    def sample_local(self, points: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
        """Velocity (m/s, CFD frame) at points relative to `origin` (metres). NaN outside."""
        raise NotImplementedError

    def sample(self, points: Float[ArrayLike, "... 3"]) -> Float[Array, "... 3"]:
        """Velocity (m/s, CFD frame) at absolute CFD points (metres). NaN outside.

        Host (numpy or list) points are made relative to the origin in float64 before they
        are rounded to the field's dtype, so a float32 field samples UTM-sized coordinates
        accurately; JAX arrays are subtracted in their own precision (float32 JAX points
        at UTM coordinates are already rounded to a 0.03-0.5 m grid: use `sample_local`)."""
        dtype = self.dtype
        if is_host(points) and is_concrete(self.origin, self.origin_lo):
            p64 = np.asarray(points, dtype=np.float64)
            o64 = np.asarray(self.origin, np.float64) + np.asarray(self.origin_lo, np.float64)
            return _sample_local(self, host_array((p64 - o64).astype(dtype)))
        points = jnp.asarray(points)
        if not jnp.issubdtype(points.dtype, jnp.floating):
            points = points.astype(dtype)
        return _sample_absolute(self, points)

    def los_local(
        self, points: Float[Array, "... 3"], directions: Float[Array, "... 3"]
    ) -> Float[Array, ...]:
        """Velocity at local points projected on unit `directions` (m/s, + along direction).

        NaN where the velocity is NaN, inserted after the projection so that the gradient
        with respect to `directions` stays finite there (a NaN times a zero cotangent would
        be NaN)."""
        v = self.sample_local(points)
        ok = jnp.all(jnp.isfinite(v), axis=-1)
        v = jnp.where(ok[..., None], v, 0.0)
        return jnp.where(ok, jnp.sum(v * directions, axis=-1), jnp.nan)

    def sample_local_at(
        self, points: Float[Array, "... 3"], time: Float[ArrayLike, ...]
    ) -> Float[Array, "... 3"]:
        """Velocity (m/s, CFD frame) at local points (metres, relative to `origin`) and
        times (seconds, broadcastable to ``points.shape[:-1]``). Time-dependent fields
        (frozen turbulence) define it; a steady field ignores `time`."""
        del time
        return self.sample_local(points)

    def los_local_at(
        self,
        points: Float[Array, "... 3"],
        directions: Float[Array, "... 3"],
        time: Float[ArrayLike, ...],
    ) -> Float[Array, ...]:
        """`los_local` at times (seconds): velocity at local points and times projected on
        unit `directions` (m/s, + along the direction); NaN as in `los_local`."""
        v = self.sample_local_at(points, time)
        ok = jnp.all(jnp.isfinite(v), axis=-1)
        v = jnp.where(ok[..., None], v, 0.0)
        return jnp.where(ok, jnp.sum(v * directions, axis=-1), jnp.nan)

    def time_sampler(
        self,
        points: Float[Array, "... 3"],
        directions: Float[Array, "... 3"] | None = None,
        *,
        n_times: int = 1,
    ) -> TimeSampler:
        """This field prepared for sampling the same local points (metres, relative to
        `origin`) at many times: ``sampler(time)`` equals ``sample_local_at(points, time)``
        (velocity, m/s, CFD frame, shape ``broadcast(time.shape, points.shape[:-1]) + (3,)``)
        or, with unit `directions` (broadcastable to `points`), ``los_local_at(points,
        directions, time)`` (m/s along the directions, that shape without the last axis).

        `n_times` (static) is how many times each point will be sampled by the compiled call;
        a field may use it to decide whether work per point pays (frozen turbulence builds
        one line along the wind per point when it does). A steady field (one that does not
        override `sample_local_at`) samples the points once and returns them for any time.
        Differentiable in the points, directions, times and every field value."""
        del n_times
        points = jnp.asarray(points)
        steady = (type(self).sample_local_at is AbstractField.sample_local_at
                  and type(self).los_local_at is AbstractField.los_local_at)
        if not steady:
            return DirectSampler(self, points, directions)
        if directions is None:
            return SteadySampler(self.sample_local(points), vector=True)
        directions = jnp.broadcast_to(jnp.asarray(directions, points.dtype), points.shape)
        return SteadySampler(self.los_local(points, directions), vector=False)


class TimeSampler(eqx.Module):
    """A field prepared for sampling fixed points at many times (`AbstractField.time_sampler`):
    call it with times in seconds (any shape broadcastable against the points' leading
    shape)."""

    def __call__(self, time: Float[ArrayLike, ...]) -> Float[Array, ...]:
        raise NotImplementedError


class SteadySampler(TimeSampler):
    """The values of a steady field at the points, the same at every time."""

    values: Float[Array, ...]
    vector: bool = eqx.field(static=True)

    def __call__(self, time):
        lead = self.values.shape[:-1] if self.vector else self.values.shape
        shape = jnp.broadcast_shapes(jnp.shape(time), lead)
        return jnp.broadcast_to(self.values, shape + self.values.shape[len(lead):])


@compiled
def _sample_local(field, points):
    """`AbstractField.sample_local`, one compiled program when called from the host."""
    return field.sample_local(points)


@compiled
def _sample_absolute(field, points):
    """`AbstractField.sample` at absolute points already in a JAX array."""
    # points wider than the field are split into the field's dtype first; the high parts
    # are subtracted exactly whatever the compiler fuses (`lidarjax._precision`)
    dtype = field.dtype
    zero = jnp.zeros((), dtype)
    return field.sample_local(difference(points, zero, field.origin, field.origin_lo, dtype))


@compiled
def _has_inf(values):
    """Whether a JAX array holds an infinity (one compiled program from the host)."""
    return jnp.any(jnp.isinf(values))


class DirectSampler(TimeSampler):
    """Samples the field at the points at each call (no preparation)."""

    field: AbstractField
    points: Float[Array, "... 3"]
    directions: Float[Array, "... 3"] | None

    def __call__(self, time):
        # the field's contract: times broadcastable to points.shape[:-1]
        time = jnp.asarray(time)
        shape = jnp.broadcast_shapes(time.shape, self.points.shape[:-1])
        points = jnp.broadcast_to(self.points, shape + (3,))
        time = jnp.broadcast_to(time, shape)
        if self.directions is None:
            return self.field.sample_local_at(points, time)
        directions = jnp.broadcast_to(self.directions, shape + (3,))
        return self.field.los_local_at(points, directions, time)



# A fixed direction, not along any axis or diagonal, on which `PointIndex` sorts its points.
_KEY = np.array([0.5773502691896258, 0.6741998624632421, 0.46056110315609574])
_KEY = _KEY / np.linalg.norm(_KEY)


class PointIndex(eqx.Module):
    """Prepared points and the lookup of the nearest one within a tolerance, for fields that
    answer exactly at prepared points (`lidarjax.workflows.MonitorPointField`,
    `lidarjax.io.CellPointField`).

    The points are sorted along a fixed direction; a query is compared with the few points
    whose projection lies within the tolerance of its own (a binary search, then a fixed
    window), so it costs O(log n) per query in memory and time. Projections are elementwise
    products summed, never a ``dot``: a GPU may run a float32 ``dot`` in TensorFloat-32.

    - `points`: ``(n, 3)`` the points relative to the field's origin (metres), in the
      field's working dtype.
    - `tolerance`: the match distance (metres).
    - `projection`, `order`: the sorted projections and the points' order.
    - `window` (static): the most points any interval of twice the tolerance holds (at least
      4, one compiled shape for small sets).
    """

    points: Float[Array, "n 3"]
    tolerance: Float[Array, ""]
    projection: Float[Array, " n"]
    order: Array
    window: int = eqx.field(static=True)

    @classmethod
    def build(cls, local, dtype, tolerance=None, *, caller: str) -> PointIndex:
        """The index of `local` ``(n, 3)`` points (float64 metres relative to the field's
        origin) kept in `dtype`. `tolerance` (metres): default ``1e-9`` (float64) or ``2e-5``
        (float32) times the largest distance of a point from the origin (at least that times
        one metre), which covers the rounding of points a simulation forms in that dtype.
        `caller` names the field in the error for a non-positive tolerance."""
        local = np.asarray(local, np.float64)
        if tolerance is None:
            rel = 1e-9 if np.dtype(dtype).itemsize >= 8 else 2e-5
            tolerance = rel * max(1.0, float(np.linalg.norm(local, axis=1).max()))
        tol = float(tolerance)
        if not tol > 0:
            raise ValueError(f"{caller}: tolerance must be positive metres, got {tolerance!r}")
        kept = local.astype(dtype)  # the points as stored, rounded to the dtype
        proj = (kept.astype(np.float64) * _KEY).sum(axis=1)
        order = np.argsort(proj, kind="stable")
        sp = proj[order]
        # a query's match lies at most this many places after the first point within tol
        count = np.searchsorted(sp, sp + 2 * tol, side="right") - np.arange(sp.size)
        return cls(points=host_array(kept), tolerance=jnp.asarray(tol, dtype),
                   projection=host_array(sp.astype(dtype)), order=host_array(order.astype(np.int32)),
                   window=max(4, int(count.max())))

    @property
    def n_points(self) -> int:
        return int(self.points.shape[0])

    def match(self, points: Float[Array, "... 3"]):
        """``(index, hit)``: the nearest prepared point ``(...)`` to each query (local metres,
        in the index's dtype) and whether it lies within the tolerance."""
        p = jnp.sum(points * jnp.asarray(_KEY, points.dtype), axis=-1)
        # compare_all: O(queries x points) comparisons but the quickest to compile; the
        # points of one mount number a few hundred to a few thousand
        method = "compare_all" if self.n_points <= 4096 else "scan"
        start = jnp.searchsorted(self.projection, p - self.tolerance, side="left", method=method)
        idx = jnp.clip(start[..., None] + jnp.arange(self.window), 0, self.n_points - 1)
        cand = self.order[idx]  # (..., window)
        d2 = jnp.sum((self.points[cand] - points[..., None, :]) ** 2, axis=-1)
        k = jnp.argmin(d2, axis=-1)
        best = jnp.take_along_axis(cand, k[..., None], axis=-1)[..., 0]
        dmin = jnp.take_along_axis(d2, k[..., None], axis=-1)[..., 0]
        return best, dmin <= self.tolerance**2


class IndexedPoints:
    """The accessors of a field answering at prepared points held as `index` (a
    `PointIndex`): `n_points`, `points_local` (metres from the field's origin, its dtype)
    and `tolerance` (metres)."""

    @property
    def n_points(self) -> int:
        """Number of prepared points."""
        return self.index.n_points

    @property
    def points_local(self) -> Float[Array, "n 3"]:
        """The prepared points relative to the field's origin (metres, its dtype)."""
        return self.index.points

    @property
    def tolerance(self) -> Float[Array, ""]:
        """The match distance (metres)."""
        return self.index.tolerance


def axes_resolution(local_axes, stated: float | None = None) -> float | None:
    """A grid's resolution (m) from its axes (`GridField.resolution`): `stated` if given, else
    the smallest node spacing (``None`` when traced)."""
    if stated is not None:
        return stated
    if not is_concrete(*local_axes):
        return None
    steps = [np.diff(np.asarray(a, np.float64)) for a in local_axes]
    steps = np.concatenate([d[d > 0] for d in steps])
    return float(steps.min()) if steps.size else None


def axes_spacing_at(local_axes, origin, origin_lo, stated: float | None, points):
    """A grid's spacing at absolute CFD `points` (m, host) from its axes relative to
    ``origin + origin_lo`` (`GridField.spacing_at`): the smallest edge of the cell holding
    each point (at least `stated`), NaN outside; ``None`` when traced or uniform."""
    if not is_concrete(origin, origin_lo, *local_axes):
        return None
    nodes = [np.asarray(a, np.float64) for a in local_axes]
    steps = [np.diff(a) for a in nodes]
    if all(np.ptp(d) <= 1e-9 * np.max(np.abs(d)) for d in steps):
        return None
    p = (np.asarray(points, np.float64).reshape(-1, 3)
         - np.asarray(origin, np.float64) - np.asarray(origin_lo, np.float64))
    out = np.full(p.shape[0], np.inf)
    inside = np.all(np.isfinite(p), axis=-1)
    for a, (nd, d) in enumerate(zip(nodes, steps, strict=True)):
        i = np.clip(np.searchsorted(nd, p[:, a], side="right") - 1, 0, nd.size - 2)
        out = np.minimum(out, d[i])
        inside &= (p[:, a] >= nd[0]) & (p[:, a] <= nd[-1])
    if stated is not None:
        out = np.maximum(out, stated)
    return np.where(inside, out, np.nan)


def _index_scale(xp, local_axes, dtype):
    """Nodes per metre along each axis, ``(n - 1) / extent`` (0 for a single node), in
    `dtype`, from the axes relative to their first node: `xp` is numpy for host axes,
    jax.numpy for traced ones (the same IEEE division either way)."""
    return xp.stack([xp.asarray(a.shape[0] - 1, dtype) / xp.where(a[-1] > 0, a[-1], 1).astype(dtype)
                     for a in local_axes])


def _check_axis(name: str, values) -> np.ndarray:
    arr = np.asarray(values, dtype=np.float64)
    if arr.ndim != 1:
        raise ValueError(f"GridField: `{name}` must be 1-D, got shape {arr.shape}.")
    if arr.size < 2:
        raise ValueError(
            f"GridField: `{name}` needs at least 2 nodes to interpolate, got {arr.size}."
        )
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"GridField: `{name}` contains NaN or inf coordinates.")
    steps = np.diff(arr)
    if np.any(steps <= 0):
        k = int(np.argmax(steps <= 0))
        raise ValueError(
            f"GridField: `{name}` must be strictly increasing; {name}[{k}]={arr[k]!r} >= "
            f"{name}[{k + 1}]={arr[k + 1]!r}. Sort the axis (and the velocity array with it)."
        )
    return arr


def _is_uniform(arr: np.ndarray, rtol: float) -> bool:
    steps = np.diff(arr)
    mean = (arr[-1] - arr[0]) / (arr.size - 1)
    return bool(np.max(np.abs(steps - mean)) <= rtol * mean)


class GridField(AbstractField):
    """A gridded CFD velocity field with trilinear interpolation.

    **Arguments:**

    - `x`, `y`, `z`: 1-D strictly increasing node coordinates in metres (CFD frame). Uniform
      spacing is detected (to the input's floating resolution) and uses O(1) index
      arithmetic; stretched axes use a binary search.
    - `velocity`: ``(nx, ny, nz, 3)`` velocities ``(u, v, w)`` in m/s in the CFD frame. NaN
      marks solid nodes; any point in a cell touching one samples to NaN (inf is refused).
      Its floating dtype is the field's working dtype.
    - `uniform`: per-axis override of the uniform-spacing detection (needed only when the
      coordinates are traced, e.g. built inside `jax.jit`).
    - `resolution`: the field's smallest length scale in metres, where it is coarser than the
      grid (a smooth CFD solution on a fine mesh: the probe then needs fewer nodes). Probe
      nodes are chosen for it (`lidarjax.probe_for_field`); default: the smallest node
      spacing, which is right for a turbulence box or an LES. Kept by `crop` and stacking.

    Coordinates are stored relative to the first node (`origin`), so float32 fields at UTM
    coordinates interpolate as accurately as fields near zero. A field cut out of another by
    `crop` keeps its parent's origin and node numbering, so it interpolates bit for bit like
    the parent inside the cut.

    The kernel (see `los_local`) gathers, for each point, the two ``z``-neighbouring nodes of
    each of the cell's four ``(x, y)`` columns as one contiguous run of six numbers (``u, v,
    w`` of both nodes), projects at the corners and lerps; with the component axis last this
    is four small contiguous loads per point, which XLA fuses with the index arithmetic.
    """

    origin: Float[Array, 3]
    origin_lo: Float[Array, 3]
    x_local: Float[Array, " nx"]
    y_local: Float[Array, " ny"]
    z_local: Float[Array, " nz"]
    velocity: Float[Array, "nx ny nz 3"]
    # Uniform axes: ``p * index_scale`` is the fractional node index in the numbering of the
    # grid the nodes came from ((nodes - 1) / extent of that grid) and `index_start` the
    # (integer-valued) number of this grid's first node there: 0 unless made by `crop`.
    index_scale: Float[Array, 3]
    index_start: Float[Array, 3]
    uniform: tuple[bool, bool, bool] = eqx.field(static=True)
    stated_resolution: float | None = eqx.field(static=True)

    @property
    def resolution(self) -> float | None:
        """The field's smallest length scale (m): the `resolution` it was built with, else the
        grid's smallest node spacing (``None`` when traced)."""
        return axes_resolution((self.x_local, self.y_local, self.z_local), self.stated_resolution)

    def spacing_at(self, points: Float[ArrayLike, "n 3"]) -> np.ndarray | None:
        """The grid's spacing at `points` (absolute CFD metres, host) ``(n,)``: the smallest
        edge of the cell holding each point (the stated `resolution` where it is coarser),
        NaN outside the grid; ``None`` when the axes are traced, and when the grid is uniform
        (its `resolution` everywhere). A mesh graded to a wall is fine only near it."""
        return axes_spacing_at((self.x_local, self.y_local, self.z_local), self.origin,
                               self.origin_lo, self.stated_resolution, points)

    def __init__(self, x, y, z, velocity, *, uniform=None, resolution=None):
        if resolution is not None:
            r = np.asarray(resolution, np.float64)
            if r.shape != () or not np.isfinite(r) or not r > 0:
                raise ValueError(f"GridField: `resolution` must be one finite positive length "
                                 f"(m), got {resolution!r}.")
            resolution = float(r)
        self.stated_resolution = resolution
        host = velocity if isinstance(velocity, np.ndarray) else None
        kind = getattr(velocity, "dtype", None)
        if kind is None:
            kind = np.asarray(velocity).dtype
        if np.issubdtype(kind, np.complexfloating):
            raise ValueError(f"GridField: `velocity` is complex ({kind}); a velocity field is "
                             "real m/s (take .real if the imaginary part is zero).")
        if kind in (np.float16, jnp.bfloat16):
            raise ValueError(f"GridField: `velocity` is {kind}; lidarjax computes in float32 or "
                             "float64 (cast with .astype(np.float32)).")
        if not (np.issubdtype(kind, np.number) or kind == np.bool_):
            raise ValueError(f"GridField: `velocity` must be numbers (m/s), got dtype {kind}.")
        velocity = host_array(velocity) if isinstance(velocity, np.ndarray) else jnp.asarray(velocity)
        if not jnp.issubdtype(velocity.dtype, jnp.floating):
            velocity = velocity.astype(default_float())
        dtype = velocity.dtype
        axes = (x, y, z)
        if host is not None:
            has_inf = bool(np.isinf(host).any())
        else:
            has_inf = is_concrete(velocity) and bool(_has_inf(velocity))
        if has_inf:
            raise ValueError(
                "GridField: velocity contains inf; mark solid or missing nodes with NaN."
            )
        if is_concrete(x, y, z):
            arrays = [_check_axis(n, a) for n, a in zip("xyz", axes, strict=True)]
            shape = tuple(a.size for a in arrays)
            if velocity.shape != (*shape, 3):
                raise ValueError(
                    f"GridField: velocity must have shape (nx, ny, nz, 3) = {(*shape, 3)} "
                    f"for the given axes, got {velocity.shape}. Stack u, v, w on the last axis."
                )
            in_dtype = np.result_type(*[np.asarray(a).dtype for a in axes])
            if not np.issubdtype(in_dtype, np.floating):
                in_dtype = np.float64
            rtol = 256 * float(np.finfo(in_dtype).eps)  # spacing equal to input rounding
            detected = tuple(_is_uniform(a, rtol) for a in arrays)
            origin64 = np.array([a[0] for a in arrays])
            self.origin, self.origin_lo = split(origin64, dtype)
            local = [(a - a[0]).astype(dtype) for a in arrays]
            self.x_local, self.y_local, self.z_local = (host_array(a) for a in local)
            scale = _index_scale(np, local, dtype)  # on the host: no device operations
        else:
            detected = (False, False, False)
            xs = [jnp.asarray(a) for a in axes]
            if velocity.shape[:3] != tuple(a.shape[0] for a in xs) or velocity.shape[-1] != 3:
                raise ValueError(
                    f"GridField: velocity shape {velocity.shape} does not match the axes."
                )
            origin = jnp.stack([a[0] for a in xs])
            self.origin, self.origin_lo = split(origin, dtype)
            self.x_local, self.y_local, self.z_local = (
                (a - a[0]).astype(dtype) for a in xs
            )
            scale = _index_scale(jnp, (self.x_local, self.y_local, self.z_local), dtype)
        if uniform is None:
            uniform = detected
        elif isinstance(uniform, bool):
            uniform = (uniform,) * 3
        self.uniform = tuple(bool(u) for u in uniform)
        self.velocity = velocity
        self.index_scale = jnp.asarray(scale).astype(dtype)
        self.index_start = jnp.zeros(3, dtype)

    # -- coordinates --------------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int, int]:
        """Grid shape ``(nx, ny, nz)``."""
        return tuple(self.velocity.shape[:3])

    @property
    def x(self) -> Float[Array, " nx"]:
        """Node x coordinates in CFD metres (rounded to the working dtype)."""
        return self.x_local + self.origin[0]

    @property
    def y(self) -> Float[Array, " ny"]:
        """Node y coordinates in CFD metres."""
        return self.y_local + self.origin[1]

    @property
    def z(self) -> Float[Array, " nz"]:
        """Node z coordinates in CFD metres."""
        return self.z_local + self.origin[2]

    @classmethod
    def from_function(
        cls,
        fn: Callable[[Float[Array, "... 3"]], Float[Array, "... 3"]],
        x,
        y,
        z,
        *,
        dtype=None,
    ) -> GridField:
        """Grid a field given as a function of absolute CFD points ``(..., 3) -> (..., 3)``.

        `fn` may be a scene's ``.sample`` or any JAX/numpy function. It is called with the
        node coordinates as a float64 numpy array (so UTM-sized coordinates are not rounded
        before `fn` sees them) and its result is cast to `dtype` (default: the result's own
        floating dtype). Nodes where it returns NaN stay NaN (solid).
        """
        xs = [np.asarray(a, dtype=np.float64) for a in (x, y, z)]
        pts = np.stack(np.meshgrid(*xs, indexing="ij"), axis=-1)
        vel = np.asarray(fn(pts))
        if dtype is None:
            dtype = vel.dtype if np.issubdtype(vel.dtype, np.floating) else default_float()
        return cls(xs[0], xs[1], xs[2], jnp.asarray(vel, dtype=dtype))

    # -- cropping -----------------------------------------------------------------------
    def crop(self, lo: Float[ArrayLike, 3], hi: Float[ArrayLike, 3]) -> GridField:
        """The sub-grid covering the box ``[lo, hi]`` (absolute CFD metres) plus one cell.

        Keeps the nodes bracketing ``[lo, hi]`` on each axis and one more node beyond each
        side (the interpolation margin: a point on the box's boundary, or rounded just past
        it, still finds its whole cell), clipped to the grid. The crop keeps this field's
        origin and node numbering, so every point inside the box samples **bit for bit** as
        in the full field; points outside the crop give NaN (as outside any field). Typical
        use: ``field.crop(*lidarjax.scan_bounds(scan, mount, heights, probe=probe))``, which
        cuts a ``(200, 200, 100)`` grid to the few thousand nodes one lidar sees.

        Needs concrete (not traced) coordinates and bounds. Raises `ValueError` when
        ``lo > hi`` on an axis or the box misses the grid entirely.
        """
        lo64 = np.asarray(lo, dtype=np.float64).reshape(3)
        hi64 = np.asarray(hi, dtype=np.float64).reshape(3)
        if not (np.all(np.isfinite(lo64)) and np.all(np.isfinite(hi64))):
            raise ValueError(f"GridField.crop: bounds must be finite, got {lo64}, {hi64}.")
        if np.any(lo64 > hi64):
            raise ValueError(f"GridField.crop: need lo <= hi on every axis, got {lo64}, {hi64}.")
        if not is_concrete(self.x_local, self.y_local, self.z_local, self.origin):
            raise ValueError("GridField.crop: needs concrete coordinates (call it outside jit).")
        origin = np.asarray(self.origin, np.float64) + np.asarray(self.origin_lo, np.float64)
        starts, stops, locals_ = [], [], []
        for a, nodes in enumerate((self.x_local, self.y_local, self.z_local)):
            loc = np.asarray(nodes)
            absolute = loc.astype(np.float64) + origin[a]
            n = loc.size
            if hi64[a] < absolute[0] or lo64[a] > absolute[-1]:
                raise ValueError(
                    f"GridField.crop: the box [{lo64[a]}, {hi64[a]}] misses the grid's "
                    f"{'xyz'[a]} range [{absolute[0]}, {absolute[-1]}]."
                )
            i0 = int(np.searchsorted(absolute, lo64[a], side="right")) - 1 - 1
            i1 = int(np.searchsorted(absolute, hi64[a], side="left")) + 1
            i0, i1 = max(i0, 0), min(i1, n - 1)
            i1 = max(i1, i0 + 1)
            starts.append(i0)
            stops.append(i1 + 1)
            locals_.append(nodes[i0 : i1 + 1])
        velocity = self.velocity[starts[0] : stops[0], starts[1] : stops[1], starts[2] : stops[2]]
        index_start = self.index_start + jnp.asarray(starts, self.index_start.dtype)
        return eqx.tree_at(
            lambda f: (f.x_local, f.y_local, f.z_local, f.velocity, f.index_start),
            self,
            (*locals_, velocity, index_start),
        )

    @property
    def nbytes(self) -> int:
        """Bytes held by the velocity array."""
        return int(self.velocity.size * self.velocity.dtype.itemsize)

    # -- interpolation ------------------------------------------------------------------
    def _axis_index(self, axis: int, p):
        """Lower node index (int32, always a valid cell), fraction in the cell, inside mask."""
        nodes = (self.x_local, self.y_local, self.z_local)[axis]
        n = nodes.shape[0]
        if self.uniform[axis]:
            # f is the node index in the parent grid's numbering, so a crop computes the very
            # same f and fraction t as its parent (only the integer start differs)
            f = p * self.index_scale[axis]
            start = self.index_start[axis]
            inside = (f >= start) & (f <= start + (n - 1))
            i0 = jnp.clip(jnp.floor(f), start, start + (n - 2))
            t = f - i0
            i0 = i0 - start
        else:
            i0 = jnp.clip(jnp.searchsorted(nodes, p, side="right") - 1, 0, n - 2)
            lo, hi = nodes[i0], nodes[i0 + 1]
            t = (p - lo) / (hi - lo)
            inside = (p >= nodes[0]) & (p <= nodes[-1])
        # NaN or huge points: any valid cell (their value is masked to NaN anyway); this keeps
        # the unchecked gather below in bounds
        i0 = jnp.where(inside, i0, 0).astype(jnp.int32)
        return i0, t, inside

    def _cell_columns(self, points, safe: bool, snapshot=None):
        """Gather the cell of every point: four ``(..., 6)`` runs ``(u, v, w)`` of the lower
        and upper ``z`` node of the columns ``(i, j), (i, j+1), (i+1, j), (i+1, j+1)``, the
        fractions ``(tx, ty, tz)`` and the mask of points inside the grid.

        With `safe` (the derivative path, see `_grid_sample`), the mask also excludes cells
        touching a solid (NaN) node, and the runs and fractions are zeroed outside it,
        so everything downstream is finite. `snapshot` (int32, broadcastable to the points'
        leading shape): for a stack of snapshots (`SnapshotField`: velocity ``(t, nx, ny, nz,
        3)``), which one each point reads.
        """
        nx, ny, nz = (a.shape[0] for a in (self.x_local, self.y_local, self.z_local))
        if self.velocity.size >= 2**31:
            raise ValueError(
                f"GridField: {self.velocity.size} velocity values exceed the int32 flat index "
                f"of the kernel; crop the field (GridField.crop) or split it."
            )
        (i, tx, ix), (j, ty, iy), (k, tz, iz) = (
            self._axis_index(a, points[..., a]) for a in range(3)
        )
        base = 3 * ((i * ny + j) * nz + k)
        if snapshot is not None:
            base = base + snapshot * (3 * nx * ny * nz)
        flat = self.velocity.reshape(-1)
        dims = jax.lax.GatherDimensionNumbers(
            offset_dims=(base.ndim,), collapsed_slice_dims=(), start_index_map=(0,)
        )

        def run(offset):
            # i0 <= n - 2 on every axis, so the six numbers are always inside the array
            return jax.lax.gather(
                flat,
                (base + offset)[..., None],
                dims,
                slice_sizes=(6,),
                mode=jax.lax.GatherScatterMode.PROMISE_IN_BOUNDS,
            )

        sy, sx = 3 * nz, 3 * ny * nz
        columns = (run(0), run(sy), run(sx), run(sx + sy))
        inside = ix & iy & iz
        t = (tx, ty, tz)
        if safe:
            total = columns[0] + columns[1] + columns[2] + columns[3]
            inside = inside & ~jnp.any(jnp.isnan(total), axis=-1)
            columns = tuple(jnp.where(inside[..., None], c, 0.0) for c in columns)
            t = tuple(jnp.where(inside, tt, 0.0) for tt in t)
        return columns, t, inside

    @staticmethod
    def _lerp_cell(values, t):
        """Nested trilinear lerps: ``values`` are the four columns' ``(lower, upper)`` pairs."""
        tx, ty, tz = t

        def lerp(a, b, s):
            return a + s * (b - a)

        (a0, a1), (b0, b1), (c0, c1), (d0, d1) = values
        c00, c01, c10, c11 = lerp(a0, a1, tz), lerp(b0, b1, tz), lerp(c0, c1, tz), lerp(d0, d1, tz)
        return lerp(lerp(c00, c01, ty), lerp(c10, c11, ty), tx)

    def sample_local(self, points: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
        """Trilinear velocity (m/s, CFD frame) at points relative to `origin` (metres).

        Outside the grid, or in a cell touching a NaN node: NaN (with finite gradients).
        """
        return _grid_sample(self, jnp.asarray(points).astype(self.dtype))

    def los_local(
        self, points: Float[Array, "... 3"], directions: Float[Array, "... 3"]
    ) -> Float[Array, ...]:
        """Trilinear velocity projected on unit `directions` (m/s), projected at the corners
        so the gather, the dot product and the lerps fuse into one loop. NaN as in
        `sample_local`."""
        points = jnp.asarray(points).astype(self.dtype)
        d = jnp.broadcast_to(jnp.asarray(directions).astype(self.dtype), points.shape)
        return _grid_los(self, points, d)

    def _sample(self, points, safe: bool, snapshot=None):
        columns, t, inside = self._cell_columns(points, safe, snapshot)
        t = [tt[..., None] for tt in t]
        val = self._lerp_cell([(c[..., 0:3], c[..., 3:6]) for c in columns], t)
        return jnp.where(inside[..., None], val, jnp.nan)

    def _los(self, points, d, safe: bool, snapshot=None):
        columns, t, inside = self._cell_columns(points, safe, snapshot)
        dx, dy, dz = d[..., 0], d[..., 1], d[..., 2]

        def project(c):
            return (
                c[..., 0] * dx + c[..., 1] * dy + c[..., 2] * dz,
                c[..., 3] * dx + c[..., 4] * dy + c[..., 5] * dz,
            )

        val = self._lerp_cell([project(c) for c in columns], t)
        return jnp.where(inside, val, jnp.nan)


# The kernels run in two forms with equal values. The plain one lets NaN (solid) nodes flow
# through the lerps, which keeps the gather fused into one loop (sanitising the gathered
# nodes costs 3-4x in throughput). Derivatives use the safe form, which zeroes solid and
# outside cells before the lerps and inserts NaN last: in the plain form `0 * NaN` would make
# the gradient with respect to the points, directions and field values NaN even for a loss
# that masks the NaN results out.
@jax.custom_jvp
def _grid_sample(field, points):
    return field._sample(points, safe=False)


@_grid_sample.defjvp
def _grid_sample_jvp(primals, tangents):
    return jax.jvp(lambda f, p: f._sample(p, safe=True), primals, tangents)


@jax.custom_jvp
def _grid_los(field, points, directions):
    return field._los(points, directions, safe=False)


@_grid_los.defjvp
def _grid_los_jvp(primals, tangents):
    return jax.jvp(lambda f, p, d: f._los(p, d, safe=True), primals, tangents)


@jax.custom_jvp
def _snapshot_sample(field, points, snapshot):
    return field._sample(points, False, snapshot)


@_snapshot_sample.defjvp
def _snapshot_sample_jvp(primals, tangents):
    field, points, snapshot = primals
    return jax.jvp(lambda f, p: f._sample(p, True, snapshot), primals[:2], tangents[:2])


@jax.custom_jvp
def _snapshot_los(field, points, directions, snapshot):
    return field._los(points, directions, False, snapshot)


@_snapshot_los.defjvp
def _snapshot_los_jvp(primals, tangents):
    field, points, directions, snapshot = primals
    return jax.jvp(lambda f, p, d: f._los(p, d, True, snapshot), primals[:3], tangents[:3])


def _lerp_in_time(v0, v1, s, ok):
    """``v0 + s (v1 - v0)`` where `ok`, NaN elsewhere; non-finite values are zeroed before
    the lerp so that gradients stay finite where the result is masked (`AbstractField`)."""
    v0, v1 = jnp.where(ok, v0, 0.0), jnp.where(ok, v1, 0.0)
    s = jnp.where(ok, s, 0.0)
    return jnp.where(ok, v0 + s * (v1 - v0), jnp.nan)


class OnGrid:
    """A field carried by a `GridField` in its `grid` (snapshots of it, or exact values at
    points prepared within it): the grid's resolution and spacing are the field's."""

    @property
    def resolution(self) -> float | None:
        """The grid's resolution (m): probe nodes are chosen for it, as for the grid alone."""
        return self.grid.resolution

    def spacing_at(self, points):
        """The grid's spacing (m) at `points` (`GridField.spacing_at`)."""
        return self.grid.spacing_at(points)


class SnapshotField(OnGrid, AbstractField):
    """Snapshots of an unsteady flow (LES, URANS) on one grid: trilinear in space, linear in
    time between consecutive snapshots, NaN outside their span.

    **Arguments:**

    - `times`: ``(t,)`` snapshot times in seconds, strictly increasing, at least two. Use
      times relative to the start of the run or record: in float32 a time ``t`` resolves
      ``ulp(t)`` (0.002 s at one hour).
    - `fields`: ``t`` `GridField`\\ s on one grid (equal axes, origin and dtype; e.g. one
      CFD case's time folders resampled onto the same nodes), velocity m/s in the CFD frame.

    At a point and time ``tau`` with ``times[i] <= tau <= times[i + 1]`` the velocity is
    ``(1 - s) u_i + s u_{i+1}``, ``s = (tau - times[i]) / (times[i + 1] - times[i])``, each
    ``u`` trilinear as in `GridField`: NaN outside the grid, in a solid cell, or for
    ``tau`` outside ``[times[0], times[-1]]`` (`time_span`; `lidarjax.simulate_series` flags
    those LOS with `lidarjax.Flag.TIME_OUTSIDE`). Steady sampling (`sample_local`, as
    `lidarjax.simulate` calls it) reads the first snapshot. Differentiable in the points,
    the times and every velocity value (gradients finite where the value is).

    Built on the host from concrete fields; to keep memory bounded over a long run, let a
    `FieldSequence` load the few snapshots each stretch of time needs
    (`lidarjax.simulate_series` accepts one).
    """

    origin: Float[Array, 3]
    origin_lo: Float[Array, 3]
    grid: GridField  # velocity (t, nx, ny, nz, 3): the snapshots on the shared grid
    times: Float[Array, " t"]

    def __init__(self, times, fields):
        fields = list(fields)
        if len(fields) < 2:
            raise ValueError(f"SnapshotField: needs at least two snapshots to interpolate in "
                             f"time, got {len(fields)}.")
        for k, f in enumerate(fields):
            if not isinstance(f, GridField) or f.velocity.ndim != 4:
                raise ValueError(f"SnapshotField: snapshot {k} is a {type(f).__name__}, not a "
                                 f"single lidarjax.GridField.")
        first = fields[0]
        t = np.asarray(times, np.float64) if is_concrete(times) else None
        if t is not None:
            if t.ndim != 1 or t.size != len(fields):
                raise ValueError(f"SnapshotField: `times` must be 1-D with one time per "
                                 f"snapshot ({len(fields)}), got shape {t.shape}.")
            if not np.all(np.isfinite(t)):
                raise ValueError("SnapshotField: `times` must be finite seconds.")
            if np.any(np.diff(t) <= 0):
                k = int(np.argmax(np.diff(t) <= 0))
                raise ValueError(f"SnapshotField: `times` must be strictly increasing; "
                                 f"times[{k}]={t[k]!r} >= times[{k + 1}]={t[k + 1]!r}.")
        for k, f in enumerate(fields[1:], start=1):
            same = (f.uniform == first.uniform and f.velocity.shape == first.velocity.shape
                    and f.velocity.dtype == first.velocity.dtype)
            for a, b in ((f.x_local, first.x_local), (f.y_local, first.y_local),
                         (f.z_local, first.z_local), (f.origin, first.origin),
                         (f.origin_lo, first.origin_lo), (f.index_start, first.index_start)):
                same = same and a.shape == b.shape and bool(jnp.array_equal(a, b))
            if not same:
                raise ValueError(f"SnapshotField: snapshot {k} has other axes, origin, shape or "
                                 f"dtype than snapshot 0; snapshots must share one grid "
                                 f"(resample them onto the same nodes).")
        self.origin, self.origin_lo = first.origin, first.origin_lo
        self.grid = eqx.tree_at(lambda g: g.velocity, first,
                                jnp.stack([f.velocity for f in fields]))
        self.times = jnp.asarray(times if t is None else t, first.dtype)

    @property
    def time_span(self):
        return self.times[0], self.times[-1]

    @property
    def n_snapshots(self) -> int:
        """Number of snapshots ``t``."""
        return int(self.times.shape[0])

    @property
    def nbytes(self) -> int:
        """Bytes held by the snapshots' velocities."""
        return self.grid.nbytes

    def snapshot(self, k: int) -> GridField:
        """Snapshot `k` as a steady `GridField`."""
        return eqx.tree_at(lambda g: g.velocity, self.grid, self.grid.velocity[k])

    def _locate(self, time):
        """Lower snapshot index (int32), fraction ``s`` in the interval, inside-span mask."""
        ts = self.times
        time = jnp.asarray(time).astype(self.dtype)
        i = jnp.clip(jnp.searchsorted(ts, time, side="right") - 1, 0, ts.shape[0] - 2)
        i = i.astype(jnp.int32)
        t0, t1 = ts[i], ts[i + 1]
        s = (time - t0) / (t1 - t0)
        return i, s, (time >= ts[0]) & (time <= ts[-1])

    def _broadcast(self, points, time):
        points = jnp.asarray(points).astype(self.dtype)
        time = jnp.asarray(time).astype(self.dtype)
        shape = jnp.broadcast_shapes(time.shape, points.shape[:-1])
        return jnp.broadcast_to(points, shape + (3,)), jnp.broadcast_to(time, shape)

    def sample_local(self, points: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
        """The first snapshot's velocity (m/s, CFD frame) at local points (metres)."""
        return self.sample_local_at(points, self.times[0])

    @compiled
    def sample_local_at(self, points, time):
        points, time = self._broadcast(points, time)
        i, s, inside = self._locate(time)
        v0 = _snapshot_sample(self.grid, points, i)
        v1 = _snapshot_sample(self.grid, points, i + 1)
        ok = inside & jnp.all(jnp.isfinite(v0) & jnp.isfinite(v1), axis=-1)
        return _lerp_in_time(v0, v1, s[..., None], ok[..., None])

    @compiled
    def los_local_at(self, points, directions, time):
        points, time = self._broadcast(points, time)
        d = jnp.broadcast_to(jnp.asarray(directions).astype(self.dtype), points.shape)
        i, s, inside = self._locate(time)
        l0 = _snapshot_los(self.grid, points, d, i)
        l1 = _snapshot_los(self.grid, points, d, i + 1)
        ok = inside & jnp.isfinite(l0) & jnp.isfinite(l1)
        return _lerp_in_time(l0, l1, s, ok)

    def time_sampler(self, points, directions=None, *, n_times: int = 1) -> TimeSampler:
        """As `AbstractField.time_sampler`; when the points are sampled at more times than
        there are snapshots, each snapshot is sampled once at the points and the calls only
        interpolate in time (`SnapshotSampler`)."""
        points = jnp.asarray(points).astype(self.dtype)
        if n_times <= self.n_snapshots:
            return DirectSampler(self, points, directions)
        k = jnp.arange(self.n_snapshots, dtype=jnp.int32)
        if directions is None:
            values = jax.vmap(lambda j: _snapshot_sample(self.grid, points, j))(k)
        else:
            d = jnp.broadcast_to(jnp.asarray(directions).astype(self.dtype), points.shape)
            values = jax.vmap(lambda j: _snapshot_los(self.grid, points, d, j))(k)
        return SnapshotSampler(self.times, values, vector=directions is None)


class SnapshotSampler(TimeSampler):
    """A `SnapshotField`'s values at fixed points at every snapshot (``(t, ...)``),
    interpolated linearly in time at each call; NaN outside the snapshots' span."""

    times: Float[Array, " t"]
    values: Float[Array, ...]
    vector: bool = eqx.field(static=True)

    def __call__(self, time):
        ts, vals = self.times, self.values
        lead = vals.shape[1:-1] if self.vector else vals.shape[1:]
        time = jnp.asarray(time).astype(vals.dtype)
        shape = jnp.broadcast_shapes(time.shape, lead)
        time = jnp.broadcast_to(time, shape)
        i = jnp.clip(jnp.searchsorted(ts, time, side="right") - 1, 0, ts.shape[0] - 2)
        s = (time - ts[i]) / (ts[i + 1] - ts[i])
        inside = (time >= ts[0]) & (time <= ts[-1])
        flat = vals.reshape((vals.shape[0], -1) + vals.shape[1 + len(lead):])
        n = int(np.prod(lead, dtype=np.int64))
        where_ = jnp.broadcast_to(jnp.arange(n).reshape(lead), shape)
        v0, v1 = flat[i, where_], flat[i + 1, where_]
        if self.vector:
            ok = inside & jnp.all(jnp.isfinite(v0) & jnp.isfinite(v1), axis=-1)
            return _lerp_in_time(v0, v1, s[..., None], ok[..., None])
        ok = inside & jnp.isfinite(v0) & jnp.isfinite(v1)
        return _lerp_in_time(v0, v1, s, ok)


class FieldSequence:
    """Snapshots of an unsteady flow that stay on disk until a stretch of time needs them.

    A host-side loader, not a pytree: `lidarjax.simulate_series` asks it for the snapshots
    bracketing each chunk of LOS times (`window`) and runs the chunk on a `SnapshotField`
    of those only, so memory holds at most `max_snapshots` snapshots whatever the run's
    length. The readers in `lidarjax.io` build one from OpenFOAM time folders, a NetCDF
    file with a time axis or a list of field files (`lidarjax.io.load_field_sequence`).

    **Arguments:**

    - `times`: ``(t,)`` snapshot times in seconds, strictly increasing, at least two.
    - `load`: ``load(k) -> GridField``, snapshot ``k`` (all on one grid, one dtype); called
      at most once per window for each snapshot the window lacks.
    - `max_snapshots`: the most snapshots one window holds (at least 2); default 8.
    - `name`: what error messages call the sequence (a path).
    - `assemble`: ``assemble(times, snapshots) -> AbstractField``, the field of one window
      from what `load` returned for its snapshots (default `SnapshotField`, `load` then
      returning `GridField`\\ s); a reader that prepares more than a grid per snapshot (the
      exact cellPoint values at the points a run samples, `lidarjax.io.load_field_sequence`'s
      `exact_at`) gives its own.
    - `exact`: ``exact(points, max_snapshots) -> FieldSequence``, the same snapshots made
      exact at `points` (an ``exact_at`` of `lidarjax.io.load_field_sequence`): a mesh's
      sequence loaded without them, which `lidarjax.simulate_series` makes exact at a fixed
      lidar's points (`made_exact`). None (default): the snapshots are their own data.
    """

    def __init__(self, times, load: Callable[[int], Any], *, max_snapshots: int = 8,
                 name: str = "FieldSequence", assemble: Callable[..., Any] | None = None,
                 exact: Callable[..., FieldSequence] | None = None):
        t = np.asarray(times, np.float64)
        if t.ndim != 1 or t.size < 2 or not np.all(np.isfinite(t)):
            raise ValueError(f"{name}: needs at least two finite snapshot times (s), got "
                             f"{t.tolist() if t.size < 10 else t.shape}.")
        if np.any(np.diff(t) <= 0):
            k = int(np.argmax(np.diff(t) <= 0))
            raise ValueError(f"{name}: snapshot times must be strictly increasing; "
                             f"times[{k}]={t[k]!r} >= times[{k + 1}]={t[k + 1]!r}.")
        if int(max_snapshots) < 2:
            raise ValueError(f"{name}: `max_snapshots` must be at least 2, got {max_snapshots}.")
        self.times = t
        self.name = name
        self.max_snapshots = int(max_snapshots)
        self._load = load
        self._assemble = assemble
        self._exact = exact
        self._loaded: dict[int, Any] = {}

    def __len__(self) -> int:
        return int(self.times.size)

    def __repr__(self) -> str:
        return (f"FieldSequence({self.name!r}, {len(self)} snapshots, "
                f"{self.times[0]:g}..{self.times[-1]:g} s)")

    @property
    def time_span(self) -> tuple[float, float]:
        """``(first, last)`` snapshot time, s."""
        return float(self.times[0]), float(self.times[-1])

    @property
    def can_be_exact(self) -> bool:
        """Whether `made_exact` can prepare the mesh's own values at given points (a mesh's
        sequence loaded without ``exact_at``)."""
        return self._exact is not None

    def made_exact(self, points) -> FieldSequence:
        """The same snapshots, exact (the mesh's own cellPoint) at `points`: ``(n, 3)`` CFD
        metres or a function of the first snapshot's `GridField` returning them (e.g.
        `lidarjax.ExactPoints`); this sequence itself where it cannot be (`can_be_exact`)."""
        return self if self._exact is None else self._exact(points, self.max_snapshots)

    def indices(self, t0: float, t1: float) -> tuple[int, int]:
        """``(first, last)`` snapshot numbers whose interval(s) cover ``[t0, t1]`` (clipped
        to the sequence; at least two snapshots)."""
        t = self.times
        i0 = int(np.clip(np.searchsorted(t, t0, side="right") - 1, 0, t.size - 2))
        i1 = int(np.clip(np.searchsorted(t, t1, side="left"), i0 + 1, t.size - 1))
        return i0, i1

    def snapshot(self, k: int) -> GridField:
        """Snapshot `k`, loaded (or reused from the current window)."""
        k = int(k)
        if k in self._loaded:
            return self._loaded[k]
        f = self._load(k)
        if self._assemble is not None:
            return f
        if not isinstance(f, GridField) or f.velocity.ndim != 4:
            raise ValueError(f"{self.name}: snapshot {k} (t = {self.times[k]:g} s) loaded as a "
                             f"{type(f).__name__}, not a lidarjax.GridField.")
        return f

    def window(self, first: int, last: int, *, base: float = 0.0) -> AbstractField:
        """Snapshots ``first..last`` (inclusive, at most `max_snapshots`) as one
        `SnapshotField` whose times are relative to `base` seconds (reduced in float64, so a
        float32 window resolves its own times finely however late in the run); the
        snapshots loaded for the previous window are reused and every other one is
        released."""
        first, last = int(first), int(last)
        if not 0 <= first < last < len(self) or last - first + 1 > self.max_snapshots:
            raise ValueError(f"{self.name}: window {first}..{last} must lie in 0..{len(self) - 1}"
                             f" and hold 2..{self.max_snapshots} snapshots.")
        fields = {k: self.snapshot(k) for k in range(first, last + 1)}
        self._loaded = fields
        try:
            make = SnapshotField if self._assemble is None else self._assemble
            return make(self.times[first:last + 1] - float(base), list(fields.values()))
        except ValueError as e:
            raise ValueError(f"{self.name}: {e}") from None
