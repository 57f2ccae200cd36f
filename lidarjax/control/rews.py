"""The rotor-effective wind speed (REWS) of any lidarjax field, and a lidar's estimate of it
as IEA Wind Task 52's lidar data processing forms it.

**Frames.** The rotor frame of `geometry` (``x`` upstream along the rotor axis, ``z`` up)
placed in the field's (CFD) frame at the hub position `hub` (m) and facing `yaw`: the compass
direction the rotor faces, i.e. where the wind it is aligned with comes from (degrees,
clockwise from the CFD ``+y``, as lidarjax's meteorological wind directions: ``yaw = 270``
faces a westerly wind blowing along ``+x``). The longitudinal wind is the velocity's
component *downstream* along the rotor axis (m/s, positive through the rotor).

- `rotor_to_cfd`: the rotor frame's points and vectors in the CFD frame.
- `rotor_rews`: the disc mean (or a radially weighted mean, `rotor_disc`) of the longitudinal
  wind over the rotor, at given times (frozen turbulence and other time-dependent fields
  through ``sample_local_at``).
- `lidar_rews`: the lidar's estimate at given times: each node's line-of-sight speed, sampled
  at its own measurement time (``t - delay``), divided by its beam's direction cosine to the
  rotor axis, averaged with the range weights over the beams (Task 52's ``LDP_v1``
  ``WindFieldReconstruction``). It previews the REWS ``x / U`` ahead: compare ``lidar_rews(t)``
  with ``rotor_rews(t + x / U)``.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._util import compiled
from .geometry import LidarSamples, RotorDisc

__all__ = ["lidar_rews", "rotor_rews", "rotor_to_cfd"]


@compiled
def rotor_to_cfd(yaw: Float[ArrayLike, ""]) -> Float[Array, "3 3"]:
    """The rotation whose columns are the rotor frame's axes in the CFD frame: ``x``
    upstream ``(sin yaw, cos yaw, 0)``, ``y = z cross x``, ``z`` up; `yaw` in degrees."""
    a = jnp.deg2rad(yaw)
    s, c = jnp.sin(a), jnp.cos(a)
    zero, one = jnp.zeros_like(a), jnp.ones_like(a)
    return jnp.stack([jnp.stack([s, c, zero]), jnp.stack([-c, s, zero]), jnp.stack([zero, zero, one])], axis=1)


def _local(field, points):
    return points - (field.origin.astype(points.dtype) + field.origin_lo.astype(points.dtype))


@compiled
def rotor_rews(field, rotor: RotorDisc, *, hub: Float[ArrayLike, " 3"], yaw: Float[ArrayLike, ""],
               times: Float[ArrayLike, " t"]) -> Float[Array, " t"]:
    """The REWS of `field` over `rotor` at `hub` facing `yaw`, at `times` (s).

    **Arguments:** `field` (any lidarjax field, steady or time-dependent), `rotor`
    (`rotor_disc`: its weights make the disc mean or the user's radial weighting), `hub`
    (``(3,)`` CFD position of the hub, m), `yaw` (degrees, see the module docs), `times`
    (``(t,)`` s).

    **Returns:** ``(t,)`` REWS (m/s, the weighted mean of the longitudinal wind; NaN where a
    point lies outside the field). Differentiable in `hub`, `yaw` and the field's numbers.
    """
    rot = rotor_to_cfd(yaw)
    dtype = rot.dtype
    yz = rotor.points.astype(dtype)
    pts = jnp.asarray(hub, dtype) + yz[:, :1] * rot[:, 1] + yz[:, 1:] * rot[:, 2]
    t = jnp.asarray(times, dtype)
    v = field.sample_local_at(_local(field, pts)[None], t[:, None])
    u = jnp.broadcast_to(-jnp.sum(v * rot[:, 0], axis=-1), t.shape + pts.shape[:1])  # steady: (1, n)
    return u @ rotor.weights.astype(dtype)


@compiled
def lidar_rews(field, samples: LidarSamples, *, hub: Float[ArrayLike, " 3"], yaw: Float[ArrayLike, ""],
               times: Float[ArrayLike, " t"]) -> Float[Array, " t"]:
    """The lidar's REWS estimate at `times` (s), Task 52's processing (see the module docs).

    **Arguments:** `field`; `samples` (`lidar_samples`: nodes in the rotor frame, the lidar
    where they say); `hub` and `yaw` place the rotor frame in the field (m, degrees);
    `times` ``(t,)`` (s) when the estimate is formed.

    **Returns:** ``(t,)`` estimate (m/s): ``sum_j w_j (-LOS_j) / nx_j``, ``LOS_j`` the velocity
    at node ``j`` and time ``t - delay_j`` projected on its beam (positive away from the
    lidar, so a headwind is negative), ``nx_j`` the beam's cosine to the upstream rotor axis.
    Differentiable in every number of `samples`, `hub`, `yaw` and the field.
    """
    rot = rotor_to_cfd(yaw)
    dtype = rot.dtype
    pts = jnp.asarray(hub, dtype) + samples.points.astype(dtype) @ rot.T
    dirs = samples.directions.astype(dtype) @ rot.T
    t = jnp.asarray(times, dtype)[:, None] - samples.delays.astype(dtype)[None]
    los = jnp.broadcast_to(field.los_local_at(_local(field, pts)[None], dirs[None], t), t.shape)
    u_est = -los / samples.directions[:, 0].astype(dtype)
    return u_est @ samples.weights.astype(dtype)
