"""Correction-factor roses: speed ratio and direction addend against direction, per height.

A rose tabulates, at a fine direction step (1 degree by default), the factors that turn what
the lidar reports into the wind wanted (the seed's ``cff_U``, ``cff_th``; ZephyCube's
"360-degree rose of normalised results"):

``U_target = speed_ratio * U_lidar``,  ``d_target = d_lidar + direction_addend``,

with the target the free stream (``target="free"``) or the vertical above the lidar
(``target="point"``). The abscissa (``reference``) is either the free-stream direction of
the CFD runs (``"free"``, what the table is indexed by) or the direction the lidar reports
(``"lidar"``, what a user has when correcting a record; found by inverting the table's
reconstructed response with `lidarjax.invert_reconstructed`).

`sector_rose` averages a rose into WAsP-style sectors (12 of 30 degrees centred on 0, 30,
...): arithmetic mean of the ratios, circular mean of the addends.

All directions are meteorological (from, degrees clockwise from north).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ._precision import HIGHEST
from ._util import compiled
from .angles import direction_difference, horizontal_speed, wrap180
from .inverse import invert_reconstructed
from .response import ResponseTable

__all__ = ["CorrectionRose", "correction_rose", "sector_rose"]

_TARGETS = ("free", "point")
_REFERENCES = ("free", "lidar")


class CorrectionRose(eqx.Module):
    """Correction factors against direction (``n`` directions, ``h`` heights).

    - `directions`: ``(n,)`` abscissa, degrees, evenly spaced from 0 (sector centres for a
      sector rose).
    - `speed_ratio`: ``(n, h)`` ``U_target / U_lidar``.
    - `direction_addend`: ``(n, h)`` ``d_target - d_lidar`` in degrees, ``(-180, 180]``.
    - `reference`: ``"free"`` or ``"lidar"``: which direction the abscissa is (static).
    - `target`: ``"free"`` or ``"point"`` (static).
    - `sectors`: piecewise constant over sectors (True) or linear between directions (static).
    """

    directions: Float[Array, " n"]
    speed_ratio: Float[Array, "n h"]
    direction_addend: Float[Array, "n h"]
    reference: str = eqx.field(static=True)
    target: str = eqx.field(static=True)
    sectors: bool = eqx.field(static=True)

    @compiled
    def at(
        self, direction: Float[ArrayLike, "... h"]
    ) -> tuple[Float[Array, "... h"], Float[Array, "... h"]]:
        """``(speed_ratio, direction_addend)`` at `direction` ``(..., h)`` (degrees, one per
        height): the sector's values for a sector rose, else linear interpolation."""
        direction = jnp.asarray(direction, self.directions.dtype)
        n, h = self.speed_ratio.shape
        if direction.ndim < 1 or direction.shape[-1] != h:
            raise ValueError(
                f"CorrectionRose.at: `direction` must be shaped (..., {h}), got {direction.shape}."
            )
        step = 360.0 / n
        x = jnp.mod(direction - self.directions[0], 360.0) / step
        cols = jnp.arange(h)
        if self.sectors:
            k = jnp.mod(jnp.round(x).astype(jnp.int32), n)
            return self.speed_ratio[k, cols], self.direction_addend[k, cols]
        k0 = jnp.clip(jnp.floor(x).astype(jnp.int32), 0, n - 1)
        k1 = jnp.mod(k0 + 1, n)
        t = x - k0
        ratio = (1 - t) * self.speed_ratio[k0, cols] + t * self.speed_ratio[k1, cols]
        a0, a1 = self.direction_addend[k0, cols], self.direction_addend[k1, cols]
        addend = wrap180(a0 + t * wrap180(a1 - a0))
        return ratio, addend

    def apply(
        self, speed: Float[ArrayLike, "... h"], direction: Float[ArrayLike, "... h"]
    ) -> tuple[Float[Array, "... h"], Float[Array, "... h"]]:
        """Correct reported ``(speed, direction)`` ``(..., h)``: returns the target's
        ``(speed, direction)``. Needs a rose with ``reference="lidar"`` (the record only knows
        the lidar's direction)."""
        if self.reference != "lidar":
            raise ValueError(
                "CorrectionRose.apply: this rose is indexed by the free-stream direction, "
                "which a record does not know; build it with reference='lidar'."
            )
        ratio, addend = self.at(direction)
        return jnp.asarray(speed) * ratio, jnp.mod(jnp.asarray(direction) + addend, 360.0)


