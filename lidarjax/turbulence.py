"""Turbulence boxes: the `TurbulenceBox` container, the Mann (1994) spectral tensor and the
generators of Mann boxes (lidarjax's own exact-spectrum FFT synthesis, and hipersim's).

**The box frame.** A `TurbulenceBox` holds velocity fluctuations on a regular grid:

- ``x`` along the mean wind (downwind), ``z`` up, ``y = z x x`` lateral, to the *left* when
  looking downwind (right-handed; Mann 1994, hipersim, TurbSim and HAWC2 all use these
  directions for ``u, v, w``);
- node ``(i, j, k)`` sits at ``(i dx, (j - (ny - 1)/2) dy, k dz)``: laterally centred,
  vertically from the box's bottom row;
- ``velocity[i, j, k] = (u', v', w')`` in m/s along those axes.

The box is a *spatial* field (a snapshot of the fluctuations), periodic along ``x`` with period
``Lx = nx dx``: that is how FFT generators (Mann, TurbSim) make it. Laterally and vertically it
is periodic (period ``ny dy``, ``nz dz``) when the generator made it so (`periodic`), else it
covers the nodes only and points outside give NaN (never a clamped value). The scene that
advects a box with the wind is `lidarjax.scenes.FrozenTurbulence`; the box readers and writers
(HAWC2, TurbSim) are in `lidarjax.io`.

**The spectral tensor** is Mann's uniform-shear model (`mann_tensor`): the von Karman energy
spectrum ``E(k) = alpha eps^(2/3) L^(5/3) (kL)^4 / (1 + (kL)^2)^(17/6)`` (isotropic for
``gamma = 0``), sheared by the eddy lifetime ``beta = gamma (kL)^(-2/3) /
sqrt(2F1(1/3, 17/6; 4/3; -(kL)^-2))``. Units: wavenumbers in rad/m, ``alphaepsilon`` in
``m^(4/3) s^-2``, variances in ``m^2/s^2``.

**Generators.**

- `fft_mann_box` (numpy and scipy only) draws the box's discrete spectrum exactly, with Mann's
  (1998, equation 16) closed-form square root ``C(k)`` of the tensor (``C C^H = Phi(k)``): each
  Fourier coefficient is ``C(k) n(k) sqrt(dk1 dk2 dk3)`` with complex Gaussian noise ``n``,
  the velocity is the real part of the inverse FFT, so its covariance is exactly
  `box_variance`, ``sum_k Phi(k) dk`` over the box's wavenumbers. The ``k = 0`` mode is zero
  (zero-mean box). One periodic box (no lateral/vertical doubling). Cost: one complex FFT per
  component, ``O(N log N)``: a 512 x 32 x 32 box takes about 0.3 s on one core.
  `synthesize_box` wraps its array as a `TurbulenceBox`. This is the library's one such
  generator: the demo, the command line and the spectral model of `lidarjax.spectral` use it.
- `mann_box` generates boxes with hipersim (the optional extra ``turbulence``), the reference
  implementation, which applies Mann's low-wavenumber cell averaging.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float
from scipy import special

from ._precision import default_float, is_concrete
from ._util import import_optional

__all__ = [
    "TurbulenceBox",
    "mann_box",
    "fft_mann_box",
    "synthesize_box",
    "mann_spectrum_level",
    "mann_tensor",
    "mann_eddy_lifetime",
    "eddy_lifetime_jax",
    "mann_tensor_jax",
    "box_wavenumbers",
    "box_variance",
]


class TurbulenceBox(eqx.Module):
    """Velocity fluctuations on a regular grid in the box frame (see the module docs).

    **Arguments:**

    - `velocity`: ``(nx, ny, nz, 3)`` fluctuations ``(u', v', w')`` in m/s along the box axes
      (``x`` downwind, ``y`` to the left looking downwind, ``z`` up). Its floating dtype is the
      box's working dtype.
    - `spacing`: ``(dx, dy, dz)`` node spacing in metres, positive.
    - `periodic`: whether the box is periodic laterally and vertically ``(y, z)`` (static).
      Along ``x`` it is always periodic. Default ``(False, False)``: outside the nodes gives
      NaN. FFT boxes generated without doubling (hipersim's ``double_xyz=(False, False,
      False)``) are periodic in all three directions.

    Raises `ValueError` for a wrong shape, non-finite values or spacings, or fewer than 2 nodes
    along ``x`` (4 recommended) and 2 along a non-periodic axis.
    """

    velocity: Float[Array, "nx ny nz 3"]
    spacing: Float[Array, 3]
    periodic: tuple[bool, bool] = eqx.field(static=True)

    def __init__(self, velocity, spacing, *, periodic=(False, False)):
        velocity = jnp.asarray(velocity)
        if not jnp.issubdtype(velocity.dtype, jnp.floating):
            velocity = velocity.astype(default_float())
        if velocity.ndim != 4 or velocity.shape[-1] != 3:
            raise ValueError(
                f"TurbulenceBox: velocity must have shape (nx, ny, nz, 3) with (u', v', w') "
                f"last, got {velocity.shape}."
            )
        if isinstance(periodic, bool):
            periodic = (periodic, periodic)
        periodic = tuple(bool(p) for p in periodic)
        if len(periodic) != 2:
            raise ValueError(f"TurbulenceBox: periodic is (y, z), got {periodic!r}.")
        nx, ny, nz = velocity.shape[:3]
        if nx < 2:
            raise ValueError(f"TurbulenceBox: need at least 2 nodes along x, got {nx}.")
        for n, name, per in ((ny, "y", periodic[0]), (nz, "z", periodic[1])):
            if n < (1 if per else 2):
                raise ValueError(
                    f"TurbulenceBox: need at least 2 nodes along non-periodic {name}, got {n}."
                )
        if is_concrete(velocity) and not bool(_all_finite(velocity)):
            raise ValueError("TurbulenceBox: velocity contains NaN or inf.")
        if is_concrete(spacing):
            s = np.asarray(spacing, dtype=np.float64)
            if s.shape != (3,) or not np.all(np.isfinite(s)) or np.any(s <= 0):
                raise ValueError(
                    f"TurbulenceBox: spacing must be (dx, dy, dz), finite and positive metres; "
                    f"got {spacing!r}."
                )
        self.velocity = velocity
        self.spacing = jnp.asarray(spacing, dtype=velocity.dtype)
        self.periodic = periodic

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(nx, ny, nz)``."""
        return tuple(self.velocity.shape[:3])

    @property
    def dtype(self):
        return self.velocity.dtype

    @property
    def length(self) -> Float[Array, ""]:
        """Period along ``x``, ``nx dx`` (m)."""
        return self.shape[0] * self.spacing[0]

    def coordinates(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Node coordinates ``(x, y, z)`` in the box frame (m, float64 numpy)."""
        s = np.asarray(self.spacing, dtype=np.float64)
        nx, ny, nz = self.shape
        return (np.arange(nx) * s[0], (np.arange(ny) - (ny - 1) / 2) * s[1], np.arange(nz) * s[2])

    def astype(self, dtype) -> TurbulenceBox:
        """The same box in another floating dtype."""
        return TurbulenceBox(self.velocity.astype(dtype), self.spacing.astype(dtype),
                             periodic=self.periodic)

    def scaled(self, factor) -> TurbulenceBox:
        """The box with every fluctuation multiplied by `factor` (e.g. to set a TI)."""
        return eqx.tree_at(lambda b: b.velocity, self, self.velocity * factor)

    def sample_box(
        self, xi: Float[Array, ...], eta: Float[Array, ...], zeta: Float[Array, ...]
    ) -> Float[Array, "... 3"]:
        """Trilinear fluctuations ``(u', v', w')`` (m/s, box axes) at box coordinates (m).

        Periodic along ``x`` (and along ``y``/``z`` where `periodic`); NaN outside a
        non-periodic axis' nodes, inserted last over a safe stand-in (finite gradients)."""
        return self._trilinear(xi, eta, zeta, lambda v: v, vector=True)

    def los_box(
        self, xi: Float[Array, ...], eta: Float[Array, ...], zeta: Float[Array, ...],
        direction: Float[Array, "... 3"],
    ) -> Float[Array, ...]:
        """``sample_box(xi, eta, zeta) . direction`` (m/s) for `direction` in box axes, with
        the projection done at the cell's corners: one number flows through the lerps, so the
        compiler keeps the eight gathers in one loop (projecting the interpolated vector reads
        it per component, and the gathers are repeated for each). NaN as in `sample_box`."""
        d = jnp.asarray(direction).astype(self.dtype)
        dx, dy, dz = d[..., 0], d[..., 1], d[..., 2]
        return self._trilinear(xi, eta, zeta,
                               lambda v: v[..., 0] * dx + v[..., 1] * dy + v[..., 2] * dz, vector=False)

    def _trilinear(self, xi, eta, zeta, value, *, vector: bool):
        """Trilinear interpolation of ``value(row)`` over the cell's eight ``(u, v, w)`` rows
        (``(..., 3)`` from `value` when `vector`, else a number), NaN outside."""
        dtype = self.dtype
        nx, ny, nz = self.shape
        s = self.spacing
        ix0, ix1, fx, okx = box_axis(xi.astype(dtype) / s[0], nx, True)
        iy0, iy1, fy, oky = box_axis(eta.astype(dtype) / s[1] + (ny - 1) / 2, ny, self.periodic[0])
        iz0, iz1, fz, okz = box_axis(zeta.astype(dtype) / s[2], nz, self.periodic[1])
        flat = self.velocity.reshape(-1, 3)

        def corner(i, j, k):
            # indices are reduced into the box by `box_axis`: no bounds handling in the gather
            return value(flat.at[(i * ny + j) * nz + k].get(mode="promise_in_bounds"))

        ok = okx & oky & okz
        if vector:
            fx, fy, fz, ok = fx[..., None], fy[..., None], fz[..., None], ok[..., None]
        c00 = corner(ix0, iy0, iz0) * (1 - fz) + corner(ix0, iy0, iz1) * fz
        c01 = corner(ix0, iy1, iz0) * (1 - fz) + corner(ix0, iy1, iz1) * fz
        c10 = corner(ix1, iy0, iz0) * (1 - fz) + corner(ix1, iy0, iz1) * fz
        c11 = corner(ix1, iy1, iz0) * (1 - fz) + corner(ix1, iy1, iz1) * fz
        c0 = c00 * (1 - fy) + c01 * fy
        c1 = c10 * (1 - fy) + c11 * fy
        return jnp.where(ok, c0 * (1 - fx) + c1 * fx, jnp.nan)


def box_axis(s, n: int, periodic: bool):
    """Lower and upper node indices, fraction and in-domain mask of fractional index `s`."""
    s = jnp.asarray(s)
    if periodic:
        fl = jnp.floor(s)
        frac = s - fl
        i0 = jnp.mod(fl.astype(jnp.int32), n)
        i1 = jnp.where(i0 + 1 == n, 0, i0 + 1)
        return i0, i1, frac, jnp.isfinite(s)
    ok = (s >= 0) & (s <= n - 1)
    safe = jnp.where(ok, s, 0)
    i0 = jnp.clip(jnp.floor(safe), 0, n - 2).astype(jnp.int32)
    frac = safe - i0.astype(safe.dtype)
    return i0, i0 + 1, frac, ok




@jax.jit
def _all_finite(values):
    """Whether every value is finite: one compiled program per box shape (two eagerly)."""
    return jnp.all(jnp.isfinite(values))


def mann_spectrum_level(sigma_u: float, length_scale: float, gamma: float = 3.9) -> float:
    """``alpha eps^(2/3)`` (m^(4/3)/s^2) giving an infinite-domain ``sigma_u`` (m/s) for Mann's
    model with `length_scale` L (m) and `gamma`, by the isotropic relation
    ``sigma_iso^2 = 0.6883 alpha eps^(2/3) L^(2/3)`` scaled by the shear's ``sigma_u^2 /
    sigma_iso^2`` (about 1.9 at gamma 3.9, computed here by quadrature). Use it to set a target
    turbulence level; a finite box holds less variance (its largest scales are missing)."""
    return float(sigma_u**2 / _u_variance_per_level(float(length_scale), float(gamma)))


@functools.lru_cache(maxsize=64)
def _u_variance_per_level(length_scale: float, gamma: float) -> float:
    """The infinite-domain ``sigma_u^2`` (m^2/s^2) per unit ``alpha eps^(2/3)`` of Mann's model
    (`mann_spectrum_level`); 1.6 million tensor evaluations (2.5 s) for a shear, so remembered
    per ``(L, gamma)``."""
    k = np.logspace(-4, 3, 4000) / length_scale
    e = length_scale ** (5 / 3) * (k * length_scale) ** 4 / (1 + (k * length_scale) ** 2) ** (17 / 6)
    iso = np.trapezoid(e, k) * 2 / 3  # sigma^2 per component per unit alpha eps^(2/3)
    if gamma <= 0:
        return float(iso)
    # sheared u variance by Monte-Carlo-free quadrature of Phi_11 on a spherical grid
    kk = np.logspace(-3, 2.5, 220) / length_scale
    th = np.linspace(0, np.pi, 61)
    ph = np.linspace(0, 2 * np.pi, 121, endpoint=False)
    K, T, P = np.meshgrid(kk, th, ph, indexing="ij")
    k1, k2, k3 = K * np.sin(T) * np.cos(P), K * np.sin(T) * np.sin(P), K * np.cos(T)
    c = _amplitude(k1, k2, k3, 1.0, length_scale, gamma)
    phi11 = np.sum(np.abs(c[..., 0, :]) ** 2, axis=-1)
    integrand = phi11 * K**2 * np.sin(T)
    return float(np.trapezoid(np.trapezoid(np.sum(integrand, axis=2) * (2 * np.pi / ph.size), th,
                                           axis=1), kk))


def _amplitude(k1, k2, k3, ae, L, gamma):
    """Mann's amplitude matrix ``C(k)`` ``(..., 3, 3)`` with ``C C^H = Phi``."""
    k1, k2, k3 = np.broadcast_arrays(np.asarray(k1, float), np.asarray(k2, float),
                                     np.asarray(k3, float))
    ksq = k1**2 + k2**2 + k3**2
    k = np.sqrt(ksq)
    kl = np.where(k > 0, k * L, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        if gamma > 0:
            beta = gamma * kl ** (-2 / 3) / np.sqrt(special.hyp2f1(1 / 3, 17 / 6, 4 / 3, -kl ** -2))
        else:
            beta = np.zeros_like(kl)
        k30 = k3 + beta * k1
        k0sq = k1**2 + k2**2 + k30**2
        k0 = np.sqrt(k0sq)
        k0l = k0 * L
        e = ae * L ** (5 / 3) * k0l**4 / (1 + k0l**2) ** (17 / 6)
        amp = np.sqrt(e / (4 * np.pi * k0sq**2))
        amp = np.where(k0sq > 0, amp, 0.0)
        kh2 = k1**2 + k2**2
        safe_kh2 = np.where(kh2 > 0, kh2, 1.0)
        c1 = beta * k1**2 * (k0sq - 2 * k30**2 + beta * k1 * k30) / (np.where(ksq > 0, ksq, 1) * safe_kh2)
        c2 = (k2 * k0sq / safe_kh2**1.5
              * np.arctan2(beta * k1 * np.sqrt(safe_kh2), k0sq - k30 * k1 * beta))
        c1 = np.where(kh2 > 0, c1, 0.0)
        c2 = np.where(kh2 > 0, c2, 0.0)
        safe_k1 = np.where(k1 != 0, k1, 1.0)
        # k1 -> 0: (k2 / k1) C2 -> beta k2^2 / (k1^2 + k2^2) = beta, so zeta1 -> -beta
        zeta1 = np.where(k1 != 0, c1 - k2 / safe_k1 * c2, np.where(kh2 > 0, -beta, 0.0))
        zeta2 = np.where(k1 != 0, k2 / safe_k1 * c1 + c2, 0.0)
        ratio = np.where(ksq > 0, k0sq / np.where(ksq > 0, ksq, 1), 1.0)
    z = np.zeros_like(k1)
    iso = np.stack([np.stack([z, k30, -k2], -1), np.stack([-k30, z, k1], -1),
                    np.stack([k2, -k1, z], -1)], -2) * amp[..., None, None]
    o = np.ones_like(k1)
    shear = np.stack([np.stack([o, z, zeta1], -1), np.stack([z, o, zeta2], -1),
                      np.stack([z, z, ratio], -1)], -2)
    return shear @ iso


def fft_mann_box(
    shape: tuple[int, int, int],
    spacing: tuple[float, float, float],
    *,
    length_scale: float = 30.0,
    gamma: float = 3.9,
    alphaepsilon: float = 1.0,
    sigma_u: float | None = None,
    seed: int = 0,
    dtype=np.float64,
) -> np.ndarray:
    """A periodic Mann turbulence box ``(nx, ny, nz, 3)`` of fluctuations ``(u', v', w')``
    (m/s, box frame: ``x`` downwind, ``y`` left, ``z`` up) on nodes ``spacing`` (m) apart.

    **Arguments:** `shape` ``(nx, ny, nz)``; `spacing` ``(dx, dy, dz)`` m; `length_scale`
    ``L`` m and `gamma` (Mann's anisotropy; 0 gives isotropic von Karman turbulence);
    `alphaepsilon` the spectral level (m^(4/3)/s^2), or `sigma_u` (m/s) to rescale the drawn
    box so that its own ``u'`` standard deviation is exactly that; `seed` for numpy's
    generator.

    Wrap it as a field with ``lidarjax.TurbulenceBox(box, spacing, periodic=(True,
    True))`` and `lidarjax.scenes.FrozenTurbulence`.
    """
    nx, ny, nz = (int(n) for n in shape)
    if min(nx, ny, nz) < 2:
        raise ValueError(f"fft_mann_box: shape must have at least 2 nodes per axis, got {shape}.")
    d = np.asarray(spacing, float)
    if d.shape != (3,) or not np.all(d > 0):
        raise ValueError(f"fft_mann_box: spacing must be 3 positive metres, got {spacing}.")
    if not (length_scale > 0 and gamma >= 0 and alphaepsilon > 0):
        raise ValueError("fft_mann_box: need length_scale > 0, gamma >= 0 and alphaepsilon > 0.")
    k1 = 2 * np.pi * np.fft.fftfreq(nx, d[0])
    k2 = 2 * np.pi * np.fft.fftfreq(ny, d[1])
    k3 = 2 * np.pi * np.fft.fftfreq(nz, d[2])
    dk = (2 * np.pi) ** 3 / (nx * ny * nz * d.prod())
    rng = np.random.default_rng(seed)
    out = np.empty((nx, ny, nz, 3), dtype)
    # slab by slab along x keeps memory at a few box-sized arrays
    coef = np.empty((nx, ny, nz, 3), np.complex128)
    for i in range(nx):
        c = _amplitude(k1[i], k2[:, None], k3[None, :], alphaepsilon, length_scale, gamma)
        noise = rng.standard_normal((ny, nz, 3)) + 1j * rng.standard_normal((ny, nz, 3))
        coef[i] = np.einsum("yzij,yzj->yzi", c, noise) * np.sqrt(dk)
    coef[0, 0, 0] = 0.0
    for comp in range(3):
        out[..., comp] = np.real(np.fft.ifftn(coef[..., comp])) * (nx * ny * nz)
    if sigma_u is not None:
        out *= float(sigma_u) / np.std(out[..., 0])
    return out




def mann_eddy_lifetime(kl):
    """Mann's non-dimensional eddy lifetime ``beta / Gamma = (kL)^(-2/3) /
    sqrt(2F1(1/3, 17/6; 4/3; -(kL)^-2))`` (exact hypergeometric function)."""
    kl = np.asarray(kl, dtype=np.float64)
    safe = np.where(kl > 0, kl, 1.0)
    out = safe ** (-2.0 / 3.0) / np.sqrt(special.hyp2f1(1.0 / 3.0, 17.0 / 6.0, 4.0 / 3.0, -(safe**-2.0)))
    return np.where(kl > 0, out, np.inf)


def _hyp2f1_series(a, b, c, x, n_terms=64):
    """``2F1(a, b; c; x)`` by its first `n_terms` Taylor terms (Horner; for ``0 <= x <= 1/2``
    the truncation error is below ``2^-n_terms`` times a slowly growing factor)."""
    ratio = [(a + i) * (b + i) / ((c + i) * (i + 1)) for i in range(n_terms - 1)]
    coef = np.cumprod(np.concatenate([[1.0], ratio]))
    return jnp.polyval(jnp.asarray(coef[::-1], x.dtype), x)


def eddy_lifetime_jax(kl):
    """`mann_eddy_lifetime` in JAX (differentiable, jit-compatible; ``kl > 0``), agreeing with
    scipy's to 1e-14 relative. With ``x = kL``, ``F = 2F1(1/3, 17/6; 4/3; -x^-2)`` is summed as
    a Taylor series whose argument is at most 1/2 (JAX's own ``hyp2f1`` is slow, and wrong
    for arguments below -1): for ``x >= 1`` by Pfaff's transformation, ``F = (1 + x^-2)^(-1/3)
    2F1(1/3, -3/2; 4/3; 1 / (1 + x^2))``; for ``x < 1`` by the ``1/z`` transformation (its
    first term's series is exactly 1) followed by Pfaff's, ``F = C1 x^(2/3) + C2 x^(17/3)
    (1 + x^2)^(-5/2) 2F1(5/2, 2/3; 7/2; x^2 / (1 + x^2))``, ``C1 = G(4/3) G(5/2) / G(17/6)``,
    ``C2 = G(4/3) G(-5/2) / (G(1/3) G(-3/2))``."""
    x = jnp.asarray(kl)
    big = x >= 1
    xb = jnp.where(big, x, 1.0)
    xs = jnp.where(big, 0.5, x)
    f_big = (1 + xb**-2.0) ** (-1.0 / 3.0) * _hyp2f1_series(1 / 3, -1.5, 4 / 3, 1 / (1 + xb**2))
    g = special.gamma
    c1 = g(4 / 3) * g(2.5) / g(17 / 6)
    c2 = g(4 / 3) * g(-2.5) / (g(1 / 3) * g(-1.5))
    x2 = xs**2
    f_small = c1 * xs ** (2.0 / 3.0) + c2 * xs ** (17.0 / 3.0) * (1 + x2) ** -2.5 * _hyp2f1_series(
        2.5, 2 / 3, 3.5, x2 / (1 + x2))
    return x ** (-2.0 / 3.0) / jnp.sqrt(jnp.where(big, f_big, f_small))


def mann_tensor(k, alphaepsilon, length_scale, gamma):
    """The Mann (1994) spectral velocity tensor ``Phi_ij(k)`` in ``(m/s)^2 m^3`` (variance per
    unit volume of wavenumber space, so ``sum_k Phi dk`` is a covariance in m^2/s^2) at
    wavenumbers `k` ``(..., 3)`` in rad/m (box frame: ``x`` downwind, ``y`` to the left,
    ``z`` up), for ``alphaepsilon`` = ``alpha eps^(2/3)`` (m^(4/3)/s^2), length scale ``L`` (m)
    and anisotropy ``Gamma``. Returns ``(..., 3, 3)``; zero at ``k = 0``.

    Sheared von Karman tensor (Mann 1994, J. Fluid Mech. 273, eqs. 12-16): the isotropic
    spectrum ``E(k) = alphaepsilon L^(5/3) (kL)^4 / (1 + (kL)^2)^(17/6)`` at the undistorted
    wavevector ``k0 = (k1, k2, k3 + beta k1)``, ``beta = Gamma * mann_eddy_lifetime(kL)``. The
    ``arctan`` of the distortion uses the two-argument form (as hipersim does); on ``k1 = 0``
    the limit ``zeta1 = -beta``, ``zeta2 = 0`` is taken. With ``Gamma = 0`` it is the isotropic
    von Karman tensor ``E(k) / (4 pi k^4) (k^2 delta_ij - k_i k_j)``. Host numpy, float64;
    `mann_tensor_jax` is the same formulas in JAX.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        return _mann_tensor(np.asarray(k, dtype=np.float64), float(alphaepsilon), float(length_scale),
                            float(gamma), np, mann_eddy_lifetime)


def mann_tensor_jax(k, alphaepsilon, length_scale, gamma):
    """`mann_tensor` in JAX: the same formulas, jit-compatible and differentiable in `k` and
    the three parameters (`eddy_lifetime_jax`); results in `k`'s dtype. Zero at ``k = 0``
    (finite gradients need ``k1 != 0`` and ``(k1, k2) != 0``)."""
    k = jnp.asarray(k)
    return _mann_tensor(k, jnp.asarray(alphaepsilon, k.dtype), jnp.asarray(length_scale, k.dtype),
                        jnp.asarray(gamma, k.dtype), jnp, eddy_lifetime_jax)


def _mann_tensor(k, alphaepsilon, L, gamma, xp, lifetime):
    """The tensor's formulas on array module `xp` (numpy or jax.numpy) with its eddy lifetime."""
    k1, k2, k3 = k[..., 0], k[..., 1], k[..., 2]
    ksq = k1 * k1 + k2 * k2 + k3 * k3
    zero = ksq == 0
    ksq_s = xp.where(zero, 1.0, ksq)
    kmag = xp.sqrt(ksq_s)
    beta = gamma * lifetime(kmag * L)
    k30 = k3 + beta * k1
    k0sq = k1 * k1 + k2 * k2 + k30 * k30
    kl0 = xp.sqrt(k0sq) * L
    e0 = alphaepsilon * L ** (5.0 / 3.0) * kl0**4 / (1.0 + kl0**2) ** (17.0 / 6.0)
    khsq = k1 * k1 + k2 * k2
    on_axis = khsq == 0  # k1 = k2 = 0: no distortion term survives
    khsq_s = xp.where(on_axis, 1.0, khsq)
    kh_s = xp.sqrt(khsq_s)
    c1 = beta * k1 * k1 * (k0sq - 2 * k30 * k30 + beta * k1 * k30) / (ksq_s * khsq_s)
    ang = xp.arctan2(beta * k1 * kh_s, k0sq - k30 * k1 * beta)
    k1z = k1 == 0
    k1_s = xp.where(k1z, 1.0, k1)
    pref = k2 * k0sq / kh_s**3
    c2 = pref * ang
    zeta1 = xp.where(k1z, -beta, c1 - (k2 / k1_s) * c2)
    zeta2 = xp.where(k1z, 0.0, (k2 / k1_s) * c1 + c2)
    zeta1 = xp.where(on_axis, 0.0, zeta1)
    zeta2 = xp.where(on_axis, 0.0, zeta2)
    a = e0 / (4 * np.pi * k0sq**2)
    p11 = a * (k0sq - k1 * k1 - 2 * k1 * k30 * zeta1 + khsq * zeta1**2)
    p22 = a * (k0sq - k2 * k2 - 2 * k2 * k30 * zeta2 + khsq * zeta2**2)
    p33 = e0 / (4 * np.pi * ksq_s**2) * khsq
    p12 = a * (-k1 * k2 - k1 * k30 * zeta2 - k2 * k30 * zeta1 + khsq * zeta1 * zeta2)
    b = e0 / (4 * np.pi * k0sq * ksq_s)
    p13 = b * (-k1 * k30 + khsq * zeta1)
    p23 = b * (-k2 * k30 + khsq * zeta2)
    phi = xp.stack([xp.stack([p11, p12, p13], -1), xp.stack([p12, p22, p23], -1),
                    xp.stack([p13, p23, p33], -1)], -2)
    return xp.where(zero[..., None, None], 0.0, phi)


def box_wavenumbers(shape, spacing):
    """The FFT wavenumbers ``(k1, k2, k3)`` (rad/m) of a periodic box of `shape` nodes and
    `spacing` metres, and the cell volume ``dk`` of wavenumber space."""
    shape = tuple(int(n) for n in shape)
    spacing = np.asarray(spacing, dtype=np.float64)
    ks = [2 * np.pi * np.fft.fftfreq(n, d) for n, d in zip(shape, spacing, strict=True)]
    dk = float(np.prod(2 * np.pi / (np.asarray(shape) * spacing)))
    return ks, dk


def box_variance(shape, spacing, alphaepsilon, length_scale, gamma):
    """The ``(3, 3)`` velocity covariance of a periodic Mann box, ``sum_k Phi(k) dk`` over its
    wavenumbers (m^2/s^2): the expected variances of an FFT-generated box (no high-frequency
    compensation)."""
    (k1, k2, k3), dk = box_wavenumbers(shape, spacing)
    total = np.zeros((3, 3))
    for a in k1:
        kk = np.stack(np.broadcast_arrays(a, k2[:, None], k3[None, :]), -1)
        total += mann_tensor(kk, alphaepsilon, length_scale, gamma).sum(axis=(0, 1))
    return total * dk


def synthesize_box(shape, spacing, alphaepsilon, length_scale, gamma, *, seed=0, dtype=None):
    """A periodic Gaussian Mann box whose spectrum is *exactly* ``Phi(k) dk`` on the box's
    wavenumbers (the spectral model of `lidar_variance`), as a `lidarjax.TurbulenceBox`
    (``periodic=(True, True)``, box frame of `lidarjax.scenes.turbulence`).

    The one generator of such boxes is `lidarjax.turbulence.fft_mann_box` (FFT synthesis
    ``u(x) = Re sum_k sqrt(dk) C(k) xi_k exp(i k . x)`` with Mann's closed-form ``C C^H =
    Phi`` and independent complex standard normal ``xi_k``); this wraps its array. Unlike
    hipersim it does not apply Mann's (1998) low-wavenumber cell averaging, so its expected
    covariances are those of `box_variance` exactly.
    """
    u = fft_mann_box(shape, spacing, length_scale=length_scale, gamma=gamma,
                     alphaepsilon=alphaepsilon, seed=seed)
    dtype = default_float() if dtype is None else dtype
    return TurbulenceBox(jnp.asarray(u, dtype=dtype), jnp.asarray(spacing, dtype=dtype),
                         periodic=(True, True))




def mann_box(
    alphaepsilon: float,
    length_scale: float,
    gamma: float,
    shape: tuple[int, int, int],
    spacing: tuple[float, float, float],
    *,
    seed: int = 1,
    periodic: bool = False,
    high_freq_comp: int = 0,
    dtype=None,
) -> TurbulenceBox:
    """Generate a Mann (1994) turbulence box with hipersim (optional extra ``turbulence``).

    **Arguments:**

    - `alphaepsilon`: ``alpha eps^(2/3)`` (m^(4/3)/s^2), the spectral level.
    - `length_scale`: ``L`` (m); `gamma`: the anisotropy ``Gamma`` (dimensionless).
    - `shape`: ``(nx, ny, nz)`` nodes; `spacing`: ``(dx, dy, dz)`` in metres.
    - `seed`: the random seed (hipersim's generator).
    - `periodic`: ``False`` (default) generates a box twice as wide and high and keeps one
      quarter (hipersim's ``double_xyz=(False, True, True)``), so it is not periodic laterally
      and vertically (`TurbulenceBox.periodic` = ``(False, False)``); ``True`` keeps the plain
      FFT box, periodic in all three directions (what the spectral model of `lidarjax.spectral`
      describes exactly).
    - `high_freq_comp`: hipersim's high-frequency compensation option (0, 1 or 2).

    The box is in the box frame of this module (``x`` downwind, ``y`` to the left, ``z`` up),
    as hipersim makes it.
    """
    hipersim = import_optional("hipersim", "turbulence", "Generating a Mann box")
    shape = tuple(int(n) for n in shape)
    field = hipersim.MannTurbulenceField.generate(
        alphaepsilon=float(alphaepsilon), L=float(length_scale), Gamma=float(gamma),
        Nxyz=shape, dxyz=tuple(float(d) for d in spacing), seed=int(seed),
        HighFreqComp=high_freq_comp, double_xyz=(False, not periodic, not periodic),
    )
    uvw = np.moveaxis(np.asarray(field.uvw), 0, -1)
    dtype = default_float() if dtype is None else dtype
    return TurbulenceBox(jnp.asarray(uvw, dtype=dtype), jnp.asarray(spacing, dtype=dtype),
                         periodic=(periodic, periodic))


