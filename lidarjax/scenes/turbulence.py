"""Frozen turbulence: a mean field plus a turbulence box advected with the wind (Taylor).

A `lidarjax.TurbulenceBox` holds velocity fluctuations ``(u', v', w')`` (m/s) on a regular
grid in the box frame that `lidarjax.turbulence` describes: ``x`` downwind, ``y`` lateral to
the left looking downwind, ``z`` up; periodic along ``x``, and laterally and vertically only
when its generator made it so (else NaN outside the nodes).

`FrozenTurbulence` adds the box to any mean field (a `GridField` or a scene) under Taylor's
hypothesis. With ``e_x`` the unit vector the wind blows towards (meteorological `direction`,
degrees clockwise from the CFD ``+y``, where the wind comes *from*), ``e_z`` up and
``e_y = e_z x e_x``, a point ``p`` (field-local metres) at time ``t`` (seconds) reads the box at

    ``xi = (p - anchor) . e_x - shift - U t``,  ``eta = (p - anchor) . e_y``,
    ``zeta = (p - anchor) . e_z``

(trilinear interpolation, periodic along ``xi``), and its velocity is
``mean(p, t) + u' e_x + v' e_y + w' e_z``. ``anchor`` is the field-local point at the box's
bottom, lateral centre, ``x = 0`` node at ``t = 0``; ``shift`` an advected distance already
travelled (m). Every number (box values, speed, direction, anchor, shift, time) is dynamic and
differentiable; `jax.vmap` over time works.

**Float32 over long advections.** ``U t`` reaches kilometres in a 10-minute record (hundreds of
km over a day) while the box resolves a fraction of a metre. The advected distance is reduced
modulo ``Lx`` without ever rounding ``U t`` (`advected_distance`): ``U`` and ``t`` are each
split exactly into a high part with 12 significant bits and a low part with 11
(`lidarjax._precision.split_bits`: power-of-two quantisation with ``rint``), so the four
partial products ``U_hi t_hi``, ``U_hi t_lo``, ``U_lo t_hi`` and ``U_lo t_lo`` are *exact*
float32 numbers; the three large ones are reduced by ``lax.rem`` (exact in IEEE arithmetic)
and the pieces, each smaller than ``Lx``, summed. The position in the box thus keeps the
resolution of a float32 coordinate *inside the box* (a few ``ulp(Lx)``, 0.5 mm each for an
8 km box) whatever ``t``, rather than ``ulp(U t)``. This holds whatever the compiler does
with the arithmetic: XLA contracts ``a * b + c`` into FMAs (on GPU and CPU), and
``--xla_cpu_enable_fast_math`` also reassociates sums; every product here is exact, so an
FMA computes the same number, the split uses ``rint`` rather than arithmetic a compiler
could rewrite, and the only sums left are of box-sized terms, whose order does not matter
at that resolution. (The former formulation, Dekker's two-product, relied on its splitting
``c x - (c x - x)`` being evaluated as written: reassociated it folds to ``x``, and fast
math put the box 1.4 cm off after a day.) Time itself is read in the working
dtype: a float32 ``t`` of 3600 s resolves 0.24 ms (2.4 mm at 10 m/s); for absolute times of
days or more, advance the field to the record start first with `FrozenTurbulence.advanced`
(reduced in float64 on the host) and pass times within the record. The time sampler's lines
are projected by matrix products at ``Precision.HIGHEST``: at DEFAULT, a GPU runs float32 ones
in TensorFloat-32 (10-bit mantissas, 3e-4 of the amplitude off).

**Reading other codes' boxes.** HAWC2 and OpenFAST's InflowWind sweep a Mann box through the
turbine in *increasing* box ``x`` (Wise and Bachynski 2020, appendix), i.e. they see the mirror
image of the spatial field the Mann model describes (which a Taylor-advected snapshot passes in
*decreasing* ``x``). lidarjax advects the box as the spatial field it is; to reproduce what
those codes feed a turbine, read it with ``reverse_x=True`` (`lidarjax.io.turbulence`).
TurbSim's ``.bts`` planes are times, converted to space by the reader (plane ``n`` taken at
``t = n dt`` lies ``n dt U`` *upstream*).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._deprecated import deprecated_getattr
from .._precision import is_concrete, split_bits
from .._util import compiled
from ..angles import heading
from ..field import AbstractField, TimeSampler
from ..frames import rotate
from ..turbulence import TurbulenceBox, box_axis

__all__ = ["FrozenTurbulence", "frozen_turbulence"]


@jax.custom_jvp
def advected_distance(speed, time, length):
    """``speed * time`` reduced modulo `length` (m), accurate to a few ulp of `length` rather
    than to the rounding of the product, also under FMA contraction and reassociation (see
    the module docs): ``speed`` and ``time`` are split exactly into half-precision parts, the
    partial products (all exact) reduced by ``lax.rem`` and summed. Result in about
    ``(-length, length)``; its derivatives are those of ``speed * time`` (and ``-n`` with
    respect to `length`, ``n`` the number of whole periods removed, as for ``lax.rem``)."""
    speed, time = jnp.broadcast_arrays(speed, time)
    dtype = jnp.result_type(speed, time)
    speed, time = speed.astype(dtype), time.astype(dtype)
    length = jnp.asarray(length).astype(dtype)
    bits = (jnp.finfo(dtype).nmant + 1) // 2  # 12 for float32, 26 for float64: exact products
    uh, ul = split_bits(speed, bits)
    th, tl = split_bits(time, bits)

    def rem(x):
        return jax.lax.rem(x, length)

    big = rem(rem(uh * th) + rem(uh * tl))
    return rem(big + (rem(ul * th) + ul * tl))


@advected_distance.defjvp
def _advected_distance_jvp(primals, tangents):
    speed, time, length = primals
    d_speed, d_time, d_length = tangents
    out = advected_distance(speed, time, length)
    dtype = out.dtype
    speed, time, length = (jnp.asarray(a).astype(dtype) for a in primals)
    periods = jnp.round((speed * time - out) / length)
    tangent = d_speed * time + speed * d_time - periods * d_length
    return out, jnp.broadcast_to(tangent, out.shape).astype(dtype)


class FrozenTurbulence(AbstractField):
    """A mean field plus a `TurbulenceBox` advected at `speed` towards `direction` (Taylor).

    **Arguments:**

    - `mean`: any `AbstractField` (a `GridField` or a scene), CFD frame, m/s; its
      `sample_local_at` is called with the same points and times (steady fields ignore time).
    - `box`: the `TurbulenceBox` of fluctuations.
    - `speed`: advection speed ``U`` in m/s (usually the mean speed at hub or measurement
      height).
    - `direction`: meteorological direction the wind (and the box) comes from, degrees
      clockwise from the CFD ``+y`` (north in scenes): the box's ``x`` axis points towards
      ``direction + 180``.
    - `anchor`: ``(3,)`` field-local point (metres, relative to ``mean.origin``) of the box's
      bottom, lateral-centre, ``x = 0`` node at ``t = 0``. Default ``(0, 0, 0)``: the box
      stands on the field origin's level, centred on it.
    - `shift`: advected distance already travelled at ``t = 0`` (m); see `advanced`.

    The field's dtype, origin and frame are the mean field's. See the module docs for the
    formulas, periodicity and float32 precision.
    """

    mean: AbstractField
    box: TurbulenceBox
    speed: Float[Array, ""]
    direction: Float[Array, ""]
    anchor: Float[Array, 3]
    shift: Float[Array, ""]

    @property
    def resolution(self) -> float | None:
        """The box's smallest node spacing (or the mean field's resolution, if finer)."""
        scales = [self.mean.resolution]
        if is_concrete(self.box.spacing):
            scales.append(float(np.min(np.asarray(self.box.spacing, np.float64))))
        scales = [v for v in scales if v is not None]
        return min(scales) if scales else None

    def __init__(self, mean, box, speed, direction, *, anchor=(0.0, 0.0, 0.0), shift=0.0):
        if not isinstance(mean, AbstractField):
            raise ValueError(
                f"FrozenTurbulence: `mean` must be a lidarjax field (GridField or scene), got "
                f"{type(mean).__name__}."
            )
        if not isinstance(box, TurbulenceBox):
            raise ValueError(
                f"FrozenTurbulence: `box` must be a TurbulenceBox, got {type(box).__name__}."
            )
        for name, value, shape in (("speed", speed, ()), ("direction", direction, ()),
                                   ("anchor", anchor, (3,)), ("shift", shift, ())):
            if is_concrete(value):
                v = np.asarray(value, dtype=np.float64)
                if v.shape != shape or not np.all(np.isfinite(v)):
                    raise ValueError(
                        f"FrozenTurbulence: `{name}` must be finite with shape {shape}, got "
                        f"{value!r}."
                    )
        dtype = mean.dtype
        self.mean = mean
        self.box = box if box.dtype == dtype else box.astype(dtype)
        self.speed = jnp.asarray(speed, dtype=dtype)
        self.direction = jnp.asarray(direction, dtype=dtype)
        self.anchor = jnp.asarray(anchor, dtype=dtype)
        if is_concrete(shift, box.spacing) and not isinstance(shift, jax.core.Tracer):
            length = box.shape[0] * float(np.asarray(box.spacing, np.float64)[0])
            shift = np.mod(np.asarray(shift, np.float64), length)
        self.shift = jnp.asarray(shift, dtype=dtype)

    @property
    def origin(self):
        return self.mean.origin

    @property
    def origin_lo(self):
        return self.mean.origin_lo

    def advanced(self, time) -> FrozenTurbulence:
        """The same field with its clock moved on by `time` seconds: sampling the result at
        ``t`` equals sampling this field at ``time + t``. A concrete `time` is reduced modulo
        the box length in float64 on the host (any absolute time, e.g. a record start a year
        in, in float32); a traced one in-graph as in `sample_local_at`."""
        if is_concrete(time, self.speed, self.shift, self.box.spacing):
            t = np.asarray(time, np.float64)
            if t.shape != () or not np.isfinite(t):
                raise ValueError(f"FrozenTurbulence.advanced: `time` must be one finite number of "
                                 f"seconds, got {time!r}.")
            length = self.box.shape[0] * float(np.asarray(self.box.spacing, np.float64)[0])
            new = np.mod(float(np.asarray(self.shift, np.float64))
                         + float(np.asarray(self.speed, np.float64)) * float(t), length)
            return eqx.tree_at(lambda f: f.shift, self, jnp.asarray(new, self.dtype))
        d = advected_distance(self.speed, jnp.asarray(time, self.dtype), self.box.length)
        return eqx.tree_at(lambda f: f.shift, self, self.shift + d)

    def axes(self) -> Float[Array, "3 3"]:
        """Rows ``e_x, e_y, e_z``: the box axes as unit vectors in the CFD frame."""
        ex = heading(self.direction, self.dtype)
        ez = jnp.array([0.0, 0.0, 1.0], self.dtype)
        ey = jnp.stack([-ex[1], ex[0], jnp.zeros((), self.dtype)])  # e_z x e_x
        return jnp.stack([ex, ey, ez])

    def fluctuation_at(self, points: Float[Array, "... 3"], time) -> Float[Array, "... 3"]:
        """The box's fluctuation (m/s, CFD frame) at field-local points and times (s)."""
        axes, shape, coords = self._box_coordinates(points, time)
        return rotate(axes.T, self.box.sample_box(*coords))

    def _box_coordinates(self, points, time):
        """The box axes (rows, CFD frame), the broadcast shape of points and times, and the
        box coordinates ``(xi, eta, zeta)`` (m) of field-local `points` at `time` (s)."""
        dtype = self.dtype
        points = jnp.asarray(points).astype(dtype)
        time = jnp.asarray(time)
        if not jnp.issubdtype(time.dtype, jnp.floating):
            time = time.astype(dtype)
        time = time.astype(dtype)
        axes = self.axes()
        local = rotate(axes, points - self.anchor)
        travelled = advected_distance(self.speed, time, self.box.length)
        shape = jnp.broadcast_shapes(local.shape[:-1], travelled.shape)
        xi = (local[..., 0] - self.shift) - travelled
        return axes, shape, tuple(jnp.broadcast_to(c, shape) for c in (xi, local[..., 1], local[..., 2]))

    @compiled
    def sample_local_at(self, points, time):
        """Velocity (m/s, CFD frame) at field-local points (m) and times (s, broadcastable to
        ``points.shape[:-1]``): the mean field plus the advected fluctuation. NaN where either
        is NaN (outside the mean field, or outside a non-periodic box laterally/vertically)."""
        return self.mean.sample_local_at(points, time) + self.fluctuation_at(points, time)

    @compiled
    def los_local_at(self, points, directions, time):
        """`sample_local_at` projected on unit `directions` (m/s): the mean field's LOS plus
        the box's, projected at the box cell's corners on the direction in box axes (the
        same number to rounding; one gather loop instead of one per component). NaN where
        either is NaN."""
        points = jnp.asarray(points).astype(self.dtype)
        directions = jnp.broadcast_to(jnp.asarray(directions).astype(self.dtype), points.shape)
        axes, shape, coords = self._box_coordinates(points, time)
        fluct = self.box.los_box(*coords, jnp.broadcast_to(rotate(axes, directions), shape + (3,)))
        return self.mean.los_local_at(points, directions, time) + fluct

    def sample_local(self, points):
        """The field at ``t = 0``."""
        return self.sample_local_at(points, jnp.zeros((), self.dtype))

    def time_sampler(self, points, directions=None, *, n_times=1):
        """Fixed points sampled at many times (`AbstractField.time_sampler`).

        A fixed point keeps its lateral and vertical box coordinates ``(eta, zeta)`` at every
        time; only ``xi`` moves with the advection. So the box is interpolated bilinearly in
        ``(y, z)`` once per point along its whole ``x`` period (one *line* of ``nx`` values,
        already projected on the point's direction for a LOS), and each time costs one
        linear interpolation in that line: the same trilinear value (to rounding) for two
        gathers instead of eight. The mean field is prepared the same way (steady: sampled
        once).

        Used when it pays and fits: ``2 n_times >= nx`` (the lines cost about ``nx`` gathers
        per point) and they take at most `LINE_BUDGET` numbers; otherwise every time is
        sampled directly."""
        points = jnp.asarray(points).astype(self.dtype)
        n_pts = int(np.prod(points.shape[:-1], dtype=np.int64))
        nx = self.box.shape[0]
        width = 1 if directions is not None else 3
        if 2 * int(n_times) < nx or n_pts * (nx + 1) * width > LINE_BUDGET:
            return super().time_sampler(points, directions, n_times=n_times)
        return _LineSampler.build(self, points, directions, n_times)


