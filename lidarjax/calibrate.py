"""Installation calibration: constant north offset and tilt estimated from many records.

A lidar whose beams are turned and tilted by offsets ``theta = (d_epsilon, d_pitch,
d_roll)`` (degrees) from the installation its response table assumed
(`ResponseTable.instrument`, 0 when unknown) points beam ``b`` along ``n_b' = M(theta) n_b``
instead of the table's ``n_b`` (north frame), with

``M = Rz(-(e0 + d_epsilon)) T(p0 + d_pitch, r0 + d_roll) T(p0, r0)^T Rz(e0)``

(``T`` the tilt of `lidarjax.tilt_rotation`, ``Rz`` `lidarjax.frames.rotation_z`,
``e0, p0, r0`` the table's installation): the tilt offsets change the instrument's tilt,
and a north offset turns the instrument about the vertical so that every beam's bearing
grows by ``d_epsilon`` (`lidarjax.frames`: ``v_north = R(-epsilon) v_lidar``). Turning a
beam does two things, both first order in the offset:

1. it projects the flow on another direction: ``(n_b' - n_b) . V_hb``;
2. it moves the measurement point (each node of the probe volume, at range ``r_k``, by
   ``r_k (n_b' - n_b)``: up to 1.7 m at 136 m range for 0.7 degrees), where the flow differs
   by ``G_hb r_k (n_b' - n_b)``. Relative to term 1 this is of order ``r |grad V| / U``:
   0.1-0.15 over a ridge, about ``alpha tan(cone)`` (0.07) in power-law shear over flat
   ground. It is **not** negligible: leaving it out biased roll by two standard errors over
   a ridge (issue 29).

For a free stream of speed ``U`` from the meteorological direction ``d``, the model is

``los_hb = U * [R_hb(d) + (n_b' - n_b) . S_hb(d)]``,  ``S_hb = V_hb + rho_hb G_hb^T n_b'``

- ``R_hb``: the table's LOS response (per unit free-stream speed) at ``d``;
- ``V_hb``: the flow at the beam points per unit free-stream speed: the table's
  `beam_velocity`, else its centre-line `point` velocity, else the undisturbed horizontal
  free stream;
- ``G_hb``: the table's `beam_gradient` (`lidarjax.beam_gradient`: the velocity gradient
  weighted over the probe volume, each node by its range over the focus range ``rho_hb``;
  the focus ranges are the table's heights over the cosines of the beams in the body frame
  of its installation). Without it term 2 is left out, `calibrate` warns once and says so
  in `Calibration.notes` (rebuild the table with ``fields=`` or ``lidarjax table``).

**Order of the model.** The beams turn exactly (``M`` is the exact rotation); the
displacement enters through the gradient, at first order, with ``S`` taken along the beams
as turned by the current estimate (relinearised every pass, its change with the offsets in
the Jacobian), which also includes the displacement's cross term
``(n_b' - n_b) . G (r (n_b' - n_b))``. What is left
out is the flow's curvature over the displacement, ``(r |n' - n|)^2 |grad grad V| / 2``: of
second order in the offsets, about 1e-4 of the tilt's effect for 2 degrees over a ridge of
200 m half width, and a few 1e-3 for north offsets of 10 degrees; next to a body (the
hemisphere platform's roof) a tenth to a half of a standard error of a 400-record campaign.

**Iterating on the exact geometry.** Given the table's CFD runs (``runs=``, a
`lidarjax.TableRuns`), `calibrate` removes that error: after a fit it builds the table again
for the instrument at the estimate (`TableRuns.table`: `lidarjax.simulate` of every run with
the beams turned and tilted, so every measurement point is where the estimate puts it) and
fits the offsets left, which are small, so the linearisation's error falls quadratically;
it stops once a fit moves no reported offset by more than `REFINE_SHARE` of its standard
error (at most `refinements` rebuilds; usually two). Without a reference, the nuisance turn
(below) is built into the geometry once, from the first fit, and kept to first order about
it afterwards: fed back, its flat direction makes the rebuilds cycle.

With ``north_offset="site"`` (the flow turns with the instrument, as the distortion of a
platform that carries it) the north offset is a shift of the direction labels instead,
``R_hb(d - d_epsilon)``, ``S_hb(d - d_epsilon)``, and ``M`` keeps ``Rz(-e0)``.

`calibrate` finds the offsets (any subset of ``("epsilon", "pitch", "roll")``, degrees) that
minimise the sum of squared LOS residuals over all records and heights, jointly with every
record-height's own free stream (the nuisances: ``(u, v)`` without a reference, the speed
``U`` with a reference direction). The Jacobian of the model gives Gauss--Newton steps in
which each record-height's nuisances are eliminated exactly (Schur complement: the reduced
gradient is the gradient through the per-record inversion, by the implicit function
theorem), so a year of records costs a few passes over the data.

**What is identifiable.**

- *With a reference* (free-stream speed and direction at the same heights from a mast,
  another lidar or a model): epsilon (the mean rotation between the inverted and reference
  directions, weighted by the table's sensitivity), pitch and roll.
- *Without a reference*: pitch and roll, from the vertical beam and from how the apparent
  vertical wind (and the slanted beams' sum) varies with direction: a tilt turns the
  horizontal wind into an apparent vertical wind that follows the wind direction, while the
  true mean ``w`` of the table does not. It needs records from several directions.
  **Epsilon is not identifiable without a reference**: turning every direction by the same
  angle fits the records almost as well. `calibrate` then returns NaN for it,
  ``identifiable = False`` and says so in `notes`. Where the flow varies in space an unknown
  turn still moves the measurement points; with ``north_offset="instrument"`` and a table
  with `beam_gradient` that displacement is fitted as a nuisance (the turn itself is taken
  up by the records' directions; a ridge of `RIDGE` holds it where the records cannot tell
  it), so that it does not go into the tilt, whose standard errors are then marginal
  over it.

**Uncertainty.** ``cov = H^-1 B H^-1`` (the sandwich, `covariance="robust"`, default) with
``H`` the reduced Gauss--Newton matrix and ``B`` the sum over records of the outer products
of each record's reduced gradient (so noise correlated between the beams and heights of one
record, and noise that varies between records, are accounted for), scaled by
``n / (n - k)``; or ``sigma**2 H^-1`` (`covariance="model"`) with ``sigma`` estimated from
the residuals. 95 % intervals are ``offset +- 1.96 std``.

The code follows the steps of the computation: `_checked` (arguments, before computing),
then per table `_fit_table`: `_flattened` (records to record-height problems), `_model_of`
(the table as a `_CalibrationModel`), `_solve` (the compiled Gauss--Newton passes) and
`_covariance`; `calibrate` itself rebuilds the table at the estimate when given its runs,
and `_result` makes the `Calibration`.

Angles in degrees, north frame, meteorological directions (from, clockwise from north).
"""

from __future__ import annotations

