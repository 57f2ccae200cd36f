"""Analytic lidar–rotor spectra for lidar-assisted control (Task 52's analytic model; Schlipf
2015, §5): the spectra of the rotor-effective wind speed ``R`` and of its lidar estimate
``L``, their cross-spectrum, coherence and transfer function, and what a feed-forward
controller reads from them: the coherence bandwidth, the first-order filter's cut-off, the
filter's delay and the buffer time.

**Model.** ``R = sum_k rho_k u_k`` over the rotor disc (`RotorDisc`); ``L = sum_j w_j LOS_j /
nx_j`` over the lidar's nodes (`LidarSamples`), ``LOS_j = nx_j u + ny_j v + nz_j w``. Under
frozen turbulence a node ``x_j`` upstream sees the rotor's wind ``x_j / U`` earlier, and a
node measured ``d_j`` before the estimate is formed is that much older: lead
``tau_j = x_j / U - d_j``. With the IEC Kaimal spectra and the IEC coherence of ``u`` between
lateral-vertical distances ``r`` (`KaimalInflow`):

- ``S_RR = S_u sum_kl rho_k rho_l coh(r_kl)``;
- ``S_LL = S_u sum_jl w_j w_l coh(r_jl) cos(2 pi f (tau_j - tau_l))
  + sum_j w_j^2 (S_v ny_j^2 + S_w nz_j^2) / nx_j^2`` (``v`` and ``w`` enter through their
  auto-spectra, uncorrelated between distinct nodes, as in Task 52's model);
- ``S_RL = E[R conj(L)] = S_u sum_kj rho_k w_j coh(r_kj) exp(-i 2 pi f tau_j)`` (its phase
  is minus the lidar's lead: the rotor lags);
- coherence ``S_RL^2 / (S_RR S_LL)``, transfer ``|G_RL| = |S_RL| / S_LL``.

Spectra are one-sided, (m/s)^2/Hz, at frequencies in Hz.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Complex, Float

from .._precision import is_concrete, safe_sqrt
from .._util import compiled
from .geometry import LidarSamples, RotorDisc
from .inflow import KaimalInflow
from .mann import MannInflow, _mann_spectra

__all__ = ["HALF_POWER", "LacSpectra", "buffer_time", "coherence_bandwidth", "filter_cutoff", "filter_delay",
           "lac_spectra"]

#: ``10^(-3/20)``: the -3 dB magnitude (MATLAB's ``db2mag(-3)``, Task 52's cut-off level).
HALF_POWER = 10 ** (-3 / 20)


class LacSpectra(eqx.Module):
    """Lidar–rotor spectra at a set of frequencies (from `lac_spectra`).

    **Fields:** `frequency` (Hz), `S_RR`, `S_LL` ((m/s)^2/Hz), `S_RL` (complex, (m/s)^2/Hz,
    ``E[R conj(L)]``), `mean_speed` (m/s).
    """

    frequency: Float[Array, " f"]
    S_RR: Float[Array, " f"]
    S_LL: Float[Array, " f"]
    S_RL: Complex[Array, " f"]
    mean_speed: Float[Array, ""]

    @property
    def coherence(self) -> Float[Array, " f"]:
        """Squared coherence ``gamma^2 = |S_RL|^2 / (S_RR S_LL)`` (dimensionless, 0..1)."""
        return _coherence(self.S_RL, self.S_RR, self.S_LL)

    @property
    def transfer(self) -> Float[Array, " f"]:
        """``|G_RL| = |S_RL| / S_LL``, the optimal filter's magnitude (dimensionless)."""
        return jnp.abs(self.S_RL) / self.S_LL

    @property
    def wavenumber(self) -> Float[Array, " f"]:
        """``k = 2 pi f / U`` (rad/m)."""
        return 2 * np.pi * self.frequency / self.mean_speed


@jax.jit
def _coherence(s_rl, s_rr, s_ll):
    """`LacSpectra.coherence`: one compiled program (eagerly, four)."""
    return jnp.abs(s_rl) ** 2 / (s_rr * s_ll)


def _lateral_distance(a, b):
    d = a[:, None, :] - b[None, :, :]
    return safe_sqrt(jnp.sum(d**2, axis=-1))


