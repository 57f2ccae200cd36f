"""`lidarjax.farm_study` from Python: a ground lidar west of two turbines in a row, four
inflow directions; the physics of the result (free stream outside the wakes, the IEC
disturbed sectors, yaw gradients) and `write_farm_study` writing what `lidarjax farm` writes."""

import json

import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj
from lidarjax.cli import main
from lidarjax.disturbed_sectors import excluded_width
from lidarjax.io.layout import read_farm
from lidarjax.workflows.farm_study import (
    FarmStudy,
    check_lidar_position,
    farm_monitor_points,
    farm_study,
    write_farm_study,
)

from ..io.test_layout import TYPE

LIDAR = (300000.0, 5000000.0, 0.0)
SPEED = 9.0
DIRECTIONS = np.arange(0.0, 360.0, 90.0)  # as the command line's 0:360:90
TEXT_FILES = ("directions.csv", "yaw_gradient.csv", "sectors.csv", "probes.csv", "lidarProbes",
              "lidarProbes_zcfd.py")


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    root = tmp_path_factory.mktemp("farm_study")
    # A 600 m and B 1300 m east of the lidar (4.8 D and 10.3 D), hub 90 m, D = 126 m
    (root / "row.txt").write_text(f"A {LIDAR[0] + 600.0} {LIDAR[1]}\n"
                                  f"B {LIDAR[0] + 1300.0} {LIDAR[1]}\n")
    (root / "t.csv").write_text(TYPE)
    layout, turbine = str(root / "row.txt"), str(root / "t.csv")
    study = farm_study(layout, turbine, lidar=LIDAR, speed=SPEED, directions=DIRECTIONS,
                       probe="point", yaw={"A": 10.0})
    return root, layout, turbine, study


def _row(study, direction):
    return int(np.flatnonzero(study.directions == direction)[0])


def test_free_stream_outside_the_wakes_and_waked_from_the_east(case):
    *_, study = case
    assert isinstance(study, FarmStudy) and study.names == ("A", "B")
    assert study.lidar_speed.shape == study.speed_ratio.shape == (4, 1)
    np.testing.assert_array_equal(study.heights, [90.0])  # default: the mean hub height
    # wind from the west: the lidar is upstream of both rotors (wakes only grow downstream)
    west = _row(study, 270.0)
    assert study.lidar_speed[west, 0] == pytest.approx(SPEED, rel=1e-9)
    assert study.speed_ratio[west, 0] == pytest.approx(1.0, abs=1e-9)
    assert study.direction_addend[west, 0] == pytest.approx(0.0, abs=1e-7)
    # from north and south the wakes pass 600 m and more beside the lidar
    for d in (0.0, 180.0):
        assert study.speed_ratio[_row(study, d), 0] == pytest.approx(1.0, abs=1e-6)
    # from the east the lidar stands in A's (and B's) wake: it reads less than the free stream
    east = _row(study, 90.0)
    assert study.lidar_speed[east, 0] < SPEED - 0.1 and study.speed_ratio[east, 0] > 1.01
    assert study.map_direction == 90.0 and study.map_index == east  # the largest correction
    assert study.largest_correction == pytest.approx(abs(study.speed_ratio[east, 0] - 1))
    assert study.yaw_misalignment is None and study.kind == "ground lidar"
    assert study.table is not None and study.table.directions.shape == (4,)


def test_disturbed_sectors_follow_the_iec_rule(case):
    *_, study = case
    by_name = {s.name: s for s in study.sectors}
    for name, distance in (("A", 600.0), ("B", 1300.0)):
        s = by_name[name]
        assert s.bearing == pytest.approx(90.0) and s.distance == pytest.approx(distance)
        assert s.width == pytest.approx(float(excluded_width(distance, 126.0)))
        assert s.considered and not s.too_close
    # B's sector lies inside A's (wider, nearer): one merged sector centred on the bearing
    wa = by_name["A"].width
    assert len(study.merged_sectors) == 1
    assert study.merged_sectors[0] == pytest.approx((90.0 - wa / 2, 90.0 + wa / 2))
    assert study.disturbed.tolist() == [False, True, False, False]


def test_yaw_gradient_finite_and_zero_where_the_wakes_miss_the_beams(case):
    *_, study = case
    g = study.yaw_gradient
    assert g.shape == (4, 2) and np.all(np.isfinite(g))
    np.testing.assert_array_equal(g[_row(study, 270.0)], 0.0)  # upstream of every rotor
    np.testing.assert_allclose(g[[_row(study, 0.0), _row(study, 180.0)]], 0.0, atol=1e-8)
    # from the east A's yawed wake (deflected by the yaw) moves the reading
    assert abs(g[_row(study, 90.0), 0]) > 1e-4
    # the gradient is d(speed)/d(yaw) in m/s per degree: a centred finite difference agrees
    lay = read_farm(case[1], case[2])
    step = 0.5

    def speed(yaw_a):
        farm = lay.to_farm(speed=SPEED, direction=90.0, model="gaussian", yaw=[yaw_a, 0.0])
        sim = lj.simulate(farm, lj.windcube_v2(), lj.Mount(np.asarray(LIDAR)), jnp.array([90.0]),
                          point_reference=False)
        return float(sim.lidar_speed[0])

    fd = (speed(10.0 + step) - speed(10.0 - step)) / (2 * step)
    assert g[_row(study, 90.0), 0] == pytest.approx(fd, rel=1e-3)


