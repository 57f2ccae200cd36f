"""Disturbed sectors around a measurement (IEC 61400-12-1, Annex A).

A wind turbine at distance ``L`` (m) and bearing ``b`` (degrees clockwise from north, seen from
the measurement) with rotor diameter ``D`` disturbs the wind directions within ``w / 2`` of
``b``, with the excluded width (degrees)::

    w = 1.3 atan(2.5 D / L + 0.15) + 10        (atan in degrees)

Conventions where the standard's figure stops (it covers ``2 <= L / D <= 20``):

- **beyond 20 D** a turbine is not a disturbance (Annex A considers neighbours up to 20 D);
  `DisturbedSector.considered` is False and it excludes nothing;
- **below 2 D** the width is evaluated at ``L = 2 D`` (80.8 degrees, the widest the formula
  gives; the formula grows without a physical basis as ``L -> 0``) and the sector is marked
  `too_close`: a measurement this close to a rotor does not meet Annex A's siting at all, and
  its excluded sector is a lower bound.

A turbine at the measurement's own position (a nacelle lidar on its turbine: ``L`` below
1 mm) is skipped. Overlapping sectors are merged on the circle (`merge_sectors`);
`in_sectors` tells which wind directions (meteorological degrees) fall in them. Host numpy:
geometry, not part of the compiled model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["DisturbedSector", "excluded_width", "disturbed_sectors", "merge_sectors",
           "in_sectors", "MIN_DISTANCE_D", "MAX_DISTANCE_D"]

#: Below this many rotor diameters the width is evaluated here and the sector is `too_close`.
MIN_DISTANCE_D = 2.0
#: Beyond this many rotor diameters a turbine disturbs nothing (IEC 61400-12-1 Annex A).
MAX_DISTANCE_D = 20.0


def excluded_width(distance, diameter):
    """IEC 61400-12-1 Annex A excluded width in degrees, ``1.3 atan(2.5 D / L + 0.15) + 10``,
    with ``L`` clamped to at least ``2 D`` (module docs). Broadcasts; metres in."""
    d = np.asarray(diameter, np.float64)
    L = np.maximum(np.asarray(distance, np.float64), MIN_DISTANCE_D * d)
    return 1.3 * np.degrees(np.arctan(2.5 * d / L + 0.15)) + 10.0


@dataclass(frozen=True)
class DisturbedSector:
    """One turbine seen from the measurement: `bearing` (degrees clockwise from north),
    `distance` (m), `diameter` (m), excluded `width` (degrees), whether it is `considered`
    (within 20 D) and `too_close` (below 2 D)."""

    name: str
    bearing: float
    distance: float
    diameter: float
    width: float
    considered: bool
    too_close: bool

    @property
    def start(self) -> float:
        """First excluded direction (degrees, in [0, 360))."""
        return float(np.mod(self.bearing - 0.5 * self.width, 360.0))

    @property
    def end(self) -> float:
        """Last excluded direction, ``start + width`` (may exceed 360)."""
        return self.start + self.width


def disturbed_sectors(location, easting, northing, diameter, names=None) -> list[DisturbedSector]:
    """The disturbed sector of every turbine seen from `location` ``(x, y[, z])`` (m; same
    frame as `easting`/`northing`). Turbines within 1 mm of the location (the lidar's own
    turbine) are skipped."""
    loc = np.asarray(location, np.float64)
    e, n = np.asarray(easting, np.float64), np.asarray(northing, np.float64)
    d = np.broadcast_to(np.asarray(diameter, np.float64), e.shape)
    names = [f"T{k}" for k in range(e.size)] if names is None else list(names)
    out = []
    for k in range(e.size):
        dx, dy = e[k] - loc[0], n[k] - loc[1]
        dist = float(np.hypot(dx, dy))
        if dist < 1e-3:
            continue
        bearing = float(np.mod(np.degrees(np.arctan2(dx, dy)), 360.0))
        out.append(DisturbedSector(
            names[k], bearing, dist, float(d[k]), float(excluded_width(dist, d[k])),
            bool(dist <= MAX_DISTANCE_D * d[k]), bool(dist < MIN_DISTANCE_D * d[k])))
    return out


def merge_sectors(sectors) -> list[tuple[float, float]]:
    """Merge sectors (`DisturbedSector`\\ s, only the `considered` ones, or ``(start, end)``
    pairs in degrees) into disjoint ``(start, end)`` intervals, ``start`` in [0, 360) and
    ``start < end <= start + 360``; a union covering every direction is ``[(0, 360)]``."""
    iv = []
    for s in sectors:
        if isinstance(s, DisturbedSector):
            if not s.considered:
                continue
            a, b = s.start, s.end
        else:
            a, b = float(s[0]), float(s[1])
            b = a + np.mod(b - a, 360.0) if b - a < 360.0 else a + 360.0
            a0 = np.mod(a, 360.0)
            a, b = a0, a0 + (b - a)
        iv.append((a, b))
    if not iv:
        return []
    iv.sort()
    merged = [list(iv[0])]
    for a, b in iv[1:]:
        if a <= merged[-1][1]:
            merged[-1][1] = max(merged[-1][1], b)
        else:
            merged.append([a, b])
    # the last interval may wrap past 360 onto the first ones
    while len(merged) > 1 and merged[-1][1] - 360.0 >= merged[0][0]:
        a, b = merged.pop(0)
        merged[-1][1] = max(merged[-1][1], b + 360.0)
    if any(b - a >= 360.0 for a, b in merged):
        return [(0.0, 360.0)]
    return [(float(a), float(b)) for a, b in merged]


def in_sectors(directions, merged) -> np.ndarray:
    """Whether each wind direction (degrees) lies in one of the `merged` intervals
    (closed at both ends)."""
    d = np.mod(np.asarray(directions, np.float64), 360.0)
    out = np.zeros(d.shape, bool)
    for a, b in merged:
        out |= np.mod(d - a, 360.0) <= (b - a) + 1e-12
        if b - a >= 360.0:
            out[...] = True
    return out
