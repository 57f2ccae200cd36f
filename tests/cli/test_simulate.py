"""`lidarjax simulate` on an OpenFOAM case given as its folder, one of its time folders or its
controlDict (the real turbineSiting cut of tests/data/openfoam), each run read only where
the beams look."""

import numpy as np
import pytest

from lidarjax.cli import main
from lidarjax.io import Settings, read_table_csv, write_settings

from ..helpers import DATA

CUT = DATA / "openfoam" / "turbineSiting_cut"
LIDAR = [581700.0, 4786000.0, 982.309]  # on the hill (tests/io/test_openfoam.py)


@pytest.fixture(scope="module")
def settings(tmp_path_factory):
    path = tmp_path_factory.mktemp("s") / "settings.dat"
    write_settings(path, Settings(zone=2, verbose=1, height=36.0, nh=3, gamma=0.0, beta=0.0,
                                  psi=0.0, epsilon=0.0, betas=np.array([0.0]),
                                  locations=np.array([LIDAR])))
    return path


def _run(settings, field, out):
    argv = ["simulate", str(settings), "--field", str(field), "--scan", "windcube_v2",
            "--out", str(out)]
    assert main(argv) == 0
    return read_table_csv(out / "simulation_0.csv").columns


def test_case_folder_time_folder_and_control_dict_agree(settings, tmp_path, capsys):
    ref = _run(settings, CUT, tmp_path / "case")
    assert np.all(np.isfinite(ref["U_mag_lidar"])) and np.all(ref["U_mag_lidar"] > 1.0)
    for i, field in enumerate((CUT / "168", CUT / "system" / "controlDict")):
        got = _run(settings, field, tmp_path / f"other{i}")
        for key in ("U_mag_lidar", "Th_lidar", "W_lidar", "U_mag_point"):
            np.testing.assert_array_equal(got[key], ref[key], err_msg=f"{field}: {key}")
    capsys.readouterr()


def test_a_folder_that_is_no_case_is_one_line(settings, tmp_path, capsys):
    (tmp_path / "runs").mkdir()
    argv = ["simulate", str(settings), "--field", str(tmp_path / "runs"), "--out",
            str(tmp_path / "o")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "not an OpenFOAM case" in err
    argv[3] = str(CUT / "999")
    assert main(argv) == 2
    assert "not found" in capsys.readouterr().err
