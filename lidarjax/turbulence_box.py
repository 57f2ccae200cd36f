"""The FFT generator of exact-spectrum Mann (1994, 1998) turbulence boxes (numpy and scipy
only).

`lidarjax.scenes.turbulence.mann_box` generates boxes with hipersim (the optional extra
``turbulence``), the reference implementation, which applies Mann's low-wavenumber cell
averaging. This module draws the box's discrete spectrum exactly, with Mann's closed-form
square root ``C(k)`` of the spectral tensor (its ``C C^H`` equals
`lidarjax.spectral.mann_tensor` to rounding, and its boxes have the covariance of
`lidarjax.spectral.box_variance`; both tested): the box the spectral model of
`lidarjax.spectral` describes. It is the library's one such generator: the demo, the command
line and `lidarjax.spectral.synthesize_box` (the same box as a `TurbulenceBox`) use it. One
periodic box (no lateral/vertical doubling, periodic in all three directions, as FFT boxes
are).

The spectral tensor is Mann's uniform-shear model: the von Karman energy spectrum
``E(k) = alpha eps^(2/3) L^(5/3) (kL)^4 / (1 + (kL)^2)^(17/6)`` (isotropic for
``gamma = 0``), sheared by the eddy lifetime ``beta = gamma (kL)^(-2/3) /
sqrt(2F1(1/3, 17/6; 4/3; -(kL)^-2))``. Each Fourier coefficient is
``C(k) n(k) sqrt(dk1 dk2 dk3)`` with complex Gaussian noise ``n`` and Mann's
(1998, equation 16) amplitude matrix ``C(k)`` (``C C^H = Phi(k)``); the velocity is the real
part of the inverse FFT, so its covariance is ``sum_k Phi(k) dk`` over the box's wave
numbers. The ``k = 0`` mode is zero (zero-mean box).

The box frame is that of `lidarjax.scenes.turbulence`: ``x`` downwind, ``y`` to the left
looking downwind, ``z`` up; ``velocity[i, j, k] = (u', v', w')`` m/s.

Cost: one complex FFT of the box per component, ``O(N log N)``: a 512 x 32 x 32 box takes
about 0.3 s on one core.
"""

from __future__ import annotations

import numpy as np
from scipy import special

__all__ = ["fft_mann_box", "mann_spectrum_level"]


def mann_spectrum_level(sigma_u: float, length_scale: float, gamma: float = 3.9) -> float:
    """``alpha eps^(2/3)`` (m^(4/3)/s^2) giving an infinite-domain ``sigma_u`` (m/s) for Mann's
    model with `length_scale` L (m) and `gamma`, by the isotropic relation
    ``sigma_iso^2 = 0.6883 alpha eps^(2/3) L^(2/3)`` scaled by the shear's ``sigma_u^2 /
    sigma_iso^2`` (about 1.9 at gamma 3.9, computed here by quadrature). Use it to set a target
    turbulence level; a finite box holds less variance (its largest scales are missing)."""
    k = np.logspace(-4, 3, 4000) / length_scale
    e = length_scale ** (5 / 3) * (k * length_scale) ** 4 / (1 + (k * length_scale) ** 2) ** (17 / 6)
    iso = np.trapezoid(e, k) * 2 / 3  # sigma^2 per component per unit alpha eps^(2/3)
    if gamma <= 0:
        return float(sigma_u**2 / iso)
    # sheared u variance by Monte-Carlo-free quadrature of Phi_11 on a spherical grid
    kk = np.logspace(-3, 2.5, 220) / length_scale
    th = np.linspace(0, np.pi, 61)
    ph = np.linspace(0, 2 * np.pi, 121, endpoint=False)
    K, T, P = np.meshgrid(kk, th, ph, indexing="ij")
    k1, k2, k3 = K * np.sin(T) * np.cos(P), K * np.sin(T) * np.sin(P), K * np.cos(T)
    c = _amplitude(k1, k2, k3, 1.0, length_scale, gamma)
    phi11 = np.sum(np.abs(c[..., 0, :]) ** 2, axis=-1)
    integrand = phi11 * K**2 * np.sin(T)
    var = np.trapezoid(np.trapezoid(np.sum(integrand, axis=2) * (2 * np.pi / ph.size), th, axis=1),
                       kk)
    return float(sigma_u**2 / var)


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

    Wrap it as a field with ``lidarjax.scenes.TurbulenceBox(box, spacing, periodic=(True,
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
