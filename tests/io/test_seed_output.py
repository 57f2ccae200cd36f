"""Seed output files, azimuth conventions, self-describing CSV and NetCDF writers."""

import math
import os
import sys

import numpy as np
import pytest

import lidarjax
from lidarjax.io import (
    SEED_COLUMNS,
    SEED_UNITS,
    meteorological_from_seed,
    read_seed_output,
    read_table_csv,
    seed_from_meteorological,
    seed_output_filename,
    write_netcdf,
    write_seed_output,
    write_table_csv,
)
from lidarjax.io.seed_output import _seed_azimuth_uv as seed_azimuth


def c_seed_azimuth(u, v):
    """The seed C code's quadrant formula (thl / thp), for u != 0 and v != 0."""
    a = math.degrees(math.atan(v / u))
    if u > 0:
        return 360.0 - a if v > 0 else -a
    return 180.0 - a


def columns(nh=5, seed=0):
    rng = np.random.default_rng(seed)
    cols = {name: rng.normal(0.0, 10.0, nh) for name in SEED_COLUMNS}
    cols["h"] = np.arange(1, nh + 1) * 0.02
    cols["Th_lidar"] = rng.uniform(0.0, 360.0, nh)
    return cols


# -- azimuth conventions ---------------------------------------------------------------


def test_seed_table1_example():
    theta = seed_azimuth(2.25, -15.06)
    assert theta == pytest.approx(81.503, abs=1e-3)  # the UDF printed 81.484 from unrounded u, v
    assert meteorological_from_seed(theta) == pytest.approx(351.503, abs=1e-3)
    assert seed_from_meteorological(351.5) == pytest.approx(81.5, abs=1e-12)


def test_seed_azimuth_matches_c_quadrants():
    for u in (-7.0, -0.5, 0.3, 12.0):
        for v in (-9.0, -0.2, 0.4, 5.0):
            assert seed_azimuth(u, v) == pytest.approx(c_seed_azimuth(u, v) % 360.0, abs=1e-12)


def test_conventions_agree_with_core_wind_direction():
    rng = np.random.default_rng(1)
    u, v = rng.normal(size=(2, 200))
    met = meteorological_from_seed(seed_azimuth(u, v))
    core = np.asarray(lidarjax.wind_direction(np.stack([u, v, np.zeros_like(u)], axis=-1)))
    gap = np.abs((met - core + 180.0) % 360.0 - 180.0)
    assert np.max(gap) < 1e-10
    # cardinal cases: a southward flow heads 90 deg clockwise from east, comes from north (0)
    assert seed_azimuth(0.0, -1.0) == 90.0 and meteorological_from_seed(90.0) == 0.0
    assert seed_azimuth(1.0, 0.0) == 0.0 and meteorological_from_seed(0.0) == 270.0  # westerly


def test_conversions_are_inverse_and_wrapped():
    d = np.array([0.0, 1e-15, 89.999, 90.0, 270.0, 359.9999999, -10.0, 725.0, np.nan])
    theta = seed_from_meteorological(d)
    back = meteorological_from_seed(theta)
    assert np.all((theta[:-1] >= 0) & (theta[:-1] < 360))
    assert np.all((back[:-1] >= 0) & (back[:-1] < 360))
    np.testing.assert_allclose(back[:-1], np.mod(d[:-1], 360.0), atol=1e-9)
    assert np.isnan(theta[-1]) and np.isnan(back[-1])
    assert meteorological_from_seed(-1e-15) < 360.0


def test_calm_has_no_azimuth():
    out = seed_azimuth(np.array([0.0, 1.0]), np.array([0.0, 0.0]))
    assert np.isnan(out[0]) and out[1] == 0.0


# -- seed output files -----------------------------------------------------------------


@pytest.mark.parametrize(
    ("beta", "name"),
    [(330.0, "windcube simulation 330 degrees.dat"), (0, "windcube simulation 0 degrees.dat"),
     (22.5, "windcube simulation 22.5 degrees.dat"),
     (-30.0, "windcube simulation -30 degrees.dat")],
)
def test_filename(beta, name):
    assert seed_output_filename(beta) == name


