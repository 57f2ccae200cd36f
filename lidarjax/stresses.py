"""Reynolds stresses from the radial-velocity variances of a scan: the 6-beam method (Sathe
et al. 2015, "A six-beam method to measure turbulence statistics using ground-based wind
lidars", AMT 8, 729-740).

A LOS ``s_b = n_b . V`` of a beam with unit vector ``n_b`` (positive away from the lidar)
has, over a record in horizontally homogeneous turbulence, the variance

    ``var(s_b) = n_b^T R n_b = n_x^2 u'u' + n_y^2 v'v' + n_z^2 w'w'
    + 2 n_x n_y u'v' + 2 n_x n_z u'w' + 2 n_y n_z v'w'``

with ``R`` the symmetric Reynolds-stress tensor (m^2/s^2). Six beams whose rows
``(n_x^2, n_y^2, n_z^2, 2 n_x n_y, 2 n_x n_z, 2 n_y n_z)`` are independent give six linear
equations ``M sigma = var(s)`` in the six stresses ``sigma = (u'u', v'v', w'w', u'v', u'w',
v'w')`` (`STRESS_COMPONENTS`), solved with the inverse of ``M`` (`stress_matrix`; more beams:
least squares). For `lidarjax.six_beam` (five beams 45 degrees from the vertical, 72 degrees
apart, plus the vertical beam) the condition number of ``M`` is 3.34 whatever the azimuth
offset (9.9 at a 30 degree cone, 2.1 at 54.7): relative errors of the beam variances reach
the stresses amplified at most 3.34 times. A single cone without a vertical beam (DBS,
VAD) cannot separate ``w'w'`` from ``(u'u' + v'v') / 2`` (``M`` has rank 5) and is refused.

Unlike the instrument's wind vectors (`lidarjax.Series.velocity`, each built from beams up
to a cycle apart and tens of metres apart, so their covariance mixes components: the
"DBS-style" variances, `ReynoldsStresses.vector_stress`), the 6-beam stresses use only
each beam's own variance, so a point probe in homogeneous turbulence recovers ``R`` to
sampling error; a probe volume (pulsed, CW) attenuates each beam's variance by its
weighting's filter along the beam, and the 6-beam inversion carries that attenuation into
the stresses (see docs/time-series.md).

Frames. The beam directions are those the instrument believes, as for its wind vector
(`lidarjax.reconstruct` then the software north rotation): the body-frame beams turned to
the north frame by ``R(-epsilon)`` (after the tilt when the scan compensates it). Stresses
are given

- in the **north frame** (`ReynoldsStresses.stress`): ``u`` east, ``v`` north, ``w`` up
  (the order of lidarwind's ``var_u, var_v, var_w, var_uv, var_uw, var_vw``);
- in the **mean-wind frame** (`ReynoldsStresses.stress_wind`): ``x`` along the record's
  mean horizontal wind (downwind), ``z`` up, ``y = z x x`` to the left looking downwind:
  the box frame of `lidarjax.TurbulenceBox` (Mann, IEC), so ``u'u'`` is the longitudinal
  variance, ``u'w'`` the kinematic momentum flux (negative in a sheared surface layer).

Dimensions: ``r`` records, ``h`` heights, ``b`` beams, ``6`` stress components.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int

from ._precision import HIGHEST, is_concrete
from .mount import Mount
from .scan import MAX_CONDITION, Scan
from .series import RECORD_LENGTH, Series, _to_north

__all__ = ["ReynoldsStresses", "reynolds_stresses", "stress_matrix", "STRESS_COMPONENTS"]

#: Order of the six stresses in every ``(..., 6)`` array (m^2/s^2).
STRESS_COMPONENTS = ("uu", "vv", "ww", "uv", "uw", "vw")


def stress_matrix(directions: Float[ArrayLike, "b 3"]) -> Float[Array, "b 6"]:
    """The ``(b, 6)`` matrix ``M`` of ``var(s_b) = M_b . sigma`` (module docs): row ``b`` is
    ``(n_x^2, n_y^2, n_z^2, 2 n_x n_y, 2 n_x n_z, 2 n_y n_z)`` of the unit vector ``n_b``
    (any frame; the stresses come out in that frame, ordered as `STRESS_COMPONENTS`)."""
    n = jnp.asarray(directions)
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    return jnp.stack([x * x, y * y, z * z, 2 * x * y, 2 * x * z, 2 * y * z], axis=-1)


def _to_tensor(s):
    """``(..., 6)`` stresses to ``(..., 3, 3)`` symmetric tensors."""
    uu, vv, ww, uv, uw, vw = (s[..., i] for i in range(6))
    return jnp.stack([jnp.stack([uu, uv, uw], -1), jnp.stack([uv, vv, vw], -1),
                      jnp.stack([uw, vw, ww], -1)], -2)


def _to_six(t):
    return jnp.stack([t[..., 0, 0], t[..., 1, 1], t[..., 2, 2], t[..., 0, 1], t[..., 0, 2],
                      t[..., 1, 2]], -1)


class ReynoldsStresses(eqx.Module):
    """Reynolds stresses per record and height (`reynolds_stresses`). Stresses in m^2/s^2,
    ordered as `STRESS_COMPONENTS` ``(uu, vv, ww, uv, uw, vw)``.

    - `stress`: ``(r, h, 6)`` the 6-beam retrieval, north frame (``u`` east, ``v`` north,
      ``w`` up); NaN where a beam has fewer than `min_los` valid LOS in the record.
    - `stress_wind`: ``(r, h, 6)`` the same in the mean-wind frame (``u`` along the mean
      horizontal wind, ``v`` to its left, ``w`` up); NaN also at zero mean horizontal speed.
    - `mean_velocity`: ``(r, h, 3)`` the record's mean wind, north frame, m/s: the least
      squares over the beams' mean LOS (for `lidarjax.six_beam`: all six beams).
    - `los_mean`, `los_variance`: ``(r, h, b)`` each beam's mean LOS (m/s) and variance
      (population, ``1/N``, as `lidarjax.statistics`) over its valid LOS in the record.
    - `los_count`: ``(r, h, b)`` valid (finite) LOS of each beam in the record.
    - `vector_stress`, `vector_stress_wind`: ``(r, h, 6)`` the covariance (``1/N``) of the
      instrument's reconstructed wind vectors (`Series.velocity`) in the record, in the
      same two frames: the standard DBS/VAD-style turbulence statistics, for comparison
      (their ``uu`` in the wind frame is what a ``.sta`` horizontal-speed dispersion
      approximates). NaN where the record has no valid vector.
    - `condition_number`: ``()`` of the stress matrix ``M`` (3.34 for `lidarjax.six_beam`).
    """

    stress: Float[Array, "r h 6"]
    stress_wind: Float[Array, "r h 6"]
    mean_velocity: Float[Array, "r h 3"]
    los_mean: Float[Array, "r h b"]
    los_variance: Float[Array, "r h b"]
    los_count: Int[Array, "r h b"]
    vector_stress: Float[Array, "r h 6"]
    vector_stress_wind: Float[Array, "r h 6"]
    condition_number: Float[Array, ""]


def _host_condition(scan: Scan) -> float:
    """The stress matrix's condition number in float64 on the host (numpy only: it also
    runs while a caller's jit traces)."""
    az = np.deg2rad(np.asarray(scan.azimuths, np.float64))
    c = np.deg2rad(float(np.asarray(scan.cone_angle, np.float64)))
    n = np.stack([np.sin(c) * np.sin(az), np.sin(c) * np.cos(az), np.full(az.shape, np.cos(c))], -1)
    if scan.vertical:
        n = np.vstack([n, [0.0, 0.0, 1.0]])
    x, y, z = n.T
    m = np.stack([x * x, y * y, z * z, 2 * x * y, 2 * x * z, 2 * y * z], -1)
    s = np.linalg.svd(m, compute_uv=False)
    return float(s[0] / s[-1]) if s.size == 6 and s[-1] > 0 else np.inf


