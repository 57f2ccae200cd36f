"""Wind farms: engineering wake models as a differentiable scene (`WindFarm`).

A `WindFarm` is an `lidarjax.AbstractField`: `lidarjax.simulate`, `simulate_rotations` and
`ResponseTable` take it like any scene, and it is jit-, vmap- and grad-able in every number
(turbine positions, yaw, thrust, free stream). What changes the compiled graph is static:
the wake `model` (``"top_hat"`` Park/Jensen or ``"gaussian"`` Bastankhah & Porte-Agel 2014),
the `combination` rule and the number of turbines.

**Frames and conventions.** CFD frame ``+x`` east, ``+y`` north, ``+z`` up, metres and m/s;
the field's `origin` is a reference point (by default the first turbine's easting/northing
on the ground datum) and turbine positions are stored relative to it, so float32 stays
accurate at UTM coordinates. The free stream blows from the meteorological `direction`
(degrees clockwise from north), with power-law shear ``U(h) = speed (h / z_ref)**alpha`` at
height ``h`` above the ground datum (NaN below it). Wakes are computed in coordinates
rotated so that ``x_r`` lies along the wind (seed 001, eq. 1, always from the original
coordinates)::

    x_r =  cos(t) x + sin(t) y,     y_r = -sin(t) x + cos(t) y,     t = 270 - direction,

so ``x_r`` points downstream and ``y_r`` to the left of the wind seen from above. `yaw` is the
rotor's misalignment in degrees, positive anticlockwise seen from above (the rotor faces
bearing ``direction - yaw``); the rotor pushes the air against its axis, so a positive yaw
pushes the wake to the right of the wind (``-y_r``). This is FLORIS's sign: with the same
yaw angles the two agree to round-off (tests/scenes/test_farm.py).

**Turbines.** Each turbine ``i`` has a hub at height ``hub_height[i]`` above the datum, a
rotor diameter ``D_i``, a thrust curve ``Ct_i(U)`` (piecewise linear in the rotor-averaged
inflow speed ``U``, constant beyond its ends) and a yaw. The effective thrust of a yawed
rotor is ``Ct cos(yaw)`` and its axial induction ``a = (1 - sqrt(1 - Ct cos^2 yaw)) /
(2 cos yaw)`` (FLORIS's cosine-loss operation model); ``Ct`` is clipped to ``[0, 0.9999]``.

**Wake deficits** (fractions of the local free stream ``U(h)``; ``dx``, ``dy``, ``dz`` are
the rotated offsets from the hub, ``dy`` measured from the deflected centre line):

- ``"top_hat"`` (Jensen 1983 / Katic 1986 Park model): ``2 a (R / (R + k dx + eps))^2``
  inside the cone ``sqrt(dy^2 + dz^2) < R + k dx`` for ``dx > eps``, 0 outside, with the
  wake expansion ``k`` (FLORIS's ``we``) and ``eps = 1 mm`` (FLORIS's ``NUM_EPS``; it
  changes nothing physical and makes the two agree to round-off).
- ``"gaussian"`` (Bastankhah & Porte-Agel 2014): ``C exp(-(dy^2 + dz^2) / (2 sigma^2))`` with
  ``sigma = k dx + 0.2 sqrt(beta) D``, ``beta = (1 + sqrt(1 - Ct')) / (2 sqrt(1 - Ct'))`` and
  ``C = 1 - sqrt(1 - Ct' D^2 / (8 sigma^2))``, ``Ct' = Ct cos(yaw)``. In the near wake
  (``Ct' D^2 / (8 sigma^2) > 1`` for ``Ct'`` above about 0.3 within a few diameters) the
  formula is not valid and reaches full blockage; ``C`` is therefore capped at momentum
  theory's fully expanded deficit ``2a`` by a smooth minimum
  (``(C + 2a - sqrt((C - 2a)^2 + 1e-4)) / 2``; 5e-5 below ``C`` where the cap does not bind,
  i.e. everywhere past about 3-4 D). Two more smoothings keep it differentiable everywhere:
  the square root's argument is floored smoothly (``(s + sqrt(s^2 + 1e-4)) / 2``) and the
  deficit is switched on over the first rotor diameter behind the disc by
  ``1 - exp(-(2 dx / D)^2)`` (0 and flat at the disc, 0.98 at ``dx = D``), so nothing is
  discontinuous at the rotor plane.

**Deflection** of the centre line (seed 001, eq. 7): Jimenez et al. (2010) for yaw, as in
FLORIS (``kd`` = 0.05)::

    xi = Ct' sin(yaw) cos(yaw) / 2  (Ct' = Ct cos yaw),   delta_yaw = xi A / B - C / D0,
    A = 15 (2 kd dx / D + 1)^4 + xi^2,  B = (30 kd / D) (2 kd dx / D + 1)^5,
    C = xi D (15 + xi^2),  D0 = 30 kd,

(0 at the disc, tending to ``-C / D0`` far downstream: negative, to the right of the wind,
for positive yaw), plus the rotation-induced lateral offset
``delta_rot = ad + bd dx`` (Gebraad et al. 2016; FLORIS's ``ad``, ``bd``; metres and m/m,
positive to the left of the wind). Both are added: ``delta = delta_yaw + delta_rot``.

**Combination** of the wakes at a point (static `combination`): ``"sum_of_squares"`` (Katic,
the default) ``sqrt(sum d_i^2)``, ``"linear"`` ``sum d_i``, or ``"max"`` ``max d_i``. The
velocity is ``U(h) (1 - combined)`` along the free-stream heading (no lateral or vertical
wake velocities), as FLORIS's free-stream superpositions (SOSFS, FLS, MAX).

**Turbine interaction.** Each turbine's inflow is the rotor average of the upstream wakes:
each wake's deficit averaged over the receiving disc, then combined. For the top-hat model
the average is exact, the deficit times the overlap area of the wake circle and the rotor
disc (seed 001, eqs. 2-6) over the disc area; for the Gaussian model it is a 32-node disc
quadrature. The free-stream part is the same quadrature's average of the shear profile.
Thrust then follows each turbine's curve at its own inflow: the turbines are solved in
upstream order (``lax.scan`` over the argsort of ``x_r``, one fixed-size step per turbine,
differentiable in every number).

References: N. O. Jensen (1983), Risoe-M-2411; I. Katic et al. (1986), EWEC; M. Bastankhah &
F. Porte-Agel (2014), Renewable Energy 70; A. Jimenez et al. (2010), Wind Energy 13; P.
Gebraad et al. (2016), Wind Energy 19; IEC 61400-12-1 Annex A (see `lidarjax.disturbed_sectors`).
"""