import math
import warnings
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from ._precision import HIGHEST, is_concrete
from .flags import InverseFlag
from .frames import rotation_z, tilt_rotation
from .response import (
    ProfileTable,
    ResponseTable,
    TableRuns,
    _spline_coefficients,
    spline_at,
    tabulated_start,
)

__all__ = ["Calibration", "calibrate", "CALIBRATION_PARAMETERS"]

#: The installation offsets `calibrate` can estimate, in this order.
CALIBRATION_PARAMETERS = ("epsilon", "pitch", "roll")

#: Largest change of (epsilon, pitch, roll) per Gauss--Newton pass, degrees (a trust region).
_MAX_STEP = np.array([5.0, 1.0, 1.0])

#: Gauss--Newton stops, converged, once no reported offset moved in a pass by more than
#: this share of its standard error (``sigma sqrt((H^-1)_ii)``, the model's), or by less
#: than `TOLERANCE` degrees. The same rule, with `REFINE_SHARE`, ends the rebuilds of the
#: table at the estimate.
STEP_SHARE = 1e-2

#: Steps below this many degrees count as converged whatever the standard errors.
TOLERANCE = 1e-7

#: With the table's runs (`calibrate(runs=...)`), the table is built again at the estimate
#: until a rebuild moves no reported offset by more than this share of its standard error.
REFINE_SHARE = 0.01

#: Most rebuilds of the table at the estimate (`calibrate`'s `refinements`), by default.
REFINEMENTS = 3

#: A free offset is identifiable when the normalised reduced matrix's smallest eigenvalue
#: along it exceeds this fraction of the largest (offsets correlated beyond 0.9999 are not).
IDENTIFIABILITY_RCOND = 1e-4

#: The ridge that holds a nuisance offset (epsilon without a reference) where the records
#: cannot tell it, relative to the largest diagonal entry of the reduced matrix.
RIDGE = 1e-6

_NOT_IDENTIFIABLE_EPSILON = (
    "epsilon (north offset) is not identifiable without a reference: rotating every "
    "direction by one angle fits the records equally well; give reference=(speed, direction) "
    "from a mast, another lidar or a model")

_EPSILON_AS_NUISANCE = (
    "without a reference the north offset is kept as a nuisance: the displacement of the "
    "measurement points by an unknown turn is fitted (the turn itself is taken up by the "
    "records' directions), and the tilt's standard errors are marginal over it")

_NO_GRADIENT = (
    "the table has no beam_gradient: how the offsets move the measurement points is left "
    "out (an error of order r |grad V| / U of the offsets, 0.1 over a ridge); rebuild the "
    "table with ResponseTable.from_simulations(fields=...) or lidarjax table")


class Calibration(eqx.Module):
    """Result of `calibrate`; arrays ``(k,)`` follow `names`.

    - `names`: the estimated offsets, a subset of ``("epsilon", "pitch", "roll")``.
    - `offset`: the offset from the table's installation, degrees (NaN where not
      identifiable); `value`: the installation it implies, ``nominal + offset``.
    - `nominal`: the table's installation (`ResponseTable.instrument`; 0 where unknown).
    - `std`: one-sigma standard errors, degrees; `covariance` ``(k, k)``, deg^2;
      `correlation` ``(k, k)``.
    - `identifiable`: bool per offset.
    - `header`: the record header's value (degrees) where the records state one (pitch and
      roll of a Windcube ``.rtd``/``.sta``), else NaN.
    - `noise`: RMS LOS residual per beam, m/s; `n_records`, `n_problems`: records and
      record-heights used.
    - `flags`: `InverseFlag` bits: ``NOT_CONVERGED`` (the offsets still moved by more than
      `STEP_SHARE` of their standard errors (and `TOLERANCE` degrees) in the last pass, or a
      number is not finite, or with `runs` the
      last rebuild of the table still moved them by more than `REFINE_SHARE` of their
      standard errors),
      ``ILL_CONDITIONED`` (an asked-for offset is not identifiable); `converged` reads it.
    - `num_steps`: Gauss--Newton passes taken (in the last fit); `last_step`: the largest
      change of an offset in the last pass, degrees.
    - `rebuilds`: how often the table was built again at the estimate (`calibrate`'s
      `runs`; 0 without).
    - `notes`: what the records could not tell, and the model's order, in words.
    """

    names: tuple[str, ...] = eqx.field(static=True)
    offset: Float[Array, " k"]
    value: Float[Array, " k"]
    nominal: Float[Array, " k"]
    std: Float[Array, " k"]
    covariance: Float[Array, "k k"]
    correlation: Float[Array, "k k"]
    identifiable: Bool[Array, " k"]
    header: Float[Array, " k"]
    noise: Float[Array, ""]
    n_records: Int[Array, ""]
    n_problems: Int[Array, ""]
    flags: Int[Array, ""]
    num_steps: Int[Array, ""]
    last_step: Float[Array, ""]
    rebuilds: Int[Array, ""]
    notes: tuple[str, ...] = eqx.field(static=True)

    @property
    def converged(self) -> bool:
        """No ``NOT_CONVERGED`` bit in `flags`."""
        return not int(self.flags) & int(InverseFlag.NOT_CONVERGED)

    def summary(self) -> list[str]:
        """One line per offset: estimate, standard error, 95 % interval, header value."""
        lines = []
        for i, name in enumerate(self.names):
            off, sd = float(self.offset[i]), float(self.std[i])
            if not bool(self.identifiable[i]) or not math.isfinite(off):
                lines.append(f"{name}: not identifiable from these records")
                continue
            hv = float(self.header[i])
            head = f"; header {hv:.3f} deg" if math.isfinite(hv) else ""
            lines.append(f"{name}: {'(not converged) ' if not self.converged else ''}"
                         f"{float(self.value[i]):.3f} deg (offset {off:+.3f} +- "
                         f"{sd:.3f} deg from the table's {float(self.nominal[i]):.3f}; 95 % "
                         f"[{off - 1.96 * sd:+.3f}, {off + 1.96 * sd:+.3f}]){head}")
        return lines + list(self.notes)


# ------------------------------------------------------------------------------------------
# the model of one record-height