def test_write_verbose_and_read_back(tmp_path):
    cols = columns()
    cols["cfp_th"][2] = np.nan
    path = write_seed_output(tmp_path / "out", 330.0, cols, verbose=1)
    assert path == tmp_path / "out" / "windcube simulation 330 degrees.dat"
    lines = path.read_text().splitlines()
    assert lines[0] == " ".join(SEED_COLUMNS)
    assert len(lines) == 6
    first = lines[1]
    assert first == "".join(f" {v:6.3f}" for v in (cols[c][0] for c in SEED_COLUMNS)) + " "
    assert first.startswith("  0.020 ")  # C's " %6.3f"
    assert lines[3].split()[-1] == "nan"
    back = read_seed_output(path)
    assert list(back) == list(SEED_COLUMNS)
    for name in SEED_COLUMNS:
        np.testing.assert_allclose(back[name], cols[name], atol=5e-4 + 1e-12)
    assert np.isnan(back["cfp_th"][2])
    assert os.listdir(tmp_path / "out") == [path.name]


def test_write_abbreviated_has_no_header(tmp_path):
    cols = columns(nh=3)
    path = write_seed_output(tmp_path, 22.5, cols, verbose=False)
    lines = path.read_text().splitlines()
    assert len(lines) == 3 and len(lines[0].split()) == 21
    np.testing.assert_allclose(read_seed_output(path)["h"], [0.02, 0.04, 0.06])


def test_write_rejects_bad_columns(tmp_path):
    cols = columns()
    with pytest.raises(ValueError, match="missing seed columns: cff_u, cfp_th"):
        write_seed_output(tmp_path, 0, {k: v for k, v in cols.items()
                                        if k not in ("cff_u", "cfp_th")}, verbose=0)
    with pytest.raises(ValueError, match="unknown columns 'Th_Lidar'"):
        write_seed_output(tmp_path, 0, {**cols, "Th_Lidar": cols["h"]}, verbose=0)
    with pytest.raises(ValueError, match="column 'W_lidar' has length 4, expected 5"):
        write_seed_output(tmp_path, 0, {**cols, "W_lidar": np.zeros(4)}, verbose=0)
    with pytest.raises(ValueError, match="must be 1-D"):
        write_seed_output(tmp_path, 0, {**cols, "W_lidar": np.zeros((5, 1))}, verbose=0)
    with pytest.raises(ValueError, match="verbose must be 0 or 1"):
        write_seed_output(tmp_path, 0, cols, verbose=2)
    assert os.listdir(tmp_path) == []


def test_read_seed_output_errors(tmp_path):
    path = tmp_path / "bad.dat"
    path.write_text(" ".join(SEED_COLUMNS) + "\n" + " 1.0" * 21 + "\n" + " 1.0" * 20 + "\n")
    with pytest.raises(ValueError, match=rf"^{path}, line 3: expected 21 numbers, found 20"):
        read_seed_output(path)
    path.write_text(" 1.0" * 20 + " x\n")
    with pytest.raises(ValueError, match=r"line 1: column 'cfp_th': expected a number, found 'x'"):
        read_seed_output(path)
    path.write_text("h U V\n")
    with pytest.raises(ValueError, match="line 1: expected the seed header"):
        read_seed_output(path)
    with pytest.raises(FileNotFoundError, match="missing.dat"):
        read_seed_output(tmp_path / "missing.dat")


