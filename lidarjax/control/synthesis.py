"""Time series of the rotor-effective wind speed and of its lidar estimate in synthetic
Kaimal/IEC turbulence (Veers' spectral method), the time-domain counterpart of
`lac_spectra`: the same model, simulated rather than summed.

**Field.** ``u`` on the rotor plane enters through the REWS ``R = sum_k rho_k u_k`` and ``u``
at the lateral-vertical position of every lidar node: at each frequency ``f_k = k / T`` these
``1 + J`` numbers are a complex Gaussian vector with covariance ``2 S_u(f_k) df M_k``, ``M_k``
the IEC coherence ``exp(-rate(f_k) r)`` between the nodes, bordered by ``rho^T C_k rho``
(the disc over itself) and ``rho^T C_k`` (the disc with each node), factorised by Cholesky;
an inverse FFT makes a periodic series of duration ``T``. Synthesising ``u`` at every rotor
point and averaging gives the same joint distribution of ``(R, u_nodes)`` (a linear map of one
Gaussian vector) at the cost of a Cholesky factor of the whole ``(n_rotor + J)`` matrix per
frequency: 2,500 times the work for Task 52's 709-point rotor and 44 nodes.
Frozen turbulence (Taylor): a node ``x_j`` upstream sees the plane's wind
``x_j / U`` earlier, and its measurement is ``d_j`` old when the estimate is formed, so its
series is the plane's shifted by the lead ``tau_j = x_j / U - d_j`` (a phase
``exp(i 2 pi f tau_j)``, exact for the periodic series). ``v`` and ``w`` are synthesised at
each node independently (their Kaimal spectra, no coherence between nodes: Task 52's model).

**Processing.** ``REWS(t) = sum_k rho_k u_k(t)`` over the disc; each node's line-of-sight speed
``LOS_j = nx_j u_j + ny_j v_j + nz_j w_j`` and the estimate ``sum_j w_j LOS_j / nx_j`` (Task
52's lidar data processing), both in the time domain.

Host-side numpy in float64 (a simulation, not differentiable).
"""

from __future__ import annotations

import contextlib

import equinox as eqx
import numpy as np
from scipy import special

try:  # optional: scipy usually brings it
    from threadpoolctl import threadpool_limits
except ImportError:  # pragma: no cover
    threadpool_limits = None

from .geometry import LidarSamples, RotorDisc
from .inflow import KaimalInflow

__all__ = ["coherence_band", "kaimal_rews_series", "welch_coherence"]


def _one_blas_thread():
    """Many small Cholesky factorisations run ten times faster on one BLAS thread than on a
    shared machine's oversubscribed pool (threadpoolctl, when installed)."""
    return contextlib.nullcontext() if threadpool_limits is None else threadpool_limits(1)


def _disc_pairs(yz, rho):
    """The disc's pairs grouped by distance: unique distances ``d`` (m) and the summed weights
    ``sum rho_k rho_l`` over the pairs at each (exact to 1e-9 m), so that ``rho^T C rho`` is a
    sum over a few thousand distances, not ``n^2`` pairs."""
    r = np.hypot(*(yz[:, None, :] - yz[None]).transpose(2, 0, 1))
    d, inverse = np.unique(np.round(r, 9).ravel(), return_inverse=True)
    return d, np.bincount(inverse, (rho[:, None] * rho[None]).ravel(), d.size)


def _coherence_matrices(rotor_yz, rho, node_yz, rate):
    """``M_k`` of the module docs, ``(n_freq, 1 + J, 1 + J)``: the REWS first, then the nodes."""
    d, pair_weight = _disc_pairs(rotor_yz, rho)
    r_rn = np.hypot(*(rotor_yz[:, None, :] - node_yz[None]).transpose(2, 0, 1))
    r_nn = np.hypot(*(node_yz[:, None, :] - node_yz[None]).transpose(2, 0, 1))
    m = np.empty((rate.size, 1 + node_yz.shape[0], 1 + node_yz.shape[0]))
    m[:, 0, 0] = np.exp(-rate[:, None] * d) @ pair_weight
    m[:, 0, 1:] = m[:, 1:, 0] = np.einsum("k,fkj->fj", rho, np.exp(-rate[:, None, None] * r_rn))
    m[:, 1:, 1:] = np.exp(-rate[:, None, None] * r_nn)
    return m


def _plane_coefficients(rotor_yz, rho, node_yz, freq, s_u, rate, rng, chunk=256):
    """Complex Fourier amplitudes ``(1 + J, n_freq)`` of the REWS and of ``u`` at the nodes,
    ``E[A A^H] = 2 S_u df M`` at each frequency (Veers' method on the reduced vector)."""
    df = freq[1] - freq[0] if freq.size > 1 else freq[0]
    out = np.empty((1 + node_yz.shape[0], freq.size), np.complex128)
    for a in range(0, freq.size, chunk):
        b = min(a + chunk, freq.size)
        m = _coherence_matrices(rotor_yz, rho, node_yz, rate[a:b])
        jitter = 1e-12 * np.einsum("fii->fi", m)[:, :, None] * np.eye(m.shape[1])
        with _one_blas_thread():
            chol = np.linalg.cholesky(m + jitter)
        z = rng.standard_normal((b - a, m.shape[1])) + 1j * rng.standard_normal((b - a, m.shape[1]))
        amp = np.sqrt(s_u[a:b] * df)[:, None]  # |z|^2 has mean 2: E|A|^2 = 2 S df
        out[:, a:b] = (amp * np.einsum("fij,fj->fi", chol, z)).T
    return out


