"""Seed 004 layouts and turbine types: `lidarjax.io.read_layout`, `read_turbine_type`,
`read_farm` and their one-line errors."""

import numpy as np
import pytest

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


def test_thrust_curve_outside_0_1_is_clipped_as_floris_does(tmp_path):
    (tmp_path / "t.csv").write_text(TYPE.replace("4.0,0.82", "4.0,1.3"))
    with pytest.warns(UserWarning, match=r"t.csv: Ct 0..1.3 leaves \[0, 1\); clipped to "
                                         r"\[0.0001, 0.9999\] as FLORIS does"):
        t = read_turbine_type(tmp_path / "t.csv")
    np.testing.assert_allclose(t.ct, [1e-4, 0.9999, 0.72, 0.06])


def _floris_library():
    from pathlib import Path

    import floris
    import yaml  # noqa: F401  (the test extra brings it)

    return Path(floris.__file__).parent / "turbine_library"


def test_floris_turbine_library_yaml_as_floris_ships_it():
    """FLORIS's own NREL 5 MW definition: Ct rises to 1.13 below cut-in; it is read, clipped
    the way FLORIS clips it, and every value matches the file."""
    import yaml

    path = _floris_library() / "nrel_5MW.yaml"
    raw = yaml.safe_load(path.read_text())
    with pytest.warns(UserWarning, match="nrel_5MW.yaml: Ct .* clipped"):
        t = read_turbine_type(path)
    assert t.name == "nrel_5MW" and t.diameter == raw["rotor_diameter"]
    assert t.hub_height == raw["hub_height"]
    table = raw["power_thrust_table"]
    np.testing.assert_array_equal(t.speed, table["wind_speed"])
    np.testing.assert_allclose(t.ct, np.clip(table["thrust_coefficient"], 1e-4, 0.9999))
    for other in ("iea_10MW.yaml", "iea_15MW.yaml"):  # in-range curves: as given, no warning
        u = read_turbine_type(_floris_library() / other)
        assert u.diameter > 150 and np.all((u.ct >= 0) & (u.ct < 1))


def test_windio_turbine_yaml(tmp_path):
    import yaml  # noqa: F401  (the test extra brings it)
    (tmp_path / "wt.yaml").write_text(
        "name: IEA 3.4MW\nhub_height: 110.0\nrotor_diameter: 130.0\nperformance:\n"
        "  Ct_curve:\n    Ct_wind_speeds: [3.0, 8.0, 12.0, 25.0]\n"
        "    Ct_values: [0.8, 0.77, 0.5, 0.05]\n"
        "  power_curve:\n    power_wind_speeds: [3.0, 25.0]\n    power_values: [0, 3.37e6]\n")
    t = read_turbine_type(tmp_path / "wt.yaml")
    assert (t.name, t.diameter, t.hub_height) == ("IEA 3.4MW", 130.0, 110.0)
    np.testing.assert_array_equal(t.ct, [0.8, 0.77, 0.5, 0.05])
    (tmp_path / "bad.yaml").write_text("name: x\nhub_height: 110\nrotor_diameter: 130\n")
    with pytest.raises(ValueError, match="bad.yaml: no thrust curve"):
        read_turbine_type(tmp_path / "bad.yaml")
    (tmp_path / "bad2.yaml").write_text("hub_height: 110\npower_thrust_table:\n"
                                        "  wind_speed: [3, 4]\n  thrust_coefficient: [0.8, 0.7]\n")
    with pytest.raises(ValueError, match="bad2.yaml: FLORIS turbine without 'rotor_diameter'"):
        read_turbine_type(tmp_path / "bad2.yaml")
