"""Time series: every line of sight (LOS) at the time it is taken, the instrument's
reconstructions from beams taken at different times, and the 10-minute statistics of a
``.sta`` file.

`simulate_series` runs a scan `Schedule` (`lidarjax.timing`) through a time-dependent field
(`AbstractField.sample_local_at`: frozen turbulence over a mean flow; a steady field gives a
constant series) with an optional platform `lidarjax.motion` motion:

1. LOS times ``(m, h, b)`` from the schedule (``m`` cycles, or rotations for sequential
   heights); each LOS is the probe-weighted projection of the field *at its own time* along
   the beam of the mount *at that time* (the forward model's probe quadrature,
   `lidarjax.beam.beam_los`, on the field frozen at that instant), minus the
   lidar's own velocity along the beam;
2. reconstructions as the instrument builds them (`Schedule.update`): Windcube, after each
   new LOS from the latest LOS of every beam (so consecutive vectors share 4 of 5 LOS and
   mix beams up to one cycle apart); ZephIR, once per height visit from the LOS of its
   rotations. The wind vector is `lidarjax.reconstruct` of those LOS in the lidar frame,
   turned to the north frame by the software offset (and by the tilt at the reconstruction's
   time with ``Scan(..., tilt_compensation=True)``);
3. point sensors directly above the lidar's location at rest sample the field every
   `point_dt` seconds (a cup and a sonic anemometer at each height).

`statistics` reduces a series to what the ``.sta`` reports per record and height, plus
turbulence intensities and the point sensors' statistics (`SeriesStatistics`);
`simulate_statistics` streams many records (and an ensemble of fields) through
`simulate_series` + `statistics` in jit-compiled, vmapped and device-sharded chunks, keeping
only the statistics; `write_series_sta` writes them with `lidarjax.io.write_sta`.

Dimensions: ``m`` LOS cycles (rotations), ``h`` heights, ``b`` beams, ``n`` reconstructions,
``p`` point samples, ``r`` records, ``e`` ensemble members. Times in seconds, speeds m/s,
directions meteorological degrees (where the wind comes from, clockwise from north).
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int

from ._backend import CPU_BATCH, default_batch
from ._deprecated import deprecated_getattr
from ._precision import HIGHEST, difference, is_concrete
from .angles import horizontal_speed, wind_direction
from .beam import (
    ExactPoints,
    beam_los,
    exact_by_default,
    graded_warning,
    probe_for_field,
    profile_geometry,
    scan_points,
    simulate_points,
)
from .field import AbstractField, FieldSequence
from .flags import Flag
from .forward import _validate
from .frames import (
    cfd_to_north_rotation,
    lidar_to_cfd_rotation,
    lidar_to_north_rotation,
    rotate,
    tilt_rotation,
)
from .motion import AbstractMotion
from .mount import Mount
from .probe import AbstractProbe, PointProbe
from .scan import Scan, reconstruct
from .scanning.pattern import ScanPattern
from .scanning.simulate import simulate_scan_series
from .timing import Schedule, schedule_for

__all__ = ["Series", "SeriesStatistics", "simulate_series", "statistics", "simulate_statistics",
           "probe_for_field", "RECORD_LENGTH"]

#: Seconds in one statistics record (the ``.sta`` 10-minute interval).
RECORD_LENGTH = 600.0


class Series(eqx.Module):
    """A simulated lidar time series (`simulate_series`).

    - `heights`: ``(h,)`` m above the lidar.
    - `los_time`: ``(m, h, b)`` time of every LOS, s; `los`: ``(m, h, b)`` LOS, m/s
      (positive away from the lidar; NaN outside the field).
    - `time`: ``(n, h)`` time of each reconstruction (its latest LOS), s.
    - `velocity`: ``(n, h, 3)`` reconstructed wind, north frame, m/s (NaN when a LOS is).
    - `point_time`: ``(p,)`` s; `point_velocity`: ``(p, h, 3)`` true wind directly above the
      lidar's location at rest, north frame, m/s.
    - `start`, `duration`: the span simulated, s.
    - `los_flags`: ``(m, h, b)`` `lidarjax.Flag` bits of each LOS: ``BEAM_OUTSIDE`` (a probe
      node outside the field or in a solid: NaN), ``TIME_OUTSIDE`` (the LOS time lies
      outside an unsteady field's snapshots: NaN).
    - `point_flags`: ``(p, h)``: ``POINT_OUTSIDE`` (NaN), ``TIME_OUTSIDE``.
    """

    heights: Float[Array, " h"]
    los_time: Float[Array, "m h b"]
    los: Float[Array, "m h b"]
    time: Float[Array, "n h"]
    velocity: Float[Array, "n h 3"]
    point_time: Float[Array, " p"]
    point_velocity: Float[Array, "p h 3"]
    start: Float[Array, ""]
    duration: Float[Array, ""]
    los_flags: Int[Array, "m h b"]
    point_flags: Int[Array, "p h"]

    @property
    def speed(self) -> Float[Array, "n h"]:
        """Horizontal speed of each reconstruction, m/s."""
        return horizontal_speed(self.velocity)

    @property
    def direction(self) -> Float[Array, "n h"]:
        """Meteorological direction of each reconstruction, degrees."""
        return wind_direction(self.velocity)


class _AtTime(AbstractField):
    """A field frozen at given times: lets the forward model's probe quadrature
    (`lidarjax.beam.beam_los`) sample a time-dependent field unchanged. `time` is a
    scalar or one time per beam focus ``(h, b)``; the quadrature's extra node axis (points
    ``(h, b, q, 3)``) shares its focus' time."""

    origin: Float[Array, 3]
    origin_lo: Float[Array, 3]
    field: AbstractField
    time: Float[Array, ...]

    @property
    def resolution(self) -> float | None:
        return self.field.resolution

    def _time(self, points):
        t = self.time
        return t if t.ndim >= points.ndim - 1 else t[..., None]

    def sample_local(self, points):
        return self.field.sample_local_at(points, self._time(points))

    def los_local(self, points, directions):
        return self.field.los_local_at(points, directions, self._time(points))


