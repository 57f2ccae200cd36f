"""Installation calibration: constant north offset and tilt estimated from many records.

A lidar installed with a north offset ``epsilon`` and a tilt ``(pitch, roll)`` that differ
from what its response table assumed (`ResponseTable.instrument`, 0 when unknown) measures,
for a free stream of speed ``U`` and true meteorological direction ``d``, beam by beam,

``los_hb = U * [R_hb(d - de) + ((M(dp, dr) - I) n_b) . V_hb(d - de)]``

- ``R_hb``: the table's LOS response (per unit free-stream speed) at the direction the table
  sees, ``d - de``: with the software north offset wrong by ``de = epsilon_true -
  epsilon_table`` every direction label is shifted by ``-de`` (`lidarjax.frames`:
  ``v_north = R(-epsilon) v_lidar``, so bearings grow by epsilon).
- ``n_b``: the table's beam unit vectors (north frame); ``M = Rz(-e0) T(p0 + dp, r0 + dr)
  T(p0, r0)^T Rz(e0)`` the change of beam directions by the tilt offsets (``T`` the
  installation tilt of `lidarjax.tilt_rotation`, ``e0, p0, r0`` the table's installation).
- ``V_hb``: the flow at the beam points per unit free-stream speed: the table's
  `beam_velocity` when it has one, else its centre-line `point` velocity, else the
  undisturbed horizontal free stream. Its vertical component is what a tilt turns into the
  horizontal and back; the error of this first-order model is of order (tilt x distortion).
  The focus points' small displacement by the tilt is neglected (second order).

`calibrate` finds the offsets ``theta`` (any subset of ``("epsilon", "pitch", "roll")``,
degrees) that minimise the sum of squared LOS residuals over all records and heights,
jointly with every record-height's own free stream (the nuisances: ``(u, v)`` without a
reference, the speed ``U`` with a reference direction). The Jacobian of the forward model
(``jax.jacfwd``) gives Gauss--Newton steps in which each record-height's nuisances are
eliminated exactly (Schur complement: the reduced gradient is the gradient through the
per-record inversion, by the implicit function theorem), so a year of records costs a few
passes over the data.

**What is identifiable.**

- *With a reference* (free-stream speed and direction at the same heights from a mast,
  another lidar or a model): epsilon (the mean rotation between the inverted and reference
  directions, weighted by the table's sensitivity), pitch and roll.
- *Without a reference*: pitch and roll, from the vertical beam and from how the apparent
  vertical wind (and the slanted beams' sum) varies with direction: a tilt turns the
  horizontal wind into an apparent ``w = U (sin(dr) u_hat - sin(dp) v_hat)`` that follows
  the wind direction, while the true mean ``w`` of the table does not. It needs records from
  several directions. **Epsilon is not identifiable without a reference**: rotating every
  direction by the same angle fits the records exactly as well (its Jacobian column is the
  direction's). `calibrate` then returns NaN for it, ``identifiable = False`` and says so in
  `notes`.

**Uncertainty.** ``cov = H^-1 B H^-1`` (the sandwich, `covariance="robust"`, default) with
``H`` the reduced Gauss--Newton matrix and ``B`` the sum over records of the outer products
of each record's reduced gradient (so noise correlated between the beams and heights of one
record, and noise that varies between records, are accounted for), scaled by
``n / (n - k)``; or ``sigma**2 H^-1`` (`covariance="model"`) with ``sigma`` estimated from
the residuals. 95 % intervals are ``offset +- 1.96 std``.

Angles in degrees, north frame, meteorological directions (from, clockwise from north).
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from ._precision import HIGHEST, is_concrete
from .frames import rotation_z, tilt_rotation
from .response import ProfileTable, ResponseTable, locate

__all__ = ["Calibration", "calibrate", "CALIBRATION_PARAMETERS"]

#: The installation offsets `calibrate` can estimate, in this order.
CALIBRATION_PARAMETERS = ("epsilon", "pitch", "roll")

#: Largest change of (epsilon, pitch, roll) per Gauss--Newton pass, degrees (a trust region).
_MAX_STEP = np.array([5.0, 1.0, 1.0])

#: Gauss--Newton stops when no offset moved more than this in a pass, degrees.
_TOLERANCE = 1e-7

#: A free offset is identifiable when the normalised reduced matrix's smallest eigenvalue
#: along it exceeds this fraction of the largest (offsets correlated beyond 0.9999 are not).
IDENTIFIABILITY_RCOND = 1e-4

_NOT_IDENTIFIABLE_EPSILON = (
    "epsilon (north offset) is not identifiable without a reference: rotating every "
    "direction by one angle fits the records equally well; give reference=(speed, direction) "
    "from a mast, another lidar or a model")


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
      record-heights used; `iterations`: passes taken; `converged` (last step below 1e-6
      degrees and every number finite).
    - `notes`: what the records could not tell, in words.
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
    n_records: int = eqx.field(static=True)
    n_problems: int = eqx.field(static=True)
    iterations: int = eqx.field(static=True)
    converged: bool = eqx.field(static=True)
    notes: tuple[str, ...] = eqx.field(static=True)

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
# the forward model of one record-height


def _spline_and_slope(geom, coefficients, hidx, direction):
    """Values and direction derivatives (per degree) of a direction spline at one direction
    per problem: `coefficients` ``(4, s, h, ...)``, `hidx`, `direction` ``(n,)`` ->
    two ``(n, ...)`` arrays."""
    start, offsets, widths, uniform = geom
    k, t = locate(start, offsets, widths, uniform, direction)
    c = coefficients[:, k, hidx]  # (4, n, ...)
    tt = t.reshape(t.shape + (1,) * (c.ndim - 2))
    wd = widths[k].reshape(tt.shape)
    value = c[0] + tt * (c[1] + tt * (c[2] + tt * c[3]))
    slope = (c[1] + tt * (2.0 * c[2] + 3.0 * tt * c[3])) / wd
    return value, slope


def _tilt_change(theta_full, nominal):
    """``M - I`` (3x3, north frame of the table) for offsets ``(de, dp, dr)``."""
    e0, p0, r0 = nominal[0], nominal[1], nominal[2]
    t_new = tilt_rotation(p0 + theta_full[1], r0 + theta_full[2])
    t_old = tilt_rotation(p0, r0)
    m = rotation_z(-e0) @ t_new @ t_old.T @ rotation_z(e0)
    return m - jnp.eye(3, dtype=m.dtype)


def _model_and_jacobian(beta, theta, ref_dir, hidx, ctx):
    """LOS ``(n, b)`` of every record-height and its Jacobians, in closed form: in the
    nuisances `beta` ``(n, m)`` (``(u, v)`` m/s, or the speed with a reference direction)
    -> ``(n, b, m)``, and in the offsets ``(de, dp, dr)`` (degrees) -> ``(n, b, 3)``."""
    geom, rc, vc, vkind, nvec, nominal = ctx
    dtype = beta.dtype
    # the beams' change by the tilt offsets and its derivatives, once for all problems
    dn_of = lambda th: nvec @ _tilt_change(th, nominal).T  # noqa: E731  (b, 3)
    dn = dn_of(theta)
    ddn = jax.jacfwd(dn_of)(theta)  # (b, 3, 3[theta])
    if beta.shape[1] == 2:
        u, v = beta[:, 0], beta[:, 1]
        h2 = u * u + v * v
        pos = h2 > 0
        safe = jnp.where(pos, h2, 1.0)
        speed = jnp.where(pos, jnp.sqrt(safe), 0.0)
        d = jnp.rad2deg(jnp.arctan2(jnp.where(pos, -u, 0.0), jnp.where(pos, -v, 1.0)))
    else:
        speed, d = beta[:, 0], ref_dir
    dl = d - theta[0]
    r, dr = _spline_and_slope(geom, rc, hidx, dl)  # (n, b)
    if vkind == "beam":
        vel, dvel = _spline_and_slope(geom, vc, hidx, dl)  # (n, b, 3)
    elif vkind == "point":
        vel, dvel = _spline_and_slope(geom, vc, hidx, dl)  # (n, 3)
        vel, dvel = vel[:, None, :], dvel[:, None, :]
    else:
        rad = jnp.deg2rad(dl)
        zero = jnp.zeros_like(rad)
        vel = jnp.stack([-jnp.sin(rad), -jnp.cos(rad), zero], -1)[:, None, :]
        dvel = jnp.stack([-jnp.cos(rad), jnp.sin(rad), zero], -1)[:, None, :] * (np.pi / 180.0)
    f = r + jnp.sum(dn * vel, -1)  # (n, b) per unit speed
    df = dr + jnp.sum(dn * dvel, -1)  # per degree of direction
    model = speed[:, None] * f
    j_eps = -speed[:, None] * df
    j_tilt = speed[:, None, None] * jnp.einsum("bkt,nbk->nbt", ddn, jnp.broadcast_to(
        vel, f.shape + (3,)), precision=HIGHEST)  # (n, b, 3)
    j_theta = jnp.concatenate([j_eps[..., None], j_tilt[..., 1:]], -1)
    if beta.shape[1] == 2:
        deg = 180.0 / np.pi
        su = jnp.where(pos, u / jnp.where(pos, speed, 1.0), 0.0)
        sv = jnp.where(pos, v / jnp.where(pos, speed, 1.0), 0.0)
        du = jnp.where(pos, v / safe, 0.0) * deg  # d(direction)/du, degrees per m/s
        dv = jnp.where(pos, -u / safe, 0.0) * deg
        j_beta = jnp.stack([su[:, None] * f + speed[:, None] * df * du[:, None],
                            sv[:, None] * f + speed[:, None] * df * dv[:, None]], -1)
    else:
        j_beta = f[..., None]
    return model, j_beta.astype(dtype), j_theta.astype(dtype)


def _start(los, w, values):
    """Best tabulated direction and its closed-form speed per problem (as `invert`):
    problems ``(r * h, b)`` record-major, `values` ``(s, h, b)``."""
    s, h, b = values.shape
    los, w = los.reshape(-1, h, b), w.reshape(-1, h, b)
    a = jnp.einsum("rhb,shb->rhs", w * los, values, precision=HIGHEST)
    c = jnp.einsum("rhb,shb->rhs", w, values * values, precision=HIGHEST)
    uk = jnp.where((a > 0) & (c > 0), a / jnp.where(c > 0, c, 1.0), 0.0)
    k = jnp.argmax(a * uk, axis=-1)
    u0 = jnp.take_along_axis(uk, k[..., None], axis=-1)[..., 0]
    return k.reshape(-1), u0.reshape(-1)


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


@eqx.filter_jit
def _calibrate_core(los, w, ref_dir, hidx, rec, ctx, values, knots, free, iterations,
                    n_records, with_ref):
    """Schur-complement Gauss--Newton over the offsets (mask `free` of 3) and every
    problem's nuisances; returns the offsets, the reduced matrices and residual facts."""
    dtype = los.dtype
    n, b = los.shape
    k_start, u0 = _start(los, w, values)
    if with_ref:
        beta = u0[:, None]
        # start from the closed-form speed at the reference direction
        r_ref = _spline_and_slope(ctx[0], ctx[1], hidx, ref_dir)[0]
        num = jnp.sum(w * los * r_ref, -1)
        den = jnp.sum(w * r_ref * r_ref, -1)
        beta = jnp.where(den > 0, num / jnp.where(den > 0, den, 1.0), 0.0)[:, None]
    else:
        d0 = jnp.deg2rad(knots[k_start])
        beta = jnp.stack([-u0 * jnp.sin(d0), -u0 * jnp.cos(d0)], -1)
    theta = jnp.zeros(3, dtype)
    freef = free.astype(dtype)

    def pieces(beta, theta):
        model, jb, jt = _model_and_jacobian(beta, theta, ref_dir, hidx, ctx)
        r = los - model
        jt = jt * freef
        a = jnp.einsum("nb,nbi,nbj->nij", w, jb, jb, precision=HIGHEST)
        gb = jnp.einsum("nb,nbi,nb->ni", w, jb, r, precision=HIGHEST)
        c = jnp.einsum("nb,nbi,nbj->nij", w, jb, jt, precision=HIGHEST)
        ainv, ok = _small_inv(a)
        okf = ok.astype(dtype)
        tt = jnp.einsum("nb,nbi,nbj->nij", w, jt, jt, precision=HIGHEST)
        gt = jnp.einsum("nb,nbi,nb->ni", w, jt, r, precision=HIGHEST)
        ca = jnp.einsum("nki,nkl->nil", c, ainv, precision=HIGHEST)  # C^T A^-1 (n, 3, m)
        h_i = (tt - jnp.einsum("nil,nlj->nij", ca, c, precision=HIGHEST)) * okf[:, None, None]
        s_i = (gt - jnp.einsum("nil,nl->ni", ca, gb, precision=HIGHEST)) * okf[:, None]
        return r, h_i, s_i, ainv, gb, c, ok

    def solve_theta(hmat, g):
        eye = jnp.eye(3, dtype=dtype)
        hm = hmat * freef[:, None] * freef[None, :] + eye * (1.0 - freef)[:, None]
        return jnp.linalg.solve(hm, g * freef)

    limit = jnp.asarray(_MAX_STEP, dtype)

    def step(carry):
        it, beta, theta, _ = carry
        r, h_i, s_i, ainv, gb, c, ok = pieces(beta, theta)
        hmat, g = jnp.sum(h_i, 0), jnp.sum(s_i, 0)
        # a trust region: at most 5 degrees of north offset and 1 degree of tilt per pass
        dtheta = jnp.clip(solve_theta(hmat, g), -limit, limit)
        dbeta = jnp.einsum("nij,nj->ni", ainv, gb - jnp.einsum("nij,j->ni", c, dtheta))
        dbeta = jnp.where(ok[:, None], dbeta, 0.0)
        return it + 1, beta + dbeta, theta + dtheta, jnp.max(jnp.abs(dtheta))

    def going(carry):
        it, _, _, last = carry
        # at least three passes (the nuisances settle), then until the offsets stop moving
        return (it < iterations) & ((it < 3) | ~(last < _TOLERANCE))

    start = (jnp.asarray(0), beta, theta, jnp.asarray(jnp.inf, dtype))
    passes, beta, theta, last = jax.lax.while_loop(going, step, start)
    r, h_i, s_i, _, _, _, ok = pieces(beta, theta)
    hmat = jnp.sum(h_i, 0)
    # the sandwich's meat: per record, the sum of its problems' reduced gradients
    s_rec = jax.ops.segment_sum(s_i, rec, num_segments=n_records)
    meat = jnp.einsum("ri,rj->ij", s_rec, s_rec, precision=HIGHEST)
    wrss = jnp.sum(w * r * r * ok[:, None])
    nobs = jnp.sum((w > 0) & ok[:, None])
    n_ok = jnp.sum(ok)
    return (theta, hmat, meat, wrss, nobs, n_ok, last, jnp.sum(jnp.any(w > 0, -1) & ok),
            passes)


