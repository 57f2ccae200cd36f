"""`lidarjax monitor-points` (formerly `probes`): write the lidar's sample points for the CFD
code, read its samples back through the forward model."""

import numpy as np

import lidarjax as lj
from lidarjax.cli import main
from lidarjax.io import Settings, read_monitor_points_csv, write_settings

from .._foamwrite import write_probes_output

SCENE = lj.scenes.hemisphere(radius=20.0, speed=10.0, direction=250.0)
SCAN = lj.windcube_v2()
U_REF = 10.0 * np.asarray(lj.heading(250.0))


def test_cli_writes_then_reads_back(tmp_path, capsys):
    locs_xyz = np.array([[4.0, 3.0, 20.1], [-3.0, 6.0, 20.1]])
    write_settings(tmp_path / "settings.dat", Settings(
        zone=2, verbose=1, height=80.0, nh=2, gamma=5.0, beta=0.0, psi=180.0, epsilon=21.0,
        betas=np.array([0.0, 30.0]), locations=locs_xyz))
    base = ["monitor-points", str(tmp_path / "settings.dat"), "--all", "--scan", "windcube_v2"]
    assert main(base + ["--heights", "10,40,80", "--out", str(tmp_path / "p")]) == 0
    locs = read_monitor_points_csv(tmp_path / "p" / "lidarProbes.csv")
    assert (tmp_path / "p" / "lidarProbes").is_file() and (tmp_path / "p" / "lidarProbes_zcfd.py").is_file()
    values = np.asarray(SCENE.sample(locs.points))
    write_probes_output(tmp_path / "pp" / "lidarProbes" / "500" / "U", locs, [(500, values)])
    argv = base + ["--heights", "10,40,80", "--sampled", str(tmp_path / "pp" / "lidarProbes"),
                   "--u-ref", ",".join(map(str, U_REF)), "--out", str(tmp_path / "r")]
    assert main(argv) == 0
    from lidarjax.io import read_table_csv

    cols = read_table_csv(tmp_path / "r" / "simulation_30.csv").columns
    assert (tmp_path / "r" / "windcube simulation 30 degrees.dat").is_file()
    mount = lj.Mount(locs_xyz[1], beta=30.0, gamma=5.0, psi=180.0, epsilon=21.0)
    ref = lj.simulate(SCENE, SCAN, mount, [10.0, 40.0, 80.0], u_ref=U_REF)  # the point probe
    np.testing.assert_allclose(cols["U_mag_lidar"], np.asarray(ref.lidar_speed), atol=1e-12)
    np.testing.assert_allclose(cols["cff_U"], np.asarray(ref.cff_U), atol=1e-12)
    np.testing.assert_allclose(cols["cfp_th"], np.asarray(ref.cfp_th), atol=1e-10)
    # heights other than those written: one clear line, exit 2
    capsys.readouterr()
    bad = [a if a != "10,40,80" else "10,50" for a in argv]
    assert main(bad) == 2
    assert "lidarjax monitor-points: error:" in capsys.readouterr().err


def test_cli_old_name_probes_still_works_with_one_deprecation_line(tmp_path, capsys):
    write_settings(tmp_path / "settings.dat", Settings(
        zone=2, verbose=1, height=80.0, nh=2, gamma=5.0, beta=0.0, psi=180.0, epsilon=21.0,
        betas=np.array([0.0]), locations=np.array([[4.0, 3.0, 20.1]])))
    argv = [str(tmp_path / "settings.dat"), "--scan", "windcube_v2", "--heights", "10,40"]
    assert main(["probes", *argv, "--out", str(tmp_path / "old")]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["lidarjax probes: deprecated name; use 'lidarjax monitor-points' (same options)"]
    assert main(["monitor-points", *argv, "--out", str(tmp_path / "new")]) == 0
    assert capsys.readouterr().err == ""
    old = (tmp_path / "old" / "lidarProbes.csv").read_text()
    assert old == (tmp_path / "new" / "lidarProbes.csv").read_text()


def test_cli_tilted_installation_writes_and_reads_what_simulate_samples(tmp_path):
    # --pitch/--roll move every beam's points as `simulate` moves them: the written points
    # are the tilted mount's, and the samples read back give simulate's tilted results
    loc = np.array([[4.0, 3.0, 20.1]])
    write_settings(tmp_path / "settings.dat", Settings(
        zone=2, verbose=1, height=40.0, nh=2, gamma=5.0, beta=0.0, psi=180.0, epsilon=21.0,
        betas=np.array([0.0]), locations=loc))
    base = ["monitor-points", str(tmp_path / "settings.dat"), "--heights", "10,40",
            "--pitch", "2.5", "--roll", "-1.5"]
    assert main(base + ["--out", str(tmp_path / "p")]) == 0
    locs = read_monitor_points_csv(tmp_path / "p" / "lidarProbes.csv")
    mount = lj.Mount(loc[0], beta=0.0, gamma=5.0, psi=180.0, epsilon=21.0, pitch=2.5,
                     roll=-1.5)
    ref = lj.simulate(SCENE, SCAN, mount, [10.0, 40.0], u_ref=U_REF)
    focus = np.asarray(ref.points).reshape(-1, 3)  # (h * b, 3) the tilted focus points
    dist = np.min(np.linalg.norm(np.asarray(locs.points)[None] - focus[:, None], axis=-1), 1)
    assert dist.max() < 1e-9
    level = lj.simulate(SCENE, SCAN, lj.Mount(loc[0], beta=0.0, gamma=5.0, psi=180.0,
                                              epsilon=21.0), [10.0, 40.0]).points
    assert np.abs(np.asarray(level) - np.asarray(ref.points)).max() > 0.3  # the tilt matters
    values = np.asarray(SCENE.sample(locs.points))
    write_probes_output(tmp_path / "pp" / "lidarProbes" / "500" / "U", locs, [(500, values)])
    assert main(base + ["--sampled", str(tmp_path / "pp" / "lidarProbes"), "--u-ref",
                        ",".join(map(str, U_REF)), "--out", str(tmp_path / "r")]) == 0
    from lidarjax.io import read_table_csv

    cols = read_table_csv(tmp_path / "r" / "simulation_0.csv").columns
    np.testing.assert_allclose(cols["U_mag_lidar"], np.asarray(ref.lidar_speed), atol=1e-12)
    np.testing.assert_allclose(cols["cff_U"], np.asarray(ref.cff_U), atol=1e-12)
