"""Free-stream wind from what a lidar measured, by inverting a `ResponseTable`.

For every record ``r`` and height ``h`` the LOS of beam ``b`` is modelled as
``los_b = U * R_hb(d)``: the free-stream speed ``U`` (m/s) times the tabulated response at the
free-stream direction ``d`` (Reynolds independence). `invert` solves

``min_{U, d}  sum_b w_b (los_b - U R_hb(d))**2``

per record and height with an optimistix least-squares solver (Gauss--Newton by default),
vmapped over the whole batch.

Parametrisation. The unknown is the free-stream horizontal velocity ``y = (u, v)`` in the
north frame (m/s), ``U = |y|`` and ``d = wind_direction(y)``. The Jacobian in these
coordinates is a rotation of ``[R(d), dR/dd]`` and so stays well conditioned down to calm
wind, and there is no 0/360 branch: a start at 359 degrees reaches a truth at 1 degree.

Start. For each tabulated direction ``d_k`` the closed-form speed
``U_k = max(0, sum w los R_k / sum w R_k**2)`` and its cost are computed; the best ``(U_k, d_k)``
starts the solver. It needs no scan geometry and cannot start in a wrong branch.

Robustness. NaN LOS and beams missing from the table get zero weight; a record and height
with fewer than `min_beams` usable beams, or whose beams cannot tell the direction, gets NaN
with ``converged=False``; the solver runs with ``throw=False`` and a bounded step count, so no
record can stop or disturb the others (every problem is solved independently).

Uncertainty. From the Jacobian at the solution, ``cov(U, d) = sigma**2 (J^T W J)^-1`` with
the LOS noise level ``sigma`` (m/s for a beam of unit weight) given as `noise` or estimated
from the weighted residuals, ``sigma**2 = sum w r**2 / (n_beams - 2)``.

Gradients. ``speed`` and ``direction`` are differentiable with respect to the LOS, the
weights and the table's spline coefficients (``table.response_spline.coefficients``; the fit
of those coefficients runs on the host and is not traced) by implicit differentiation of the
optimum (`optimistix.ImplicitAdjoint`): propagate LOS noise with ``jax.jacrev`` or run
sensitivity studies without differentiating through the iterations.

Directions are meteorological (from, degrees clockwise from north) in ``[0, 360)``.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from ._backend import CPU_BATCH, bucket, default_batch, positive_size
from ._precision import HIGHEST, default_float, is_concrete
from ._util import compiled
from .angles import _calm_mask
from .flags import InverseFlag
from .response import (
    AbstractProfile,
    PeriodicSpline,
    ProfileTable,
    ResponseTable,
    parameter_weights,
    spline_at,
    tabulated_start,
)

__all__ = ["Inversion", "invert", "invert_reconstructed", "default_solver", "JointInversion",
           "invert_joint", "invert_joint_reconstructed"]

#: Problems (record-heights) per vmapped batch on a CPU (rounded down to whole records), the
#: default there. Small batches waste little on their slowest member; measured best on CPU
#: between 256 and 1024 (benchmarks/inverse.py). On an accelerator the default is the whole
#: campaign when it fits in memory (`lidarjax._backend.default_batch`).
DEFAULT_BATCH_SIZE = CPU_BATCH["invert"]


class Inversion(eqx.Module):
    """Results of `invert` / `invert_reconstructed`, each shaped ``(..., h)``.

    - `speed`: free-stream horizontal speed, m/s (NaN where not converged).
    - `direction`: free-stream meteorological direction, degrees in ``[0, 360)`` (NaN where
      not converged or calm).
    - `converged`: bool; False means NaN results, with the reason in `flags`.
    - `residual_rms`: weighted RMS of the LOS residuals ``los - U R(d)``, m/s.
    - `speed_std`, `direction_std`: one-sigma uncertainties (m/s, degrees) from the
      Jacobian at the solution and the noise level `noise`. With a given noise level,
      ``1.96 * std`` covers 95 %; with the noise estimated from ``dof = n_beams - 2`` spare
      beams, use Student's t quantile for `dof` (3.18 for a Windcube V2's 3 spare beams).
    - `noise`: LOS noise level used (given, or estimated from the residuals), m/s.
    - `n_beams`: number of beams used (finite LOS, positive weight, present in the table).
    - `num_steps`: solver steps taken (bounded by `max_steps`).
    - `result`: the solver's `optimistix.RESULTS` (compare with
      ``optimistix.RESULTS.successful``).
    - `flags`: int32 bitmask of `InverseFlag`.
    """

    speed: Float[Array, "... h"]
    direction: Float[Array, "... h"]
    converged: Bool[Array, "... h"]
    residual_rms: Float[Array, "... h"]
    speed_std: Float[Array, "... h"]
    direction_std: Float[Array, "... h"]
    noise: Float[Array, "... h"]
    n_beams: Int[Array, "... h"]
    num_steps: Int[Array, "... h"]
    result: optx.RESULTS
    flags: Int[Array, "... h"]

    @property
    def dof(self) -> Int[Array, "... h"]:
        """Spare beams behind the noise estimate: ``n_beams - 2``."""
        return self.n_beams - 2

    @property
    def velocity(self) -> Float[Array, "... h 2"]:
        """Free-stream horizontal velocity ``(u, v)`` in the north frame, m/s."""
        d = jnp.deg2rad(self.direction)
        return jnp.stack([-self.speed * jnp.sin(d), -self.speed * jnp.cos(d)], axis=-1)


# ------------------------------------------------------------------------------------------
# The per-problem model


def _polar(y):
    """Speed and meteorological direction (degrees) of ``y = (u, v)``, gradient-safe at 0."""
    u, v = y[0], y[1]
    h2 = u * u + v * v
    calm = _calm_mask(u, v)
    speed = jnp.where(calm, 0.0, jnp.sqrt(jnp.where(calm, 1.0, h2)))
    d = jnp.rad2deg(jnp.arctan2(jnp.where(calm, 0.0, -u), jnp.where(calm, 1.0, -v)))
    return speed, d, calm


def _row(geom, coefficients, hidx, direction):
    """Spline value ``(b,)`` of height `hidx` at `direction` (degrees, any real)."""
    return spline_at(geom, coefficients, direction, (hidx,))


def _residuals(y, args):
    los, sw, hidx, geom, coefficients = args
    speed, d, _ = _polar(y)
    return sw * (los - speed * _row(geom, coefficients, hidx, d))


def _usable(w):
    """The usable beams' count and the residual weights ``sqrt(w)`` (0 where ``w <= 0``)."""
    usable = w > 0
    n_beams = jnp.sum(usable.astype(jnp.int32))
    return n_beams, jnp.sqrt(jnp.where(usable, w, 1.0)) * usable