def _one_frequency(f, spec, rate, rotor, samples, lead, r_ll, r_rl, inverse, vw):
    om = 2 * np.pi * f
    rr = jnp.dot(rotor.pair_weight, jnp.exp(-rate * rotor.pair_distance))
    # cos(om (t_j - t_l)) = cos cos + sin sin: n cosines per frequency, not n^2
    wc = samples.weights * jnp.cos(om * lead)
    ws = samples.weights * jnp.sin(om * lead)
    e = jnp.exp(-rate * r_ll)
    ll = wc @ e @ wc + ws @ e @ ws
    a = rotor.weights @ jnp.exp(-rate * r_rl)  # the disc's coherence with each node (or class)
    if inverse is not None:
        a = a[inverse]
    rl = jnp.dot(a, wc) - 1j * jnp.dot(a, ws)
    s_ll = spec[0] * ll + spec[1] * vw[0] + spec[2] * vw[1]
    return spec[0] * rr, s_ll, spec[0] * rl


@jax.jit
def _spectra(samples, rotor, inflow, frequency, classes=None):
    f = jnp.asarray(frequency)
    spec = inflow.spectra(f).T
    rate = inflow.decay_rate(f)
    lead = samples.points[:, 0] / inflow.mean_speed - samples.delays
    yz = samples.points[:, 1:]
    r_ll = _lateral_distance(yz, yz)
    rep, inverse = (None, None) if classes is None else classes
    r_rl = _lateral_distance(rotor.points.astype(yz.dtype), yz if rep is None else yz[rep])
    nd = samples.directions
    w2 = samples.weights**2
    vw = jnp.stack([jnp.sum(w2 * (nd[:, 1] / nd[:, 0]) ** 2), jnp.sum(w2 * (nd[:, 2] / nd[:, 0]) ** 2)])

    def one(args):
        return _one_frequency(*args, rotor, samples, lead, r_ll, r_rl, inverse, vw)

    s_rr, s_ll, s_rl = jax.lax.map(one, (f, spec, rate))
    return LacSpectra(frequency=f, S_RR=s_rr, S_LL=s_ll, S_RL=s_rl, mean_speed=inflow.mean_speed)


def lac_spectra(samples: LidarSamples, rotor: RotorDisc, inflow: KaimalInflow | MannInflow,
                frequency: Float[ArrayLike, " f"]) -> LacSpectra:
    """``S_RR``, ``S_LL``, ``S_RL`` of the REWS and its lidar estimate (see the module docs).

    **Arguments:**

    - `samples`: the lidar's nodes (`lidar_samples`).
    - `rotor`: the rotor disc (`rotor_disc`).
    - `inflow`: the turbulence: `KaimalInflow` (the model above) or `MannInflow` (the Mann
      tensor, `lidarjax.control.mann`; chosen by type when traced).
    - `frequency`: ``(f,)`` frequencies (Hz, positive).

    **Returns:** `LacSpectra`. Differentiable in every number of `samples` and `inflow`.
    """
    f = np.asarray(frequency) if not isinstance(frequency, jax.Array) else frequency
    if f.ndim != 1 or f.shape[0] < 2:
        raise ValueError("lac_spectra: frequency must be a 1-D array of at least 2 frequencies (Hz), "
                         f"got shape {f.shape}")
    if isinstance(f, np.ndarray) and not np.all(f > 0):
        raise ValueError("lac_spectra: frequency must be positive (Hz)")
    if not isinstance(inflow, KaimalInflow | MannInflow):
        raise ValueError(f"lac_spectra: inflow must be a KaimalInflow or a MannInflow, got "
                         f"{type(inflow).__name__}")
    classes = None if isinstance(inflow, MannInflow) else _symmetry_classes(samples, rotor)
    return _inflow_spectra(samples, rotor, inflow, jnp.asarray(f), classes)


def _inflow_spectra(samples, rotor, inflow, frequency, classes=None):
    """`lac_spectra` without its checks (also at one frequency, and traced): the Kaimal
    model (`_spectra`) or the Mann tensor (`_mann_spectra`), chosen by the inflow's type."""
    if isinstance(inflow, MannInflow):
        s_rr, s_ll, s_rl = _mann_spectra(samples, rotor, inflow, frequency)
        return LacSpectra(frequency=frequency, S_RR=s_rr, S_LL=s_ll, S_RL=s_rl, mean_speed=inflow.mean_speed)
    return _spectra(samples, rotor, inflow, frequency, classes)


