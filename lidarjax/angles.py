"""Wind speed and direction from velocity vectors, with gradient-safe masks.

Conventions (used everywhere in lidarjax):

- Vectors are ``(..., 3)`` arrays ``(u, v, w)`` in a right-handed frame with ``+y`` north
  (or the lidar's ``+y`` beam S0), ``+x`` east, ``+z`` up, in m/s.
- *Meteorological direction*: where the wind comes **from**, in degrees clockwise from
  ``+y`` (north), in ``[0, 360)``. A wind blowing towards ``-y`` (southward) has direction 0.
- Direction *addends* (differences of directions) are wrapped to ``(-180, 180]``.
- The seed UDF's own azimuth (``Th_lidar`` in its output files) is the flow heading
  measured clockwise from ``+x``: ``theta_seed = -atan2(v, u) mod 360``; hence
  ``meteorological = (theta_seed + 270) mod 360``. See `seed_azimuth`.

Calm (a horizontal speed whose square underflows: at or below ``sqrt(finfo.tiny)``, about
1.5e-154 m/s in float64 and 1.1e-19 m/s in float32) has no direction: `wind_direction` gives NaN there, and its
gradient is zero rather than NaN/inf (the jax-md ``safe_mask`` pattern: mask the input,
then the output).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._util import compiled

__all__ = [
    "horizontal_speed",
    "wind_direction",
    "direction_difference",
    "wrap180",
    "seed_azimuth",
    "heading",
]

def _calm_mask(u, v):
    """True where the horizontal vector ``(u, v)`` (m/s) is calm: ``u*u + v*v`` at or below
    the dtype's smallest normal number ``finfo.tiny`` (zero, or a square that underflows, as
    the backend computes it: one that flushes subnormals to zero, as XLA's CPU does, adds
    each component's square after flushing; NaN is not calm). The one definition of calm:
    `wind_direction` and the other functions here, `lidarjax.simulate`'s `Flag.CALM` and
    the inversions' `InverseFlag.CALM`."""
    h2 = u * u + v * v
    tiny = jnp.finfo(jnp.result_type(h2)).tiny
    return h2 <= tiny


def _unit(u, v, calm):
    """(u, v) / |(u, v)| with calm entries replaced by (1, 0) (finite gradients).

    Divided first by the larger component, held constant under differentiation: the unit
    vector does not change with a common scale, so that derivative is exactly zero, and
    without it the reverse pass multiplies ``1 / |(u, v)|`` in twice (1e37 at 1e-19 m/s in
    float32, beyond its range once a degree conversion follows)."""
    su = jnp.where(calm, 1.0, u)
    sv = jnp.where(calm, 0.0, v)
    scale = jax.lax.stop_gradient(jnp.maximum(jnp.abs(su), jnp.abs(sv)))
    su, sv = su / scale, sv / scale
    n = jnp.sqrt(su * su + sv * sv)
    return su / n, sv / n


@compiled
def horizontal_speed(velocity: Float[ArrayLike, "... 3"]) -> Float[Array, ...]:
    """Horizontal speed ``sqrt(u**2 + v**2)`` in the units of ``velocity`` (m/s).

    Gradient-safe: at exactly zero speed the value is 0 and its gradient is 0 (not NaN).

    **Arguments:**

    - `velocity`: ``(..., 3)`` vectors ``(u, v, w)``; ``w`` is ignored.

    **Returns:** ``(...)`` horizontal speed, same dtype as the input.
    """
    velocity = jnp.asarray(velocity)
    u, v = velocity[..., 0], velocity[..., 1]
    calm = _calm_mask(u, v)
    su = jnp.where(calm, 1.0, u)
    sv = jnp.where(calm, 0.0, v)
    return jnp.where(calm, jnp.zeros_like(u), jnp.sqrt(su * su + sv * sv))


