"""The `lidarjax farm` command, and the nacelle scans and mounts it builds on. Layout and
turbine-type reading is tested in tests/io/test_layout.py, the IEC disturbed sectors in
tests/core/test_disturbed_sectors.py and the study itself in
tests/workflows/test_farm_study.py."""

import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj
from lidarjax.cli import main

from ..io.test_layout import TYPE


@pytest.fixture
def files(tmp_path):
    (tmp_path / "a.txt").write_text("# seed 004 xy file\nT001 251865.0 646486.0\n"
                                    "T002 252240.0 646200.0\n\nT003 252500.0 646900.0\n")
    (tmp_path / "b.txt").write_text("T101 253308.0 647985.0\n")
    (tmp_path / "t.csv").write_text(TYPE)
    return tmp_path


# ------------------------------------------------------------------------ nacelle scans
def test_nacelle_scans_uniform_flow():
    """A forward-looking nacelle lidar (pitch -90) in a uniform wind misaligned by 8 degrees
    reports the speed and the yaw misalignment exactly; 4-beam shear recovers the exponent."""
    u = lj.scenes.power_law(10.0, z_ref=90.0, alpha=0.0, direction=278.0)
    mount = lj.Mount([0.0, 0.0, 90.0], psi=270.0, pitch=-90.0)  # axis towards the west
    for scan in (lj.scan.nacelle_2beam(), lj.scan.nacelle_4beam(20.0)):
        sim = lj.simulate(u, scan, mount, jnp.array([150.0]))
        assert float(sim.lidar_speed[0]) == pytest.approx(10.0, rel=1e-12)
        assert float(lj.wrap180(sim.lidar_direction[0])) == pytest.approx(8.0, abs=1e-9)
    sheared = lj.scenes.power_law(10.0, z_ref=90.0, alpha=0.2, direction=270.0)
    scan = lj.scan.nacelle_4beam(15.0)
    sim = lj.simulate(sheared, scan, mount, jnp.array([100.0]))
    alpha, lo, hi = lj.scan.nacelle_shear(scan, sim.los[0], 100.0, 90.0)
    assert float(alpha) == pytest.approx(0.2, rel=1e-9) and float(hi) > float(lo)
    with pytest.raises(ValueError, match="needs body azimuths"):
        lj.Scan([0.0, 180.0], 15.0, method="nacelle_2beam")


def test_nacelle_mount_on_farm():
    import equinox as eqx
    farm = lj.scenes.wind_farm([0.0, 630.0], [0.0, 0.0], 90.0, 126.0, yaw=[0.0, 10.0],
                               direction=90.0, model="gaussian")
    scan, dist = lj.scan.nacelle_2beam(), jnp.array([250.0])
    # wind from the east: turbine 1 is upstream and sees the free stream; its rotor faces
    # 90 - 10 degrees, so the lidar reports a yaw misalignment of +10 degrees
    sim = lj.simulate(farm, scan, lj.scenes.nacelle_mount(farm, 1), dist)
    assert float(sim.lidar_speed[0]) == pytest.approx(10.0, rel=1e-9)
    assert float(lj.wrap180(sim.lidar_direction[0])) == pytest.approx(10.0, abs=1e-9)
    # wind from the west, no yaw: turbine 1 looks along turbine 0's wake axis
    west = eqx.tree_at(lambda f: (f.direction, f.yaw), farm,
                       (jnp.asarray(270.0), jnp.zeros(2)))
    sw = lj.simulate(west, scan, lj.scenes.nacelle_mount(west, 1), dist)
    assert float(sw.lidar_speed[0]) < 9.0
    # turbine 0 (not yawed) looking backward along its own wake's axis: both beams in the
    # wake, symmetric, so the reading is the wake speed (a yawed rotor's beams would see
    # the wake edge on one side only, and the 2-beam reconstruction breaks down there)
    back = lj.simulate(west, scan, lj.scenes.nacelle_mount(west, 0, backward=True), dist)
    assert float(back.lidar_speed[0]) < 9.0
    assert float(lj.wrap180(back.lidar_direction[0] - 180.0)) == pytest.approx(0.0, abs=1e-9)


# ---------------------------------------------------------------------------------- CLI
def _run(args, capsys):
    code = main(args)
    return code, capsys.readouterr()