def _symmetry_classes(samples, rotor):
    """For a symmetric disc and concrete nodes: one representative node per class of nodes
    that the disc's symmetries map onto each other (same ``sort(|y|, |z|)`` to 1e-9 m), and
    each node's class; ``None`` when traced (gradients keep every node's own distances) or when
    nothing repeats."""
    if not rotor.symmetric or not is_concrete(samples.points):
        return None
    canon = np.sort(np.abs(np.asarray(samples.points, np.float64)[:, 1:]), axis=1)
    _, rep, inverse = np.unique(np.round(canon, 9), axis=0, return_index=True, return_inverse=True)
    if rep.size == canon.shape[0]:
        return None
    return jnp.asarray(rep), jnp.asarray(inverse.ravel())


def _first_crossing(x, y, level):
    """``x`` where ``y`` first falls below `level` (linear interpolation between the grid's
    two bracketing points); NaN if ``y`` starts below it or never falls below it."""
    below = y < level
    i = jnp.argmax(below)
    ok = jnp.any(below) & (i > 0)
    i0 = jnp.maximum(i - 1, 0)
    y0, y1, x0, x1 = y[i0], y[i], x[i0], x[i]
    denom = jnp.where(ok, y1 - y0, 1.0)
    return jnp.where(ok, x0 + (level - y0) * (x1 - x0) / denom, jnp.nan)


@compiled
def coherence_bandwidth(spectra: LacSpectra, level: Float[ArrayLike, ""] = 0.5):
    """The coherence bandwidth: where ``gamma^2`` first falls to `level` (0.5).

    **Returns:** ``(frequency, wavenumber)``: Hz and rad/m (``k = 2 pi f / U``), by linear
    interpolation on the spectra's frequency grid; NaN where the coherence starts below
    `level` or never reaches it on the grid.
    """
    f = _first_crossing(spectra.frequency, spectra.coherence, level)
    return f, 2 * np.pi * f / spectra.mean_speed


@compiled
def filter_cutoff(spectra: LacSpectra, level: Float[ArrayLike, ""] = HALF_POWER):
    """The cut-off of the first-order low-pass feed-forward filter (rad/s): ``2 pi f`` at the
    first frequency where ``|G_RL|`` falls to -3 dB (`HALF_POWER`), Task 52's design (its
    ``FFP_v1`` ``f_cutoff``), by linear interpolation on the grid; NaN if never reached."""
    return 2 * np.pi * _first_crossing(spectra.frequency, spectra.transfer, level)


@compiled
def filter_delay(spectra: LacSpectra, cutoff: Float[ArrayLike, ""], *, n_lags: int = 2001):
    """The delay of the first-order filter of `cutoff` (rad/s) on the lidar signal (s).

    The lag of the peak of the cross-correlation between the filtered and the unfiltered
    estimate, ``sum_f S_LL Re[H(f) exp(i 2 pi f t)]`` with ``H = 1 / (1 + i 2 pi f / cutoff)``:
    the analytic form of Task 52's time-domain estimate of ``T_filter``. Searched on `n_lags`
    lags in ``[0, 4 / cutoff]`` and refined by two Newton steps (differentiable through the
    last step). It is shorter than the low-frequency group delay ``1 / cutoff``.
    """
    f = spectra.frequency
    om = 2 * np.pi * f
    df = jnp.gradient(f)
    c = jnp.asarray(cutoff)
    h = spectra.S_LL * df / (1 + 1j * om / c)
    lags = jnp.linspace(0.0, 4.0, n_lags) / jax.lax.stop_gradient(c)
    corr = jnp.real(jnp.exp(1j * om[None] * lags[:, None]) @ h)
    t = lags[jnp.argmax(corr)]

    def newton(t):
        e = h * jnp.exp(1j * om * t)
        return t - jnp.real(jnp.sum(1j * om * e)) / jnp.real(jnp.sum(-(om**2) * e))

    t = jax.lax.stop_gradient(newton(t))
    return newton(t)


def buffer_time(distance, mean_speed, *, scan_time, filter_delay, prediction_time):
    """Buffer time of the feed-forward signal, ``x/U - T_scan/2 - T_filter - tau`` (Schlipf
    2015, eq. 5.40), in seconds.

    **Arguments:** `distance` ``x``, the preview distance upstream (m); `mean_speed` ``U``
    (m/s); `scan_time` ``T_scan``, one full scan (s); `filter_delay` ``T_filter`` (s, e.g.
    `filter_delay`); `prediction_time` ``tau``, how far ahead the pitch must act (s).

    **Returns:** ``T_buffer`` (s); negative when the preview is too short for the request.
    """
    return (jnp.asarray(distance) / jnp.asarray(mean_speed) - jnp.asarray(scan_time) / 2
            - jnp.asarray(filter_delay) - jnp.asarray(prediction_time))
