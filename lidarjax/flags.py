"""Bit flags that explain NaN or doubtful values in forward-model results.

`lidarjax.Simulation.flags` is an ``int32`` array per height holding the bitwise OR of these
values; test one with ``(sim.flags & Flag.BEAM_OUTSIDE) != 0``.
"""

from __future__ import annotations

import enum

__all__ = ["Flag"]


class Flag(enum.IntFlag):
    """Why a forward-model value is NaN (or doubtful). ``OK`` is 0."""

    OK = 0
    #: A beam's measurement point (or a quadrature node of its probe volume) lies outside the
    #: field or in a solid: its LOS, the reconstructed vector and the lidar factors are NaN.
    BEAM_OUTSIDE = 1
    #: The point directly above the lidar is outside the field or in a solid: the point
    #: velocity and the ``cfp_*`` factors are NaN.
    POINT_OUTSIDE = 2
    #: The reconstructed horizontal wind is exactly zero: its direction is undefined (NaN).
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