def _check_span(times, schedule: Schedule, n_heights: int):
    """(start, n_cycles) from `times` = (start, duration) (host numbers)."""
    try:
        start, duration = (float(np.asarray(v)) for v in times)
    except (TypeError, ValueError):
        raise ValueError("simulate_series: `times` must be (start, duration) in seconds, e.g. "
                         "(0.0, 600.0).") from None
    try:
        period, refocus = float(np.asarray(schedule.period)), float(np.asarray(schedule.refocus))
    except jax.errors.TracerArrayConversionError:
        raise ValueError("simulate_series: the schedule's period must be concrete (it sets the "
                         "number of LOS); build the Schedule outside jit.") from None
    cycle = (n_heights * (schedule.rotations_per_height * period + refocus)
             if schedule.heights_sequential else period)
    n = int(np.floor(duration / cycle + 1e-9))
    if not np.isfinite(start) or not np.isfinite(duration) or n < 1:
        raise ValueError(f"simulate_series: the span (start={start}, duration={duration} s) must "
                         f"be finite and hold at least one scan cycle of {cycle:g} s.")
    return start, duration, n


def _sliding_windows(los, t_los, order):
    """Sliding reconstruction windows over ``m`` cycles of beams taken in `order`, by
    static slices (no gather): LOS ``(n, h, b)`` of each window and its time ``(n, h)``
    (that of the beam just taken). Window 0 is the first complete cycle; then one window per
    new LOS: the window closed by the ``r``-th LOS of cycle ``c`` holds beam ``j`` from cycle
    ``c - 1`` if ``j`` comes later in the order than that LOS, else from ``c``."""
    m, _, b = los.shape
    order = np.asarray(order)
    rank = np.empty(b, int)
    rank[order] = np.arange(b)
    first_w, first_t = los[:1], t_los[:1, :, order[-1]]
    if m == 1:
        return first_w, first_t
    per_r = []
    for r in range(b):
        d = (rank > r).astype(int)
        per_r.append(jnp.stack([los[1 - d[j]:m - d[j], :, j] for j in range(b)], axis=-1))
    wins = jnp.stack(per_r, axis=1).reshape((m - 1) * b, *los.shape[1:])  # (c, r) order
    times = jnp.stack([t_los[1:, :, order[r]] for r in range(b)], axis=1)
    times = times.reshape((m - 1) * b, t_los.shape[1])
    return (jnp.concatenate([first_w, wins], axis=0),
            jnp.concatenate([first_t, times], axis=0))


def simulate_series(
    field: AbstractField,
    scan: Scan | ScanPattern,
    mount: Mount,
    heights: Float[ArrayLike, " h"] | None,
    times: tuple[float, float],
    *,
    schedule: Schedule | None = None,
    probe: AbstractProbe | None = None,
    motion: AbstractMotion | None = None,
    point_dt: float = 1.0,
    refine_probe: bool = True,
    chunk: int | None = None,
) -> Series:
    """Simulate the lidar's time series: every LOS at the time it is taken.

    **Arguments:**

    - `field`: a time-dependent field (frozen turbulence over a mean flow; the snapshots of
      an unsteady CFD run, `lidarjax.SnapshotField`; CFD frame, m/s), any steady field, or a
      `lidarjax.FieldSequence` (snapshots loaded as the run reaches them: see below).
    - `scan`, `mount`, `heights`, `probe`: as in `lidarjax.simulate`. A scanning pattern
      (`lidarjax.ppi`, ...; ``heights=None``, no `schedule`: it has its own gates and timing)
      is flown through the field by `lidarjax.simulate_scan_series` for every whole
      repetition of the pattern in `times`, and its `ScanResult` is returned.
    - `times`: ``(start, duration)`` seconds: whole scan cycles from `start` that fit in
      `duration` (host numbers: they set the number of LOS).
    - `schedule`: the scan timing (default `lidarjax.timing.schedule_for(scan)`).
    - `motion`: platform motion (`lidarjax.motion`), default none.
    - `point_dt`: sampling interval of the point sensors, s (1 Hz by default; a sonic logs
      at 10-20 Hz: 0.05).
    - `refine_probe`: a probe built without an explicit `n_nodes` integrates its weighting
      with the nodes the field's resolution needs (`lidarjax.probe_for_field` with the
      mount, the same choice as `simulate`: for a turbulence box, its spacing; a pulsed
      probe needs 17 nodes for a 4 m box, where 9 alias waves shorter than about 30 m; on a
      graded grid, per height from the spacing along a fixed lidar's beams; with a
      `motion`, one count at every height, the finest spacing's); the weighting is
      unchanged, and an explicit count wins. ``False`` keeps the probe's nodes as given.
      A mesh sequence prepared for this run samples the same points:
      ``load_field_sequence(case, exact_at=lidarjax.ExactPoints(scan, mount, heights,
      probe))``; an OpenFOAM sequence loaded without `exact_at` is prepared so by this call
      for a fixed lidar (below).
    - `chunk`: with a `FieldSequence`, the most LOS cycles (rows of `Series.los`) one
      compiled call simulates; default: as many as one window of snapshots spans.

    **Unsteady CFD.** A `FieldSequence` is flown through window by window: the LOS cycles
    (and point samples) are grouped into chunks whose times fit between `max_snapshots`
    consecutive snapshots, each chunk is simulated on a `SnapshotField` of those snapshots
    only (times relative to the window's first snapshot, so float32 keeps its resolution
    over long runs), and the instrument's reconstructions are built from all the LOS
    together, exactly as from one `SnapshotField` holding every snapshot. Memory holds one
    window (two while the next is stacked), whatever the run's length. LOS and point samples
    outside the snapshots' span are NaN, flagged ``TIME_OUTSIDE``.

    **Exact by default.** An OpenFOAM sequence loaded without ``exact_at``
    (`lidarjax.io.load_field_sequence`) is made exact, the mesh's own cellPoint (what
    OpenFOAM's `probes` report), at every point a fixed lidar samples, on the first window
    (`FieldSequence.made_exact` at `lidarjax.ExactPoints`, as ``lidarjax series
    --sequence``); a scanning pattern from a fixed mount likewise at `lidarjax.scan_points`,
    and one snapshot's grid `lidarjax.io.load_field` resampled from a mesh without
    ``exact_at`` (also in `simulate_statistics`). A moving lidar (or a traced mount) samples
    the graded grid instead, with a one-line `UserWarning` naming the grid's local spacing
    above the lidar and the fix (``exact_at=False`` at loading accepts the grid silently).

    **Returns:** a `Series`. Raises `ValueError` before compiling for bad inputs.
    """
    if isinstance(scan, ScanPattern):
        return _scan_series(field, scan, mount, heights, times, schedule, probe, motion)
    schedule = schedule_for(scan) if schedule is None else schedule
    probe = PointProbe() if probe is None else probe
    sequence = field if isinstance(field, FieldSequence) else None
    if sequence is not None:
        # a mesh's sequence made exact at a fixed lidar's points (the mesh's own cellPoint)
        sequence, graded = _exact_sequence(sequence, scan, mount, heights, probe, motion,
                                           refine_probe)
        # the window the run starts in: validated here, reused by the first chunk
        width = min(sequence.max_snapshots, len(sequence))
        try:
            first = sequence.indices(float(np.asarray(times[0])), float(np.asarray(times[0])))[0]
        except (TypeError, ValueError, IndexError):
            first = 0  # `_check_span` below names the bad span
        first = min(first, len(sequence) - width)
        field = sequence.window(first, first + width - 1)
        if graded is not None:
            graded_warning("simulate_series", field, mount, heights, sequence.name, graded,
                           "for a fixed lidar the run is exact by default; give a finer "
                           "`spacing` to load_field_sequence (or exact_at=False to accept "
                           "the grid)")
    else:  # a mesh's grid (`lidarjax.io.load_field`): exact at a fixed lidar's points
        field = exact_by_default(field, scan, mount, heights, probe, "simulate_series",
                                 moving=motion is not None)
    _validate(field, scan, mount, np.asarray(heights), None, probe)
    if not isinstance(schedule, Schedule):
        raise ValueError(f"simulate_series: `schedule` must be a lidarjax.Schedule, got "
                         f"{type(schedule).__name__}.")
    if motion is not None and not isinstance(motion, AbstractMotion):
        raise ValueError(f"simulate_series: `motion` must be a lidarjax motion (SinusoidalMotion,"
                         f" SampledMotion), got {type(motion).__name__}.")
    schedule.check(scan)
    if refine_probe:
        # with the mount, as `simulate` (and `lidarjax.ExactPoints`, which prepares a
        # mesh's points for this run) choose them: per height on a graded grid
        probe = probe_for_field(field, scan, heights, probe, mount=_fixed(mount, motion),
                                caller="simulate_series")
    heights = jnp.atleast_1d(jnp.asarray(heights, dtype=field.dtype))
    start, duration, n_cycles = _check_span(times, schedule, heights.shape[0])
    if not point_dt > 0:
        raise ValueError(f"simulate_series: `point_dt` must be positive seconds, got {point_dt}.")
    n_points = max(int(np.floor(duration / point_dt + 1e-9)), 1)
    order = tuple(int(i) for i in schedule.order())
    if sequence is not None:
        return _series_over_sequence(sequence, field, scan, mount, heights, start, duration,
                                     schedule, probe, motion, point_dt, n_cycles=n_cycles,
                                     n_points=n_points, order=order, chunk=chunk)
    return _series_jit(field, scan, mount, heights, jnp.asarray(start, field.dtype), schedule,
                       probe, motion, jnp.asarray(point_dt, field.dtype),
                       n_cycles=n_cycles, n_points=n_points, order=order,
                       duration=float(duration))