class _CalibrationModel(eqx.Module):
    """The table as `calibrate`'s model needs it (north frame, per unit free-stream speed).

    - `geom`: the direction splines' knots ``(start, offsets, widths, uniform)``;
    - `response`: ``(4, s, h, b)`` coefficients of the LOS response ``R``;
    - `velocity`: ``(4, s, h, b, 3)`` coefficients of the flow at the beam points ``V``;
    - `gradient`: ``(4, s, h, b, 3, 3)`` coefficients of ``rho G`` (the beam gradient
      times the focus range), or None;
    - `beams`: ``(b, 3)`` the table's beam unit vectors ``n``;
    - `nominal`: ``(3,)`` the table's installation ``(e0, p0, r0)``, degrees;
    - `values`, `knots`: the tabulated response ``(s, h, b)`` and directions (the start).
    """

    geom: tuple
    response: Float[Array, "4 s h b"]
    velocity: Float[Array, "4 s h b 3"]
    gradient: Float[Array, "4 s h b 3 3"] | None
    beams: Float[Array, "b 3"]
    nominal: Float[Array, " 3"]
    values: Float[Array, "s h b"]
    knots: Float[Array, " s"]
    turn_beams: bool = eqx.field(static=True)

    def turn(self, theta: Float[Array, " 3"]) -> Float[Array, "3 3"]:
        """``M(theta)``: the table's beams to the turned and tilted ones (north frame); the
        north offset turns them only with ``north_offset="instrument"``."""
        e0, p0, r0 = self.nominal[0], self.nominal[1], self.nominal[2]
        t_new = tilt_rotation(p0 + theta[1], r0 + theta[2])
        t_old = tilt_rotation(p0, r0)
        de = theta[0] if self.turn_beams else jnp.zeros_like(theta[0])
        return rotation_z(-(e0 + de)) @ t_new @ t_old.T @ rotation_z(e0)

    def sensitivity(self, theta: Float[Array, " 3"]) -> Float[Array, "4 s h b 3"]:
        """Coefficients of ``S = V + rho G^T n'`` with the beams ``n'`` turned by `theta`:
        the first-order change of the LOS per change of beam direction (linear in the
        tabulated values, so the spline of ``S`` is this sum of splines)."""
        if self.gradient is None:
            return self.velocity
        turned = self.beams @ self.turn(theta).T  # (b, 3)
        return self.velocity + jnp.einsum("cshbij,bi->cshbj", self.gradient, turned,
                                          precision=HIGHEST)


def _model_and_jacobian(model: _CalibrationModel, nuisance, theta, ref_dir, hidx):
    """LOS ``(n, b)`` of every record-height per the module's model and its Jacobians: in
    the `nuisance` ``(n, m)`` (``(u, v)`` m/s, or the speed with a reference direction)
    -> ``(n, b, m)``, and in the offsets `theta` ``(3,)`` degrees -> ``(n, b, 3)``, with
    ``S`` (`_CalibrationModel.sensitivity`) taken at `theta` and differentiated with it."""
    dtype = nuisance.dtype
    # the beams' change by the offsets and its derivatives, once for all problems
    change = lambda th: model.beams @ (  # noqa: E731  (b, 3)
        model.turn(th) - jnp.eye(3, dtype=dtype)).T
    dn = change(theta)
    ddn = jax.jacfwd(change)(theta)  # (b, 3, 3[theta])
    if nuisance.shape[1] == 2:
        u, v = nuisance[:, 0], nuisance[:, 1]
        h2 = u * u + v * v
        pos = h2 > 0
        safe = jnp.where(pos, h2, 1.0)
        speed = jnp.where(pos, jnp.sqrt(safe), 0.0)
        d = jnp.rad2deg(jnp.arctan2(jnp.where(pos, -u, 0.0), jnp.where(pos, -v, 1.0)))
    else:
        speed, d = nuisance[:, 0], ref_dir
    # the direction the table sees: shifted by the north offset when the flow turns with
    # the instrument (north_offset="site")
    dl = d if model.turn_beams else d - theta[0]
    # the beams' changes are the same for every problem: contracted with S on the table's
    # coefficients (the splines are linear in them), so each problem evaluates one spline
    # with its slope, ``R + dn . S``, and one without, ``(d dn / d theta) . S``
    sens = model.sensitivity(theta)
    f_c = model.response + jnp.einsum("cshbk,bk->cshb", sens, dn, precision=HIGHEST)
    p_c = jnp.einsum("cshbk,bkt->cshbt", sens, ddn, precision=HIGHEST)
    if model.gradient is not None:  # S turns with the beams: d S_j = rho G_ij d n_i
        p_c = p_c + jnp.einsum("cshbij,bit,bj->cshbt", model.gradient, ddn, dn,
                               precision=HIGHEST)
    f, df = spline_at(model.geom, f_c, dl, (hidx,), slope=True)  # (n, b) per unit speed
    los = speed[:, None] * f
    j_theta = speed[:, None, None] * spline_at(model.geom, p_c, dl, (hidx,))  # (n, b, 3)
    if not model.turn_beams:
        j_theta = jnp.concatenate([-speed[:, None, None] * df[..., None], j_theta[..., 1:]],
                                  -1)
    if nuisance.shape[1] == 2:
        deg = 180.0 / np.pi
        su = jnp.where(pos, u / jnp.where(pos, speed, 1.0), 0.0)
        sv = jnp.where(pos, v / jnp.where(pos, speed, 1.0), 0.0)
        du = jnp.where(pos, v / safe, 0.0) * deg  # d(direction)/du, degrees per m/s
        dv = jnp.where(pos, -u / safe, 0.0) * deg
        j_nuisance = jnp.stack([su[:, None] * f + speed[:, None] * df * du[:, None],
                                sv[:, None] * f + speed[:, None] * df * dv[:, None]], -1)
    else:
        j_nuisance = f[..., None]
    return los, j_nuisance.astype(dtype), j_theta.astype(dtype)


def _small_inv(a):
    """Inverse of ``(n, m, m)`` SPD blocks (m = 1 or 2) and whether each is well posed."""
    m = a.shape[-1]
    if m == 1:
        ok = a[:, 0, 0] > 0
        return jnp.where(ok, 1.0 / jnp.where(ok, a[:, 0, 0], 1.0), 0.0)[:, None, None], ok
    det = a[:, 0, 0] * a[:, 1, 1] - a[:, 0, 1] * a[:, 1, 0]
    tr = a[:, 0, 0] + a[:, 1, 1]
    ok = det > 1e-10 * tr * tr
    sd = jnp.where(ok, det, 1.0)
    inv = jnp.stack([jnp.stack([a[:, 1, 1], -a[:, 0, 1]], -1),
                     jnp.stack([-a[:, 1, 0], a[:, 0, 0]], -1)], -2) / sd[:, None, None]
    return jnp.where(ok[:, None, None], inv, 0.0), ok


# ------------------------------------------------------------------------------------------
# the solve


class _Problems(eqx.Module):
    """The records flattened to record-height problems: `los`, `weights` ``(n, b)``
    (unusable beams: weight 0, LOS 0), `ref_dir` ``(n,)`` (degrees; 0 without a reference),
    `height` and `record` indices ``(n,)``."""

    los: Float[Array, "n b"]
    weights: Float[Array, "n b"]
    ref_dir: Float[Array, " n"]
    height: Int[Array, " n"]
    record: Int[Array, " n"]


class _Solution(eqx.Module):
    """What `_solve` returns: the offsets ``(3,)``, the reduced matrix `hessian` and the
    sandwich's `meat` ``(3, 3)``, the weighted residual sum of squares, the observations
    and problems used, and the passes' statistics."""

    theta: Float[Array, " 3"]
    hessian: Float[Array, "3 3"]
    meat: Float[Array, "3 3"]
    wrss: Float[Array, ""]
    n_obs: Int[Array, ""]
    n_ok: Int[Array, ""]
    n_used: Int[Array, ""]
    n_records: Int[Array, ""]
    num_steps: Int[Array, ""]
    last_step: Float[Array, ""]
    converged: Bool[Array, ""]


