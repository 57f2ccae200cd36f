"""Probe volumes: how a lidar weights the wind along its beam around the focus range.

A real lidar does not measure at a point. A probe turns the focus range ``f`` (along a beam)
into quadrature nodes: offsets ``o_q`` along the beam (positive away from the lidar) and
weights ``w_q`` summing to one; the LOS is ``sum_q w_q n . V(x_lidar + (f + o_q) n)``, an
approximation of ``integral phi(o) n . V(x_lidar + (f + o) n) do`` with the probe's
continuous weighting ``phi`` (`AbstractProbe.weight`, unit integral over the whole line).

- `PointProbe`: the ideal point measurement (the seed UDF's model); `simulate` compiles no
  quadrature for it at all.
- `PulsedProbe`: a pulsed lidar (Windcube): Gaussian pulse convolved with the range gate.
- `CWProbe`: a focused continuous-wave lidar (ZephIR): a Lorentzian whose width grows with
  the square of the focus distance.

**Units.** Every length (pulse length, gate, wavelength, aperture, offsets) is in the
*field's* length unit. The defaults are full-scale metres. For a model-scale CFD field (e.g.
a platform model 0.35 m high at 1:100) use ``probe.scaled(100)``: it divides every length by
the factor, which keeps the probe geometrically similar to the full-scale instrument (for
the CW probe, dividing the wavelength and the aperture by ``s`` scales its width
``lambda f^2 / (pi a^2)`` at the scaled focus ``f/s`` by exactly ``1/s``).

**Quadrature.** Node count ``n_nodes`` is static (it sets shapes); the reference nodes
(Gauss-Legendre on ``[-1, 1]``, symmetric) are computed with numpy at construction and
stored as arrays, so changing any number (pulse length, gate, wavelength, aperture, tail)
never recompiles `simulate`; the scaling to physical offsets happens in the graph and is
differentiable. Nodes are symmetric about the focus, so a field whose LOS varies linearly
along the beam gives exactly the point-probe LOS.

**Truncation.** The weighting has infinite support; the nodes cover a truncated support
that holds at least ``1 - tail`` of the weight, and the weights are renormalised over it.

- Pulsed: support ``|o| <= gate/2 + erfcinv(tail) * rp`` (the Gaussian's own tail bound, so
  the weight outside is at most ``tail`` for any gate). With the defaults (``tail = 1e-3``)
  the support is +-49.1 m, the weight outside is 1.2e-4, and the second moment (which sets
  the bias in a curved profile, ``V''/2 * sigma^2``) is 0.17 % short of the untruncated
  ``sigma^2 = rp^2/2 + gate^2/12 = (13.26 m)^2``: a curvature bias error of 0.17 % of the
  probe-volume effect itself. ``tail = 1e-6`` makes that 2e-6 at a support of +-66.9 m.
- CW: the Lorentzian's tails are heavy (its second moment is infinite), so no truncation
  makes the curvature bias converge: the truncated support *defines* the model. The
  support is ``|o| <= HWHM * cot(tail * pi / 2)`` (12.7 HWHM for the default ``tail =
  0.05``: 95 % of the weight) and the nodes are the Gauss rule of the truncated Lorentzian
  itself (computed once per ``(n_nodes, tail)`` by the discretised Stieltjes procedure),
  exact for polynomial variation along the beam up to degree ``2 n_nodes - 1``: its
  moments equal those of the truncated weighting to about 1e-12.

**Behind the lidar.** No light returns from behind the lidar, and neither weighting is a
faithful model next to the telescope. The probe is therefore cut symmetrically at the lidar:
nodes with ``|o| >= f`` get zero weight on both sides and the rest are renormalised, so the
probe stays centred on its focus (a linear field still gives the point LOS exactly) and no
node samples behind the lidar. `simulate` raises `Flag.PROBE_TRUNCATED` for a height when
the weight so dropped exceeds the probe's ``tail`` (smaller drops are within the truncation
already accepted). For the default pulsed probe the cut starts at focus ranges below
47.6 m (its outermost node) and is flagged below about 41 m (e.g. the vertical beam at
40 m; real pulsed lidars have a blind zone of that order too); for the default CW probe,
whose support grows as ``f^2``, the cut starts at about 125 m and is flagged beyond about
260 m. The LOS stays finite. Symmetric rules with an odd node count have a node at the
focus, which is never cut; with an even count, a focus range below the innermost offset
would keep no node at all, and the LOS is then the focus point's (the limit of the
symmetric cut).

**Default parameters** (typical published values, used here as assumptions; set your
instrument's):

- `PulsedProbe`: a 175 ns pulse (as in Windcube V2 headers), FWHM length
  ``c * 175 ns / 2 = 26.2 m``; range gate 25 m (published Windcube V2 gates are 20-30 m).
- `CWProbe`: wavelength 1.565 um and an effective aperture radius of 28 mm (ZephIR 300), so
  HWHM ``lambda f^2 / (pi a^2)`` is 6.35 m at 100 m focus (FWHM 12.7 m), 1.0 m at 40 m.
"""

