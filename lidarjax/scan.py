"""Scan geometries and wind-vector reconstruction from line-of-sight (LOS) velocities.

Beam azimuths are degrees clockwise from the lidar's ``+y`` (beam S0), the cone angle is the
beam's angle from the vertical in degrees, and a beam's unit vector in the lidar frame is
``(sin c sin a, sin c cos a, cos c)`` (seed 000, equation 1). LOS velocities are positive
away from the lidar. Beams are ordered as the tilted beams in the given azimuth order, then
the vertical beam if the scan has one.

Reconstruction methods (`Scan.method`, static):

- ``"windcube_v1"``: the seed's DBS formulas for four beams at ``a0 + k*90`` degrees:
  ``u = (s1 - s3) / (2 sin c)``, ``v = (s0 - s2) / (2 sin c)``, ``w = (s0 + s2) / (2 cos c)``
  (the listing's formulas; the report's printed equation 12, ``u = (s1 + s3)/(2 cos c)``, is a
  typo). For ``a0 != 0`` the horizontal pair is rotated back by ``a0``.
- ``"windcube_v2"``: as V1 for ``u, v``; ``w`` is the vertical beam's LOS.
- ``"sine_fit"``: ZephIR's fit ``s(a) = A sin a + B cos a + C`` by linear least squares
  (seed 003, equations 5 to 8), ``u = A / sin c``, ``v = B / sin c``, ``w = C / cos c``.
- ``"least_squares"``: ``(u, v, w)`` minimising ``sum_b (n_b . V - s_b)^2`` for any scan whose
  beam vectors span 3-D (for a single cone angle it equals ``"sine_fit"``).

Conditioning. Every method solves (exactly or in effect) the linear system ``N V = s`` with
the ``(b, 3)`` beam matrix ``N`` of the unit vectors above, so LOS errors reach the wind
through ``N``'s condition number ``cond = sigma_max / sigma_min`` (`Scan.condition_number`).
For ``K >= 3`` tilted beams evenly spaced in azimuth (Windcube V1's DBS: ``K = 4``; ZephIR's
sine fit: ``K = n_los``), ``N^T N = diag(K/2 sin^2 c, K/2 sin^2 c, K cos^2 c)``, so

- without a vertical beam: ``cond = sqrt(2) / tan(c)`` for ``c < 54.7`` degrees
  (``tan(c) / sqrt(2)`` above), whatever ``K``: 2.45 at 30 degrees, 16.2 at 5, and about
  ``81 / c`` for ``c`` in degrees near 0;
- with a vertical beam (Windcube V2, ``K = 4``): ``cond = sqrt((4 cos^2 c + 1) / (2 sin^2 c))``
  for ``c < 65.9`` degrees: 3.06 at 28 degrees, 18.1 at 5, about ``91 / c`` near 0.

Independent LOS noise of standard deviation ``sigma`` gives reconstructed horizontal
components of standard deviation ``sigma sqrt(2/K) / sin(c) = cond sigma / (sqrt(K) cos c)``
(no vertical beam; ``cond sigma / sqrt(4 cos^2 c + 1)`` for the V2): the error grows like the
condition number as the cone closes, while the vertical component stays well determined. A
cone of 0 cannot see the horizontal wind at all. Hence two thresholds:

- `ILL_CONDITIONED` (100; cone angles below 0.81 degrees for DBS and the sine fit, 0.91 for
  the V2): `simulate` sets `lidarjax.Flag.ILL_CONDITIONED`. LOS errors reach the horizontal
  wind amplified more than 50 times (0.1 m/s of LOS noise: over 5 m/s).
- `MAX_CONDITION` (1e4; below 0.0081 degrees, V2 0.0091): `Scan` refuses the geometry with
  a message naming the condition number, the cone angle and the smallest cone angle
  accepted. Beyond it float32 rounding alone (``cond * eps ~ 1e-3`` of the wind) spoils the
  reconstruction, and any real record is noise.

The supported range of real instruments, cone angles 5 to 60 degrees, has ``cond <= 18.1``.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ._precision import HIGHEST, default_float, is_concrete
from .frames import beam_directions

__all__ = ["Scan", "windcube_v1", "windcube_v2", "zephir", "reconstruct", "METHODS",
           "nacelle_2beam", "nacelle_4beam", "nacelle_shear", "NACELLE_AZIMUTHS", "six_beam",
           "SIX_BEAM_AZIMUTHS"]

METHODS = ("windcube_v1", "windcube_v2", "sine_fit", "least_squares", "nacelle_2beam",
           "nacelle_4beam")

#: Body-frame beam azimuths (degrees clockwise from body ``+y``) of the nacelle methods. With
#: the forward-looking mount (``pitch = -90``: body ``z`` along the lidar's ``+y``, body ``+y``
#: pointing down) azimuth 90 looks right and 270 left (2-beam, horizontal); 45/315 are the
#: lower pair and 135/225 the upper pair (4-beam, a square seen from the nacelle).
NACELLE_AZIMUTHS = {"nacelle_2beam": (90.0, 270.0), "nacelle_4beam": (45.0, 135.0, 225.0, 315.0)}

#: Largest condition number of the beam matrix accepted at construction (a cone angle of
#: 0.0081 degrees for DBS and the sine fit, 0.0091 for the Windcube V2); see the module docs.
MAX_CONDITION = 1e4
#: `simulate` flags condition numbers above this with `lidarjax.Flag.ILL_CONDITIONED` (cone
#: angles below 0.81 degrees for DBS and the sine fit, 0.91 for the V2): LOS errors are
#: amplified over 50 times in the horizontal wind. See the module docs.
ILL_CONDITIONED = 1e2


class Scan(eqx.Module):
    """A lidar scan: beam azimuths, cone angle, optional vertical beam, reconstruction.

    **Arguments:**

    - `azimuths`: ``(b,)`` azimuths of the tilted beams in degrees, clockwise from lidar ``+y``.
    - `cone_angle`: angle of the tilted beams from the vertical in degrees, in ``(0, 90)``.
    - `vertical`: whether a vertical beam follows the tilted beams (static).
    - `method`: the reconstruction, one of `METHODS` (static).
    - `tilt_compensation`: whether the instrument knows its tilt (static, default False; see
      `lidarjax.Mount` for pitch and roll). Uncompensated, the reconstruction uses the
      body-frame beam directions (the instrument believes it is level), so a tilted
      instrument reports its body-frame vector. Compensated, it uses the true level-frame
      directions ``T n_b``: every method is a left inverse ``M`` of the body beam matrix
      ``N`` (``M N = I``), and with the true directions ``N T^T`` the same method's left
      inverse is ``T M``, so the compensated vector is ``T`` times the body-frame one
      (for ``"least_squares"`` and ``"sine_fit"`` this is exactly the least-squares solution
      with the level directions). Both agree for a level mount.

    Raises `ValueError` for a cone angle outside ``(0, 90)``, a method whose beam pattern
    does not match, or beams that cannot determine the 3-D wind (condition number of the
    beam matrix above `MAX_CONDITION`).
    """

    azimuths: Float[Array, " b"]
    cone_angle: Float[Array, ""]
    vertical: bool = eqx.field(static=True)
    method: str = eqx.field(static=True)
    tilt_compensation: bool = eqx.field(static=True)

    def __init__(
        self,
        azimuths: Float[ArrayLike, " b"],
        cone_angle: Float[ArrayLike, ""],
        *,
        vertical: bool = False,
        method: str = "least_squares",
        tilt_compensation: bool = False,
    ):
        if method not in METHODS:
            raise ValueError(f"Scan: unknown method {method!r}; choose one of {METHODS}.")
        if not isinstance(tilt_compensation, bool | np.bool_):
            raise ValueError(
                f"Scan: `tilt_compensation` must be True or False, got {tilt_compensation!r}."
            )
        self.vertical = bool(vertical)
        self.method = method
        self.tilt_compensation = bool(tilt_compensation)
        if is_concrete(azimuths, cone_angle):
            _validate(np.asarray(azimuths, dtype=np.float64), np.asarray(cone_angle, np.float64),
                      self.vertical, method)
        self.azimuths = _float(azimuths)
        self.cone_angle = _float(cone_angle)

    @property
    def n_beams(self) -> int:
        """Number of beams, the vertical one included."""
        return self.azimuths.shape[0] + int(self.vertical)

    def beam_azimuths(self) -> Float[Array, " b"]:
        """Azimuth of every beam in degrees (0 for the vertical beam)."""
        if not self.vertical:
            return self.azimuths
        return jnp.concatenate([self.azimuths, jnp.zeros((1,), self.azimuths.dtype)])

    def beam_cones(self) -> Float[Array, " b"]:
        """Cone angle of every beam in degrees (0 for the vertical beam)."""
        c = jnp.broadcast_to(self.cone_angle, self.azimuths.shape)
        if not self.vertical:
            return c
        return jnp.concatenate([c, jnp.zeros((1,), c.dtype)])

    def directions(self) -> Float[Array, "b 3"]:
        """Beam unit vectors in the lidar frame."""
        return beam_directions(self.beam_azimuths(), self.beam_cones())

    def condition_number(self) -> Float[Array, ""]:
        """Condition number of the ``(b, 3)`` beam matrix: the factor by which relative LOS
        errors can grow in the reconstructed vector. ``sqrt(2) / tan(c)`` for evenly spaced
        tilted beams (DBS, sine fit) at cone angles ``c`` below 54.7 degrees,
        ``sqrt((4 cos^2 c + 1) / (2 sin^2 c))`` for the Windcube V2; it diverges as the cone
        angle goes to 0 (see the module docs)."""
        n = self.directions()
        if self.method in NACELLE_AZIMUTHS:  # they solve the two components in the beam plane
            n = n[:, jnp.array([0, 2])]
        s = jnp.linalg.svd(n, compute_uv=False)
        return s[0] / s[-1]


def _float(value):
    value = jnp.asarray(value)
    if not jnp.issubdtype(value.dtype, jnp.floating):
        value = value.astype(default_float())
    return value


def _validate(az: np.ndarray, cone: np.ndarray, vertical: bool, method: str) -> None:
    if az.ndim != 1 or az.size == 0:
        raise ValueError(f"Scan: `azimuths` must be a non-empty 1-D array, got shape {az.shape}.")
    if not np.all(np.isfinite(az)):
        raise ValueError("Scan: `azimuths` must be finite degrees.")
    if cone.shape != () or not np.isfinite(cone) or not (0.0 < cone < 90.0):
        raise ValueError(
            f"Scan: `cone_angle` must be one angle in (0, 90) degrees from the vertical, got "
            f"{cone.tolist()}. A cone of 0 points every beam up and cannot see the horizontal wind."
        )
    if method in ("windcube_v1", "windcube_v2"):
        want_vertical = method == "windcube_v2"
        if az.size != 4 or not np.allclose(np.mod(az - az[0], 360.0), [0, 90, 180, 270], atol=1e-6):
            raise ValueError(
                f"Scan: method {method!r} needs 4 tilted beams at a0 + (0, 90, 180, 270) degrees, "
                f"got azimuths {az.tolist()}. Use method='least_squares' for other patterns."
            )
        if vertical != want_vertical:
            raise ValueError(
                f"Scan: method {method!r} {'needs' if want_vertical else 'has no'} vertical beam; "
                f"got vertical={vertical}."
            )
    if method == "sine_fit" and vertical:
        raise ValueError("Scan: method 'sine_fit' fits tilted beams only; use vertical=False.")
    if method in NACELLE_AZIMUTHS:
        want = np.array(NACELLE_AZIMUTHS[method])
        if vertical or az.size != want.size or not np.allclose(np.mod(az, 360.0), want, atol=1e-6):
            raise ValueError(
                f"Scan: method {method!r} needs body azimuths {want.tolist()} degrees and no "
                f"vertical beam, got {az.tolist()} (vertical={vertical}); use "
                f"lidarjax.scan.{method}()."
            )
        cond = max(np.tan(np.radians(float(cone))), 1.0 / np.tan(np.radians(float(cone))))
        if not cond <= MAX_CONDITION:
            raise ValueError(
                f"Scan: half-angle {float(cone):.3g} degrees of a nacelle lidar gives a "
                f"condition number {cond:.3g} > MAX_CONDITION = {MAX_CONDITION:.0e}; real "
                f"instruments use 10 to 30 degrees."
            )
        return
    if az.size + int(vertical) < 3:
        raise ValueError(
            f"Scan: {az.size + int(vertical)} beams cannot determine the three wind components; "
            f"need at least 3."
        )
    cond = _condition(az, float(cone), vertical)
    if not cond <= MAX_CONDITION:
        if _condition(az, 45.0, vertical) > ILL_CONDITIONED:
            raise ValueError(
                f"Scan: the beams cannot determine the wind (beam-matrix condition number "
                f"{cond:.3g} > MAX_CONDITION = {MAX_CONDITION:.0e}); azimuths {az.tolist()} must "
                f"span at least three distinct directions around the cone."
            )
        if float(cone) < 45.0:
            raise ValueError(
                f"Scan: cone angle {float(cone):.3g} degrees is too close to the vertical: the "
                f"beam-matrix condition number is {cond:.3g} > MAX_CONDITION = "
                f"{MAX_CONDITION:.0e} (about sqrt(2)/tan(cone) for evenly spaced beams), so LOS "
                f"errors would be amplified {cond:.3g} times in the horizontal wind. Use a cone "
                f"angle of at least {_round(_limit_cone(az, vertical, 0.0, 45.0), np.ceil):.2g} degrees (real "
                f"instruments: 15 to 30)."
            )
        raise ValueError(
            f"Scan: cone angle {float(cone):.6g} degrees is too close to the horizontal: the "
            f"beam-matrix condition number is {cond:.3g} > MAX_CONDITION = {MAX_CONDITION:.0e}, "
            f"so the vertical wind is not determined. Use a cone angle of at most "
            f"{_round(_limit_cone(az, vertical, 90.0, 45.0), np.floor, 6):.6g} degrees."
        )


def _condition(az: np.ndarray, cone: float, vertical: bool) -> float:
    """Beam-matrix condition number on the host, in float64 (inf when rank deficient)."""
    cones = np.concatenate([np.full(az.shape, cone), [0.0] if vertical else []])
    azs = np.concatenate([az, [0.0] if vertical else []])
    a, c = np.deg2rad(azs), np.deg2rad(cones)
    n = np.stack([np.sin(c) * np.sin(a), np.sin(c) * np.cos(a), np.cos(c)], axis=-1)
    s = np.linalg.svd(n, compute_uv=False)
    return float(s[0] / s[-1]) if s[-1] > 0 else np.inf


def _round(x: float, direction, digits: int = 2) -> float:
    """`x` rounded to `digits` significant digits by `direction` (np.ceil or np.floor)."""
    step = 10.0 ** (np.floor(np.log10(x)) - digits + 1)
    return float(direction(x / step) * step)


def _limit_cone(az: np.ndarray, vertical: bool, bad: float, good: float) -> float:
    """The cone angle (degrees) between `bad` and `good` where the condition number crosses
    `MAX_CONDITION`, on the `good` side (bisection: the condition number is monotonic on
    either side of its minimum near 55 degrees)."""
    for _ in range(60):
        mid = 0.5 * (bad + good)
        if _condition(az, mid, vertical) > MAX_CONDITION:
            bad = mid
        else:
            good = mid
    return good


def windcube_v1(cone_angle: float = 30.0, *, tilt_compensation: bool = False) -> Scan:
    """Windcube V1: four beams S0..S3 at azimuths 0, 90, 180, 270 degrees (clockwise from
    lidar ``+y``), cone angle in degrees (30 for the V1), the seed's DBS reconstruction.
    `tilt_compensation`: see `Scan`."""
    return Scan([0.0, 90.0, 180.0, 270.0], cone_angle, vertical=False, method="windcube_v1",
                tilt_compensation=tilt_compensation)


def windcube_v2(cone_angle: float = 28.0, *, tilt_compensation: bool = False) -> Scan:
    """Windcube V2: four tilted beams at 0, 90, 180, 270 degrees plus a vertical beam (last);
    ``w`` from the vertical beam. Cone angle in degrees (28 for the V2).
    `tilt_compensation`: see `Scan`."""
    return Scan([0.0, 90.0, 180.0, 270.0], cone_angle, vertical=True, method="windcube_v2",
                tilt_compensation=tilt_compensation)


def zephir(cone_angle: float = 30.0, n_los: int = 50, *, tilt_compensation: bool = False) -> Scan:
    """ZephIR conical scan: `n_los` evenly spaced azimuths from 0 degrees, cone angle in
    degrees (30), reconstructed by the sine fit of seed 003. The real instrument cannot tell
    the sign of a LOS (a CW lidar measures ``|s|``) and resolves direction with a vane;
    lidarjax simulates signed LOS. `tilt_compensation`: see `Scan`."""
    if int(n_los) < 3:
        raise ValueError(f"zephir: n_los must be at least 3, got {n_los}.")
    return Scan(np.arange(int(n_los)) * (360.0 / int(n_los)), cone_angle, method="sine_fit",
                tilt_compensation=tilt_compensation)


def _dbs_horizontal(scan: Scan, los):
    """u, v in the lidar frame from the four tilted DBS beams (rotated back by a0)."""
    c = jnp.deg2rad(scan.cone_angle)
    a0 = jnp.deg2rad(scan.azimuths[0])
    two_sin = 2.0 * jnp.sin(c)
    along0 = (los[..., 0] - los[..., 2]) / two_sin  # along beam S0's horizontal direction
    along1 = (los[..., 1] - los[..., 3]) / two_sin  # along beam S1's (a0 + 90)
    sa, ca = jnp.sin(a0), jnp.cos(a0)
    u = along1 * ca + along0 * sa
    v = -along1 * sa + along0 * ca
    return u, v


def reconstruct(scan: Scan, los: Float[Array, "... b"]) -> Float[Array, "... 3"]:
    """The wind vector ``(u, v, w)`` in the lidar frame (m/s) that the instrument reports.

    **Arguments:**

    - `scan`: the scan; its static `method` selects the formulas (see module docs).
    - `los`: ``(..., b)`` LOS velocities in m/s, positive away from the lidar, beams ordered
      as `Scan.directions`.

    **Returns:** ``(..., 3)`` reconstructed vector in the body frame (the lidar frame of a
    level mount), before the software north rotation. A tilt-compensating instrument
    reports ``T`` times this (see `Scan`; `lidarjax.simulate` applies it).
    """
    los = jnp.asarray(los)
    if los.shape[-1] != scan.n_beams:
        raise ValueError(f"reconstruct: los has {los.shape[-1]} beams, the scan {scan.n_beams}.")
    if scan.method in NACELLE_AZIMUTHS:
        x, _, z = _nacelle_pairs(scan, los)
        return jnp.stack([x, jnp.zeros_like(x), z], axis=-1)
    if scan.method in ("windcube_v1", "windcube_v2"):
        u, v = _dbs_horizontal(scan, los)
        if scan.method == "windcube_v1":
            w = (los[..., 0] + los[..., 2]) / (2.0 * jnp.cos(jnp.deg2rad(scan.cone_angle)))
        else:
            w = los[..., 4]
        return jnp.stack([u, v, w], axis=-1)
    # sine_fit and least_squares: the same linear least squares on the beam matrix.
    pinv = jnp.linalg.pinv(scan.directions().astype(los.dtype))  # (3, b)
    return jnp.einsum("kb,...b->...k", pinv, los, precision=HIGHEST)


# ------------------------------------------------------------------------------------------
# nacelle lidars (forward-looking, Mount(..., pitch=-90))
# ------------------------------------------------------------------------------------------
def nacelle_2beam(half_angle: float = 15.0, *, tilt_compensation: bool = True) -> Scan:
    """A 2-beam forward-looking nacelle lidar (e.g. Avent Wind Iris): two horizontal beams
    `half_angle` degrees either side of the rotor axis (body azimuths 90 and 270 about the
    instrument axis). Mount it with `lidarjax.Mount(..., pitch=-90)` (or
    `lidarjax.scenes.farm.nacelle_mount`): ``heights`` are then distances along the axis and
    each beam focuses at ``distance / cos(half_angle)``.

    Reconstruction (``"nacelle_2beam"``; Kragh et al. 2013, Borraccino et al. 2017) for a
    horizontally homogeneous wind without vertical component: with ``l_r``, ``l_l`` the
    right and left LOS (m/s, positive away),

    ``V_axis = (l_r + l_l) / (2 cos c)``, ``V_cross = (l_r - l_l) / (2 sin c)``,

    the body vector ``(V_cross, 0, V_axis)``; with tilt compensation (default: a nacelle
    lidar knows its mounting) it is reported level, so the horizontal speed of the reported
    vector is the hub-height (rotor-effective) wind speed and its direction, relative to the
    lidar's ``+y`` (the rotor axis, for ``epsilon = 0``), is the yaw misalignment
    (`lidarjax.wrap180` of it; the wind direction minus the nacelle heading)."""
    return Scan(list(NACELLE_AZIMUTHS["nacelle_2beam"]), half_angle, method="nacelle_2beam",
                tilt_compensation=tilt_compensation)


def nacelle_4beam(half_angle: float = 15.0, *, tilt_compensation: bool = True) -> Scan:
    """A 4-beam forward-looking nacelle lidar: beams on a square around the rotor axis,
    `half_angle` degrees off it (body azimuths 45, 135, 225, 315: with ``pitch = -90`` a
    lower pair 45/315 and an upper pair 135/225, each pair left and right).

    Reconstruction (``"nacelle_4beam"``; Borraccino et al. 2017): each pair is a 2-beam lidar
    at its own height (`nacelle_2beam`'s formulas with the pair's horizontal half-angle,
    ``sin c sin 45`` across), assuming no vertical wind; the reported vector is the mean of
    the two pairs' (the rotor-effective hub-height wind and yaw misalignment). The vertical
    shear comes from the pairs' speeds: `nacelle_shear`."""
    return Scan(list(NACELLE_AZIMUTHS["nacelle_4beam"]), half_angle, method="nacelle_4beam",
                tilt_compensation=tilt_compensation)