def _noise_level(w, resid, n_beams, n_free, noise, scale):
    """The weighted residual RMS (NaN without weights) and the noise variance ``sigma**2``
    in units of `scale`: from `noise` (m/s) when given, else ``wrss / (n_beams - n_free)``
    (NaN without spare beams)."""
    wrss = jnp.sum(w * resid * resid)
    wsum = jnp.sum(w)
    residual_rms = jnp.where(wsum > 0, jnp.sqrt(wrss / jnp.where(wsum > 0, wsum, 1.0)), jnp.nan)
    dof = n_beams - n_free
    sigma2_est = jnp.where(dof > 0, wrss / jnp.maximum(dof, 1), jnp.nan)
    return residual_rms, jnp.where(jnp.isnan(noise), sigma2_est, (noise / scale) ** 2)


def _wrap360(d):
    """Degrees wrapped to ``[0, 360)`` (``mod`` can round up to 360 itself)."""
    direction = jnp.mod(d, 360.0)
    return jnp.where(direction >= 360.0, direction - 360.0, direction)


def _one_statistics(los, w, n_beams, noise, scale, speed, d, hidx, geom, coefficients):
    """The residual RMS, ``sigma**2``, the variances of speed and direction (Schur
    complements of ``J^T W J`` in (U, d [degrees]); inf where singular) and whether the
    direction is identifiable independently of the speed, at the solution ``(speed, d)``."""
    dtype = los.dtype
    r_d, dr_d = jax.jvp(lambda x: _row(geom, coefficients, hidx, x), (d,), (jnp.ones_like(d),))
    residual_rms, sigma2 = _noise_level(w, los - speed * r_d, n_beams, 2, noise, scale)
    m_uu = jnp.sum(w * r_d * r_d)
    m_ud = jnp.sum(w * r_d * dr_d) * speed
    m_dd = jnp.sum(w * dr_d * dr_d) * speed * speed
    schur_u = m_uu - jnp.where(m_dd > 0, m_ud * m_ud / jnp.where(m_dd > 0, m_dd, 1.0), 0.0)
    schur_d = m_dd - jnp.where(m_uu > 0, m_ud * m_ud / jnp.where(m_uu > 0, m_uu, 1.0), 0.0)
    inf = jnp.asarray(jnp.inf, dtype)
    var_u = jnp.where(schur_u > 0, sigma2 / jnp.where(schur_u > 0, schur_u, 1.0), inf)
    var_d = jnp.where(schur_d > 0, sigma2 / jnp.where(schur_d > 0, schur_d, 1.0), inf)

    # Identifiability of the direction, independent of the speed: [R, dR/dd (per radian)].
    g = dr_d * (180.0 / np.pi)
    g_uu, g_ud, g_dd = m_uu, jnp.sum(w * r_d * g), jnp.sum(w * g * g)
    tr = g_uu + g_dd
    det = g_uu * g_dd - g_ud * g_ud
    disc = jnp.sqrt(jnp.maximum(tr * tr - 4.0 * det, 0.0))
    lam_min = 0.5 * (tr - disc)
    lam_max = 0.5 * (tr + disc)
    rcond = jnp.sqrt(jnp.finfo(dtype).eps)
    return residual_rms, sigma2, var_u, var_d, lam_min > rcond * lam_max


def _solve_one(los, w, hidx, noise, k, u0, scale, knots, geom, coefficients, cfg):
    """One record-height, in units of `scale` (the record's weighted RMS LOS, m/s; 1 for an
    all-zero record): `los`, `w` ``(b,)`` (cleaned: unusable beams have ``w = 0`` and
    ``los = 0``), `los` divided by `scale`; `noise` scalar in m/s (NaN: estimate); start
    ``(k, u0)``: tabulated direction index and its closed-form speed in units of `scale`.

    Working in these units keeps the solver's tolerances relative (it behaves the same at
    0.01 and 100 m/s) and keeps every square (residuals, Jacobian products) in range: in
    float32 the LOS of a record below ~1e-19 m/s or above ~1e19 m/s would otherwise
    underflow or overflow when squared."""
    solver, max_steps, min_beams = cfg
    dtype = los.dtype
    n_beams, sw = _usable(w)
    d0 = jnp.deg2rad(knots[k])
    unit = jnp.stack([-jnp.sin(d0), -jnp.cos(d0)])

    # A problem the solver cannot start (no tabulated direction fits a positive speed, so
    # the answer is calm; or too few beams) is swapped for a trivial one (the table's own
    # response at the start direction, solved at the first step) and its outputs overridden.
    calm_start = u0 <= 0
    trivial = calm_start | (n_beams < min_beams)
    args = (
        jnp.where(trivial, _row(geom, coefficients, hidx, knots[k]), los),
        jnp.where(trivial, jnp.ones_like(sw), sw),
        hidx,
        geom,
        coefficients,
    )
    y0 = jax.lax.stop_gradient(jnp.where(trivial, unit, u0 * unit))
    sol = optx.least_squares(_residuals, solver, y0, args, max_steps=max_steps, throw=False)
    y = jnp.where(trivial, 0.0, sol.value)
    speed, d, calm = _polar(y)
    d = jnp.where(calm, knots[k], d)  # a direction for the calm Jacobian (speed variance)
    residual_rms, sigma2, var_u, var_d, well_posed = _one_statistics(
        los, w, n_beams, noise, scale, speed, d, hidx, geom, coefficients)

    ok_solver = sol.result == optx.RESULTS.successful
    finite = jnp.all(jnp.isfinite(y))
    enough = n_beams >= min_beams
    converged = ok_solver & finite & enough & well_posed
    flags = (
        jnp.where(enough, 0, int(InverseFlag.TOO_FEW_BEAMS))
        | jnp.where(ok_solver & finite, 0, int(InverseFlag.NOT_CONVERGED))
        | jnp.where(well_posed | ~enough, 0, int(InverseFlag.ILL_CONDITIONED))
        | jnp.where(converged & calm, int(InverseFlag.CALM), 0)
        | jnp.where(converged & jnp.isnan(sigma2), int(InverseFlag.NO_NOISE_ESTIMATE), 0)
    )
    nan = jnp.asarray(jnp.nan, dtype)
    inf = jnp.asarray(jnp.inf, dtype)
    return dict(
        speed=jnp.where(converged, speed * scale, nan),
        direction=jnp.where(converged & ~calm, _wrap360(d), nan),
        converged=converged,
        residual_rms=residual_rms * scale,
        speed_std=jnp.where(converged, jnp.sqrt(var_u) * scale, nan),
        direction_std=jnp.where(converged, jnp.where(calm, inf, jnp.sqrt(var_d)), nan),
        noise=jnp.sqrt(sigma2) * scale,
        n_beams=n_beams,
        num_steps=sol.stats["num_steps"].astype(jnp.int32),
        result=sol.result,
        flags=flags.astype(jnp.int32),
    )


