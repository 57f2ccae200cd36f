"""Scan timing: when each line of sight (LOS) of a scan is taken, and which beams a
reconstruction uses.

A `Schedule` describes one scan cycle of one height (dimensions: ``b`` beams in the order
of `lidarjax.Scan.directions`, ``h`` heights, ``r`` rotations):

- `beam_times`: ``(b,)`` offset of each beam's LOS from the start of its cycle, seconds;
- `period`: duration of one cycle (one rotation for a conical scan), seconds;
- `heights_sequential` (static): a pulsed lidar measures every range gate of a LOS at once
  (``False``); a focused continuous-wave lidar focuses one height at a time and cycles
  through the heights (``True``);
- `rotations_per_height` (static): cycles spent at one height before refocusing (sequential
  heights only), and `refocus` seconds lost between heights;
- `update` (static): ``"each_los"`` rebuilds the wind vector after every new LOS from the
  latest LOS of every beam (a sliding window, one reconstruction per LOS), ``"each_visit"``
  reconstructs once per cycle (simultaneous heights) or once per height visit from the LOS
  of all its rotations, averaged per beam (sequential heights; for the linear sine fit this
  equals the least-squares fit of all ``r * b`` LOS at once).

Times are dynamic (differentiable, never recompile); counts and modes are static.

**Defaults by scan method** (`schedule_for`; public figures, used as assumptions; override
them with your instrument's):

- Windcube V1 (``"windcube_v1"``, DBS): 4 LOS in the order 0, 90, 180, 270 degrees, about
  1.5 s per LOS including the prism rotation, so one full cycle every 6 s (Courtney et al.
  2008, "Testing and comparison of lidars for profile and turbulence measurements in wind
  energy"; Sathe et al. 2011 use the same figures); the instrument updates the wind
  vector after each LOS from the latest 4 LOS (``update="each_los"``).
- Windcube V2 (``"windcube_v2"``): 4 tilted LOS at 0, 90, 180, 270 degrees then the
  vertical beam, about 1 s per LOS (Leosphere data sheet: ~1 Hz LOS rate), 5 s per cycle;
  updated after each LOS from the latest 5 (4 tilted + vertical) LOS.
- ZephIR 300 (``"sine_fit"``, conical scan, CW): one rotation of 50 LOS per second (20 ms per
  LOS), 3 rotations per height, heights cycled one at a time (the focus moves), refocusing
  time taken as 0 by default; one sine fit per height visit from the 150 LOS (ZephIR 300
  data sheet and Sathe et al. 2011). The ZephIR's extra reference height (38 m) of every
  cycle is not simulated: give it as one of the heights if you need its time.
- The 6-beam scan (`lidarjax.six_beam`, ``"least_squares"`` over 5 beams at 45 degrees
  from the vertical, 72 degrees apart, then the vertical beam): the Windcube V2's optics in
  a 6-beam pattern, 1 s per LOS (the V2's ~1 Hz LOS rate above, an assumption: Sathe et
  al. 2015 measured the 6-beam method with a WindScanner, whose timing differs), 6 s per
  cycle, updated after each LOS from the latest 6 LOS. The Reynolds stresses use the LOS
  themselves (`lidarjax.reynolds_stresses`), not these reconstructions.
- ``"least_squares"``: treated as a pulsed lidar with 1 s per LOS, one reconstruction per
  LOS from the latest LOS of every beam.

Under all heights measured at once, every height's LOS ``j`` of cycle ``c`` is at
``t0 + c * period + beam_times[j]``; under sequential heights, height ``k``'s LOS ``j`` of
rotation ``r`` in cycle ``c`` is at ``t0 + c * T + k * D + r * period + beam_times[j]`` with
the visit ``D = rotations_per_height * period + refocus`` and the cycle ``T = h * D``.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ._precision import default_float, is_concrete
from .scan import Scan

__all__ = ["Schedule", "schedule_for", "UPDATES"]

UPDATES = ("each_los", "each_visit")


class Schedule(eqx.Module):
    """When each LOS of a scan cycle is taken (see the module docs for the layout).

    **Arguments:**

    - `beam_times`: ``(b,)`` seconds from the start of the cycle to each beam's LOS, beams in
      the order of `Scan.directions` (tilted beams, then the vertical one).
    - `period`: seconds per cycle (per rotation for a conical scan); at least the latest
      beam time.
    - `heights_sequential`: heights measured one at a time (CW lidar) instead of all at once
      (pulsed lidar) (static).
    - `rotations_per_height`: cycles per height visit, sequential heights only (static).
    - `refocus`: seconds lost when the focus moves to the next height (sequential only).
    - `update`: ``"each_los"`` (sliding window) or ``"each_visit"`` (static).

    Raises `ValueError` for negative or unordered-beyond-period times, a non-positive period,
    or an unknown update mode.
    """

    beam_times: Float[Array, " b"]
    period: Float[Array, ""]
    refocus: Float[Array, ""]
    heights_sequential: bool = eqx.field(static=True)
    rotations_per_height: int = eqx.field(static=True)
    update: str = eqx.field(static=True)

    def __init__(
        self,
        beam_times: Float[ArrayLike, " b"],
        period: Float[ArrayLike, ""],
        *,
        heights_sequential: bool = False,
        rotations_per_height: int = 1,
        refocus: Float[ArrayLike, ""] = 0.0,
        update: str = "each_los",
    ):
        if update not in UPDATES:
            raise ValueError(f"Schedule: unknown update {update!r}; choose one of {UPDATES}.")
        if int(rotations_per_height) < 1:
            raise ValueError(
                f"Schedule: rotations_per_height must be at least 1, got {rotations_per_height}.")
        if is_concrete(beam_times, period, refocus):
            bt = np.asarray(beam_times, dtype=np.float64)
            p = np.asarray(period, dtype=np.float64)
            if bt.ndim != 1 or bt.size == 0 or not np.all(np.isfinite(bt)) or np.any(bt < 0):
                raise ValueError(
                    f"Schedule: `beam_times` must be a non-empty 1-D array of non-negative "
                    f"seconds, got {np.asarray(beam_times).tolist()}.")
            if p.shape != () or not np.isfinite(p) or p <= 0 or p < bt.max():
                raise ValueError(
                    f"Schedule: `period` must be one positive number of seconds at least the "
                    f"latest beam time ({bt.max():g} s), got {np.asarray(period).tolist()}.")
            if not np.isfinite(refocus) or float(refocus) < 0:
                raise ValueError(f"Schedule: `refocus` must be >= 0 seconds, got {refocus!r}.")
        self.beam_times = _float(beam_times)
        self.period = _float(period)
        self.refocus = _float(refocus)
        self.heights_sequential = bool(heights_sequential)
        self.rotations_per_height = int(rotations_per_height)
        self.update = update

    @property
    def n_beams(self) -> int:
        return self.beam_times.shape[0]

    def order(self) -> np.ndarray:
        """Beam indices in the order they are taken (needs concrete `beam_times`)."""
        return np.argsort(np.asarray(self.beam_times), kind="stable")

    def cycle_time(self, n_heights: int) -> Float[Array, ""]:
        """Seconds until the schedule repeats: `period` for simultaneous heights, the
        visits of all `n_heights` for sequential ones."""
        if not self.heights_sequential:
            return self.period
        return n_heights * (self.rotations_per_height * self.period + self.refocus)

    def check(self, scan: Scan) -> None:
        """Raise `ValueError` unless this schedule has one time per beam of `scan`."""
        if self.n_beams != scan.n_beams:
            raise ValueError(
                f"Schedule: {self.n_beams} beam times for a scan of {scan.n_beams} beams; give "
                f"one time per beam (tilted beams, then the vertical one).")


def _float(value):
    value = jnp.asarray(value)
    if not jnp.issubdtype(value.dtype, jnp.floating):
        value = value.astype(default_float())
    return value


def schedule_for(scan: Scan, *, seconds_per_los: float | None = None) -> Schedule:
    """The default `Schedule` of a scan, by its reconstruction method (module docs):
    Windcube V1 1.5 s per LOS, V2 and the 6-beam scan (`lidarjax.six_beam`) 1 s per LOS
    (sliding reconstruction); ZephIR 1 s per rotation of its LOS, 3 rotations per height,
    heights in turn. `seconds_per_los`
    overrides the time per LOS (for the conical scan: the rotation is ``b`` LOS)."""
    b = scan.n_beams
    if scan.method == "sine_fit":
        dt = 1.0 / b if seconds_per_los is None else float(seconds_per_los)
        return Schedule(np.arange(b) * dt, b * dt, heights_sequential=True,
                        rotations_per_height=3, update="each_visit")
    default = {"windcube_v1": 1.5, "windcube_v2": 1.0}.get(scan.method, 1.0)
    dt = default if seconds_per_los is None else float(seconds_per_los)
    if not dt > 0:
        raise ValueError(f"schedule_for: seconds_per_los must be positive, got {seconds_per_los}.")
    return Schedule(np.arange(b) * dt, b * dt, update="each_los")