def _exact_sequence(sequence: FieldSequence, scan, mount: Mount, heights, probe, motion,
                    refine_probe: bool) -> tuple[FieldSequence, str | None]:
    """`sequence` made exact (the mesh's own cellPoint) at every point a fixed lidar samples,
    as ``lidarjax series --sequence`` prepares them (`lidarjax.ExactPoints`: the nodes this
    run chooses); where it cannot be, the sequence as given and why (a moving lidar, a
    traced mount) for the one-line warning. A sequence that is its own data (gridded
    snapshots, or prepared with ``exact_at``) is returned as it is."""
    if not sequence.can_be_exact:
        return sequence, None
    if motion is not None:
        return sequence, "a moving lidar's points are not known in advance"
    if not is_concrete(mount, heights):
        return sequence, "a traced mount's points are not known on the host"
    if refine_probe:
        points = ExactPoints(scan, mount, heights, probe)
    else:  # the probe's nodes as given
        points = lambda grid: simulate_points(scan, mount, heights, probe)  # noqa: E731
    return sequence.made_exact(points), None


def _fixed(mount: Mount, motion) -> Mount | None:
    """The mount the probe's nodes are chosen for (`probe_for_field`): a fixed lidar's, per
    height along its beams as `simulate` chooses them; None for a moving lidar (its beams
    move: one count, the field's finest spacing's, at every height)."""
    return mount if motion is None else None


def _los_times(schedule: Schedule, start, n_cycles: int, n_heights: int, dtype):
    """``(m, h, b)`` LOS times."""
    bt = schedule.beam_times.astype(dtype)
    cycle = schedule.cycle_time(n_heights).astype(dtype)
    c0 = start + jnp.arange(n_cycles, dtype=dtype) * cycle  # (c,)
    if not schedule.heights_sequential:
        t = c0[:, None, None] + bt[None, None, :]
        return jnp.broadcast_to(t, (n_cycles, n_heights, bt.shape[0]))
    rot = schedule.rotations_per_height
    visit = rot * schedule.period.astype(dtype) + schedule.refocus.astype(dtype)
    k = jnp.arange(n_heights, dtype=dtype)
    r = jnp.arange(rot, dtype=dtype)
    t = (c0[:, None, None, None] + r[None, :, None, None] * schedule.period.astype(dtype)
         + k[None, None, :, None] * visit + bt[None, None, None, :])  # (c, r, h, b)
    return t.reshape(n_cycles * rot, n_heights, bt.shape[0])


def _mount_at(mount: Mount, attitude):
    """The mount turned by a motion's attitude ``(pitch, roll, yaw)`` in degrees."""
    pitch, roll, yaw = attitude[0], attitude[1], attitude[2]
    return eqx.tree_at(lambda m: (m.gamma, m.pitch, m.roll), mount,
                       (mount.gamma + yaw, mount.pitch + pitch, mount.roll + roll))


def _to_north(scan: Scan, mount: Mount, v_lidar):
    """Body-frame reconstruction to the north frame: the software north rotation, after the
    tilt when the scan compensates it (as `lidarjax.simulate`)."""
    to_north = lidar_to_north_rotation(mount)
    if scan.tilt_compensation:
        to_north = jnp.matmul(to_north, tilt_rotation(mount.pitch, mount.roll), precision=HIGHEST)
    return rotate(to_north, v_lidar)


