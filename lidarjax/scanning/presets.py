"""Scan presets: PPI (sector and 360), RHI, stare, VAD at any elevation, the SpinnerLidar
rosette, and the pulsed probe of a scanning instrument.

Timing (all presets; angles in degrees, times in seconds, speeds in deg/s):

- ``mode="continuous"``: the head turns at a constant rate while accumulating; ray ``k`` of a
  sweep of ``n`` rays over ``span`` degrees is centred on ``start + (k + 1/2) span / n``, sweeps
  ``span / n`` during its accumulation ``T`` (rate ``span / (n T)``) and starts at ``k T``.
- ``mode="step"`` (step-and-stare): the head moves ``step`` at `head_speed`, stops, and
  accumulates ``T`` at rest (rate 0); rays at ``start + k step`` (a 360-degree sweep: ``step =
  360 / n``; a sector: both ends included, ``step = span / (n - 1)``), ray ``k`` starting at
  ``k (T + |step| / head_speed)``.
- `sweeps` repetitions in order: with ``alternate=True`` every other sweep runs backwards
  (a sector scanned back and forth, no return); otherwise the head returns to the start at
  `head_speed` between sweeps (a full 360-degree continuous sweep simply goes on turning).

Pulsed probe per gate (`instrument_probe`): the range weighting of `lidarjax.PulsedProbe`
with the instrument's gate length and pulse FWHM ``c tau / 2``. Defaults (public figures, used
as assumptions; set your instrument's): Halo StreamLine 30 m gates, 0.2 us pulse (Pearson et
al. 2009, J. Atmos. Oceanic Technol. 26, 240-250: 30 m range gates, pulse duration 0.2 us);
Windcube 200S 50 m gates with a 200 ns pulse (Leosphere: pulse 100/200/400 ns for the 25/50/75 m
resolutions).
"""

from __future__ import annotations

import numpy as np

from ..probe import SPEED_OF_LIGHT, PulsedProbe
from .pattern import ScanPattern

__all__ = ["ppi", "rhi", "stare", "vad", "spinner_rosette", "instrument_probe", "INSTRUMENTS",
           "MODES"]

MODES = ("continuous", "step")

#: Gate length (m) and pulse duration (s) of scanning instruments (assumptions: module docs).
INSTRUMENTS = {
    "halo_streamline": {"gate_length": 30.0, "pulse_duration": 0.2e-6},
    "windcube_200s": {"gate_length": 50.0, "pulse_duration": 200e-9},
}


def instrument_probe(instrument: str = "halo_streamline", *, gate_length: float | None = None,
                     pulse_duration: float | None = None, n_nodes: int | None = None) -> PulsedProbe:
    """The pulsed range weighting of a scanning instrument (`INSTRUMENTS`), optionally with
    its gate length (m) and pulse duration (s) overridden: a `lidarjax.PulsedProbe` with
    ``pulse_fwhm = c * pulse_duration / 2`` and the gate length."""
    if instrument not in INSTRUMENTS:
        raise ValueError(f"instrument_probe: unknown instrument {instrument!r}; choose one of "
                         f"{tuple(INSTRUMENTS)} or give gate_length and pulse_duration.")
    spec = INSTRUMENTS[instrument]
    gate = spec["gate_length"] if gate_length is None else gate_length
    tau = spec["pulse_duration"] if pulse_duration is None else pulse_duration
    if not (np.isfinite(tau) and tau > 0):
        raise ValueError(f"instrument_probe: pulse_duration must be positive seconds, got {tau!r}.")
    return PulsedProbe(SPEED_OF_LIGHT * tau / 2, gate, n_nodes=n_nodes)


def _positive(name, value):
    v = np.asarray(value, np.float64)
    if v.shape != () or not np.isfinite(v) or v <= 0:
        raise ValueError(f"{name} must be one positive number, got {value!r}.")
    return float(v)


