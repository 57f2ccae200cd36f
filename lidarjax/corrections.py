"""Correction factors of the seed (section 3.4 and its listing), safely defined.

All vectors are in the north frame, m/s. Speeds are horizontal. For each height:

- to the free stream: ``cff_u = u_free / u_lidar``, ``cff_v = v_free / v_lidar``,
  ``cff_w = (w_free - w_lidar) / U_free`` (equation 20; 21 for ``w_free = 0``),
  ``cff_U = U_free / U_lidar``, ``cff_th = theta_free - theta_lidar``;
- to the point above the lidar: ``cfp_u = u_point / u_lidar``, ``cfp_v``, ``cfp_w`` likewise,
  ``cfp_U = U_point / U_lidar``, ``cfp_th = theta_point - theta_lidar``.

So ``u_free = cff_u * u_lidar``, ``w_free = w_lidar + cff_w * U_free`` and
``theta_free = theta_lidar + cff_th``. Direction addends are in degrees, wrapped to
``(-180, 180]`` and computed without subtracting wrapped angles (no 0/360 artefact); they
equally hold for meteorological and seed azimuths (both are clockwise).

The seed divides blindly. Here a ratio whose denominator is smaller in magnitude than
``ratio_tol`` times the 3-D speed of the lidar vector (``|V_lidar|``) is NaN, never inf or
a huge value; ``cff_w`` is NaN when ``U_free`` is zero. The seed normalises ``cff_w`` by the
3-D free-stream magnitude; lidarjax uses the horizontal one, identical for the seed's
horizontal free streams and the right scale for the horizontal ``cff_U``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .angles import direction_difference, horizontal_speed

__all__ = ["correction_factors", "DEFAULT_RATIO_TOL"]

#: Default relative tolerance for ratio denominators: ratios are bounded by about
#: ``1 / DEFAULT_RATIO_TOL`` in magnitude.
DEFAULT_RATIO_TOL = 1e-4


def _norm(v):
    """3-D norm, zero where its square underflows (so its own gradient stays finite)."""
    sq = jnp.sum(v * v, axis=-1)
    pos = sq > jnp.finfo(sq.dtype).tiny
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, sq, 1.0)), 0.0)


def safe_ratio(num, den, scale, tol):
    """``num / den``, NaN unless ``scale > 0`` and ``|den| > tol * scale``.

    Both are divided by `scale` first, so the derivative never squares a tiny denominator;
    `scale` is held constant under differentiation (the ratio does not depend on it, and
    through it the reverse pass would square ``1 / scale``: beyond float32's range at
    1e-19 m/s).
    """
    ok = (scale > 0) & (jnp.abs(den) > tol * scale)
    s = jax.lax.stop_gradient(jnp.where(ok, scale, 1.0))
    safe = jnp.where(ok, den / s, 1.0)
    return jnp.where(ok, (num / s) / safe, jnp.nan)


def correction_factors(
    lidar: Float[Array, "h 3"],
    point: Float[Array, "h 3"] | None,
    free: Float[Array, 3] | None,
    ratio_tol: float | Float[Array, ""] = DEFAULT_RATIO_TOL,
) -> dict[str, Float[Array, " h"] | None]:
    """The ten correction factors (``None`` for those whose reference is not given).

    **Arguments:**

    - `lidar`: ``(h, 3)`` reconstructed vectors, north frame, m/s.
    - `point`: ``(h, 3)`` true velocity above the lidar, north frame, or None.
    - `free`: ``(3,)`` free-stream velocity, north frame, or None.
    - `ratio_tol`: relative denominator tolerance (see module docs).

    **Returns:** a dict ``name -> (h,)`` with keys ``cff_u, cff_v, cff_w, cff_U, cff_th,
    cfp_u, cfp_v, cfp_w, cfp_U, cfp_th``; ratios dimensionless, addends in degrees.
    """
    out: dict[str, Float[Array, " h"] | None] = {}
    scale = _norm(lidar)
    u_l = horizontal_speed(lidar)
    names = ("cff_u", "cff_v", "cff_w", "cff_U", "cff_th")
    if free is None:
        out.update(dict.fromkeys(names))
    else:
        free_b = jnp.broadcast_to(free, lidar.shape)
        u_f = horizontal_speed(free_b)
        out["cff_u"] = safe_ratio(free_b[..., 0], lidar[..., 0], scale, ratio_tol)
        out["cff_v"] = safe_ratio(free_b[..., 1], lidar[..., 1], scale, ratio_tol)
        out["cff_w"] = safe_ratio(free_b[..., 2] - lidar[..., 2], u_f, u_f, 0.0)
        out["cff_U"] = safe_ratio(u_f, u_l, scale, ratio_tol)
        out["cff_th"] = direction_difference(free_b, lidar)
    names = ("cfp_u", "cfp_v", "cfp_w", "cfp_U", "cfp_th")
    if point is None:
        out.update(dict.fromkeys(names))
    else:
        out["cfp_u"] = safe_ratio(point[..., 0], lidar[..., 0], scale, ratio_tol)
        out["cfp_v"] = safe_ratio(point[..., 1], lidar[..., 1], scale, ratio_tol)
        out["cfp_w"] = safe_ratio(point[..., 2], lidar[..., 2], scale, ratio_tol)
        out["cfp_U"] = safe_ratio(horizontal_speed(point), u_l, scale, ratio_tol)
        out["cfp_th"] = direction_difference(point, lidar)
    return out
