"""Correction-factor roses (`lidarjax.correction_rose`, `lidarjax.sector_rose`): the free
rose is the seed's correction factors, the lidar rose corrects records, sectors average it."""

import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj

from .. import sites


def test_free_rose_is_the_seed_correction_factors():
    table = sites.table(30.0)
    sims = sites.records(np.arange(0.0, 360.0, 30.0), 10.0)
    rose = lj.correction_rose(table, reference="free")
    idx = np.round(np.asarray(sims.free_direction)).astype(int) % 360
    np.testing.assert_allclose(rose.speed_ratio[idx], sims.cff_U, rtol=1e-10)
    np.testing.assert_allclose(rose.direction_addend[idx], sims.cff_th, atol=1e-8)
    point = lj.correction_rose(table, reference="free", target="point")
    np.testing.assert_allclose(point.speed_ratio[idx], sims.cfp_U, rtol=1e-10)
    np.testing.assert_allclose(point.direction_addend[idx], sims.cfp_th, atol=1e-8)
    with pytest.raises(ValueError, match="reference='lidar'"):
        rose.apply(sims.lidar_speed, sims.lidar_direction)


def test_lidar_rose_corrects_records_and_sectors_average_it(site_records):
    table = sites.table(30.0)
    rose = lj.correction_rose(table)  # indexed by the lidar's direction, 1 degree
    assert rose.speed_ratio.shape == (360, len(sites.HEIGHTS))
    speed, direction = rose.apply(site_records.lidar_speed, site_records.lidar_direction)
    es = np.abs(np.asarray(speed) / np.asarray(site_records.free_speed)[:, None] - 1)
    ed = np.abs(np.asarray(lj.wrap180(direction - site_records.free_direction[:, None])))
    unc = np.abs(np.asarray(site_records.cff_U) - 1)
    assert np.all(es.mean(0) * 20 < unc.mean(0)) and ed.max() < 0.05
    sectors = lj.sector_rose(rose, 12)
    assert sectors.sectors and sectors.directions.shape == (12,)
    # sector 30 deg: the mean over 16..44 deg plus half of 15 and 45
    w = np.zeros(360)
    w[16:45] = 1.0
    w[[15, 45]] = 0.5
    np.testing.assert_allclose(sectors.speed_ratio[1], w @ np.asarray(rose.speed_ratio) / w.sum())
    ratio, _ = sectors.at(jnp.full((3, len(sites.HEIGHTS)), 44.9))
    np.testing.assert_allclose(ratio[0], sectors.speed_ratio[1])
    ratio, _ = sectors.at(jnp.full((1, len(sites.HEIGHTS)), 359.0))
    np.testing.assert_allclose(ratio[0], sectors.speed_ratio[0])
    s12, _ = sectors.apply(site_records.lidar_speed, site_records.lidar_direction)
    e12 = np.abs(np.asarray(s12) / np.asarray(site_records.free_speed)[:, None] - 1)
    assert np.mean(e12) > np.mean(es)  # coarser sectors correct less well
    with pytest.raises(ValueError, match="divide 360"):
        lj.correction_rose(table, resolution=7.0)
    with pytest.raises(ValueError, match="sector rose"):
        lj.sector_rose(sectors)
