"""Nodes per height on a real mesh and the exact path together: the points `lidarjax.beam_points`
prepares on the graded grid are the points `simulate` samples on the `CellPointField` built at
them (the node choice sees the same spacing through the field's `spacing_at`), so every node is
answered from its cellPoint tetrahedron."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

import lidarjax as lj
from lidarjax.io import CellPointField, read_settings

from ..helpers import DATA

FOAM = DATA / "openfoam"


def test_graded_nodes_are_the_prepared_points_on_the_roof():
    s = read_settings(FOAM / "pulsed" / "roof.dat")
    scan, probe = lj.windcube_v2(), lj.PulsedProbe()
    mount = lj.Mount(s.location(0.0), beta=0.0, gamma=0.0, psi=0.0, epsilon=0.0)
    h = np.asarray(s.heights())
    chosen = {}

    def points(grid):
        chosen["probe"] = lj.probe_for_field(grid, scan, h, probe, mount=mount)
        return lj.beam_points(grid, scan, mount, h, probe)

    f = lj.io.load_field(FOAM / "windAroundBuildings_cut", exact_at=points,
                         region=lj.scan_bounds(scan, mount, h, probe=probe))
    assert isinstance(f, CellPointField)
    on_grid = chosen["probe"]
    on_exact = lj.probe_for_field(f, scan, h, probe, mount=mount)
    counts = getattr(on_grid, "node_counts", (on_grid.n_nodes,) * h.size)
    assert getattr(on_exact, "node_counts", (on_exact.n_nodes,) * h.size) == counts
    assert min(counts) < lj.probe_for_field(f.grid, scan, h, probe).n_nodes  # graded: fewer
    # every point simulate samples is a prepared one
    pts = lj.io.simulate_points(scan, mount, h, on_exact)
    origin = np.asarray(f.origin, np.float64) + np.asarray(f.origin_lo, np.float64)
    assert np.asarray(f._match(jnp.asarray(pts - origin))[1]).all()
    exact = np.asarray(lj.simulate(f, scan, mount, h, probe=probe).lidar_speed)
    grid = np.asarray(lj.simulate(f.grid, scan, mount, h, probe=on_exact).lidar_speed)
    ok = np.isfinite(exact) & np.isfinite(grid)
    assert ok.sum() >= 3 and np.abs(exact - grid)[ok].max() > 1e-4  # the mesh's own values
