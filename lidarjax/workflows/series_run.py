"""The field of a simulated lidar series: frozen turbulence advected over a mean flow (the
field ``lidarjax series`` simulates).

`series_field` builds a `lidarjax.scenes.FrozenTurbulence` from a mean flow (a CFD field or
a scene) and a turbulence box: read from a TurbSim ``.bts`` file or three HAWC2 binary
files, given as a `lidarjax.TurbulenceBox`, or generated (a periodic Mann box, lidarjax's
numpy FFT or hipersim). The box is advected (Taylor) at the speed and from the direction
given, by default those of the mean flow above the lidar (`mean_wind_above`), and anchored
under the lidar. The field goes to `lidarjax.simulate_statistics`; its statistics to
`lidarjax.write_series_report`.

Units and frames: positions in absolute CFD metres (``z`` up), heights in metres above the
lidar, speeds in m/s, directions in meteorological degrees clockwise from CFD ``+y`` (north
in scenes), box spacings in metres, ``ti`` = sigma_u / advection speed.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from .._util import PathLike
from ..angles import horizontal_speed, wind_direction
from ..field import AbstractField
from ..io import read_hawc2_box, read_turbsim
from ..scenes import FrozenTurbulence
from ..turbulence import TurbulenceBox, fft_mann_box, mann_box

__all__ = ["series_field", "mean_wind_above"]


def mean_wind_above(mean: AbstractField, location, height: float) -> tuple[float, float]:
    """The horizontal speed (m/s) and meteorological direction (degrees) of the mean flow
    `height` metres above `location` ``(x, y, z)`` (absolute CFD metres); NaN, NaN where the
    flow is undefined there (off the grid, in a solid)."""

    top = np.asarray(location, np.float64) + np.array([0.0, 0.0, float(height)])
    v = mean.sample(top[None, :])[0]
    if not bool(jnp.all(jnp.isfinite(v))):
        return float("nan"), float("nan")
    return float(horizontal_speed(v)), float(wind_direction(v))


def series_field(
    mean: AbstractField,
    location,
    *,
    height: float | None = None,
    speed: float | None = None,
    direction: float | None = None,
    box: TurbulenceBox | PathLike | Sequence[PathLike] | None = None,
    box_shape: tuple[int, int, int] | None = None,
    box_spacing: Sequence[float] = (4.0, 4.0, 4.0),
    generate_box: tuple[int, int, int] | None = None,
    length_scale: float = 30.0,
    gamma: float = 3.9,
    ti: float = 0.10,
    seed: int = 0,
    generator: str = "builtin",
) -> tuple[FrozenTurbulence, str]:
    """Frozen turbulence over `mean`, anchored under the lidar at `location`.

    **Arguments:**

    - `mean`: the mean flow (`lidarjax.AbstractField`: a CFD field or a scene).
    - `location`: the lidar ``(x, y, z)``, absolute CFD metres: the box's anchor (its bottom,
      lateral centre, ``x = 0`` node at ``t = 0``).
    - `speed`, `direction`: the advection (m/s; meteorological degrees). Each one not given
      is the mean flow's `height` metres above the lidar (`mean_wind_above`; the top
      measurement height, say).
    - `box`: a `lidarjax.TurbulenceBox`, a TurbSim ``.bts`` path (converted at the advection
      speed) or three HAWC2 binary paths ``(u, v, w)`` with `box_shape` ``(nx, ny, nz)`` and
      `box_spacing` ``(dx, dy, dz)`` (m). Or
    - `generate_box`: ``(nx, ny, nz)`` nodes of a periodic Mann box of `box_spacing`,
      `length_scale` (m), `gamma`, ``sigma_u = ti * speed``, `seed`, made by `generator`
      (``"builtin"``: `lidarjax.fft_mann_box`; ``"hipersim"``: `lidarjax.mann_box`, extra
      ``turbulence``).

    **Returns:** ``(field, description)``: the `FrozenTurbulence` and one line describing the
    box and the advection. Raises `ValueError` for neither or both of `box` and
    `generate_box`, an undefined mean flow above the lidar, a non-positive speed or `ti`,
    or HAWC2 files without `box_shape`.
    """

    if (box is None) == (generate_box is None):
        raise ValueError("series_field: give either box= (a TurbulenceBox or file(s)) or "
                         "generate_box=(nx, ny, nz)")
    if generate_box is not None and not ti > 0:
        raise ValueError(f"series_field: ti must be positive, got {ti}")
    if generator not in ("builtin", "hipersim"):
        raise ValueError(f"series_field: generator must be 'builtin' or 'hipersim', got "
                         f"{generator!r}")
    origin = np.asarray(mean.origin, np.float64) + np.asarray(mean.origin_lo, np.float64)
    anchor = np.asarray(location, np.float64) - origin
    if speed is None or direction is None:
        if height is None:
            raise ValueError("series_field: give speed= and direction=, or height= (m above "
                             "the lidar) where the mean flow sets them")
        s, d = mean_wind_above(mean, location, height)
        if not np.isfinite(s):
            top = np.asarray(location, np.float64) + np.array([0.0, 0.0, float(height)])
            raise ValueError(f"series_field: the mean flow is undefined above the lidar at "
                             f"{top.tolist()}; pass speed= and direction=")
        speed = s if speed is None else speed
        direction = d if direction is None else direction
    speed, direction = float(speed), float(direction)
    if not speed > 0:
        raise ValueError(f"the advection speed must be positive, got {speed}")
    spacing = tuple(float(s) for s in box_spacing)
    if generate_box is not None:
        shape = tuple(int(n) for n in generate_box)
        sigma = ti * speed
        if generator == "hipersim":
            made = mann_box(1.0, length_scale, gamma, shape, spacing, seed=seed, periodic=True)
            made = made.scaled(sigma / float(jnp.std(made.velocity[..., 0])))
        else:
            vel = fft_mann_box(shape, spacing, length_scale=length_scale, gamma=gamma,
                               sigma_u=sigma, seed=seed)
            made = TurbulenceBox(jnp.asarray(vel, mean.dtype), jnp.asarray(spacing, mean.dtype),
                                 periodic=(True, True))
        info = (f"generated Mann box {shape} x {spacing} m ({generator}, "
                f"L = {length_scale:g} m, Gamma = {gamma:g}, sigma_u = {sigma:.3g} m/s)")
    elif isinstance(box, TurbulenceBox):
        made = box
        info = (f"box {tuple(int(n) for n in box.velocity.shape[:3])} x "
                f"{tuple(float(s) for s in np.asarray(box.spacing))} m")
    elif isinstance(box, str | Path):
        made = read_turbsim(box).box(speed)
        info = f"box {box}"
    else:
        parts = list(box)
        if len(parts) != 3:
            raise ValueError(f"series_field: box must be one .bts file or three HAWC2 files "
                             f"(u, v, w); got {len(parts)}")
        if box_shape is None:
            raise ValueError("series_field: HAWC2 boxes need box_shape=(nx, ny, nz) (and "
                             "box_spacing)")
        made = read_hawc2_box(*parts, box_shape, spacing)
        info = "box " + ",".join(str(p) for p in parts)
    field = FrozenTurbulence(mean, made, speed, direction, anchor=anchor)
    return field, info + f", advected at {speed:.3g} m/s from {direction:.1f} deg"
