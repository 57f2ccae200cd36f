"""ZephyCube's Windcube corrections (seed 002), as baselines for `lidarjax.invert`.

ZephyCube corrects a Windcube's horizontal wind to the vertical above the lidar (the
*centre line*, ``M_vert``), not to the free stream, using CFD speed-ups picked at the
*uncorrected* measured direction (its stated assumption: the speed-ups vary slowly with
direction). Both methods need a `ResponseTable` with `beam_vectors` and `point`
(`ResponseTable.from_simulations(..., mount=...)`); the scalar one also `beam_velocity`
(``fields=...``).

Beam layout: the four tilted beams ``0..3`` at azimuths ``offset + (0, 90, 180, 270)`` degrees
clockwise from north (``offset`` is ZephyCube's ``theta_offset``; beams North, East, South,
West of its figures for ``offset = 0``), cone angle ``theta_laser`` from the vertical, then an
optional vertical beam. Both are read from the table's `beam_vectors`.

- `homogeneous_wind` (section 3.1): the closed-form DBS reconstruction, ``u_m = (V_n - V_s) /
  (2 sin theta_laser)`` per beam pair, rotated by the offset: what the ``.sta`` files hold.
- `scalar_correction` (section 3.2.1): from ``.sta`` values. For each beam pair ``p`` (beams
  0/2 along the offset azimuth, 1/3 along offset + 90) with along-pair ``.sta`` component
  ``c_sta``, ``c_m = (2 c_sta - (b_+ - b_-) w_m cot theta_laser) / (a_+ + a_-)`` where
  ``a_+- = c(M_+-) / c(M_vert)`` are the CFD speed-ups of the along-pair component from the
  centre line to the two beam points and ``b_+- = w(M_+-) / w(M_vert)`` those of the
  vertical component. ZephyCube's filter, "homogeneous horizontal speed under 1 m/s", sets
  ``a_+- = 1`` where ``|c_sta| < threshold``: the text derives everything one component at a
  time, so the threshold is applied to the along-pair component, which is where the ratios
  misbehave.
- `normalised_rose` (section 2): the CFD results at the beam points normalised by the centre
  line (horizontal speed-up ratios and direction deviations) on a 360-degree rose.
- `vector_correction` (section 3.2.2): from raw beams, ``P_corr = P_raw * SU(alpha)`` with the
  per-beam speed-up ``SU = (V(M_vert) . n_b) / (V(M_b) . n_b)`` from the table (numerator and
  denominator are interpolated separately, then divided), then the DBS formulas with the
  offset.

Ratios whose denominator is smaller than ``ratio_tol`` times the centre-line (or beam-point)
speed scale give NaN, never inf (as in `lidarjax.correction_factors`). Directions are
meteorological (from, degrees clockwise from north); speeds in m/s.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ._deprecated import deprecated_getattr
from ._precision import HIGHEST
from .angles import direction_difference, horizontal_speed, wind_direction
from .corrections import DEFAULT_RATIO_TOL, safe_ratio
from .response import ResponseTable

__all__ = [
    "ZephyCubeWind",
    "NormalisedRose",
    "beam_layout",
    "homogeneous_wind",
    "normalised_rose",
    "scalar_correction",
    "vector_correction",
]


class ZephyCubeWind(eqx.Module):
    """A horizontal wind per height: `speed` (m/s) and meteorological `direction` (degrees),
    each ``(..., h)``; for ZephyCube the wind on the vertical above the lidar."""

    speed: Float[Array, "... h"]
    direction: Float[Array, "... h"]

    @property
    def velocity(self) -> Float[Array, "... h 2"]:
        """Horizontal velocity ``(u, v)``, north frame, m/s."""
        d = jnp.deg2rad(self.direction)
        return jnp.stack([-self.speed * jnp.sin(d), -self.speed * jnp.cos(d)], axis=-1)


def _require(table: ResponseTable, name: str, caller: str, build: str, what: str | None = None) -> None:
    """Raise `ValueError` naming `caller` and how to `build` a table with `name` when the
    table has none."""
    if getattr(table, name) is None:
        raise ValueError(f"{caller}: the table has no {what or f'`{name}`'}; build it with {build}.")


def beam_layout(table: ResponseTable) -> tuple[float, float, bool]:
    """``(offset, cone, vertical)`` of a Windcube table: azimuth of beam 0 (degrees clockwise
    from north), cone angle of the tilted beams (degrees from the vertical), and whether a
    fifth, vertical beam follows. Raises `ValueError` for other beam patterns."""
    _require(table, "beam_vectors", "zephycube", "ResponseTable.from_simulations(sims, mount=mount)")
    n = np.asarray(table.beam_vectors, np.float64)
    if n.shape[0] not in (4, 5):
        raise ValueError(
            f"zephycube: ZephyCube's methods need a Windcube (4 tilted beams, optionally a "
            f"vertical fifth); this table has {n.shape[0]} beams."
        )
    vertical = n.shape[0] == 5
    if vertical and not np.allclose(n[4], [0.0, 0.0, 1.0], atol=1e-6):
        raise ValueError("zephycube: the fifth beam must be vertical (Windcube V2).")
    cones = np.degrees(np.arccos(np.clip(n[:4, 2], -1.0, 1.0)))
    az = np.degrees(np.arctan2(n[:4, 0], n[:4, 1]))
    steps = np.mod(az - az[0], 360.0)
    same_cone = np.allclose(cones, cones[0], atol=1e-6)
    if not (same_cone and np.allclose(steps, [0, 90, 180, 270], atol=1e-6)):
        raise ValueError(
            f"zephycube: beams 0..3 must share one cone angle and sit at offset + (0, 90, 180, "
            f"270) degrees; got cones {cones.round(3).tolist()} and azimuths "
            f"{np.mod(az, 360).round(3).tolist()}."
        )
    if not 0.0 < cones[0] < 90.0:
        raise ValueError(f"zephycube: cone angle must be in (0, 90) degrees, got {cones[0]:g}.")
    return float(np.mod(az[0], 360.0)), float(cones[0]), vertical


def _pair_axes(offset, dtype):
    """Horizontal unit vectors ``(2, 2)`` along pair 0 (beams 0/2) and pair 1 (beams 1/3)."""
    a = np.deg2rad(offset)
    return jnp.asarray([[np.sin(a), np.cos(a)], [np.cos(a), -np.sin(a)]], dtype)


def _dbs(los4, offset, cone):
    """ZephyCube's reconstruction of ``(u, v)`` (north frame) from beams 0..3 (N, E, S, W)."""
    two_sin = 2.0 * np.sin(np.deg2rad(cone))
    along0 = (los4[..., 0] - los4[..., 2]) / two_sin  # along the North beam (offset azimuth)
    along1 = (los4[..., 1] - los4[..., 3]) / two_sin  # along the East beam
    so, co = np.sin(np.deg2rad(offset)), np.cos(np.deg2rad(offset))
    u = along1 * co + along0 * so
    v = -along1 * so + along0 * co
    return jnp.stack([u, v], axis=-1)