#: Most numbers (points x (nx + 1) x components) `FrozenTurbulence.time_sampler` holds in
#: lines along the wind (2^25: 256 MiB in float64) before it samples directly instead. Per
#: field: an ensemble vmapped over fields (`simulate_statistics(..., ensemble=True)`) holds
#: one set per member.
LINE_BUDGET = 2**25
#: Points per chunk when building lines (the build's (nx, chunk, 3) intermediate).
_LINE_CHUNK = 2048
#: Precision of the lines' projections: full float32 on GPUs, where a DEFAULT float32 `dot`
#: runs in TensorFloat-32 (10-bit mantissa: 5e-4 of the fluctuation off).
_FULL = jax.lax.Precision.HIGHEST


class _LineSampler(TimeSampler):
    """`FrozenTurbulence` at fixed points: per point, the box's fluctuation along the wind
    (bilinear in ``(y, z)``, CFD frame or projected on the point's direction), ``(P, nx + 1)``
    (``[..., 3]``) with the first node repeated last (periodic); at time ``t`` a linear
    interpolation at ``xi0 - U t`` (reduced modulo the box length as in `sample_local_at`)."""

    mean: TimeSampler
    lines: Float[Array, "p nx1 ..."]
    xi0: Float[Array, " p"]
    ok: Float[Array, " p"]
    dx: Float[Array, ""]
    speed: Float[Array, ""]
    length: Float[Array, ""]
    shape: tuple[int, ...] = eqx.field(static=True)

    @classmethod
    def build(cls, field: FrozenTurbulence, points, directions, n_times):
        box = field.box
        nx, ny, nz = box.shape
        lead = points.shape[:-1]
        axes = field.axes()
        local = rotate(axes, points - field.anchor).reshape(-1, 3)
        s = box.spacing
        iy0, iy1, fy, oky = box_axis(local[:, 1] / s[1] + (ny - 1) / 2, ny, box.periodic[0])
        iz0, iz1, fz, okz = box_axis(local[:, 2] / s[2], nz, box.periodic[1])
        vel = box.velocity
        n_pts = local.shape[0]
        if directions is not None:
            d = jnp.broadcast_to(jnp.asarray(directions).astype(points.dtype), points.shape)
            proj = rotate(axes, d).reshape(-1, 3)  # box-frame projection
        else:
            proj = jnp.zeros((n_pts, 3), vel.dtype)

        def lines_of(chunk):
            """Lines of a chunk of points: (nx, C, 3) cross-wind interpolation, projected."""
            jy0, jy1, gy, jz0, jz1, gz, c = chunk
            gy, gz = gy[None, :, None], gz[None, :, None]
            c0 = vel[:, jy0, jz0] * (1 - gz) + vel[:, jy0, jz1] * gz
            c1 = vel[:, jy1, jz0] * (1 - gz) + vel[:, jy1, jz1] * gz
            line = c0 * (1 - gy) + c1 * gy  # (nx, C, 3), box axes
            if directions is not None:
                return jnp.einsum("xpc,pc->px", line, c, precision=_FULL)  # (C, nx)
            return jnp.einsum("xpc,cj->pxj", line, axes, precision=_FULL)  # (C, nx, 3), CFD

        # in chunks of points, so the (nx, points, 3) intermediate stays small
        per = (iy0, iy1, fy, iz0, iz1, fz, proj)
        n_chunks = -(-n_pts // _LINE_CHUNK)
        if n_chunks <= 1:
            line = lines_of(per)
        else:
            pad = n_chunks * _LINE_CHUNK - n_pts
            per = tuple(jnp.pad(a, [(0, pad)] + [(0, 0)] * (a.ndim - 1)) for a in per)
            per = tuple(a.reshape((n_chunks, _LINE_CHUNK) + a.shape[1:]) for a in per)
            line = jax.lax.map(lines_of, per)
            line = line.reshape((n_chunks * _LINE_CHUNK,) + line.shape[2:])[:n_pts]
        line = jnp.concatenate([line, line[:, :1]], axis=1)
        mean = field.mean.time_sampler(points, directions, n_times=n_times)
        return cls(mean=mean, lines=line, xi0=local[:, 0] - field.shift, ok=oky & okz,
                   dx=s[0], speed=field.speed, length=box.length, shape=tuple(lead))

    def __call__(self, time):
        dtype = self.xi0.dtype
        time = jnp.asarray(time)
        if not jnp.issubdtype(time.dtype, jnp.floating):
            time = time.astype(dtype)
        time = time.astype(dtype)
        travelled = advected_distance(self.speed, time, self.length)
        shape = jnp.broadcast_shapes(travelled.shape, self.shape)
        xi0 = self.xi0.reshape(self.shape)
        s = (xi0 - travelled) / self.dx
        nx = self.lines.shape[1] - 1
        fl = jnp.floor(jnp.where(jnp.isfinite(s), s, 0))
        frac = s - fl
        i0 = jnp.mod(fl.astype(jnp.int32), nx)
        p = jnp.broadcast_to(jnp.arange(self.xi0.shape[0], dtype=jnp.int32).reshape(self.shape), shape)
        flat = p * (nx + 1) + jnp.broadcast_to(i0, shape)
        vector = self.lines.ndim == 3
        lines = self.lines.reshape((-1, 3) if vector else (-1,))
        v0 = lines.at[flat].get(mode="promise_in_bounds")
        v1 = lines.at[flat + 1].get(mode="promise_in_bounds")
        f = jnp.broadcast_to(frac, shape)
        f = f[..., None] if vector else f
        val = v0 * (1 - f) + v1 * f
        ok = jnp.broadcast_to(self.ok.reshape(self.shape), shape) & jnp.isfinite(
            jnp.broadcast_to(s, shape))
        ok = ok[..., None] if vector else ok
        return self.mean(time) + jnp.where(ok, val, jnp.nan)


def frozen_turbulence(mean, box, speed, direction, **kwargs) -> FrozenTurbulence:
    """Functional alias of `FrozenTurbulence` (same arguments)."""
    return FrozenTurbulence(mean, box, speed, direction, **kwargs)


__getattr__ = deprecated_getattr(__name__)