def _series_los(field, scan, mount_d, origin_local, heights, t_los, probe, motion, base,
                repeat=1):
    """``(m, h, b)`` LOS at the times `t_los` (field time, s); `base` (s) is added for the
    motion's clock (a `FieldSequence` window samples its field at times relative to it)."""
    dtype = field.dtype
    m, h, b = t_los.shape
    beam = jnp.broadcast_to(jnp.arange(b), t_los.shape)
    hgt = jnp.broadcast_to(heights[None, :, None], t_los.shape)
    to_cfd_rest = lidar_to_cfd_rotation(mount_d)

    def one(t, j, z):
        """One LOS of a moving lidar: its own mount, position and velocity at time t."""
        off, vel, att = motion.state(t + base)
        mt = _mount_at(mount_d, att.astype(dtype))
        offset = rotate(to_cfd_rest, off.astype(dtype))
        v_lidar = rotate(to_cfd_rest, vel.astype(dtype))
        n_cfd, rng = profile_geometry(scan, mt, z.reshape(1))
        n = n_cfd[j]
        rng = rng[:, j][:, None]  # (1, 1)
        frozen = _AtTime(field.origin, field.origin_lo, field, t)
        los, _ = beam_los(frozen, origin_local + offset, n[None, :], rng, probe)
        return los[0, 0] - jnp.dot(n, v_lidar, precision=HIGHEST)

    if motion is not None:
        return jax.vmap(one)(t_los.reshape(-1), beam.reshape(-1),
                             hgt.reshape(-1)).reshape(m, h, b)
    # a fixed lidar: one geometry, every cycle's (h, b) LOS at their own times at once
    n_cfd, ranges = profile_geometry(scan, mount_d, heights)

    # The sample points are the same at every time: the field is prepared for them once
    # (`AbstractField.time_sampler`: frozen turbulence builds one line along the wind
    # per point, a steady field samples them once) and sampled at every LOS time.
    n_times = m * repeat

    def los_at(pts, dirs, rows=slice(None)):  # rows: the heights of a GradedProbe's group
        t = t_los[:, rows]
        t = t[..., None] if pts.ndim == 4 else t  # (m, h, b[, 1])
        return field.time_sampler(pts, dirs, n_times=n_times)(t)

    return beam_los(field, origin_local, n_cfd, ranges, probe, los=los_at)[0]


def _series_points(field, mount_d, origin_local, heights, t_pt, repeat=1):
    """``(p, h, 3)`` point velocities (north frame) above the lidar's location at rest, at
    the times `t_pt` (field time, s)."""
    zhat = jnp.array([0.0, 0.0, 1.0], field.dtype)
    pts = origin_local + heights[:, None] * zhat  # (h, 3)
    v_pt = field.time_sampler(pts, n_times=t_pt.shape[0] * repeat)(t_pt[:, None])  # (p, h, 3)
    return rotate(cfd_to_north_rotation(mount_d), v_pt)


def _time_flags(t, span):
    """``Flag.TIME_OUTSIDE`` where `t` lies outside `span` = ``(first, last)`` or None."""
    if span is None:
        return jnp.zeros(jnp.shape(t), jnp.int32)
    outside = (t < span[0]) | (t > span[1])
    return jnp.where(outside, int(Flag.TIME_OUTSIDE), 0).astype(jnp.int32)