def _wind(uv):
    vel = jnp.concatenate([uv, jnp.zeros_like(uv[..., :1])], axis=-1)
    return ZephyCubeWind(horizontal_speed(vel), wind_direction(vel))


def _float(x, dtype=None):
    x = jnp.asarray(x)
    if not jnp.issubdtype(x.dtype, jnp.floating):
        x = x.astype(dtype if dtype is not None else jnp.asarray(0.0).dtype)
    return x


def _check_los(fname, table, los):
    if los.ndim < 2 or los.shape[-2:] != (table.n_heights, table.n_beams):
        raise ValueError(
            f"{fname}: `los` must be shaped (..., h, b) = (..., {table.n_heights}, "
            f"{table.n_beams}) as in the table; got {los.shape}."
        )


def homogeneous_wind(table: ResponseTable, los: Float[ArrayLike, "... h b"]) -> ZephyCubeWind:
    """No correction (section 3.1): the Windcube's homogeneous-flow reconstruction from raw
    LOS ``(..., h, b)`` (m/s), in the north frame. This is what its ``.sta`` files hold."""
    offset, cone, _ = beam_layout(table)
    los = _float(los, table.dtype)
    _check_los("homogeneous_wind", table, los)
    return _homogeneous(los, offset, cone)


@eqx.filter_jit
def _homogeneous(los, offset, cone):
    return _wind(_dbs(los[..., :4], offset, cone))


