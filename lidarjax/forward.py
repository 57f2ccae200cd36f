"""The forward model: what a lidar would measure and report in a velocity field.

`simulate` is one jit-compiled pure function of a field, a scan, a mount and heights. Its
static configuration (scan method and beam count, vertical beam, probe type and node count,
whether a free stream and a point reference are wanted) selects the compiled graph; every
number (angles, location, heights, field values, ``u_ref``) is a dynamic, differentiable
input, so changing numbers never recompiles.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int

from ._precision import difference, is_concrete
from .angles import _calm_mask, horizontal_speed, wind_direction
from .beam import _cut, beam_los, exact_by_default, probe_for_field, profile_geometry
from .corrections import DEFAULT_RATIO_TOL, correction_factors
from .field import AbstractField
from .flags import Flag
from .frames import (
    cfd_to_north_rotation,
    lidar_to_north_rotation,
    rotate,
    tilt_rotation,
)
from .mount import Mount
from .probe import AbstractProbe, PointProbe
from .scan import ILL_CONDITIONED, Scan, reconstruct
from .scanning.pattern import ScanPattern
from .scanning.simulate import ScanResult, simulate_scan

__all__ = ["Simulation", "simulate", "probe_for_field", "beam_gradient"]


class Simulation(eqx.Module):
    """Results of `simulate` (dimensions: ``h`` heights, ``b`` beams).

    - `heights`: ``(h,)`` measurement heights above the lidar, m.
    - `points`: ``(h, b, 3)`` beam measurement points (focus) in CFD coordinates, m.
    - `directions`: ``(b, 3)`` beam unit vectors in the CFD frame (tilt included).
    - `ranges`: ``(h, b)`` focus ranges along the beams, m (``h / cos(cone)``; ``h`` for the
      vertical beam), whatever the tilt: the instrument assumes it is level.
    - `los`: ``(h, b)`` LOS velocities, m/s, positive away from the lidar.
    - `lidar_velocity`: ``(h, 3)`` the instrument's reconstructed vector, north frame, m/s.
    - `point_velocity`: ``(h, 3)`` true velocity directly above the lidar, north frame
      (None with ``point_reference=False``).
    - `free_velocity`: ``(3,)`` ``u_ref`` carried through the same chain (None without it).
    - `cff_u, cff_v, cff_w, cff_U, cff_th`: ``(h,)`` factors to the free stream (None
      without ``u_ref``); `cfp_u, cfp_v, cfp_w, cfp_U, cfp_th` to the point (None without the
      point reference). See `lidarjax.corrections`.
    - `flags`: ``(h,)`` int32 bitmask of `lidarjax.Flag` explaining NaNs.
    - `condition_number`: the scan's beam-matrix condition number.
    """

    heights: Float[Array, " h"]
    points: Float[Array, "h b 3"]
    directions: Float[Array, "b 3"]
    ranges: Float[Array, "h b"]
    los: Float[Array, "h b"]
    lidar_velocity: Float[Array, "h 3"]
    point_velocity: Float[Array, "h 3"] | None
    free_velocity: Float[Array, 3] | None
    cff_u: Float[Array, " h"] | None
    cff_v: Float[Array, " h"] | None
    cff_w: Float[Array, " h"] | None
    cff_U: Float[Array, " h"] | None
    cff_th: Float[Array, " h"] | None
    cfp_u: Float[Array, " h"] | None
    cfp_v: Float[Array, " h"] | None
    cfp_w: Float[Array, " h"] | None
    cfp_U: Float[Array, " h"] | None
    cfp_th: Float[Array, " h"] | None
    flags: Int[Array, " h"]
    condition_number: Float[Array, ""]

    @property
    def lidar_speed(self) -> Float[Array, " h"]:
        """Horizontal speed the lidar reports, m/s."""
        return horizontal_speed(self.lidar_velocity)

    @property
    def lidar_direction(self) -> Float[Array, " h"]:
        """Meteorological direction the lidar reports (north frame), degrees."""
        return wind_direction(self.lidar_velocity)

    @property
    def point_speed(self) -> Float[Array, " h"]:
        """Horizontal speed directly above the lidar, m/s."""
        return horizontal_speed(self.point_velocity)

    @property
    def point_direction(self) -> Float[Array, " h"]:
        """Meteorological direction directly above the lidar (north frame), degrees."""
        return wind_direction(self.point_velocity)

    @property
    def free_speed(self) -> Float[Array, ""]:
        """Horizontal free-stream speed, m/s."""
        return horizontal_speed(self.free_velocity)

    @property
    def free_direction(self) -> Float[Array, ""]:
        """Meteorological free-stream direction (north frame), degrees."""
        return wind_direction(self.free_velocity)


def _validate(field, scan, mount, heights, u_ref, probe) -> None:
    if not isinstance(field, AbstractField):
        raise ValueError(
            f"simulate: `field` must be a lidarjax.GridField or a scene from lidarjax.scenes, "
            f"got {type(field).__name__}."
        )
    if not isinstance(scan, Scan):
        raise ValueError(
            f"simulate: `scan` must be a lidarjax.Scan (e.g. lidarjax.windcube_v1()), got "
            f"{type(scan).__name__}."
        )
    if not isinstance(mount, Mount):
        raise ValueError(f"simulate: `mount` must be a lidarjax.Mount, got {type(mount).__name__}.")
    if mount.batch_shape:
        raise ValueError(f"simulate: `mount` holds {mount.n_mounts} mounts (a batch); simulate "
                         "takes one: use lidarjax.simulate_rotations for a batch, or jax.vmap.")
    if not isinstance(probe, AbstractProbe):
        raise ValueError(f"simulate: `probe` must be a probe, got {type(probe).__name__}.")
    if is_concrete(heights):
        h = np.asarray(heights, dtype=np.float64)
        if h.ndim != 1 or h.size == 0:
            raise ValueError(
                f"simulate: `heights` must be a non-empty 1-D array of metres above the lidar, "
                f"got shape {h.shape}."
            )
        if not np.all(np.isfinite(h)) or np.any(h <= 0):
            raise ValueError(
                f"simulate: `heights` must be positive and finite (metres above the lidar), got "
                f"{h.tolist()}."
            )
    if u_ref is not None and is_concrete(u_ref):
        u = np.asarray(u_ref, dtype=np.float64)
        if u.shape != (3,) or not np.all(np.isfinite(u)):
            raise ValueError(
                f"simulate: `u_ref` must be a finite free-stream vector (u, v, w) in the CFD "
                f"frame, m/s, shape (3,); got {u_ref!r}."
            )


def simulate(
    field: AbstractField,
    scan: Scan | ScanPattern,
    mount: Mount,
    heights: Float[ArrayLike, " h"] | None = None,
    *,
    u_ref: Float[ArrayLike, 3] | None = None,
    probe: AbstractProbe | None = None,
    point_reference: bool = True,
    ratio_tol: float = DEFAULT_RATIO_TOL,
) -> Simulation | ScanResult:
    """Simulate a lidar in a velocity field.

    **Arguments:**

    - `field`: a `lidarjax.GridField` or an analytic scene (CFD frame, m/s). A grid
      `lidarjax.io.load_field` resampled from a mesh (OpenFOAM, VTK) without ``exact_at``
      is sampled exact, the mesh's own cellPoint (what OpenFOAM's `probes` report), at every
      point this call samples from one concrete mount (prepared here: `lidarjax.ExactPoints`,
      for a scanning pattern `lidarjax.scan_points`); a batch or traced mount samples the
      grid, with a one-line warning (once per field; ``load_field(..., exact_at=False)``
      accepts the grid silently).
    - `scan`: beam geometry and reconstruction (`lidarjax.windcube_v1` etc.). A scanning
      pattern (`lidarjax.ppi`, `rhi`, `stare`, `vad`, `spinner_rosette`, a
      `lidarjax.scanning.ScanPattern`) samples its own range gates: the call is
      `lidarjax.simulate_scan(field, scan, mount, probe=probe)` and returns its
      `ScanResult` (LOS per ray and gate); `heights` and `u_ref` are refused.
    - `mount`: location, angles and tilt (`lidarjax.Mount`, degrees and metres).
    - `heights`: ``(h,)`` measurement heights above the lidar in metres; a tilted beam's focus
      for height ``h`` is at range ``h / cos(cone)``, the vertical beam's at ``h``, along the
      beams as tilted by the mount's pitch and roll (for a nacelle lidar, ``pitch = -90``,
      they are distances along the instrument axis). The point reference is sampled at
      ``h`` straight above the lidar (level).
    - `u_ref`: free-stream vector ``(u, v, w)`` in the CFD frame (m/s); gives `free_velocity`
      and the ``cff_*`` factors. Without it none of that is compiled.
    - `probe`: probe volume (default `lidarjax.PointProbe`, which compiles no quadrature;
      `lidarjax.PulsedProbe`, `lidarjax.CWProbe` average along each beam, in the field's
      length units: see `lidarjax.probe`). `points` stay the focus points. A probe built
      without an explicit `n_nodes` gets the nodes the field's resolution needs
      (`probe_for_field`).
    - `point_reference`: also sample the true wind directly above the lidar (static).
    - `ratio_tol`: relative tolerance of correction-factor denominators (see
      `lidarjax.corrections`).

    **Returns:** a `Simulation`; its dtype follows the field's.

    Raises `ValueError` before compiling for inputs of the wrong type, shape or range.
    Inside the compiled function, points outside the field give NaN with a `Flag`; the NaN
    never meets arithmetic on the inputs, so gradients of the finite results (and of a loss
    that masks the NaN ones out) are finite. A scan whose condition number exceeds
    `lidarjax.scan.ILL_CONDITIONED` is flagged (see `lidarjax.scan` for the closed forms).
    """
    if isinstance(scan, ScanPattern):
        if heights is not None or u_ref is not None:
            raise ValueError("simulate: a scanning pattern samples its own range gates; drop "
                             "`heights` and `u_ref` (simulate(field, pattern, mount, probe=...)).")
        field = exact_by_default(field, scan, mount, None, probe, "simulate")
        return simulate_scan(field, scan, mount, probe=probe)
    if heights is None:
        raise ValueError("simulate: `heights` (m above the lidar) are needed for a profiling "
                         "scan; only a scanning pattern (lidarjax.ppi, ...) samples its own gates.")
    if isinstance(scan, Scan):  # a mesh's grid: exact at the points sampled (where known)
        field = exact_by_default(field, scan, mount, heights, probe, "simulate")
    probe, heights = _prepared(field, scan, mount, heights, u_ref, probe, "simulate")
    if u_ref is not None:
        u_ref = jnp.asarray(u_ref)
    return _simulate_jit(
        field, scan, mount, heights, u_ref, probe, ratio_tol, point_reference=point_reference
    )


def _prepared(field, scan, mount, heights, u_ref, probe, caller):
    """The checked inputs of `simulate` (and `beam_gradient`): ``(probe, heights)`` with the
    probe's nodes chosen for the field along the mount's beams and the heights a float
    array."""
    if probe is None:
        probe = PointProbe()
    _validate(field, scan, mount, heights, u_ref, probe)
    probe = probe_for_field(field, scan, heights, probe, mount=mount, caller=caller)
    heights = jnp.atleast_1d(jnp.asarray(heights))
    if not jnp.issubdtype(heights.dtype, jnp.floating):
        heights = heights.astype(field.dtype)
    return probe, heights


def _simulate(field, scan, mount, heights, u_ref, probe, ratio_tol, *, point_reference):
    # Matrix products here (rotation compositions, reconstructions) are tiny and must keep
    # the field's precision: on Ampere+ GPUs XLA runs a float32 `dot` at DEFAULT precision in
    # TensorFloat-32 (10-bit mantissas), which turned the beams of a tilted, turned mount
    # 5e-4 off (1e-2 m/s of LOS in a 10 m/s wind; tests/core/test_fused_arithmetic.py).
    # Scoped to the trace of this function (every dot traced in it, also in `frames` and
    # `scan`, gets HIGHEST precision); nothing global changes.
    with jax.default_matmul_precision("highest"):
        return _simulate_traced(field, scan, mount, heights, u_ref, probe, ratio_tol,
                                point_reference=point_reference)


def _simulate_traced(field, scan, mount, heights, u_ref, probe, ratio_tol, *, point_reference):
    dtype = field.dtype
    heights = heights.astype(dtype)
    cast = lambda a: jnp.asarray(a).astype(dtype)  # noqa: E731
    # The lidar relative to the field's origin, before anything is rounded to `dtype`.
    origin_local = difference(mount.location, mount.location_lo, field.origin, field.origin_lo, dtype)
    scan = jax.tree_util.tree_map(cast, scan)
    angles = jax.tree_util.tree_map(cast, mount)
    tilt = tilt_rotation(angles.pitch, angles.roll)  # body -> level lidar frame
    n_cfd, ranges = profile_geometry(scan, mount, heights)  # (b, 3), (h, b): h / cos(cone)
    los, truncated = beam_los(field, origin_local, n_cfd, ranges, probe)

    # NaN (beams outside the field or in a solid) is masked out of every computation below
    # and put back into the results last (the safe_mask pattern): finite results keep
    # finite gradients, and so does a loss that masks the NaN results out.
    beam_ok = jnp.all(jnp.isfinite(los), axis=-1)  # (h,)
    los_safe = jnp.where(jnp.isfinite(los), los, 0)
    to_north = lidar_to_north_rotation(angles)
    if scan.tilt_compensation:  # the method's formulas with the true (level) directions
        to_north = to_north @ tilt
    lidar_safe = rotate(to_north, reconstruct(scan, los_safe))
    lidar_velocity = jnp.where(beam_ok[:, None], lidar_safe, jnp.nan)
    cfd_to_north = cfd_to_north_rotation(angles)

    flags = jnp.where(beam_ok, 0, int(Flag.BEAM_OUTSIDE))
    if truncated is not None:
        flags |= jnp.where(jnp.any(truncated, axis=-1), int(Flag.PROBE_TRUNCATED), 0)
    if point_reference:
        zhat = jnp.array([0.0, 0.0, 1.0], dtype)
        v_point = field.sample_local(origin_local + heights[:, None] * zhat)
        point_ok = jnp.all(jnp.isfinite(v_point), axis=-1)
        point_safe = rotate(cfd_to_north, jnp.where(point_ok[:, None], v_point, 0))
        point_velocity = jnp.where(point_ok[:, None], point_safe, jnp.nan)
        flags |= jnp.where(point_ok, 0, int(Flag.POINT_OUTSIDE))
    else:
        point_ok = jnp.ones(heights.shape, bool)
        point_safe = point_velocity = None
    free_velocity = None if u_ref is None else rotate(cfd_to_north, cast(u_ref))

    factors = correction_factors(lidar_safe, point_safe, free_velocity, ratio_tol)
    ratio_nan = jnp.zeros(heights.shape, bool)
    for key, f in factors.items():
        if f is None:
            continue
        ok = beam_ok & (point_ok if key.startswith("cfp") else True)
        factors[key] = jnp.where(ok, f, jnp.nan)
        if key in ("cff_u", "cff_v", "cff_U", "cfp_u", "cfp_v", "cfp_w", "cfp_U"):
            ratio_nan |= ok & jnp.isnan(f)
    calm = _calm_mask(lidar_velocity[..., 0], lidar_velocity[..., 1])  # NaN direction there
    flags |= jnp.where(calm, int(Flag.CALM), 0)
    cond = scan.condition_number()
    flags |= jnp.where(cond > ILL_CONDITIONED, int(Flag.ILL_CONDITIONED), 0)
    flags |= jnp.where(ratio_nan, int(Flag.RATIO_UNDEFINED), 0)

    points = field.origin + (origin_local + ranges[..., None] * n_cfd) + field.origin_lo
    return Simulation(
        heights=heights,
        points=points,
        directions=n_cfd,
        ranges=ranges,
        los=los,
        lidar_velocity=lidar_velocity,
        point_velocity=point_velocity,
        free_velocity=free_velocity,
        flags=flags.astype(jnp.int32),
        condition_number=cond,
        **factors,
    )


_simulate_jit = jax.jit(_simulate, static_argnames=("point_reference",))


def beam_gradient(
    field: AbstractField,
    scan: Scan,
    mount: Mount,
    heights: Float[ArrayLike, " h"],
    *,
    probe: AbstractProbe | None = None,
) -> Float[Array, "h b 3 3"]:
    """The velocity gradient along each beam's probe volume, for the first-order change of
    the LOS when the beam turns about the lidar.

    A beam turned from ``n`` to ``n + dn`` (about the lidar, ``|dn|`` small) moves its
    quadrature node at range ``r_k`` by ``r_k dn``, so its LOS changes by
    ``dn . V_bar + rho * n . (G dn)`` at first order, with ``V_bar`` the probe-weighted
    velocity, ``rho`` the focus range and
    ``G_ij = sum_k w_k (r_k / rho) dV_i/dx_j (x_k)`` (the probe's weights ``w_k`` after
    its cut at the lidar, as `simulate` uses them; the point probe: the gradient at the
    focus). This returns ``G``.

    **Arguments:** as `simulate` (`field`, `scan`, one `mount`, `heights` in m, `probe`;
    the probe's nodes are chosen for the field by `probe_for_field`, as `simulate` does).

    **Returns:** ``(h, b, 3, 3)`` ``G[h, b, i, j] = dV_i / dx_j`` in the north frame
    (velocity component ``i`` and position component ``j`` both rotated by
    `lidarjax.frames.cfd_to_north_rotation`), 1/s. Computed by forward-mode
    differentiation (`jax.jvp`) of the field's sampling at the nodes, so it is the exact
    derivative of the field's interpolant (piecewise constant in a trilinear grid cell). NaN
    where `simulate`'s LOS is NaN.
    """
    if isinstance(scan, ScanPattern) or not isinstance(scan, Scan):
        raise ValueError("beam_gradient: `scan` must be a profiling lidarjax.Scan "
                         "(lidarjax.windcube_v2(), ...).")
    probe, heights = _prepared(field, scan, mount, heights, None, probe, "beam_gradient")
    return _beam_gradient_jit(field, scan, mount, heights, probe)


@jax.jit
def _beam_gradient_jit(field, scan, mount, heights, probe):
    return beam_flow(field, scan, mount, heights, probe)[1]


def beam_flow(field: AbstractField, scan: Scan, mount: Mount, heights: Float[Array, " h"],
              probe: AbstractProbe) -> tuple[Float[Array, "h b 3"], Float[Array, "h b 3 3"]]:
    """The velocity at each beam's measurement point (its focus, m/s) and the gradient
    ``G`` of `beam_gradient` (1/s), both in the north frame, ``((h, b, 3), (h, b, 3, 3))``,
    for one `mount` at `heights` (m) with `probe` (its nodes as given, see
    `probe_for_field`). Traceable: no checks; `beam_gradient` and
    `lidarjax.TableRuns` call it."""
    with jax.default_matmul_precision("highest"):
        dtype = field.dtype
        heights = heights.astype(dtype)
        origin_local = difference(mount.location, mount.location_lo, field.origin,
                                  field.origin_lo, dtype)
        angles = jax.tree_util.tree_map(lambda a: jnp.asarray(a).astype(dtype), mount)
        n_cfd, ranges = profile_geometry(scan, mount, heights)
        q = cfd_to_north_rotation(angles)
        velocity = field.sample_local(origin_local + ranges[..., None] * n_cfd)
        gradient = jnp.einsum("ik,hbkl,jl->hbij", q, gradient_along_beams(
            field, origin_local, n_cfd, ranges, probe), q)
        return jnp.einsum("ij,hbj->hbi", q, velocity), gradient


def gradient_along_beams(field, origin_local, directions, ranges, probe):
    """``G`` of `beam_gradient` in the CFD frame, ``(h, b, 3, 3)``, for beams from
    `origin_local` (m, relative to the field's origin) along CFD unit `directions`
    ``(b, 3)`` focused at `ranges` ``(h, b)`` (m), with `probe` (its nodes as given; a
    `lidarjax.GradedProbe` pads every height's nodes to one count with weight 0).
    Traceable; `lidarjax.ResponseTable.from_simulations` calls it on a run's geometry."""

    def gradient(points):  # (..., 3) -> (..., 3 [velocity], 3 [position])
        eye = jnp.eye(3, dtype=points.dtype)
        cols = [jax.jvp(field.sample_local, (points,),
                        (jnp.broadcast_to(eye[j], points.shape),))[1] for j in range(3)]
        return jnp.stack(cols, axis=-1)

    focus = gradient(origin_local + ranges[..., None] * directions)  # (h, b, 3, 3)
    if isinstance(probe, PointProbe):
        return focus
    offsets, weights = probe.nodes(ranges)
    offsets = jnp.broadcast_to(offsets.astype(ranges.dtype), ranges.shape + offsets.shape[-1:])
    weights = jnp.broadcast_to(weights.astype(ranges.dtype), offsets.shape)
    node_ranges = ranges[..., None] + offsets  # (h, b, q)
    g_q = gradient(origin_local + node_ranges[..., None] * directions[:, None, :])
    ahead, kept, total = _cut(offsets, weights, ranges)
    g_q = jnp.where(ahead[..., None, None], g_q, 0)  # nodes behind the lidar: NaN
    lever = kept * node_ranges / ranges[..., None]
    g = jnp.einsum("hbq,hbqij->hbij", lever, g_q) / jnp.where(
        total > 0, total, 1)[..., None, None]
    return jnp.where((total > 0)[..., None, None], g, focus)