def _start(model: _CalibrationModel, problems: _Problems, with_ref: bool):
    """Each problem's starting nuisance: the best tabulated direction's closed-form speed as
    ``(u, v)``, or with a reference the closed-form speed at the reference direction."""
    w, los = problems.weights, problems.los
    if with_ref:
        resp = spline_at(model.geom, model.response, problems.ref_dir, (problems.height,))
        num = jnp.sum(w * los * resp, -1)
        den = jnp.sum(w * resp * resp, -1)
        return jnp.where(den > 0, num / jnp.where(den > 0, den, 1.0), 0.0)[:, None]
    s, h, b = model.values.shape
    k, u0 = tabulated_start(w.reshape(-1, h, b), los.reshape(-1, h, b), model.values,
                            "rhb,shb->rhs", 2)
    d0 = jnp.deg2rad(model.knots[k.reshape(-1)])
    u0 = u0.reshape(-1)
    return jnp.stack([-u0 * jnp.sin(d0), -u0 * jnp.cos(d0)], -1)


def _reduced_pieces(model: _CalibrationModel, problems: _Problems, freef, nuisance, theta):
    """Each problem's residuals and its Schur-complement pieces at ``(nuisance, theta)``: the
    reduced matrix `h_i` and gradient `s_i` over the offsets, the nuisance block's inverse
    `ainv`, its gradient `gn`, the cross block `c` and whether the block is well posed."""
    dtype = problems.los.dtype
    w = problems.weights
    los, jn, jt = _model_and_jacobian(model, nuisance, theta, problems.ref_dir,
                                      problems.height)
    resid = problems.los - los
    jt = jt * freef
    a = jnp.einsum("nb,nbi,nbj->nij", w, jn, jn, precision=HIGHEST)
    gn = jnp.einsum("nb,nbi,nb->ni", w, jn, resid, precision=HIGHEST)
    c = jnp.einsum("nb,nbi,nbj->nij", w, jn, jt, precision=HIGHEST)
    ainv, ok = _small_inv(a)
    okf = ok.astype(dtype)
    tt = jnp.einsum("nb,nbi,nbj->nij", w, jt, jt, precision=HIGHEST)
    gt = jnp.einsum("nb,nbi,nb->ni", w, jt, resid, precision=HIGHEST)
    ca = jnp.einsum("nki,nkl->nil", c, ainv, precision=HIGHEST)  # C^T A^-1 (n, 3, m)
    h_i = (tt - jnp.einsum("nil,nlj->nij", ca, c, precision=HIGHEST)) * okf[:, None, None]
    s_i = (gt - jnp.einsum("nil,nl->ni", ca, gn, precision=HIGHEST)) * okf[:, None]
    return resid, h_i, s_i, ainv, gn, c, ok


@eqx.filter_jit  # traced once: for the loop's shapes (eval_shape) and in the loop
def _evaluate(model, problems, freef, n_records, nuisance, theta, it):
    """The statistics at a point (`_Solution`) and what its step needs."""
    w = problems.weights
    resid, h_i, s_i, ainv, gn, c, ok = _reduced_pieces(model, problems, freef, nuisance, theta)
    hmat = jnp.sum(h_i, 0)
    # the sandwich's meat: per record, the sum of its problems' reduced gradients
    s_rec = jax.ops.segment_sum(s_i, problems.record, num_segments=n_records)
    sol = _Solution(
        theta=theta, hessian=hmat,
        meat=jnp.einsum("ri,rj->ij", s_rec, s_rec, precision=HIGHEST),
        wrss=jnp.sum(w * resid * resid * ok[:, None]),
        n_obs=jnp.sum((w > 0) & ok[:, None]), n_ok=jnp.sum(ok),
        n_used=jnp.sum(jnp.any(w > 0, -1) & ok),
        n_records=jnp.sum(jax.ops.segment_max(jnp.any(w > 0, -1), problems.record,
                                              num_segments=n_records)),
        num_steps=it, last_step=jnp.zeros((), problems.los.dtype),
        converged=jnp.asarray(False))
    return sol, (jnp.sum(s_i, 0), ainv, gn, c, ok)


def _offset_step(sol, g, theta, freef, weakf, anchor):
    """The Gauss--Newton step of the offsets from the reduced system (the weak offsets held
    near `anchor` by the ridge), clipped to the trust region, with the ridge and how far
    the step moves the reported offsets (in units of the larger of `TOLERANCE` and
    `STEP_SHARE` standard errors, and in degrees)."""
    dtype = theta.dtype
    hmat = sol.hessian
    ridge = weakf * (RIDGE * jnp.max(jnp.diagonal(hmat) * freef))
    hm = (hmat * freef[:, None] * freef[None, :] + jnp.eye(3, dtype=dtype) * (1.0 - freef)[:, None]
          + jnp.diag(ridge))
    g = g - ridge * (theta - anchor)
    # a trust region: at most 5 degrees of north offset and 1 degree of tilt per pass
    limit = jnp.asarray(_MAX_STEP, dtype)
    dtheta = jnp.clip(jnp.linalg.solve(hm, g * freef), -limit, limit)
    # convergence is judged on the offsets reported: a nuisance offset (epsilon without
    # a reference) that the records hardly tell creeps on for passes while moving the
    # reported ones by far less than their rounding
    sd = jnp.sqrt(sol.wrss / jnp.maximum(sol.n_obs, 1)
                  * jnp.abs(jnp.diagonal(jnp.linalg.inv(hm))))
    scale = jnp.maximum(STEP_SHARE * jnp.where(jnp.isfinite(sd), sd, 0.0), TOLERANCE)
    moved = jnp.max(jnp.abs(dtheta) / scale * freef * (1.0 - weakf))
    moved_deg = jnp.max(jnp.abs(dtheta) * freef * (1.0 - weakf))
    return dtheta, ridge, (moved, moved_deg)


