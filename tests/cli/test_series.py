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


def test_series_on_a_mesh_matches_simulate_there(tmp_path, capsys, monkeypatch):
    """A profiler's series over an OpenFOAM mean flow (the real windAroundBuildings cut, a
    Windcube V2 on the roof, a 31-node pulsed probe) samples the mesh's own cellPoint at the points it
    flies through, as `lidarjax simulate` does: with a calm box (TI 1e-9) the 10-minute mean
    speed and the point speed equal simulate's ``U_mag_lidar`` and ``U_mag_point`` to 1e-6
    m/s; the graded grid alone (a moving lidar samples it) is off by more than 1e-4."""

    import foamlib  # noqa: F401  (the test extra brings it)

    from lidarjax.cli import main
    from lidarjax.io import read_table_csv

    from ._roof import CASE as case
    from ._roof import record_regions, roof_settings

    regions = record_regions(monkeypatch)
    settings = roof_settings(tmp_path / "settings.dat", nh=2)
    assert main(["simulate", str(settings), "--field", str(case), "--scan", "windcube_v2",
                 "--probe", "pulsed", "--probe-nodes", "31", "--out", str(tmp_path / "sim")]) == 0
    sim = read_table_csv(tmp_path / "sim" / "simulation_0.csv").columns
    args = ["series", str(settings), "--field", str(case), "--speed", "5", "--direction", "270",
            "--generate-box", "8,4,4", "--box-spacing", "40,40,40", "--ti", "1e-9",
            "--hours", "0.17", "--probe", "pulsed", "--probe-nodes", "31", "--no-plots"]
    assert main(args + ["--out", str(tmp_path / "ser")]) == 0
    assert "exact cellPoint" in capsys.readouterr().out
    ser = read_table_csv(tmp_path / "ser" / "series_statistics.csv").columns
    assert np.isfinite(sim["U_mag_lidar"]).all()
    np.testing.assert_allclose(ser["speed"], sim["U_mag_lidar"], rtol=0, atol=1e-6)
    np.testing.assert_allclose(ser["cup_speed"], sim["U_mag_point"], rtol=0, atol=1e-6)
    # a (still) moving lidar: the graded grid, which misses the roof's shear layer
    motion = tmp_path / "still.csv"
    motion.write_text("time,surge,sway,heave,roll,pitch,yaw\n0,0,0,0,0,0,0\n1000,0,0,0,0,0,0\n")
    assert main(args + ["--motion", str(motion), "--out", str(tmp_path / "moving")]) == 0
    moving = read_table_csv(tmp_path / "moving" / "series_statistics.csv").columns
    # the fixed lidar read only where its beams look (10 m up, cone 28 deg); the moving one all
    (lo, hi), everything = regions
    assert everything is None and hi[2] >= 39.0 + 10.0 and np.all(hi - lo < 30.0)
    assert np.nanmax(np.abs(moving["speed"] - sim["U_mag_lidar"])) > 1e-4


def test_series_through_an_openfoam_sequence_matches_its_probes(tmp_path, capsys):
    """`lidarjax series --sequence CASE`: the committed pimpleFoam run (11 snapshots, 10-30 s),
    a Windcube V2 standing on the ground at (150, 60, 0), heights 10-60 m: every LOS written
    to series_los.csv at its own time agrees with OpenFOAM's own probes (cellPoint) at the
    same point, projected on the beam from the lidar (independent geometry) and
    interpolated between the snapshot times, within 1e-5 m/s at every height, the
    ground-adjacent 10 m included; the reconstructions are in series_wind.csv."""
    from pathlib import Path

    from lidarjax.cli import main
    from lidarjax.io import Settings, read_table_csv, write_settings
    from lidarjax.io.monitor_points import read_openfoam_probes
    from tests._transient import LIDAR as lidar
    from tests._transient import probe_los

    case = Path(__file__).resolve().parents[1] / "data" / "openfoam_transient" / "case"
    settings = tmp_path / "settings.dat"
    write_settings(settings, Settings(zone=2, verbose=1, height=60.0, nh=6, gamma=0.0, beta=0.0,
                                      psi=0.0, epsilon=0.0, betas=np.array([0.0]),
                                      locations=lidar[None]))
    out = tmp_path / "out"
    assert main(["series", str(settings), "--sequence", str(case), "--probe", "point",
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "11 snapshots" in text and "exact cellPoint" in text
    los = read_table_csv(out / "series_los.csv").columns
    assert np.isfinite(los["los"]).all() and not los["flags"].any()
    probes = read_openfoam_probes(case / "postProcessing" / "lidarProbes")
    scan = lidarjax.windcube_v2()
    heights = np.arange(10.0, 60.1, 10.0)
    mp = lidarjax.monitor_points(scan, lidarjax.Mount(lidar), heights)
    err = np.zeros(heights.size)
    for i, h in enumerate(heights):
        for b in range(5):
            sel = (los["height"] == h) & (los["beam"] == b)
            assert sel.sum() == 4  # whole 5-s cycles in 10..30 s
            ref = probe_los(probes, mp, h, b, los["time"][sel])
            err[i] = np.max(np.abs(los["los"][sel] - ref))
    assert err.max() < 1e-5, err
    wind = read_table_csv(out / "series_wind.csv").columns
    assert np.isfinite(wind["speed"]).any() and np.all(wind["speed"][np.isfinite(wind["speed"])] > 0)
    # without a box the two kinds of flow are not mixed
    assert main(["series", str(settings), "--sequence", str(case), "--generate-box", "8,4,4",
                 "--out", str(out)]) == 2
    assert "drop --generate-box" in capsys.readouterr().err
