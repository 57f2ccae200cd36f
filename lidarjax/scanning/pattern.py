"""A scanning lidar's scan: rays (beam directions and their timing) sampled at range gates.

A `ScanPattern` is one repetition of a scan (dimensions: ``r`` rays, ``g`` range gates, ``k``
sub-rays):

- ray ``i`` points at `azimuth` ``a_i`` and `elevation` ``e_i`` (degrees) at the middle of its
  accumulation, which starts at `ray_start` ``t_i`` (s from the start of the scan) and lasts
  `accumulation` ``T_i`` (s);
- during the accumulation the head turns at `azimuth_rate` and `elevation_rate` (deg/s): 0 for
  step-and-stare (the head stops, then accumulates), the sweep speed for a continuous sweep;
- every ray is sampled at the same range gates, gate centres `ranges` (m along the beam);
- `period` (s) is the time from the start of one repetition of the scan to the next (the
  last ray's end plus the head's return or turn-around).

**Angles.** Directions are relative to the mount, in the lidar's body frame of
`lidarjax.frames`: azimuth clockwise from the body ``+y`` axis (north for a level mount with
``beta + gamma - psi = 0`` in a scene whose ``+y`` is north), elevation above the body's
``x-y`` plane (the horizon of a level mount). The unit vector is ``(cos e sin a, cos e cos a,
sin e)``; `lidarjax.Mount` turns and tilts it into the CFD frame exactly as the profilers'
beams (pitch and roll, the nacelle's ``pitch = -90``). An elevation above 90 degrees looks over
the top (an RHI from horizon to horizon).

**A moving beam averages over its arc.** A pulsed lidar averages the spectra of all pulses of
a ray; while the head turns, the pulses sample the arc swept during the accumulation. The
model averages `n_sub` sub-rays (static) at the midpoints of equal slices of the
accumulation, ``tau_j = ((j + 1/2) / n_sub - 1/2) T_i``, each at the angles ``a_i + rate_a
tau_j``, ``e_i + rate_e tau_j`` and (in time) at the time ``t_i + T_i / 2 + tau_j``. For a
LOS varying as ``cos`` of the azimuth (uniform flow) over a swept arc ``D = rate T`` the
midpoint rule gives ``sin(D/2) / (n_sub sin(D / (2 n_sub)))`` of the centre ray's LOS where
the continuous average gives ``sin(D/2) / (D/2)``: about ``D^2 / (24 n_sub^2)`` apart (one
sub-ray: 1.3e-5 for a 1-degree arc, 1.1e-2 for 30 degrees; `suggest_sub_rays`).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._precision import default_float, is_concrete
from .._util import compiled

__all__ = ["ScanPattern", "ray_unit_vectors", "suggest_sub_rays", "gate_ranges"]


@compiled
def ray_unit_vectors(azimuth_deg: Float[ArrayLike, ...],
                     elevation_deg: Float[ArrayLike, ...]) -> Float[Array, "... 3"]:
    """Unit vectors ``(cos e sin a, cos e cos a, sin e)`` in the lidar's body frame for
    azimuths (degrees clockwise from body ``+y``) and elevations (degrees above the body's
    horizon)."""
    a, e = jnp.broadcast_arrays(jnp.deg2rad(jnp.asarray(azimuth_deg)),
                                jnp.deg2rad(jnp.asarray(elevation_deg)))
    ce = jnp.cos(e)
    return jnp.stack([ce * jnp.sin(a), ce * jnp.cos(a), jnp.sin(e)], axis=-1)


def gate_ranges(n_gates: int, gate_length: float, *, first: float | None = None) -> np.ndarray:
    """Gate-centre ranges (m): ``first + i * gate_length``; `first` defaults to half a gate
    (Halo StreamLine: ``(i + 1/2) * gate_length``)."""
    if int(n_gates) != n_gates or n_gates < 1:
        raise ValueError(f"gate_ranges: n_gates must be a positive integer, got {n_gates!r}.")
    if not (np.isfinite(gate_length) and gate_length > 0):
        raise ValueError(f"gate_ranges: gate_length must be positive metres, got {gate_length!r}.")
    first = 0.5 * gate_length if first is None else float(first)
    return first + np.arange(int(n_gates)) * float(gate_length)


def suggest_sub_rays(swept_deg: float, tol: float = 1e-4) -> int:
    """Fewest sub-rays whose midpoint average of ``cos`` over an arc of `swept_deg` degrees
    is within relative `tol` of the continuous average (``D^2 / (24 n^2) <= tol``)."""
    d = np.deg2rad(abs(float(swept_deg)))
    return max(1, int(np.ceil(d / np.sqrt(24.0 * tol))))


def _float(value, shape=None):
    value = jnp.asarray(value)
    if not jnp.issubdtype(value.dtype, jnp.floating):
        value = value.astype(default_float())
    if shape is not None:
        value = jnp.broadcast_to(value, shape)
    return value


class ScanPattern(eqx.Module):
    """One repetition of a scan: rays with their timing, sampled at range gates.

    **Arguments:**

    - `azimuth`, `elevation`: ``(r,)`` ray directions at mid-accumulation, degrees (body
      frame; see the module docs).
    - `ranges`: ``(g,)`` gate-centre ranges along the beam, m (positive, finite).
    - `ray_start`: ``(r,)`` start of each ray's accumulation, s from the scan start
      (non-decreasing).
    - `accumulation`: ``(r,)`` or one accumulation time per ray, s (positive).
    - `azimuth_rate`, `elevation_rate`: ``(r,)`` or one head rate during accumulation, deg/s
      (0: step-and-stare).
    - `period`: seconds from one repetition's start to the next; default the last ray's end.
    - `n_sub`: sub-rays averaged per ray (static; see the module docs and
      `suggest_sub_rays`). Default 1 (the centre ray).
    - `kind`: a label (``"ppi"``, ``"rhi"``, ``"stare"``, ``"vad"``, ``"rosette"``,
      ``"custom"``), static, used by plots and writers.

    Every number is dynamic and differentiable; `n_sub` and `kind` are static, as are the
    counts ``r`` and ``g`` (shapes). Raises `ValueError` for inconsistent shapes or, for
    concrete inputs, non-finite or out-of-range values.
    """

    azimuth: Float[Array, " r"]
    elevation: Float[Array, " r"]
    ranges: Float[Array, " g"]
    ray_start: Float[Array, " r"]
    accumulation: Float[Array, " r"]
    azimuth_rate: Float[Array, " r"]
    elevation_rate: Float[Array, " r"]
    period: Float[Array, ""]
    n_sub: int = eqx.field(static=True)
    kind: str = eqx.field(static=True)

    def __init__(self, azimuth, elevation, ranges, *, ray_start, accumulation,
                 azimuth_rate=0.0, elevation_rate=0.0, period=None, n_sub: int = 1,
                 kind: str = "custom"):
        if int(n_sub) != n_sub or int(n_sub) < 1:
            raise ValueError(f"ScanPattern: n_sub must be a positive integer, got {n_sub!r}.")
        az_shape, el_shape = np.shape(azimuth), np.shape(elevation)
        if len(az_shape) != 1 or az_shape[0] == 0 or el_shape not in ((), az_shape):
            raise ValueError(f"ScanPattern: `azimuth` must be (r,) degrees (r >= 1) and `elevation` "
                             f"(r,) or one angle; got shapes {az_shape} and {el_shape}.")
        r = az_shape[0]
        if len(np.shape(ranges)) != 1 or np.shape(ranges)[0] == 0:
            raise ValueError(f"ScanPattern: `ranges` must be (g,) gate-centre ranges in m, got shape "
                             f"{np.shape(ranges)}.")
        for name, val in (("ray_start", ray_start), ("accumulation", accumulation),
                          ("azimuth_rate", azimuth_rate), ("elevation_rate", elevation_rate)):
            if np.shape(val) not in ((), (r,)):
                raise ValueError(f"ScanPattern: `{name}` must be one value or one per ray ({r},), "
                                 f"got shape {np.shape(val)}.")
        if is_concrete(azimuth, elevation, ranges, ray_start, accumulation, azimuth_rate,
                       elevation_rate, period):
            _check(azimuth, elevation, ranges, ray_start, accumulation, azimuth_rate,
                   elevation_rate, period)
        self.azimuth = _float(azimuth)
        self.elevation = _float(elevation, (r,))
        self.ranges = _float(ranges)
        self.ray_start = _float(ray_start, (r,))
        self.accumulation = _float(accumulation, (r,))
        self.azimuth_rate = _float(azimuth_rate, (r,))
        self.elevation_rate = _float(elevation_rate, (r,))
        if period is None:
            period = jnp.max(self.ray_start + self.accumulation)
        self.period = _float(period)
        self.n_sub = int(n_sub)
        self.kind = str(kind)

    @property
    def n_rays(self) -> int:
        return self.azimuth.shape[0]

    @property
    def n_gates(self) -> int:
        return self.ranges.shape[0]

    def ray_times(self) -> Float[Array, " r"]:
        """Mid-accumulation time of every ray, s from the scan start."""
        return self.ray_start + self.accumulation / 2

    def sub_offsets(self) -> Float[Array, "r k"]:
        """Time of each sub-ray relative to its ray's middle, s: midpoints of `n_sub` equal
        slices of the accumulation."""
        frac = (jnp.arange(self.n_sub, dtype=self.accumulation.dtype) + 0.5) / self.n_sub - 0.5
        return self.accumulation[:, None] * frac[None, :]

    @compiled
    def sub_angles(self) -> tuple[Float[Array, "r k"], Float[Array, "r k"]]:
        """Azimuth and elevation (degrees) of every sub-ray."""
        tau = self.sub_offsets()
        return (self.azimuth[:, None] + self.azimuth_rate[:, None] * tau,
                self.elevation[:, None] + self.elevation_rate[:, None] * tau)

    @compiled
    def sub_times(self) -> Float[Array, "r k"]:
        """Time of every sub-ray, s from the scan start."""
        return self.ray_times()[:, None] + self.sub_offsets()

    def directions(self) -> Float[Array, "r 3"]:
        """Body-frame unit vectors of the rays at mid-accumulation."""
        return ray_unit_vectors(self.azimuth, self.elevation)

    @compiled
    def sub_directions(self) -> Float[Array, "r k 3"]:
        """Body-frame unit vectors of every sub-ray."""
        return ray_unit_vectors(*self.sub_angles())

    def swept(self) -> Float[Array, " r"]:
        """Angle each ray sweeps during its accumulation, degrees (great-circle, small-arc
        approximation ``T sqrt((rate_a cos e)^2 + rate_e^2)``)."""
        ce = jnp.cos(jnp.deg2rad(self.elevation))
        return self.accumulation * jnp.hypot(self.azimuth_rate * ce, self.elevation_rate)

    def repeated(self, n: int) -> ScanPattern:
        """The pattern repeated `n` times back to back (every `period`), one pattern of
        ``n * r`` rays."""
        n = int(n)
        if n < 1:
            raise ValueError(f"ScanPattern.repeated: n must be a positive integer, got {n}.")
        t = (self.ray_start[None, :] + self.period * jnp.arange(n)[:, None]).reshape(-1)
        tile = lambda a: jnp.tile(a, n)  # noqa: E731
        return ScanPattern(tile(self.azimuth), tile(self.elevation), self.ranges, ray_start=t,
                           accumulation=tile(self.accumulation),
                           azimuth_rate=tile(self.azimuth_rate),
                           elevation_rate=tile(self.elevation_rate), period=n * self.period,
                           n_sub=self.n_sub, kind=self.kind)


def _check(azimuth, elevation, ranges, ray_start, accumulation, azimuth_rate, elevation_rate,
           period):
    arrays = {"azimuth": azimuth, "elevation": elevation, "ranges": ranges,
              "ray_start": ray_start, "accumulation": accumulation,
              "azimuth_rate": azimuth_rate, "elevation_rate": elevation_rate}
    for name, val in arrays.items():
        v = np.asarray(val, np.float64)
        if not np.all(np.isfinite(v)):
            raise ValueError(f"ScanPattern: `{name}` must be finite, got {v.tolist()[:8]}.")
    rng = np.asarray(ranges, np.float64)
    if np.any(rng <= 0):
        raise ValueError(f"ScanPattern: `ranges` must be positive metres along the beam, got "
                         f"{rng.min()} m.")
    acc = np.asarray(accumulation, np.float64)
    if np.any(acc <= 0):
        raise ValueError("ScanPattern: `accumulation` must be positive seconds per ray.")
    start = np.asarray(ray_start, np.float64)
    if start.ndim and np.any(np.diff(start) < 0):
        k = int(np.argmax(np.diff(start) < 0))
        raise ValueError(f"ScanPattern: `ray_start` must not decrease (ray {k + 1} starts at "
                         f"{start[k + 1]} s before ray {k} at {start[k]} s).")
    if period is not None:
        p = np.asarray(period, np.float64)
        end = float(np.max(start + acc))
        if p.shape != () or not np.isfinite(p) or p < end - 1e-9 * max(1.0, end):
            raise ValueError(f"ScanPattern: `period` must be one number of seconds at least the "
                             f"last ray's end ({end:g} s), got {period!r}.")