def _nacelle_pairs(scan: Scan, los):
    """Body-frame ``(V_cross, pairs, V_axis)`` of the nacelle methods: 2-beam gives one pair;
    4-beam the mean of the lower (45/315) and upper (135/225) pairs, and `pairs` carries the
    per-pair ``(cross, axis)`` as ``(..., 2, 2)`` (lower, upper)."""
    c = jnp.deg2rad(scan.cone_angle)
    if scan.method == "nacelle_2beam":
        x = (los[..., 0] - los[..., 1]) / (2.0 * jnp.sin(c))
        z = (los[..., 0] + los[..., 1]) / (2.0 * jnp.cos(c))
        return x, None, z
    s = 2.0 * jnp.sin(c) * jnp.sin(jnp.deg2rad(jnp.asarray(45.0, los.dtype)))
    two_cos = 2.0 * jnp.cos(c)
    lower = ((los[..., 0] - los[..., 3]) / s, (los[..., 0] + los[..., 3]) / two_cos)
    upper = ((los[..., 1] - los[..., 2]) / s, (los[..., 1] + los[..., 2]) / two_cos)
    pairs = jnp.stack([jnp.stack(lower, -1), jnp.stack(upper, -1)], -2)
    x = 0.5 * (lower[0] + upper[0])
    z = 0.5 * (lower[1] + upper[1])
    return x, pairs, z