from __future__ import annotations

import copy
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._precision import default_float, is_concrete, safe_sqrt, split
from .._util import compiled
from ..field import AbstractField
from ..mount import Mount

__all__ = ["WindFarm", "FarmState", "wind_farm", "overlap_area", "to_floris", "nacelle_mount",
           "MODELS", "COMBINATIONS",
           "DEFAULT_EXPANSION"]

MODELS = ("top_hat", "gaussian")
COMBINATIONS = ("sum_of_squares", "linear", "max")
#: Default wake expansion ``k`` per model: Jensen's onshore 0.05 (FLORIS's ``we``) and the
#: Gaussian wake growth rate ``k*`` = 0.0324555 (PyWake's BastankhahGaussian default).
DEFAULT_EXPANSION = {"top_hat": 0.05, "gaussian": 0.0324555}
#: FLORIS's NUM_EPS (m): the top-hat deficit's denominator is ``R + k dx + eps`` and a point
#: is in a wake only ``eps`` behind the disc.
EPS = 1e-3
_SQRT_FLOOR = 1e-2  # softness of the Gaussian's square-root floor (see module docs)


# ----------------------------------------------------------------------------------------
# overlap area of two circles (seed 001, eqs. 2-6), with exact, finite derivatives
# ----------------------------------------------------------------------------------------
def _half_angles(r1, r2, d):
    """Half-angles (radians) subtended by the common chord at each centre, with the
    limits of the no/full-overlap cases; finite for every input (safe-masked)."""
    ok = d > 0
    ds = jnp.where(ok, d, 1.0)
    c1 = jnp.clip((r1 * r1 - r2 * r2 + ds * ds) / (2.0 * ds * r1), -1.0, 1.0)
    c2 = jnp.clip((r2 * r2 - r1 * r1 + ds * ds) / (2.0 * ds * r2), -1.0, 1.0)
    a1 = jnp.arccos(c1)
    a2 = jnp.arccos(c2)
    none = d >= r1 + r2
    inside = d <= jnp.abs(r1 - r2)  # one circle inside the other (d = 0 included)
    wake_covers = r1 >= r2
    a1 = jnp.where(none, 0.0, jnp.where(inside, jnp.where(wake_covers, 0.0, jnp.pi), a1))
    a2 = jnp.where(none, 0.0, jnp.where(inside, jnp.where(wake_covers, jnp.pi, 0.0), a2))
    return a1, a2


@jax.custom_jvp
def _overlap_area(r1, r2, d):
    """Overlap area (m^2) of a wake circle of radius `r1` and a rotor disc of radius `r2`
    whose centres are `d` apart (metres), seed 001's eqs. 2-6.

    - no overlap, ``d >= r1 + r2``: 0 (eq. 2);
    - partial, ``|r1 - r2| < d < r1 + r2``:
      ``r1^2 acos((r1^2 - r2^2 + d^2) / (2 d r1)) + r2^2 acos((r2^2 - r1^2 + d^2) / (2 d r2))
      - sqrt(T) / 2`` with ``T = ((r1 + r2)^2 - d^2)(d^2 - (r1 - r2)^2)`` (eqs. 3-5);
    - full, ``d <= r1 - r2``: ``pi r2^2`` (eq. 6), and ``pi r1^2`` when the wake is the
      smaller circle (``d <= r2 - r1``, not in the seed).

    Broadcasts over its arguments. The derivatives are the closed forms
    ``dA/dr1 = 2 r1 a1``, ``dA/dr2 = 2 r2 a2``, ``dA/dd = -sqrt(T) / d`` (the common chord),
    with ``a1, a2`` the half-angles of the chord: continuous across the case boundaries and
    finite everywhere (no infinite ``acos'`` at +-1, no ``sqrt'(T)`` at ``T = 0``).
    """
    r1, r2, d = jnp.broadcast_arrays(r1, r2, d)
    none = d >= r1 + r2
    inside = d <= jnp.abs(r1 - r2)
    partial = ~(none | inside)
    ds = jnp.where(partial, d, 1.0)
    r1s = jnp.where(partial, r1, 1.0)
    r2s = jnp.where(partial, r2, 1.0)
    c1 = jnp.clip((r1s**2 - r2s**2 + ds**2) / (2.0 * ds * r1s), -1.0, 1.0)
    c2 = jnp.clip((r2s**2 - r1s**2 + ds**2) / (2.0 * ds * r2s), -1.0, 1.0)
    t = ((r1s + r2s) ** 2 - ds**2) * (ds**2 - (r1s - r2s) ** 2)
    lens = r1s**2 * jnp.arccos(c1) + r2s**2 * jnp.arccos(c2) - 0.5 * jnp.sqrt(jnp.maximum(t, 0.0))
    small = jnp.minimum(r1, r2)
    return jnp.where(none, 0.0, jnp.where(inside, jnp.pi * small * small, lens))


