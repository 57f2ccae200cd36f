"""Where the rotor and the lidar sample the wind, in the rotor frame of the control spectra.

**Rotor frame.** Origin at the hub centre; ``x`` along the rotor axis, positive *upstream*
(towards the lidar's measurements: a point at ``x = 160`` is 160 m in front of the rotor);
``z`` up; ``y`` completes a right-handed frame (to the left when looking upstream). Metres
throughout. A nacelle lidar on the hub looking upstream sits at the origin; its beams are the
lidarjax nacelle beams (`lidarjax.nacelle_4beam`, ``pitch=-90``) seen from the rotor.

- `RotorDisc` / `rotor_disc`: the points and weights of the rotor-effective wind speed
  (REWS), the disc mean of ``u`` (Task 52's square grid inside the radius, or a user's
  radial weighting).
- `LidarSamples` / `lidar_samples`: every point a lidar estimate of the REWS averages
  (beams or scan points times range-weighting nodes), with its beam direction, weight and
  age; `cone_points`: focus points on a cone about the rotor axis.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._precision import default_float, safe_sqrt

__all__ = ["LidarSamples", "RotorDisc", "cone_points", "lidar_samples", "rotor_disc"]


class RotorDisc(eqx.Module):
    """Points of the rotor disc and their weights in the REWS (build with `rotor_disc`).

    **Fields:**

    - `points`: ``(n, 2)`` lateral ``y`` and vertical ``z`` of each point from the hub (m).
    - `weights`: ``(n,)`` weights of the disc mean (sum 1).
    - `pair_distance`, `pair_weight`: every distinct distance between two points (m) and the
      summed product of the two points' weights at that distance (the double sum of ``S_RR``
      folded once on the host; the disc is fixed, not a design variable).
    - `radius`: the rotor radius (m).
    - `symmetric`: the points and weights are unchanged by ``y -> -y``, ``z -> -z`` and
      ``y <-> z`` (`rotor_disc`'s grids): the spectra then evaluate the disc's coherence once per
      class of lidar nodes those symmetries map onto each other (static).
    """

    points: Float[Array, "n 2"]
    weights: Float[Array, " n"]
    pair_distance: Float[Array, " m"]
    pair_weight: Float[Array, " m"]
    radius: Float[Array, ""]
    symmetric: bool = eqx.field(static=True, default=False)


def rotor_disc(radius: float, *, spacing: float = 8.0,
               weighting: Callable[[np.ndarray], np.ndarray] | None = None) -> RotorDisc:
    """The rotor disc as Task 52 samples it: a square grid of `spacing` centred on the hub,
    the points within `radius` (``sqrt(y^2 + z^2) <= radius``), equal weights.

    **Arguments:**

    - `radius`: rotor radius (m); 120 m for the IEA 15 MW, 63 m for the NREL 5 MW.
    - `spacing`: grid spacing (m). Task 52's IEA 15 MW grid, 8 m, gives 709 points.
    - `weighting`: optional radial weighting, a function of ``r / radius`` (numpy array in
      ``[0, 1]``) returning non-negative weights; the weights are normalised to sum 1.
      ``None``: the disc mean (equal weights).

    **Returns:** a `RotorDisc`. Built on the host (it sets shapes); not differentiable.
    """
    radius, spacing = float(radius), float(spacing)
    if not (np.isfinite(radius) and radius > 0):
        raise ValueError(f"rotor_disc: radius must be a finite positive number of metres, got {radius}")
    if not (np.isfinite(spacing) and 0 < spacing <= radius):
        raise ValueError(f"rotor_disc: spacing must be positive and at most the radius ({radius} m), "
                         f"got {spacing}")
    m = int(np.floor(radius / spacing + 1e-9))
    i, j = np.meshgrid(np.arange(-m, m + 1), np.arange(-m, m + 1), indexing="xy")
    keep = (i**2 + j**2) * spacing**2 <= radius**2 * (1 + 1e-12)
    i, j = i[keep], j[keep]
    r = np.hypot(i, j) * spacing / radius
    w = np.ones_like(r) if weighting is None else np.asarray(weighting(r), np.float64)
    if w.shape != r.shape or not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
        raise ValueError("rotor_disc: weighting must return finite non-negative weights, not all zero, "
                         "one per point (a numpy function of r / radius)")
    w = w / w.sum()
    d2 = (i[:, None] - i[None]) ** 2 + (j[:, None] - j[None]) ** 2
    folded = np.bincount(d2.ravel(), weights=np.outer(w, w).ravel())
    keep = np.nonzero(folded)[0]
    dtype = default_float()
    return RotorDisc(points=jnp.asarray(np.stack([i, j], 1) * spacing, dtype),
                     weights=jnp.asarray(w, dtype),
                     pair_distance=jnp.asarray(np.sqrt(keep) * spacing, dtype),
                     pair_weight=jnp.asarray(folded[keep], dtype),
                     radius=jnp.asarray(radius, dtype), symmetric=True)


class LidarSamples(eqx.Module):
    """Every point that a lidar's REWS estimate averages (build with `lidar_samples`).

    The estimate is ``sum_j weights_j * LOS_j / nx_j``: each line-of-sight speed divided by its
    beam's direction cosine to the rotor axis (Task 52's lidar data processing), the LOS of a
    beam or scan point being the range-weighted mean over its nodes.

    **Fields** (rotor frame, see the module docs):

    - `points`: ``(n, 3)`` position of each node (m), ``x`` upstream of the rotor.
    - `directions`: ``(n, 3)`` unit vector of its beam, from the lidar outwards.
    - `weights`: ``(n,)`` weight in the estimate (sum 1: range weights over beams).
    - `delays`: ``(n,)`` age of the measurement when the estimate is formed (s, >= 0).
    """

    points: Float[Array, "n 3"]
    directions: Float[Array, "n 3"]
    weights: Float[Array, " n"]
    delays: Float[Array, " n"]


def cone_points(distance: Float[ArrayLike, ""], half_cone: Float[ArrayLike, ""], n_points: int, *,
                azimuth_offset: Float[ArrayLike, ""] = 0.0) -> Float[Array, "b 3"]:
    """Focus points on a cone about the rotor axis, evenly spaced in azimuth.

    **Arguments:**

    - `distance`: upstream distance ``x`` of the focus plane from the lidar (m).
    - `half_cone`: half-cone angle between each beam and the rotor axis (degrees); the focus
      circle's radius is ``distance * tan(half_cone)``.
    - `n_points`: number of beams or scan points (static).
    - `azimuth_offset`: azimuth of the first point (degrees, from ``+y`` towards ``+z``).

    **Returns:** ``(n_points, 3)`` focus points in the rotor frame (m), the lidar at the
    origin. Differentiable in `distance`, `half_cone` and `azimuth_offset`.
    """
    if not isinstance(n_points, int | np.integer) or n_points < 1:
        raise ValueError(f"cone_points: n_points must be a positive integer, got {n_points!r}")
    return _cone_points(jnp.asarray(distance, default_float()), half_cone, azimuth_offset, int(n_points))


@functools.partial(jax.jit, static_argnums=3)
def _cone_points(x, half_cone, azimuth_offset, n_points):
    """`cone_points` as one compiled program (eagerly, each operation compiles on its own)."""
    rho = x * jnp.tan(jnp.deg2rad(half_cone))
    phi = jnp.deg2rad(azimuth_offset) + 2 * np.pi * jnp.arange(n_points, dtype=x.dtype) / n_points
    return jnp.stack([jnp.broadcast_to(x, phi.shape), rho * jnp.cos(phi), rho * jnp.sin(phi)], axis=1)


def _range_nodes(probe, offsets, offset_weights, ranges, dtype):
    if probe is not None:
        o, w = probe.nodes(ranges)
        return o.astype(dtype), w.astype(dtype)
    if offsets is None:
        return jnp.zeros(ranges.shape + (1,), dtype), jnp.ones(ranges.shape + (1,), dtype)
    o = offsets.astype(dtype)
    w = jnp.ones_like(o) if offset_weights is None else offset_weights.astype(dtype)
    return jnp.broadcast_to(o, ranges.shape + o.shape), jnp.broadcast_to(w, ranges.shape + o.shape)


def _check_samples(fp, probe, offsets, offset_weights, times):
    """`lidar_samples`' ValueErrors, from the shapes alone (before anything compiles)."""
    if fp.ndim != 2 or fp.shape[1] != 3:
        raise ValueError(f"lidar_samples: focus_points must be (b, 3) metres, got shape {fp.shape}")
    if probe is not None and (offsets is not None or offset_weights is not None):
        raise ValueError("lidar_samples: give either probe or offsets/offset_weights, not both")
    if offsets is None and offset_weights is not None:
        raise ValueError("lidar_samples: offset_weights needs offsets")
    if offsets is not None:
        o_shape = np.shape(offsets)
        w_shape = o_shape if offset_weights is None else np.shape(offset_weights)
        if len(o_shape) != 1 or w_shape != o_shape:
            raise ValueError(f"lidar_samples: offsets and offset_weights must be 1-D of one length, "
                             f"got {o_shape} and {w_shape}")
    if times is not None and np.shape(times) != (fp.shape[0],):
        raise ValueError(f"lidar_samples: times must be one per focus point ({fp.shape[0]},), "
                         f"got {np.shape(times)}")


