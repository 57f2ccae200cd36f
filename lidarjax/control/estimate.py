"""The lidar's REWS estimate from a simulated (or recorded) LOS time series: what
`lidarjax.simulate_series` gives for a nacelle or spinner lidar, processed as Task 52's lidar
data processing does, next to the rotor's REWS at the times it previews.

`series_rews` takes a `lidarjax.Series` (a profiling scan mounted forward-looking:
`lidarjax.nacelle_2beam`, `lidarjax.nacelle_4beam`, a circular `lidarjax.Scan` or
`lidarjax.zephir` with ``Mount(..., pitch=-90)``; ``heights`` are then distances along the
axis) or a `lidarjax.ScanResult` (a scanning pattern such as `lidarjax.spinner_rosette`,
through `simulate_series` or `lidarjax.simulate_scan_series`; its rays are the beams, its
range gates the gates). Frames as `lidarjax.control.rews`: the rotor at `hub` (field
coordinates, m) facing `yaw` (degrees).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..beam import profile_geometry
from ..mount import Mount
from ..scan import Scan
from ..scanning.simulate import ScanResult
from ..series import Series, _reconstruction_windows
from ..timing import Schedule, schedule_for
from .geometry import RotorDisc
from .rews import rotor_rews, rotor_to_cfd

__all__ = ["RewsSeries", "series_rews"]

UPDATES = ("each_los", "each_scan")


class RewsSeries(eqx.Module):
    """The lidar's REWS estimate through time, and the rotor's REWS it previews (`series_rews`).

    **Fields** (``n`` estimates):

    - `time`: ``(n,)`` when each estimate is formed: the latest LOS in its window (s).
    - `preview_time`: ``(n,)`` when the wind it measured reaches the rotor (s): the mean over
      the window's LOS of ``t_j + x_j / U``, ``t_j`` the LOS time and ``x_j`` its focus
      point's distance upstream of the hub along the rotor axis (frozen turbulence at `speed`).
    - `estimate`: ``(n,)`` the estimate (m/s): the mean over the window's beams and gates of
      ``-LOS_j / nx_j`` (LOS positive away from the lidar, ``nx_j`` the beam's cosine to the
      upstream rotor axis); NaN where a LOS of the window is.
    - `speed`: the ``U`` of the preview (m/s).
    - `rews`: ``(n,)`` `rotor_rews` of the field at `preview_time` (m/s), or None without a field.
    """

    time: Float[Array, " n"]
    preview_time: Float[Array, " n"]
    estimate: Float[Array, " n"]
    speed: Float[Array, ""]
    rews: Float[Array, " n"] | None


def series_rews(result: Series | ScanResult, scan: Scan | None = None, mount: Mount | None = None, *,
                hub: Float[ArrayLike, " 3"], yaw: Float[ArrayLike, ""], field=None,
                rotor: RotorDisc | None = None, speed: Float[ArrayLike, ""] | None = None,
                schedule: Schedule | None = None, update: str | None = None) -> RewsSeries:
    """The REWS estimate of a nacelle or spinner lidar from its LOS time series, Task 52's
    processing (`lidar_rews`'s estimate, on the LOS the instrument took), at the times it
    previews, and the rotor's REWS there.

    **Arguments:**

    - `result`: a `lidarjax.Series` (`simulate_series` of a `Scan`) or a `ScanResult` (of a
      scanning pattern, one mount; a single scan's ``(r, g)`` counts as one repetition).
    - `scan`, `mount`: the `Scan` and `Mount` the `Series` was simulated with (its beams'
      directions and focus points; ``heights`` are the series'). Not used with a `ScanResult`,
      which holds its rays' directions and gate centres.
    - `hub`, `yaw`: the rotor in the field (CFD m; degrees, the compass direction it faces).
    - `field`, `rotor`: give both for the rotor's REWS (`rotor_rews`) at the preview times.
    - `speed`: ``U`` of the preview shift (m/s); default the mean of the finite estimates.
    - `schedule`: the `Series`' scan timing (default `lidarjax.schedule_for(scan)`).
    - `update` (static): ``"each_los"``, after every new LOS from the latest LOS of every beam
      and gate (Task 52's ``LDP_v1``; the windows of a sliding reconstruction), or
      ``"each_scan"``, one estimate per complete scan (per height visit of every height for
      sequential heights, its rotations averaged). Default: the schedule's (``"each_los"``
      for a sliding schedule, else ``"each_scan"``); ``"each_scan"`` for a `ScanResult`.

    **Returns:** a `RewsSeries`. Jit-compiled; differentiable in the LOS, the geometry
    (`scan`, `mount`), `hub`, `yaw`, `speed` and the field's numbers. Raises `ValueError`
    before compiling for inconsistent inputs.
    """
    if (field is None) != (rotor is None):
        raise ValueError("series_rews: give both `field` and `rotor` for the rotor's REWS, or neither.")
    if update is not None and update not in UPDATES:
        raise ValueError(f"series_rews: `update` must be one of {UPDATES} or None, got {update!r}.")
    if isinstance(result, ScanResult):
        los, times, dirs, points, order, rot = _scan_result_parts(result)
        sliding = update == "each_los"
    elif isinstance(result, Series):
        los, times, dirs, points, order, rot, sliding = _series_parts(result, scan, mount, schedule,
                                                                      update)
    else:
        raise ValueError(f"series_rews: `result` must be a lidarjax Series or ScanResult, got "
                         f"{type(result).__name__}.")
    if np.shape(hub) != (3,):
        raise ValueError(f"series_rews: `hub` must be (x, y, z) in field metres, got shape {np.shape(hub)}.")
    dtype = los.dtype
    speed = None if speed is None else jnp.asarray(speed, dtype)
    return _rews_series(los, times, dirs, points, jnp.asarray(hub, dtype), jnp.asarray(yaw, dtype),
                        speed, field, rotor, order=order, rot=rot, sliding=sliding)


def _scan_result_parts(res: ScanResult):
    """A `ScanResult` as ``(m, h, b)`` LOS and times (gates as heights, rays as beams) and
    the ``(h, b, 3)`` directions and focus points, CFD."""
    if res.directions.ndim != 2:
        raise ValueError("series_rews: a ScanResult of a batch of mounts; pass one mount's "
                         "(jax.tree_util.tree_map(lambda a: a[k], result)).")
    los, times = (res.los, res.times) if res.los.ndim == 3 else (res.los[None], res.times[None])
    los = jnp.swapaxes(los, 1, 2)  # (n, g, r)
    times = jnp.broadcast_to(times[:, None, :], los.shape)
    dirs = jnp.broadcast_to(res.directions[None], los.shape[1:] + (3,))
    points = jnp.swapaxes(res.points, 0, 1)
    return los, times, dirs, points, tuple(range(los.shape[2])), 1


def _series_parts(series: Series, scan, mount, schedule, update):
    """A `Series`' LOS, times, and its beams' ``(h, b, 3)`` directions and focus points."""
    if not isinstance(scan, Scan) or not isinstance(mount, Mount):
        raise ValueError("series_rews: a Series needs the `scan` (lidarjax.Scan) and `mount` "
                         "(lidarjax.Mount) it was simulated with.")
    if mount.batch_shape:
        raise ValueError("series_rews: `mount` is a batch; pass the one mount of the series.")
    if series.los.shape[-1] != scan.n_beams:
        raise ValueError(f"series_rews: the series has {series.los.shape[-1]} beams, the scan "
                         f"{scan.n_beams}; pass the scan it was simulated with.")
    schedule = schedule_for(scan) if schedule is None else schedule
    if not isinstance(schedule, Schedule):
        raise ValueError(f"series_rews: `schedule` must be a lidarjax.Schedule, got "
                         f"{type(schedule).__name__}.")
    schedule.check(scan)
    update = update or ("each_los" if schedule.update == "each_los" else "each_scan")
    if update == "each_los" and schedule.heights_sequential:
        raise ValueError("series_rews: update='each_los' needs all heights measured at once; a "
                         "schedule with sequential heights updates once per visit ('each_scan').")
    rot = schedule.rotations_per_height if schedule.heights_sequential else 1
    if series.los.shape[0] % rot:
        raise ValueError(f"series_rews: {series.los.shape[0]} rotations are not whole visits of "
                         f"{rot}; pass the schedule the series was simulated with.")
    dirs, points = _profile_points(scan, mount, series.heights)
    return (series.los, series.los_time, dirs, points, tuple(int(i) for i in schedule.order()), rot,
            update == "each_los")


@eqx.filter_jit
def _profile_points(scan, mount, heights):
    """A profiling scan's ``(h, b, 3)`` beam directions and focus points (CFD)."""
    n_cfd, ranges = profile_geometry(scan, mount, heights)
    dtype = heights.dtype
    lidar = mount.location.astype(dtype) + mount.location_lo.astype(dtype)
    return jnp.broadcast_to(n_cfd, ranges.shape + (3,)), lidar + ranges[..., None] * n_cfd


@eqx.filter_jit
def _rews_series(los, times, dirs, points, hub, yaw, speed, field, rotor, *, order, rot, sliding):
    axis = rotor_to_cfd(yaw)[:, 0]  # upstream rotor axis, CFD
    u = -los / jnp.sum(dirs * axis, axis=-1)
    x = jnp.sum((points - hub) * axis, axis=-1)  # (h, b) upstream of the hub
    u_w, t_est = _reconstruction_windows(u, times, order, sliding, rot)
    t_w, _ = _reconstruction_windows(times, times, order, sliding, rot)
    estimate = jnp.mean(u_w, axis=(1, 2))
    if speed is None:
        ok = jnp.isfinite(estimate)
        speed = jnp.sum(jnp.where(ok, estimate, 0)) / jnp.sum(ok)
    preview = jnp.mean(t_w + x / speed, axis=(1, 2))
    rews = None if field is None else rotor_rews(field, rotor, hub=hub, yaw=yaw, times=preview)
    return RewsSeries(time=jnp.max(t_est, axis=1), preview_time=preview, estimate=estimate,
                      speed=speed, rews=rews)
