"""ZephyCube baselines (seed 002, sections 3.1 and 3.2)."""

import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj
from lidarjax import zephycube as zc

from .. import sites


@pytest.fixture(scope="module")
def table():
    return sites.table(15.0, fields=True)


@pytest.fixture(scope="module")
def records(site_records):
    return site_records


def _err(wind, speed, direction):
    es = np.abs(np.asarray(wind.speed) / np.asarray(speed) - 1.0)
    ed = np.abs(np.asarray(lj.wrap180(wind.direction - direction)))
    return es, ed


def test_beam_layout(table):
    offset, cone, vertical = zc.beam_layout(table)
    assert offset == pytest.approx(sites.EPSILON) and cone == pytest.approx(28.0)
    assert vertical
    bare = lj.ResponseTable(table.directions, table.response)
    with pytest.raises(ValueError, match="beam_vectors"):
        zc.beam_layout(bare)
    n = np.stack([np.sin(np.linspace(0, 6, 6)), np.cos(np.linspace(0, 6, 6)), np.ones(6)], -1)
    odd = lj.ResponseTable(table.directions, np.zeros((24, 4, 6)),
                           beam_vectors=n / np.linalg.norm(n, axis=-1, keepdims=True))
    with pytest.raises(ValueError, match="Windcube"):
        zc.beam_layout(odd)
    with pytest.raises(ValueError, match="beam_velocity"):
        zc.scalar_correction(lj.ResponseTable.from_simulations(sites.records([0, 120, 240], 1.0),
                                                                mount=sites.MOUNT), 1, 1, 1)


def test_homogeneous_is_what_the_instrument_reports(table, records):
    wind = zc.homogeneous_wind(table, records.los)
    np.testing.assert_allclose(wind.speed, records.lidar_speed, rtol=1e-12)
    np.testing.assert_allclose(lj.wrap180(wind.direction - records.lidar_direction), 0, atol=1e-9)


def test_both_corrections_are_exact_at_the_true_direction(table, records):
    """With the speed-ups taken at the true free-stream direction, both methods recover the
    centre-line wind up to the table's interpolation error (their equations are exact)."""
    alpha = jnp.broadcast_to(records.free_direction[:, None], records.lidar_speed.shape)
    w_m = records.lidar_velocity[..., 2]  # the V2's vertical beam: w on the centre line
    vec = zc.vector_correction(table, records.los, alpha=alpha)
    sca = zc.scalar_correction(table, records.lidar_speed, records.lidar_direction, w_m,
                               alpha=alpha, threshold=0.0)
    for wind in (vec, sca):
        es, ed = _err(wind, records.point_speed, records.point_direction)
        assert np.mean(np.isnan(es)) < 0.05  # CFD ratio poles (denominator near zero)
        assert np.nanmax(es) < 1e-3 and np.nanmax(ed) < 0.05, (np.nanmax(es), np.nanmax(ed))
        assert np.nanmedian(es) < 1e-5


def test_zephycube_defaults_improve_on_uncorrected(table, records):
    w_m = records.lidar_velocity[..., 2]
    unc = zc.homogeneous_wind(table, records.los)
    vec = zc.vector_correction(table, records.los)
    sca = zc.scalar_correction(table, records.lidar_speed, records.lidar_direction, w_m)
    eu, du = _err(unc, records.point_speed, records.point_direction)
    ev, dv = _err(vec, records.point_speed, records.point_direction)
    es, ds = _err(sca, records.point_speed, records.point_direction)
    assert np.nanmean(ev) < np.mean(eu) / 10 and np.nanmean(dv) < np.mean(du)
    assert np.nanmean(es) < np.mean(eu) / 5


def test_filter_and_missing_beams(table, records):
    w0 = jnp.zeros_like(records.lidar_speed)
    # everything below the threshold and no vertical term: the .sta values come back
    out = zc.scalar_correction(table, records.lidar_speed, records.lidar_direction, w0,
                               threshold=np.inf)
    np.testing.assert_allclose(out.speed, records.lidar_speed, rtol=1e-12)
    los = np.array(records.los)
    los[0, 1, 2] = np.nan
    vec = zc.vector_correction(table, los)
    assert np.isnan(vec.speed[0, 1]) and np.all(np.isfinite(vec.speed[0, [0, 2, 3]]))
    with pytest.raises(ValueError, match=r"\(\.\.\., h, b\)"):
        zc.vector_correction(table, los[..., :4])


def test_normalised_rose_matches_the_tabulated_runs(table):
    rose = zc.normalised_rose(table)
    assert rose.speed_up.shape == (360, len(sites.HEIGHTS), 5)
    k = np.round(np.asarray(table.directions)).astype(int) % 360  # runs at whole degrees
    beams, centre = np.asarray(table.beam_velocity), np.asarray(table.point)
    ratio = np.hypot(beams[..., 0], beams[..., 1])
    ratio = ratio / np.hypot(centre[..., 0], centre[..., 1])[..., None]
    np.testing.assert_allclose(rose.speed_up[k], ratio, rtol=1e-10)
    dev = lj.direction_difference(beams, np.broadcast_to(centre[:, :, None], beams.shape))
    np.testing.assert_allclose(rose.deviation[k], dev, atol=1e-8)
    with pytest.raises(ValueError, match="beam_velocity"):
        zc.normalised_rose(sites.table(30.0))