def _solve_pass(model, problems, freef, weakf, anchor, n_records, carry):
    """One pass: the statistics of the point it is at, then the step (halved back towards
    the last point accepted when it made the objective worse)."""
    it, nuisance, theta, _, sol_kept, kept = carry
    nuis_k, theta_k, wrss_k = kept  # the last point accepted
    sol, (g, ainv, gn, c, ok) = _evaluate(model, problems, freef, n_records, nuisance, theta,
                                          it)
    dtheta, ridge, moved = _offset_step(sol, g, theta, freef, weakf, anchor)
    dnuis = jnp.einsum("nij,nj->ni", ainv, gn - jnp.einsum("nij,j->ni", c, dtheta))
    dnuis = jnp.where(ok[:, None], dnuis, 0.0)
    # a step that made the objective (with the nuisance offset's ridge) worse is halved
    # back towards the last point accepted: a nuisance offset the records hardly tell
    # can make the Gauss--Newton steps overshoot and cycle
    penalty = lambda th: jnp.sum(ridge * (th - anchor) ** 2)  # noqa: E731
    obj, obj_k = sol.wrss + penalty(theta), wrss_k + penalty(theta_k)
    worse = (it > 0) & (obj > obj_k + 1e-10 * jnp.abs(obj_k))
    pick = lambda bad, good: jax.tree_util.tree_map(  # noqa: E731
        lambda x, y: jnp.where(worse, x, y), bad, good)
    inf = jnp.asarray(jnp.inf, theta.dtype)
    nxt_nuis, nxt_theta, last, sol_out, kept_out = pick(
        (0.5 * (nuis_k + nuisance), 0.5 * (theta_k + theta), (inf, inf), sol_kept, kept),
        (nuisance + dnuis, theta + dtheta, moved, sol, (nuisance, theta, sol.wrss)))
    return it + 1, nxt_nuis, nxt_theta, last, sol_out, kept_out


@eqx.filter_jit
def _solve(model: _CalibrationModel, problems: _Problems, free, weak, anchor, theta0,
           max_passes, n_records, with_ref):
    """Schur-complement Gauss--Newton over the offsets (mask `free` of 3) and every
    problem's nuisances, `S` relinearised at every pass; see the module docstring. The
    offsets in `weak` (a subset of `free`) are held near `anchor` (``(3,)`` degrees: 0, or
    the first table's installation when the table was built again at an estimate) by a
    ridge of `RIDGE` times the largest diagonal of the reduced matrix where the records
    cannot tell them. The offsets start at `theta0` ``(3,)`` degrees."""
    dtype = problems.los.dtype
    freef = free.astype(dtype)
    weakf = weak.astype(dtype)

    def step(carry):
        return _solve_pass(model, problems, freef, weakf, anchor, n_records, carry)

    def going(carry):
        it, _, _, (last, _), _, _ = carry
        # at least three passes (the nuisances settle), then until the offsets stop moving
        return (it < max_passes) & ((it < 3) | ~(last < 1.0))

    nuisance0 = _start(model, problems, with_ref)
    theta0 = (theta0 * freef).astype(dtype)
    inf = jnp.asarray(jnp.inf, dtype)
    kept0 = (nuisance0, theta0, inf)
    empty = jax.eval_shape(lambda: _evaluate(model, problems, freef, n_records, nuisance0,
                                             theta0, jnp.asarray(0))[0])
    empty = jax.tree_util.tree_map(lambda x: jnp.zeros(x.shape, x.dtype), empty)
    start = (jnp.asarray(0), nuisance0, theta0, (inf, inf), empty, kept0)
    passes, _, theta, (last, last_deg), sol, _ = jax.lax.while_loop(going, step, start)
    # the statistics are those of the last pass's starting point, which the last step (below
    # STEP_SHARE of the standard errors when converged) moved by less than they matter for
    return eqx.tree_at(lambda x: (x.theta, x.num_steps, x.last_step, x.converged), sol,
                       (theta, passes, last_deg, last < 1.0))


# ------------------------------------------------------------------------------------------
# the steps of `calibrate` before and after the solve


def _checked(records, table, wrt, reference, covariance, north_offset):
    """The arguments checked before anything is computed: ``(names, los, ref_speed,
    ref_dir, header)``; raises `ValueError` naming the argument and the fix."""
    fname = "calibrate"
    if isinstance(table, ProfileTable):
        raise ValueError(f"{fname}: pass a ResponseTable; for a ProfileTable use table.at(value) "
                         "at the site's typical profile parameter.")
    if not isinstance(table, ResponseTable):
        raise ValueError(f"{fname}: `table` must be a lidarjax.ResponseTable, got "
                         f"{type(table).__name__}.")
    names = tuple(wrt) if not isinstance(wrt, str) else (wrt,)
    bad = [x for x in names if x not in CALIBRATION_PARAMETERS]
    if bad or not names or len(set(names)) != len(names):
        raise ValueError(f"{fname}: `wrt` must name distinct offsets among "
                         f"{CALIBRATION_PARAMETERS}, got {wrt!r}.")
    if north_offset not in ("instrument", "site"):
        raise ValueError(f"{fname}: `north_offset` must be 'instrument' (the instrument turned "
                         "on its site) or 'site' (the flow turns with it: a platform's heading), "
                         f"got {north_offset!r}.")
    if covariance not in ("robust", "model"):
        raise ValueError(f"{fname}: `covariance` must be 'robust' or 'model', got "
                         f"{covariance!r}.")
    header = {"pitch": float(getattr(records, "pitch", math.nan) or math.nan),
              "roll": float(getattr(records, "roll", math.nan) or math.nan)}
    los_in = getattr(records, "los", records)
    if los_in is None:
        raise ValueError(f"{fname}: the records carry no LOS (a .sta file reports winds only); "
                         "calibrate needs raw LOS records such as a Windcube .rtd.")
    los = jnp.asarray(los_in)
    h, b = table.n_heights, table.n_beams
    if los.ndim != 3 or los.shape[1:] != (h, b):
        raise ValueError(f"{fname}: `records` must be LOS shaped (r, h, b) with (h, b) = "
                         f"{(h, b)} as in the table; got {tuple(los.shape)}.")
    if table.beam_vectors is None:
        raise ValueError(f"{fname}: the table has no beam_vectors; build it with a mount "
                         "(ResponseTable.from_simulations(mount=...), lidarjax table).")
    r = los.shape[0]
    ref_speed = ref_dir = None
    if reference is not None:
        if isinstance(reference, tuple | list):
            if len(reference) != 2:
                raise ValueError(f"{fname}: `reference` must be (speed, direction) arrays "
                                 "shaped (r, h).")
            ref_speed, ref_dir = reference
        else:
            ref_speed = getattr(reference, "speed", None)
            ref_dir = getattr(reference, "direction", None)
        ref_dir = None if ref_dir is None else np.asarray(ref_dir, np.float64)
        ref_speed = None if ref_speed is None else np.asarray(ref_speed, np.float64)
        if ref_dir is None or ref_dir.shape != (r, h) or (
                ref_speed is not None and ref_speed.shape != (r, h)):
            raise ValueError(f"{fname}: `reference` speed and direction must be shaped (r, h) = "
                             f"{(r, h)} like the records; got "
                             f"{None if ref_dir is None else ref_dir.shape}.")
    return names, los, ref_speed, ref_dir, header