from __future__ import annotations

import abc
import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float
from scipy import special

from ._precision import default_float, is_concrete

__all__ = ["AbstractProbe", "PointProbe", "PulsedProbe", "CWProbe", "probe_for_spacing", "probe_transfer"]

#: Speed of light in vacuum, m/s (for converting pulse durations to lengths).
SPEED_OF_LIGHT = 299_792_458.0


class AbstractProbe(eqx.Module):
    """Interface of a probe volume.

    - ``nodes(focus_range) -> (offsets, weights)``: quadrature ``(..., q)`` (broadcastable
      against ``focus_range[..., None]``), offsets in field length units along the beam,
      weights summing to one.
    - ``weight(offset, focus_range)``: the continuous weighting, unit integral over the line.
    - ``support(focus_range)``: half-width of the truncated support (0 for a point).
    - ``scaled(factor)``: the same probe with every length divided by `factor`.

    A probe may also carry ``tail``, the weight it already leaves outside its truncated
    support; `simulate` flags a height only when the cut at the lidar drops more than that
    (0 when absent). Nodes must be symmetric about the focus.
    """

    @abc.abstractmethod
    def nodes(self, focus_range):
        """Quadrature ``(offsets (..., q), weights (..., q))`` for ranges ``(...)``."""

    @abc.abstractmethod
    def weight(self, offset, focus_range):
        """Weighting density at `offset` from the focus (1 / length unit)."""

    @abc.abstractmethod
    def support(self, focus_range):
        """Half-width of the truncated support the nodes cover (length unit)."""

    @abc.abstractmethod
    def scaled(self, factor):
        """The probe with every length divided by `factor` (for model-scale fields)."""


class PointProbe(AbstractProbe):
    """An ideal point measurement at the focus range (the seed UDF's model)."""

    def nodes(self, focus_range):  # pragma: no cover - never traced: simulate skips it
        raise TypeError("PointProbe has no quadrature; simulate samples the focus point only.")

    def weight(self, offset, focus_range):
        """A Dirac delta: ``inf`` at offset 0, 0 elsewhere."""
        offset = jnp.asarray(offset)
        return jnp.where(offset == 0, jnp.inf, jnp.zeros_like(offset, dtype=_float_dtype(offset)))

    def support(self, focus_range):
        """Zero: a point."""
        return jnp.zeros_like(jnp.asarray(focus_range, dtype=_float_dtype(focus_range)))

    def scaled(self, factor):
        """A point stays a point."""
        return self


def _float_dtype(x):
    dt = jnp.asarray(x).dtype
    return dt if jnp.issubdtype(dt, jnp.floating) else default_float()


def _param(name: str, value, *, positive: bool = True):
    if is_concrete(value):
        v = np.asarray(value, dtype=np.float64)
        if v.shape != () or not np.isfinite(v) or (positive and not v > 0):
            raise ValueError(f"{name} must be one finite positive number, got {value!r}.")
    value = jnp.asarray(value)
    if not jnp.issubdtype(value.dtype, jnp.floating):
        value = value.astype(default_float())
    return value


def _check_nodes_tail(cls: str, n_nodes, tail) -> tuple[int, float]:
    if int(n_nodes) != n_nodes or int(n_nodes) < 1:
        raise ValueError(f"{cls}: n_nodes must be a positive integer, got {n_nodes!r}.")
    if not is_concrete(tail):
        raise ValueError(f"{cls}: `tail` sets the reference nodes and must be a concrete number.")
    t = float(tail)
    if not 0.0 < t < 1.0:
        raise ValueError(
            f"{cls}: `tail` is the weight left outside the truncated support, in (0, 1); "
            f"got {tail!r}."
        )
    return int(n_nodes), t


