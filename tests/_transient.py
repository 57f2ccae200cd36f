"""The committed pimpleFoam transient's own probes as a lidar's reference (shared by tests)."""

from __future__ import annotations

import numpy as np

#: The snapshot times of tests/data/openfoam_transient/case, s.
SNAPSHOTS = np.arange(10.0, 30.1, 2.0)
#: The Windcube V2 the probes were written for, standing on the ground, CFD metres.
LIDAR = np.array([150.0, 60.0, 0.0])


def probe_los(probes, mp, height, beam, times, *, lidar=LIDAR, snapshots=SNAPSHOTS):
    """OpenFOAM's probes at the monitor point of (`height`, `beam`) projected on the beam
    from the `lidar` (geometry independent of lidarjax's), interpolated linearly between the
    `snapshots` times (what a snapshot sequence represents) at `times` (s)."""
    rows = [int(np.argmin(np.abs(probes.times - t))) for t in snapshots]
    j = int(np.flatnonzero((mp.height == height) & (mp.beam == beam))[0])
    d = probes.header_points[j] - lidar
    return np.interp(times, snapshots, probes.values[rows, j] @ (d / np.linalg.norm(d)))
