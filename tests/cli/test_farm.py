"""Farm inputs and geometry: seed 004 layouts and turbine types, IEC disturbed sectors,
nacelle scans (2-beam, 4-beam, shear), and the `lidarjax farm` command."""

import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj
from lidarjax.cli import main
from lidarjax.disturbed_sectors import disturbed_sectors, excluded_width, in_sectors, merge_sectors
from lidarjax.io.layout import read_farm, read_layout, read_turbine_type

TYPE = """# NREL 5 MW (abridged)
# rotor_diameter = 126
# hub_height = 90
speed,ct
3.0,0.0
4.0,0.82
11.4,0.72
25.0,0.06
"""


@pytest.fixture
def files(tmp_path):
    (tmp_path / "a.txt").write_text("# seed 004 xy file\nT001 251865.0 646486.0\n"
                                    "T002 252240.0 646200.0\n\nT003 252500.0 646900.0\n")
    (tmp_path / "b.txt").write_text("T101 253308.0 647985.0\n")
    (tmp_path / "t.csv").write_text(TYPE)
    return tmp_path


def test_layout_and_type(files):
    lay = read_layout(files / "a.txt")
    assert lay.names == ("T001", "T002", "T003")
    assert lay.easting[0] == 251865.0 and lay.northing[2] == 646900.0
    t = read_turbine_type(files / "t.csv")
    assert (t.diameter, t.hub_height) == (126.0, 90.0)
    np.testing.assert_array_equal(t.ct, [0.0, 0.82, 0.72, 0.06])
    farm = read_farm([files / "a.txt", files / "b.txt"], [files / "t.csv"])
    assert farm.names[-1] == "T101" and farm.diameter.shape == (4,)
    wf = farm.to_farm(speed=8.0)
    # UTM coordinates relative to the first turbine, exact
    assert float(wf.x[1]) == 375.0 and float(wf.y[1]) == -286.0
    assert float(wf.origin[0] + wf.origin_lo[0]) == 251865.0


@pytest.mark.parametrize("content,message", [
    ("T1 1 2\nT1 3 4\n", "line 2: duplicate turbine name 'T1'"),
    ("T1 1\n", "line 1: expected '<name> <easting> <northing>'"),
    ("T1 1 x\n", "line 1: turbine 'T1': easting and northing must be numbers"),
    ("# nothing\n", "no turbines"),
])
def test_layout_errors(tmp_path, content, message):
    (tmp_path / "l.txt").write_text(content)
    with pytest.raises(ValueError, match=message):
        read_layout(tmp_path / "l.txt")


@pytest.mark.parametrize("content,message", [
    (TYPE.replace("speed,ct", "speed,power"), "missing thrust-curve column 'ct'"),
    (TYPE.replace("speed,ct", "u_hub,ct"), "missing thrust-curve column 'speed'"),
    (TYPE.replace("# hub_height = 90\n", ""), "missing '# hubheight"),
    (TYPE.replace("4.0,0.82", "2.0,0.82"), "strictly increasing"),
    (TYPE.replace("4.0,0.82", "4.0,1.3"), r"Ct must lie in \[0, 1\)"),
])
def test_type_errors(tmp_path, content, message):
    (tmp_path / "t.csv").write_text(content)
    with pytest.raises(ValueError, match=message):
        read_turbine_type(tmp_path / "t.csv")


def test_farm_errors(files):
    (files / "c.txt").write_text("T001 0 0\n")
    with pytest.raises(ValueError, match="duplicate turbine name 'T001'"):
        read_farm([files / "a.txt", files / "c.txt"], files / "t.csv")
    (files / "d.txt").write_text("A 0 0\nB 100 0\n")
    with pytest.raises(ValueError, match="A and B are 100.0 m apart, closer than one rotor"):
        read_farm(files / "d.txt", files / "t.csv")


# ----------------------------------------------------------------------------- sectors
def test_excluded_width_iec():
    # IEC 61400-12-1 Annex A: 2 D -> 80.8 deg, 5 D -> 52.9 deg, 20 D -> 30.0 deg
    assert excluded_width(2 * 80.0, 80.0) == pytest.approx(80.80, abs=0.01)
    assert excluded_width(5 * 80.0, 80.0) == pytest.approx(52.93, abs=0.01)
    assert excluded_width(20 * 80.0, 80.0) == pytest.approx(29.99, abs=0.01)
    assert excluded_width(0.5 * 80.0, 80.0) == excluded_width(2 * 80.0, 80.0)  # clamped below 2 D
    s = disturbed_sectors([0, 0], [0.0, 100.0, 0.0, 3000.0], [500.0, 0.0, -1e-4, 0.0], 100.0,
                          ["N", "E", "self", "far"])
    names = [x.name for x in s]
    assert names == ["N", "E", "far"]  # the lidar's own turbine is skipped
    assert s[0].bearing == pytest.approx(0.0) and s[1].bearing == pytest.approx(90.0)
    assert s[1].too_close and not s[0].too_close and not s[2].considered
    merged = merge_sectors(s)
    assert len(merged) == 2  # far turbine ignored; N and E do not overlap (45 + 40 < 90)
    assert merged[-1][0] == pytest.approx(360 - s[0].width / 2)  # N wraps through 0
    assert in_sectors([0.0, 90.0, 180.0], merged).tolist() == [True, True, False]


def test_merge_wraps_and_overlaps():
    assert merge_sectors([(350.0, 10.0), (5.0, 20.0), (100.0, 120.0), (110.0, 130.0)]) == [
        (100.0, 130.0), (350.0, 380.0)]
    assert merge_sectors([(0.0, 200.0), (190.0, 370.0)]) == [(0.0, 360.0)]
    assert in_sectors([355.0, 15.0, 25.0], [(350.0, 380.0)]).tolist() == [True, True, False]


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