def _flattened(los, table, weights, ref_speed, ref_dir, min_beams, with_ref, dtype):
    """Records ``(r, h, b)`` to record-height `_Problems` ``(r * h, ...)``, record-major,
    keeping the record-heights with at least `min_beams` usable beams (and a reference)."""
    if weights is not None:
        w = jnp.broadcast_to(jnp.asarray(weights, dtype), los.shape)
        if is_concrete(w) and (np.any(np.asarray(w) < 0) or np.any(np.isinf(np.asarray(w)))):
            raise ValueError("calibrate: `weights` must be finite and nonnegative.")
    else:
        w = None
    as_array = lambda x: None if x is None else jnp.asarray(x, dtype)  # noqa: E731
    return _flatten(los.astype(dtype), w, table.valid, as_array(ref_speed), as_array(ref_dir),
                    int(min_beams), bool(with_ref))


@eqx.filter_jit
def _flatten(los, w, valid, ref_speed, ref_dir, min_beams, with_ref):
    """`_flattened`'s array work, one compiled program (not a dozen eager operations over
    the year's records)."""
    dtype = los.dtype
    w = jnp.ones(los.shape, dtype) if w is None else jnp.where(jnp.isnan(w), 0.0, w)
    usable = jnp.isfinite(los) & (w > 0) & valid
    enough = jnp.sum(usable, -1) >= min_beams  # (r, h)
    if with_ref:
        enough = enough & jnp.isfinite(ref_dir)
        if ref_speed is not None:
            enough = enough & jnp.isfinite(ref_speed)
    w = jnp.where(usable & enough[..., None], w, 0.0).astype(dtype)
    los = jnp.where(w > 0, los, 0.0)
    r, h = los.shape[:2]
    flat = lambda x: x.reshape((r * h,) + x.shape[2:])  # noqa: E731
    return _Problems(
        los=flat(los), weights=flat(w),
        ref_dir=jnp.zeros((r * h,), dtype) if ref_dir is None else flat(
            jnp.where(jnp.isfinite(ref_dir), ref_dir, 0.0)),
        height=flat(jnp.broadcast_to(jnp.arange(h, dtype=jnp.int32), (r, h))),
        record=flat(jnp.broadcast_to(jnp.arange(r, dtype=jnp.int32)[:, None], (r, h))))


def _model_of(table: ResponseTable, dtype, north_offset: str = "instrument"
              ) -> tuple[_CalibrationModel, list[str]]:
    """The table as a `_CalibrationModel`, and notes on what it lacks."""
    notes = []
    inst = table.instrument
    nominal = np.array([0.0 if inst is None or getattr(inst, f"{x}_deg") is None
                        else float(getattr(inst, f"{x}_deg")) for x in CALIBRATION_PARAMETERS])
    sp = table.response_spline
    s, h, b = table.response.shape
    if table.beam_velocity_spline is not None:
        velocity = table.beam_velocity_spline.coefficients
    elif table.point_spline is not None:
        velocity = jnp.broadcast_to(table.point_spline.coefficients[:, :, :, None, :],
                                    (4, s, h, b, 3))
    else:  # the undisturbed horizontal free stream, as a spline through the knots
        d = np.deg2rad(np.asarray(table.directions, np.float64))
        free = np.stack([-np.sin(d), -np.cos(d), np.zeros_like(d)], -1)
        velocity = jnp.broadcast_to(jnp.asarray(_spline_coefficients(
            np.asarray(table.directions, np.float64), free))[:, :, None, None, :],
            (4, s, h, b, 3))
    beams = np.asarray(table.beam_vectors, np.float64)
    gradient = None
    if table.beam_gradient_spline is None:
        notes.append(_NO_GRADIENT)
    elif table.heights is None:
        notes.append(_NO_GRADIENT.replace("has no beam_gradient", "has no heights"))
    else:
        # focus ranges: heights over the beams' cosines in the body frame of the
        # installation (as `simulate` computes them: the instrument assumes it is level)
        e0, p0, r0 = nominal
        body = beams @ (np.asarray(tilt_rotation(p0, r0), np.float64).T
                        @ np.asarray(rotation_z(e0), np.float64)).T
        ranges = np.asarray(table.heights, np.float64)[:, None] / body[None, :, 2]  # (h, b)
        gradient = (table.beam_gradient_spline.coefficients
                    * jnp.asarray(ranges, table.dtype)[None, None, :, :, None, None])
        notes.append("model: the beams turned exactly, the measurement points' displacement "
                     "to first order (the table's beam_gradient), relinearised around the "
                     "estimate at every pass; second order in the offsets is left out (the "
                     "flow's curvature over the displacement): for offsets of several "
                     "degrees rebuild the table at the estimate and calibrate again")
    values = jnp.where(table.valid, table.response, 0.0)
    cast = lambda x: None if x is None else jnp.asarray(x, dtype)  # noqa: E731
    model = _CalibrationModel(
        geom=(cast(sp.start), cast(sp.offsets), cast(sp.widths), sp.uniform),
        response=cast(sp.coefficients), velocity=cast(velocity), gradient=cast(gradient),
        beams=cast(beams), nominal=cast(nominal), values=cast(values),
        knots=cast(table.directions), turn_beams=north_offset == "instrument")
    return model, notes


def _covariance(sol: _Solution, free, weak, with_ref, n_rec, covariance):
    """``(identifiable (3,), cov (3, 3), sigma2)`` on the host from the solution: for the
    offsets in `free` but not `weak`, marginal over the `weak` ones (their ridge kept)."""
    hmat, meat = (np.asarray(x, np.float64) for x in (sol.hessian, sol.meat))
    m = 1 if with_ref else 2
    dof = max(int(sol.n_obs) - m * int(sol.n_ok) - int(free.sum()), 1)
    sigma2 = float(sol.wrss) / dof
    ident = np.zeros(3, bool)
    cov = np.full((3, 3), np.nan)
    shown = np.flatnonzero(free & ~weak)
    held = np.flatnonzero(weak)
    if not shown.size:
        return ident, cov, sigma2
    hreg = hmat + np.diag(weak * RIDGE * np.max(np.diag(hmat) * free, initial=0.0))
    # identifiability: eigenvalues of the normalised reduced matrix of the shown offsets,
    # the held ones eliminated
    hs = hreg[np.ix_(shown, shown)]
    if held.size:
        hw = hreg[np.ix_(held, held)]
        if np.all(np.diag(hw) > 0):
            cross = hreg[np.ix_(shown, held)]
            hs = hs - cross @ np.linalg.solve(hw, cross.T)
    d = np.sqrt(np.maximum(np.diag(hs), 0.0))
    if not np.all(d > 0):
        return ident, cov, sigma2
    eig, vec = np.linalg.eigh(hs / np.outer(d, d))
    weak_dirs = eig < IDENTIFIABILITY_RCOND * max(eig[-1], 1e-300)
    ident[shown] = True
    for j in np.flatnonzero(weak_dirs):  # offsets along a null direction are not identified
        ident[shown[np.abs(vec[:, j]) > 0.3]] = False
    if ident[shown].any():
        sub = np.concatenate([shown[ident[shown]], held])
        k = int(ident[shown].sum())
        hinv = np.linalg.inv(hreg[np.ix_(sub, sub)])
        if covariance == "robust":
            c = hinv @ meat[np.ix_(sub, sub)] @ hinv * (n_rec / max(n_rec - sub.size, 1))
        else:
            c = sigma2 * hinv
        keep = sub[:k]
        cov[np.ix_(keep, keep)] = c[:k, :k]
    return ident, cov, sigma2


