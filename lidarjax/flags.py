"""Every bit-flag enumeration of lidarjax, in one place.

- `Flag`: why a forward-model value is NaN or doubtful (`lidarjax.Simulation.flags`).
- `InverseFlag`: why an inversion result is NaN or doubtful (`lidarjax.Inversion.flags`).
- `RecordFlag`: why a value read from a lidar record file is NaN or doubtful (the readers'
  ``flags`` arrays), with `BLOCKING_FLAGS` and `MIN_AVAILABILITY`.

Forward-model flags in detail:

`lidarjax.Simulation.flags` is an ``int32`` array per height holding the bitwise OR of these
values; test one with ``(sim.flags & Flag.BEAM_OUTSIDE) != 0``.
"""

from __future__ import annotations

import enum

__all__ = ["Flag", "InverseFlag", "RecordFlag", "BLOCKING_FLAGS", "MIN_AVAILABILITY"]


class Flag(enum.IntFlag):
    """Why a forward-model value is NaN (or doubtful). ``OK`` is 0."""

    OK = 0
    #: A beam's measurement point (or a quadrature node of its probe volume) lies outside the
    #: field or in a solid: its LOS, the reconstructed vector and the lidar factors are NaN.
    BEAM_OUTSIDE = 1
    #: The point directly above the lidar is outside the field or in a solid: the point
    #: velocity and the ``cfp_*`` factors are NaN.
    POINT_OUTSIDE = 2
    #: The reconstructed horizontal wind is calm: zero, or its square at or below the dtype's
    #: smallest normal number (``finfo.tiny``: speeds to about 1.5e-154 m/s in float64,
    #: 1.1e-19 m/s in float32). Its direction is undefined: `Simulation.lidar_direction`
    #: and `lidarjax.wind_direction` give NaN exactly where this flag is set (one definition).
    CALM = 4
    #: The scan's beam matrix is ill-conditioned: condition number above
    #: `lidarjax.scan.ILL_CONDITIONED` = 100, a cone angle below 0.81 degrees (DBS, sine fit;
    #: 0.91 for the Windcube V2). The values are computed as usual, but LOS errors reach the
    #: horizontal wind amplified more than 50 times (``cond / sqrt(K)`` for ``K`` evenly spaced
    #: beams; see `lidarjax.scan`).
    ILL_CONDITIONED = 8
    #: A correction factor is NaN because its denominator is below the ratio tolerance
    #: (a component of the lidar vector is nearly zero).
    RATIO_UNDEFINED = 16
    #: A probe volume reached the lidar (range <= 0) on some beam: its nodes were cut
    #: symmetrically at ``|offset| < range`` and renormalised, and the weight dropped exceeded
    #: the probe's ``tail``. The LOS is finite but averages over a shorter stretch of beam
    #: (or, when no node is left, is the focus point's; see `lidarjax.probe`).
    PROBE_TRUNCATED = 32
    #: A time-dependent field is not defined at the LOS's (or point sample's) time: it lies
    #: outside the span of an unsteady field's snapshots (`lidarjax.SnapshotField`,
    #: `lidarjax.FieldSequence`). The value is NaN (`lidarjax.Series.los_flags`).
    TIME_OUTSIDE = 64


class InverseFlag(enum.IntFlag):
    """Why an inversion result is NaN or doubtful (bitmask in `Inversion.flags`). ``OK`` is 0."""

    OK = 0
    #: Fewer than `min_beams` finite, positively weighted beams: result NaN, not converged.
    TOO_FEW_BEAMS = 1
    #: The solver did not converge within `max_steps` (or met non-finite values): NaN.
    NOT_CONVERGED = 2
    #: The usable beams cannot tell the direction (``[R, dR/dd]`` is rank deficient): NaN.
    ILL_CONDITIONED = 4
    #: The best fit is zero speed: `direction` is NaN and `direction_std` inf.
    CALM = 8
    #: No noise level was given and there are no spare beams to estimate it (two beams for
    #: two unknowns): the standard deviations are NaN.
    NO_NOISE_ESTIMATE = 16
    #: The input is physically impossible (a negative reported speed): NaN, never
    #: reinterpreted (a negative speed is not read as the opposite direction).
    IMPOSSIBLE_INPUT = 32
    #: `lidarjax.invert_joint`: the profile parameter lies outside the table's range; the
    #: response was continued linearly in the parameter (the result is kept, but doubtful).
    PARAMETER_EXTRAPOLATED = 64


class RecordFlag(enum.IntFlag):
    """Why a value of a lidar record read from a file is NaN (or doubtful). ``OK`` is 0.

    Readers (`read_sta`, `read_zephir_csv`, `group_rtd`) return a ``flags`` integer array
    holding the bitwise OR of these bits; test one with ``(rec.flags & RecordFlag.X) != 0``.
    """

    OK = 0
    #: The file's row could not be read (cut mid-row, unreadable time stamp, non-numeric
    #: cell, wrong field count): every value of the record is NaN. A warning names the line.
    CORRUPT_ROW = 1
    #: The row's time stamp was unreadable and was inferred from its neighbours (regular
    #: spacing); the values are still NaN (`CORRUPT_ROW` is set too).
    TIME_INFERRED = 2
    #: The interval is only partly covered by the file (first or last interval of a `.rtd`
    #: file that starts or stops inside it).
    PARTIAL_INTERVAL = 4
    #: Data availability below the reader's minimum (`MIN_AVAILABILITY` percent by default):
    #: the value is not used (NaN).
    LOW_AVAILABILITY = 8
    #: A physically impossible value in the file (negative speed, dispersion or
    #: availability, direction outside [0, 360], availability above 100 %): kept out (NaN),
    #: never reinterpreted.
    IMPOSSIBLE_VALUE = 16
    #: A beam of a `.rtd` interval has no sample at or above the CNR threshold.
    BELOW_CNR_THRESHOLD = 32
    #: The row repeats an earlier row's time stamp.
    DUPLICATE_TIME = 64
    #: CNR above 0 dB: no clear-air aerosol return is that strong (Windcube CNR is typically
    #: -30 to -5 dB); a cloud, fog or a hard target is in the probe volume. The wind value
    #: is kept (the real `.sta` files show plausible speeds there) but is doubtful.
    HIGH_CNR = 128


BLOCKING_FLAGS = (RecordFlag.CORRUPT_ROW | RecordFlag.LOW_AVAILABILITY
                  | RecordFlag.IMPOSSIBLE_VALUE | RecordFlag.BELOW_CNR_THRESHOLD)
"""The `RecordFlag` bits whose values are NaN and must not be used; the others are advisory."""


MIN_AVAILABILITY = 80.0
"""Minimum data availability (percent) for a record to be used (`RecordFlag.LOW_AVAILABILITY`).

80 % is the usual filter of wind-resource practice for 10-minute lidar statistics (a
record built from fewer than 4 in 5 expected line-of-sight samples, or reconstructions, is
discarded). Every reader takes a `min_availability` argument to change it.
"""
