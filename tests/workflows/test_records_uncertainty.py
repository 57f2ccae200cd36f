"""The uncertainty of corrected 10-minute records without `noise`: built from each record's
own dispersion and availability (`lidarjax.workflows.records.reported_noise`), it must cover the
truth as often as it claims, on synthetic records whose scans have known noise."""

import numpy as np
import pytest

import lidarjax as lj
from lidarjax.io import write_sta
from lidarjax.workflows.records import correct_records, load_records, reported_noise

HEIGHTS = np.array([40.0, 54.0, 74.0])
SCANS = 120  # 10 minutes of Windcube V2 scans (5 s each, the model's default)


def _gain(d):
    return 1.0 - 0.06 * np.cos(np.deg2rad(d))[..., None] * (1 + 0.2 * np.arange(3))


def _free(d):
    r = np.deg2rad(d)
    return np.stack([-np.sin(r), -np.cos(r)], -1)


@pytest.fixture(scope="module")
def table():
    d = np.arange(0.0, 360.0, 10.0)
    rec = np.concatenate([_gain(d)[..., None] * _free(d)[:, None, :],
                          np.zeros((d.size, 3, 1))], -1)  # (s, h, 3)
    vec = np.asarray(lj.windcube_v2().directions())
    return lj.ResponseTable(d, np.einsum("shk,bk->shb", rec, vec), reconstructed=rec,
                            beam_vectors=vec, heights=HEIGHTS)


def _synthetic(rng, n_records):
    """Records of SCANS scans each: free stream U (+ along-wind noise sigma_u, cross-wind
    0.8 sigma_u), seen through the table's distortion, some scans lost."""
    u = rng.uniform(4.0, 15.0, n_records)
    d = rng.uniform(0.0, 360.0, n_records)
    ti = rng.uniform(0.06, 0.18, (n_records, 3))
    avail = rng.uniform(0.5, 1.0, (n_records, 3))
    speed = np.empty((n_records, 3))
    direction = np.empty((n_records, 3))
    dispersion = np.empty((n_records, 3))
    used = np.empty((n_records, 3))
    for i in range(n_records):
        for j in range(3):
            n = max(2, int(round(avail[i, j] * SCANS)))
            su = ti[i, j] * u[i]
            along = u[i] + su * rng.standard_normal(n)
            cross = 0.8 * su * rng.standard_normal(n)
            e_along, e_cross = _free(d[i]), _free(d[i] + 90.0)
            v = along[:, None] * e_along + cross[:, None] * e_cross  # scan free streams
            dirs = np.rad2deg(np.arctan2(-v[:, 0], -v[:, 1])) % 360.0
            seen = _gain(dirs)[:, j, None] * v  # what each scan reports (distorted)
            mean = seen.mean(0)
            speed[i, j] = np.hypot(*mean)
            direction[i, j] = np.rad2deg(np.arctan2(-mean[0], -mean[1])) % 360.0
            dispersion[i, j] = np.hypot(seen[:, 0], seen[:, 1]).std(ddof=1)
            used[i, j] = n / SCANS
    return u, d, speed, direction, dispersion, 100.0 * used


def test_noise_model_formula():
    # n_eff = 0.8 * 600 / 5 = 96; across the wind 0.8 sigma_u
    along, cross = reported_noise(10.0, 1.0, availability=80.0, period_s=600.0,
                                  scan_period_s=5.0)
    np.testing.assert_allclose([along, cross], np.array([1.0, 0.8]) / np.sqrt(96.0))
    # a direction dispersion replaces the 0.8 ratio: sigma_v = U * sigma_dir (rad)
    along, cross = reported_noise(10.0, 1.0, direction_std=np.rad2deg(0.05), availability=100.0)
    np.testing.assert_allclose([along, cross], np.array([1.0, 0.5]) / np.sqrt(120.0))
    # the number of scans averaged, when the file says it, replaces the availability
    along, _ = reported_noise(10.0, 1.0, n_samples=25.0, availability=10.0)
    np.testing.assert_allclose(along, 0.2)
    assert np.isnan(reported_noise(10.0, np.nan)[0]) and np.isnan(reported_noise(10.0, 0.0)[0])


def test_intervals_cover_the_truth(table, tmp_path):
    rng = np.random.default_rng(2024)
    n = 300
    u, d, speed, direction, dispersion, avail = _synthetic(rng, n)
    time = np.datetime64("2024-01-01T00:10") + np.arange(n) * np.timedelta64(10, "m")
    path = tmp_path / "noisy.sta"
    write_sta(path, time, HEIGHTS, speed, direction, speed_std=dispersion,
              availability=avail, scan_angle=28.0)
    rec = load_records(path, min_availability=0.0)  # the test spans 50-100 % on purpose
    assert rec.instrument == "windcube_v2" and rec.period_s == 600.0
    res = correct_records(table, path, min_availability=0.0)
    assert res.converged.all() and np.all(res.speed_std > 0)
    z_speed = (res.speed - u[:, None]) / res.speed_std
    dd = (res.direction - d[:, None] + 180.0) % 360.0 - 180.0
    z_dir = dd / res.direction_std
    cover_speed = np.mean(np.abs(z_speed) < 1.96)
    cover_dir = np.mean(np.abs(z_dir) < 1.96)
    # 900 intervals: the binomial standard error of a 95 % coverage is 0.7 %
    assert 0.925 < cover_speed < 0.975, cover_speed
    assert 0.925 < cover_dir < 0.975, cover_dir
    # and the standard deviations are calibrated, not just wide enough
    assert 0.85 < np.std(z_speed) < 1.15 and 0.85 < np.std(z_dir) < 1.15
    # the noise used is reported per record-height
    along, _ = reported_noise(speed, dispersion, availability=avail)
    np.testing.assert_allclose(res.noise, along, rtol=1e-3)