def scalar_correction(
    table: ResponseTable,
    speed: Float[ArrayLike, "... h"],
    direction: Float[ArrayLike, "... h"],
    w: Float[ArrayLike, "... h"],
    *,
    alpha: Float[ArrayLike, "... h"] | None = None,
    threshold: float = 1.0,
    ratio_tol: float = DEFAULT_RATIO_TOL,
) -> ZephyCubeWind:
    """ZephyCube's scalar correction (section 3.2.1) of ``.sta`` records to the centre line.

    **Arguments:**

    - `table`: a Windcube `ResponseTable` with `beam_vectors`, `point` and `beam_velocity`.
    - `speed`, `direction`: ``(..., h)`` the ``.sta`` horizontal speed (m/s) and
      meteorological direction (degrees, north frame): the homogeneous reconstruction.
    - `w`: ``(..., h)`` the measured vertical speed ``w_m`` (m/s; the V2's vertical beam).
    - `alpha`: ``(..., h)`` the direction (degrees) at which the CFD speed-ups are taken;
      default: the uncorrected `direction`, as ZephyCube does.
    - `threshold`: ZephyCube's homogeneous filter, m/s: along-pair components below it use
      unit speed-ups ``a`` (``0`` disables the filter).
    - `ratio_tol`: relative tolerance of the CFD ratio denominators (NaN below it).

    **Returns:** the corrected `ZephyCubeWind` on the vertical above the lidar.
    """
    offset, cone, _ = beam_layout(table)
    _require(table, "beam_velocity", "scalar_correction",
             "ResponseTable.from_simulations(sims, mount=mount, fields=fields)")
    speed = _float(speed, table.dtype)
    dtype = speed.dtype
    direction = _float(direction, dtype)
    w = _float(w, dtype)
    alpha = direction if alpha is None else _float(alpha, dtype)
    try:
        shape = jnp.broadcast_shapes(speed.shape, direction.shape, w.shape, alpha.shape)
    except ValueError:
        shape = ()
    if len(shape) < 1 or shape[-1] != table.n_heights:
        raise ValueError(
            f"scalar_correction: `speed`, `direction`, `w` and `alpha` must broadcast to "
            f"(..., h) with h = {table.n_heights}; got {speed.shape}, {direction.shape}, "
            f"{w.shape}, {alpha.shape}."
        )
    speed, direction, w, alpha = (
        jnp.broadcast_to(a, shape).astype(dtype) for a in (speed, direction, w, alpha)
    )
    return _scalar(_cast(table, dtype), speed, direction, w, alpha, offset, cone, threshold,
                   ratio_tol)


@eqx.filter_jit
def _scalar(table, speed, direction, w, alpha, offset, cone, threshold, ratio_tol):
    rad = jnp.deg2rad(jnp.where(speed == 0, 0.0, direction))
    sta = jnp.stack([-speed * jnp.sin(rad), -speed * jnp.cos(rad)], axis=-1)  # (..., h, 2)
    axes = _pair_axes(offset, speed.dtype)  # (2 pairs, 2)
    c_sta = jnp.einsum("...hk,pk->...hp", sta, axes, precision=HIGHEST)
    centre = table.point_spline.per_row(alpha)  # (..., h, 3)
    beams = table.beam_velocity_spline.per_row(alpha)  # (..., h, b, 3)
    scale_c = jnp.linalg.norm(centre, axis=-1)[..., None]  # (..., h, 1)
    c_centre = jnp.einsum("...hk,pk->...hp", centre[..., :2], axes, precision=HIGHEST)  # (..., h, 2)
    plus = beams[..., :2, :]  # beams 0 and 1: the + beam of each pair
    minus = beams[..., 2:4, :]
    c_plus = jnp.einsum("...hpk,pk->...hp", plus[..., :2], axes, precision=HIGHEST)
    c_minus = jnp.einsum("...hpk,pk->...hp", minus[..., :2], axes, precision=HIGHEST)
    a_plus = safe_ratio(c_plus, c_centre, scale_c, ratio_tol)
    a_minus = safe_ratio(c_minus, c_centre, scale_c, ratio_tol)
    w_centre = centre[..., 2:3]
    b_plus = safe_ratio(plus[..., 2], w_centre, scale_c, ratio_tol)
    b_minus = safe_ratio(minus[..., 2], w_centre, scale_c, ratio_tol)
    cot = 1.0 / np.tan(np.deg2rad(cone))
    vertical = (b_plus - b_minus) * w[..., None] * cot
    homog = jnp.abs(c_sta) < threshold
    a_sum = jnp.where(homog, 2.0, a_plus + a_minus)
    c_m = (2.0 * c_sta - vertical) / a_sum
    return _wind(jnp.einsum("...hp,pk->...hk", c_m, axes, precision=HIGHEST))