def _series(coefficients, n):
    """Real series of length `n` from one-sided amplitudes at ``f_k = k / T``, ``k = 1..``:
    ``sum_k Re[A_k exp(i 2 pi f_k t)]``."""
    full = np.zeros(coefficients.shape[:-1] + (n // 2 + 1,), np.complex128)
    m = min(coefficients.shape[-1], n // 2 - 1)
    full[..., 1:m + 1] = coefficients[..., :m] * (n / 2)
    return np.fft.irfft(full, n)


@eqx.filter_jit
def _spectra_and_rate(inflow, freq):
    """The inflow's spectra and coherence decay rate at `freq`: one compiled program."""
    return inflow.spectra(freq), inflow.decay_rate(freq)


def kaimal_rews_series(samples: LidarSamples, rotor: RotorDisc, inflow: KaimalInflow, *,
                       duration: float, dt: float, seed: int = 0):
    """The REWS and its lidar estimate simulated in Kaimal/IEC turbulence (module docs).

    **Arguments:**

    - `samples`: the lidar's nodes (`lidar_samples`; rotor frame, ``x`` upstream, m).
    - `rotor`: the rotor disc (`rotor_disc`).
    - `inflow`: the turbulence (`KaimalInflow`: mean speed, intensity, scale, coherence decay).
    - `duration`: the series' length ``T`` (s); its frequencies are ``k / T``.
    - `dt`: the sampling interval (s); the synthesis stops below the Nyquist ``1 / (2 dt)``.
    - `seed`: the random seed (the same seed, the same turbulence).

    **Returns:** ``(time, rews, estimate)``: ``(n,)`` arrays, seconds and m/s (fluctuations
    about the mean; zero mean), ``n = round(duration / dt)``.
    """
    duration, dt = float(duration), float(dt)
    if not (np.isfinite(duration) and np.isfinite(dt) and 0 < 4 * dt <= duration):
        raise ValueError(f"kaimal_rews_series: need 0 < 4 dt <= duration (s), got dt={dt}, "
                         f"duration={duration}")
    n = int(round(duration / dt))
    freq = np.arange(1, n // 2) / (n * dt)
    spec, rate = (np.asarray(a, np.float64) for a in _spectra_and_rate(inflow, freq))
    rng = np.random.default_rng(seed)
    pts = np.asarray(samples.points, np.float64)
    rotor_yz = np.asarray(rotor.points, np.float64)
    coef = _plane_coefficients(rotor_yz, np.asarray(rotor.weights, np.float64), pts[:, 1:], freq, spec[0],
                               rate, rng)
    lead = pts[:, 0] / float(inflow.mean_speed) - np.asarray(samples.delays, np.float64)
    rews = _series(coef[0], n)
    u_node = _series(coef[1:] * np.exp(2j * np.pi * freq * lead[:, None]), n)
    noise = rng.standard_normal((2, pts.shape[0], freq.size)) + 1j * rng.standard_normal((2, pts.shape[0],
                                                                                          freq.size))
    v, w = _series(np.sqrt(spec[1:, None, :] * (freq[1] - freq[0])) * noise, n)
    d = np.asarray(samples.directions, np.float64)
    los = d[:, :1] * u_node + d[:, 1:2] * v + d[:, 2:] * w
    estimate = np.asarray(samples.weights, np.float64) / d[:, 0] @ los
    return np.arange(n) * dt, rews, estimate


def welch_coherence(rews, estimate, dt: float, *, nperseg: int, lead: float = 0.0):
    """Welch's squared coherence of the REWS and its lidar estimate (Hann windows of `nperseg`
    samples, no overlap, no detrending: the series are fluctuations).

    The estimate is first delayed by `lead` (s, rounded to a sample; the preview time, as Task
    52's processing shifts it): the analytic coherence does not change under a delay, but
    Welch's estimate of a cross-spectrum whose phase turns within a bin is biased low.

    **Returns:** ``(frequency, coherence, n_segments)``: Hz (the bins above 0), the estimate,
    the number of independent segments averaged.
    """
    # imported here: scipy.signal (and the scipy.stats it imports) was 1.1 s of `import lidarjax`
    import scipy.signal

    est = np.roll(np.asarray(estimate, np.float64), int(round(float(lead) / float(dt))))
    f, c = scipy.signal.coherence(np.asarray(rews, np.float64), est, fs=1 / float(dt),
                                  window="hann", nperseg=int(nperseg), noverlap=0, detrend=False)
    return f[1:], c[1:], len(est) // int(nperseg)


def coherence_band(coherence, n_segments: int, *, level: float = 0.95, n_bins: int = 1):
    """The band in which Welch's estimate of a squared coherence falls with probability
    `level` (Fisher's ``z = atanh(|gamma|)``, normal with mean ``atanh(|gamma|) + 1 / (2(n-1))``
    and standard deviation ``1 / sqrt(2(n-1))`` for ``n`` = `n_segments`); with `n_bins` > 1
    the simultaneous band over that many bins (Bonferroni).

    **Returns:** ``(low, high)``: arrays like `coherence` (the true squared coherence).
    """
    n = int(n_segments)
    if n < 3:
        raise ValueError(f"coherence_band: n_segments must be at least 3, got {n}")
    z = np.arctanh(np.sqrt(np.clip(np.asarray(coherence, np.float64), 0, 1 - 1e-15))) + 1 / (2 * (n - 1))
    half = special.ndtri(1 - (1 - level) / (2 * n_bins)) / np.sqrt(2 * (n - 1))  # normal quantile
    return np.tanh(np.maximum(z - half, 0)) ** 2, np.tanh(z + half) ** 2