@compiled
def wind_direction(velocity: Float[ArrayLike, "... 3"]) -> Float[Array, ...]:
    """Meteorological wind direction in degrees, ``[0, 360)``.

    The direction the wind comes **from**, clockwise from ``+y`` (north of the frame the
    vector is expressed in). A southward wind ``(0, -1, 0)`` gives 0, a westward wind
    ``(-1, 0, 0)`` gives 90.

    Calm (zero horizontal speed or one whose square underflows, module docs; `Flag.CALM` in
    a simulation) gives NaN, with a zero (finite) gradient.

    **Arguments:**

    - `velocity`: ``(..., 3)`` vectors ``(u, v, w)`` in m/s.

    **Returns:** ``(...)`` direction in degrees.
    """
    velocity = jnp.asarray(velocity)
    u, v = velocity[..., 0], velocity[..., 1]
    calm = _calm_mask(u, v)
    su = jnp.where(calm, 0.0, u)
    sv = jnp.where(calm, -1.0, v)
    d = jnp.rad2deg(jnp.arctan2(-su, -sv))
    d = jnp.mod(d, 360.0)
    # mod can return exactly 360 for tiny negative inputs in floating point
    d = jnp.where(d >= 360.0, d - 360.0, d)
    return jnp.where(calm, jnp.nan, d)


@compiled
def wrap180(angle: Float[ArrayLike, ...]) -> Float[Array, ...]:
    """Wrap angles in degrees to ``(-180, 180]``."""
    angle = jnp.asarray(angle)
    return 180.0 - jnp.mod(180.0 - angle, 360.0)


@compiled
def direction_difference(
    to: Float[ArrayLike, "... 3"], frm: Float[ArrayLike, "... 3"]
) -> Float[Array, ...]:
    """Direction addend ``direction(to) - direction(frm)`` in degrees, in ``(-180, 180]``.

    Computed from the cross and dot products of the horizontal parts (no subtraction of
    wrapped angles, so there is no artefact at the 0/360 wrap and the gradient is smooth).
    It is the clockwise angle from the horizontal vector `frm` to `to`; so
    ``direction(frm) + result == direction(to)`` modulo 360.

    NaN where either vector is calm (zero horizontal speed), with finite gradients.
    """
    to = jnp.asarray(to)
    frm = jnp.asarray(frm)
    bx, by = to[..., 0], to[..., 1]
    ax, ay = frm[..., 0], frm[..., 1]
    calm = _calm_mask(ax, ay) | _calm_mask(bx, by)
    # unit horizontal vectors first, so cross and dot stay O(1) for tiny speeds (their squares
    # would underflow in the atan2 derivative)
    ax, ay = _unit(ax, ay, calm)
    bx, by = _unit(bx, by, calm)
    cross = ax * by - ay * bx  # counter-clockwise sine term
    dot = ax * bx + ay * by
    cross = jnp.where(calm, 0.0, cross)
    dot = jnp.where(calm, 1.0, dot)
    d = wrap180(-jnp.rad2deg(jnp.arctan2(cross, dot)))
    return jnp.where(calm, jnp.nan, d)


@compiled
def seed_azimuth(velocity: Float[ArrayLike, "... 3"]) -> Float[Array, ...]:
    """The seed UDF's flow azimuth in degrees, ``[0, 360)``: heading clockwise from ``+x``.

    The UDF computes it piecewise from ``atan(v/u)`` (dividing by zero for ``u = 0``);
    the closed form is ``-atan2(v, u) mod 360``, and it relates to the meteorological
    direction by ``wind_direction = (seed_azimuth + 270) mod 360``. Calm gives NaN.
    """
    d = wind_direction(velocity)
    return jnp.mod(d + 90.0, 360.0)


def heading(direction_deg, dtype=None) -> Float[Array, 3]:
    """Unit horizontal vector the wind blows *towards* for a meteorological direction."""
    return _heading(jnp.asarray(direction_deg, dtype=dtype))


@compiled
def _heading(direction_deg):
    d = jnp.deg2rad(direction_deg)
    return jnp.stack([-jnp.sin(d), -jnp.cos(d), jnp.zeros_like(d)])