@_overlap_area.defjvp
def _overlap_area_jvp(primals, tangents):
    r1, r2, d = jnp.broadcast_arrays(*primals)
    t1, t2, td = (jnp.broadcast_to(t, r1.shape) for t in tangents)
    area = _overlap_area(r1, r2, d)
    a1, a2 = _half_angles(r1, r2, d)
    chord = 2.0 * r1 * jnp.sin(a1)  # = sqrt(T) / d in the partial case, 0 outside it
    return area, 2.0 * r1 * a1 * t1 + 2.0 * r2 * a2 * t2 - chord * td


# public: one compiled program from the host (eagerly, its ~40 operations compiled one by one)
overlap_area = compiled(_overlap_area)


# ----------------------------------------------------------------------------------------
# the scene
# ----------------------------------------------------------------------------------------
def _disc_nodes(n_r: int = 4, n_a: int = 8):
    """Unit-disc quadrature: Gauss-Legendre in ``rho^2`` (area-uniform) times a uniform
    azimuth rule; returns ``(q, 2)`` offsets (lateral, vertical) and ``(q,)`` weights
    summing to 1. Exact for polynomials of degree ``2 n_r - 1`` in ``rho^2``."""
    x, w = np.polynomial.legendre.leggauss(n_r)
    rho = np.sqrt(0.5 * (x + 1.0))
    phi = (np.arange(n_a) + 0.5) * (2.0 * np.pi / n_a)
    yy = (rho[:, None] * np.cos(phi)[None]).ravel()
    zz = (rho[:, None] * np.sin(phi)[None]).ravel()
    ww = (0.5 * w[:, None] * np.full(n_a, 1.0 / n_a)[None]).ravel()
    return np.stack([yy, zz], -1), ww


_DISC_XY, _DISC_W = _disc_nodes()


class FarmState(eqx.Module):
    """The solved turbines of a `WindFarm` (``i`` turbines, in input order).

    - `inflow`: ``(i,)`` rotor-averaged inflow speed, m/s (what the thrust curve reads).
    - `ct`: ``(i,)`` thrust coefficient from the curve at `inflow` (before the yaw loss).
    - `induction`: ``(i,)`` axial induction with the yaw (cosine) loss.
    - `x_r`, `y_r`: ``(i,)`` hub coordinates in the wind-aligned frame (m, relative to
      the origin; ``x_r`` downstream, ``y_r`` to the left of the wind).
    - `order`: ``(i,)`` turbine indices from upstream to downstream.
    """

    inflow: Float[Array, " i"]
    ct: Float[Array, " i"]
    induction: Float[Array, " i"]
    x_r: Float[Array, " i"]
    y_r: Float[Array, " i"]
    order: Array


