"""`lidarjax demo` end to end (the whole pipeline, cold: its own file, so that `--dist
loadfile` can start it early on one worker while the other runs the rest)."""

import json

from lidarjax.cli import main


def test_demo_runs_end_to_end(tmp_path, capsys):
    import matplotlib  # noqa: F401  (the test extra brings it)
    assert main(["demo", "--out", str(tmp_path / "demo")]) == 0
    text = capsys.readouterr().out
    assert "C_U = U / U_free" in text and "corrected" in text
    for name in ("seed/settings.dat", "seed/windcube simulation 330 degrees.dat", "table.npz",
                 "synthetic.sta", "synthetic_corrected.csv", "plots/profiles.png",
                 "plots/los_fit.png", "plots/roses.png", "plots/sensitivity.png", "summary.json"):
        assert (tmp_path / "demo" / name).is_file(), name
    summary = json.loads((tmp_path / "demo" / "summary.json").read_text())["records"]
    assert summary["converged_fraction"] > 0.99
    # the correction removes the platform's distortion: what is left is the LOS noise
    assert summary["speed_rms_corrected"] < 0.5 * summary["speed_rms_uncorrected"]
    assert abs(summary["speed_bias_corrected"]) < 0.01
