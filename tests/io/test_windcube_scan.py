"""Windcube 200S scanning NetCDF (a real cut, where available: `scanning_file`,
tests/data/scanning/README.md) and the CF NetCDF writer of scans:
the reader against h5py, the real DBS reconstructed by `vad_fit` and simulated in its own
layout, the file's own wind product explained (its processing took the east ray for the
vertical one), and a simulated series written and read back."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
import xarray  # noqa: F401  (the test extra brings it)

import lidarjax as lj
from lidarjax.io import read_scan_netcdf, read_windcube_scan, write_scan_netcdf

from ..helpers import scanning_file

DBS_NAME = "WLS200S-218_2021-07-01_13-03-28_dbs_452_100m_cut.nc"


@pytest.fixture(scope="module")
def dbs_path():
    return scanning_file(DBS_NAME)


@pytest.fixture(scope="module")
def dbs(dbs_path):
    return read_windcube_scan(dbs_path)


def test_reader_matches_h5py(dbs, dbs_path):
    with h5py.File(dbs_path, "r") as f:
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
    with h5py.File(dbs_path, "r") as f:
        g = f["Sweep_748901"]
        np.testing.assert_array_equal(dbs.measurement_height, g["measurement_height"][()])
        np.testing.assert_array_equal(dbs.horizontal_wind_speed, g["horizontal_wind_speed"][()])
        np.testing.assert_array_equal(dbs.wind_direction, g["wind_direction"][()])
        np.testing.assert_array_equal(dbs.wind_status, g["wind_speed_status"][()] == 1)
    # the processing's elevations, from range and measurement_height: the east ray (the last)
    # was gated as the vertical one, the vertical one (the second) as a 75-degree ray
    np.testing.assert_allclose(dbs.range_elevation(), [75, 75, 75, 75, 90], atol=0.05)
    np.testing.assert_array_equal(dbs.elevation, [75, 90, 75, 75, 75])


def test_ray_time_is_the_end_of_each_ray(dbs, dbs_path):
    """`time` is the end of each ray, as the instrument's software states in the file it
    wrote (the comments of ``time``, ``timestamp``, ``azimuth`` and ``elevation``, server
    3.3.0); the file name's 13-03-28 is the first ray's end time (13:03:28.088) cut to the
    second, so it does not mark a start: the first ray began one accumulation
    (``ray_accumulation_time``, 2000 ms) earlier, at 13:03:26.088."""
    with h5py.File(dbs_path, "r") as f:
        g = f["Sweep_748901"]
        comments = {k: g[k].attrs["comments"].decode() for k in ("time", "timestamp", "azimuth",
                                                                  "elevation")}
        stamps = [np.datetime64(t.decode().rstrip("Z"), "us") for t in g["timestamp"][()]]
        acc_ms = float(g["ray_accumulation_time"][()])
    assert "the end of each ray measurement" in comments["time"]
    assert "at the end of each ray measurement" in comments["timestamp"]
    assert all("when each measurement finished" in comments[k] for k in ("azimuth", "elevation"))
    np.testing.assert_array_equal(dbs.time.astype("datetime64[ms]"), np.array(stamps, "datetime64[ms]"))
    named = np.datetime64(DBS_NAME.split("_")[1] + "T" + DBS_NAME.split("_")[2].replace("-", ":"))
    assert dbs.time[0].astype("datetime64[s]") == named
    assert dbs.accumulation == acc_ms * 1e-3 == 2.0
    # rays 2.95 to 5.46 s apart: more than an accumulation, room for the head's moves
    assert np.all(np.diff(dbs.seconds()) > dbs.accumulation)


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
    assert np.all((direction > 255) & (direction < 300))  # westerly, as the file reports (269-292)
    sim = np.empty_like(los)
    for g in range(los.shape[1]):
        wind = lj.scenes.linear(v[g], np.zeros((3, 3)))
        for r in range(los.shape[0]):
            p = lj.ScanPattern([dbs.azimuth[r]], dbs.elevation[r], [dbs.ranges[r, good][g]], ray_start=0.0,
                               accumulation=dbs.accumulation)
            sim[r, g] = float(lj.simulate_scan(wind, p, lj.Mount([0.0, 0.0, 0.0])).los[0, 0])
    rms = np.sqrt(np.mean((los - sim) ** 2, axis=0))
    np.testing.assert_allclose(rms, np.asarray(prof.residual), rtol=1e-9, atol=1e-12)


def _quantised_bound(azimuth, elevation, los_step=0.01):
    """Largest change of the fitted (u, v) when each LOS moves by half `los_step` (the file
    stores LOS in steps of 0.01 m/s): half a step times the absolute row sums of the
    least-squares pseudo-inverse."""
    a, e = np.radians(azimuth), np.radians(elevation)
    rays = np.stack([np.cos(e) * np.sin(a), np.cos(e) * np.cos(a), np.sin(e)], axis=1)
    pinv = np.linalg.pinv(rays)
    return 0.5 * los_step * np.abs(pinv[:2]).sum(axis=1)


def test_reported_wind_is_the_fit_with_the_processing_elevations(dbs):
    """The file's horizontal wind (on its last ray, the first with 4 inclined LOS: CI 100)
    is the least-squares DBS fit of the sweep's 4 non-vertical-labelled rays with the
    elevations its processing used (`range_elevation`: the east ray at 90 degrees), to the
    rounding of the stored numbers; with the head's angles the same LOS give a wind about 25%
    slower in the same direction. Tolerance: the LOS and speeds are stored in steps of 0.01
    m/s and directions of 0.1 degree, so speed agrees within half a step times the fit's
    sensitivity plus half a step, direction within the same over the speed plus 0.05 deg."""
    last = dbs.wind_status.shape[0] - 1
    ok = dbs.wind_status[last]
    assert ok.sum() == 14 and not dbs.wind_status[:last].any()
    rays = np.flatnonzero(dbs.elevation < 89)  # N, S, W, E: the rays the product combines
    los = dbs.radial_velocity()[rays][:, ok]
    el_proc = np.round(dbs.range_elevation()[rays])
    assert list(el_proc) == [75, 75, 75, 90]
    heights = dbs.measurement_height[last, ok]
    inst = lj.vad_fit(los, dbs.azimuth[rays], el_proc, heights)
    u, v = np.asarray(inst.velocity)[:, 0], np.asarray(inst.velocity)[:, 1]
    speed = np.hypot(u, v)
    direction = np.degrees(np.arctan2(-u, -v)) % 360
    du, dv = _quantised_bound(dbs.azimuth[rays], el_proc)
    tol_speed = np.hypot(du, dv) + 0.005
    tol_dir = np.degrees(np.hypot(du, dv) / speed) + 0.05
    assert tol_speed < 0.05 and np.all(tol_dir < 0.5)
    np.testing.assert_array_less(np.abs(speed - dbs.horizontal_wind_speed[last, ok]), tol_speed)
    ddir = (direction - dbs.wind_direction[last, ok] + 180) % 360 - 180
    np.testing.assert_array_less(np.abs(ddir), tol_dir)
    # the head's angles (all 5 rays, the vertical one included): same direction, slower
    phys = lj.vad_fit(dbs.radial_velocity()[:, ok], dbs.azimuth, dbs.elevation, heights)
    vp = np.asarray(phys.velocity)
    ratio = dbs.horizontal_wind_speed[last, ok] / np.hypot(vp[:, 0], vp[:, 1])
    assert np.all((ratio > 1.15) & (ratio < 1.5)) and 1.25 < ratio.mean() < 1.4
    dphys = (np.degrees(np.arctan2(-vp[:, 0], -vp[:, 1])) - dbs.wind_direction[last, ok] + 180) % 360 - 180
    assert np.all(np.abs(dphys) < 6.0)


def test_head_angles_are_the_physical_ones(dbs):
    """Which geometry is real: with the head's angles the three estimates of ``w sin 75``
    (north + south, east + west, the vertical ray) agree to the vertical wind's variability
    over the 15 s sweep (0.25 m/s; the 69 sweeps of the source day give a sweep-to-sweep
    spread of 0.23 m/s), while the processing's geometry (east ray vertical) would need a
    1.4 m/s updraft on it against -0.3 m/s from the north-south pair."""
    los = dbs.radial_velocity()
    good = np.all(np.isfinite(los), axis=0)
    n, vert, s_, w_, e = los[:, good]
    sin = np.sin(np.radians(75.0))
    ns, ew, vz = np.mean((n + s_) / 2), np.mean((e + w_) / 2), np.mean(vert) * sin
    assert abs(ns - ew) < 0.1 and abs(ns - vz) < 0.4 and abs(ew - vz) < 0.4
    east_as_vertical = np.mean(e) * sin
    assert east_as_vertical - ns > 1.0


def test_processing_geometry_overreads_a_uniform_wind_in_closed_form(dbs):
    """A uniform wind simulated along the file's own rays (head angles, per-ray stored
    ranges) and reconstructed the instrument's way (the east ray taken as vertical) gives
    ``u (1 + s / (2 s^2 + 1)) + w s (s - 1) / (c (2 s^2 + 1))`` east and ``v`` north
    (``s, c = sin, cos 75 deg``): a westerly is over-read by 1.337; the head's angles give
    the wind back."""
    wind = np.array([8.0, -1.5, 0.4])
    field = lj.scenes.linear(wind, np.zeros((3, 3)))
    g = 1  # one gate per ray (a uniform wind is the same at every gate): shares the compiled scan
    los = np.empty((dbs.azimuth.size, g))
    for r in range(dbs.azimuth.size):
        p = lj.ScanPattern([dbs.azimuth[r]], dbs.elevation[r], dbs.ranges[r, 3:3 + g], ray_start=0.0,
                           accumulation=dbs.accumulation)
        los[r] = np.asarray(lj.simulate_scan(field, p, lj.Mount([0.0, 0.0, 0.0])).los[0])
    np.testing.assert_allclose(np.asarray(lj.vad_fit(los, dbs.azimuth, dbs.elevation,
                                                     dbs.ranges[0, 3:3 + g]).velocity),
                               np.broadcast_to(wind, (g, 3)), atol=1e-10)
    rays = np.flatnonzero(dbs.elevation < 89)
    inst = np.asarray(lj.vad_fit(los[rays], dbs.azimuth[rays], np.round(dbs.range_elevation()[rays]),
                                 dbs.ranges[0, 3:3 + g]).velocity)
    s, c = np.sin(np.radians(75.0)), np.cos(np.radians(75.0))
    u, v, w = wind
    expect_u = u * (1 + s / (2 * s**2 + 1)) + w * s * (s - 1) / (c * (2 * s**2 + 1))
    np.testing.assert_allclose(inst[:, 0], expect_u, rtol=1e-10)
    np.testing.assert_allclose(inst[:, 1], v, rtol=1e-10)
    assert abs(1 + s / (2 * s**2 + 1) - 1.337) < 5e-4


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