def _sweeps(fn, start, span, n_rays, full, accumulation, mode, head_speed, sweeps, alternate):
    """Angles (relative to nothing: absolute), rates, ray starts and the period of `sweeps`
    sweeps of `n_rays` rays over `span` degrees from `start` (module docs)."""
    if mode not in MODES:
        raise ValueError(f"{fn}: mode must be one of {MODES}, got {mode!r}.")
    if int(n_rays) != n_rays or n_rays < 1:
        raise ValueError(f"{fn}: n_rays must be a positive integer, got {n_rays!r}.")
    if int(sweeps) != sweeps or sweeps < 1:
        raise ValueError(f"{fn}: sweeps must be a positive integer, got {sweeps!r}.")
    n = int(n_rays)
    t_acc = _positive(f"{fn}: accumulation", accumulation)
    speed = _positive(f"{fn}: head_speed", head_speed)
    if not np.isfinite(span) or (span == 0 and n > 1 and mode == "continuous"):
        raise ValueError(f"{fn}: the sweep spans no angle; give distinct start and stop angles.")
    if mode == "continuous":
        step = span / n
        angles = start + (np.arange(n) + 0.5) * step
        rate = np.full(n, step / t_acc)
        t0 = np.arange(n) * t_acc
        duration = n * t_acc
    else:
        step = span / n if full or n == 1 else span / (n - 1)
        angles = start + np.arange(n) * step
        rate = np.zeros(n)
        t0 = np.arange(n) * (t_acc + abs(step) / speed)
        duration = t0[-1] + t_acc
    if alternate is None:
        alternate = not full
    a_all, r_all, t_all = [], [], []
    clock = 0.0
    for s in range(int(sweeps)):
        backwards = alternate and s % 2 == 1
        a = angles[::-1] if backwards else angles
        r = -rate if backwards else rate
        a_all.append(a)
        r_all.append(r)
        t_all.append(clock + t0)
        if full and mode == "continuous":
            gap = 0.0  # the head keeps turning
        elif full:
            gap = abs(step) / speed  # one more step closes the circle
        elif alternate:
            gap = 0.0  # turns round at the end of the sector
        else:
            gap = abs(span) / speed  # returns to the start
        clock += duration + gap
    return (np.concatenate(a_all), np.concatenate(r_all), np.concatenate(t_all), clock,
            t_acc)


def ppi(elevation: float, ranges, *, azimuth_start: float = 0.0, azimuth_stop: float | None = None,
        n_rays: int = 360, accumulation: float = 1.0, mode: str = "continuous",
        head_speed: float = 30.0, sweeps: int = 1, alternate: bool | None = None,
        n_sub: int = 1) -> ScanPattern:
    """A plan-position indicator: fixed `elevation` (degrees), azimuth swept from
    `azimuth_start` to `azimuth_stop` (degrees clockwise; ``None``: a full 360-degree turn;
    a stop below the start sweeps anticlockwise), `n_rays` rays per sweep of `accumulation`
    seconds, gates at `ranges` (m). Timing (`mode`, `head_speed`, `sweeps`, `alternate`):
    module docs. `n_sub`: sub-rays averaged over each ray's swept arc."""
    full = azimuth_stop is None
    span = 360.0 if full else float(azimuth_stop) - float(azimuth_start)
    if not full and abs(span) >= 360.0:
        raise ValueError("ppi: a sector spans less than 360 degrees; leave azimuth_stop=None for "
                         "a full turn.")
    az, rate, t0, period, t_acc = _sweeps("ppi", float(azimuth_start), span, n_rays, full,
                                          accumulation, mode, head_speed, sweeps, alternate)
    return ScanPattern(np.mod(az, 360.0), float(elevation), ranges, ray_start=t0,
                       accumulation=t_acc, azimuth_rate=rate, period=period, n_sub=n_sub,
                       kind="ppi")


def rhi(azimuth: float, ranges, *, elevation_start: float = 0.0, elevation_stop: float = 90.0,
        n_rays: int = 90, accumulation: float = 1.0, mode: str = "continuous",
        head_speed: float = 30.0, sweeps: int = 1, alternate: bool | None = None,
        n_sub: int = 1) -> ScanPattern:
    """A range-height indicator: fixed `azimuth` (degrees clockwise), elevation swept from
    `elevation_start` to `elevation_stop` (degrees above the horizon; up to 180 looks over the
    top to the opposite horizon), `n_rays` rays per sweep; other arguments as `ppi`."""
    span = float(elevation_stop) - float(elevation_start)
    el, rate, t0, period, t_acc = _sweeps("rhi", float(elevation_start), span, n_rays, False,
                                          accumulation, mode, head_speed, sweeps, alternate)
    return ScanPattern(np.full(el.shape, float(azimuth)), el, ranges, ray_start=t0,
                       accumulation=t_acc, elevation_rate=rate, period=period, n_sub=n_sub,
                       kind="rhi")


def stare(azimuth: float, elevation: float, ranges, *, n_rays: int = 1,
          accumulation: float = 1.0, gap: float = 0.0) -> ScanPattern:
    """A fixed stare at `azimuth`, `elevation` (degrees): `n_rays` rays of `accumulation`
    seconds, `gap` seconds apart (end to start)."""
    if int(n_rays) != n_rays or n_rays < 1:
        raise ValueError(f"stare: n_rays must be a positive integer, got {n_rays!r}.")
    t_acc = _positive("stare: accumulation", accumulation)
    if not (np.isfinite(gap) and gap >= 0):
        raise ValueError(f"stare: gap must be >= 0 seconds, got {gap!r}.")
    n = int(n_rays)
    t0 = np.arange(n) * (t_acc + gap)
    return ScanPattern(np.full(n, float(azimuth)), float(elevation), ranges, ray_start=t0,
                       accumulation=t_acc, period=n * (t_acc + gap), kind="stare")


