"""`lidarjax lac`: the summary it prints and writes agrees with `lidarjax.control` called
directly, and the pictures and table are written."""

import json

import numpy as np

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