class WindFarm(AbstractField):
    """A wind farm's wake field (see the module docs for models and conventions).

    Build one with `wind_farm` (which validates and handles UTM coordinates). Fields, all
    dynamic and differentiable unless marked static (``i`` turbines, ``m`` curve points):

    - `origin`, `origin_lo`: reference point, CFD metres (high part + float64 residual);
      ``origin[2]`` is the ground datum of heights.
    - `x`, `y`: ``(i,)`` turbine easting/northing relative to the origin, m.
    - `hub_height`: ``(i,)`` hub heights above the datum, m. `diameter`: ``(i,)`` rotor
      diameters, m.
    - `ct_speed`, `ct_value`: ``(i, m)`` thrust curves: increasing speeds (m/s) and Ct.
    - `yaw`: ``(i,)`` misalignment, degrees, positive anticlockwise seen from above (the
      rotor faces bearing ``direction - yaw``; FLORIS's sign).
    - `speed` (m/s at `z_ref` m), `direction` (degrees, meteorological), `alpha` (shear
      exponent).
    - `expansion`: wake expansion ``k`` (top hat) or growth rate ``k*`` (Gaussian).
    - `kd`: Jimenez deflection coefficient; `ad` (m), `bd` (m/m): rotation-induced offset.
    - `model`, `combination`: static strings (`MODELS`, `COMBINATIONS`).
    """

    origin: Float[Array, 3]
    origin_lo: Float[Array, 3]
    x: Float[Array, " i"]
    y: Float[Array, " i"]
    hub_height: Float[Array, " i"]
    diameter: Float[Array, " i"]
    ct_speed: Float[Array, "i m"]
    ct_value: Float[Array, "i m"]
    yaw: Float[Array, " i"]
    speed: Float[Array, ""]
    direction: Float[Array, ""]
    z_ref: Float[Array, ""]
    alpha: Float[Array, ""]
    expansion: Float[Array, ""]
    kd: Float[Array, ""]
    ad: Float[Array, ""]
    bd: Float[Array, ""]
    model: str = eqx.field(static=True)
    combination: str = eqx.field(static=True)

    @property
    def resolution(self) -> float | None:
        """A sixth of the smallest rotor diameter: a Gaussian wake of width ``sigma >= 0.2 D``
        has a spectrum below 1e-3 of its peak beyond ``k = 3.7 / sigma``, the Nyquist
        wavenumber of a spacing ``0.85 sigma``."""
        if not is_concrete(self.diameter):
            return None
        return float(np.min(np.asarray(self.diameter, np.float64))) / 6.0

    def __check_init__(self):
        if self.model not in MODELS:
            raise ValueError(f"WindFarm: unknown model {self.model!r}; choose one of {MODELS}.")
        if self.combination not in COMBINATIONS:
            raise ValueError(
                f"WindFarm: unknown combination {self.combination!r}; choose one of {COMBINATIONS}."
            )

    @property
    def n_turbines(self) -> int:
        return self.x.shape[-1]

    # -- frames -------------------------------------------------------------------------
    def _trig(self):
        t = jnp.deg2rad(270.0 - self.direction)
        return jnp.cos(t), jnp.sin(t)

    def rotated(self, points: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
        """Local points (m, relative to `origin`) in the wind-aligned frame of seed 001 eq. 1:
        ``(x_r, y_r, z)``, ``x_r`` downstream, ``y_r`` left of the wind, ``z`` unchanged."""
        c, s = self._trig()
        px, py = points[..., 0], points[..., 1]
        return jnp.stack([c * px + s * py, -s * px + c * py, points[..., 2]], -1)

    def heading(self) -> Float[Array, 3]:
        """Unit vector the free stream blows towards (CFD frame)."""
        c, s = self._trig()
        return jnp.stack([c, s, jnp.zeros_like(c)])

    def free_speed(self, height):
        """Free-stream speed (m/s) at `height` m above the datum; finite stand-in below it."""
        hs = jnp.where(height > 0, height, self.z_ref)
        return jnp.where(height > 0, self.speed * (hs / self.z_ref) ** self.alpha, 0.0)

    # -- wake physics -------------------------------------------------------------------
    def _thrust(self, ct, yaw_rad):
        cy = jnp.cos(yaw_rad)
        ct = jnp.clip(ct, 0.0, 0.9999)
        ct_eff = ct * cy
        a = (1.0 - jnp.sqrt(1.0 - ct_eff * cy)) / (2.0 * cy)
        return ct_eff, a

    def _deflection(self, dx, ct_eff, yaw_rad, diam):
        """Lateral offset (m, +y_r) of wake centre lines at `dx` m behind their discs."""
        dxs = jnp.maximum(dx, 0.0)
        kd = self.kd
        xi = jnp.cos(yaw_rad) * jnp.sin(yaw_rad) * ct_eff / 2.0
        g = 2.0 * kd * dxs / diam + 1.0
        g4 = (g * g) * (g * g)
        big_a = 15.0 * g4 + xi * xi
        big_b = (30.0 * kd / diam) * g4 * g
        big_c = xi * diam * (15.0 + xi * xi)
        y_yaw = xi * big_a / big_b - big_c / (30.0 * kd)
        return y_yaw + self.ad + self.bd * dx

    def _deficit(self, dx, dy, dz, radius, a, ct_eff, diam):
        """Fractional deficit of one wake at offsets from its (deflected) centre line."""
        if self.model == "top_hat":
            r = radius + self.expansion * dx
            inside = (dx > EPS) & (dy * dy + dz * dz < r * r)
            c = (radius / (r + EPS)) ** 2
            return jnp.where(inside, 2.0 * a * c, 0.0)
        ahead = dx > 0
        dxs = jnp.where(ahead, dx, 0.0)
        root = jnp.sqrt(1.0 - ct_eff)
        beta = 0.5 * (1.0 + root) / root
        sigma = self.expansion * dxs + 0.2 * jnp.sqrt(beta) * diam
        arg = 1.0 - ct_eff * diam * diam / (8.0 * sigma * sigma)
        arg = 0.5 * (arg + jnp.sqrt(arg * arg + _SQRT_FLOOR**2))
        amp = 1.0 - jnp.sqrt(arg)
        cap = 2.0 * a  # momentum theory's far-wake deficit: BPA exceeds it in the near wake
        amp = 0.5 * (amp + cap - jnp.sqrt((amp - cap) ** 2 + _SQRT_FLOOR**2))
        onset = 1.0 - jnp.exp(-((2.0 * dxs / diam) ** 2))
        value = amp * onset * jnp.exp(-(dy * dy + dz * dz) / (2.0 * sigma * sigma))
        return jnp.where(ahead, value, 0.0)

    def _combine(self, d, axis):
        if self.combination == "linear":
            return jnp.sum(d, axis=axis)
        if self.combination == "max":
            return jnp.max(d, axis=axis)
        return safe_sqrt(jnp.sum(d * d, axis=axis))

    def solve(self) -> FarmState:
        """Solve the turbines in upstream order: rotor-averaged inflow, Ct and induction.
        (Compiled once per farm structure: the number of turbines, curve length, model.)"""
        return _solve_jit(self)

    def _solve(self) -> FarmState:
        dtype = self.dtype
        xr, yr, _ = jnp.moveaxis(self.rotated(jnp.stack(
            [self.x, self.y, self.hub_height], -1)), -1, 0)
        yaw = jnp.deg2rad(self.yaw)
        radius = 0.5 * self.diameter
        nodes = jnp.asarray(_DISC_XY, dtype)
        weights = jnp.asarray(_DISC_W, dtype)
        node_z = self.hub_height[:, None] + radius[:, None] * nodes[None, :, 1]  # (j, q)
        free_rotor = jnp.sum(self.free_speed(node_z) * weights, -1)  # (j,)
        order = jnp.argsort(xr)
        n = self.n_turbines
        ct0, a0 = jnp.zeros(n, dtype), jnp.zeros(n, dtype)
        cte0 = jnp.zeros(n, dtype)

        def step(carry, j):
            ct, cte, a, inflow = carry
            dx = xr[j] - xr  # (i,) distance of j behind each source i
            defl = self._deflection(dx, cte, yaw, self.diameter)
            dy = yr[j] - yr - defl
            dz = self.hub_height[j] - self.hub_height
            if self.model == "top_hat":
                r1 = radius + self.expansion * dx
                dist = safe_sqrt(dy * dy + dz * dz)
                frac = _overlap_area(jnp.maximum(r1, 0.0), radius[j], dist) / (
                    jnp.pi * radius[j] ** 2)
                c = (radius / (r1 + EPS)) ** 2
                d = jnp.where(dx > EPS, 2.0 * a * c * frac, 0.0)
            else:
                ny = dy[:, None] + radius[j] * nodes[None, :, 0]
                nz = dz[:, None] + radius[j] * nodes[None, :, 1]
                dq = self._deficit(dx[:, None], ny, nz, radius[:, None], a[:, None],
                                   cte[:, None], self.diameter[:, None])
                d = jnp.sum(dq * weights, -1)
            u_j = free_rotor[j] * (1.0 - self._combine(d, 0))
            ct_j = jnp.interp(u_j, self.ct_speed[j], self.ct_value[j])
            cte_j, a_j = self._thrust(ct_j, yaw[j])
            carry = (ct.at[j].set(ct_j), cte.at[j].set(cte_j), a.at[j].set(a_j),
                     inflow.at[j].set(u_j))
            return carry, None

        (ct, _, a, inflow), _ = jax.lax.scan(step, (ct0, cte0, a0, jnp.zeros(n, dtype)), order)
        return FarmState(inflow, ct, a, xr, yr, order)

    def deficits(self, points: Float[Array, "... 3"], state: FarmState | None = None
                 ) -> Float[Array, "... i"]:
        """Each wake's fractional deficit at local points (m, relative to `origin`)."""
        if state is None:
            state = self.solve()
        pr = self.rotated(points)
        yaw = jnp.deg2rad(self.yaw)
        cte, _ = self._thrust(state.ct, yaw)
        dx = pr[..., 0, None] - state.x_r
        defl = self._deflection(dx, cte, yaw, self.diameter)
        dy = pr[..., 1, None] - state.y_r - defl
        dz = pr[..., 2, None] - self.hub_height
        return self._deficit(dx, dy, dz, 0.5 * self.diameter, state.induction, cte, self.diameter)

    def streamwise_local(self, points: Float[Array, "... 3"], state: FarmState | None = None
                         ) -> Float[Array, ...]:
        """Speed along the free-stream heading (m/s) at local points: ``U(h) (1 - combined)``;
        NaN below the ground datum."""
        if state is None:
            return _streamwise_jit(self, points)
        return self._streamwise(points, state)

    def _streamwise(self, points, state):
        h = points[..., 2]
        u = self.free_speed(h) * (1.0 - self._combine(self.deficits(points, state), -1))
        return jnp.where(h >= 0, u, jnp.nan)

    def sample_local(self, points):
        u = self.streamwise_local(points)
        return u[..., None] * self.heading().astype(u.dtype)

    # -- helpers for users --------------------------------------------------------------
    def hub_points(self) -> Float[Array, "i 3"]:
        """Hub centres, local coordinates (m, relative to `origin`)."""
        return jnp.stack([self.x, self.y, self.hub_height], -1)

    def reference_points(self, offset: float = 1.0) -> Float[Array, "i 3"]:
        """Seed 004's reference points: `offset` rotor diameters upstream of each disc
        centre along the free-stream direction, at hub height (local coordinates, m)."""
        up = -self.heading()
        return self.hub_points() + (offset * self.diameter)[:, None] * up

    def rotor_heading(self) -> Float[Array, " i"]:
        """Bearing (degrees clockwise from north) each rotor faces: ``direction - yaw``."""
        return self.direction - self.yaw


@eqx.filter_jit
def _solve_jit(farm: WindFarm) -> FarmState:
    return farm._solve()


@eqx.filter_jit
def _streamwise_jit(farm: WindFarm, points):
    return farm._streamwise(points, farm._solve())


def _is_1d(value) -> bool:
    """A 1-D sequence of numbers (a curve's speeds or Ct), not a scalar or a curve."""
    try:
        return np.asarray(value, np.float64).ndim == 1
    except (ValueError, TypeError):
        return False


#: FLORIS clips every thrust coefficient to this range before using it
#: (``floris.core.turbine.operation_models``); lidarjax applies the same clip to curves that
#: leave ``[0, 1)``, such as FLORIS's own NREL 5 MW curve (Ct up to 1.13 below cut-in).
FLORIS_CT_BOUNDS = (1e-4, 0.9999)


def clip_thrust_curve(ct, where: str) -> np.ndarray:
    """`ct` (any shape) as float64, clipped to `FLORIS_CT_BOUNDS` as FLORIS does when some
    value lies outside ``[0, 1)``, with one `UserWarning` naming `where` and the range found;
    returned unchanged (no clip, no warning) when every value is in ``[0, 1)``. Non-finite
    values raise `ValueError`."""
    v = np.asarray(ct, np.float64)
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{where}: Ct contains NaN or inf.")
    if v.size and (v.min() < 0.0 or v.max() >= 1.0):
        lo, hi = FLORIS_CT_BOUNDS
        warnings.warn(f"{where}: Ct {v.min():g}..{v.max():g} leaves [0, 1); clipped to "
                      f"[{lo:g}, {hi:g}] as FLORIS does", UserWarning, stacklevel=3)
        v = np.clip(v, lo, hi)
    return v


def _curves(ct, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Thrust curves as ``(n, m)`` speed and Ct arrays (host, float64)."""
    if isinstance(ct, int | float | np.floating) or (
            not isinstance(ct, list | tuple) and np.ndim(ct) == 0):
        v = float(ct)
        if not 0.0 <= v < 1.0:
            raise ValueError(f"wind_farm: constant `ct` must be in [0, 1), got {v}.")
        return np.tile([0.0, 100.0], (n, 1)), np.full((n, 2), v)
    if isinstance(ct, tuple) and len(ct) == 2 and _is_1d(ct[0]) and _is_1d(ct[1]):
        ct = [ct] * n  # one (speeds, ct) curve for every turbine
    ct = list(ct) if isinstance(ct, list | tuple) else list(np.asarray(ct))
    if len(ct) != n:
        raise ValueError(f"wind_farm: `ct` needs one thrust curve per turbine ({n}), got {len(ct)}.")
    curves = []
    for k, c in enumerate(ct):
        if np.ndim(c) == 0:
            curves.append((np.array([0.0, 100.0]), np.full(2, float(c))))
            continue
        s, v = (np.asarray(a, np.float64) for a in c)
        if s.ndim != 1 or s.shape != v.shape or s.size < 1:
            raise ValueError(f"wind_farm: thrust curve {k} must be two 1-D arrays (speeds, Ct) "
                             f"of one length, got shapes {s.shape} and {v.shape}.")
        if not (np.all(np.isfinite(s)) and np.all(np.isfinite(v))):
            raise ValueError(f"wind_farm: thrust curve {k} contains NaN or inf.")
        if np.any(np.diff(s) <= 0):
            raise ValueError(f"wind_farm: thrust curve {k}: speeds must be strictly increasing.")
        curves.append((s, clip_thrust_curve(v, f"wind_farm: thrust curve {k}")))
    m = max(c[0].size for c in curves)
    speeds = np.empty((n, max(m, 2)))
    values = np.empty((n, max(m, 2)))
    for k, (s, v) in enumerate(curves):
        if s.size == 1:
            s, v = np.array([s[0], s[0] + 1.0]), np.array([v[0], v[0]])
        pad = speeds.shape[1] - s.size  # pad with flat points beyond the last speed
        speeds[k] = np.concatenate([s, s[-1] + 1.0 + np.arange(pad)])
        values[k] = np.concatenate([v, np.full(pad, v[-1])])
    return speeds, values


def wind_farm(
    easting: Float[ArrayLike, " i"],
    northing: Float[ArrayLike, " i"],
    hub_height: Float[ArrayLike, " i"],
    diameter: Float[ArrayLike, " i"],
    *,
    ct=0.8,
    yaw: Float[ArrayLike, " i"] = 0.0,
    speed: float = 10.0,
    direction: float = 270.0,
    alpha: float = 0.0,
    z_ref: float | None = None,
    model: str = "top_hat",
    combination: str = "sum_of_squares",
    expansion: float | None = None,
    kd: float = 0.05,
    ad: float = 0.0,
    bd: float = 0.0,
    ground: float = 0.0,
    origin: Float[ArrayLike, 2] | None = None,
    dtype=None,
) -> WindFarm:
    """A `WindFarm` from turbine coordinates (CFD/UTM metres) and a free stream.

    **Arguments:**

    - `easting`, `northing`: ``(i,)`` turbine positions, m (UTM-sized values are fine in
      float32: they are stored relative to `origin`, computed in float64).
    - `hub_height`, `diameter`: hub heights above the ground datum `ground` and rotor
      diameters, m; scalars broadcast.
    - `ct`: a constant thrust coefficient in ``[0, 1)``, a ``(speeds, ct)`` curve for all
      turbines, or a list with one constant or curve per turbine (speeds in m/s,
      increasing). A curve that leaves ``[0, 1)`` (FLORIS's NREL 5 MW rises to 1.13 below
      cut-in) is clipped to `FLORIS_CT_BOUNDS` as FLORIS does, with one warning.
    - `yaw`: misalignment in degrees (scalar or ``(i,)``), positive anticlockwise seen from
      above (FLORIS's sign): the rotor faces bearing ``direction - yaw``.
    - `speed`: free-stream speed at `z_ref` (m/s; default height: the mean hub height),
      `direction`: meteorological degrees, `alpha`: power-law shear exponent (0: uniform).
    - `model`: ``"top_hat"`` or ``"gaussian"``; `combination`: ``"sum_of_squares"``,
      ``"linear"`` or ``"max"`` (static).
    - `expansion`: ``k`` (default `DEFAULT_EXPANSION` of the model); `kd`, `ad`, `bd`: the
      deflection parameters (module docs).
    - `origin`: ``(easting, northing)`` of the reference point (default: the first turbine).

    Raises `ValueError` for bad shapes, non-positive sizes, unknown options, or turbines
    sharing a position.
    """
    if model not in MODELS:
        raise ValueError(f"wind_farm: unknown model {model!r}; choose one of {MODELS}.")
    if combination not in COMBINATIONS:
        raise ValueError(f"wind_farm: unknown combination {combination!r}; choose one of "
                         f"{COMBINATIONS}.")
    dt = jnp.dtype(dtype) if dtype is not None else default_float()
    e = np.atleast_1d(np.asarray(easting, np.float64))
    nn = np.atleast_1d(np.asarray(northing, np.float64))
    if e.ndim != 1 or e.shape != nn.shape or e.size == 0:
        raise ValueError(f"wind_farm: easting and northing must be 1-D of one length, got "
                         f"{e.shape} and {nn.shape}.")
    n = e.size
    hh = np.broadcast_to(np.asarray(hub_height, np.float64), (n,)).copy()
    dd = np.broadcast_to(np.asarray(diameter, np.float64), (n,)).copy()
    for name, arr in (("easting", e), ("northing", nn), ("hub_height", hh), ("diameter", dd)):
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"wind_farm: `{name}` must be finite.")
    if np.any(dd <= 0) or np.any(hh <= 0):
        raise ValueError("wind_farm: hub heights and rotor diameters must be positive metres.")
    if np.any(hh < 0.5 * dd):
        k = int(np.argmax(hh < 0.5 * dd))
        raise ValueError(f"wind_farm: turbine {k}: hub height {hh[k]:g} m is below its rotor "
                         f"radius {0.5 * dd[k]:g} m (the blades would hit the ground).")
    dup = _first_duplicate(e, nn)
    if dup is not None:
        raise ValueError(f"wind_farm: turbines {dup[0]} and {dup[1]} share one position.")
    speeds, values = _curves(ct, n)
    if is_concrete(yaw):
        yy = np.broadcast_to(np.asarray(yaw, np.float64), (n,))
        if np.any(np.abs(yy) >= 90.0):
            raise ValueError("wind_farm: |yaw| must be below 90 degrees.")
    if is_concrete(speed, direction, alpha) and not (np.isfinite(speed) and speed > 0):
        raise ValueError(f"wind_farm: `speed` must be positive m/s, got {speed!r}.")
    o_en = np.array([e[0], nn[0]]) if origin is None else np.asarray(origin, np.float64)
    o, lo = split(np.array([o_en[0], o_en[1], float(ground)]), dt)
    k = DEFAULT_EXPANSION[model] if expansion is None else expansion
    zr = float(np.mean(hh)) if z_ref is None else z_ref
    f = lambda v: jnp.asarray(v, dt)  # noqa: E731
    return WindFarm(
        o, lo, f(e - o_en[0]), f(nn - o_en[1]), f(hh), f(dd), f(speeds), f(values),
        jnp.broadcast_to(jnp.asarray(yaw, dt), (n,)), f(speed), f(direction), f(zr), f(alpha),
        f(k), f(kd), f(ad), f(bd), model, combination,
    )


def _first_duplicate(e, n):
    for i in range(e.size):
        same = np.flatnonzero((e[i + 1:] == e[i]) & (n[i + 1:] == n[i]))
        if same.size:
            return i, i + 1 + int(same[0])
    return None


_FLORIS_DEFAULTS: dict = {}


def _floris_defaults(model_cls) -> dict:
    if "d" not in _FLORIS_DEFAULTS:
        _FLORIS_DEFAULTS["d"] = model_cls("defaults").core.as_dict()
    return _FLORIS_DEFAULTS["d"]


def to_floris(farm: WindFarm, *, turbulence_intensity: float = 0.06):
    """The same farm as a FLORIS (``floris>=4``) model, for validation and benchmarks.

    The conventions that map one package onto the other (all verified to round-off by
    tests/scenes/test_farm.py):

    - coordinates: FLORIS's ``layout_x``/``layout_y`` are `WindFarm.x` / `WindFarm.y` (the
      turbines relative to ``farm.origin``, m, ``x`` east, ``y`` north) and FLORIS ``z`` is
      the height above the ground datum ``origin[2]``; sample FLORIS at local points;
    - direction: both meteorological, FLORIS's 270 blowing towards ``+x``; FLORIS rotates
      about the centre of the layout's bounding box, lidarjax about the origin (a shift
      along and across the wind: nothing changes);
    - yaw: the same angle and sign (positive anticlockwise seen from above, wake to the
      right of the wind);
    - Jensen's ``we`` is `WindFarm.expansion`; Jimenez's ``kd``, ``ad``, ``bd`` are `kd`,
      `ad`, `bd`; FLORIS's NUM_EPS (1 mm) is lidarjax's `EPS`;
    - thrust: the ``cosine-loss`` operation model with ``ref_tilt = 0`` (Ct cos(yaw) and
      the induction of the module docs); FLORIS reads its curve at the rotor-grid cubic
      mean and returns 1e-4 outside the curve, lidarjax at the exact rotor average (top
      hat) and holds the end values;
    - shear: ``wind_shear = alpha``, ``reference_wind_height = z_ref``;
    - combination: ``sum_of_squares`` is ``sosfs``, ``linear`` is ``fls``, ``max`` is ``max``;
    - no secondary steering, yaw-added recovery or transverse velocities (FLORIS's GCH
      additions, absent from the Jensen/Jimenez model).

    Only the top-hat model has a FLORIS twin (FLORIS's ``gauss`` is Bastankhah & Porte-Agel
    2016 with a near-wake core, not the 2014 model here). Needs the ``farm`` extra
    (``pip install lidarjax[farm]``).
    """
    try:
        from floris import FlorisModel
    except ImportError as err:  # pragma: no cover - depends on the environment
        raise ImportError("to_floris needs FLORIS: pip install 'lidarjax[farm]'") from err
    if farm.model != "top_hat":
        raise ValueError("to_floris: only the top-hat (Jensen) model has a FLORIS twin.")
    comb = {"sum_of_squares": "sosfs", "linear": "fls", "max": "max"}[farm.combination]
    f = lambda a: np.asarray(a, np.float64)  # noqa: E731
    turbines = []
    for k in range(farm.n_turbines):
        turbines.append({
            "turbine_type": f"lidarjax_{k}", "hub_height": float(farm.hub_height[k]),
            "rotor_diameter": float(farm.diameter[k]), "TSR": 8.0,
            "operation_model": "cosine-loss",
            "power_thrust_table": {
                "ref_air_density": 1.225, "ref_tilt": 0.0, "cosine_loss_exponent_yaw": 1.88,
                "cosine_loss_exponent_tilt": 1.88, "wind_speed": f(farm.ct_speed[k]).tolist(),
                "power": [0.0] * farm.ct_speed.shape[1],
                "thrust_coefficient": f(farm.ct_value[k]).tolist()},
        })
    d = copy.deepcopy(_floris_defaults(FlorisModel))
    d["wake"]["model_strings"].update(velocity_model="jensen", deflection_model="jimenez",
                                      combination_model=comb, turbulence_model="crespo_hernandez")
    d["wake"]["enable_secondary_steering"] = False
    d["wake"]["enable_yaw_added_recovery"] = False
    d["wake"]["enable_transverse_velocities"] = False
    d["wake"]["wake_velocity_parameters"]["jensen"] = {"we": float(farm.expansion)}
    d["wake"]["wake_deflection_parameters"]["jimenez"] = {
        "kd": float(farm.kd), "ad": float(farm.ad), "bd": float(farm.bd)}
    d["flow_field"]["wind_shear"] = float(farm.alpha)
    d["flow_field"]["reference_wind_height"] = float(farm.z_ref)
    d["farm"]["layout_x"] = f(farm.x).tolist()
    d["farm"]["layout_y"] = f(farm.y).tolist()
    d["farm"]["turbine_type"] = turbines
    model = FlorisModel(d)
    model.set(wind_directions=[float(farm.direction)], wind_speeds=[float(farm.speed)],
              turbulence_intensities=[turbulence_intensity], yaw_angles=f(farm.yaw)[None])
    return model


def nacelle_mount(farm: WindFarm, index: int, *, backward: bool = False, north: bool = False,
                  offset: float = 0.0):
    """A `lidarjax.Mount` for a nacelle lidar on turbine `index` of `farm`, at its hub,
    yawed with the rotor and looking along the rotor axis (``pitch = -90``).

    - forward (default): the instrument axis points upstream, to bearing
      ``direction - yaw`` (`WindFarm.rotor_heading`); ``backward=True`` turns it 180 degrees
      to look downstream into the turbine's own wake;
    - `offset`: metres along the looking direction from the hub (e.g. negative for a lidar
      on the nacelle roof behind the rotor);
    - `north`: report directions in the north frame (``epsilon`` = the lidar heading);
      by default (False) they are relative to the lidar's axis, so the reported direction of
      a forward lidar is the yaw misalignment (wind direction minus rotor heading, use
      `lidarjax.wrap180`).

    Dynamic in the farm (direction, yaw): use it inside `jax.vmap` over directions. The
    location is kept exact at UTM coordinates (the farm's origin plus the local hub)."""

    heading = farm.rotor_heading()[index] + (180.0 if backward else 0.0)
    h = jnp.deg2rad(heading)
    ahead = jnp.stack([jnp.sin(h), jnp.cos(h), jnp.zeros_like(h)])
    local = farm.hub_points()[index] + offset * ahead
    mount = Mount(np.zeros(3), pitch=-90.0)
    dt = farm.dtype
    return eqx.tree_at(
        lambda m: (m.location, m.location_lo, m.psi, m.epsilon, m.pitch),
        mount,
        (farm.origin, farm.origin_lo + local.astype(dt), heading.astype(dt),
         (heading if north else jnp.zeros_like(heading)).astype(dt), jnp.asarray(-90.0, dt)),
    )