def _as_array(x, name):
    if x is None:
        return None
    a = np.asarray(x, np.float64)
    return a


def calibrate(
    records,
    table: ResponseTable,
    wrt: tuple[str, ...] | list[str] = CALIBRATION_PARAMETERS,
    reference=None,
    *,
    weights: Float[ArrayLike, "r h b"] | None = None,
    min_beams: int = 3,
    iterations: int = 12,
    covariance: str = "robust",
) -> Calibration:
    """Constant installation offsets (north offset, pitch, roll) from many records.

    **Arguments:**

    - `records`: LOS records ``(r, h, b)`` (m/s, positive away from the lidar, beams and
      heights as in the table; NaN marks a missing beam), or an object with a `los` array
      of that shape (a `lidarjax.RecordSet` of a ``.rtd`` file, whose `pitch` and `roll`
      header values are then compared with the estimate).
    - `table`: the site's `ResponseTable` with `beam_vectors` (and, best, `beam_velocity`
      or `point`), built for the nominal installation (`table.instrument`; level and
      ``epsilon = 0`` when it states none). For a `ProfileTable` pass ``table.at(value)``.
    - `wrt`: the offsets to estimate, any of ``("epsilon", "pitch", "roll")``.
    - `reference`: None, or the free stream at the records' times and the table's heights:
      a pair ``(speed, direction)`` of ``(r, h)`` arrays (m/s, meteorological degrees;
      speed may be None) or an object with `speed` and `direction` arrays. NaN marks a
      missing reference value (that record-height is not used). The offsets rest on the
      reference *directions*: the speed stays a free nuisance per record-height, so a
      reference whose speed calibration differs from the lidar's cannot bias the angles.
    - `weights`: optional ``(r, h, b)`` relative inverse variances of the beams.
    - `min_beams`: fewest usable beams for a record-height to count (default 3).
    - `iterations`: most Gauss--Newton passes over the records (default 12; each pass
      updates the offsets, by at most 5 degrees of epsilon and 1 degree of tilt, and every
      record-height's free stream; it stops once the offsets move less than 1e-7 degrees).
    - `covariance`: ``"robust"`` (record-clustered sandwich, default) or ``"model"``
      (``sigma**2 H^-1``); see the module docstring.

    **Returns:** a `Calibration`. Without a reference, epsilon is NaN with
    ``identifiable = False`` and a note. Raises `ValueError` before computing for unknown
    names in `wrt`, shapes that do not match the table, or a table without beam vectors.
    """
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
    dtype = los.dtype if jnp.issubdtype(los.dtype, jnp.floating) else table.dtype
    h, b = table.n_heights, table.n_beams
    if los.ndim != 3 or los.shape[1:] != (h, b):
        raise ValueError(f"{fname}: `records` must be LOS shaped (r, h, b) with (h, b) = "
                         f"{(h, b)} as in the table; got {tuple(los.shape)}.")
    if table.beam_vectors is None:
        raise ValueError(f"{fname}: the table has no beam_vectors; build it with a mount "
                         "(ResponseTable.from_simulations(mount=...), lidarjax table).")
    r = los.shape[0]
    with_ref = reference is not None
    ref_speed = ref_dir = None
    if with_ref:
        if isinstance(reference, tuple | list):
            if len(reference) != 2:
                raise ValueError(f"{fname}: `reference` must be (speed, direction) arrays "
                                 "shaped (r, h).")
            ref_speed, ref_dir = reference
        else:
            ref_speed = getattr(reference, "speed", None)
            ref_dir = getattr(reference, "direction", None)
        ref_dir = _as_array(ref_dir, "direction")
        ref_speed = _as_array(ref_speed, "speed")
        if ref_dir is None or ref_dir.shape != (r, h) or (
                ref_speed is not None and ref_speed.shape != (r, h)):
            raise ValueError(f"{fname}: `reference` speed and direction must be shaped (r, h) = "
                             f"{(r, h)} like the records; got "
                             f"{None if ref_dir is None else ref_dir.shape}.")
    if weights is None:
        w = jnp.ones(los.shape, dtype)
    else:
        w = jnp.broadcast_to(jnp.asarray(weights, dtype), los.shape)
        if is_concrete(w) and (np.any(np.asarray(w) < 0) or np.any(np.isinf(np.asarray(w)))):
            raise ValueError(f"{fname}: `weights` must be finite and nonnegative.")
        w = jnp.where(jnp.isnan(w), 0.0, w)
    usable = jnp.isfinite(los) & (w > 0) & table.valid
    enough = jnp.sum(usable, -1) >= int(min_beams)  # (r, h)
    if with_ref:
        enough = enough & jnp.isfinite(jnp.asarray(ref_dir))
        if ref_speed is not None:
            enough = enough & jnp.isfinite(jnp.asarray(ref_speed))
    w = jnp.where(usable & enough[..., None], w, 0.0).astype(dtype)
    los = jnp.where(w > 0, los, 0.0).astype(dtype)
    n = r * h
    flat = lambda x: x.reshape((n,) + x.shape[2:])  # noqa: E731
    hidx = flat(jnp.broadcast_to(jnp.arange(h, dtype=jnp.int32), (r, h)))
    rec = flat(jnp.broadcast_to(jnp.arange(r, dtype=jnp.int32)[:, None], (r, h)))
    rdir = jnp.zeros((n,), dtype) if ref_dir is None else flat(
        jnp.asarray(np.nan_to_num(ref_dir), dtype))
    sp = table.response_spline
    geom = (sp.start.astype(dtype), sp.offsets.astype(dtype), sp.widths.astype(dtype),
            sp.uniform)
    if table.beam_velocity_spline is not None:
        vkind, vc = "beam", table.beam_velocity_spline.coefficients
    elif table.point_spline is not None:
        vkind, vc = "point", table.point_spline.coefficients
    else:
        vkind, vc = "free", jnp.zeros((4, 1, 1), dtype)
    inst = table.instrument
    nominal_all = np.array([0.0 if inst is None or getattr(inst, f"{x}_deg") is None
                            else float(getattr(inst, f"{x}_deg"))
                            for x in CALIBRATION_PARAMETERS])
    ctx = (geom, sp.coefficients.astype(dtype), vc.astype(dtype), vkind,
           table.beam_vectors.astype(dtype), jnp.asarray(nominal_all, dtype))
    free = np.array([x in names for x in CALIBRATION_PARAMETERS])
    notes = []
    if not with_ref and free[0]:
        free[0] = False
        notes.append(_NOT_IDENTIFIABLE_EPSILON)
    values = jnp.where(table.valid, table.response, 0.0).astype(dtype)
    theta, hmat, meat, wrss, nobs, n_ok, last, n_used, passes = _calibrate_core(
        flat(los), flat(w), rdir, hidx, rec, ctx, values, table.directions.astype(dtype),
        jnp.asarray(free), int(iterations), int(r), bool(with_ref))
    theta, hmat, meat = (np.asarray(x, np.float64) for x in (theta, hmat, meat))
    n_used = int(n_used)
    n_rec = int(np.unique(np.asarray(rec)[np.asarray(flat(w)).sum(-1) > 0]).size)
    m = 1 if with_ref else 2
    k_free = int(free.sum())
    dof = max(int(nobs) - m * int(n_ok) - k_free, 1)
    sigma2 = float(wrss) / dof
    # identifiability: eigenvalues of the normalised reduced matrix over the free offsets
    idx = np.flatnonzero(free)
    ident = np.zeros(3, bool)
    cov = np.full((3, 3), np.nan)
    if idx.size:
        hs = hmat[np.ix_(idx, idx)]
        d = np.sqrt(np.maximum(np.diag(hs), 0.0))
        ok_d = d > 0
        if ok_d.all():
            hn = hs / np.outer(d, d)
            eig, vec = np.linalg.eigh(hn)
            weak = eig < IDENTIFIABILITY_RCOND * max(eig[-1], 1e-300)
            ident[idx] = True
            for j in np.flatnonzero(weak):  # offsets along a null direction are not identified
                ident[idx[np.abs(vec[:, j]) > 0.3]] = False
            if ident[idx].any():
                sub = idx[ident[idx]]
                hsub = hmat[np.ix_(sub, sub)]
                hinv = np.linalg.inv(hsub)
                if covariance == "robust":
                    corr = n_rec / max(n_rec - sub.size, 1)
                    c = hinv @ meat[np.ix_(sub, sub)] @ hinv * corr
                else:
                    c = sigma2 * hinv
                cov[np.ix_(sub, sub)] = c
        else:
            ident[idx[ok_d]] = False
    converged = bool(np.isfinite(float(last)) and float(last) < 1e-6 and np.all(
        np.isfinite(theta)))
    if not converged:
        notes.append(f"did not converge in {int(passes)} passes (offsets still moving by "
                     f"{float(last):.2g} deg): these records do not determine the offsets; the "
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
    nom = nominal_all[sel]
    head = np.array([header.get(x, math.nan) for x in names])
    f = lambda a: jnp.asarray(a, dtype)  # noqa: E731
    return Calibration(
        names=names, offset=f(off), value=f(nom + off), nominal=f(nom), std=f(std),
        covariance=f(cov), correlation=f(corr), identifiable=jnp.asarray(ident[sel]),
        header=f(head), noise=f(math.sqrt(sigma2)),
        n_records=n_rec,
        n_problems=n_used, iterations=int(passes), converged=converged,
        notes=tuple(notes))
