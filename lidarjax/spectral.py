"""Spectral models of what a lidar measures in turbulence (validation of the time simulation).

The turbulence is a homogeneous Gaussian field with the Mann (1994) spectral tensor
``Phi_ij(k)`` in the box frame of `lidarjax.scenes.turbulence` (``x`` downwind, ``y`` to the
left, ``z`` up). Any quantity the instrument reports that is *linear* in the velocity field,

    ``q = sum_b a_b sum_q w_bq n_b . u(p_b + o_bq n_b, t_b)``

(a reconstructed component is a fixed linear combination of LOS, each LOS a probe-weighted
average along its beam), has, under Taylor's hypothesis, the variance

    ``var q = sum_k F(k_1) A_i(k)^* Phi_ij(k) A_j(k) dk``,
    ``A(k) = sum_b a_b n_b W_b(k . n_b) exp(i k . (p_b - U t_b e_x))``,

with ``W_b`` the Fourier transform of beam ``b``'s range weighting (`probe_transfer`) and
``F(k_1) = 1 - sinc^2(k_1 U T / 2)`` the part of the variance left inside records of length
``T`` (the record mean removes the rest). This is the model of Sathe et al. (2011, "Can wind
lidars measure turbulence?", J. Atmos. Oceanic Technol. 28): the lidar's variance differs from
a point sensor's because the probe averages along each beam and because the reconstruction
mixes components (``v``, ``w``) and points far apart.

The sum runs over the wavenumbers of a periodic box, ``k = 2 pi (m_1/L_x, m_2/L_y, m_3/L_z)``
with ``dk = (2 pi)^3 / (L_x L_y L_z)``: exactly the content of an FFT-generated Mann box of
that shape and spacing (hipersim without high-frequency compensation; for a box generated with
lateral/vertical doubling, give the doubled generation shape), and the continuous-space model
as the box grows and refines. `lidar_variance` returns the lidar's and a point sensor's
variances and their ratio (``TI_lidar^2 / TI_point^2``, the ratio Sathe et al. plot).

Everything here is float64 numpy on the host (a reference model, not part of the
differentiable forward model). Units: wavenumbers in rad/m, ``alphaepsilon`` in
``m^(4/3) s^-2``, variances in ``m^2/s^2``.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._deprecated import deprecated_getattr
from .probe import _nodes, probe_transfer
from .scan import reconstruct
from .turbulence import box_wavenumbers, mann_tensor

__all__ = [
    "LidarVariance",
    "lidar_variance",
    "lidar_variance_ratio",
    "reconstruction_coefficients",
    "LidarGeometry",
    "lidar_geometry",
    "lidar_response",
]


def reconstruction_coefficients(scan) -> np.ndarray:
    """The ``(3, b)`` matrix ``C`` with ``reconstruct(scan, los) = C @ los`` (every method is
    linear in the LOS), in the lidar frame; float64."""
    return np.asarray(_scan_matrices(scan)[1], dtype=np.float64)


@eqx.filter_jit
def _scan_matrices(scan):
    """Beam unit vectors ``(b, 3)`` and reconstruction matrix ``(3, b)`` (one compile per scan
    structure instead of one per eager operation)."""

    zeros = jnp.zeros((scan.n_beams,), dtype=scan.azimuths.dtype)
    return scan.directions(), jax.jacfwd(lambda s: reconstruct(scan, s))(zeros)


@dataclasses.dataclass(frozen=True)
class LidarVariance:
    """Result of `lidar_variance`: variances (m^2/s^2) of the lidar's reconstructed component
    and of a point sensor at the same height, inside records; `ratio` = lidar / point."""

    lidar: float
    point: float

    @property
    def ratio(self) -> float:
        """``var_lidar / var_point`` (= ``(TI_lidar / TI_point)^2``)."""
        return self.lidar / self.point

    @property
    def ti_ratio(self) -> float:
        """``TI_lidar / TI_point`` = ``sqrt(ratio)``."""
        return float(np.sqrt(self.ratio))


_COMPONENTS = {"u": 0, "v": 1, "w": 2}


@dataclasses.dataclass(frozen=True)
class LidarGeometry:
    """A level lidar's beams in the box frame, and the weight of each LOS in one reported
    component (see `lidar_geometry`). Lengths in metres, the lidar at the origin."""

    directions: np.ndarray  # (b, 3) beam unit vectors, box frame
    ranges: np.ndarray  # (b,) focus ranges
    coefficients: np.ndarray  # (b,) weight of each LOS in the component
    times: np.ndarray  # (r, b) beam times, s
    point: np.ndarray  # (3,) point sensor, box frame
    component: np.ndarray  # (3,) unit vector of the component, box frame


def lidar_geometry(scan, height, *, direction=270.0, beam_times=None, component="u") -> LidarGeometry:
    """The beams of a level lidar (lidar frame = CFD frame) in the box frame of a wind from
    meteorological `direction` (degrees clockwise from the lidar's ``+y``), focus ranges for
    `height` (m), and the weight ``a_b`` of each LOS in the reconstructed `component`
    (``"u"`` along the wind, ``"v"`` to its left, ``"w"`` up): the instrument reports
    ``sum_b a_b LOS_b`` (`reconstruction_coefficients`)."""
    if component not in _COMPONENTS:
        raise ValueError(f"lidar_geometry: component must be 'u', 'v' or 'w', got {component!r}.")
    h = float(height)
    if not h > 0:
        raise ValueError(f"lidar_geometry: height must be positive metres, got {height!r}.")
    n_lidar = np.asarray(_scan_matrices(scan)[0], dtype=np.float64)  # (b, 3) lidar frame
    nb = n_lidar.shape[0]
    d = np.deg2rad(float(direction))
    ex = np.array([-np.sin(d), -np.cos(d), 0.0])
    ey = np.array([-ex[1], ex[0], 0.0])
    axes = np.stack([ex, ey, np.array([0.0, 0.0, 1.0])])  # rows: box axes in the lidar frame
    c = _COMPONENTS[component]
    a = axes[c] @ reconstruction_coefficients(scan)
    if beam_times is None:
        times = np.zeros((1, nb))
    else:
        times = np.asarray(beam_times, dtype=np.float64)
        if times.ndim not in (1, 2) or times.shape[-1] != nb:
            raise ValueError(f"lidar_geometry: beam_times must be (b,) or (r, b) with b = {nb}, "
                             f"got shape {times.shape}.")
        times = times.reshape(-1, nb)
    return LidarGeometry(directions=n_lidar @ axes.T, ranges=h / n_lidar[:, 2], coefficients=a,
                         times=times, point=np.array([0.0, 0.0, h]), component=np.eye(3)[c])


def lidar_response(geometry: LidarGeometry, probe, k, *, speed=10.0, probe_model="weight"):
    """The lidar's transfer vector ``A(k)`` ``(..., 3)`` (complex) at wavenumbers `k`
    ``(..., 3)`` (rad/m, box frame): a velocity mode ``Re(c exp(i k . x))`` (the box advected at
    `speed` m/s) makes the reported component ``Re(A(k) . c)`` at ``t = 0``, so its variance
    is ``sum_k A^* Phi A dk``. The point sensor's is ``component * exp(i k . point)``."""
    k = np.asarray(k, dtype=np.float64)
    g = geometry
    amp = np.zeros(k.shape, dtype=np.complex128)
    k1 = k[..., 0]
    for b in np.flatnonzero(np.abs(g.coefficients) > 1e-12 * np.max(np.abs(g.coefficients))):
        m = g.directions[b]
        w = probe_transfer(probe, k @ m, g.ranges[b], model=probe_model)
        phase = np.exp(1j * (k @ (g.ranges[b] * m)))
        tfac = np.mean(np.exp(-1j * np.multiply.outer(k1 * float(speed), g.times[:, b])), axis=-1)
        amp += (g.coefficients[b] * w * phase * tfac)[..., None] * m
    return amp


def _lattice_factor(pos, k_axis, spacing, offset):
    """Exact linear-interpolation factor of mode ``exp(i k x)`` at positions `pos` (m) on a
    node lattice of `spacing` through `offset` (m): interpolated value / ``exp(i k pos)``,
    ``exp(-i f theta) ((1 - f) + f exp(i theta))`` with ``f`` the fraction of the cell and
    ``theta = k spacing``."""
    s = (np.asarray(pos, np.float64) - offset) / spacing
    f = s - np.floor(s)
    theta = np.asarray(k_axis, np.float64) * spacing
    return np.exp(-1j * f * theta) * ((1 - f) + f * np.exp(1j * theta))


def _aliased_amplitudes(geo, probe, kk, *, speed, spacing, node_offset, n_alias, times):
    """Lidar and point responses to one box mode as the simulator samples it (trilinear
    between the box's nodes): for every x alias ``n`` (``k1 + 2 pi n / dx``, amplitude
    ``sinc^2`` of the linear-interpolation kernel), the lidar's ``A_n(k)`` ``(w, ..., 3)``
    for each of the ``w`` beam-time patterns `times` ``(w, r, b)`` and the point's scalar
    factor, with the exact lateral/vertical interpolation factors of every probe node
    (fixed fractions: the nodes do not move across the wind)."""
    dx, dy, dz = spacing
    y0, z0 = node_offset
    k1, k2, k3 = kk[..., 0], kk[..., 1], kk[..., 2]
    beams = np.flatnonzero(np.abs(geo.coefficients) > 1e-12 * np.max(np.abs(geo.coefficients)))
    nodes = []
    for b in beams:
        m, r = geo.directions[b], float(geo.ranges[b])
        off, w = (np.asarray(a, np.float64).reshape(-1) for a in _nodes(probe, np.asarray(r)))
        w = np.broadcast_to(w, off.shape)
        keep = np.abs(off) < r  # the simulator's cut at the lidar
        off, w = off[keep], w[keep] / w[keep].sum()
        pos = (r + off)[:, None] * m  # (q, 3)
        # lateral and vertical parts: fixed per node, the same for every alias
        lateral = (np.exp(1j * (k2[..., None] * pos[:, 1] + k3[..., None] * pos[:, 2]))
                   * _lattice_factor(pos[:, 1], k2[..., None], dy, y0)
                   * _lattice_factor(pos[:, 2], k3[..., None], dz, z0) * w)  # (..., q)
        nodes.append((b, m, pos[:, 0], lateral))
    pt = geo.point
    point_yz = _lattice_factor(pt[1], k2, dy, y0) * _lattice_factor(pt[2], k3, dz, z0)
    out = []
    for n in range(-n_alias, n_alias + 1):
        q1 = k1 + 2 * np.pi * n / dx
        sx = np.sinc(q1 * dx / (2 * np.pi)) ** 2
        amp = np.zeros((times.shape[0],) + kk.shape, np.complex128)
        for b, m, px, lateral in nodes:
            acc = np.sum(np.exp(1j * q1[..., None] * px) * lateral, axis=-1)
            # (w, ...): the mean over the passes r of each pattern's time factor
            tfac = np.mean(np.exp(-1j * np.multiply.outer(times[:, :, b], q1 * float(speed))), axis=1)
            amp += (geo.coefficients[b] * acc * sx * tfac)[..., None] * m
        out.append((q1, amp, sx * point_yz))
    return out


def lidar_variance(
    scan,
    probe,
    height: float,
    length_scale: float,
    gamma: float,
    *,
    box_shape: tuple[int, int, int],
    box_spacing: tuple[float, float, float],
    alphaepsilon: float = 1.0,
    direction: float = 270.0,
    speed: float = 10.0,
    record_length: float | None = 600.0,
    beam_times=None,
    component: str = "u",
    probe_model: str = "weight",
    interpolation: str | None = None,
    node_offset: tuple[float, float] = (0.0, 0.0),
    n_alias: int = 2,
) -> LidarVariance:
    """Variance of a lidar's reconstructed wind component in Mann turbulence, and of a point
    sensor at the same height (see the module docs for the model).

    **Arguments:**

    - `scan`: a `lidarjax.Scan` (beam geometry and reconstruction method, e.g.
      `lidarjax.windcube_v2()`, `lidarjax.zephir()`); the lidar is level, its frame the CFD
      frame.
    - `probe`: the range weighting (`lidarjax.PulsedProbe`, `CWProbe`, `PointProbe`).
    - `height`: measurement height above the lidar (m); tilted beams focus at
      ``height / cos(cone)``.
    - `length_scale`, `gamma`, `alphaepsilon`: Mann parameters (m, -, m^(4/3)/s^2). The
      ratio does not depend on `alphaepsilon`.
    - `box_shape`, `box_spacing`: the periodic box whose wavenumbers are summed (nodes and
      metres, ``x`` along the wind); for a hipersim box generated with doubling, the doubled
      generation shape.
    - `direction`: meteorological wind direction relative to the lidar (degrees clockwise
      from the lidar's ``+y``, beam S0, where the wind comes from).
    - `speed`: advection speed ``U`` (m/s); with `record_length` ``T`` (s) it sets the record
      filter ``1 - sinc^2(k1 U T / 2)``; ``None`` keeps the whole variance.
    - `beam_times`: times (s) at which each beam is taken, ``(b,)``, or ``(r, b)`` for ``r``
      passes whose LOS are averaged before the reconstruction; default all at ``t = 0``.
      With ``interpolation="nodes"`` also ``(w, r, b)``: ``w`` patterns that occur equally
      often in a record (a Windcube's sliding windows: each new LOS closes a window with
      its own beam times), whose lidar variances are averaged.
    - `component`: ``"u"`` (along the wind, what the horizontal speed's dispersion measures to
      first order), ``"v"`` (lateral, to the left) or ``"w"`` (up).
    - `probe_model`: ``"weight"``, ``"truncated"`` or ``"nodes"`` (see `probe_transfer`).
    - `interpolation`: ``None`` (the continuous field of the box's modes) or ``"trilinear"``:
      the variance lost by trilinear interpolation between the box's nodes, as
      `FrozenTurbulence` samples it, for points spread uniformly within cells: each mode's
      contribution to the lidar is multiplied by the mean-square trilinear transfer
      ``prod_a (2 + cos(k_a d_a)) / 3`` (exact for one point; for the cross-beam terms, which
      matter only at wavenumbers well below the grid's where the factor is close to 1, an
      approximation), and the point sensor's by ``(2 + cos(k1 dx)) / 3`` (a sensor on a node
      column, sampled at times spread uniformly over the cells it crosses).

      ``"nodes"``: exactly how `FrozenTurbulence` interpolates, node by node. Across the
      wind every probe node and the point sensor keep their place between the box's nodes
      (lateral and vertical fractions fixed, set by `node_offset`): each gets its exact
      linear-interpolation factor, coherently across nodes and beams. Along the wind the
      advection sweeps them through the cells: linear interpolation of a mode ``k1`` is the
      sum of its aliases ``k1 + 2 pi n / dx`` (``|n| <= n_alias``) with amplitudes
      ``sinc^2((k1 + 2 pi n / dx) dx / 2)``, each advected, probe-weighted, record-filtered
      and summed in variance (their cross terms average out over a record whose LOS times do
      not repeat the same positions in the cells: choose a speed for which ``U`` times the
      revisit period of a beam is not a simple fraction of ``dx``). Needs the probe's nodes
      (``probe_model="nodes"``).
    - `node_offset`: ``(y, z)`` metres, for ``interpolation="nodes"``: the lidar's lateral
      and vertical box coordinates modulo the node spacing (``(0, 0)``: it stands on a
      column of nodes, as with `FrozenTurbulence`'s default anchor when ``ny`` is odd, or an
      anchor half a lateral spacing off for even ``ny``).
    - `n_alias`: aliases per side along the wind for ``interpolation="nodes"`` (2 keeps the
      point's mean-square transfer to 0.2 % at the grid's Nyquist wavenumber).

    **Returns:** a `LidarVariance` (``lidar``, ``point``, ``ratio``, ``ti_ratio``).
    """
    if interpolation not in (None, "trilinear", "nodes"):
        raise ValueError(f"lidar_variance: interpolation must be None, 'trilinear' or 'nodes', got "
                         f"{interpolation!r}.")
    if interpolation == "nodes" and probe_model != "nodes":
        raise ValueError("lidar_variance: interpolation='nodes' needs probe_model='nodes' (it "
                         "interpolates the probe's quadrature nodes one by one).")
    patterns = None
    if beam_times is not None and np.ndim(beam_times) == 3:
        if interpolation != "nodes":
            raise ValueError("lidar_variance: beam_times (w, r, b) (several patterns) needs "
                             "interpolation='nodes'; give one (b,) or (r, b) pattern otherwise.")
        patterns = np.asarray(beam_times, np.float64)
        beam_times = patterns[0]
    geo = lidar_geometry(scan, height, direction=direction, beam_times=beam_times, component=component)
    if interpolation == "nodes" and patterns is None:
        patterns = geo.times[None]
    spacing = np.asarray(box_spacing, dtype=np.float64)
    (k1s, k2, k3), dk = box_wavenumbers(box_shape, box_spacing)
    n1 = len(k1s)
    half = np.abs(k1s[: n1 // 2 + 1])  # k and -k contribute equally (Phi even, A(-k) = A(k)^*)
    mult = np.where((np.arange(half.size) == 0) | (2 * np.arange(half.size) == n1), 1.0, 2.0)
    if record_length is None:
        filt = np.ones_like(half)
    else:
        filt = 1.0 - np.sinc(half * float(speed) * float(record_length) / (2 * np.pi)) ** 2
    weight = mult * filt
    keep = np.flatnonzero(weight > 0)
    chunk = max(1, 200_000 // (k2.size * k3.size))
    var_l = var_p = 0.0
    for start in range(0, keep.size, chunk):
        idx = keep[start:start + chunk]
        kk = np.stack(np.broadcast_arrays(half[idx, None, None], k2[None, :, None], k3[None, None, :]), -1)
        phi = mann_tensor(kk, alphaepsilon, length_scale, gamma)
        if interpolation == "nodes":
            quad_p_base = np.einsum("i,...ij,j->...", geo.component, phi, geo.component)
            w = mult[idx][:, None, None]
            for q1, amp_n, point_n in _aliased_amplitudes(
                    geo, probe, kk, speed=speed, spacing=spacing, node_offset=node_offset,
                    n_alias=int(n_alias), times=patterns):
                f = (np.ones_like(q1) if record_length is None else
                     1.0 - np.sinc(q1 * float(speed) * float(record_length) / (2 * np.pi)) ** 2)
                quad_l = np.mean(np.real(np.einsum("w...i,...ij,w...j->w...", amp_n.conj(), phi,
                                                   amp_n)), axis=0)
                var_l += float(np.sum(w * f * quad_l))
                var_p += float(np.sum(w * f * np.abs(point_n) ** 2 * quad_p_base))
            continue
        amp = lidar_response(geo, probe, kk, speed=speed, probe_model=probe_model)
        quad_l = np.real(np.einsum("...i,...ij,...j->...", amp.conj(), phi, amp))
        quad_p = np.einsum("i,...ij,j->...", geo.component, phi, geo.component)
        if interpolation == "trilinear":
            t = (2 + np.cos(kk * spacing)) / 3
            quad_l = quad_l * np.prod(t, axis=-1)
            quad_p = quad_p * t[..., 0]
        w = weight[idx][:, None, None]
        var_l += float(np.sum(w * quad_l))
        var_p += float(np.sum(w * quad_p))
    return LidarVariance(lidar=var_l * dk, point=var_p * dk)


def lidar_variance_ratio(scan, probe, height, length_scale, gamma, **kwargs) -> float:
    """``var_lidar / var_point`` of `lidar_variance` (same arguments): the squared ratio of the
    lidar's to a point sensor's turbulence intensity (Sathe et al. 2011)."""
    return lidar_variance(scan, probe, height, length_scale, gamma, **kwargs).ratio


__getattr__ = deprecated_getattr(__name__)