def vad(elevation: float, ranges, *, n_rays: int = 24, accumulation: float = 1.0,
        azimuth_start: float = 0.0, mode: str = "step", head_speed: float = 30.0,
        sweeps: int = 1, n_sub: int = 1) -> ScanPattern:
    """A velocity-azimuth display at any `elevation` (degrees): `n_rays` rays evenly around a
    full turn (step-and-stare by default, Halo's VAD; ``mode="continuous"`` for a sweeping
    one), reconstructed by `lidarjax.scanning.vad_fit`."""
    p = ppi(elevation, ranges, azimuth_start=azimuth_start, n_rays=n_rays,
            accumulation=accumulation, mode=mode, head_speed=head_speed, sweeps=sweeps,
            n_sub=n_sub)
    return ScanPattern(p.azimuth, p.elevation, p.ranges, ray_start=p.ray_start,
                       accumulation=p.accumulation, azimuth_rate=p.azimuth_rate, period=p.period,
                       n_sub=p.n_sub, kind="vad")


def rosette_angles(t, *, duration: float = 2.0, half_angle: float = 30.0,
                   turns: tuple[int, int] = (3, 4)):
    """Off-axis angle ``theta`` and azimuth about the axis ``phi`` (degrees) of the
    SpinnerLidar's rosette at times `t` (s); see `spinner_rosette`."""
    m1, m2 = turns
    w1, w2 = 2 * np.pi * m1 / duration, -2 * np.pi * m2 / duration
    t = np.asarray(t, np.float64)
    half = 0.5 * half_angle
    dx = half * (np.sin(w1 * t) + np.sin(w2 * t))
    dy = half * (np.cos(w1 * t) + np.cos(w2 * t))
    return np.hypot(dx, dy), np.rad2deg(np.arctan2(dx, dy))


def spinner_rosette(ranges, *, n_points: int = 400, duration: float = 2.0,
                    half_angle: float = 30.0, turns: tuple[int, int] = (3, 4),
                    n_sub: int = 1) -> ScanPattern:
    """The DTU SpinnerLidar's rosette (a nacelle lidar scanning through two counter-rotating
    prisms), `n_points` continuous rays over one pattern of `duration` seconds.

    Two wedge prisms each deflect the beam by ``half_angle / 2``; by first-order Risley-prism
    theory (Marshall 1999, "Risley prism scan patterns", Proc. SPIE 3787; the SpinnerLidar's
    optics, Mikkelsen et al. 2013, "A spinner-integrated wind lidar for enhanced wind turbine
    control", Wind Energy 16, 625-643, and its rosette in Herges et al. 2017, J. Phys.: Conf.
    Ser. 854, 012021) the deflections add as vectors:

        ``d(t) = (half_angle / 2) [(sin w1 t, cos w1 t) + (sin w2 t, cos w2 t)]``

    with prism rates ``w1 = 2 pi m1 / duration`` and ``w2 = -2 pi m2 / duration``
    (`turns` ``= (m1, m2)``, counter-rotating), a rose curve of ``m1 + m2`` petals reaching
    `half_angle` off the axis. The beam is ``|d|`` off the instrument axis at azimuth
    ``atan2(d_x, d_y)`` about it: in the body frame, elevation ``90 - |d|`` and that azimuth,
    so the axis is body ``+z``; mount it looking forward with ``lidarjax.Mount(..., pitch=-90)``
    (the nacelle chain of `lidarjax.frames`). The published instrument takes 984 points per
    2-second rosette within a 60-degree cone; the petal count here is an assumption (set
    `turns`). Each ray runs linearly in azimuth and elevation from the curve's point at the
    start of its accumulation (``duration / n_points``) to the one at its end (its centre is
    their midpoint, its rates their difference over the accumulation), so the rays join."""
    if int(n_points) != n_points or n_points < 2:
        raise ValueError(f"spinner_rosette: n_points must be an integer >= 2, got {n_points!r}.")
    dur = _positive("spinner_rosette: duration", duration)
    ha = _positive("spinner_rosette: half_angle", half_angle)
    if ha >= 90:
        raise ValueError(f"spinner_rosette: half_angle must be below 90 degrees, got {ha}.")
    n = int(n_points)
    t_acc = dur / n
    t0 = np.arange(n) * t_acc
    th0, ph0 = rosette_angles(t0, duration=dur, half_angle=ha, turns=turns)
    th1, ph1 = rosette_angles(t0 + t_acc, duration=dur, half_angle=ha, turns=turns)
    dphi = np.mod(ph1 - ph0 + 180.0, 360.0) - 180.0
    # each ray runs linearly in (azimuth, elevation) from the curve's point at its start to
    # the one at its end, so consecutive rays join
    theta, phi = (th0 + th1) / 2, ph0 + dphi / 2
    return ScanPattern(np.mod(phi, 360.0), 90.0 - theta, ranges, ray_start=t0,
                       accumulation=t_acc, azimuth_rate=dphi / t_acc,
                       elevation_rate=-(th1 - th0) / t_acc, period=dur, n_sub=n_sub,
                       kind="rosette")