def test_monitor_points_of_the_lidar_and_the_turbines(case):
    *_, study = case
    locs = study.monitor_points
    names = list(locs.names)
    assert names[-4:] == ["A_hub", "B_hub", "A_ref1D", "B_ref1D"]
    assert "lidar_h90_beam4_q0" in names  # the vertical beam at 90 m
    pts = np.asarray(locs.points)
    hub, ref = pts[names.index("A_hub")], pts[names.index("A_ref1D")]
    np.testing.assert_allclose(hub, [LIDAR[0] + 600.0, LIDAR[1], 90.0])
    # map direction 90 (wind from the east): the reference point is 1 D east of the hub
    np.testing.assert_allclose(ref - hub, [126.0, 0.0, 0.0], atol=1e-9)
    again = farm_monitor_points(study.map_farm, study.scan, lj.Mount(np.asarray(LIDAR)),
                                study.heights, None, names=study.names)
    assert again.names == locs.names
    np.testing.assert_array_equal(again.points, locs.points)


def test_writer_writes_what_the_command_writes(case, capsys):
    root, layout, turbine, study = case
    out = root / "py"
    written = write_farm_study(out, study)
    assert sorted(written) == sorted(TEXT_FILES + ("roses.png", "map.png", "table.npz"))
    assert all(p.is_file() for p in written.values())
    rc = main(["farm", layout, "--turbine", turbine, "--lidar", *map(str, LIDAR), "--speed",
               str(SPEED), "--directions", "0:360:90", "--probe", "point", "--yaw", "A=10",
               "--out", str(root / "cli")])
    assert rc == 0, capsys.readouterr().err
    printed = capsys.readouterr().out
    assert printed.startswith("farm: 2 turbines, 4 directions (1 in disturbed sectors)")
    assert sorted(p.name for p in (root / "cli").iterdir()) == sorted(written)
    for name in TEXT_FILES:
        assert (out / name).read_bytes() == (root / "cli" / name).read_bytes(), name
    with np.load(out / "table.npz") as a, np.load(root / "cli" / "table.npz") as b:
        assert sorted(a.files) == sorted(b.files)
        for k in a.files:
            np.testing.assert_array_equal(a[k], b[k])
        assert json.loads(str(a["metadata"]))["layouts"] == [layout]
    # without figures
    bare = write_farm_study(root / "bare", study, plots=False)
    assert "roses.png" not in bare and not (root / "bare" / "map.png").exists()


def test_windfarm_input_with_a_nacelle_lidar():
    """A forward 2-beam nacelle lidar on the western turbine of a `WindFarm`: from the west
    it reads the free stream and no yaw misalignment, from the east it looks into the
    other turbine's wake."""
    farm = lj.scenes.wind_farm([0.0, 630.0], [0.0, 0.0], 90.0, 126.0, speed=10.0,
                               model="gaussian")
    study = farm_study(farm, nacelle="T0", directions=[270.0, 90.0], probe=None)
    assert study.names == ("T0", "T1") and study.scan_name == "nacelle_2beam"
    np.testing.assert_array_equal(study.heights, [2.5 * 126.0])
    assert study.lidar_speed[0, 0] == pytest.approx(10.0, abs=1e-9)
    assert study.yaw_misalignment[0, 0] == pytest.approx(0.0, abs=1e-6)
    assert study.lidar_speed[1, 0] < 9.5
    assert study.table is None  # fewer than three directions
    assert study.kind == "nacelle lidar on T0"
    with pytest.raises(ValueError, match="speed configure a farm built from a layout"):
        farm_study(farm, nacelle="T0", speed=8.0)


@pytest.mark.parametrize("kwargs, message", [
    ({"lidar": (LIDAR[0] + 600.0, LIDAR[1], 90.0)}, "inside turbine A's rotor"),
    ({"lidar": (LIDAR[0] + 620.0, LIDAR[1], 0.0)}, "inside turbine A's rotor footprint"),
    ({"lidar": LIDAR, "nacelle": "A"}, "either lidar="),
    ({"nacelle": "Z"}, "no turbine named 'Z'"),
    ({"lidar": LIDAR, "yaw": {"Z": 3.0}}, "yaw: no turbine named 'Z'"),
    ({"lidar": LIDAR, "yaw": {"A": 95.0}}, "below 90 degrees"),
    ({"lidar": LIDAR, "scan": "nacelle_2beam"}, "use nacelle=NAME"),
    ({"lidar": LIDAR, "heights": [-5.0]}, "heights must be positive"),
    ({"lidar": LIDAR, "directions": [0.0, 360.0]}, "repeat modulo 360"),
    ({"lidar": LIDAR, "backward": True}, "backward=True needs a nacelle lidar"),
])
def test_errors_before_computing(case, kwargs, message):
    root, layout, turbine, _ = case
    with pytest.raises(ValueError, match=message):
        farm_study(layout, turbine, **kwargs)
    # the same study given as a FarmStudyConfig, and as a config the keywords complete
    with pytest.raises(ValueError, match=message):
        farm_study(layout, turbine, config=lj.FarmStudyConfig(**kwargs))
    first, *rest = kwargs.items()
    with pytest.raises(ValueError, match=message):
        farm_study(layout, turbine, lj.FarmStudyConfig(**dict([first])), **dict(rest))


def test_farm_study_options_are_the_config_fields(case):
    root, layout, turbine, _ = case
    with pytest.raises(TypeError, match="lidar_position"):
        farm_study(layout, turbine, lidar_position=LIDAR)


def test_check_lidar_position(case):
    lay = read_farm(case[1], case[2])
    check_lidar_position(lay, LIDAR)  # 600 m away: fine
    with pytest.raises(ValueError, match="its beams would cross the blades"):
        check_lidar_position(lay, (LIDAR[0] + 1300.0 - 30.0, LIDAR[1], 0.0))
