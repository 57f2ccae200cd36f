"""Windcube 200S scanning NetCDF (the committed real cut) and the CF NetCDF writer of scans:
the reader against h5py, the real DBS reconstructed by `vad_fit` and simulated in its own
layout, and a simulated series written and read back."""

from __future__ import annotations

import numpy as np
import pytest

import lidarjax as lj
from lidarjax.io import read_scan_netcdf, read_windcube_scan, write_scan_netcdf

from ..helpers import DATA

h5py = pytest.importorskip("h5py")
pytest.importorskip("xarray")

DBS = DATA / "scanning" / "WLS200S-218_2021-07-01_13-03-28_dbs_452_100m_cut.nc"


@pytest.fixture(scope="module")
def dbs():
    return read_windcube_scan(DBS)


def test_reader_matches_h5py(dbs):
    with h5py.File(DBS, "r") as f:
        g = f["Sweep_748901"]
        np.testing.assert_array_equal(dbs.radial_wind_speed, g["radial_wind_speed"][()])
        np.testing.assert_array_equal(dbs.azimuth, g["azimuth"][()])
        np.testing.assert_array_equal(dbs.elevation, g["elevation"][()])
        np.testing.assert_array_equal(dbs.ranges, g["range"][()])
        np.testing.assert_array_equal(dbs.cnr, g["cnr"][()])
        secs = g["time"][()]
        stamps = [s.decode() if isinstance(s, bytes) else s for s in g["timestamp"][()]]
    np.testing.assert_array_equal(dbs.time, np.array([s.rstrip("Z") for s in stamps], "datetime64[us]"))
    np.testing.assert_allclose(dbs.seconds(), secs - secs[0], atol=1e-6)
    assert (dbs.sweep_mode, dbs.gate_length, dbs.accumulation) == ("dbs", 100.0, 2.0)
    assert dbs.instrument == "WLS200S-218"


def test_real_dbs_fit_and_simulation_in_its_layout(dbs):
    """`vad_fit` of the real LOS; the fitted wind simulated along the file's own rays and
    gates (per-ray ranges) differs from the real LOS by exactly the fit's residual."""
    los = dbs.radial_velocity()
    good = np.all(np.isfinite(los), axis=0)  # gates the instrument accepted on every ray
    assert good.sum() >= 5
    los = los[:, good]
    prof = lj.vad_fit(los, dbs.azimuth, dbs.elevation, dbs.ranges[0, good])
    v = np.asarray(prof.velocity)
    assert np.all(np.isfinite(v)) and np.all(np.asarray(prof.flags) == 0)
    direction = np.degrees(np.arctan2(-v[:, 0], -v[:, 1])) % 360
    assert np.all((direction > 255) & (direction < 300))  # westerly, as the file reports (269-283)
    sim = np.empty_like(los)
    for g in range(los.shape[1]):
        wind = lj.scenes.linear(v[g], np.zeros((3, 3)))
        for r in range(los.shape[0]):
            p = lj.ScanPattern([dbs.azimuth[r]], dbs.elevation[r], [dbs.ranges[r, good][g]], ray_start=0.0,
                               accumulation=dbs.accumulation)
            sim[r, g] = float(lj.simulate_scan(wind, p, lj.Mount([0.0, 0.0, 0.0])).los[0, 0])
    rms = np.sqrt(np.mean((los - sim) ** 2, axis=0))
    np.testing.assert_allclose(rms, np.asarray(prof.residual), rtol=1e-9, atol=1e-12)


def test_malformed_netcdf_refused(tmp_path):
    bad = tmp_path / "bad.nc"
    bad.write_bytes(b"not a netcdf file at all")
    with pytest.raises(ValueError) as err:
        read_windcube_scan(bad)
    assert str(bad) in str(err.value) and "\n" not in str(err.value)
    other = tmp_path / "other.nc"
    write_scan_netcdf(other, np.zeros((1, 2, 3)), azimuth=[0, 1], elevation=5.0, ranges=[1, 2, 3],
                      ray_time=[[0.0, 1.0]])
    with pytest.raises(ValueError, match="sweep_group_name"):
        read_windcube_scan(other)


def test_series_written_as_cf_time_beam_range_and_read_back(tmp_path):
    field = lj.scenes.uniform(7.0, 200.0)
    p = lj.ppi(3.0, lj.gate_ranges(8, 30.0), azimuth_start=10.0, azimuth_stop=70.0, n_rays=4,
               mode="step")
    res = lj.simulate_scan_series(field, p, lj.Mount([0.0, 0.0, 0.0]), n_scans=3, start=100.0)
    path = write_scan_netcdf(tmp_path / "ppi.nc", res.los, azimuth=res.azimuth, elevation=res.elevation,
                             ranges=res.ranges, ray_time=res.times, flags=res.flags)
    back = read_scan_netcdf(path)
    assert back["radial_velocity"].shape == (3, 4, 8)
    np.testing.assert_array_equal(back["radial_velocity"], np.asarray(res.los))
    np.testing.assert_array_equal(back["ray_time"], np.asarray(res.times))
    np.testing.assert_array_equal(back["range"], np.asarray(res.ranges))
    np.testing.assert_array_equal(back["flags"], np.asarray(res.flags))
    assert back["attrs"]["Conventions"] == "CF-1.8"
    with pytest.raises(ValueError, match="shapes disagree"):
        write_scan_netcdf(tmp_path / "x.nc", res.los, azimuth=res.azimuth, elevation=res.elevation,
                          ranges=res.ranges[:3], ray_time=res.times)
