"""Probe volumes: how a lidar weights the wind along its beam around the focus range.

A real lidar does not measure at a point. A probe turns the focus range ``f`` (along a beam)
into quadrature nodes: offsets ``o_q`` along the beam (positive away from the lidar) and
weights ``w_q``; the LOS is ``sum_q w_q n . V(x_lidar + (f + o_q) n) / sum_q w_q``, an
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

**Quadrature: nodes exact to the field's resolution.** A node rule averages a wave ``exp(i
k o)`` along the beam to ``W_q(k) = sum_q w_q cos(k o_q)``; the weighting's own transfer
function is ``exp(-(k rp)^2/4) sinc(k Dp/2)`` (pulsed) or ``exp(-G |k|)`` (CW), and a rule
follows it only up to some wavenumber, beyond which it aliases. A field carries content up
to its Nyquist wavenumber ``pi / resolution`` (`lidarjax.AbstractField.resolution`: a grid's
or turbulence box's spacing, or the coarser scale a `GridField` of a smooth solution is built
with, a scene's smallest length scale), so `simulate`, the rotations,
`sensitivity`, `uncertainty`, the tables built from them and the series all take their nodes
from one place, `lidarjax.probe_for_field` (`lidarjax.beam`) -> `probe_for_spacing`: the fewest nodes whose
``|W_q - W|`` stays within `TRANSFER_TOL` (0.01) for every wavenumber up to ``pi /
resolution`` at every focus range, ``W`` being the transfer function of the weighting the
simulator integrates (below). A probe built with ``n_nodes=None`` (the default) is refined
so; an explicit ``n_nodes`` is used as given; a field that states no length scale (uniform,
linear, power-law scenes) gets the default count (9 pulsed, 17 CW). Node counts are static
(they set shapes) and the choice is cached, so the same field and heights never recompile;
every number (pulse, gate, wavelength, aperture, resolution) stays dynamic and
differentiable.

- Pulsed: midpoints of equal cells over the truncated support (weights ``phi``), whose error
  at ``k`` is the weighting's transfer function at the alias ``2 pi / spacing - k``: 11 nodes
  for an 8 m field, 17 for 4 m, 29 for 2 m (the earlier Gauss rule needed 17 / 25 / 49 for
  0.02).
- CW: nodes uniform in ``s(o) = atan(o / G) / delta + o / H``: uniform in the Lorentzian's
  angle near the focus, where its weight is, and at most ``H = 0.8 resolution`` apart in its
  tails (at least 40 % of the nodes, which carry its second moment). Default optics, 0.01
  (``n`` for 2 / 4 / 8 m): 17 / 15 / 13 at 10 m, 63 / 37 / 25 at 100 m, 139 / 77 / 45 at
  250 m. The Lorentzian widens as the focus range squared, so the count grows with range.

**Truncation and the cut at the lidar.** No light returns from behind the lidar, and neither
weighting is a faithful model next to the telescope. Both probes are cut symmetrically at the
lidar, ``|o| < f``, so they stay centred on the focus (a field whose LOS varies linearly along
the beam gives exactly the point LOS), and the rule is laid over the cut support (no node is
wasted behind the lidar). The weights sum to the weighting's weight inside it; `simulate`
renormalises them and raises `Flag.PROBE_TRUNCATED` for a height when the rest exceeds the
probe's ``tail``.

- Pulsed: the support is also truncated at ``|o| <= gate/2 + erfcinv(tail) * rp`` (the
  Gaussian's own tail bound, so the weight outside is at most ``tail`` for any gate): +-49.1 m
  with the default ``tail = 1e-3``, 1.2e-4 of the weight outside, a second moment 0.17 %
  short of ``rp^2/2 + gate^2/12 = (13.26 m)^2``. The cut bites below 49 m and is flagged below
  about 41 m (real pulsed lidars have a blind zone of that order).
- CW: the whole Lorentzian up to the cut. It keeps ``P = (2/pi) atan(f / G)`` of the weight:
  0.996 at 10 m, 0.96 at 100 m, 0.90 at 249 m (flagged beyond, ``tail = 0.1``). Its transfer
  function is then ``[exp(-G k) - (2G/pi) Re int_f^inf exp(i k o) / (o^2 + G^2) do] / P``
  (`probe_transfer(..., model="truncated")`, in closed form with exponential integrals),
  which differs from ``exp(-G |k|)`` by at most ``2 (1 - P) / P``: 0.005 at 10 m, 0.05 at
  100 m, 0.12 at 250 m. The earlier model truncated the Lorentzian at 5 % of its weight at
  every range and filtered turbulence about 10 % less than the full weighting.
- OpenFAST's InflowWind lidar (``Lidar.f90``) uses the same half width ``lambda f^2 / (pi
  a^2)`` in the Gaussian-beam form ``1 / (r^2 + (1 - r/f')^2 z_R^2)`` (``z_R = pi a^2 /
  lambda``), sampled at a fixed step (half the mean wind times the measurement interval, not
  the field's resolution), evaluated on the far side and mirrored, stopped where it falls
  below 2 % of the peak (about 7 half widths: it drops about 9 % of the weight at every range)
  or at the lidar. lidarjax integrates the whole Lorentzian to the cut, with nodes set by the
  field's resolution.

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
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float
from scipy import special

from ._precision import default_float, is_concrete
from ._util import compiled

__all__ = ["AbstractProbe", "PointProbe", "PulsedProbe", "CWProbe", "host_nodes", "host_weighting",
           "probe_for_spacing", "probe_transfer"]

#: Speed of light in vacuum, m/s (for converting pulse durations to lengths).
SPEED_OF_LIGHT = 299_792_458.0


class AbstractProbe(eqx.Module):
    """Interface of a probe volume.

    - ``nodes(focus_range) -> (offsets, weights)``: quadrature ``(..., q)`` (broadcastable
      against ``focus_range[..., None]``), offsets in field length units along the beam,
      weights summing to the weighting's weight over the nodes' span (at most one: `simulate`
      renormalises and reports the rest as cut).
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


