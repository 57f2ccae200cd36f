"""Scanning-lidar forward model: LOS per (ray, range gate), in a steady field or through time.

`simulate_scan` samples a steady field (a time-dependent one at ``t = 0``); `simulate_scan_series`
flies the scan's trajectory through a time-dependent field (`AbstractField.sample_local_at`:
`lidarjax.scenes.FrozenTurbulence`, or any field that defines it), every sub-ray at its own
time. Both use the profilers' machinery unchanged: the mount's frame chain
(`lidarjax.body_to_cfd_rotation`: location, beta/gamma/psi, pitch and roll, the nacelle's
``pitch = -90``), the probe quadrature of `lidarjax.simulate` (a `lidarjax.PulsedProbe` per
gate: each gate centre is a focus range, cut at the lidar), probe nodes chosen for the
field's resolution (`lidarjax.beam.pattern_probe`), NaN plus a flag outside the field.
The beams' geometry, nodes, points and LOS are `lidarjax.beam`'s.

A ray is the mean of its `ScanPattern.n_sub` sub-rays (the arc swept during accumulation; see
`lidarjax.scanning.pattern`). A batched `lidarjax.Mount` (``(s, 3)`` locations) adds a leading
mount axis to every result (one compiled call, vmapped).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int

from .._precision import difference, is_concrete
from ..beam import beam_los, gates_los, pattern_probe
from ..field import AbstractField, DirectSampler
from ..flags import Flag
from ..frames import body_to_cfd_rotation, lidar_to_cfd_rotation, rotate
from ..motion import AbstractMotion
from ..mount import Mount
from ..probe import AbstractProbe, PointProbe
from .pattern import ScanPattern

__all__ = ["ScanResult", "simulate_scan", "simulate_scan_series"]


class ScanResult(eqx.Module):
    """A simulated scan (dimensions: ``r`` rays, ``g`` gates, ``n`` scans of a series; a
    batched mount adds a leading mount axis to every field).

    - `los`: ``(r, g)`` (series: ``(n, r, g)``) LOS velocities, m/s, positive away from the
      lidar; NaN where a probe node is outside the field or in a solid.
    - `times`: ``(r,)`` (series ``(n, r)``) mid-accumulation time of each ray, s.
    - `ranges`: ``(g,)`` gate-centre ranges, m.
    - `azimuth`, `elevation`: ``(r,)`` the rays' nominal angles (body frame, degrees), as the
      instrument reports them.
    - `directions`: ``(r, 3)`` the rays' unit vectors at mid-accumulation, CFD frame.
    - `points`: ``(r, g, 3)`` gate centres at mid-accumulation, CFD metres.
    - `flags`: int32 like `los`: `lidarjax.Flag.BEAM_OUTSIDE` (NaN), `PROBE_TRUNCATED`.
    """

    los: Float[Array, "*n r g"]
    times: Float[Array, "*n r"]
    ranges: Float[Array, " g"]
    azimuth: Float[Array, " r"]
    elevation: Float[Array, " r"]
    directions: Float[Array, "r 3"]
    points: Float[Array, "r g 3"]
    flags: Int[Array, "*n r g"]


def _validate(fn, field, pattern, mount, probe):
    if not isinstance(field, AbstractField):
        raise ValueError(f"{fn}: `field` must be a lidarjax.GridField or a scene, got "
                         f"{type(field).__name__}.")
    if not isinstance(pattern, ScanPattern):
        raise ValueError(f"{fn}: `pattern` must be a lidarjax.scanning.ScanPattern (e.g. "
                         f"lidarjax.scanning.ppi(...)), got {type(pattern).__name__}.")
    if not isinstance(mount, Mount):
        raise ValueError(f"{fn}: `mount` must be a lidarjax.Mount, got {type(mount).__name__}.")
    if not isinstance(probe, AbstractProbe):
        raise ValueError(f"{fn}: `probe` must be a lidarjax probe, got {type(probe).__name__}.")


def _scalar(value, dtype):
    """`value` as a 0-d array of `dtype`: a host number stays on the host (the compiled call
    transfers it with its other arguments), a JAX value keeps its trace."""
    if isinstance(value, (int, float, np.number, np.ndarray)):
        return np.asarray(value, dtype)
    return jnp.asarray(value).astype(dtype)


def simulate_scan(field: AbstractField, pattern: ScanPattern, mount: Mount, *,
                  probe: AbstractProbe | None = None,
                  start: Float[ArrayLike, ""] = 0.0, shared_nodes: bool = True) -> ScanResult:
    """LOS of every (ray, gate) of `pattern` in a steady `field`.

    **Arguments:**

    - `field`: a `lidarjax.GridField` or a scene (CFD frame, m/s); a time-dependent field is
      sampled at ``t = 0`` (use `simulate_scan_series` to fly through time).
    - `pattern`: the scan (`lidarjax.scanning.ppi`, `rhi`, `stare`, `vad`,
      `spinner_rosette`, or a `ScanPattern`).
    - `mount`: the lidar's `lidarjax.Mount` (one, or a batch: leading mount axis).
    - `probe`: range weighting per gate (default `lidarjax.PointProbe`; a scanning pulsed
      lidar: `lidarjax.scanning.instrument_probe`). Nodes without an explicit count are
      chosen for the field's resolution.
    - `start`: time of the scan start, s (only shifts `times`).
    - `shared_nodes`: a pulsed probe on equally spaced gates samples each beam once and
      shares the nodes between neighbouring gates (default; `gate_nodes` gives the rule);
      ``False``: every gate has its own nodes. Both integrate the probe within the same
      tolerance; sharing samples the field 2-4 times less.

    **Returns:** a `ScanResult`; its dtype follows the field's. Jit-compiled; every number is
    differentiable (field values, angles, rates, ranges, mount, probe).
    """
    probe = PointProbe() if probe is None else probe
    _validate("simulate_scan", field, pattern, mount, probe)
    probe, rule = pattern_probe(field, pattern, probe, "simulate_scan", shared_nodes)
    return _steady_jit(field, pattern, mount, probe, _scalar(start, field.dtype), rule=rule)


def simulate_scan_series(field: AbstractField, pattern: ScanPattern, mount: Mount, *,
                         n_scans: int = 1, start: Float[ArrayLike, ""] = 0.0,
                         probe: AbstractProbe | None = None,
                         motion: AbstractMotion | None = None,
                         shared_nodes: bool = True) -> ScanResult:
    """Fly `n_scans` repetitions of `pattern` (every `ScanPattern.period` from `start`, s)
    through a time-dependent `field`: every sub-ray samples the field at its own time
    (`AbstractField.los_local_at`), so a moving beam averages over its swept arc *and* over
    the time it takes.

    The sample points are the same in every repetition (a fixed mount), so the field is
    prepared for them once (`AbstractField.time_sampler`: frozen turbulence builds one line
    along the wind per point when it pays) and sampled at every time. For a series of
    different rays (a trajectory that never repeats), put them in one long pattern
    (`ScanPattern.repeated` or your own) with ``n_scans=1``.

    With a platform `motion` (`lidarjax.SinusoidalMotion`, `lidarjax.SampledMotion`), every
    sub-ray has the mount of its own time (offset, and attitude added to the mount's pitch,
    roll and ``gamma`` for yaw, as `lidarjax.simulate_series` does) and its LOS is the
    field's minus the lidar's own velocity along the beam; `points` and `directions` stay
    those of the mount at rest.

    **Arguments:** as `simulate_scan`, plus `n_scans` (static: shapes) and `motion` (with a
    motion every gate has its own nodes: the beams move during the scan).
    **Returns:** a `ScanResult` with `los` and `flags` ``(n, r, g)`` and `times` ``(n, r)``.
    """
    probe = PointProbe() if probe is None else probe
    _validate("simulate_scan_series", field, pattern, mount, probe)
    if int(n_scans) != n_scans or int(n_scans) < 1:
        raise ValueError(f"simulate_scan_series: n_scans must be a positive integer, got {n_scans!r}.")
    if is_concrete(start) and not np.isfinite(np.asarray(start, np.float64)).all():
        raise ValueError(f"simulate_scan_series: `start` must be finite seconds, got {start!r}.")
    if motion is not None and not isinstance(motion, AbstractMotion):
        raise ValueError(f"simulate_scan_series: `motion` must be a lidarjax motion (SinusoidalMotion, "
                         f"SampledMotion), got {type(motion).__name__}.")
    probe, rule = pattern_probe(field, pattern, probe, "simulate_scan_series", shared_nodes)
    return _series_jit(field, pattern, mount, probe, _scalar(start, field.dtype), motion,
                       n_scans=int(n_scans), rule=None if motion is not None else rule)


def _moving_los(field, pattern, mount_d, origin_local, probe, t_sub, motion):
    """LOS ``(n, g, B)`` of sub-rays at times `t_sub` ``(n, 1, B)`` from a moving mount: each
    sub-ray with the mount, offset and velocity of its time."""
    dtype = field.dtype
    g = pattern.n_gates
    n_body = pattern.sub_directions().reshape(-1, 3)  # (B, 3)
    to_cfd_rest = lidar_to_cfd_rotation(mount_d)
    n_scans, _, b = t_sub.shape
    ranges = pattern.ranges[:, None]

    def one(t, j):
        off, vel, att = (a.astype(dtype) for a in motion.state(t))
        moved = eqx.tree_at(lambda m: (m.gamma, m.pitch, m.roll), mount_d,
                            (mount_d.gamma + att[2], mount_d.pitch + att[0], mount_d.roll + att[1]))
        n = rotate(body_to_cfd_rotation(moved), n_body[j])
        at_t = lambda pts, dirs: field.los_local_at(pts, dirs, t)  # noqa: E731
        los, _ = beam_los(field, origin_local + rotate(to_cfd_rest, off), n[None], ranges, probe,
                           los=at_t)
        return los[:, 0] - jnp.dot(n, rotate(to_cfd_rest, vel), precision=jax.lax.Precision.HIGHEST)

    beams = jnp.broadcast_to(jnp.arange(b), (n_scans, b)).reshape(-1)
    los = jax.vmap(one)(t_sub.reshape(-1), beams)  # (n B, g)
    return jnp.moveaxis(los.reshape(n_scans, b, g), 1, 2)  # (n, g, B)


def _core(field, pattern, mount, probe, start, n_scans, motion=None, rule=None):
    """The scan in one mount's geometry; `n_scans` None: steady; `rule`: the gates' shared
    nodes (`lidarjax.beam.shared_gate_rule`), None: per-gate nodes."""
    dtype = field.dtype
    cast = lambda a: jnp.asarray(a).astype(dtype)  # noqa: E731
    origin_local = difference(mount.location, mount.location_lo, field.origin, field.origin_lo,
                              dtype)
    pattern = jax.tree_util.tree_map(cast, pattern)
    mount_d = jax.tree_util.tree_map(cast, mount)
    r, k, g = pattern.n_rays, pattern.n_sub, pattern.n_gates
    to_cfd = body_to_cfd_rotation(mount_d)
    n_cfd = rotate(to_cfd, pattern.sub_directions().reshape(r * k, 3))  # (B, 3)
    # every ray has the same gates: the probe's nodes are computed once per gate, (g, 1),
    # and broadcast over the rays by `beam_los` (its points are (g, B, q, 3))
    ranges = pattern.ranges[:, None]

    def pattern_los(los=None):
        if rule is None:
            return beam_los(field, origin_local, n_cfd, ranges, probe, los=los)
        return gates_los(field, origin_local, n_cfd, pattern.ranges, probe, rule, los=los)

    if n_scans is None:
        los, truncated = pattern_los()
        times = start + pattern.ray_times()
    else:
        scans = jnp.arange(n_scans, dtype=dtype)[:, None, None] * pattern.period
        t_sub = (start + scans + pattern.sub_times()[None]).reshape(n_scans, 1, r * k)  # (n, 1, B)

        def los_at(pts, dirs):
            if rule is not None:  # shared gate nodes: points (B, L, 3)
                t = jnp.swapaxes(t_sub, -1, -2)
            else:  # points (g, B, q, 3) or (g, B, 3)
                t = t_sub[..., None] if pts.ndim == 4 else t_sub
            sampler = field.time_sampler(pts, dirs, n_times=n_scans)
            if isinstance(sampler, DirectSampler):
                # no preparation pays: sample directly with times that broadcast (one per
                # sub-ray), so per-time work (frozen turbulence's advected distance) is done
                # per sub-ray, not per probe node
                return field.los_local_at(pts, dirs, t)
            return sampler(t)

        if motion is None:
            los, truncated = pattern_los(los_at)
        else:  # the probe's cut at the lidar does not move with it: flags from the rest geometry
            truncated = beam_los(field, origin_local, n_cfd, ranges, probe)[1]
            los = _moving_los(field, pattern, mount_d, origin_local, probe, t_sub, motion)
        times = start + scans[:, :, 0] + pattern.ray_times()[None]
    los = jnp.mean(los.reshape(los.shape[:-1] + (r, k)), axis=-1)  # (..., g, r)
    los = jnp.swapaxes(los, -1, -2)  # (..., r, g)
    flags = jnp.where(jnp.isfinite(los), 0, int(Flag.BEAM_OUTSIDE))
    if truncated is not None:
        cut = jnp.any(jnp.broadcast_to(truncated, (g, r * k)).reshape(g, r, k), axis=-1).T
        flags = flags | jnp.where(cut, int(Flag.PROBE_TRUNCATED), 0)
    n_mid = rotate(to_cfd, pattern.directions())
    points = (field.origin + (origin_local + pattern.ranges[None, :, None] * n_mid[:, None, :])
              + field.origin_lo)
    return ScanResult(los=los, times=times, ranges=pattern.ranges, azimuth=pattern.azimuth,
                      elevation=pattern.elevation, directions=n_mid, points=points,
                      flags=flags.astype(jnp.int32))


def _run(field, pattern, mount, probe, start, n_scans, motion=None, rule=None):
    # tiny rotation products keep the field's precision (TF32 on GPUs; see lidarjax.forward)
    with jax.default_matmul_precision("highest"):
        if mount.batch_shape:
            return jax.vmap(lambda m: _core(field, pattern, m, probe, start, n_scans, motion,
                                            rule))(mount)
        return _core(field, pattern, mount, probe, start, n_scans, motion, rule)


def _steady(field, pattern, mount, probe, start, *, rule=None):
    return _run(field, pattern, mount, probe, start, None, rule=rule)


def _series(field, pattern, mount, probe, start, motion, *, n_scans, rule=None):
    return _run(field, pattern, mount, probe, start, n_scans, motion, rule)


_steady_jit = jax.jit(_steady, static_argnames=("rule",))
_series_jit = jax.jit(_series, static_argnames=("n_scans", "rule"))
