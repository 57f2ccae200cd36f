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
give NaN: never a clamped value.
"""

from __future__ import annotations

from collections.abc import Callable

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ._precision import default_float, is_concrete, split

__all__ = ["AbstractField", "GridField"]


class AbstractField(eqx.Module):
    """A velocity field in the CFD frame (m/s), sampled at points in metres.

    Subclasses define `origin`, `origin_lo` and `sample_local`.
    """

    origin: eqx.AbstractVar[Float[Array, "3"]]
    origin_lo: eqx.AbstractVar[Float[Array, "3"]]

    @property
    def dtype(self):
        """The working floating dtype of this field: results of `simulate` follow it."""
        return self.origin.dtype

    def sample_local(self, points: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
        """Velocity (m/s, CFD frame) at points relative to `origin` (metres). NaN outside."""
        raise NotImplementedError

    def sample(self, points: Float[ArrayLike, "... 3"]) -> Float[Array, "... 3"]:
        """Velocity (m/s, CFD frame) at absolute CFD points (metres). NaN outside."""
        points = jnp.asarray(points)
        dtype = self.dtype
        local = (points.astype(dtype) - self.origin) - self.origin_lo
        if jnp.dtype(points.dtype).itemsize > jnp.dtype(dtype).itemsize:
            # the input is wider than the field: subtract in its precision first
            local = (points - self.origin.astype(points.dtype)).astype(dtype) - self.origin_lo
        return self.sample_local(local)

    def los_local(
        self, points: Float[Array, "... 3"], directions: Float[Array, "... 3"]
    ) -> Float[Array, "..."]:
        """Velocity at local points projected on unit `directions` (m/s, + along direction)."""
        return jnp.sum(self.sample_local(points) * directions, axis=-1)


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
      marks solid nodes; any point in a cell touching one samples to NaN. Its floating
      dtype is the field's working dtype.
    - `uniform`: per-axis override of the uniform-spacing detection (needed only when the
      coordinates are traced, e.g. built inside `jax.jit`).

    Coordinates are stored relative to the first node (`origin`), so float32 fields at UTM
    coordinates interpolate as accurately as fields near zero.
    """

    origin: Float[Array, "3"]
    origin_lo: Float[Array, "3"]
    x_local: Float[Array, " nx"]
    y_local: Float[Array, " ny"]
    z_local: Float[Array, " nz"]
    velocity: Float[Array, "nx ny nz 3"]
    uniform: tuple[bool, bool, bool] = eqx.field(static=True)

    def __init__(self, x, y, z, velocity, *, uniform=None):
        velocity = jnp.asarray(velocity)
        if not jnp.issubdtype(velocity.dtype, jnp.floating):
            velocity = velocity.astype(default_float())
        dtype = velocity.dtype
        axes = (x, y, z)
        if is_concrete(x, y, z):
            arrays = [_check_axis(n, a) for n, a in zip("xyz", axes)]
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
            self.x_local, self.y_local, self.z_local = (
                jnp.asarray((a - a[0]).astype(dtype)) for a in arrays
            )
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
        if uniform is None:
            uniform = detected
        elif isinstance(uniform, bool):
            uniform = (uniform,) * 3
        self.uniform = tuple(bool(u) for u in uniform)
        self.velocity = velocity

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

        `fn` may be a scene's ``.sample`` or any JAX/numpy function. Nodes where it returns
        NaN stay NaN (solid).
        """
        xs = [np.asarray(a, dtype=np.float64) for a in (x, y, z)]
        pts = np.stack(np.meshgrid(*xs, indexing="ij"), axis=-1)
        vel = np.asarray(fn(jnp.asarray(pts, dtype=dtype) if dtype else pts))
        if dtype is None:
            dtype = vel.dtype if np.issubdtype(vel.dtype, np.floating) else default_float()
        return cls(xs[0], xs[1], xs[2], jnp.asarray(vel, dtype=dtype))

    # -- interpolation ------------------------------------------------------------------
    def _axis_index(self, axis: int, p):
        nodes = (self.x_local, self.y_local, self.z_local)[axis]
        n = nodes.shape[0]
        if self.uniform[axis]:
            f = p * ((n - 1) / nodes[-1])
            i0 = jnp.clip(jnp.floor(f), 0, n - 2)
            t = f - i0
            i0 = i0.astype(jnp.int32)
            inside = (f >= 0) & (f <= n - 1)
        else:
            i0 = jnp.clip(jnp.searchsorted(nodes, p, side="right") - 1, 0, n - 2)
            i0 = i0.astype(jnp.int32)
            lo, hi = nodes[i0], nodes[i0 + 1]
            t = (p - lo) / (hi - lo)
            inside = (p >= 0) & (p <= nodes[-1])
        return i0, t, inside

    def _corners(self, points):
        """Flat index of the lower corner, the fractions and the inside mask."""
        nx, ny, nz = self.shape
        (i, tx, ix), (j, ty, iy), (k, tz, iz) = (
            self._axis_index(a, points[..., a]) for a in range(3)
        )
        base = (i * ny + j) * nz + k
        return base, (tx, ty, tz), ix & iy & iz

    def _interpolate(self, corner, t):
        """Nested trilinear lerps of ``corner(offset)`` over the cell's eight nodes."""
        _, ny, nz = self.shape
        sx, sy = ny * nz, nz
        tx, ty, tz = t

        def lerp(a, b, s):
            return a + s * (b - a)

        c00 = lerp(corner(0), corner(1), tz)
        c01 = lerp(corner(sy), corner(sy + 1), tz)
        c10 = lerp(corner(sx), corner(sx + 1), tz)
        c11 = lerp(corner(sx + sy), corner(sx + sy + 1), tz)
        return lerp(lerp(c00, c01, ty), lerp(c10, c11, ty), tx)

    def sample_local(self, points: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
        """Trilinear velocity (m/s, CFD frame) at points relative to `origin` (metres).

        Outside the grid, or in a cell touching a NaN node: NaN.
        """
        points = jnp.asarray(points).astype(self.dtype)
        base, t, inside = self._corners(points)
        flat = self.velocity.reshape(-1, 3)
        val = self._interpolate(lambda off: flat[base + off], [tt[..., None] for tt in t])
        return jnp.where(inside[..., None], val, jnp.nan)

    def los_local(
        self, points: Float[Array, "... 3"], directions: Float[Array, "... 3"]
    ) -> Float[Array, "..."]:
        """Trilinear velocity projected on unit `directions` (m/s), projected at the corners
        so the gather, the dot product and the lerps fuse."""
        points = jnp.asarray(points).astype(self.dtype)
        base, t, inside = self._corners(points)
        flat = self.velocity.reshape(-1, 3)
        d = jnp.broadcast_to(directions.astype(self.dtype), points.shape)
        val = self._interpolate(lambda off: jnp.sum(flat[base + off] * d, axis=-1), t)
        return jnp.where(inside, val, jnp.nan)
