"""Analytic flows (lidarjax's validation problems), usable wherever a `GridField` is.

Each scene is an `equinox.Module` with the field interface of `lidarjax.field.AbstractField`
(``sample``, ``sample_local``, ``origin``), so `lidarjax.simulate` takes it directly, and
`GridField.from_function(scene.sample, x, y, z)` grids it.

Conventions: CFD frame with ``+y`` north, ``+x`` east, ``+z`` up, metres and m/s. Inflow
directions are meteorological (where the wind comes from, degrees clockwise from ``+y``), so
direction 270 blows towards ``+x``. All parameters are dynamic and differentiable; the dtype
of the scene (and of `simulate`'s results) is that of its parameters (the default float
unless given as arrays of another float dtype).

NaN (inside a body, below the ground or the terrain) is inserted last over values computed
at safe stand-in points, so gradients stay finite for losses that mask the NaN out.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._precision import HIGHEST, default_float, is_concrete, split
from .._util import compiled
from ..angles import heading
from ..field import AbstractField

__all__ = ["Uniform", "PowerLaw", "Linear", "Hemisphere", "Hill",
           "uniform", "power_law", "linear", "hemisphere", "hill"]


def _f(value, dtype):
    return jnp.asarray(value, dtype=dtype)


def _dtype(dtype):
    return jnp.dtype(dtype) if dtype is not None else default_float()


def _host_scale(length, factor) -> float | None:
    """``factor * min(length)`` as a host float (``None`` when traced)."""
    if not is_concrete(length):
        return None
    return float(factor * np.min(np.asarray(length, np.float64)))


class Uniform(AbstractField):
    """A uniform wind: `speed` (m/s) from meteorological `direction` (degrees), vertical `w`."""

    origin: Float[Array, 3]
    origin_lo: Float[Array, 3]
    speed: Float[Array, ""]
    direction: Float[Array, ""]
    w: Float[Array, ""]

    @compiled
    def sample_local(self, points):
        v = self.speed * heading(self.direction, self.dtype) + jnp.stack(
            [0.0, 0.0, 1.0]
        ).astype(self.dtype) * self.w
        return jnp.broadcast_to(v, jnp.shape(points)[:-1] + (3,)) + 0.0 * points


def uniform(speed: float = 10.0, direction: float = 270.0, w: float = 0.0, *, dtype=None) -> Uniform:
    """A uniform wind of horizontal `speed` (m/s) from `direction` (degrees), vertical `w` (m/s)."""
    dt = _dtype(dtype)
    o, lo = split([0.0, 0.0, 0.0], dt)
    return Uniform(o, lo, _f(speed, dt), _f(direction, dt), _f(w, dt))


class PowerLaw(AbstractField):
    """Sheared (and optionally veering) wind over flat ground at ``z = z_ground``.

    Horizontal speed ``speed_ref * (h / z_ref)**alpha`` at height ``h = z - z_ground``;
    direction ``direction + veer * (h - z_ref)`` (veer in degrees per metre, positive
    clockwise with height as in the northern-hemisphere Ekman spiral). NaN below ground.
    """

    origin: Float[Array, 3]
    origin_lo: Float[Array, 3]
    speed_ref: Float[Array, ""]
    z_ref: Float[Array, ""]
    alpha: Float[Array, ""]
    direction: Float[Array, ""]
    veer: Float[Array, ""]

    @compiled
    def sample_local(self, points):
        h = points[..., 2]
        above = h > 0
        hs = jnp.where(above, h, self.z_ref)
        speed = self.speed_ref * (hs / self.z_ref) ** self.alpha
        d = jnp.deg2rad(self.direction + self.veer * (hs - self.z_ref))
        v = jnp.stack([-speed * jnp.sin(d), -speed * jnp.cos(d), jnp.zeros_like(speed)], -1)
        at_ground = (h == 0)[..., None]
        v = jnp.where(at_ground, 0.0, v)
        return jnp.where((h >= 0)[..., None], v, jnp.nan)


def power_law(
    speed_ref: float = 10.0,
    z_ref: float = 100.0,
    alpha: float = 0.14,
    direction: float = 270.0,
    veer: float = 0.0,
    z_ground: float = 0.0,
    *,
    dtype=None,
) -> PowerLaw:
    """Power-law shear: `speed_ref` m/s at `z_ref` m above `z_ground` (m), exponent `alpha`,
    meteorological `direction` (degrees) at `z_ref`, `veer` degrees per metre."""
    dt = _dtype(dtype)
    o, lo = split([0.0, 0.0, z_ground], dt)
    return PowerLaw(o, lo, *(_f(a, dt) for a in (speed_ref, z_ref, alpha, direction, veer)))


class Linear(AbstractField):
    """A flow with a constant velocity gradient: ``V(p) = velocity + gradient @ (p - point)``.

    ``gradient[i, j] = dV_i / dx_j`` in 1/s. Trilinear interpolation reproduces it exactly.
    """

    origin: Float[Array, 3]
    origin_lo: Float[Array, 3]
    velocity: Float[Array, 3]
    gradient: Float[Array, "3 3"]

    @compiled
    def sample_local(self, points):
        return self.velocity + jnp.einsum("ij,...j->...i", self.gradient, points,
                                           precision=HIGHEST)


def linear(
    velocity: Float[ArrayLike, 3],
    gradient: Float[ArrayLike, "3 3"],
    point: Float[ArrayLike, 3] = (0.0, 0.0, 0.0),
    *,
    dtype=None,
) -> Linear:
    """Constant-gradient flow: `velocity` (m/s) at `point` (CFD metres), `gradient` (1/s)
    with ``gradient[i, j] = dV_i/dx_j``."""
    dt = _dtype(dtype)
    o, lo = split(point, dt)
    return Linear(o, lo, _f(velocity, dt), _f(gradient, dt))


class Hemisphere(AbstractField):
    """Potential flow over a hemisphere of `radius` (m) on flat ground: a platform stand-in.

    The exact potential of a uniform stream past a sphere centred on the ground plane,
    ``phi = U (e . r) (1 + R^3 / (2 |r|^3))``, whose mirror symmetry makes ``w = 0`` on the
    ground. Speed-up at the top is 1.5. NaN inside the body (``|r| < R``) and below ground.
    """

    origin: Float[Array, 3]
    origin_lo: Float[Array, 3]
    radius: Float[Array, ""]
    speed: Float[Array, ""]
    direction: Float[Array, ""]

    @property
    def resolution(self) -> float | None:
        """Half the radius: the potential-flow perturbation ``(R/r)^3`` varies on the scale of
        the distance to the centre, at least ``R`` outside the body."""
        return _host_scale(self.radius, 0.5)

    @compiled
    def sample_local(self, points):
        e = heading(self.direction, self.dtype)
        r2 = jnp.sum(points * points, axis=-1)
        inside = (r2 < self.radius**2) | (points[..., 2] < 0)
        r2s = jnp.where(inside, self.radius**2, r2)
        ratio3 = self.radius**3 / (r2s * jnp.sqrt(r2s))
        edotr = jnp.sum(points * e, axis=-1)
        v = self.speed * (
            e * (1.0 + 0.5 * ratio3)[..., None]
            - (1.5 * ratio3 * edotr / r2s)[..., None] * points
        )
        return jnp.where(inside[..., None], jnp.nan, v)


def hemisphere(
    radius: float = 20.0,
    speed: float = 10.0,
    direction: float = 270.0,
    centre: Float[ArrayLike, 3] = (0.0, 0.0, 0.0),
    *,
    dtype=None,
) -> Hemisphere:
    """Hemisphere of `radius` m centred at `centre` (CFD m, on the ground), free stream
    `speed` m/s from meteorological `direction` degrees."""
    dt = _dtype(dtype)
    o, lo = split(centre, dt)
    return Hemisphere(o, lo, _f(radius, dt), _f(speed, dt), _f(direction, dt))


class Hill(AbstractField):
    """Linearised potential flow over a 2-D ridge of Witch-of-Agnesi profile.

    Terrain ``zs(n) = H / (1 + (n/L)^2)`` with ``n`` the horizontal distance across the ridge
    (along its normal ``(sin a, cos a)``, ``a = ridge_normal`` degrees clockwise from north)
    and ``L`` the half-width at half height. The cross-ridge component ``U_n`` of the free
    stream sees the perturbation of linear theory, with ``zeta = n + i z``:

    ``u_n' - i w' = U_n * H * L / (L - i zeta)^2``,

    i.e. ``u_n'(n, 0) = U_n H L (L^2 - n^2) / (L^2 + n^2)^2`` (fractional speed-up ``H/L`` at
    the crest) and ``w'(n, 0) = U_n dzs/dn`` (flow along the surface). The along-ridge
    component is unchanged. NaN below the terrain (a point on it to within 8 units of
    rounding counts as on it). Valid for gentle slopes (``H/L < ~0.3``).
    """

    origin: Float[Array, 3]
    origin_lo: Float[Array, 3]
    height: Float[Array, ""]
    half_width: Float[Array, ""]
    speed: Float[Array, ""]
    direction: Float[Array, ""]
    ridge_normal: Float[Array, ""]

    @property
    def resolution(self) -> float | None:
        """Half the half-width ``L``: the perturbation ``1 / (L + z - i n)^2`` has a spectrum
        across the ridge falling as ``exp(-k (L + z))``, below 1e-3 of its peak beyond
        ``k = 6.9 / L``, the Nyquist wavenumber of a spacing ``0.45 L``."""
        return _host_scale(self.half_width, 0.5)

    @compiled
    def sample_local(self, points):
        a = jnp.deg2rad(self.ridge_normal)
        nvec = jnp.stack([jnp.sin(a), jnp.cos(a), jnp.zeros_like(a)])
        e = heading(self.direction, self.dtype)
        free = self.speed * e
        un = jnp.dot(free, nvec, precision=HIGHEST)
        n = jnp.sum(points * nvec, axis=-1)
        big_h, big_l = self.height, self.half_width
        ground = big_h / (1.0 + (n / big_l) ** 2)
        # a point on the terrain to rounding (computed by another program: a few ulps
        # either way) is on it, not below
        slack = 8 * jnp.finfo(ground.dtype).eps * jnp.abs(ground)
        above = points[..., 2] >= ground - slack
        z = jnp.where(above, points[..., 2], ground)  # finite below the terrain (masked)
        # 1/A^2 with A = L - i zeta = (L + z) - i n:  1/A^2 = conj(A)^2 / |A|^4
        a_re, a_im = big_l + z, -n
        den = (a_re**2 + a_im**2) ** 2
        inv_re = (a_re**2 - a_im**2) / den
        inv_im = -2.0 * a_re * a_im / den
        scale = un * big_h * big_l
        du = scale * inv_re
        dw = -scale * inv_im
        v = free + du[..., None] * nvec + dw[..., None] * jnp.array([0.0, 0.0, 1.0], self.dtype)
        return jnp.where(above[..., None], v, jnp.nan)


def hill(
    height: float = 50.0,
    half_width: float = 250.0,
    speed: float = 10.0,
    direction: float = 270.0,
    ridge_normal: float = 90.0,
    crest: Float[ArrayLike, 3] = (0.0, 0.0, 0.0),
    *,
    dtype=None,
) -> Hill:
    """A 2-D ridge of `height` m and `half_width` m (half-width at half height) whose crest
    line passes through `crest` (CFD m, ground datum ``z = crest[2]``), with normal direction
    `ridge_normal` degrees clockwise from north; free stream `speed` m/s from `direction`."""
    dt = _dtype(dtype)
    o, lo = split(crest, dt)
    return Hill(o, lo, *(_f(a, dt) for a in (height, half_width, speed, direction, ridge_normal)))