def test_failed_replace_leaves_old_file_and_no_temp(tmp_path, monkeypatch):
    cols = columns()
    path = write_seed_output(tmp_path, 30, cols, verbose=1)
    before = path.read_bytes()

    def boom(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr("lidarjax._util.os.replace", boom)
    with pytest.raises(OSError, match="disk full"):
        write_seed_output(tmp_path, 30, columns(seed=5), verbose=0)
    assert path.read_bytes() == before
    assert os.listdir(tmp_path) == [path.name]


# -- CSV and NetCDF ----------------------------------------------------------------------


def test_table_csv_round_trip(tmp_path):
    cols = columns(nh=4)
    cols["U_lidar"][1] = np.nan
    meta = {"beta": 330, "settings": "settings.dat", "lidarjax": "0.1"}
    path = write_table_csv(tmp_path / "t.csv", cols, metadata=meta)
    lines = path.read_text().splitlines()
    assert lines[:3] == ["# beta: 330", "# settings: settings.dat", "# lidarjax: 0.1"]
    header = lines[3].split(",")
    assert header[0] == "h [m]" and header[2] == "U_lidar [m/s]"
    assert "Th_lidar [deg" in lines[3] and "Th_lidar [deg, seed azimuth]" in lines[3]
    assert "cff_u [1]" in lines[3]
    table = read_table_csv(path)
    assert table.metadata == {"beta": "330", "settings": "settings.dat", "lidarjax": "0.1"}
    assert table.units["Th_lidar"] == "deg, seed azimuth" and table.units == SEED_UNITS
    for name in SEED_COLUMNS:
        np.testing.assert_array_equal(table.columns[name], cols[name])  # exact round trip


def test_table_csv_custom_units_and_errors(tmp_path):
    path = write_table_csv(tmp_path / "a.csv", {"x": [1.0, 2.5], "los": [0.1, -3.0]},
                           {"x": "m", "los": "m/s, positive away"})
    t = read_table_csv(path)
    assert t.units == {"x": "m", "los": "m/s, positive away"} and t.metadata == {}
    np.testing.assert_array_equal(t.columns["los"], [0.1, -3.0])
    with pytest.raises(ValueError, match="no unit given for columns los"):
        write_table_csv(tmp_path / "b.csv", {"x": [1.0], "los": [2.0]}, {"x": "m"})
    with pytest.raises(ValueError, match="must be a single line"):
        write_table_csv(tmp_path / "b.csv", {"x": [1.0]}, {"x": "m"}, {"note": "a\nb"})
    with pytest.raises(ValueError, match="must not contain"):
        write_table_csv(tmp_path / "b.csv", {"x,y": [1.0]}, {"x,y": "m"})
    assert not (tmp_path / "b.csv").exists()
    bad = tmp_path / "c.csv"
    bad.write_text("# a: 1\nx [m],y [m]\n1,2\n3\n")
    with pytest.raises(ValueError, match=rf"^{bad}, line 4: expected 2 comma-separated values"):
        read_table_csv(bad)
    bad.write_text("x,y\n1,2\n")
    with pytest.raises(ValueError, match="line 1: expected a header of 'name \\[unit\\]' cells"):
        read_table_csv(bad)


def test_netcdf_needs_xarray(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "xarray", None)
    with pytest.raises(ImportError, match=r"pip install lidarjax\[netcdf\]"):
        write_netcdf(tmp_path / "a.nc", columns(), {})
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("force_scipy", [False, True])
def test_netcdf_round_trip(tmp_path, monkeypatch, force_scipy):
    import xarray as xr

    from lidarjax import _util as _common

    if force_scipy:  # as on a machine with xarray but without h5netcdf/h5py
        monkeypatch.setattr(_common, "have_module", lambda name: name not in ("h5netcdf", "h5py"))
        assert _common.netcdf_engine() == "scipy"
    cols = columns(nh=6)
    path = write_netcdf(tmp_path / "seed.nc", cols, {"beta": 330.0, "verbose": True,
                                                    "source": "settings.dat"})
    with xr.open_dataset(path) as ds:
        ds.load()
        np.testing.assert_array_equal(ds["h"].values, cols["h"])
        np.testing.assert_array_equal(ds["Th_lidar"].values, cols["Th_lidar"])
        assert ds["U_lidar"].attrs["units"] == "m/s"
        assert ds["Th_lidar"].attrs["units"] == "deg, seed azimuth"
        assert ds.attrs["beta"] == 330.0 and ds.attrs["verbose"] == 1
        assert ds.attrs["source"] == "settings.dat"
        assert ds["cff_u"].dims == ("h",)
    assert os.listdir(tmp_path) == ["seed.nc"]