def reynolds_stresses(
    series: Series,
    scan: Scan,
    mount: Mount,
    starts: Float[ArrayLike, " r"] | None = None,
    record_length: float = RECORD_LENGTH,
    *,
    min_los: int = 2,
) -> ReynoldsStresses:
    """The six Reynolds stresses per record and height from the beams' LOS variances (the
    6-beam method; module docs), with the DBS-style covariance of the reconstructed vectors.

    **Arguments:**

    - `series`: a `lidarjax.Series` (`lidarjax.simulate_series`) of `scan` on `mount`.
    - `scan`: the scan that made it, at least 6 beams whose directions determine the six
      stresses (`lidarjax.six_beam`); the stress matrix's condition number must not exceed
      `lidarjax.scan.MAX_CONDITION`.
    - `mount`: the installation: its software north offset (and its tilt, for a scan with
      ``tilt_compensation``) turns the body-frame beams to the north frame, as the
      instrument's wind vector is turned. A moving platform's attitude is not followed:
      the beams at rest are used.
    - `starts`: ``(r,)`` record start times, s; a record holds the LOS (and reconstructions)
      whose time lies in ``[start, start + record_length)``. Without `starts`, the whole
      series is one record.
    - `record_length`: seconds (600).
    - `min_los`: the fewest valid LOS per beam for a stress (default 2); below it NaN.

    **Returns:** `ReynoldsStresses`. Pure and jit-compiled (`starts`, `record_length` and
    `min_los` dynamic; shapes follow the number of records); differentiable in the LOS and
    the mount's angles. Raises `ValueError` before compiling for a scan that cannot
    determine the stresses or does not match the series.
    """
    if not isinstance(series, Series):
        raise ValueError(f"reynolds_stresses: `series` must be a lidarjax.Series "
                         f"(simulate_series), got {type(series).__name__}.")
    if not isinstance(scan, Scan) or not isinstance(mount, Mount):
        raise ValueError("reynolds_stresses: pass the `scan` and `mount` that made the series "
                         "(a lidarjax.Scan and a lidarjax.Mount).")
    if scan.n_beams < 6:
        raise ValueError(f"reynolds_stresses: {scan.n_beams} beams cannot determine the six "
                         f"Reynolds stresses; use a scan of at least 6 beams such as "
                         f"lidarjax.six_beam().")
    if series.los.shape[-1] != scan.n_beams:
        raise ValueError(f"reynolds_stresses: the series has {series.los.shape[-1]} beams, the "
                         f"scan {scan.n_beams}; pass the scan that made the series.")
    if is_concrete(scan.azimuths, scan.cone_angle):
        cond = _host_condition(scan)
        if not cond <= MAX_CONDITION:
            raise ValueError(
                f"reynolds_stresses: the beams cannot separate the six stresses (stress-matrix "
                f"condition number {cond:.3g} > {MAX_CONDITION:.0e}): a single cone without a "
                f"vertical beam confuses w'w' with (u'u' + v'v')/2; use lidarjax.six_beam().")
    dtype = series.los.dtype
    if starts is None:
        starts = series.start[None]
        record_length = series.duration + 1e-6
    starts = jnp.atleast_1d(jnp.asarray(starts, dtype))
    return _stresses_jit(series, scan, mount, starts, jnp.asarray(record_length, dtype),
                         jnp.asarray(min_los, jnp.int32))


