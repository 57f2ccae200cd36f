"""An OpenFOAM snapshot sequence locates its grid in the mesh once: the second snapshot builds
the cellPoint tetrahedra, the point-value weights and each node's tetrahedron, and every later
one only mixes its own values (`lidarjax.io._cells.PointValues`,
`CellPointSampler.grid_locations` / `values_at`). Checked on the real pimpleFoam transient
(its inflow, a fixedValue patch, changes between snapshots) against building the sampler
afresh for each snapshot, with numba and with the numpy fallback."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lidarjax.io import load_field_sequence
from lidarjax.io.openfoam import read_openfoam_field
from lidarjax.io.snapshots import cells_covering

DATA = Path(__file__).resolve().parents[1] / "data" / "openfoam_transient" / "case"


@pytest.fixture(scope="module")
def sequence():
    # the whole box: the inflow patch (its fixedValue changes with time) and the slip top and
    # sides (their values follow the cells next to them) give the patch points their values
    seq = load_field_sequence(DATA, spacing=5.0, time_range=(10.0, 20.0))
    win = seq.window(0, len(seq.times) - 1)  # six snapshots, 10..20 s
    axes = [np.asarray(a, np.float64) for a in (win.grid.x, win.grid.y, win.grid.z)]
    return seq, win, axes


def _cells(of, axes):
    return cells_covering(of.bounds, axes)


def test_every_snapshot_equals_a_sampler_built_for_it(sequence):
    seq, win, axes = sequence
    assert len(seq.times) >= 4  # the first, the one that prepares, and refilled ones
    inflow = []
    for k, t in enumerate(seq.times):
        of = read_openfoam_field(DATA, time=t)
        fresh, _ = of.sampler(_cells(of, axes)).sample_grid(axes)
        got = np.asarray(win.snapshot(k).velocity, np.float64)
        assert np.array_equal(np.isnan(got), np.isnan(fresh)) and np.isfinite(fresh).mean() > 0.5
        np.testing.assert_allclose(got, fresh, rtol=0, atol=1e-12, equal_nan=True)
        inflow.append(np.nanmax(fresh[..., 0]))
    assert np.ptp(inflow) > 0.5  # the snapshots differ (the inflow ramps)


@pytest.mark.parametrize("use_numba", [True, False])
def test_grid_locations_then_values_equal_sample_grid(sequence, use_numba):
    if use_numba:
        import numba  # noqa: F401  (the test extra brings it)
    _, _, axes = sequence
    of = read_openfoam_field(DATA, time="20")
    sampler = of.sampler(_cells(of, axes))
    direct, _ = sampler.sample_grid(axes, use_numba=use_numba)
    tets, weights = sampler.grid_locations(axes, use_numba=use_numba)
    assert tets.shape == direct.shape[:3] and weights.shape == direct.shape[:3] + (4,)
    assert np.array_equal(tets < 0, np.isnan(direct).any(axis=-1))
    mixed = sampler.values_at(tets, weights, use_numba=use_numba)
    np.testing.assert_allclose(mixed, direct, rtol=0, atol=1e-12, equal_nan=True)
    np.testing.assert_allclose(weights[tets >= 0].sum(axis=-1), 1.0, atol=1e-12)