def vector_correction(
    table: ResponseTable,
    los: Float[ArrayLike, "... h b"],
    *,
    alpha: Float[ArrayLike, "... h"] | None = None,
    ratio_tol: float = DEFAULT_RATIO_TOL,
) -> ZephyCubeWind:
    """ZephyCube's vector correction (section 3.2.2) of raw beams to the centre line.

    **Arguments:**

    - `table`: a Windcube `ResponseTable` with `beam_vectors` and `point`.
    - `los`: ``(..., h, b)`` raw LOS, m/s (beams 0..3 are used; NaN propagates).
    - `alpha`: ``(..., h)`` the direction (degrees) at which the speed-ups are taken;
      default: the homogeneous (uncorrected) direction, as ZephyCube does.
    - `ratio_tol`: relative tolerance of the speed-up denominators (NaN below it).

    **Returns:** the corrected `ZephyCubeWind` on the vertical above the lidar.
    """
    offset, cone, _ = beam_layout(table)
    _require(table, "point", "vector_correction", "Simulations made with point_reference=True",
             what="`point` (centre-line) velocity")
    los = _float(los, table.dtype)
    _check_los("vector_correction", table, los)
    if alpha is None:
        alpha = _homogeneous(los, offset, cone).direction
    alpha = _float(alpha, los.dtype)
    try:
        alpha = jnp.broadcast_to(alpha, los.shape[:-1])
    except ValueError:
        raise ValueError(
            f"vector_correction: `alpha` {alpha.shape} does not broadcast to (..., h) "
            f"{los.shape[:-1]}."
        ) from None
    return _vector(_cast(table, los.dtype), los, alpha, offset, cone, ratio_tol)


@eqx.filter_jit
def _vector(table, los, alpha, offset, cone, ratio_tol):
    centre = table.point_spline.per_row(alpha)  # (..., h, 3)
    num = jnp.einsum("...hk,bk->...hb", centre, table.beam_vectors[:4], precision=HIGHEST)  # (..., h, 4)
    den = table.response_spline.per_row(alpha)[..., :4]
    scale = jnp.linalg.norm(centre, axis=-1)
    su = safe_ratio(num, den, scale[..., None], ratio_tol)
    return _wind(_dbs(los[..., :4] * su, offset, cone))


def _cast(table, dtype):
    return jax.tree_util.tree_map(
        lambda a: a.astype(dtype) if jnp.issubdtype(a.dtype, jnp.floating) else a, table
    )


class NormalisedRose(eqx.Module):
    """ZephyCube's "rose of normalised results" (``n`` directions, ``h`` heights, ``b`` beams).

    - `directions`: ``(n,)`` free-stream directions, degrees, evenly spaced from 0.
    - `speed_up`: ``(n, h, b)`` horizontal speed at each beam point over that on the centre
      line at the same height.
    - `deviation`: ``(n, h, b)`` direction at each beam point minus that on the centre line,
      degrees in ``(-180, 180]``.
    """

    directions: Float[Array, " n"]
    speed_up: Float[Array, "n h b"]
    deviation: Float[Array, "n h b"]


def normalised_rose(table: ResponseTable, *, resolution: float = 1.0) -> NormalisedRose:
    """ZephyCube's normalised CFD results, interpolated every `resolution` degrees (1 by
    default; it must divide 360), from a table with `beam_velocity` and `point`."""
    if table.beam_velocity is None or table.point is None:
        raise ValueError(
            "normalised_rose: the table needs `beam_velocity` and `point`; build it with "
            "ResponseTable.from_simulations(sims, mount=mount, fields=fields)."
        )
    n = 360.0 / float(resolution)
    if not (resolution > 0 and abs(n - round(n)) < 1e-9):
        raise ValueError(f"normalised_rose: `resolution` must divide 360, got {resolution!r}.")
    dirs = jnp.asarray(np.arange(int(round(n))) * float(resolution), table.dtype)
    speed_up, deviation = _normalised(table, dirs)
    return NormalisedRose(dirs, speed_up, deviation)


@eqx.filter_jit
def _normalised(table, dirs):
    beams = table.beam_velocity_at(dirs)  # (n, h, b, 3)
    centre = jnp.broadcast_to(table.point_at(dirs)[..., None, :], beams.shape)
    speed_up = horizontal_speed(beams) / horizontal_speed(centre)
    return speed_up, direction_difference(beams, centre)


__getattr__ = deprecated_getattr(__name__)
