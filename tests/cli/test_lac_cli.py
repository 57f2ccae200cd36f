"""`lidarjax lac`: the summary it prints and writes agrees with `lidarjax.control` called
directly, and the pictures and table are written."""

import json

import numpy as np

import lidarjax as lj
from lidarjax import control as lc
from lidarjax.cli import main


def test_lac_writes_summary_spectra_and_pictures(tmp_path, capsys):
    out = tmp_path / "lac"
    assert main(["lac", "--turbine", "NREL5MW", "--speed", "12", "--beams", "4", "--distance", "100",
                 "--half-cone", "20", "--nf", "40", "--fmax", "0.4", "--grid", "21", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    summary = json.loads((out / "lac_summary.json").read_text())
    assert f"{summary['cutoff_rad_s']:.5g}" in printed
    table = np.loadtxt(out / "lac_spectra.csv", delimiter=",", skiprows=1)
    assert table.shape == (40, 7)
    f_b = float(lc.coherence_bandwidth(lc.LacSpectra(table[:, 0], table[:, 1], table[:, 2],
                                                     table[:, 3] + 1j * table[:, 4], np.asarray(12.0)))[0])
    assert f_b == summary["bandwidth_hz"]
    expected = 100 / 12 - 0.5 - summary["filter_delay_s"] - 2.0
    assert summary["buffer_time_s"] == np.float64(expected) or abs(summary["buffer_time_s"] - expected) < 1e-12
    assert (out / "lac_coherence.png").stat().st_size > 0 and (out / "lac_disc.png").stat().st_size > 0


def test_lac_refuses_bad_input(capsys):
    assert main(["lac", "--nf", "1"]) == 2
    assert "--nf" in capsys.readouterr().err


def test_lac_mann_inflow_matches_the_library(tmp_path):
    """--inflow mann: IEC Annex C defaults (L = 0.7 Lambda_1, Gamma = 3.9, sigma_u = TI U),
    the same spectra as `lac_spectra` with that `MannInflow`, and the options in the summary."""
    out = tmp_path / "mann"
    assert main(["lac", "--turbine", "NREL5MW", "--speed", "12", "--ti", "0.15", "--inflow", "mann",
                 "--mann-nodes", "12", "--beams", "4", "--distance", "100", "--half-cone", "20", "--nf", "6",
                 "--fmax", "0.3", "--grid", "31.5", "--out", str(out)]) == 0
    summary = json.loads((out / "lac_summary.json").read_text())
    assert summary["inflow"] == "mann" and summary["gamma"] == 3.9 and summary["mann_nodes"] == 12
    assert abs(summary["mann_length_scale_m"] - 29.4) < 1e-12 and summary["turbulence_intensity"] == 0.15
    inflow = lc.MannInflow(12.0, length_scale=29.4, gamma=3.9, sigma_u=1.8, n_nodes=12)
    assert abs(summary["alphaepsilon_m43_s2"] / float(inflow.alphaepsilon) - 1) < 1e-12
    samples = lc.lidar_samples(lc.cone_points(100.0, 20.0, 4, azimuth_offset=45.0),
                               probe=lj.PulsedProbe(30.0, 30.0, n_nodes=11))
    sp = lc.lac_spectra(samples, lc.rotor_disc(63.0, spacing=31.5), inflow, np.linspace(0.05, 0.3, 6))
    table = np.loadtxt(out / "lac_spectra.csv", delimiter=",", skiprows=1)
    np.testing.assert_allclose(table[:, 5], np.asarray(sp.coherence), rtol=1e-10)


def test_lac_refuses_bad_mann_options(capsys):
    assert main(["lac", "--gamma", "2"]) == 2
    assert "--gamma: only with --inflow mann" in capsys.readouterr().err
    assert main(["lac", "--inflow", "mann", "--gamma", "-1"]) == 2
    assert "--gamma must be >= 0" in capsys.readouterr().err
    assert main(["lac", "--inflow", "mann", "--mann-nodes", "3"]) == 2
    assert "--mann-nodes must be at least 4" in capsys.readouterr().err
