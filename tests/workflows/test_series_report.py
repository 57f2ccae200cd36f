"""The report of a simulated series (`lidarjax.write_series_report`): its `.sta` reads back
through the Windcube reader, its CSV holds every statistic."""

import numpy as np

import lidarjax as lj
from lidarjax.io import read_sta, read_table_csv


def test_report_files_read_back(tmp_path):
    field = lj.scenes.uniform(8.0, 270.0)
    heights = [40.0, 100.0]
    stats = lj.simulate_statistics(field, lj.windcube_v2(), lj.Mount([0.0, 0.0, 0.0]), heights,
                                   [0.0, 600.0], record_length=600.0)
    out = lj.write_series_report(tmp_path / "rep", stats, heights, [0.0, 600.0],
                                 start_datetime="2026-01-01T00:00", scan=lj.windcube_v2(),
                                 plots=False)
    assert out["plot"] is None
    rec = read_sta(out["sta"])
    np.testing.assert_allclose(rec.heights, heights)
    np.testing.assert_allclose(rec.speed, 8.0, atol=1e-3)
    assert rec.time[0] == np.datetime64("2026-01-01T00:10")
    cols = read_table_csv(out["csv"]).columns
    np.testing.assert_allclose(cols["record_end"], [600.0, 600.0, 1200.0, 1200.0])
    np.testing.assert_allclose(cols["speed"], 8.0, atol=1e-6)
    np.testing.assert_allclose(cols["cup_speed"], 8.0, atol=1e-6)