def _result(names, sol, free, ident, cov, sigma2, nominal, header, n_rec, notes, dtype, *,
            rebuilds=0, refined=True):
    """The `Calibration` of the offsets `names` from the solution (`refined`: the iteration
    on the exact geometry, where there was one, settled)."""
    theta = np.asarray(sol.theta, np.float64)
    last = float(sol.last_step)
    fitted = bool(sol.converged) and bool(np.all(np.isfinite(theta)))
    converged = fitted and refined
    notes = list(notes)
    if fitted and not refined:
        notes.append(f"the iteration on the exact geometry did not settle in {rebuilds} "
                     "rebuilds of the table (see the model line): the offsets are the last "
                     "iterate; allow more refinements")
    elif not converged:
        notes.append(f"did not converge in {int(sol.num_steps)} passes (offsets still moving "
                     f"by {last:.2g} deg): these records do not determine the offsets; the "
                     "values are the last iterate, not an estimate")
    for j, name in enumerate(CALIBRATION_PARAMETERS):
        if free[j] and not ident[j]:
            notes.append(f"{name} is not identifiable from these records (too few directions, "
                         "records or beams; see lidarjax.calibrate)")
    sel = [CALIBRATION_PARAMETERS.index(x) for x in names]
    off = np.where(ident, theta, np.nan)[sel]
    cov = cov[np.ix_(sel, sel)]
    std = np.sqrt(np.diag(cov))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(std, std)
    nom = np.asarray(nominal, np.float64)[sel]
    flags = (0 if converged else int(InverseFlag.NOT_CONVERGED)) | (
        int(InverseFlag.ILL_CONDITIONED) if np.any(free & ~ident) else 0)
    f = lambda a: jnp.asarray(a, dtype)  # noqa: E731
    i32 = lambda a: jnp.asarray(a, jnp.int32)  # noqa: E731
    return Calibration(
        names=names, offset=f(off), value=f(nom + off), nominal=f(nom), std=f(std),
        covariance=f(cov), correlation=f(corr), identifiable=jnp.asarray(ident[sel]),
        header=f([header.get(x, math.nan) for x in names]), noise=f(math.sqrt(sigma2)),
        n_records=i32(n_rec), n_problems=i32(int(sol.n_used)), flags=i32(flags),
        num_steps=i32(int(sol.num_steps)), last_step=f(last), rebuilds=i32(rebuilds),
        notes=tuple(notes))


class _Fit(NamedTuple):
    """One fit of the records to one table (`_fit_table`): the model and its notes, the
    solution, the offsets fitted (`fit`) and held as a nuisance (`weak`) ``(3,)``, what is
    identifiable, the covariance ``(3, 3)``, the residual variance and the records used."""

    model: _CalibrationModel
    notes: list
    sol: _Solution
    fit: np.ndarray
    weak: np.ndarray
    ident: np.ndarray
    cov: np.ndarray
    sigma2: float
    n_rec: int


def _fit_table(table, data, free, north_offset, anchor, start, iterations, covariance
               ) -> _Fit:
    """The offsets in `free` fitted to the records `data` ``(los, weights, ref_speed,
    ref_dir, min_beams, with_ref, dtype)`` through `table`, starting at `start` and with
    a nuisance offset's ridge held at `anchor` (``(3,)`` degrees from the table's
    installation)."""
    los, weights, ref_speed, ref_dir, min_beams, with_ref, dtype = data
    problems = _flattened(los, table, weights, ref_speed, ref_dir, min_beams, with_ref, dtype)
    model, notes = _model_of(table, dtype, north_offset)
    fit = free.copy()
    weak = np.zeros(3, bool)
    if not with_ref and free[0]:
        notes.append(_NOT_IDENTIFIABLE_EPSILON)
        if model.turn_beams and model.gradient is not None:
            # the turn itself is taken up by the records' directions, but where the flow
            # varies in space it also moves the measurement points: that part is fitted (a
            # nuisance, held by a ridge where the records cannot tell it), so that it does
            # not go into the tilt
            weak[0] = True
            notes.append(_EPSILON_AS_NUISANCE)
        else:
            fit[0] = False
    sol = _solve(model, problems, jnp.asarray(fit), jnp.asarray(weak),
                 jnp.asarray(anchor, dtype), jnp.asarray(start, dtype),
                 jnp.asarray(int(iterations), jnp.int32), int(los.shape[0]), bool(with_ref))
    n_rec = int(sol.n_records)
    ident, cov, sigma2 = _covariance(sol, fit, weak, with_ref, n_rec, covariance)
    return _Fit(model, notes, sol, fit, weak, ident, cov, sigma2, n_rec)


def _check_runs(runs, table, refinements) -> None:
    """`calibrate`'s `runs` and `refinements` checked against the table, before computing."""
    if not isinstance(runs, TableRuns):
        raise ValueError("calibrate: `runs` must be a lidarjax.TableRuns (the table's CFD runs, "
                         f"fields, mounts, free streams, scan, heights), got "
                         f"{type(runs).__name__}.")
    if int(refinements) != refinements or refinements < 0:
        raise ValueError(f"calibrate: `refinements` must be a whole number >= 0, got "
                         f"{refinements!r}.")
    h, b = table.n_heights, table.n_beams
    if (runs.heights.shape[0], runs.scan.n_beams) != (h, b) or (
            table.heights is not None and not np.allclose(np.asarray(runs.heights),
                                                          np.asarray(table.heights))):
        raise ValueError(f"calibrate: `runs` simulate heights {np.asarray(runs.heights).tolist()}"
                         f" and {runs.scan.n_beams} beams, the table "
                         f"{None if table.heights is None else np.asarray(table.heights).tolist()}"
                         f" and {b}; give the runs the table was built from (runs.table()).")


def _refined_note(rebuilds: int, moved: float, refinements: int) -> str:
    """`Calibration.notes`' line on the iteration on the exact geometry."""
    if rebuilds == 0 and moved <= TOLERANCE:
        return ("model: exact geometry (the table's runs at the installation; the offsets "
                "from it below the tolerance)")
    head = (f"model: iterated on the exact geometry, the table built again from its runs at "
            f"the estimate {rebuilds} time(s); ")
    if math.isfinite(moved):
        return head + (f"the last fit moved the offsets by {moved:.2g} deg" +
                       ("" if rebuilds < refinements else
                        f" (the most of {refinements} rebuilds allowed)"))
    return head + "the last fit gave no finite offsets"