def _reconstruction_windows(x, t_los, order, sliding: bool, rot: int):
    """The windows the instrument reconstructs from, of any per-LOS quantity `x` ``(m, h, b)``
    (LOS, or anything computed per LOS) taken at `t_los`: `sliding` (``update="each_los"``),
    the latest LOS of every beam after each new LOS (`_sliding_windows`); else one window per
    `rot` consecutive rows (a height visit: `rot` rotations, or one cycle), `x` averaged over
    them. Returns ``(n, h, b)`` windows and their times ``(n, h)`` (the latest LOS)."""
    if sliding:
        return _sliding_windows(x, t_los, order)
    m, h, b = x.shape
    return (jnp.mean(x.reshape(m // rot, rot, h, b), axis=1),
            jnp.max(t_los.reshape(m // rot, rot, h, b), axis=(1, 3)))


def _series_assemble(scan, mount_d, heights, t_los, los, t_pt, v_pt, schedule, motion, start,
                     span, *, order, duration):
    """The reconstructions (as the instrument builds them) and flags of a series."""
    dtype = los.dtype
    rot = schedule.rotations_per_height if schedule.heights_sequential else 1
    los_w, t_rec = _reconstruction_windows(los, t_los, order, schedule.update == "each_los", rot)
    ok = jnp.all(jnp.isfinite(los_w), axis=-1)
    v_lidar = reconstruct(scan, jnp.where(jnp.isfinite(los_w), los_w, 0))
    if motion is None:
        v_north = _to_north(scan, mount_d, v_lidar)
    else:
        _, _, att = motion.state(t_rec)  # (n, h, 3)
        v_north = jax.vmap(jax.vmap(lambda a, v: _to_north(scan, _mount_at(mount_d, a.astype(dtype)),
                                                           v)))(att, v_lidar)
    velocity = jnp.where(ok[..., None], v_north, jnp.nan)
    time_los = _time_flags(t_los, span)
    los_flags = time_los | jnp.where(jnp.isfinite(los) | (time_los != 0), 0,
                                     int(Flag.BEAM_OUTSIDE)).astype(jnp.int32)
    time_pt = _time_flags(jnp.broadcast_to(t_pt[:, None], v_pt.shape[:-1]), span)
    pt_nan = ~jnp.all(jnp.isfinite(v_pt), axis=-1)
    point_flags = time_pt | jnp.where(pt_nan & (time_pt == 0), int(Flag.POINT_OUTSIDE),
                                      0).astype(jnp.int32)
    return Series(heights=heights, los_time=t_los, los=los, time=t_rec, velocity=velocity,
                  point_time=t_pt, point_velocity=v_pt, start=start,
                  duration=jnp.asarray(duration, dtype), los_flags=los_flags,
                  point_flags=point_flags)


def _prepare(field, scan, mount):
    dtype = field.dtype
    cast = lambda a: jnp.asarray(a).astype(dtype)  # noqa: E731
    scan = jax.tree_util.tree_map(cast, scan)
    mount_d = jax.tree_util.tree_map(cast, mount)
    origin_local = difference(mount.location, mount.location_lo, field.origin, field.origin_lo,
                              dtype)
    return scan, mount_d, origin_local


def _series(field, scan, mount, heights, start, schedule, probe, motion, point_dt, *,
            n_cycles, n_points, order, duration, repeat=1):
    """The series; `repeat` (static) is how many records one compiled call simulates with
    the same field (a vmapped chunk): it decides whether preparing the field's sample
    points pays (`AbstractField.time_sampler`)."""
    dtype = field.dtype
    scan, mount_d, origin_local = _prepare(field, scan, mount)
    t_los = _los_times(schedule, start, n_cycles, heights.shape[0], dtype)  # (m, h, b)
    zero = jnp.zeros((), dtype)
    los = _series_los(field, scan, mount_d, origin_local, heights, t_los, probe, motion, zero,
                      repeat)
    t_pt = start + jnp.arange(n_points, dtype=dtype) * point_dt
    v_pt = _series_points(field, mount_d, origin_local, heights, t_pt, repeat)
    return _series_assemble(scan, mount_d, heights, t_los, los, t_pt, v_pt, schedule, motion,
                            start, field.time_span, order=order, duration=duration)


def _scan_series(field, pattern, mount, heights, times, schedule, probe, motion):
    """`simulate_series` of a scanning pattern: `lidarjax.simulate_scan_series` over the
    whole repetitions of the pattern that fit in `times` = (start, duration)."""
    if heights is not None or schedule is not None:
        raise ValueError("simulate_series: a scanning pattern has its own range gates and "
                         "timing; pass heights=None and no schedule (simulate_series(field, "
                         "pattern, mount, None, (start, duration))).")
    try:
        start, duration = (float(np.asarray(v)) for v in times)
    except (TypeError, ValueError):
        raise ValueError("simulate_series: `times` must be (start, duration) in seconds.") from None
    period = float(np.asarray(pattern.period))
    n_scans = int(np.floor(duration / period + 1e-9))
    if not (np.isfinite(start) and np.isfinite(duration)) or n_scans < 1:
        raise ValueError(f"simulate_series: the span (start={start}, duration={duration} s) must "
                         f"be finite and hold at least one repetition of the scan ({period:g} s).")
    if not isinstance(field, FieldSequence):
        return simulate_scan_series(field, pattern, mount, n_scans=n_scans, start=start,
                                    probe=probe, motion=motion)
    # through unsteady CFD: the repetitions in chunks that fit a window of snapshots
    if motion is not None:
        raise ValueError("simulate_series: a scanning pattern on a moving platform through a "
                         "FieldSequence is not supported; use one SnapshotField.")
    seq = field
    if seq.can_be_exact and is_concrete(mount):
        # a mesh's sequence exact at every point the pattern samples from the fixed mount
        seq = seq.made_exact(lambda grid: scan_points(grid, pattern, mount, probe))
    width = min(seq.max_snapshots, len(seq))
    lo = start + np.arange(n_scans) * period
    parts = []
    for i0, k0, k1 in _windows(seq.times, lo, lo + period, width, None, "scan repetition",
                               seq.name):
        base = float(seq.times[i0])
        window = seq.window(i0, i0 + width - 1, base=base)
        res = simulate_scan_series(window, pattern, mount, n_scans=k1 - k0,
                                   start=float(lo[k0]) - base, probe=probe)
        parts.append(eqx.tree_at(lambda r: r.times, res, res.times + jnp.asarray(base, res.times.dtype)))
    res = parts[0]
    los = jnp.concatenate([p.los for p in parts], axis=-3)
    t = jnp.concatenate([p.times for p in parts], axis=-2)
    flags = jnp.concatenate([p.flags for p in parts], axis=-3)
    t0, t1 = seq.time_span
    outside = ((t < t0) | (t > t1))[..., None]
    flags = jnp.where(outside, int(Flag.TIME_OUTSIDE), flags).astype(flags.dtype)
    return eqx.tree_at(lambda r: (r.los, r.times, r.flags), res, (los, t, flags))


def _los_times_host(schedule: Schedule, start: float, n_cycles: int, n_heights: int):
    """`_los_times` in float64 on the host."""
    bt = np.asarray(schedule.beam_times, np.float64)
    period, refocus = float(np.asarray(schedule.period)), float(np.asarray(schedule.refocus))
    if not schedule.heights_sequential:
        cycle = period
        t = start + np.arange(n_cycles)[:, None, None] * cycle + bt[None, None, :]
        return np.broadcast_to(t, (n_cycles, n_heights, bt.size))
    rot = schedule.rotations_per_height
    visit = rot * period + refocus
    cycle = n_heights * visit
    t = (start + np.arange(n_cycles)[:, None, None, None] * cycle
         + np.arange(rot)[None, :, None, None] * period
         + np.arange(n_heights)[None, None, :, None] * visit + bt[None, None, None, :])
    return t.reshape(n_cycles * rot, n_heights, bt.size)


def _windows(times: np.ndarray, lo: np.ndarray, hi: np.ndarray, width: int, most: int | None,
             what: str, name: str):
    """Group items with time ranges ``[lo_k, hi_k]`` (sorted by ``lo``) into consecutive
    chunks that fit in a window of `width` consecutive snapshots: ``[(first_snapshot,
    first_item, stop_item)]``. Ranges are clipped to the snapshots' span (items outside it
    are NaN in any window)."""
    n_t = times.size
    lo, hi = np.clip(lo, times[0], times[-1]), np.clip(hi, times[0], times[-1])
    out, k, n = [], 0, lo.size
    while k < n:
        i0 = int(np.clip(np.searchsorted(times, lo[k], side="right") - 1, 0, n_t - 2))
        i0 = min(i0, n_t - width)
        end = times[i0 + width - 1]
        if hi[k] > end:
            raise ValueError(
                f"simulate_series: one {what} of the scan spans {lo[k]:g}..{hi[k]:g} s, more "
                f"than {width} consecutive snapshots of {name}; raise its `max_snapshots`.")
        stop = int(np.searchsorted(hi, end, side="right"))  # hi is sorted with lo
        stop = max(stop, k + 1)
        if most is not None:
            stop = min(stop, k + most)
        out.append((i0, k, stop))
        k = stop
    return out


def _series_over_sequence(sequence: FieldSequence, first_window, scan, mount, heights, start,
                          duration, schedule, probe, motion, point_dt, *, n_cycles, n_points,
                          order, chunk):
    """`simulate_series` through a `FieldSequence`, window by window (see there)."""
    dtype = first_window.dtype
    times = sequence.times
    width = min(sequence.max_snapshots, times.size)
    h = int(heights.shape[0])
    t_los = _los_times_host(schedule, start, n_cycles, h)  # (m, h, b) float64
    rows_lo, rows_hi = t_los.min(axis=(1, 2)), t_los.max(axis=(1, 2))
    t_pt = start + np.arange(n_points) * float(point_dt)
    los_chunks = _windows(times, rows_lo, rows_hi, width, chunk, "LOS cycle", sequence.name)
    pt_chunks = _windows(times, t_pt, t_pt, width, None, "point sample", sequence.name)
    rows = max(c[2] - c[1] for c in los_chunks)
    n_pt = max(c[2] - c[1] for c in pt_chunks)
    # both kinds of chunk in time order: consecutive windows share their snapshots
    jobs = sorted([(c[0], 0, c) for c in los_chunks] + [(c[0], 1, c) for c in pt_chunks])
    los = np.empty(t_los.shape, dtype)
    v_pt = np.empty((n_points, h, 3), dtype)
    field = first_window
    for i0, kind, (_, k0, k1) in jobs:
        base = float(times[i0])
        field = sequence.window(i0, i0 + width - 1, base=base)
        if kind == 0:
            t = t_los[k0:k1]
            t = np.concatenate([t, np.repeat(t[-1:], rows - t.shape[0], axis=0)])
            out = _los_chunk_jit(field, scan, mount, heights, jnp.asarray(t - base, dtype),
                                 probe, motion, jnp.asarray(base, dtype))
            los[k0:k1] = np.asarray(out)[:k1 - k0]
        else:
            t = t_pt[k0:k1]
            t = np.concatenate([t, np.repeat(t[-1:], n_pt - t.size)])
            out = _points_chunk_jit(field, mount, heights, jnp.asarray(t - base, dtype))
            v_pt[k0:k1] = np.asarray(out)[:k1 - k0]
    del field
    span = tuple(jnp.asarray(v, dtype) for v in sequence.time_span)
    return _assemble_jit(scan, mount, heights, jnp.asarray(t_los, dtype), jnp.asarray(los),
                         jnp.asarray(t_pt, dtype), jnp.asarray(v_pt), schedule, motion,
                         jnp.asarray(start, dtype), span, order=order, duration=float(duration))


@jax.jit
def _los_chunk_jit(field, scan, mount, heights, t_los, probe, motion, base):
    scan, mount_d, origin_local = _prepare(field, scan, mount)
    return _series_los(field, scan, mount_d, origin_local, heights, t_los, probe, motion, base)


@jax.jit
def _points_chunk_jit(field, mount, heights, t_pt):
    mount_d = jax.tree_util.tree_map(lambda a: jnp.asarray(a).astype(field.dtype), mount)
    origin_local = difference(mount.location, mount.location_lo, field.origin, field.origin_lo,
                              field.dtype)
    return _series_points(field, mount_d, origin_local, heights, t_pt)


@functools.partial(jax.jit, static_argnames=("order", "duration"))
def _assemble_jit(scan, mount, heights, t_los, los, t_pt, v_pt, schedule, motion, start, span, *,
                  order, duration):
    dtype = los.dtype
    cast = lambda a: jnp.asarray(a).astype(dtype)  # noqa: E731
    scan = jax.tree_util.tree_map(cast, scan)
    mount_d = jax.tree_util.tree_map(cast, mount)
    return _series_assemble(scan, mount_d, heights, t_los, los, t_pt, v_pt, schedule, motion,
                            start, span, order=order, duration=duration)


_series_jit = jax.jit(_series, static_argnames=("n_cycles", "n_points", "order", "duration"))


class SeriesStatistics(eqx.Module):
    """Statistics per record and height (`statistics`); every field ``(r, h)``.

    Lidar, as a ``.sta`` reports them (from the valid reconstructions in the record):

    - `speed`: scalar mean of the per-reconstruction horizontal speeds, m/s;
    - `direction`: direction of the vector mean of the horizontal wind, degrees
      (meteorological);
    - `speed_std`, `speed_min`, `speed_max`: standard deviation (population, ``1/N``),
      minimum and maximum of the horizontal speed, m/s;
    - `w`, `w_std`: mean and standard deviation of the vertical wind, m/s;
    - `availability`: percent of the record's reconstructions that are valid (finite: a
      simulation has no CNR threshold, only beams outside the field are lost);
    - `ti`: ``speed_std / speed``.

    Point sensors directly above the lidar, sampled every `point_dt`:

    - cup: `cup_speed` (scalar mean of horizontal speed), `cup_std`, `cup_ti`;
    - sonic (vector): `sonic_speed` (horizontal speed of the vector mean), `sonic_direction`,
      `sonic_std` (std of the component along the mean direction, the longitudinal
      ``sigma_u``), `sonic_ti` = ``sonic_std / sonic_speed``, `sonic_w`, `sonic_w_std`.
    """

    speed: Float[Array, "r h"]
    direction: Float[Array, "r h"]
    speed_std: Float[Array, "r h"]
    speed_min: Float[Array, "r h"]
    speed_max: Float[Array, "r h"]
    w: Float[Array, "r h"]
    w_std: Float[Array, "r h"]
    availability: Float[Array, "r h"]
    ti: Float[Array, "r h"]
    cup_speed: Float[Array, "r h"]
    cup_std: Float[Array, "r h"]
    cup_ti: Float[Array, "r h"]
    sonic_speed: Float[Array, "r h"]
    sonic_direction: Float[Array, "r h"]
    sonic_std: Float[Array, "r h"]
    sonic_ti: Float[Array, "r h"]
    sonic_w: Float[Array, "r h"]
    sonic_w_std: Float[Array, "r h"]


def _masked_stats(x, mask, axis):
    n = jnp.sum(mask, axis=axis)
    nn = jnp.where(n > 0, n, 1)
    xs = jnp.where(mask, x, 0)
    mean = jnp.sum(xs, axis=axis) / nn
    var = jnp.sum(jnp.where(mask, (x - jnp.expand_dims(mean, axis)) ** 2, 0), axis=axis) / nn
    empty = n == 0
    nan = jnp.nan
    return jnp.where(empty, nan, mean), jnp.where(empty, nan, _std(var)), n


def _std(var):
    """``sqrt(var)`` with a zero (not NaN) gradient where the variance is 0."""
    return jnp.sqrt(jnp.where(var > 0, var, 0)) * jnp.where(var > 0, 1, 0)


def statistics(series: Series, starts: Float[ArrayLike, " r"] | None = None,
               record_length: float = RECORD_LENGTH) -> SeriesStatistics:
    """Reduce a `Series` to per-record statistics (`SeriesStatistics`).

    A record holds the reconstructions (and point samples) whose time lies in
    ``[start, start + record_length)``. Without `starts`, the whole series is one record.
    Pure and jit-compiled (`starts` and `record_length` are dynamic; shapes follow the
    number of records).
    """
    dtype = series.velocity.dtype
    if starts is None:
        starts = series.start[None]
        record_length = series.duration + 1e-6
    starts = jnp.atleast_1d(jnp.asarray(starts, dtype))
    return _statistics_jit(series, starts, jnp.asarray(record_length, dtype))


def _statistics(series: Series, starts, record_length) -> SeriesStatistics:
    dtype = series.velocity.dtype

    def one(s):
        t = series.time  # (n, h)
        inside = (t >= s) & (t < s + record_length)
        v = series.velocity
        ok = inside & jnp.all(jnp.isfinite(v), axis=-1)
        vs = jnp.where(ok[..., None], v, 0)
        spd = horizontal_speed(vs)
        speed, speed_std, n_ok = _masked_stats(spd, ok, 0)
        w, w_std, _ = _masked_stats(vs[..., 2], ok, 0)
        mean_vec = jnp.sum(vs, axis=0) / jnp.where(n_ok > 0, n_ok, 1)[:, None]
        direction = jnp.where(n_ok > 0, wind_direction(mean_vec), jnp.nan)
        big = jnp.asarray(jnp.inf, dtype)
        smin = jnp.where(n_ok > 0, jnp.min(jnp.where(ok, spd, big), axis=0), jnp.nan)
        smax = jnp.where(n_ok > 0, jnp.max(jnp.where(ok, spd, -big), axis=0), jnp.nan)
        n_in = jnp.sum(inside, axis=0)
        avail = 100.0 * n_ok / jnp.where(n_in > 0, n_in, 1)
        ti = speed_std / speed

        tp = series.point_time
        pin = (tp >= s) & (tp < s + record_length)
        vp = series.point_velocity
        pok = pin[:, None] & jnp.all(jnp.isfinite(vp), axis=-1)
        vps = jnp.where(pok[..., None], vp, 0)
        cup, cup_std, npk = _masked_stats(horizontal_speed(vps), pok, 0)
        vmean = jnp.sum(vps, axis=0) / jnp.where(npk > 0, npk, 1)[:, None]
        sonic_speed = jnp.where(npk > 0, horizontal_speed(vmean), jnp.nan)
        sonic_dir = jnp.where(npk > 0, wind_direction(vmean), jnp.nan)
        # std of the component along the mean direction e: e^T C e with C the (u, v)
        # covariance (the projection on e, written without projecting every sample onto a
        # mean that must be reduced first: one pass over the samples)
        unit = vmean[:, :2] / jnp.where(sonic_speed > 0, sonic_speed, 1)[:, None]
        du = jnp.where(pok, vps[..., 0] - vmean[:, 0], 0)
        dv = jnp.where(pok, vps[..., 1] - vmean[:, 1], 0)
        nn = jnp.where(npk > 0, npk, 1)
        cuu, cvv, cuv = (jnp.sum(du * du, 0) / nn, jnp.sum(dv * dv, 0) / nn,
                         jnp.sum(du * dv, 0) / nn)
        var_along = unit[:, 0] ** 2 * cuu + 2 * unit[:, 0] * unit[:, 1] * cuv + unit[:, 1] ** 2 * cvv
        sonic_std = jnp.where(npk > 0, _std(var_along), jnp.nan)
        sw, sw_std, _ = _masked_stats(vps[..., 2], pok, 0)
        return SeriesStatistics(
            speed=speed, direction=direction, speed_std=speed_std, speed_min=smin,
            speed_max=smax, w=w, w_std=w_std, availability=avail, ti=ti,
            cup_speed=cup, cup_std=cup_std, cup_ti=cup_std / cup, sonic_speed=sonic_speed,
            sonic_direction=sonic_dir, sonic_std=sonic_std, sonic_ti=sonic_std / sonic_speed,
            sonic_w=sw, sonic_w_std=sw_std)

    return jax.vmap(one)(starts)


_statistics_jit = jax.jit(_statistics)


def simulate_statistics(
    field: AbstractField,
    scan: Scan,
    mount: Mount,
    heights: Float[ArrayLike, " h"],
    starts: Float[ArrayLike, " r"],
    *,
    record_length: float = RECORD_LENGTH,
    schedule: Schedule | None = None,
    probe: AbstractProbe | None = None,
    motion: AbstractMotion | None = None,
    point_dt: float = 1.0,
    ensemble: bool = False,
    chunk: int | None = None,
    shard: bool = True,
    refine_probe: bool = True,
) -> SeriesStatistics:
    """Statistics of many records, streamed: each record is simulated and reduced to its
    statistics inside one compiled function, so no raw LOS outlives its chunk.

    Each record is simulated on its own from its start: its first reconstruction needs one
    full cycle, so a sliding Windcube record holds ``n_los - b + 1`` vectors (V2: 596 of the
    instrument's 600; the few windows straddling the previous record are not rebuilt).

    **Arguments:** as `simulate_series`, plus

    - `starts`: ``(r,)`` record start times, s (each record spans `record_length`);
    - `ensemble`: `field` is a stack of ``e`` fields (`lidarjax.stack_fields`: every array
      leaf has a leading axis ``e``); the result gets a leading ``e`` axis;
    - `chunk`: records per compiled batch (vmapped); memory grows with ``chunk`` (and ``e``),
      not with ``r``. None (default) chooses per backend (`lidarjax._backend.default_batch`):
      64 on a CPU; on a GPU or TPU all records at once (padded to a bucket of 1, 2, 3, 4, 6,
      8, 12, ... so that few lengths compile) when they fit in a quarter of the free device
      memory, else the largest chunk that does; with a float32 field that is advanced per
      chunk (below), at most ``2**16`` s of records (or 64 records) per chunk;
    - `shard`: spread each chunk's records over all local devices (`jax.sharding`,
      a 1-D mesh over `jax.devices()`); the chunk is padded to a multiple of the device
      count. One device: no sharding.
    - `refine_probe`: as in `simulate_series` (the probe's nodes resolve the box).

    **Returns:** `SeriesStatistics` with fields ``(r, h)`` (``(e, r, h)`` for an ensemble),
    numpy arrays on the host.

    **Float32 and long spans.** Times are in the field's dtype; a float32 time ``t`` resolves
    ``ulp(t)`` (2 s at a year). A field with an ``advanced(time)`` method
    (`lidarjax.scenes.FrozenTurbulence`, reduced in float64 on the host) is advanced to each
    chunk's first start and sampled at times relative to it, so any span keeps the resolution
    of one chunk (``chunk * record_length``; 0.004 s for 64 records). With a motion or an
    ensemble, times stay absolute: use float64 (x64) for spans beyond about a day in float32.
    """
    schedule = schedule_for(scan) if schedule is None else schedule
    probe = PointProbe() if probe is None else probe
    starts = np.atleast_1d(np.asarray(starts, dtype=np.float64))
    if starts.ndim != 1 or starts.size == 0 or not np.all(np.isfinite(starts)):
        raise ValueError("simulate_statistics: `starts` must be a non-empty 1-D array of seconds.")
    if not isinstance(schedule, Schedule):
        raise ValueError("simulate_statistics: `schedule` must be a lidarjax.Schedule.")
    schedule.check(scan)
    if not ensemble:  # a mesh's grid (`lidarjax.io.load_field`): exact at a fixed lidar's points
        field = exact_by_default(field, scan, mount, heights, probe, "simulate_statistics",
                                 moving=motion is not None)
    probe_field = jax.tree_util.tree_map(lambda a: a[0], field) if ensemble else field
    _validate(probe_field, scan, mount, np.asarray(heights), None, probe)
    if refine_probe:
        probe = probe_for_field(field, scan, heights, probe,
                                mount=None if ensemble else _fixed(mount, motion),
                                caller="simulate_statistics")
    dtype = probe_field.dtype
    heights = jnp.atleast_1d(jnp.asarray(heights, dtype=dtype))
    _, duration, n_cycles = _check_span((0.0, record_length), schedule, heights.shape[0])
    n_points = max(int(np.floor(duration / point_dt + 1e-9)), 1)
    order = tuple(int(i) for i in schedule.order())
    devices = jax.devices()
    n_dev = len(devices) if shard else 1
    rebase = motion is None and not ensemble and hasattr(field, "advanced")
    if chunk is None:
        n_nodes = int(getattr(probe, "n_nodes", 1))
        n_ens = jax.tree_util.tree_leaves(field)[0].shape[0] if ensemble else 1
        per_record = (np.dtype(dtype).itemsize * n_ens * n_cycles * len(order)
                      * heights.shape[0] * n_nodes * 64)
        chunk = default_batch("statistics", per_record / n_dev, starts.size)
        if rebase and np.dtype(dtype).itemsize < 8:  # keep float32 times fine within a chunk
            chunk = min(chunk, max(int(2.0**16 // float(record_length)), CPU_BATCH["statistics"]))
    chunk = max(int(chunk), 1)
    chunk = -(-chunk // n_dev) * n_dev
    fn = _record_stats_fn(n_cycles, n_points, order, float(record_length), ensemble,
                          max(chunk // n_dev, 1))
    sharding = None
    if n_dev > 1:
        mesh = jax.sharding.Mesh(np.asarray(devices), ("records",))
        sharding = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("records"))
    # Float32 times far from 0 are coarse (ulp(3e7 s) = 2 s). A field that can move its own
    # clock on the host in float64 (`FrozenTurbulence.advanced`) is advanced to each chunk's
    # first start and sees times relative to it (a chunk spans chunk * record_length).
    out = []
    for i in range(0, starts.size, chunk):
        part = starts[i:i + chunk]
        pad = np.concatenate([part, np.full(chunk - part.size, part[-1])])
        base = float(part[0]) if rebase else 0.0
        f_chunk = field.advanced(base) if rebase else field
        s = jnp.asarray(pad - base, dtype)
        if sharding is not None:
            s = jax.device_put(s, sharding)
        res = fn(f_chunk, scan, mount, heights, s, schedule, probe, motion,
                 jnp.asarray(point_dt, dtype))
        out.append(jax.tree_util.tree_map(lambda a, k=part.size: np.asarray(a)[..., :k, :], res))
    return jax.tree_util.tree_map(lambda *a: np.concatenate(a, axis=-2), *out)


_STATS_CACHE: dict = {}


def _record_stats_fn(n_cycles, n_points, order, record_length, ensemble, repeat):
    """The compiled per-chunk function (one per static configuration); `repeat`: records per
    device in a chunk, all sampling the same prepared field points."""
    key = (n_cycles, n_points, order, record_length, ensemble, repeat)
    if key in _STATS_CACHE:
        return _STATS_CACHE[key]

    def one_record(field, scan, mount, heights, start, schedule, probe, motion, point_dt):
        series = _series(field, scan, mount, heights, start, schedule, probe, motion, point_dt,
                         n_cycles=n_cycles, n_points=n_points, order=order,
                         duration=record_length, repeat=repeat)
        st = _statistics(series, start[None], jnp.asarray(record_length, heights.dtype))
        return jax.tree_util.tree_map(lambda a: a[0], st)

    over_records = jax.vmap(one_record, in_axes=(None, None, None, None, 0, None, None, None, None))
    if ensemble:
        over_records = jax.vmap(over_records,
                                in_axes=(0, None, None, None, None, None, None, None, None))
    fn = jax.jit(over_records)
    _STATS_CACHE[key] = fn
    return fn


__getattr__ = deprecated_getattr(__name__)