@pytest.mark.parametrize("layout,extra,message", [
    ("A 0 0\nA 700 0\n", [], "duplicate turbine name 'A'"),
    ("A 0 0\nB 100 0\n", [], "closer than one rotor diameter"),
    ("A 0 0\nB 700 0\n", ["--lidar", "20", "5", "0"], "inside turbine A's rotor footprint"),
])
def test_cli_bad_layouts(files, capsys, layout, extra, message):
    (files / "bad.txt").write_text(layout)
    lidar = extra or ["--lidar", "300", "300", "0"]
    code, out = _run(["farm", str(files / "bad.txt"), "--turbine", str(files / "t.csv"), *lidar,
                      "--out", str(files / "o")], capsys)
    assert code == 2 and message in out.err and out.err.count("\n") == 1


def test_cli_missing_ct_column(files, capsys):
    (files / "t2.csv").write_text(TYPE.replace("speed,ct", "speed,thrust_c"))
    code, out = _run(["farm", str(files / "a.txt"), "--turbine", str(files / "t2.csv"),
                      "--lidar", "252000", "646300", "0", "--out", str(files / "o")], capsys)
    assert code == 2 and "missing thrust-curve column 'ct'" in out.err


def test_cli_farm_run(files, capsys):
    out_dir = files / "out"
    code, out = _run(["farm", str(files / "a.txt"), "--turbine", str(files / "t.csv"),
                      "--lidar", "252100", "646400", "0", "--speed", "9",
                      "--directions", "0:360:90", "--probe", "point", "--yaw", "T001=10",
                      "--out", str(out_dir)], capsys)
    assert code == 0, out.err
    for name in ("roses.png", "map.png", "directions.csv", "yaw_gradient.csv", "sectors.csv",
                 "probes.csv", "lidarProbes", "lidarProbes_zcfd.py", "table.npz"):
        assert (out_dir / name).is_file(), name
    import csv
    with open(out_dir / "directions.csv") as fh:
        rows = list(csv.DictReader(line for line in fh if not line.startswith("#")))
    assert len(rows) == 4 and {r["disturbed"] for r in rows} <= {"0", "1"}
    ratio = np.array([float(r["speed_ratio_90m"]) for r in rows])
    assert np.all(np.isfinite(ratio)) and ratio.max() > 1.001  # waked from the west
    d = np.array([float(r["direction_deg"]) for r in rows])
    assert ratio[d == 90.0][0] == pytest.approx(1.0, abs=1e-4)  # free from the east
    locs = lj.io.read_monitor_points_csv(out_dir / "probes.csv")
    names = list(locs.names)
    assert "T001_ref1D" in names and "lidar_h90_beam4_q0" in names
    hub = np.asarray(locs.points)[names.index("T001_hub")]
    ref = np.asarray(locs.points)[names.index("T001_ref1D")]
    assert np.linalg.norm(hub - ref) == pytest.approx(126.0)  # 1 D upstream
    assert "T001_ref1D" in (out_dir / "lidarProbes").read_text()
    assert "'name': 'lidar_h90_beam4_q0'" in (out_dir / "lidarProbes_zcfd.py").read_text()
    with open(out_dir / "yaw_gradient.csv") as fh:
        grad = list(csv.DictReader(line for line in fh if not line.startswith("#")))
    assert len(grad) == 4 and np.all(np.isfinite([float(g["T001"]) for g in grad]))


def test_cli_farm_nacelle_lidar_reads_the_free_stream_ahead_of_the_front_turbine(files, capsys):
    """A forward-looking 2-beam nacelle lidar on the westernmost turbine, wind from the west:
    its beams look into undisturbed air (the wake models have no induction zone), so it reads
    the free stream and no yaw misalignment; with the wind from T002 (bearing 127 degrees,
    471 m away) it looks into T002's wake."""
    out_dir = files / "nac"
    code, out = _run(["farm", str(files / "a.txt"), "--turbine", str(files / "t.csv"),
                      "--nacelle", "T001", "--speed", "9", "--directions", "127:271:143",
                      "--probe", "point", "--out", str(out_dir)], capsys)
    assert code == 0, out.err
    for name in ("directions.csv", "yaw_gradient.csv", "probes.csv", "lidarProbes", "map.png"):
        assert (out_dir / name).is_file(), name
    import csv
    with open(out_dir / "directions.csv") as fh:
        rows = {float(r["direction_deg"]): r for r in
                csv.DictReader(line for line in fh if not line.startswith("#"))}
    h = "315m"  # 2.5 D ahead along the axis
    west = rows[270.0]
    assert float(west[f"lidar_speed_{h}"]) == pytest.approx(9.0, abs=1e-9)
    assert float(west[f"speed_ratio_{h}"]) == pytest.approx(1.0, abs=1e-9)
    assert float(west[f"yaw_misalignment_{h}"]) == pytest.approx(0.0, abs=1e-6)
    assert float(rows[127.0][f"lidar_speed_{h}"]) < 9.0 - 0.1  # in T002's wake
