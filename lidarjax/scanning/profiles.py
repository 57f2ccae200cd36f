"""VAD / DBS wind profiles from the rays of a PPI, VAD or DBS scan at any elevation.

Per range gate, the wind ``V = (u, v, w)`` (m/s; ``u`` along the instrument's azimuth 90,
``v`` along azimuth 0, ``w`` up: east, north, up for an instrument aligned to north) that
minimises ``sum_r (n_r . V - los_rg)^2`` over the rays ``r`` whose LOS is finite, with ray unit
vectors ``n_r = (cos e sin a, cos e cos a, sin e)``. At one elevation over evenly spaced
azimuths this is the classic sine fit ``los = A sin a + B cos a + C`` (``u = A / cos e``,
``v = B / cos e``, ``w = C / sin e``; Browning and Wexler 1968); any elevations and azimuths
are allowed as long as they determine the three components.

Conditioning is reported per gate: the condition number ``sqrt(lambda_max / lambda_min)`` of
the normal matrix ``sum_r n_r n_r^T`` (that of the ray matrix), flagged above
`lidarjax.scan.ILL_CONDITIONED` (100: a PPI at an elevation of 89.2 degrees, or a sector of a
few degrees); rays that do not span 3-D (a sector at one elevation narrower than the float
rounding resolves) give NaN with that flag. Gates with fewer than 3 finite rays are NaN
(`lidarjax.InverseFlag.TOO_FEW_BEAMS`).
Gradients are finite everywhere (the safe-mask pattern): gates left NaN never meet arithmetic.

A gate of a ray at elevation ``e`` lies at height ``range * sin(e)``; the fit combines the rays
at the same gate index (same range), so rays of different elevations (a DBS with a vertical
beam) mix heights: `VadProfile.heights` is ``range`` times the mean ``sin e``.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float, Int

from .._precision import safe_sqrt
from ..angles import horizontal_speed
from ..flags import InverseFlag
from ..scan import ILL_CONDITIONED
from .pattern import ray_unit_vectors

__all__ = ["VadProfile", "vad_fit"]


class VadProfile(eqx.Module):
    """A VAD/DBS profile per gate (leading axes of the LOS kept, ``g`` gates).

    - `velocity`: ``(..., g, 3)`` ``(u, v, w)`` in the instrument's frame, m/s.
    - `heights`: ``(g,)`` m above the instrument (range times the mean sine of elevation).
    - `residual`: ``(..., g)`` RMS of ``los - n . V`` over the rays used, m/s.
    - `n_rays`: ``(..., g)`` rays used; `condition`: ``(..., g)`` condition numbers.
    - `flags`: ``(..., g)`` int32 `lidarjax.InverseFlag` bits (``TOO_FEW_BEAMS``,
      ``ILL_CONDITIONED``).
    """

    velocity: Float[Array, "*batch g 3"]
    heights: Float[Array, " g"]
    residual: Float[Array, "*batch g"]
    n_rays: Int[Array, "*batch g"]
    condition: Float[Array, "*batch g"]
    flags: Int[Array, "*batch g"]

    @property
    def speed(self) -> Float[Array, "*batch g"]:
        """Horizontal speed, m/s."""
        return horizontal_speed(self.velocity)


def vad_fit(los: Float[ArrayLike, "*batch r g"], azimuth: Float[ArrayLike, "*#batch r"],
            elevation: Float[ArrayLike, "*#batch r"], ranges: Float[ArrayLike, " g"]) -> VadProfile:
    """Least-squares VAD/DBS fit per gate (module docs).

    **Arguments:**

    - `los`: ``(..., r, g)`` LOS velocities, m/s, positive away from the lidar (NaN: not used).
    - `azimuth`, `elevation`: ``(r,)`` ray angles, degrees (clockwise from the instrument's
      north, above its horizon); `elevation` may be one angle. Per scan, ``(..., r)`` with
      the leading axes of `los` (or broadcasting to them): each scan of a repeated VAD
      fitted with its own angles (`lidarjax.io.HaloScan.per_scan`).
    - `ranges`: ``(g,)`` gate-centre ranges, m.

    **Returns:** a `VadProfile`. Jit-compiled and differentiable in every input.
    """
    los = jnp.asarray(los)
    if not jnp.issubdtype(los.dtype, jnp.floating):
        los = los.astype(jnp.result_type(float))
    if los.ndim < 2:
        raise ValueError(f"vad_fit: `los` must be (..., rays, gates), got shape {los.shape}.")
    r = los.shape[-2]
    az = jnp.asarray(azimuth, los.dtype)
    if az.ndim < 1 or az.shape[-1] != r or az.ndim > los.ndim - 1:
        raise ValueError(f"vad_fit: `azimuth` must hold one angle per ray ({r},) (per scan: "
                         f"(..., {r})), got {az.shape}.")
    el = jnp.asarray(elevation, los.dtype)
    shape = jnp.broadcast_shapes(az.shape, el.shape)
    try:
        jnp.broadcast_shapes(shape, los.shape[:-1])
    except ValueError:
        raise ValueError(f"vad_fit: angles of shape {shape} do not broadcast to the rays of `los` "
                         f"{los.shape[:-1]}.") from None
    az, el = jnp.broadcast_to(az, shape), jnp.broadcast_to(el, shape)
    ranges = jnp.asarray(ranges, los.dtype)
    if ranges.shape != los.shape[-1:]:
        raise ValueError(f"vad_fit: `ranges` must hold one range per gate {los.shape[-1:]}, got "
                         f"{ranges.shape}.")
    return _vad_jit(los, az, el, ranges)


def _vad(los, az, el, ranges):
    n = ray_unit_vectors(az, el)  # (..., r, 3)
    ok = jnp.isfinite(los)  # (..., r, g)
    w = ok.astype(los.dtype)
    y = jnp.where(ok, los, 0)
    a = jnp.einsum("...rg,...ri,...rj->...gij", w, n, n, precision=jax.lax.Precision.HIGHEST)
    b = jnp.einsum("...rg,...ri->...gi", w * y, n, precision=jax.lax.Precision.HIGHEST)
    count = jnp.sum(ok, axis=-2)  # (..., g)
    lam = jnp.linalg.eigvalsh(a)  # ascending
    regular = lam[..., 0] > 1e-12 * lam[..., -1]  # the rays span 3-D
    enough = (count >= 3) & regular
    eye = jnp.eye(3, dtype=los.dtype)
    a_safe = jnp.where(enough[..., None, None], a, eye)
    v = jnp.linalg.solve(a_safe, jnp.where(enough[..., None], b, 0)[..., None])[..., 0]
    lam_safe = jnp.where(enough[..., None], lam, 1)
    cond = jnp.sqrt(lam_safe[..., -1] / lam_safe[..., 0])
    resid = jnp.where(ok, y - jnp.einsum("...ri,...gi->...rg", n, v), 0)
    ms = jnp.sum(resid**2, axis=-2) / jnp.maximum(count, 1)
    rms = safe_sqrt(ms)  # finite gradient at 0
    flags = jnp.where(count >= 3, 0, int(InverseFlag.TOO_FEW_BEAMS))
    flags |= jnp.where((count >= 3) & (~regular | (cond > ILL_CONDITIONED)),
                       int(InverseFlag.ILL_CONDITIONED), 0)
    nan = jnp.nan
    heights = ranges * jnp.mean(jnp.sin(jnp.deg2rad(el)))
    return VadProfile(velocity=jnp.where(enough[..., None], v, nan), heights=heights,
                      residual=jnp.where(enough, rms, nan), n_rays=count.astype(jnp.int32),
                      condition=jnp.where(enough, cond, nan), flags=flags.astype(jnp.int32))


_vad_jit = jax.jit(_vad)