def nacelle_shear(
    scan: Scan, los: Float[Array, "... 4"], distance: Float[ArrayLike, ...],
    hub_height: Float[ArrayLike, ...],
) -> tuple[Float[Array, ...], Float[Array, ...], Float[Array, ...]]:
    """Power-law shear from a 4-beam nacelle lidar (forward-looking, ``pitch = -90``).

    **Arguments:** `scan` (`nacelle_4beam`), `los` ``(..., 4)`` LOS (m/s) at axial `distance`
    (m, the simulate ``heights``), `hub_height` (m above the ground: the lidar's height).

    Each pair's horizontal speed ``U = sqrt(V_cross^2 + V_axis^2)`` is taken at its height
    ``H -+ dz``, ``dz = (distance / cos c) sin c cos 45``; the exponent is
    ``alpha = ln(U_upper / U_lower) / ln((H + dz) / (H - dz))``.

    **Returns:** ``(alpha, U_lower, U_upper)``.
    """
    if scan.method != "nacelle_4beam":
        raise ValueError(f"nacelle_shear: needs a nacelle_4beam scan, got method {scan.method!r}.")
    los = jnp.asarray(los)
    _, pairs, _ = _nacelle_pairs(scan, los)
    speed = jnp.sqrt(jnp.sum(pairs * pairs, -1))  # (..., 2): lower, upper
    c = jnp.deg2rad(scan.cone_angle)
    dz = jnp.asarray(distance) / jnp.cos(c) * jnp.sin(c) * jnp.sqrt(jnp.asarray(0.5, los.dtype))
    h = jnp.asarray(hub_height)
    alpha = jnp.log(speed[..., 1] / speed[..., 0]) / jnp.log((h + dz) / (h - dz))
    return alpha, speed[..., 0], speed[..., 1]