def lidar_samples(focus_points: Float[ArrayLike, "b 3"], *,
                  lidar_position: Float[ArrayLike, " 3"] = (0.0, 0.0, 0.0),
                  probe=None, offsets: Float[ArrayLike, " q"] | None = None,
                  offset_weights: Float[ArrayLike, " q"] | None = None,
                  times: Float[ArrayLike, " b"] | None = None) -> LidarSamples:
    """The nodes a lidar's REWS estimate averages: each focus point's beam, range-weighted.

    **Arguments:**

    - `focus_points`: ``(b, 3)`` focus points of one full scan in the rotor frame (m), ``x``
      upstream (e.g. `cone_points`, or Task 52's ``Trajectory.x/y/z_L``).
    - `lidar_position`: ``(3,)`` the lidar in the rotor frame (m); the hub by default.
    - `probe`: a lidarjax probe (`lidarjax.PulsedProbe`, `lidarjax.CWProbe`): its
      quadrature nodes at each focus range weight the beam.
    - `offsets`, `offset_weights`: or a tabulated weighting, offsets along the beam from the
      focus (m, positive away from the lidar) and their weights (Task 52's ``a`` and
      ``f_L_d``); normalised per beam. Neither: a point measurement.
    - `times`: ``(b,)`` the time each focus point is measured within the scan (s); the
      estimate is formed at the last one, so each sample's delay is ``max(times) - times``.
      ``None``: all simultaneous (Task 52's analytic model).

    **Returns:** a `LidarSamples` with ``n = b * q`` nodes, each beam weighted ``1/b``.
    Differentiable in every number (positions, weights, the probe's lengths, times).
    """
    fp, position, offsets, offset_weights, times = (
        a if a is None or isinstance(a, jax.Array) else np.asarray(a)  # host: nothing compiles
        for a in (focus_points, lidar_position, offsets, offset_weights, times))
    dtype = fp.dtype if jnp.issubdtype(fp.dtype, jnp.floating) else default_float()
    _check_samples(fp, probe, offsets, offset_weights, times)
    return _samples(fp, position, probe, offsets, offset_weights, times, np.dtype(dtype))


@eqx.filter_jit
def _samples(fp, lidar_position, probe, offsets, offset_weights, times, dtype):
    """`lidar_samples` in one compiled program (checked inputs)."""
    fp, position = fp.astype(dtype), lidar_position.astype(dtype)
    rel = fp - position
    rng = safe_sqrt(jnp.sum(rel**2, axis=1))
    n = rel / rng[:, None]
    o, w = _range_nodes(probe, offsets, offset_weights, rng, dtype)
    w = w / jnp.sum(w, axis=1, keepdims=True) / fp.shape[0]
    pts = position + (rng[:, None] + o)[..., None] * n[:, None, :]
    if times is None:
        delay = jnp.zeros(fp.shape[0], dtype)
    else:
        t = times.astype(dtype)
        delay = jnp.max(t) - t
    q = o.shape[1]
    return LidarSamples(points=pts.reshape(-1, 3), directions=jnp.repeat(n, q, axis=0),
                        weights=w.reshape(-1), delays=jnp.repeat(delay, q))
