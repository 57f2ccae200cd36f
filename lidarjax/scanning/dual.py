"""Dual-Doppler: horizontal wind vectors where two scanning lidars' beams cross.

Two lidars (two `lidarjax.Mount`s) look at the same points ``p`` (CFD metres). Lidar ``j``
sees ``los_j = n_j . V`` along its unit vector ``n_j`` towards ``p``; with the vertical wind
``w`` given (0 by default, the usual assumption for low elevations), the horizontal wind
``(u, v)`` solves the 2x2 system

    ``[[n_ax, n_ay], [n_bx, n_by]] (u, v) = (los_a - n_az w, los_b - n_bz w)``.

Its condition number (ratio of the singular values) is ``cot(beta / 2)`` for level beams
crossing at an angle ``beta`` (below 90 degrees; ``tan(beta / 2)`` above): errors in the LOS
reach the wind amplified by it. Points where the beams cross at less than 30 degrees (or more
than 150), condition number above `DUAL_ILL_CONDITIONED` ``= cot(15 deg) = 3.73``, are flagged
`lidarjax.InverseFlag.ILL_CONDITIONED` (the usual dual-Doppler criterion; Stawiarski et al.
2013, "Scopes and challenges of dual-Doppler lidar wind measurements - an error analysis",
J. Atmos. Oceanic Technol. 30, 2044-2062); parallel beams (determinant 0) give NaN. All
frames are the CFD frame (``+x`` east, ``+y`` north in a scene whose ``+y`` is north).

- `crossing_geometry`: each lidar's azimuth, elevation (its own body frame, degrees, as in
  `lidarjax.scanning.ScanPattern`) and range to the points: the stare each lidar is steered to.
- `dual_doppler`: the 2x2 solve from LOS and directions.
- `simulate_dual_doppler`: both lidars' LOS at the points (probe per gate), then the solve.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int

from .._precision import difference, is_concrete, safe_sqrt
from ..beam import beam_los
from ..field import AbstractField
from ..flags import InverseFlag
from ..frames import body_to_cfd_rotation, rotate
from ..mount import Mount
from ..probe import AbstractProbe, PointProbe, probe_for_ranges

__all__ = ["DualDoppler", "CrossingGeometry", "crossing_geometry", "dual_doppler",
           "simulate_dual_doppler", "DUAL_ILL_CONDITIONED"]

#: Condition number of the 2x2 solve above which a point is flagged: beams crossing at less
#: than 30 degrees (``cot(15 deg)``).
DUAL_ILL_CONDITIONED = float(1.0 / np.tan(np.deg2rad(15.0)))


class CrossingGeometry(eqx.Module):
    """Where each lidar must look to reach the points (``p`` points): `azimuth_a`,
    `elevation_a`, `range_a` (degrees in lidar a's body frame, m) and the same for b;
    `direction_a`, `direction_b` ``(p, 3)`` unit vectors (CFD frame) towards the points;
    `crossing_angle` ``(p,)`` degrees between the beams."""

    azimuth_a: Float[Array, " p"]
    elevation_a: Float[Array, " p"]
    range_a: Float[Array, " p"]
    azimuth_b: Float[Array, " p"]
    elevation_b: Float[Array, " p"]
    range_b: Float[Array, " p"]
    direction_a: Float[Array, "p 3"]
    direction_b: Float[Array, "p 3"]
    crossing_angle: Float[Array, " p"]


class DualDoppler(eqx.Module):
    """Dual-Doppler result per point: `velocity` ``(p, 3)`` (CFD frame, m/s; ``w`` as
    given), `condition` ``(p,)`` of the 2x2 solve, `flags` ``(p,)`` int32 `InverseFlag`
    bits, and the LOS used, `los_a`, `los_b` ``(p,)`` m/s."""

    velocity: Float[Array, "p 3"]
    condition: Float[Array, " p"]
    flags: Int[Array, " p"]
    los_a: Float[Array, " p"]
    los_b: Float[Array, " p"]


def _look(mount, points, dtype):
    d = points - (mount.location.astype(dtype) + mount.location_lo.astype(dtype))
    rng = jnp.linalg.norm(d, axis=-1)
    n = d / rng[..., None]
    body = rotate(body_to_cfd_rotation(mount).T, n)
    az = jnp.mod(jnp.rad2deg(jnp.arctan2(body[..., 0], body[..., 1])), 360.0)
    el = jnp.rad2deg(jnp.arcsin(jnp.clip(body[..., 2], -1, 1)))
    return az, el, rng, n


def crossing_geometry(mount_a: Mount, mount_b: Mount,
                      points: Float[ArrayLike, "p 3"]) -> CrossingGeometry:
    """Steering of two lidars to `points` (CFD metres): see `CrossingGeometry`."""
    points = jnp.atleast_2d(jnp.asarray(points))
    if not jnp.issubdtype(points.dtype, jnp.floating):
        points = points.astype(jnp.result_type(float))
    if points.shape[-1] != 3 or points.ndim != 2:
        raise ValueError(f"crossing_geometry: `points` must be (p, 3) CFD metres, got {points.shape}.")
    return _geometry_jit(mount_a, mount_b, points)


def _geometry(mount_a, mount_b, points):
    dtype = points.dtype
    with jax.default_matmul_precision("highest"):
        aa, ea, ra, na = _look(mount_a, points, dtype)
        ab, eb, rb, nb = _look(mount_b, points, dtype)
    cos = jnp.clip(jnp.sum(na * nb, axis=-1), -1, 1)
    return CrossingGeometry(aa, ea, ra, ab, eb, rb, na, nb, jnp.rad2deg(jnp.arccos(cos)))


_geometry_jit = jax.jit(_geometry)


def dual_doppler(los_a: Float[ArrayLike, " p"], los_b: Float[ArrayLike, " p"],
                 direction_a: Float[ArrayLike, "p 3"], direction_b: Float[ArrayLike, "p 3"], *,
                 w: Float[ArrayLike, " p"] = 0.0) -> DualDoppler:
    """Horizontal wind from two LOS per point (module docs): `los_a`, `los_b` (m/s, positive
    away from each lidar), unit `direction_a`, `direction_b` (CFD frame) from each lidar to
    the point, vertical wind `w` (m/s) assumed. Differentiable; NaN LOS or parallel beams
    give NaN (flag ``TOO_FEW_BEAMS`` / ``ILL_CONDITIONED``)."""
    los_a, los_b = jnp.asarray(los_a), jnp.asarray(los_b)
    dtype = jnp.result_type(los_a, los_b, float)
    return _dual_jit(los_a.astype(dtype), los_b.astype(dtype), jnp.asarray(direction_a, dtype),
                     jnp.asarray(direction_b, dtype), jnp.asarray(w, dtype))


def _dual(los_a, los_b, na, nb, w):
    ya = los_a - na[..., 2] * w
    yb = los_b - nb[..., 2] * w
    m11, m12, m21, m22 = na[..., 0], na[..., 1], nb[..., 0], nb[..., 1]
    det = m11 * m22 - m12 * m21
    frob = m11**2 + m12**2 + m21**2 + m22**2
    finite = jnp.isfinite(ya) & jnp.isfinite(yb)
    # Singular values of a 2x2 matrix: s_max, s_min = (p +- q) / 2 with
    # p = |(m11 + m22, m12 - m21)|, q = |(m11 - m22, m12 + m21)|, and p^2 - q^2 = 4 det, so
    # cond = (p + q) / (p - q) = (p + q)^2 / (4 |det|): no cancellation anywhere (the textbook
    # sqrt(F^2 - 4 det^2) loses half the digits as cond -> 1: 1.5e-8 off at 90 degrees in
    # float64, and whether it lands on 0 depends on how the compiler rounds).
    # (safe_sqrt, not jnp.hypot, whose gradient is NaN at the orthogonal crossing's q = 0)
    p = safe_sqrt((m11 + m22) ** 2 + (m12 - m21) ** 2)
    q = safe_sqrt((m11 - m22) ** 2 + (m12 + m21) ** 2)
    solvable = jnp.abs(det) > 1e-12 * jnp.maximum(frob, 1e-300)
    ok = finite & solvable
    cond = (p + q) ** 2 / (4 * jnp.abs(jnp.where(solvable, det, 1)))
    det_safe = jnp.where(ok, det, 1)
    ya_s, yb_s = jnp.where(ok, ya, 0), jnp.where(ok, yb, 0)
    u = (m22 * ya_s - m12 * yb_s) / det_safe
    v = (-m21 * ya_s + m11 * yb_s) / det_safe
    vel = jnp.stack([u, v, jnp.broadcast_to(w, u.shape)], axis=-1)
    flags = jnp.where(finite, 0, int(InverseFlag.TOO_FEW_BEAMS))
    flags |= jnp.where(~solvable | (cond > DUAL_ILL_CONDITIONED), int(InverseFlag.ILL_CONDITIONED), 0)
    return DualDoppler(velocity=jnp.where(ok[..., None], vel, jnp.nan),
                       condition=jnp.where(solvable, cond, jnp.inf), flags=flags.astype(jnp.int32),
                       los_a=los_a, los_b=los_b)


_dual_jit = jax.jit(_dual)


def simulate_dual_doppler(field: AbstractField, mount_a: Mount, mount_b: Mount,
                          points: Float[ArrayLike, "p 3"], *, probe: AbstractProbe | None = None,
                          w: Float[ArrayLike, " p"] = 0.0) -> tuple[DualDoppler, CrossingGeometry]:
    """Both lidars staring at `points` (CFD metres), each gate centred on the point with the
    range weighting `probe` (default a point), and the dual-Doppler solve with the true
    directions. Returns ``(DualDoppler, CrossingGeometry)``. Jit-compiled, differentiable."""
    probe = PointProbe() if probe is None else probe
    if not isinstance(field, AbstractField):
        raise ValueError(f"simulate_dual_doppler: `field` must be a lidarjax field, got "
                         f"{type(field).__name__}.")
    for name, m in (("mount_a", mount_a), ("mount_b", mount_b)):
        if not isinstance(m, Mount) or m.batch_shape:
            raise ValueError(f"simulate_dual_doppler: `{name}` must be one lidarjax.Mount.")
    geo = crossing_geometry(mount_a, mount_b, points)
    if not isinstance(probe, PointProbe) and is_concrete(geo.range_a, geo.range_b):
        rng = np.concatenate([np.asarray(geo.range_a), np.asarray(geo.range_b)])
        probe = probe_for_ranges(probe, field.resolution, rng, caller="simulate_dual_doppler")
    pts = jnp.atleast_2d(jnp.asarray(points)).astype(field.dtype)
    return _simulate_dual_jit(field, mount_a, mount_b, pts, probe, jnp.asarray(w, field.dtype))


def _simulate_dual(field, mount_a, mount_b, points, probe, w):
    dtype = field.dtype
    geo = _geometry(mount_a, mount_b, points)
    los = []
    for mount, n, rng in ((mount_a, geo.direction_a, geo.range_a),
                          (mount_b, geo.direction_b, geo.range_b)):
        origin = difference(mount.location, mount.location_lo, field.origin, field.origin_lo, dtype)
        los.append(beam_los(field, origin, n, rng[None, :], probe)[0][0])
    return _dual(los[0], los[1], geo.direction_a, geo.direction_b, w), geo


_simulate_dual_jit = jax.jit(_simulate_dual)