# ------------------------------------------------------------------------------------------
# the 6-beam scan (Sathe et al. 2015)
# ------------------------------------------------------------------------------------------
#: Body-frame azimuths (degrees clockwise from ``+y``) of `six_beam`'s five inclined beams.
SIX_BEAM_AZIMUTHS = (0.0, 72.0, 144.0, 216.0, 288.0)


def six_beam(cone_angle: float = 45.0, *, azimuth0: float = 0.0,
             tilt_compensation: bool = False) -> Scan:
    """The 6-beam scan of Sathe et al. (2015, "A six-beam method to measure turbulence
    statistics using ground-based wind lidars", AMT 8, 729-740): five beams `cone_angle`
    degrees from the vertical (45: elevation 45 degrees) at azimuths ``azimuth0 + k * 72``
    degrees (clockwise from lidar ``+y``, ``k = 0..4``), then the vertical beam (last).

    Its mean wind is the linear least squares over all six beams (``method="least_squares"``:
    ``(u, v, w)`` minimising ``sum_b (n_b . V - s_b)^2``, `reconstruct`); with ``N^T N =
    diag(5/2 sin^2 c, 5/2 sin^2 c, 5 cos^2 c + 1)`` its beam-matrix condition number is
    ``sqrt((5 cos^2 c + 1) / (5/2 sin^2 c))``, 1.67 at 45 degrees. Its point is the
    turbulence: the six radial-velocity variances determine the six Reynolds stresses
    (`lidarjax.reynolds_stresses`; the 6 x 6 matrix has condition number 3.34 at 45 degrees,
    whatever `azimuth0`). Default timing (`lidarjax.schedule_for`): 1 s per LOS in the order
    above, 6 s per cycle, reconstructed after every LOS from the latest six.
    `tilt_compensation`: see `Scan`."""
    az = np.asarray(SIX_BEAM_AZIMUTHS) + float(azimuth0)
    return Scan(az, cone_angle, vertical=True, method="least_squares",
                tilt_compensation=tilt_compensation)