def _wind_rotation(mean_velocity):
    """Rows ``e_x, e_y, e_z`` of the mean-wind frame (north-frame components), and whether
    the mean horizontal speed is positive."""
    vx, vy = mean_velocity[..., 0], mean_velocity[..., 1]
    sq = vx * vx + vy * vy
    pos = sq > 0
    speed = jnp.sqrt(jnp.where(pos, sq, 1))  # safe mask: finite gradients at zero speed
    c, s = jnp.where(pos, vx / speed, 1), jnp.where(pos, vy / speed, 0)
    zero, one = jnp.zeros_like(c), jnp.ones_like(c)
    rows = jnp.stack([jnp.stack([c, s, zero], -1), jnp.stack([-s, c, zero], -1),
                      jnp.stack([zero, zero, one], -1)], -2)
    return rows, pos


def _rotate_stress(rows, six):
    t = _to_tensor(six)
    return _to_six(jnp.einsum("...ij,...jk,...lk->...il", rows, t, rows, precision=HIGHEST))


def _stresses(series: Series, scan: Scan, mount: Mount, starts, record_length, min_los):
    dtype = series.los.dtype
    cast = lambda a: jnp.asarray(a).astype(dtype)  # noqa: E731
    scan = jax.tree_util.tree_map(cast, scan)
    mount_d = jax.tree_util.tree_map(cast, mount)
    n_north = _to_north(scan, mount_d, scan.directions())  # (b, 3) the beams believed
    m = stress_matrix(n_north)  # (b, 6)
    m_inv = jnp.linalg.pinv(m)  # (6, b): the inverse for six beams
    n_inv = jnp.linalg.pinv(n_north)  # (3, b)
    sv = jnp.linalg.svd(m, compute_uv=False)
    cond = sv[0] / sv[-1]
    nan = jnp.asarray(jnp.nan, dtype)

    def one(s):
        t, los = series.los_time, series.los  # (m, h, b)
        ok = (t >= s) & (t < s + record_length) & jnp.isfinite(los)
        count = jnp.sum(ok, axis=0)  # (h, b)
        nn = jnp.where(count > 0, count, 1).astype(dtype)
        mean = jnp.sum(jnp.where(ok, los, 0), axis=0) / nn
        dev = jnp.where(ok, los - mean, 0)
        var = jnp.sum(dev * dev, axis=0) / nn
        enough = count >= min_los
        valid = jnp.all(enough, axis=-1)  # (h,)
        var_ok = jnp.where(enough, var, 0)
        stress = jnp.einsum("kb,hb->hk", m_inv, var_ok, precision=HIGHEST)
        stress = jnp.where(valid[:, None], stress, nan)
        mean_vel = jnp.einsum("kb,hb->hk", n_inv, jnp.where(enough, mean, 0), precision=HIGHEST)
        mean_vel = jnp.where(valid[:, None], mean_vel, nan)
        rows, moving = _wind_rotation(jnp.where(valid[:, None], mean_vel, 0))
        stress_wind = jnp.where((valid & moving)[:, None], _rotate_stress(rows, stress), nan)

        # the instrument's reconstructed vectors (DBS/VAD-style statistics)
        tv, v = series.time, series.velocity  # (n, h), (n, h, 3)
        vok = (tv >= s) & (tv < s + record_length) & jnp.all(jnp.isfinite(v), axis=-1)
        nv = jnp.sum(vok, axis=0)
        nvv = jnp.where(nv > 0, nv, 1).astype(dtype)
        vs = jnp.where(vok[..., None], v, 0)
        vmean = jnp.sum(vs, axis=0) / nvv[:, None]
        d = jnp.where(vok[..., None], v - vmean, 0)
        cov = jnp.einsum("nhi,nhj->hij", d, d, precision=HIGHEST) / nvv[:, None, None]
        vec = jnp.where((nv > 0)[:, None], _to_six(cov), nan)
        vrows, vmoving = _wind_rotation(vmean)
        vec_wind = jnp.where(((nv > 0) & vmoving)[:, None], _rotate_stress(vrows, vec), nan)
        return ReynoldsStresses(
            stress=stress, stress_wind=stress_wind, mean_velocity=mean_vel,
            los_mean=jnp.where(count > 0, mean, nan), los_variance=jnp.where(count > 0, var, nan),
            los_count=count.astype(jnp.int32), vector_stress=vec, vector_stress_wind=vec_wind,
            condition_number=cond)

    out = jax.vmap(one)(starts)
    return eqx.tree_at(lambda r: r.condition_number, out, cond)


_stresses_jit = jax.jit(_stresses)
