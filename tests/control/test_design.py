"""Scan design by gradients for lidar-assisted control against a dense grid search: as good
within 1 % with at least 10x fewer objective evaluations."""

import numpy as np
import pytest

from lidarjax import control as lc
from lidarjax.design import control as dc

INFLOW = lc.KaimalInflow(11.4, lc.iec_turbulence_intensity(11.4, "A"))
# a cheap configuration (a 3-points-per-radius disc, 24 frequencies): the cost is the search's one
# compilation, not its evaluations
KW = dict(n_points=4, distance=100.0, half_cone=(5.0, 40.0), gate_length=30.0, spacing=3.0,
          frequency=np.linspace(0.005, 0.4, 24))


def test_design_beats_grid_search():
    dense = np.linspace(5.0, 40.0, 150)[:, None]  # a 0.23 degree grid
    values, _ = dc.lac_objective("NREL5MW", INFLOW, dense, **KW)
    best = np.nanmin(values)
    kw = dict(KW, n_points=(4,))
    d = dc.design_lac_scan("NREL5MW", INFLOW, n_coarse=4, n_starts=1, max_steps=8, **kw)
    assert d.names == ("half_cone",)
    assert d.value <= best + 0.01 * abs(best)
    assert 10 * d.n_evaluations <= dense.shape[0]
    assert d.bandwidth == pytest.approx(-d.value)
    assert 5.0 < d.x[0] < 40.0  # an interior optimum: too narrow misses the disc, too wide sees v and w
    assert d.scan_radius == pytest.approx(100.0 * np.tan(np.deg2rad(d.x[0])))


def test_design_refuses_bad_input():
    with pytest.raises(ValueError, match="turbine"):
        dc.design_lac_scan("V236", INFLOW)
    with pytest.raises(ValueError, match="nothing to optimise"):
        dc.design_lac_scan("NREL5MW", INFLOW, distance=100.0, half_cone=20.0, gate_length=30.0)
    with pytest.raises(ValueError, match="objective"):
        dc.design_lac_scan("NREL5MW", INFLOW, objective="power")
    with pytest.raises(ValueError, match="inflow must be a KaimalInflow or a MannInflow"):
        dc.design_lac_scan("NREL5MW", object())


def test_design_objective_under_mann_inflow():
    """The design takes a `MannInflow` through the same code path: its bandwidth (Newton's root
    of ``gamma^2 = 0.5`` of the Mann spectra) is where `lac_spectra`'s Mann coherence of the
    same scan is 0.5, and lies between two grid frequencies bracketing that crossing."""
    mann = lc.MannInflow(11.4, length_scale=29.4, gamma=3.9, sigma_u=2.2, n_nodes=8)
    f = np.linspace(0.005, 0.4, 12)
    values, bw = dc.lac_objective("NREL5MW", mann, np.array([[20.0]]), **dict(KW, frequency=f))
    assert values[0] == pytest.approx(-bw[0])
    samples = lc.lidar_samples(lc.cone_points(100.0, 20.0, 4, azimuth_offset=45.0),
                               probe=dc.PulsedProbe(30.0, 30.0, n_nodes=7))
    rotor = lc.rotor_disc(63.0, spacing=21.0)
    sp = lc.lac_spectra(samples, rotor, mann, np.array([bw[0], bw[0] * 1.0001]))
    assert float(sp.coherence[0]) == pytest.approx(0.5, abs=1e-8)
    grid = np.asarray(lc.lac_spectra(samples, rotor, mann, f).coherence)
    i = int(np.argmax(grid < 0.5))
    assert i > 0 and f[i - 1] < bw[0] < f[i]