def calibrate(
    records,
    table: ResponseTable,
    wrt: tuple[str, ...] | list[str] = CALIBRATION_PARAMETERS,
    reference=None,
    *,
    weights: Float[ArrayLike, "r h b"] | None = None,
    min_beams: int = 3,
    iterations: int = 20,
    covariance: str = "robust",
    north_offset: str = "instrument",
    runs: TableRuns | None = None,
    refinements: int = REFINEMENTS,
) -> Calibration:
    """Constant installation offsets (north offset, pitch, roll) from many records.

    **Arguments:**

    - `records`: LOS records ``(r, h, b)`` (m/s, positive away from the lidar, beams and
      heights as in the table; NaN marks a missing beam), or an object with a `los` array
      of that shape (a `lidarjax.RecordSet` of a ``.rtd`` file, whose `pitch` and `roll`
      header values are then compared with the estimate).
    - `table`: the site's `ResponseTable` with `beam_vectors` (and, best, `beam_velocity`
      and `beam_gradient`: `ResponseTable.from_simulations(..., mount=, fields=)` or
      ``lidarjax table``), built for the nominal installation (`table.instrument`; level
      and ``epsilon = 0`` when it states none). For a `ProfileTable` pass
      ``table.at(value)``. Without `beam_gradient` the displacement of the measurement
      points is left out, with a warning and a note.
    - `wrt`: the offsets to estimate, any of ``("epsilon", "pitch", "roll")``.
    - `reference`: None, or the free stream at the records' times and the table's heights:
      a pair ``(speed, direction)`` of ``(r, h)`` arrays (m/s, meteorological degrees;
      speed may be None) or an object with `speed` and `direction` arrays. NaN marks a
      missing reference value (that record-height is not used). The offsets rest on the
      reference *directions*: the speed stays a free nuisance per record-height, so a
      reference whose speed calibration differs from the lidar's cannot bias the angles.
    - `weights`: optional ``(r, h, b)`` relative inverse variances of the beams.
    - `min_beams`: fewest usable beams for a record-height to count (default 3).
    - `iterations`: most Gauss--Newton passes over the records (default 20; each pass
      updates the offsets, by at most 5 degrees of epsilon and 1 degree of tilt, and every
      record-height's free stream; a step that raises the objective is halved back; it
      stops once no reported offset moves by more than `STEP_SHARE` (1 %) of its standard
      error, or less than `TOLERANCE` degrees, which is also what
      `Calibration.converged` asks).
    - `covariance`: ``"robust"`` (record-clustered sandwich, default) or ``"model"``
      (``sigma**2 H^-1``); see the module docstring.
    - `north_offset`: what a north offset is. ``"instrument"`` (default): the instrument is
      turned on its site, so its beams and measurement points turn while the flow (terrain,
      buildings, a platform it stands on) stays. ``"site"``: the flow turns with the
      instrument (a lidar and the platform distorting its flow share a heading error):
      every direction label is shifted, ``R(d - d_epsilon)``. The two agree where the
      flow does not vary in space.
    - `runs`: optional `lidarjax.TableRuns`, the CFD runs `table` was built from
      (``table = runs.table()``). With them `calibrate` **iterates on the exact geometry**:
      after each fit it builds the table again for the instrument at the estimate
      (`TableRuns.table`: every beam turned and every measurement point moved, by
      `lidarjax.simulate` itself) and fits the offsets left, until a fit moves no reported
      offset by more than `REFINE_SHARE` (1 %) of its standard error, at most `refinements`
      rebuilds (default `REFINEMENTS`, 3). The linearisation's error (the flow's curvature
      over the displacement, second order in the offsets) then falls quadratically with
      each rebuild; without `runs` it stays (see the module docstring). The standard errors
      are the last fit's. A last rebuild that still moved the offsets sets
      ``NOT_CONVERGED``.
    - `refinements`: most rebuilds with `runs` (0: no rebuild, the fit of `table` alone, as
      without `runs`, with a note).

    **Returns:** a `Calibration`. Without a reference, epsilon is NaN with
    ``identifiable = False`` and a note. Raises `ValueError` before computing for unknown
    names in `wrt`, shapes that do not match the table, or a table without beam vectors.
    """
    names, los, ref_speed, ref_dir, header = _checked(records, table, wrt, reference,
                                                      covariance, north_offset)
    if runs is not None:
        _check_runs(runs, table, refinements)
    dtype = los.dtype if jnp.issubdtype(los.dtype, jnp.floating) else table.dtype
    with_ref = reference is not None
    free = np.array([x in names for x in CALIBRATION_PARAMETERS])
    data = (los, weights, ref_speed, ref_dir, min_beams, with_ref, dtype)
    total = np.zeros(3)  # the offsets of the current table's installation from the first's
    start = np.zeros(3)  # where each fit starts, degrees from the current table's installation
    rebuilds, moved, small, nominal = 0, math.inf, 0.0, None
    while True:
        # the nuisance's ridge holds it at the first table's installation, whichever table
        # this is: every rebuild fits one objective from a new linearisation point
        f = _fit_table(table, data, free, north_offset, -total, start, iterations, covariance)
        if nominal is None:
            nominal = f.model.nominal
            if f.model.gradient is None and runs is None:
                warnings.warn(f"calibrate: {f.notes[0]}", stacklevel=2)
        step = np.where(f.fit, np.asarray(f.sol.theta, np.float64), 0.0)
        if north_offset == "site":  # the table's turn is a relabelling: not accumulated
            total[0] = 0.0
        if f.weak[0] and rebuilds > 0:
            # a nuisance turn the records hardly tell is built into the geometry once (the
            # first fit's); later fits keep it as a first-order nuisance about that turn:
            # fed back, its flat direction makes the rebuilds cycle
            start[0] = step[0]  # the next fit starts at this one's nuisance turn
            step[0] = 0.0
        total = total + step
        if runs is None:
            break
        shown = f.fit & ~f.weak & f.ident
        moved = float(np.max(np.abs(step[shown]), initial=0.0))
        small = max(REFINE_SHARE * float(np.min(np.sqrt(np.diag(f.cov)[shown]),
                                                initial=math.inf)), TOLERANCE)
        if not np.all(np.isfinite(step)) or moved <= small or rebuilds >= refinements:
            break
        # iterate on the exact geometry: the table of the instrument at the estimate, from
        # which the offsets left are small, so the linearisation's error falls quadratically
        table = runs.table(total, north_offset)
        rebuilds += 1
    notes = list(f.notes)
    iterated = runs is not None and refinements > 0
    if iterated:
        notes = [x for x in notes if not x.startswith("model:")]
        notes.append(_refined_note(rebuilds, moved, refinements))
    elif runs is not None:
        notes.append("refinements=0: the table was not built again at the estimate; the "
                     "linearisation's error stays (see the model line)")
    sol = eqx.tree_at(lambda x: x.theta, f.sol, jnp.asarray(total, f.sol.theta.dtype))
    return _result(names, sol, f.fit & ~f.weak, f.ident, f.cov, f.sigma2, nominal, header,
                   f.n_rec, notes, dtype, rebuilds=rebuilds,
                   refined=not iterated or moved <= small)
