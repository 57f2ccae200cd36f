"""`lidarjax series`: a simulated lidar in frozen turbulence, written as `.sta` and statistics."""

import numpy as np

import lidarjax


def test_series_command_writes_sta_and_statistics(tmp_path, capsys):
    from lidarjax.cli import main
    from lidarjax.io import Settings, read_table_csv, write_settings

    settings = tmp_path / "settings.dat"
    write_settings(settings, Settings(zone=2, verbose=1, height=100.0, nh=2, gamma=0.0, beta=0.0,
                                      psi=0.0, epsilon=0.0, betas=np.array([0.0]),
                                      locations=np.array([[0.0, 0.0, 0.0]])))
    out = tmp_path / "out"
    args = ["series", str(settings), "--field", "uniform", "--speed", "10", "--direction", "270",
            "--generate-box", "64,16,16", "--box-spacing", "8,8,8", "--hours", "0.34",
            "--probe", "point", "--no-plots", "--out", str(out)]
    assert main(args) == 0
    rec = lidarjax.io.read_sta(out / "series.sta")
    assert rec.speed.shape == (2, 2)
    np.testing.assert_allclose(rec.heights, [50.0, 100.0])
    assert np.all(np.abs(rec.speed - 10.0) < 1.5) and np.all(rec.speed_std > 0)
    table = read_table_csv(out / "series_statistics.csv")
    np.testing.assert_allclose(table.columns["cup_ti"], table.columns["cup_std"]
                               / table.columns["cup_speed"])
    assert "TI_lidar" in capsys.readouterr().out
    assert main(args + ["--hours", "0.01"]) == 2
    assert "no whole 10-minute record" in capsys.readouterr().err
