"""Lidar–rotor spectra under the Mann (1994) spectral tensor: the model of lidarjax's own
turbulence boxes (`lidarjax.turbulence`), as `lac_spectra` computes them for a `MannInflow`.

**Frames and signs.** The tensor lives in the box frame (``x`` downwind, ``y`` to the left
looking downwind, ``z`` up; `lidarjax.turbulence`); the rotor frame of `geometry` has ``x``
upstream and ``y`` to the left looking upstream, so a rotor-frame point ``(x, y, z)`` sits at
box ``(-x, -y, z)``. ``u`` is the downwind component (positive through the rotor), ``v`` the
box's lateral one, ``w`` up. A node's line-of-sight speed (positive away from the lidar) is
``n . V``; the lidar's estimate is ``-LOS / nx`` (`lidar_rews`), i.e.
``u + (ny / nx) v - (nz / nx) w`` with ``(nx, ny, nz)`` the beam's rotor-frame direction.

**Model.** Frozen turbulence advected at ``U`` along the rotor axis: a point at box ``x`` sees
``u~(x - U t)`` of the spatial field ``u~`` with tensor ``Phi``. ``R = sum_k rho_k u_k``; ``L
= sum_j w_j p_j . u(x_j, t - d_j)``, ``p_j = (1, ny_j / nx_j, -nz_j / nx_j)``, so node ``j``
leads the rotor by ``tau_j = x_j / U - d_j`` (as in the Kaimal model). At ``k1 = 2 pi f / U``
the one-sided spectra (``E[X conj(Y)]`` convention of `LacSpectra`) are

    ``S_XY(f) = (4 pi / U) int int a_X(k)^H Phi(k) a_Y(k) dk2 dk3``,
    ``a_R = e_1 sum_k rho_k exp(i (k2 y_k + k3 z_k))``,
    ``a_L = sum_j w_j p_j exp(-i 2 pi f tau_j) exp(i (k2 y_j + k3 z_j))`` (box ``y, z``),

so ``v`` and ``w`` enter ``S_LL`` (and ``S_RL``, through the ``u``-``w`` covariance of the
sheared tensor) correlated between nodes as the tensor says, unlike the Kaimal model.

**Quadrature.** Over ``(k2, k3)`` a tensor product of one rule per axis: by default
``k = s tan(theta)``, ``theta`` at `n_nodes` Gauss–Legendre nodes in ``(-pi/2, pi/2)``
(the whole real line, denser near 0), ``s = scale * sqrt(L^-2 + k1^2)`` (the tensor's width
at that frequency); or, with `box`, the
wavenumber lattice of a periodic box (``2 pi m / (n d)``, weights ``2 pi / (n d)``): exactly
the content of an FFT Mann box of that lateral and vertical size (`lidarjax.fft_mann_box`).
The amplitudes are sums of exponentials evaluated at the nodes, so the integrand is exact
there; what converges is the quadrature of it (see `MannInflow`).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..turbulence import mann_spectrum_level, mann_tensor_jax
from .inflow import _positive

__all__ = ["MannInflow"]


class MannInflow(eqx.Module):
    """Mann (1994) turbulence, frozen and advected at `mean_speed` along the rotor axis.

    **Arguments:**

    - `mean_speed`: ``U`` (m/s).
    - `alphaepsilon`: the spectral level ``alpha eps^(2/3)`` (m^(4/3)/s^2); or give
      `sigma_u` instead.
    - `length_scale`: Mann's ``L`` (m); 29.4 m is IEC 61400-1's ``0.7 Lambda_1``.
    - `gamma`: the shear anisotropy ``Gamma`` (dimensionless, >= 0; IEC 3.9; 0 is isotropic
      von Karman turbulence).
    - `sigma_u`: (keyword) the infinite-domain standard deviation of ``u`` (m/s) that sets
      `alphaepsilon` (`lidarjax.mann_spectrum_level`, on the host: not differentiable).
    - `n_nodes`: (keyword, static) quadrature nodes per axis of ``(k2, k3)`` (default 96).
    - `scale`: (keyword) the quadrature's width in units of the tensor's, ``s / sqrt(L^-2 +
      k1^2)`` (dimensionless, default 1): half the nodes of each axis lie within ``|k| < s``.
    - `box`, `box_spacing`: (keyword) ``(ny, nz)`` (static) and ``(dy, dz)`` (m): sum over
      the wavenumber lattice of a periodic box of that lateral and vertical size instead of
      integrating (the analytic model of a finite box; ``k1`` stays continuous).

    **Convergence** (`tests/control/test_mann.py`, isotropic closed forms): one-point spectra
    to 1e-5 relative already at 96 nodes; the cross terms of points ``d`` apart oscillate as
    ``exp(i k d)`` and converge slowly (algebraically) in `n_nodes`: for ``d`` up to 2 ``L``
    and ``f`` up to 0.1 Hz (``k1 L`` < 2) within 5e-3 at 256 nodes, about 1 % at 96. Refine
    `n_nodes` for wide rotors at high frequency, or use `box`.
    Every number (speed, level, scale, gamma, quadrature scale, box spacing) is dynamic and
    differentiable.
    """

    mean_speed: Float[Array, ""]
    alphaepsilon: Float[Array, ""]
    length_scale: Float[Array, ""]
    gamma: Float[Array, ""]
    scale: Float[Array, ""]
    box_spacing: Float[Array, " 2"] | None
    n_nodes: int = eqx.field(static=True)
    box: tuple[int, int] | None = eqx.field(static=True)

    def __init__(self, mean_speed: Float[ArrayLike, ""], alphaepsilon: Float[ArrayLike, ""] | None = None,
                 length_scale: Float[ArrayLike, ""] = 29.4, gamma: Float[ArrayLike, ""] = 3.9, *,
                 sigma_u: float | None = None, n_nodes: int = 96, scale: Float[ArrayLike, ""] = 1.0,
                 box: tuple[int, int] | None = None, box_spacing: Float[ArrayLike, " 2"] | None = None):
        if (alphaepsilon is None) == (sigma_u is None):
            raise ValueError("MannInflow: give exactly one of alphaepsilon (m^(4/3)/s^2) and sigma_u (m/s)")
        self.mean_speed = _positive("mean_speed", mean_speed, "MannInflow")
        self.length_scale = _positive("length_scale", length_scale, "MannInflow")
        self.gamma = _positive("gamma", gamma, "MannInflow", allow_zero=True)
        if sigma_u is not None:
            sigma_u = float(_positive("sigma_u", sigma_u, "MannInflow"))
            alphaepsilon = mann_spectrum_level(sigma_u, float(self.length_scale), float(self.gamma))
        self.alphaepsilon = _positive("alphaepsilon", alphaepsilon, "MannInflow")
        self.scale = _positive("scale", scale, "MannInflow")
        if not isinstance(n_nodes, int | np.integer) or n_nodes < 4:
            raise ValueError(f"MannInflow: n_nodes must be an integer >= 4, got {n_nodes!r}")
        self.n_nodes = int(n_nodes)
        if (box is None) != (box_spacing is None):
            raise ValueError("MannInflow: give box (ny, nz) and box_spacing (dy, dz) together")
        if box is not None:
            if len(box) != 2 or not all(isinstance(n, int | np.integer) and n >= 2 for n in box):
                raise ValueError(f"MannInflow: box must be (ny, nz), two integers >= 2, got {box!r}")
            box = (int(box[0]), int(box[1]))
            box_spacing = jnp.asarray(box_spacing, self.mean_speed.dtype)
            if box_spacing.shape != (2,):
                raise ValueError(f"MannInflow: box_spacing must be (dy, dz) metres, got shape "
                                 f"{box_spacing.shape}")
        self.box, self.box_spacing = box, box_spacing

    def quadrature(self, k1=0.0, dtype=None):
        """The ``(k2, k3)`` rule: ``((k2, w2), (k3, w3))``, nodes (rad/m, box frame) and
        weights (rad/m) per axis; the 2-D rule is their tensor product."""
        dtype = self.mean_speed.dtype if dtype is None else dtype
        if self.box is not None:
            return tuple(_lattice(n, d, dtype) for n, d in zip(self.box, self.box_spacing, strict=True))
        t, w = np.polynomial.legendre.leggauss(self.n_nodes)
        theta = jnp.asarray(t * np.pi / 2, dtype)
        s = (self.scale * jnp.sqrt(self.length_scale**-2 + jnp.asarray(k1) ** 2)).astype(dtype)
        rule = (s * jnp.tan(theta), s * jnp.asarray(w * np.pi / 2, dtype) / jnp.cos(theta) ** 2)
        return rule, rule

    def tensor(self, k: Float[ArrayLike, "... 3"]) -> Float[Array, "... 3 3"]:
        """``Phi_ij(k)`` ((m/s)^2 m^3) at box-frame wavenumbers `k` (rad/m): `lidarjax.mann_tensor`
        in JAX."""
        return mann_tensor_jax(k, self.alphaepsilon, self.length_scale, self.gamma)


def _lattice(n, d, dtype):
    d = jnp.asarray(d, dtype)
    k = 2 * np.pi * jnp.asarray(np.fft.fftfreq(n), dtype) / d
    return k, jnp.full((n,), 2 * np.pi / n, dtype) / d


def _amplitude_factors(yz, k2, k3):
    """``exp(i k2 y)`` ``(n, N2)`` and ``exp(i k3 z)`` ``(n, N3)`` at rotor-frame ``(y, z)``
    (box ``y = -y_rotor``)."""
    return jnp.exp(-1j * yz[:, :1] * k2[None]), jnp.exp(1j * yz[:, 1:] * k3[None])


@jax.jit
def _mann_spectra(samples, rotor, inflow: MannInflow, frequency):
    """`lac_spectra` under `MannInflow`: ``(S_RR, S_LL, S_RL)`` at `frequency` (Hz), see the
    module docs."""
    f = jnp.asarray(frequency)
    dtype = f.dtype
    nd = samples.directions.astype(dtype)
    proj = jnp.stack([jnp.ones_like(nd[:, 0]), nd[:, 1] / nd[:, 0], -nd[:, 2] / nd[:, 0]], 1)
    u = inflow.mean_speed.astype(dtype)
    lead = samples.points[:, 0].astype(dtype) / u - samples.delays.astype(dtype)
    ryz, lyz = rotor.points.astype(dtype), samples.points[:, 1:].astype(dtype)

    def one(fi):
        k1 = 2 * np.pi * fi / u
        (k2, w2), (k3, w3) = inflow.quadrature(k1, dtype)
        e2, e3 = _amplitude_factors(ryz, k2, k3)
        a_r = jnp.einsum("n,na,nb->ab", rotor.weights.astype(dtype), e2, e3)
        d2, d3 = _amplitude_factors(lyz, k2, k3)
        kk = jnp.stack(jnp.broadcast_arrays(k1, k2[:, None], k3[None, :]), -1)
        phi = inflow.tensor(kk) * (w2[:, None] * w3[None, :])[..., None, None]
        c = samples.weights.astype(dtype) * jnp.exp(-2j * np.pi * fi * lead)
        a_l = jnp.einsum("nc,na,nb->cab", c[:, None] * proj, d2, d3)  # (3, N2, N3)
        phi_l = jnp.einsum("abcd,dab->cab", phi, a_l)
        s_rr = jnp.sum(jnp.abs(a_r) ** 2 * phi[..., 0, 0])
        s_rl = jnp.sum(jnp.conj(a_r) * phi_l[0])
        s_ll = jnp.real(jnp.sum(jnp.conj(a_l) * phi_l))
        return jnp.stack([s_rr, s_ll]) * 4 * np.pi / u, s_rl * 4 * np.pi / u

    auto, s_rl = jax.lax.map(one, f)
    return auto[:, 0], auto[:, 1], s_rl