def default_solver(dtype=None) -> optx.AbstractLeastSquaresSolver:
    """The solver `invert` uses by default: `optimistix.GaussNewton` on the normal equations
    (`lineax.Normal(lineax.Cholesky())`: two unknowns, a well-conditioned Jacobian) with
    relative and absolute tolerances ``max(1e-6, 100 eps)`` of `dtype` (1e-6 in float64,
    1.2e-5 in float32), in units of the record's RMS LOS (the problem is solved in those
    units). Gauss--Newton converges quadratically here, so once it steps the solution is far
    more accurate than the tolerance on the last step; a start (the best tabulated direction)
    that already fits the record within the tolerance is accepted as it is, accurate to the
    tolerance (a true direction within about 1e-4 degrees of a tabulated one)."""
    eps = float(jnp.finfo(dtype if dtype is not None else default_float()).eps)
    tol = max(1e-6, 100.0 * eps)
    return optx.GaussNewton(rtol=tol, atol=tol, linear_solver=lx.Normal(lx.Cholesky()))


def _in_batches(run, los, w_r, noise, per_batch, n_real):
    """``run((los, w_r, noise))`` over the records (leading axis) in batches of `per_batch`
    (None: all at once): padded to whole batches, mapped with `jax.lax.map`, and batches
    holding only padding (beyond `n_real` records) skipped by `jax.lax.cond`."""
    n, h, b = los.shape
    if per_batch is None or n <= per_batch:
        out = run((los, w_r, noise))
    else:
        pad = (-n) % per_batch
        xs = (
            jnp.concatenate([los, jnp.zeros((pad, h, b), los.dtype)]),
            jnp.concatenate([w_r, jnp.zeros((pad, h, b), w_r.dtype)]),
            jnp.concatenate([noise, jnp.full((pad, h), jnp.nan, noise.dtype)]),
        )
        xs = jax.tree_util.tree_map(lambda x: x.reshape((-1, per_batch) + x.shape[1:]), xs)
        run = jax.jit(run)  # traced once: for its shapes here and in the cond below
        shapes = jax.eval_shape(run, jax.tree_util.tree_map(lambda x: x[0], xs))
        skipped = lambda x: jax.tree_util.tree_map(  # noqa: E731
            lambda s: jnp.zeros(s.shape, s.dtype), shapes)

        def one_batch(args):
            k, x = args
            return jax.lax.cond(k * per_batch < n_real, run, skipped, x)

        out = jax.lax.map(one_batch, (jnp.arange(xs[0].shape[0]), xs))
        out = jax.tree_util.tree_map(lambda x: x.reshape((-1,) + x.shape[2:])[:n], out)
    return out


def _solve_batch(los, w, noise, values, knots, geom, coefficients, cfg):
    """Records ``(r, h, b)``: start from the table densely, then solve every record-height."""
    r, h, b = los.shape
    usable = (w > 0) & jnp.isfinite(los)
    w = jnp.where(usable, w, 0.0)
    los = jnp.where(usable, los, 0.0)
    # The unit of each problem: its weighted RMS LOS (m/s), computed without squaring the
    # LOS themselves (no underflow or overflow in float32), 1 for an all-zero record.
    peak = jnp.max(jnp.abs(los), axis=-1)
    peak = jnp.where(peak > 0, peak, 1.0)
    wsum = jnp.sum(w, axis=-1)
    x = los / peak[..., None]
    scale = peak * jnp.sqrt(jnp.sum(w * x * x, axis=-1) / jnp.where(wsum > 0, wsum, 1.0))
    scale = jax.lax.stop_gradient(jnp.where(scale > 0, scale, 1.0))
    los = los / scale[..., None]
    # Start: best tabulated direction with its closed-form nonnegative speed.
    k, u0 = tabulated_start(w, los, values, "rhb,shb->rhs", 2)
    hidx = jnp.broadcast_to(jnp.arange(h, dtype=jnp.int32), (r, h))
    flat = lambda x: x.reshape((r * h,) + x.shape[2:])  # noqa: E731

    def one(los_i, w_i, h_i, noise_i, k_i, u0_i, scale_i):
        return _solve_one(los_i, w_i, h_i, noise_i, k_i, u0_i, scale_i, knots, geom,
                          coefficients, cfg)

    out = jax.vmap(one)(*(flat(x) for x in (los, w, hidx, noise, k, u0, scale)))
    return jax.tree_util.tree_map(lambda x: x.reshape((r, h) + x.shape[1:]), out)


@eqx.filter_jit
def _invert_core(spline, values, knots, valid, los, weights, noise, cfg, per_batch, n_real):
    """Records ``los`` ``(n, h, b)`` (weights alike, noise ``(n, h)``), solved in batches of
    `per_batch` records (None: all at once), returned as an `Inversion` of ``(n, h)``. Only
    the first `n_real` records (a traced count: no recompilation) are real; batches holding
    none of them (bucket padding) are skipped."""
    n, h, b = los.shape
    w_r = weights * valid
    values = jnp.where(valid, values, 0.0)
    geom = (spline.start, spline.offsets, spline.widths, spline.uniform)

    def run(x):
        return _solve_batch(*x, values, knots, geom, spline.coefficients, cfg)

    out = _in_batches(run, los, w_r, noise, per_batch, n_real)
    return Inversion(**out)


def _problem_bytes(h, b, n_directions, itemsize):
    """A generous estimate of the memory one record-height problem needs while it is solved
    (its LOS and weights, the start's per-direction costs, the solver's state)."""
    return itemsize * (32 * b + 8 * n_directions + 256)