def _gauss_legendre(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Symmetric Gauss-Legendre nodes and weights on [-1, 1] (weights sum to 1)."""
    x, w = np.polynomial.legendre.leggauss(n)
    x = 0.5 * (x - x[::-1])  # exact antisymmetry
    w = 0.5 * (w + w[::-1])
    return x, w / w.sum()


@functools.lru_cache(maxsize=64)
def _lorentzian_rule(n: int, tail: float) -> tuple[np.ndarray, np.ndarray]:
    """Gauss rule of the Lorentzian ``1 / (pi (1 + x^2))`` truncated to ``|x| <= cot(tail
    pi/2)``: symmetric nodes (in HWHM units) and weights summing to 1.

    Discretised Stieltjes procedure: the truncated Lorentzian is uniform in ``theta`` (``x =
    tan theta``), so a Gauss-Legendre grid in ``theta`` discretises it to far below rounding;
    the three-term recurrence of its orthonormal polynomials gives the Jacobi matrix, whose
    eigen-decomposition (Golub-Welsch) gives the rule.
    """
    theta_max = 0.5 * np.pi * (1.0 - tail)
    x_max = np.tan(theta_max)
    big = max(600, 4 * n)
    t, w = special.roots_legendre(big)
    x = np.tan(theta_max * t) / x_max  # scaled to [-1, 1] for a stable recurrence
    w = w / w.sum()
    beta = np.zeros(n)
    p_prev, p, b_prev = np.zeros(big), np.ones(big), 0.0
    for k in range(n - 1):  # symmetric measure: all recurrence alphas vanish
        q = x * p - b_prev * p_prev
        b = np.sqrt(np.sum(w * q * q))
        beta[k + 1] = b
        p_prev, p, b_prev = p, q / b, b
    nodes, vectors = np.linalg.eigh(np.diag(beta[1:], 1) + np.diag(beta[1:], -1))
    weights = vectors[0] ** 2
    nodes = 0.5 * (nodes - nodes[::-1]) * x_max  # exact antisymmetry
    weights = 0.5 * (weights + weights[::-1])
    if n % 2:
        nodes[n // 2] = 0.0
    return nodes, weights / weights.sum()


class PulsedProbe(AbstractProbe):
    """A pulsed lidar's range weighting (Windcube): Gaussian pulse convolved with the gate.

    ``phi(F) = [erf((F + Dp/2)/rp) - erf((F - Dp/2)/rp)] / (2 Dp)`` with ``Dp`` the gate
    length and ``rp = pulse_fwhm / (2 sqrt(ln 2))``; its variance is ``rp^2/2 + Dp^2/12``.

    **Arguments:**

    - `pulse_fwhm`: full width at half maximum of the pulse as a length along the beam
      (``c * duration / 2``), field length units. Default 26.2 m (175 ns).
    - `gate_length`: range-gate length ``Dp``, field length units. Default 25 m.
    - `n_nodes`: quadrature node count (static). Default 9 (see the accuracy benchmark).
    - `tail`: weight bound left outside the truncated support (see module docs), 1e-3.

    All numbers are dynamic and differentiable except `n_nodes` and `tail`, which set the
    reference nodes. See the module docs for defaults, truncation and near-lidar behaviour.
    """

    pulse_fwhm: Float[Array, ""]
    gate_length: Float[Array, ""]
    tail: Float[Array, ""]
    truncation: Float[Array, ""]  # erfcinv(tail): support = gate/2 + truncation * rp
    ref_nodes: Float[Array, " q"]
    ref_weights: Float[Array, " q"]

    def __init__(
        self,
        pulse_fwhm: Float[ArrayLike, ""] = SPEED_OF_LIGHT * 175e-9 / 2,
        gate_length: Float[ArrayLike, ""] = 25.0,
        *,
        n_nodes: int = 9,
        tail: float = 1e-3,
    ):
        n, t = _check_nodes_tail("PulsedProbe", n_nodes, tail)
        self.pulse_fwhm = _param("PulsedProbe: pulse_fwhm", pulse_fwhm)
        self.gate_length = _param("PulsedProbe: gate_length", gate_length)
        dtype = default_float()
        x, w = _gauss_legendre(n)
        self.tail = jnp.asarray(t, dtype)
        self.truncation = jnp.asarray(special.erfcinv(t), dtype)
        self.ref_nodes = jnp.asarray(x, dtype)
        self.ref_weights = jnp.asarray(w, dtype)

    @property
    def n_nodes(self) -> int:
        """Number of quadrature nodes (static)."""
        return self.ref_nodes.shape[0]

    def _rp(self, dtype):
        return self.pulse_fwhm.astype(dtype) / (2.0 * np.sqrt(np.log(2.0)))

    def variance(self) -> Float[Array, ""]:
        """Variance of the untruncated weighting, ``rp^2/2 + gate^2/12`` (length^2)."""
        rp = self._rp(self.pulse_fwhm.dtype)
        return rp**2 / 2 + self.gate_length**2 / 12

    def weight(self, offset, focus_range=None):
        """``phi(offset)`` (1 / length); independent of the focus range."""
        offset = jnp.asarray(offset)
        dtype = _float_dtype(offset)
        rp, dp = self._rp(dtype), self.gate_length.astype(dtype)
        erf = jax.scipy.special.erf
        return (erf((offset + dp / 2) / rp) - erf((offset - dp / 2) / rp)) / (2 * dp)

    def support(self, focus_range=None):
        """``gate/2 + erfcinv(tail) * rp``, the same at every range."""
        dtype = _float_dtype(focus_range) if focus_range is not None else self.tail.dtype
        half = self.gate_length.astype(dtype) / 2 + self.truncation.astype(dtype) * self._rp(dtype)
        if focus_range is None:
            return half
        return jnp.broadcast_to(half, jnp.shape(focus_range))

    def nodes(self, focus_range):
        """``(offsets (q,), weights (q,))``: the same at every range (broadcastable)."""
        dtype = _float_dtype(focus_range)
        half = self.support(None).astype(dtype)
        offsets = half * self.ref_nodes.astype(dtype)
        w = self.ref_weights.astype(dtype) * self.weight(offsets)
        return offsets, w / jnp.sum(w)

    def with_nodes(self, n_nodes: int) -> PulsedProbe:
        """The same weighting (parameters kept as they are, traced or not) integrated with
        `n_nodes` quadrature nodes."""
        ref = PulsedProbe(n_nodes=n_nodes, tail=float(self.tail))
        return eqx.tree_at(lambda p: (p.pulse_fwhm, p.gate_length), ref,
                           (self.pulse_fwhm, self.gate_length))

    def scaled(self, factor) -> PulsedProbe:
        """Pulse and gate lengths divided by `factor` (model scale ``1:factor``)."""
        return eqx.tree_at(
            lambda p: (p.pulse_fwhm, p.gate_length),
            self,
            (self.pulse_fwhm / factor, self.gate_length / factor),
        )


class CWProbe(AbstractProbe):
    """A focused continuous-wave lidar's weighting (ZephIR): a Lorentzian along the beam.

    ``phi(o) = (1/pi) G / (o^2 + G^2)`` with half width at half maximum
    ``G = lambda f^2 / (pi a^2)`` at focus distance ``f`` (full width ``2 lambda f^2/(pi a^2)``).

    **Arguments:**

    - `wavelength`: laser wavelength ``lambda``, field length units. Default 1.565e-6 m.
    - `aperture_radius`: effective aperture (beam) radius ``a`` at the lens, field length
      units. Default 28e-3 m.
    - `n_nodes`: quadrature node count (static). Default 17.
    - `tail`: Lorentzian weight left outside the truncated support (see module docs), 0.05.

    Nodes are the Gauss rule of the Lorentzian truncated to ``|o| <= G cot(tail pi/2)``
    (see the module docs); their weights do not depend on the range, their positions scale
    with ``f^2`` in the graph.
    """

    wavelength: Float[Array, ""]
    aperture_radius: Float[Array, ""]
    tail: Float[Array, ""]
    support_ratio: Float[Array, ""]  # cot(tail pi / 2): support half-width / HWHM
    ref_offsets: Float[Array, " q"]  # node offsets in units of the HWHM
    ref_weights: Float[Array, " q"]

    def __init__(
        self,
        wavelength: Float[ArrayLike, ""] = 1.565e-6,
        aperture_radius: Float[ArrayLike, ""] = 28e-3,
        *,
        n_nodes: int = 17,
        tail: float = 0.05,
    ):
        n, t = _check_nodes_tail("CWProbe", n_nodes, tail)
        self.wavelength = _param("CWProbe: wavelength", wavelength)
        self.aperture_radius = _param("CWProbe: aperture_radius", aperture_radius)
        dtype = default_float()
        x, w = _lorentzian_rule(n, t)
        self.tail = jnp.asarray(t, dtype)
        self.support_ratio = jnp.asarray(np.tan(0.5 * np.pi * (1.0 - t)), dtype)
        self.ref_offsets = jnp.asarray(x, dtype)
        self.ref_weights = jnp.asarray(w, dtype)

    @property
    def n_nodes(self) -> int:
        """Number of quadrature nodes (static)."""
        return self.ref_offsets.shape[0]

    def hwhm(self, focus_range):
        """Half width at half maximum ``lambda f^2 / (pi a^2)`` at focus `focus_range`."""
        f = jnp.asarray(focus_range)
        dtype = _float_dtype(f)
        lam, a = self.wavelength.astype(dtype), self.aperture_radius.astype(dtype)
        return lam * f.astype(dtype) ** 2 / (np.pi * a**2)

    def weight(self, offset, focus_range):
        """Lorentzian density ``G / (pi (o^2 + G^2))`` (1 / length)."""
        g = self.hwhm(focus_range)
        offset = jnp.asarray(offset).astype(g.dtype)
        return g / (np.pi * (offset**2 + g**2))

    def support(self, focus_range):
        """``HWHM(f) * cot(tail pi / 2)``."""
        g = self.hwhm(focus_range)
        return g * self.support_ratio.astype(g.dtype)

    def nodes(self, focus_range):
        """``(offsets (..., q), weights (q,))``: offsets scale with ``f^2``."""
        g = self.hwhm(focus_range)
        return g[..., None] * self.ref_offsets.astype(g.dtype), self.ref_weights.astype(g.dtype)

    def with_nodes(self, n_nodes: int) -> CWProbe:
        """The same weighting (parameters kept as they are, traced or not) integrated with
        `n_nodes` quadrature nodes."""
        ref = CWProbe(n_nodes=n_nodes, tail=float(self.tail))
        return eqx.tree_at(lambda p: (p.wavelength, p.aperture_radius), ref,
                           (self.wavelength, self.aperture_radius))

    def scaled(self, factor) -> CWProbe:
        """Wavelength and aperture radius divided by `factor` (model scale ``1:factor``):
        the width at a scaled focus is then the full-scale width divided by `factor`."""
        return eqx.tree_at(
            lambda p: (p.wavelength, p.aperture_radius),
            self,
            (self.wavelength / factor, self.aperture_radius / factor),
        )


#: Node counts `probe_for_spacing` tries, in order (odd: the focus is a node).
REFINED_NODES = (9, 13, 17, 25, 33, 49, 65)


#: Largest ``|W_q - W|`` `probe_for_spacing` accepts below the field's Nyquist wavenumber.
TRANSFER_TOL = 0.02


def probe_for_spacing(probe: AbstractProbe, spacing, ranges, *, tol: float = TRANSFER_TOL,
                      max_nodes: int = REFINED_NODES[-1]) -> AbstractProbe:
    """`probe` with enough quadrature nodes to integrate its weighting over a field resolved
    to `spacing` metres (e.g. a turbulence box's smallest node spacing).

    A node rule averages a field ``exp(i kappa o)`` along the beam to ``W_q(kappa) = sum_q
    w_q cos(kappa o_q)``, which equals the Fourier transform of the (truncated) weighting
    only up to some wavenumber; beyond it the rule aliases (9 pulsed nodes return 0.46 of a
    0.3 rad/m wave the weighting filters out). A field with content up to its Nyquist
    wavenumber ``pi / spacing`` (a turbulence box) needs the rule to hold that far. This
    returns the probe with the fewest nodes in `REFINED_NODES` (at least its own, at most
    `max_nodes`) for which ``|W_q - W|`` stays within `tol` for every wavenumber up to
    ``pi / spacing`` at the shortest, middle and longest of `ranges` (focus ranges, m), or,
    when none does, the one with the smallest such error; the weighting itself (pulse,
    gate, wavelength, aperture, tail) is unchanged. Host numbers only; `PointProbe` and
    traced probes are returned as given.

    A pulsed probe needs 17 nodes for an 8 m box, 25 for 4 m, 49 for 2 m. The CW probe's
    Gauss rule of a truncated Lorentzian spreads its nodes over ``+-12.7`` half widths, which
    grow as the focus range squared (410 m at 226 m): no node count in `REFINED_NODES`
    resolves a 4 m box beyond about 150 m.
    """
    return _refine_probe(probe, spacing, ranges, tol, max_nodes)[0]


def _refine_probe(probe, spacing, ranges, tol=TRANSFER_TOL, max_nodes=REFINED_NODES[-1]):
    """`probe_for_spacing`, plus the largest ``|W_q - W|`` of the probe returned (0 when
    nothing was checked) and `tol`."""

    if isinstance(probe, PointProbe) or not hasattr(probe, "with_nodes"):
        return probe, 0.0, tol
    if not is_concrete(probe, spacing, ranges):
        return probe, 0.0, tol
    dx = float(np.min(np.asarray(spacing, np.float64)))
    r = np.asarray(ranges, np.float64).reshape(-1)
    r = r[np.isfinite(r) & (r > 0)]
    if not dx > 0 or r.size == 0:
        return probe, 0.0, tol
    check = np.unique([r.min(), np.median(r), r.max()])
    kappa = np.linspace(0.0, np.pi / dx, 257)
    exact = [probe_transfer(probe, kappa, rr, model="truncated") for rr in check]
    best, best_err = probe, np.inf
    for n in sorted({probe.n_nodes, *(k for k in REFINED_NODES if probe.n_nodes < k <= max_nodes)}):
        cand = probe if n == probe.n_nodes else probe.with_nodes(n)
        err = max(float(np.max(np.abs(probe_transfer(cand, kappa, rr, model="nodes") - ex)))
                  for rr, ex in zip(check, exact, strict=True))
        if err < best_err - 1e-3 or err <= tol:  # more nodes only where they help
            best, best_err = cand, err
        if err <= tol:
            break
    return best, best_err, tol


def probe_transfer(probe, kappa, focus_range, *, model: str = "weight"):
    """Fourier transform ``W(kappa) = int phi(o) exp(i kappa o) do`` of a probe's range
    weighting along the beam (real: the weightings are even), at wavenumbers `kappa` (rad/m,
    the wavevector's component along the beam) and focus range `focus_range` (m).

    `model`:

    - ``"weight"``: the untruncated weighting, in closed form. `lidarjax.PulsedProbe`: a
      Gaussian pulse of ``rp = fwhm / (2 sqrt(ln 2))`` convolved with the gate ``Dp``:
      ``exp(-kappa^2 rp^2 / 4) sinc(kappa Dp / 2)``. `lidarjax.CWProbe`: the Lorentzian of
      half width ``G``: ``exp(-G |kappa|)``. `lidarjax.PointProbe`: 1.
    - ``"truncated"``: the weighting truncated to the probe's support and renormalised, as
      the simulator uses it (dense Gauss-Legendre quadrature of ``probe.weight``).
    - ``"nodes"``: exactly what the simulator computes, ``sum_q w_q cos(kappa o_q)`` over
      the probe's quadrature nodes.
    """
    kappa = np.asarray(kappa, dtype=np.float64)
    r = float(np.asarray(focus_range, dtype=np.float64))
    if isinstance(probe, PointProbe):
        return np.ones_like(kappa)
    if model == "weight":
        if isinstance(probe, PulsedProbe):
            rp = float(probe.pulse_fwhm) / (2 * np.sqrt(np.log(2.0)))
            dp = float(probe.gate_length)
            return np.exp(-(kappa * rp) ** 2 / 4) * np.sinc(kappa * dp / (2 * np.pi))
        if isinstance(probe, CWProbe):
            g = float(probe.hwhm(r))
            return np.exp(-g * np.abs(kappa))
        raise ValueError(f"probe_transfer: no closed form for {type(probe).__name__}; use model='nodes'.")
    if model == "truncated":
        x, w = _legendre(2000)
        half, phi = _truncated_weight(probe, x, np.asarray(r))
        o = float(half) * x
        phi = np.asarray(phi, dtype=np.float64) * w
        phi = phi / phi.sum()
        return np.cos(np.multiply.outer(kappa, o)) @ phi
    if model == "nodes":
        offsets, weights = _nodes(probe, np.asarray(r))
        o = np.asarray(offsets, np.float64).reshape(-1)
        wq = np.broadcast_to(np.asarray(weights, np.float64).reshape(-1), o.shape)
        wq = wq / wq.sum()
        return np.cos(np.multiply.outer(kappa, o)) @ wq
    raise ValueError(f"probe_transfer: model must be 'weight', 'truncated' or 'nodes', got {model!r}.")


@functools.lru_cache(maxsize=4)
def _legendre(n):
    return special.roots_legendre(n)


@eqx.filter_jit
def _truncated_weight(probe, x, r):
    half = probe.support(r)
    return half, probe.weight(half * x, r)


@eqx.filter_jit
def _nodes(probe, r):
    return probe.nodes(jnp.asarray(r))