def correction_rose(
    table: ResponseTable,
    *,
    resolution: float = 1.0,
    reference: str = "lidar",
    target: str = "free",
) -> CorrectionRose:
    """A rose of correction factors from a table with `reconstructed` (and `point` for
    ``target="point"``) at every `resolution` degrees (360 must be a multiple of it).

    **Arguments:**

    - `table`: the site's `ResponseTable`.
    - `resolution`: direction step in degrees (1 by default).
    - `reference`: ``"lidar"`` (abscissa = reported direction; default, what `apply` needs)
      or ``"free"`` (abscissa = free-stream direction of the runs).
    - `target`: ``"free"`` (free stream, default) or ``"point"`` (vertical above the lidar).
    """
    if reference not in _REFERENCES:
        raise ValueError(
            f"correction_rose: `reference` must be one of {_REFERENCES}, got {reference!r}."
        )
    if target not in _TARGETS:
        raise ValueError(f"correction_rose: `target` must be one of {_TARGETS}, got {target!r}.")
    n = 360.0 / float(resolution)
    if not (resolution > 0 and abs(n - round(n)) < 1e-9):
        raise ValueError(
            f"correction_rose: `resolution` must divide 360 degrees, got {resolution!r}."
        )
    if table.reconstructed is None:
        raise ValueError("correction_rose: the table has no `reconstructed` response.")
    if target == "point" and table.point is None:
        raise ValueError("correction_rose: target='point' needs a table with `point`.")
    dirs = jnp.asarray(np.arange(int(round(n))) * float(resolution), table.dtype)
    h = table.n_heights
    if reference == "free":
        free_d = jnp.broadcast_to(dirs[:, None], (dirs.shape[0], h))
        free_u = jnp.ones_like(free_d)
    else:
        inv = invert_reconstructed(table, jnp.ones((dirs.shape[0], h), table.dtype),
                                   jnp.broadcast_to(dirs[:, None], (dirs.shape[0], h)))
        free_d, free_u = inv.direction, inv.speed
    ratio, addend = _factors(table, free_d, free_u, target)
    return CorrectionRose(dirs, ratio, addend, reference, target, False)


@eqx.filter_jit
def _factors(table, free_d, free_u, target):
    lidar = table.reconstructed_spline.per_row(free_d) * free_u[..., None]  # (n, h, 3)
    rad = jnp.deg2rad(free_d)
    free = jnp.stack([-free_u * jnp.sin(rad), -free_u * jnp.cos(rad), jnp.zeros_like(rad)], -1)
    want = free if target == "free" else table.point_spline.per_row(free_d) * free_u[..., None]
    return horizontal_speed(want) / horizontal_speed(lidar), direction_difference(want, lidar)


def sector_rose(rose: CorrectionRose, n_sectors: int = 12) -> CorrectionRose:
    """Average a fine rose into `n_sectors` sectors centred on ``0, 360/n, ...`` degrees
    (WAsP style): mean speed ratio and circular-mean direction addend of the rose's
    directions inside each sector (a direction on a sector edge counts half to each)."""
    n_sectors = int(n_sectors)
    if n_sectors < 1:
        raise ValueError(f"sector_rose: `n_sectors` must be positive, got {n_sectors}.")
    if rose.sectors:
        raise ValueError("sector_rose: the rose is already a sector rose; pass the fine one.")
    width = 360.0 / n_sectors
    d = np.asarray(rose.directions, np.float64)
    centres = np.arange(n_sectors) * width
    # distance of each direction from each centre, wrapped: weights 1 inside, 1/2 on edges
    dist = np.abs((d[None, :] - centres[:, None] + 180.0) % 360.0 - 180.0)
    weights = np.where(np.isclose(dist, width / 2), 0.5, (dist < width / 2).astype(float))
    if np.any(weights.sum(axis=1) == 0):
        raise ValueError(
            f"sector_rose: {n_sectors} sectors are finer than the rose's resolution "
            f"({360.0 / d.size:g} degrees)."
        )
    wts = jnp.asarray(weights / weights.sum(axis=1, keepdims=True), rose.speed_ratio.dtype)
    ratio = jnp.matmul(wts, rose.speed_ratio, precision=HIGHEST)
    a = jnp.deg2rad(rose.direction_addend)
    addend = jnp.rad2deg(jnp.arctan2(jnp.matmul(wts, jnp.sin(a), precision=HIGHEST),
                                     jnp.matmul(wts, jnp.cos(a), precision=HIGHEST)))
    return CorrectionRose(
        jnp.asarray(centres, rose.directions.dtype), ratio, wrap180(addend), rose.reference,
        rose.target, True,
    )