def _batching(batch_size, n, h, b, n_directions, itemsize, fname):
    """``(per_batch, n_pad)``: records per vmapped batch (None: one batch) and the padded
    record count, a `bucket` (so campaigns of different lengths share few compilations)."""
    if batch_size is None:
        problems = default_batch("invert", _problem_bytes(h, b, n_directions, itemsize), n * h)
    elif isinstance(batch_size, str) and batch_size == "all":
        problems = None
    else:
        problems = positive_size(batch_size, fname, "batch_size",
                                 "(problems per batch), 'all' or None (chosen per backend)")
    per_batch = None if problems is None else max(1, problems // h)
    if per_batch is None or n <= per_batch:
        n_pad = bucket(n) if per_batch is None else min(bucket(n), per_batch)
        return None, max(n_pad, n)
    return per_batch, bucket(-(-n // per_batch)) * per_batch


def _cast_floats(tree, dtype):
    return jax.tree_util.tree_map(
        lambda a: a.astype(dtype)
        if isinstance(a, jax.Array) and jnp.issubdtype(a.dtype, jnp.floating)
        else a,
        tree,
    )


def _broadcast_input(name, value, shape, dtype, what):
    arr = jnp.asarray(value)
    try:
        return jnp.broadcast_to(arr, shape).astype(dtype)
    except ValueError:
        raise ValueError(
            f"invert: `{name}` of shape {arr.shape} does not broadcast to {what} {shape}."
        ) from None


def _los_inputs(los, weights, noise, default_dtype, fname, unit):
    """The LOS (or reported winds) in their floating dtype (else `default_dtype`), the
    weights broadcast to them (NaN -> 0, refused if negative or infinite) and the noise
    broadcast to ``(..., h)`` (NaN: estimate it; refused if not positive)."""
    los = jnp.asarray(los)
    dtype = los.dtype if jnp.issubdtype(los.dtype, jnp.floating) else default_dtype
    los = los.astype(dtype)
    shape = los.shape
    if weights is None:
        weights = jnp.ones(shape, dtype)
    else:
        weights = _broadcast_input("weights", weights, shape, dtype, f"{unit} shape")
        if is_concrete(weights):
            wn = np.asarray(weights)
            if np.any(wn < 0) or np.any(np.isinf(wn)):
                raise ValueError(
                    f"{fname}: `weights` must be finite and nonnegative (relative inverse "
                    f"variances; NaN or 0 drops a beam)."
                )
        weights = jnp.where(jnp.isnan(weights), 0.0, weights)
    if noise is None:
        noise = jnp.full(shape[:-1], jnp.nan, dtype)
    else:
        noise = _broadcast_input("noise", noise, shape[:-1], dtype, "(..., h)")
        if is_concrete(noise) and np.any(~(np.asarray(noise) > 0)):
            raise ValueError(f"{fname}: `noise` must be positive (m/s), or None to estimate it.")
    return los, weights, noise


def _run(spline, values, knots, valid, los, weights, noise, *, min_beams, max_steps, solver,
         batch_size, fname, unit):
    los, weights, noise = _los_inputs(los, weights, noise, values.dtype, fname, unit)
    dtype, shape = los.dtype, los.shape
    if int(min_beams) < 2:
        raise ValueError(
            f"{fname}: `min_beams` must be at least 2 (two unknowns), got {min_beams}."
        )
    if int(max_steps) < 1:
        raise ValueError(f"{fname}: `max_steps` must be positive, got {max_steps}.")
    if solver is None:
        solver = default_solver(dtype)
    spline, values, knots = _cast_floats((spline, values, knots), dtype)
    cfg = (solver, int(max_steps), int(min_beams))
    *batch, h, b = shape
    n = int(np.prod(batch, dtype=np.int64))
    per_batch, n_pad = _batching(batch_size, n, h, b, values.shape[0], np.dtype(dtype).itemsize,
                                 fname)
    if not is_concrete(los, weights, noise):
        n_pad = n  # inside a transformation the caller's compilation fixes the shapes anyway
    los, weights, noise = _records(los, weights, noise, n_pad)
    out = _invert_core(spline, values, knots, valid, los, weights, noise, cfg, per_batch,
                       jnp.asarray(n, jnp.int32))
    return _unpad(out, n, tuple(batch))


@functools.partial(jax.jit, static_argnums=3)
def _records(los, weights, noise, n_pad):
    """Flatten the leading axes to ``n`` records and append ``n_pad - n`` dummy records (no
    usable beam: solved trivially, skipped where a whole batch is dummy, dropped by
    `_unpad`). One small compilation per length, not one per eager operation."""
    *_, h, b = los.shape
    los, weights, noise = los.reshape(-1, h, b), weights.reshape(-1, h, b), noise.reshape(-1, h)
    pad = n_pad - los.shape[0]
    if pad > 0:
        los = jnp.concatenate([los, jnp.zeros((pad, h, b), los.dtype)])
        weights = jnp.concatenate([weights, jnp.zeros((pad, h, b), weights.dtype)])
        noise = jnp.concatenate([noise, jnp.full((pad, h), jnp.nan, noise.dtype)])
    return los, weights, noise


@functools.partial(jax.jit, static_argnums=(1, 2))
def _unpad(out, n, batch):
    """The first `n` records of `out`, with the caller's leading axes `batch`."""
    return jax.tree_util.tree_map(lambda x: x[:n].reshape(batch + x.shape[1:]), out)


def invert(
    table: ResponseTable,
    los: Float[ArrayLike, "... h b"],
    *,
    weights: Float[ArrayLike, "... h b"] | None = None,
    noise: Float[ArrayLike, "... h"] | None = None,
    min_beams: int = 3,
    max_steps: int = 32,
    solver: optx.AbstractLeastSquaresSolver | None = None,
    batch_size: int | str | None = None,
) -> Inversion:
    """Free-stream speed and direction from raw LOS records, per record and height.

    **Arguments:**

    - `table`: the site's `ResponseTable` (``h`` heights, ``b`` beams).
    - `los`: ``(..., h, b)`` measured LOS velocities, m/s, positive away from the lidar,
      beams ordered as in the table. NaN marks a missing beam.
    - `weights`: optional, broadcastable to ``(..., h, b)``: relative inverse variances of
      the beams (default 1); 0 or NaN drops a beam.
    - `noise`: optional, broadcastable to ``(..., h)``: the LOS noise standard deviation of a
      beam of unit weight, m/s; if None it is estimated from the residuals of each problem
      (needs more beams than the two unknowns).
    - `min_beams`: fewest usable beams for an answer (default 3, so one beam is spare).
    - `max_steps`: bound on solver steps per problem.
    - `solver`: an optimistix least-squares solver (default `default_solver`: Gauss--Newton,
      which takes 3 to 6 steps from the tabulated start; `optimistix.LevenbergMarquardt` is
      also fine but takes two to four times more steps). Its tolerances are relative: the
      problem is solved in units of the record's RMS LOS.
    - `batch_size`: problems (record-heights) per vmapped batch, rounded down to whole
      records; batches run one after another, which bounds memory for large campaigns, and
      each runs only as many steps as its slowest member. None (default) chooses per backend
      (`lidarjax._backend.default_batch`): `DEFAULT_BATCH_SIZE` (512) on a CPU; on a GPU or
      TPU the whole campaign at once when it fits in a quarter of the free device memory
      (else the largest batch that does). ``"all"`` solves everything at once. (Up to
      lidarjax 0.1.0, None meant all at once; pass ``"all"`` for that now.)

    **Compilations.** Outside `jax.jit`, the records (all leading axes together) are padded
    with dummy records, whose results are dropped, up to a bucket of 1, 2, 3, 4, 6, 8, 12,
    ... records, or batches when there are several: files of different lengths share a
    handful of compilations, and padding never changes a result (every problem is solved
    independently). Inside a transformation the caller's shapes are used as they are.

    **Returns:** an `Inversion` whose arrays are shaped ``(..., h)``, in the dtype of `los`
    (float32 input gives float32 results).

    Raises `ValueError` before compiling for shapes that do not match the table, negative
    weights or non-positive noise. Never raises for bad data: those records come back NaN
    with ``converged=False`` and a reason in `flags`.
    """
    if not isinstance(table, ResponseTable):
        raise ValueError(
            f"invert: `table` must be a lidarjax.ResponseTable, got {type(table).__name__}."
        )
    los_shape = jnp.shape(los)
    want = (table.n_heights, table.n_beams)
    if len(los_shape) < 2 or tuple(los_shape[-2:]) != want:
        raise ValueError(
            f"invert: `los` must be shaped (..., h, b) with (h, b) = {want} as in the table; got "
            f"{tuple(los_shape)}."
        )
    return _run(
        table.response_spline, table.response, table.directions, table.valid, los, weights,
        noise, min_beams=min_beams, max_steps=max_steps, solver=solver, batch_size=batch_size,
        fname="invert", unit="los",
    )


def invert_reconstructed(
    table: ResponseTable,
    speed: Float[ArrayLike, "... h"],
    direction: Float[ArrayLike, "... h"],
    *,
    noise: Float[ArrayLike, "... h"] | None = None,
    max_steps: int = 32,
    solver: optx.AbstractLeastSquaresSolver | None = None,
    batch_size: int | str | None = None,
) -> Inversion:
    """Free-stream speed and direction from the instrument's reconstructed records
    (``.sta``-style horizontal speed and direction per height).

    The reported horizontal vector ``(u, v)`` is modelled as ``U * Rrec_h(d)`` with the
    table's `reconstructed` response, and solved exactly like `invert` with the two vector
    components as two "beams". Two equations for two unknowns: the standard deviations need
    `noise` (the standard deviation of each reported component, m/s), else they are NaN.

    **Arguments:**

    - `table`: a `ResponseTable` with `reconstructed` (e.g. from `from_simulations`).
    - `speed`: ``(..., h)`` reported horizontal speed, m/s. A negative speed is impossible:
      that record-height is NaN, flagged `InverseFlag.IMPOSSIBLE_INPUT` (and
      `TOO_FEW_BEAMS`), never read as the opposite direction.
    - `direction`: ``(..., h)`` reported meteorological direction, degrees (north frame);
      NaN is allowed where the speed is 0 (calm).
    - `noise`, `max_steps`, `solver`, `batch_size`: as for `invert`.

    **Returns:** an `Inversion` shaped ``(..., h)``.
    """
    if not isinstance(table, ResponseTable):
        raise ValueError(
            f"invert_reconstructed: `table` must be a lidarjax.ResponseTable, got "
            f"{type(table).__name__}."
        )
    if table.reconstructed is None:
        raise ValueError(
            "invert_reconstructed: the table has no `reconstructed` response; build it with "
            "ResponseTable.from_simulations or pass `reconstructed=`."
        )
    speed = jnp.asarray(speed)
    direction = jnp.asarray(direction)
    try:
        shape = jnp.broadcast_shapes(speed.shape, direction.shape)
    except ValueError:
        raise ValueError(
            f"invert_reconstructed: `speed` {speed.shape} and `direction` {direction.shape} do "
            f"not broadcast together."
        ) from None
    if len(shape) < 1 or shape[-1] != table.n_heights:
        raise ValueError(
            f"invert_reconstructed: `speed` and `direction` must be shaped (..., h) with "
            f"h = {table.n_heights} as in the table; got {shape}."
        )
    dtype = speed.dtype if jnp.issubdtype(speed.dtype, jnp.floating) else table.dtype
    speed = jnp.broadcast_to(speed, shape).astype(dtype)
    direction = jnp.broadcast_to(direction, shape).astype(dtype)
    uv, impossible = _reported_uv(speed, direction)
    spline = table.reconstructed_spline
    sub = PeriodicSpline(
        spline.start, spline.offsets, spline.widths, spline.coefficients[..., :2], spline.uniform
    )
    valid = jnp.ones((table.n_heights, 2), bool)
    out = _run(
        sub, table.reconstructed[..., :2], table.directions, valid, uv, None, noise,
        min_beams=2, max_steps=max_steps, solver=solver, batch_size=batch_size,
        fname="invert_reconstructed", unit="(..., h, 2)",
    )
    flag = jnp.where(impossible, int(InverseFlag.IMPOSSIBLE_INPUT), 0).astype(out.flags.dtype)
    return eqx.tree_at(lambda r: r.flags, out, out.flags | flag)


@compiled
def _reported_uv(speed, direction):
    """Reported winds (speed m/s, meteorological direction degrees) as horizontal vectors
    ``(..., 2)`` (m/s, toward which the wind blows), NaN for a negative speed, and where the
    speed is negative (never reinterpreted as the opposite direction)."""
    calm = speed == 0
    impossible = speed < 0
    rad = jnp.deg2rad(jnp.where(calm, 0.0, direction))
    uv = jnp.stack([-speed * jnp.sin(rad), -speed * jnp.cos(rad)], axis=-1)
    return jnp.where(impossible[..., None], jnp.nan, uv), impossible


# ------------------------------------------------------------------------------------------
# Joint inversion across heights (tables over direction x a profile parameter)


class JointInversion(eqx.Module):
    """Results of `invert_joint`: one solution per record, shaped ``(...)`` (the records'
    leading axes), plus what it implies at each height ``(..., h)``.

    - `speed`: free-stream horizontal speed at the profile's reference height, m/s.
    - `direction`: free-stream meteorological direction (from, degrees clockwise from north,
      in ``[0, 360)``), the same at every height.
    - `parameter`: the profile parameter (the table's `name`, in its unit; e.g. the shear
      exponent alpha).
    - `speed_std`, `direction_std`, `parameter_std`: one-sigma uncertainties (m/s, degrees,
      parameter unit) from the Jacobian at the solution, ``sigma**2 (J^T W J)^-1``; with the
      noise estimated from ``dof = n_beams - 3`` spare beams use Student's t for `dof`.
    - `correlation`: ``(..., 3, 3)`` correlation matrix of (speed, direction, parameter).
    - `height_speed`, `height_speed_std`: ``(..., h)`` the free-stream speed at each of the
      table's heights, ``speed * profile(z_h, parameter)``, and its one-sigma uncertainty
      (delta method through the covariance).
    - `converged`, `residual_rms` (m/s), `noise` (m/s, given or estimated), `n_beams`
      (usable beams over all heights), `num_steps`, `result` (`optimistix.RESULTS`),
      `flags` (`InverseFlag` bits; `PARAMETER_EXTRAPOLATED` when the parameter lies outside
      the table's range).
    """

    speed: Float[Array, ...]
    direction: Float[Array, ...]
    parameter: Float[Array, ...]
    speed_std: Float[Array, ...]
    direction_std: Float[Array, ...]
    parameter_std: Float[Array, ...]
    correlation: Float[Array, "... 3 3"]
    height_speed: Float[Array, "... h"]
    height_speed_std: Float[Array, "... h"]
    converged: Bool[Array, ...]
    residual_rms: Float[Array, ...]
    noise: Float[Array, ...]
    n_beams: Int[Array, ...]
    num_steps: Int[Array, ...]
    result: optx.RESULTS
    flags: Int[Array, ...]

    @property
    def dof(self) -> Int[Array, ...]:
        """Spare beams behind the noise estimate: ``n_beams - 3``."""
        return self.n_beams - 3


class _JointContext(eqx.Module):
    """What the per-record model needs: the direction spline over ``(p, h, b)``, the
    parameter interpolation, the heights and the profile."""

    geom: tuple
    coefficients: Array  # (4, s, p, h, b)
    pknots: Array
    pwidths: Array
    pbasis: Array
    heights: Array
    profile: AbstractProfile
    centre: Array
    span: Array


def _joint_shape(ctx: _JointContext, d, a):
    """``profile(z_h, a) * R_hb(d, a)`` ``(h, b)``: LOS per unit reference speed."""
    v = spline_at(ctx.geom, ctx.coefficients, d)  # (p, h, b)
    w = parameter_weights(ctx.pknots, ctx.pwidths, ctx.pbasis, a, extrapolate=True)
    r = jnp.einsum("p,phb->hb", w, v, precision=HIGHEST)
    return ctx.profile(ctx.heights, a)[:, None] * r


def _joint_residuals(y, args):
    los, sw, ctx = args
    speed, d, _ = _polar(y[:2])
    a = ctx.centre + y[2] * ctx.span
    return (sw * (los - speed * _joint_shape(ctx, d, a))).reshape(-1)


def _joint_start_and_solve(los, sw, trivial, d0, a0, u0, ctx, solver, max_steps):
    """Least squares over ``(u, v, scaled parameter)`` from the tabulated start; a problem
    that cannot start (`trivial`) is swapped for the table's own shape at the start."""
    unit = jnp.stack([-jnp.sin(jnp.deg2rad(d0)), -jnp.cos(jnp.deg2rad(d0))])
    args = (jnp.where(trivial, _joint_shape(ctx, d0, a0), los),
            jnp.where(trivial, jnp.ones_like(sw), sw), ctx)
    s0 = (a0 - ctx.centre) / ctx.span
    y0 = jax.lax.stop_gradient(jnp.concatenate([jnp.where(trivial, unit, u0 * unit), s0[None]]))
    return optx.least_squares(_joint_residuals, solver, y0, args, max_steps=max_steps,
                              throw=False)


def _joint_covariance(wf, jac, sigma2, dtype):
    """``sigma**2 (J^T W J)^-1`` of (speed, direction, parameter) (equilibrated before the
    conditioning test), its standard deviations, correlation and whether it is well posed."""
    m = jnp.einsum("n,ni,nj->ij", wf, jac, jac, precision=HIGHEST)
    diag = jnp.sqrt(jnp.maximum(jnp.diagonal(m), 0.0))
    pos = diag > 0
    dn = jnp.where(pos, diag, 1.0)
    mn = m / (dn[:, None] * dn[None, :])
    eig = jnp.linalg.eigvalsh(jnp.where(jnp.all(pos), mn, jnp.eye(3, dtype=dtype)))
    rcond = jnp.sqrt(jnp.finfo(dtype).eps)
    well_posed = jnp.all(pos) & (eig[0] > rcond * eig[-1])
    inv = jnp.linalg.inv(jnp.where(well_posed, mn, jnp.eye(3, dtype=dtype)))
    cov = sigma2 * inv / (dn[:, None] * dn[None, :])
    std = jnp.sqrt(jnp.maximum(jnp.diagonal(cov), 0.0))
    sd = jnp.where(std > 0, std, 1.0)
    return cov, std, cov / (sd[:, None] * sd[None, :]), well_posed


def _joint_one(los, w, noise, k, j, u0, scale, ctx, knots, cfg):
    """One record: `los`, `w` ``(h, b)`` cleaned and in units of `scale`; `noise` scalar
    (m/s, NaN: estimate); start: direction knot `k`, parameter index `j`, speed `u0`."""
    solver, max_steps, min_beams = cfg
    dtype = los.dtype
    n_beams, sw = _usable(w)
    d0 = knots[k]
    trivial = (u0 <= 0) | (n_beams < min_beams)
    sol = _joint_start_and_solve(los, sw, trivial, d0, ctx.pknots[j], u0, ctx, solver,
                                 max_steps)
    y = sol.value
    speed, d, calm = _polar(y[:2])
    d = jnp.where(calm, d0, d)
    a = ctx.centre + y[2] * ctx.span

    def model(theta):
        return (theta[0] * _joint_shape(ctx, theta[1], theta[2])).reshape(-1)

    theta = jnp.stack([speed, d, a])
    jac = jax.jacfwd(model)(theta)  # (n, 3); direction per degree
    wf = w.reshape(-1)
    residual_rms, sigma2 = _noise_level(wf, los.reshape(-1) - model(theta), n_beams, 3, noise,
                                        scale)
    cov, std, corr, well_posed = _joint_covariance(wf, jac, sigma2, dtype)
    # the speed at each height and its uncertainty
    f, df = jax.jvp(lambda x: ctx.profile(ctx.heights, x), (a,), (jnp.ones_like(a),))
    g = jnp.stack([f, jnp.zeros_like(f), speed * df], axis=-1)  # (h, 3)
    hs_var = jnp.einsum("hi,ij,hj->h", g, cov, g, precision=HIGHEST)

    ok_solver = sol.result == optx.RESULTS.successful
    finite = jnp.all(jnp.isfinite(y))
    enough = n_beams >= min_beams
    converged = ok_solver & finite & enough & (well_posed | calm) & ~(u0 <= 0)
    calm = calm | (u0 <= 0)
    outside = (a < ctx.pknots[0] - 1e-9 * ctx.span) | (a > ctx.pknots[-1] + 1e-9 * ctx.span)
    flags = (
        jnp.where(enough, 0, int(InverseFlag.TOO_FEW_BEAMS))
        | jnp.where((ok_solver & finite) | ~enough | calm, 0, int(InverseFlag.NOT_CONVERGED))
        | jnp.where(well_posed | ~enough | calm, 0, int(InverseFlag.ILL_CONDITIONED))
        | jnp.where(enough & calm, int(InverseFlag.CALM), 0)
        | jnp.where(converged & jnp.isnan(sigma2), int(InverseFlag.NO_NOISE_ESTIMATE), 0)
        | jnp.where(converged & outside, int(InverseFlag.PARAMETER_EXTRAPOLATED), 0)
    )
    nan = jnp.asarray(jnp.nan, dtype)
    return dict(
        speed=jnp.where(converged, speed * scale, nan),
        direction=jnp.where(converged, _wrap360(d), nan),
        parameter=jnp.where(converged, a, nan),
        speed_std=jnp.where(converged, std[0] * scale, nan),
        direction_std=jnp.where(converged, std[1], nan),
        parameter_std=jnp.where(converged, std[2], nan),
        correlation=jnp.where(converged, corr, nan),
        height_speed=jnp.where(converged, speed * f * scale, nan),
        height_speed_std=jnp.where(converged, jnp.sqrt(jnp.maximum(hs_var, 0.0)) * scale, nan),
        converged=converged,
        residual_rms=residual_rms * scale,
        noise=jnp.sqrt(sigma2) * scale,
        n_beams=n_beams,
        num_steps=sol.stats["num_steps"].astype(jnp.int32),
        result=sol.result,
        flags=flags.astype(jnp.int32),
    )


def _joint_batch(los, w, noise, values, knots, ctx, cfg):
    """Records ``(r, h, b)``: dense start over directions x parameters, then one solve per
    record. `values` ``(s, p, h, b)``: tabulated LOS per unit reference speed."""
    usable = (w > 0) & jnp.isfinite(los)
    w = jnp.where(usable, w, 0.0)
    los = jnp.where(usable, los, 0.0)
    # given noise per height: weights become inverse variances, the noise level 1 m/s
    given = ~jnp.isnan(noise)
    w = jnp.where(given[..., None], w / jnp.where(given, noise, 1.0)[..., None] ** 2, w)
    noise_r = jnp.where(jnp.any(given, axis=-1), 1.0, jnp.nan).astype(los.dtype)
    peak = jnp.max(jnp.abs(los), axis=(-2, -1))
    peak = jnp.where(peak > 0, peak, 1.0)
    wsum = jnp.sum(w, axis=(-2, -1))
    x = los / peak[:, None, None]
    scale = peak * jnp.sqrt(jnp.sum(w * x * x, axis=(-2, -1)) / jnp.where(wsum > 0, wsum, 1.0))
    scale = jax.lax.stop_gradient(jnp.where(scale > 0, scale, 1.0))
    los = los / scale[:, None, None]
    p = values.shape[1]
    best, u0 = tabulated_start(w, los, values, "rhb,sphb->rsp", 1)
    k, j = best // p, best % p

    def one(los_i, w_i, noise_i, k_i, j_i, u0_i, scale_i):
        return _joint_one(los_i, w_i, noise_i, k_i, j_i, u0_i, scale_i, ctx, knots, cfg)

    return jax.vmap(one)(los, w, noise_r, k, j, u0, scale)


@eqx.filter_jit
def _joint_core(ctx, values, knots, valid, los, weights, noise, cfg, per_batch, n_real):
    n, h, b = los.shape
    w_r = weights * valid
    values = jnp.where(valid, values, 0.0)

    def run(x):
        return _joint_batch(*x, values, knots, ctx, cfg)

    out = _in_batches(run, los, w_r, noise, per_batch, n_real)
    return JointInversion(**out)


def _joint_run(table, spline, per_profile, los, weights, noise, *, profile, min_beams,
               max_steps, solver, batch_size, fname, valid):
    """Shared by `invert_joint` and `invert_joint_reconstructed`: `spline` over
    ``(p, h, k)``, `per_profile` ``(p, s, h, k)`` tabulated values per unit local speed."""
    if table.heights is None:
        raise ValueError(f"{fname}: the table has no heights; the profile needs them (build "
                         "it with heights, e.g. lidarjax table).")
    profile = table.profile if profile is None else profile
    if not isinstance(profile, AbstractProfile):
        raise ValueError(f"{fname}: `profile` must be a lidarjax.AbstractProfile "
                         "(PowerLawProfile(reference_height), UniformProfile()) or None.")
    los, weights, noise = _los_inputs(los, weights, noise, table.dtype, fname, "los")
    dtype, shape = los.dtype, los.shape
    if int(min_beams) < 3:
        raise ValueError(f"{fname}: `min_beams` must be at least 3 (three unknowns), got "
                         f"{min_beams}.")
    if int(max_steps) < 1:
        raise ValueError(f"{fname}: `max_steps` must be positive, got {max_steps}.")
    if solver is None:
        solver = default_solver(dtype)
    heights = jnp.asarray(table.heights, dtype)
    pk = jnp.asarray(table.parameters, dtype)
    factors = profile(heights, pk)  # (p, h)
    values = jnp.swapaxes(per_profile, 0, 1) * factors[None, :, :, None]  # (s, p, h, k)
    ctx = _JointContext(
        geom=(spline.start, spline.offsets, spline.widths, spline.uniform),
        coefficients=spline.coefficients, pknots=pk,
        pwidths=jnp.asarray(table.parameter_widths, dtype),
        pbasis=jnp.asarray(table.parameter_basis, dtype), heights=heights, profile=profile,
        centre=0.5 * (pk[0] + pk[-1]), span=0.5 * (pk[-1] - pk[0]))
    ctx, values, knots = _cast_floats((ctx, values, jnp.asarray(table.directions)), dtype)
    cfg = (solver, int(max_steps), int(min_beams))
    *batch, h, b = shape
    n = int(np.prod(batch, dtype=np.int64))
    per_batch, n_pad = _batching(batch_size, n, h, b, values.shape[0] * values.shape[1],
                                 np.dtype(dtype).itemsize, fname)
    if not is_concrete(los, weights, noise):
        n_pad = n
    los, weights, noise = _records(los, weights, noise, n_pad)
    out = _joint_core(ctx, values, knots, valid, los, weights, noise, cfg, per_batch,
                      jnp.asarray(n, jnp.int32))
    return _unpad(out, n, tuple(batch))


def _need_profile_table(table, fname):
    if isinstance(table, ResponseTable):
        raise ValueError(
            f"{fname}: the table has no profile axis (a ResponseTable over directions only); "
            "invert each height with lidarjax.invert, or build a ProfileTable (lidarjax table "
            "--param NAME=V1,V2,...).")
    if not isinstance(table, ProfileTable):
        raise ValueError(f"{fname}: `table` must be a lidarjax.ProfileTable, got "
                         f"{type(table).__name__}.")


def invert_joint(
    table: ProfileTable,
    los: Float[ArrayLike, "... h b"],
    *,
    weights: Float[ArrayLike, "... h b"] | None = None,
    noise: Float[ArrayLike, "... h"] | None = None,
    profile: AbstractProfile | None = None,
    min_beams: int = 4,
    max_steps: int = 32,
    solver: optx.AbstractLeastSquaresSolver | None = None,
    batch_size: int | str | None = None,
) -> JointInversion:
    """Speed and direction at the reference height and the profile parameter, per record,
    from the LOS of all heights in one least-squares problem.

    The model of beam ``b`` at height ``z_h`` is
    ``los_hb = U * profile(z_h, a) * R_hb(d, a)``: the reference-height free-stream speed
    ``U`` (m/s), the profile (`table.profile`, or `profile`: the static modelling choice,
    e.g. `PowerLawProfile` ``(z / z_ref) ** alpha``), and the table's response per unit local
    free-stream speed at direction ``d`` and parameter ``a`` (`ProfileTable.response_at`,
    continued linearly outside the parameter range with the flag
    `InverseFlag.PARAMETER_EXTRAPOLATED`). Unknowns ``(u, v, a)``, Gauss--Newton from the
    best tabulated (direction, parameter) with its closed-form speed, as `invert`.

    **Arguments:**

    - `table`: a `lidarjax.ProfileTable` with heights (a `ResponseTable` is refused: use
      `invert` per height).
    - `los`: ``(..., h, b)`` LOS, m/s, positive away from the lidar; NaN marks a missing beam.
    - `weights`: optional ``(..., h, b)`` relative inverse variances (0 or NaN drops a beam).
    - `noise`: optional ``(..., h)`` LOS noise (m/s) of a beam of unit weight per height; if
      None one level per record is estimated from the residuals (``n_beams - 3`` spare).
    - `profile`: replaces the table's profile (None: the table's).
    - `min_beams`: fewest usable beams over all heights (default 4: one spare).
    - `max_steps`, `solver`, `batch_size`: as for `invert` (`batch_size` counts
      record-heights, rounded down to whole records).

    **Returns:** a `JointInversion` shaped ``(...)`` (``(..., h)`` for the per-height
    speeds), in the dtype of `los`. Bad records come back NaN with ``converged=False`` and a
    reason in `flags`; the others are unaffected. Raises `ValueError` before compiling for
    a table without a profile axis or heights, shapes that do not match, negative weights,
    non-positive noise.
    """
    _need_profile_table(table, "invert_joint")
    los_shape = jnp.shape(los)
    want = (table.n_heights, table.n_beams)
    if len(los_shape) < 2 or tuple(los_shape[-2:]) != want:
        raise ValueError(f"invert_joint: `los` must be shaped (..., h, b) with (h, b) = {want} "
                         f"as in the table; got {tuple(los_shape)}.")
    return _joint_run(table, table.response_spline, table.response, los, weights, noise,
                      profile=profile, min_beams=min_beams, max_steps=max_steps, solver=solver,
                      batch_size=batch_size, fname="invert_joint", valid=table.valid)


def invert_joint_reconstructed(
    table: ProfileTable,
    speed: Float[ArrayLike, "... h"],
    direction: Float[ArrayLike, "... h"],
    *,
    noise: Float[ArrayLike, "... h"] | None = None,
    profile: AbstractProfile | None = None,
    max_steps: int = 32,
    solver: optx.AbstractLeastSquaresSolver | None = None,
    batch_size: int | str | None = None,
) -> JointInversion:
    """`invert_joint` from the instrument's reported speed and direction per height
    (``.sta``): the reported horizontal vector of each height is modelled as
    ``U * profile(z_h, a) * Rrec_h(d, a)`` with the tables' `reconstructed` response (the
    two components as two "beams"). `speed` (m/s; a negative speed is impossible:
    that height is dropped and the record flagged `IMPOSSIBLE_INPUT`, never read as the
    opposite direction), `direction` (degrees) ``(..., h)``; `noise` per component (m/s);
    other arguments as `invert_joint`. Needs two heights or more."""
    _need_profile_table(table, "invert_joint_reconstructed")
    if table.reconstructed_spline is None:
        raise ValueError("invert_joint_reconstructed: the table has no `reconstructed` "
                         "response; build it with ResponseTable.from_simulations.")
    speed = jnp.asarray(speed)
    direction = jnp.asarray(direction)
    try:
        shape = jnp.broadcast_shapes(speed.shape, direction.shape)
    except ValueError:
        raise ValueError(f"invert_joint_reconstructed: `speed` {speed.shape} and `direction` "
                         f"{direction.shape} do not broadcast together.") from None
    if len(shape) < 1 or shape[-1] != table.n_heights:
        raise ValueError(f"invert_joint_reconstructed: `speed` and `direction` must be shaped "
                         f"(..., h) with h = {table.n_heights}; got {shape}.")
    dtype = speed.dtype if jnp.issubdtype(speed.dtype, jnp.floating) else table.dtype
    speed = jnp.broadcast_to(speed, shape).astype(dtype)
    direction = jnp.broadcast_to(direction, shape).astype(dtype)
    uv, impossible = _reported_uv(speed, direction)
    sp = table.reconstructed_spline
    sub = PeriodicSpline(sp.start, sp.offsets, sp.widths, sp.coefficients[..., :2], sp.uniform)
    valid = jnp.ones((table.n_heights, 2), bool)
    out = _joint_run(table, sub, table.reconstructed[..., :2], uv, None, noise,
                     profile=profile, min_beams=3, max_steps=max_steps, solver=solver,
                     batch_size=batch_size, fname="invert_joint_reconstructed", valid=valid)
    bad = jnp.any(impossible, axis=-1)
    flag = jnp.where(bad, int(InverseFlag.IMPOSSIBLE_INPUT), 0).astype(out.flags.dtype)
    return eqx.tree_at(lambda r: r.flags, out, out.flags | flag)