#: Node counts when a probe is built without a field's resolution (`n_nodes=None`).
DEFAULT_PULSED_NODES = 9
DEFAULT_CW_NODES = 17

#: Largest ``|W_q - W|`` `probe_for_spacing` accepts below the field's Nyquist wavenumber.
TRANSFER_TOL = 0.01

#: Most nodes `probe_for_spacing` gives a probe (a CW probe far out at a 2 m resolution needs
#: a few hundred; see `lidarjax.probe`).
MAX_NODES = 1025

#: CW rule: node spacing in the Lorentzian's tails, as a fraction of the field's resolution.
CW_TAIL_SPACING = 0.8

#: CW rule: least share of the nodes spread evenly over the tails (they carry the weighting's
#: second moment, which sets the bias in a curved profile, at any resolution).
CW_TAIL_SHARE = 0.4

#: CW rule: largest angular step ``delta`` (rad) of the core nodes (uniform in ``theta``).
CW_MAX_STEP = np.pi / 12

_NEWTON_STEPS = 40
_INV_SQRT_PI = float(1.0 / np.sqrt(np.pi))


def _midpoints(n: int) -> np.ndarray:
    """``n`` midpoints of equal cells of ``[-1, 1]`` (exactly antisymmetric; 0 for odd ``n``)."""
    x = (2.0 * np.arange(n) + 1.0 - n) / n
    x = 0.5 * (x - x[::-1])
    if n % 2:
        x[n // 2] = 0.0
    return x


@functools.lru_cache(maxsize=64)
def _reference_nodes(cls: str, n_nodes, dtype) -> jax.Array:
    """`_midpoints` of a checked node count as a `dtype` array (built once per count)."""
    n, _ = _check_nodes_tail(cls, n_nodes, 0.5)
    return jnp.asarray(_midpoints(n), dtype)


def _quadrature(cls: str, n_nodes, default: int, tail):
    """A probe's quadrature, checked: its `tail` (a float and an array of the default float)
    and its reference nodes (`n_nodes`, or `default` when None)."""
    n, t = _check_nodes_tail(cls, default if n_nodes is None else n_nodes, tail)
    dtype = default_float()
    return t, jnp.asarray(t, dtype), _reference_nodes(cls, n, jnp.dtype(dtype))


def _pulsed_weight(erf, offset, rp, dp):
    """The pulsed weighting ``phi(offset)`` (1 / length) for ``rp`` and gate length ``dp``
    (`erf` of jax or scipy: traced or host)."""
    return (erf((offset + dp / 2) / rp) - erf((offset - dp / 2) / rp)) / (2 * dp)


def _pulsed_rule(xp, erf, support, r, rp, dp, x):
    """Midpoint rule of the pulsed weighting over the support cut at the lidar, ``|o| <
    h = min(support, r)`` for focus ranges `r` ``(...)``: offsets ``h * x`` ``(..., n)``
    and weights ``phi(offset)`` scaled to sum to the weighting's weight within ``|o| < h``,
    ``[Psi(h + Dp/2) - Psi(h - Dp/2)] / Dp`` with ``Psi(y) = rp (u erf(u) + exp(-u^2) /
    sqrt(pi))``, ``u = y / rp`` (at least ``1 - tail`` where the cut does not bite).
    Laying the nodes over the cut support, rather than cutting a fixed rule, keeps every
    node in use near the lidar."""
    h = xp.minimum(support, r)[..., None]
    offsets = h * x
    w = erf((offsets + dp / 2) / rp) - erf((offsets - dp / 2) / rp)

    def psi(y):
        u = y / rp
        return rp * (u * erf(u) + xp.exp(-u * u) * _INV_SQRT_PI)

    kept = (psi(h + dp / 2) - psi(h - dp / 2)) / dp
    return offsets, w * (kept / xp.sum(w, axis=-1, keepdims=True))


def _cw_rule(xp, g, r, resolution, x, *, traced: bool):
    """CW rule over the cut ``|o| < r`` for Lorentzian half widths `g`, focus ranges `r`
    (``(...)`` each), a field `resolution` (inf: none) and reference midpoints `x` ``(n,)``.

    Nodes are uniform in ``s(o) = atan(o / g) / delta + o / H``: uniform in the Lorentzian's
    angle ``theta = atan(o / g)`` near the focus (where its weight is, spacing ``g delta
    sec^2 theta``) and at most ``H`` apart in its tails, where the field's resolution, not
    the weighting, sets the spacing (a node rule aliases a wave whose wavelength is shorter
    than twice the local spacing). ``H = CW_TAIL_SPACING * resolution`` takes ``r / H`` of
    the ``n / 2`` nodes per side (at most what leaves the core a step of ``CW_MAX_STEP``);
    ``delta`` spreads the rest over ``theta`` in ``[0, atan(r / g))``. The weight of a node
    is the Lorentzian's over its cell, ``(1/pi) d theta / d s``, and the weights sum to the
    Lorentzian weight kept by the cut, ``(2/pi) atan(r / g)`` (what `simulate` reports as
    cut is one minus that). Returns ``(offsets, weights)``, ``(..., n)`` each."""
    n = x.shape[-1]
    m = 0.5 * n
    g = g[..., None]
    r = r[..., None]
    a = xp.arctan(r / g)  # theta of the cut
    most = xp.maximum(m - a / CW_MAX_STEP, 0.0)
    tails = xp.clip(xp.maximum(r / (CW_TAIL_SPACING * resolution), CW_TAIL_SHARE * m), 0.0, most)
    delta = a / (m - tails)
    c = g * tails / r  # s = theta / delta + c tan(theta)
    target = xp.abs(m * x)

    def step(th, delta, c):
        t = xp.tan(th)
        return th - (th / delta + c * t - target) / (1.0 / delta + c * (1.0 + t * t))

    # convex and increasing in theta: Newton from the right of the root converges monotonically
    th = xp.minimum(target * delta, a)
    if traced:  # iterate without derivatives, then one differentiable step (exact first ones)
        sg = jax.lax.stop_gradient
        th = jax.lax.fori_loop(0, _NEWTON_STEPS, lambda _, v: step(v, sg(delta), sg(c)), sg(th))
        th = step(th, delta, c)
    else:
        for _ in range(_NEWTON_STEPS):
            th = step(th, delta, c)
    th = xp.sign(x) * th
    t = xp.tan(th)
    w = 1.0 / (1.0 / delta + c * (1.0 + t * t))
    kept = (2.0 / np.pi) * a
    return g * t, w * (kept / xp.sum(w, axis=-1, keepdims=True))


class PulsedProbe(AbstractProbe):
    """A pulsed lidar's range weighting (Windcube): Gaussian pulse convolved with the gate.

    ``phi(F) = [erf((F + Dp/2)/rp) - erf((F - Dp/2)/rp)] / (2 Dp)`` with ``Dp`` the gate
    length and ``rp = pulse_fwhm / (2 sqrt(ln 2))``; its variance is ``rp^2/2 + Dp^2/12`` and
    its transfer function ``exp(-(k rp)^2 / 4) sinc(k Dp / 2)``.

    **Arguments:**

    - `pulse_fwhm`: full width at half maximum of the pulse as a length along the beam
      (``c * duration / 2``), field length units. Default 26.2 m (175 ns).
    - `gate_length`: range-gate length ``Dp``, field length units. Default 25 m.
    - `n_nodes`: quadrature node count (static). Default ``None``: chosen for the field
      being sampled (`probe_for_spacing` at its resolution: the fewest nodes whose transfer
      function is within 0.01 of the weighting's up to the field's Nyquist wavenumber), 9
      where the field states no length scale. An explicit count is used as given.
    - `tail`: weight bound left outside the truncated support (see module docs), 1e-3.

    Nodes are the midpoints of equal cells over the truncated support, weighted by ``phi``
    (a rule whose error at wavenumber ``k`` is the weighting's transfer function at the
    alias ``2 pi / spacing - k``, the fewest nodes for a given resolution). All numbers are
    dynamic and differentiable except `n_nodes` and `tail`.
    """

    pulse_fwhm: Float[Array, ""]
    gate_length: Float[Array, ""]
    tail: Float[Array, ""]
    truncation: Float[Array, ""]  # erfcinv(tail): support = gate/2 + truncation * rp
    ref_nodes: Float[Array, " q"]  # midpoints of n equal cells of [-1, 1]
    auto_nodes: bool = eqx.field(static=True)

    def __init__(
        self,
        pulse_fwhm: Float[ArrayLike, ""] = SPEED_OF_LIGHT * 175e-9 / 2,
        gate_length: Float[ArrayLike, ""] = 25.0,
        *,
        n_nodes: int | None = None,
        tail: float = 1e-3,
    ):
        t, self.tail, self.ref_nodes = _quadrature("PulsedProbe", n_nodes,
                                                   DEFAULT_PULSED_NODES, tail)
        self.auto_nodes = n_nodes is None
        self.pulse_fwhm = _param("PulsedProbe: pulse_fwhm", pulse_fwhm)
        self.gate_length = _param("PulsedProbe: gate_length", gate_length)
        self.truncation = jnp.asarray(special.erfcinv(t), default_float())

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

    @compiled
    def weight(self, offset, focus_range=None):
        """``phi(offset)`` (1 / length); independent of the focus range."""
        offset = jnp.asarray(offset)
        dtype = _float_dtype(offset)
        return _pulsed_weight(jax.scipy.special.erf, offset, self._rp(dtype),
                              self.gate_length.astype(dtype))

    def _host_weight(self, offset):
        """`weight` in float64 numpy (host), the rule of `_host_nodes`."""
        rp, dp = self._host_rp_gate()
        return _pulsed_weight(special.erf, np.asarray(offset, np.float64), rp, dp)

    def _host_rp_gate(self):
        """``(rp, gate length)`` as host floats."""
        return float(self.pulse_fwhm) / (2 * np.sqrt(np.log(2.0))), float(self.gate_length)

    def support(self, focus_range=None):
        """``gate/2 + erfcinv(tail) * rp``, the same at every range."""
        dtype = _float_dtype(focus_range) if focus_range is not None else self.tail.dtype
        half = self.gate_length.astype(dtype) / 2 + self.truncation.astype(dtype) * self._rp(dtype)
        if focus_range is None:
            return half
        return jnp.broadcast_to(half, jnp.shape(focus_range))

    @compiled
    def nodes(self, focus_range):
        """``(offsets (..., q), weights (..., q))`` for ranges ``(...)``: midpoints over the
        support cut at the lidar (``|o| < min(support, f)``), weights summing to the
        weighting's weight there (`simulate` renormalises them and flags the height when the
        rest exceeds `tail`)."""
        f = jnp.asarray(focus_range)
        dtype = _float_dtype(f)
        return _pulsed_rule(jnp, jax.scipy.special.erf, self.support(None).astype(dtype),
                            f.astype(dtype), self._rp(dtype), self.gate_length.astype(dtype),
                            self.ref_nodes.astype(dtype))

    def _host_nodes(self, focus_range):
        rp, dp = self._host_rp_gate()
        return _pulsed_rule(np, special.erf, dp / 2 + float(self.truncation) * rp,
                            np.asarray(focus_range, np.float64), rp, dp, _midpoints(self.n_nodes))

    def with_nodes(self, n_nodes: int, *, resolution=None) -> PulsedProbe:
        """The same weighting (parameters kept as they are, traced or not) integrated with
        `n_nodes` quadrature nodes (an explicit count: `simulate` uses it as given).
        `resolution` is accepted for symmetry with `CWProbe.with_nodes` (the pulsed rule
        does not depend on it)."""
        return self._with_rule(n_nodes, resolution, auto=False)

    def _with_rule(self, n_nodes, resolution, *, auto: bool) -> PulsedProbe:
        nodes = _reference_nodes("PulsedProbe", n_nodes, self.ref_nodes.dtype)
        base = self
        if auto != self.auto_nodes:  # a static flag: a new instance carrying these numbers
            base = eqx.tree_at(lambda p: (p.pulse_fwhm, p.gate_length, p.tail, p.truncation),
                               PulsedProbe(n_nodes=None if auto else n_nodes),
                               (self.pulse_fwhm, self.gate_length, self.tail, self.truncation))
        elif self.n_nodes == nodes.shape[0]:
            return self
        return eqx.tree_at(lambda p: p.ref_nodes, base, nodes)

    def scaled(self, factor) -> PulsedProbe:
        """Pulse and gate lengths divided by `factor` (model scale ``1:factor``; one finite
        positive number)."""
        factor = _param("PulsedProbe.scaled: factor", factor)
        return eqx.tree_at(
            lambda p: (p.pulse_fwhm, p.gate_length),
            self,
            (self.pulse_fwhm / factor, self.gate_length / factor),
        )


class CWProbe(AbstractProbe):
    """A focused continuous-wave lidar's weighting (ZephIR): a Lorentzian along the beam.

    ``phi(o) = (1/pi) G / (o^2 + G^2)`` with half width at half maximum
    ``G = lambda f^2 / (pi a^2)`` at focus distance ``f`` (full width ``2 lambda f^2/(pi a^2)``),
    transfer function ``exp(-G |k|)``. The whole Lorentzian is integrated up to the cut at the
    lidar (``|o| < f``, symmetric as for the pulsed probe: no light returns from behind the
    lidar, and the probe stays centred on its focus); the weight beyond the cut,
    ``1 - (2/pi) atan(f / G)``, is dropped and the rest renormalised (see the module docs).

    **Arguments:**

    - `wavelength`: laser wavelength ``lambda``, field length units. Default 1.565e-6 m.
    - `aperture_radius`: effective aperture (beam) radius ``a`` at the lens, field length
      units. Default 28e-3 m.
    - `n_nodes`: quadrature node count (static). Default ``None``: chosen for the field being
      sampled (`probe_for_spacing` at its resolution, within 0.01 of the weighting's transfer
      function up to the field's Nyquist wavenumber), 17 where the field states no length
      scale. An explicit count is used as given.
    - `tail`: the Lorentzian weight the cut at the lidar may drop before `simulate` flags
      the height (`Flag.PROBE_TRUNCATED`): default 0.1, flagged beyond 249 m with the
      default optics. It does not change the nodes.
    - `resolution`: the length scale the nodes resolve (field length units; ``None``: none).
      Set by `probe_for_spacing`; without one the nodes are uniform in the Lorentzian's
      angle (``o = G tan(theta)``).

    All numbers are dynamic and differentiable except `n_nodes`.
    """

    wavelength: Float[Array, ""]
    aperture_radius: Float[Array, ""]
    tail: Float[Array, ""]
    resolution: Float[Array, ""]  # inf: none
    ref_nodes: Float[Array, " q"]  # midpoints of n equal cells of [-1, 1] (in s / s_max)
    auto_nodes: bool = eqx.field(static=True)

    def __init__(
        self,
        wavelength: Float[ArrayLike, ""] = 1.565e-6,
        aperture_radius: Float[ArrayLike, ""] = 28e-3,
        *,
        n_nodes: int | None = None,
        tail: float = 0.1,
        resolution=None,
    ):
        _, self.tail, self.ref_nodes = _quadrature("CWProbe", n_nodes, DEFAULT_CW_NODES, tail)
        self.auto_nodes = n_nodes is None
        self.wavelength = _param("CWProbe: wavelength", wavelength)
        self.aperture_radius = _param("CWProbe: aperture_radius", aperture_radius)
        self.resolution = (jnp.asarray(np.inf, default_float()) if resolution is None
                           else _param("CWProbe: resolution", resolution))

    @property
    def n_nodes(self) -> int:
        """Number of quadrature nodes (static)."""
        return self.ref_nodes.shape[0]

    def hwhm(self, focus_range):
        """Half width at half maximum ``lambda f^2 / (pi a^2)`` at focus `focus_range`."""
        f = jnp.asarray(focus_range)
        dtype = _float_dtype(f)
        lam, a = self.wavelength.astype(dtype), self.aperture_radius.astype(dtype)
        return lam * f.astype(dtype) ** 2 / (np.pi * a**2)

    @compiled
    def weight(self, offset, focus_range):
        """Lorentzian density ``G / (pi (o^2 + G^2))`` (1 / length), uncut."""
        g = self.hwhm(focus_range)
        offset = jnp.asarray(offset).astype(g.dtype)
        return g / (np.pi * (offset**2 + g**2))

    def support(self, focus_range):
        """The cut at the lidar: the focus range itself (the nodes lie within ``|o| < f``)."""
        f = jnp.asarray(focus_range)
        return f.astype(_float_dtype(f))

    @compiled
    def kept_weight(self, focus_range):
        """Lorentzian weight inside the cut, ``(2/pi) atan(f / G)`` (0.96 at 100 m, 0.90 at
        249 m with the default optics)."""
        f = jnp.asarray(focus_range)
        return (2 / np.pi) * jnp.arctan(f.astype(_float_dtype(f)) / self.hwhm(f))

    @compiled
    def nodes(self, focus_range):
        """``(offsets (..., q), weights (..., q))`` for ranges ``(...)``: the weights sum to
        `kept_weight` (`simulate` renormalises them and flags the height when the rest
        exceeds `tail`)."""
        f = jnp.asarray(focus_range)
        dtype = _float_dtype(f)
        f = f.astype(dtype)
        return _cw_rule(jnp, self.hwhm(f), f, self.resolution.astype(dtype),
                        self.ref_nodes.astype(dtype), traced=True)

    def _host_nodes(self, focus_range):
        f = np.asarray(focus_range, np.float64)
        lam, a = float(self.wavelength), float(self.aperture_radius)
        g = lam * f**2 / (np.pi * a**2)
        return _cw_rule(np, g, f, float(self.resolution), _midpoints(self.n_nodes), traced=False)

    def with_nodes(self, n_nodes: int, *, resolution=None) -> CWProbe:
        """The same weighting (parameters kept as they are, traced or not) integrated with
        `n_nodes` quadrature nodes (an explicit count: `simulate` uses it as given), laid out
        for a field `resolution` (field length units; ``None``: the probe's own)."""
        return self._with_rule(n_nodes, resolution, auto=False)

    def _with_rule(self, n_nodes, resolution, *, auto: bool) -> CWProbe:
        nodes = _reference_nodes("CWProbe", n_nodes, self.ref_nodes.dtype)
        res = self.resolution if resolution is None else jnp.asarray(resolution, self.resolution.dtype)
        base = self
        if auto != self.auto_nodes:  # a static flag: a new instance carrying these numbers
            base = eqx.tree_at(lambda p: (p.wavelength, p.aperture_radius, p.tail),
                               CWProbe(n_nodes=None if auto else n_nodes),
                               (self.wavelength, self.aperture_radius, self.tail))
        return eqx.tree_at(lambda p: (p.resolution, p.ref_nodes), base, (res, nodes))

    def scaled(self, factor) -> CWProbe:
        """Wavelength, aperture radius and resolution divided by `factor` (model scale
        ``1:factor``; one finite positive number): the width at a scaled focus is then the
        full-scale width divided by `factor`."""
        factor = _param("CWProbe.scaled: factor", factor)
        # no resolution (inf) stays none, with finite derivatives (no inf / factor)
        finite = jnp.isfinite(self.resolution)
        resolution = jnp.where(finite, jnp.where(finite, self.resolution, 1.0) / factor,
                               self.resolution)
        return eqx.tree_at(
            lambda p: (p.wavelength, p.aperture_radius, p.resolution),
            self,
            (self.wavelength / factor, self.aperture_radius / factor, resolution),
        )


def probe_for_spacing(probe: AbstractProbe, spacing, ranges, *, tol: float = TRANSFER_TOL,
                      max_nodes: int = MAX_NODES) -> AbstractProbe:
    """`probe` with the fewest quadrature nodes that integrate its weighting over a field
    resolved to `spacing` (field length units: a grid's or a turbulence box's smallest node
    spacing, an analytic scene's smallest length scale) at focus `ranges`.

    A node rule averages a wave ``exp(i k o)`` along the beam to ``W_q(k) = sum_q w_q cos(k
    o_q)``, which equals the weighting's transfer function only up to some wavenumber;
    beyond it the rule aliases. A field carries content up to its Nyquist wavenumber ``pi /
    spacing``, so this returns the probe with the fewest nodes (odd, at most `max_nodes`)
    for which ``|W_q - W|`` stays within `tol` for every wavenumber up to ``pi / spacing``
    at every focus range (the shortest, longest and up to 14 between), with ``W`` the
    transfer function of the weighting the simulator integrates (cut at the lidar and
    renormalised: `probe_transfer` with ``model="truncated"``); or, when none does, the one
    with `max_nodes`. The weighting itself (pulse, gate, wavelength, aperture, tail) is
    unchanged. Host numbers only; `PointProbe` and traced probes are returned as given.

    Default optics, 0.01: a pulsed probe needs 11 nodes for an 8 m field, 17 for 4 m, 29 for
    2 m beyond 49 m; a CW probe needs more the farther it looks, since its Lorentzian
    widens as the focus range squared (see `lidarjax.probe` for the table).
    """
    return _refine_probe(probe, spacing, ranges, tol, max_nodes)[0]


def _check_ranges(ranges) -> tuple[float, ...]:
    r = np.asarray(ranges, np.float64).reshape(-1)
    r = np.unique(np.round(r[np.isfinite(r) & (r > 0)], 6))
    if r.size > 16:
        r = np.unique(np.quantile(r, np.linspace(0.0, 1.0, 16)))
    return tuple(float(v) for v in r)


def _refine_probe(probe, spacing, ranges, tol=TRANSFER_TOL, max_nodes=MAX_NODES):
    """`probe_for_spacing`, plus the largest ``|W_q - W|`` of the probe returned (0 when
    nothing was checked) and `tol`."""
    if isinstance(probe, PointProbe) or not hasattr(probe, "_with_rule"):
        return probe, 0.0, tol
    if spacing is None or not is_concrete(probe, spacing, ranges):
        return probe, 0.0, tol
    dx = float(np.min(np.asarray(spacing, np.float64)))
    check = _check_ranges(ranges)
    if not (np.isfinite(dx) and dx > 0) or not check:
        return probe, 0.0, tol
    n, err = _choose_nodes(_probe_key(probe), dx, check, float(tol), int(max_nodes))
    return probe._with_rule(n, dx, auto=getattr(probe, "auto_nodes", False)), err, tol


def _probe_key(probe):
    """Hashable description of the weighting (host numbers)."""
    if isinstance(probe, PulsedProbe):
        return ("pulsed", float(probe.pulse_fwhm), float(probe.gate_length), float(probe.tail))
    return ("cw", float(probe.wavelength), float(probe.aperture_radius), float(probe.tail))


def _probe_from_key(key, n, dx):
    if key[0] == "pulsed":
        return PulsedProbe(key[1], key[2], n_nodes=n, tail=key[3])
    return CWProbe(key[1], key[2], n_nodes=n, tail=key[3], resolution=dx)


@functools.lru_cache(maxsize=256)
def _choose_nodes(key, dx, check, tol, max_nodes) -> tuple[int, float]:
    """Fewest odd node count within `tol` (doubling, then bisection), and its error."""
    kappa = np.linspace(0.0, np.pi / dx, 513)
    exact = [probe_transfer(_probe_from_key(key, 3, dx), kappa, r, model="truncated") for r in check]

    def error(n):
        p = _probe_from_key(key, n, dx)
        return max(float(np.max(np.abs(probe_transfer(p, kappa, r, model="nodes") - ex)))
                   for r, ex in zip(check, exact, strict=True))

    lo, hi = 1, 3  # lo fails (or is below the search), hi is tried next
    max_nodes = max(3, max_nodes - (1 - max_nodes % 2))  # odd
    while True:
        e = error(hi)
        if e <= tol:
            break
        if hi >= max_nodes:
            return hi, e
        lo, hi = hi, min(2 * hi + 1, max_nodes)
    best, best_err = hi, e
    while hi - lo > 2:
        mid = lo + 2 * ((hi - lo) // 4)  # odd, strictly between
        mid = mid if mid % 2 else mid + 1
        if not lo < mid < hi:
            break
        e = error(mid)
        if e <= tol:
            hi, best, best_err = mid, mid, e
        else:
            lo = mid
    return best, best_err


def probe_for_ranges(probe: AbstractProbe, resolution, ranges, *, caller: str = "probe_for_ranges",
                     tol: float = TRANSFER_TOL):
    """The probe a field of `resolution` (field length units; ``None``: it states none) is
    sampled with at focus `ranges`: `probe` refined by `probe_for_spacing` when its node
    count is automatic (built with ``n_nodes=None``), as given otherwise (an explicit count
    wins, and so do the point probe and traced inputs). `tol`: the largest ``|W_q - W|``
    accepted (`TRANSFER_TOL`). Warns (naming `caller`) when no node count up to
    `MAX_NODES` reaches the tolerance."""
    if isinstance(probe, PointProbe) or not getattr(probe, "auto_nodes", False) or resolution is None:
        return probe
    refined, err, tol = _refine_probe(probe, resolution, ranges, tol)
    if err > tol:
        warnings.warn(
            f"{caller}: {type(probe).__name__} cannot integrate its weighting over the field's "
            f"{float(resolution):g} m resolution at focus ranges up to {np.max(ranges):.0f} m (its "
            f"node rule's transfer is off by up to {err:.3f} below the field's Nyquist wavenumber "
            f"even with {refined.n_nodes} nodes). Give a coarser resolution or an explicit "
            f"n_nodes.", stacklevel=3)
    return refined


def host_nodes(probe: AbstractProbe, focus_range) -> tuple[np.ndarray, np.ndarray]:
    """The quadrature of `probe` on the host (float64 numpy, concrete numbers): ``(offsets,
    weights)`` ``(..., q)`` for focus ranges ``(...)``, as `AbstractProbe.nodes` computes
    them in the working dtype. `PulsedProbe` and `CWProbe`."""
    if not hasattr(probe, "_host_nodes"):
        raise ValueError(f"host_nodes: no host form for {type(probe).__name__}.")
    return probe._host_nodes(np.asarray(focus_range, np.float64))


def host_weighting(probe: AbstractProbe, offsets, focus_range) -> tuple[np.ndarray, np.ndarray]:
    """The weighting of `probe` on the host (float64 numpy, concrete numbers): its density
    ``phi`` (1 / length) at `offsets` from the focus (``(..., n)``, length units) for focus
    ranges ``(...)``, and the half-width of its truncated support cut at the lidar,
    ``min(support, focus_range)`` ``(...)``. `PulsedProbe` and `CWProbe`."""
    r = np.asarray(focus_range, np.float64)
    o = np.asarray(offsets, np.float64)
    if isinstance(probe, PulsedProbe):
        rp, dp = probe._host_rp_gate()
        half = np.minimum(dp / 2 + float(probe.truncation) * rp, r)
        return _pulsed_weight(special.erf, o, rp, dp), half
    if isinstance(probe, CWProbe):
        lam, a = float(probe.wavelength), float(probe.aperture_radius)
        g = (lam * r**2 / (np.pi * a**2))[..., None]
        return g / (np.pi * (o**2 + g**2)), r
    raise ValueError(f"host_weighting: no host form for {type(probe).__name__}.")


def _cut_lorentzian_transfer(g, r, kappa):
    """Transfer function of the Lorentzian of half width `g` cut to ``|o| < r`` and
    renormalised, in closed form: ``[exp(-g k) - (2 g / pi) Re J] / P`` with ``J = int_r^inf
    exp(i k o) / (o^2 + g^2) do`` from exponential integrals ``E1`` of complex argument and
    ``P = (2/pi) atan(r / g)``."""
    k = np.abs(np.asarray(kappa, np.float64))
    out = np.ones_like(k)
    pos = k > 0
    kk = k[pos]
    # int_r^inf exp(i k o) / (o - c) do = exp(i k c) E1(z), z = -i k (r - c), written as
    # exp(i k r) * [exp(z) E1(z)] so that no factor overflows for large k g
    term = lambda c: np.exp(1j * kk * r) * _scaled_exp1(-1j * kk * (r - c))  # noqa: E731
    j = (term(1j * g) - term(-1j * g)) / (2j * g)
    kept = (2 / np.pi) * np.arctan(r / g)
    out[pos] = (np.exp(-g * kk) - (2 * g / np.pi) * j.real) / kept
    return out


def _scaled_exp1(z):
    """``exp(z) E1(z)`` for complex `z` off the negative real axis: directly for ``|z| <=
    30``, by the asymptotic series ``(1/z) sum_n (-1)^n n! / z^n`` (25 terms, relative error
    below 1e-12) beyond."""
    z = np.asarray(z, np.complex128)
    out = np.empty_like(z)
    near = np.abs(z) <= 30.0
    out[near] = np.exp(z[near]) * special.exp1(z[near])
    zf = z[~near]
    term = np.ones_like(zf)
    total = np.ones_like(zf)
    for n in range(1, 26):
        term = -term * n / zf
        total = total + term
    out[~near] = total / zf
    return out


def probe_transfer(probe, kappa, focus_range, *, model: str = "weight"):
    """Fourier transform ``W(kappa) = int phi(o) exp(i kappa o) do`` of a probe's range
    weighting along the beam (real: the weightings are even), at wavenumbers `kappa` (rad/m,
    the wavevector's component along the beam) and focus range `focus_range` (m).

    `model`:

    - ``"weight"``: the whole weighting, in closed form. `lidarjax.PulsedProbe`: a Gaussian
      pulse of ``rp = fwhm / (2 sqrt(ln 2))`` convolved with the gate ``Dp``: ``exp(-kappa^2
      rp^2 / 4) sinc(kappa Dp / 2)``. `lidarjax.CWProbe`: the Lorentzian of half width
      ``G``: ``exp(-G |kappa|)``. `lidarjax.PointProbe`: 1.
    - ``"truncated"``: the weighting the simulator integrates: truncated to the probe's
      support (pulsed: by `tail`), cut at the lidar (``|o| < focus_range``) and renormalised.
      For the CW probe in closed form (exponential integrals); for the pulsed probe by dense
      quadrature.
    - ``"nodes"``: exactly what the simulator computes, ``sum_q w_q cos(kappa o_q)`` over
      the probe's quadrature nodes kept by the cut at the lidar, renormalised.
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
        if isinstance(probe, CWProbe):
            lam, a = float(probe.wavelength), float(probe.aperture_radius)
            return _cut_lorentzian_transfer(lam * r**2 / (np.pi * a**2), r, kappa)
        x, w = _legendre(1000)
        half = min(float(np.asarray(probe.support(r))), r)
        o = half * x
        phi = np.asarray(probe.weight(o, r), dtype=np.float64) * w
        phi = phi / phi.sum()
        flat = kappa.reshape(-1)
        out = np.concatenate([np.cos(np.multiply.outer(flat[i:i + 20000], o)) @ phi
                              for i in range(0, max(flat.size, 1), 20000)])
        return out[:flat.size].reshape(kappa.shape)
    if model == "nodes":
        if hasattr(probe, "_host_nodes"):
            offsets, weights = probe._host_nodes(np.asarray(r))
        else:
            offsets, weights = _nodes(probe, np.asarray(r))
        o = np.asarray(offsets, np.float64).reshape(-1)
        wq = np.broadcast_to(np.asarray(weights, np.float64).reshape(-1), o.shape)
        wq = np.where(np.abs(o) < r, wq, 0.0)  # the simulator's cut at the lidar
        if not wq.sum() > 0:
            return np.ones_like(kappa)  # nothing kept: the focus itself
        wq = wq / wq.sum()
        return np.cos(np.multiply.outer(kappa, o)) @ wq
    raise ValueError(f"probe_transfer: model must be 'weight', 'truncated' or 'nodes', got {model!r}.")


@functools.lru_cache(maxsize=4)
def _legendre(n):
    return special.roots_legendre(n)


@eqx.filter_jit
def _nodes(probe, r):
    return probe.nodes(jnp.asarray(r))
