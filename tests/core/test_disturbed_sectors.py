"""IEC 61400-12-1 Annex A disturbed sectors: excluded widths, merging on the circle and
directions in sectors."""

import pytest

from lidarjax.disturbed_sectors import disturbed_sectors, excluded_width, in_sectors, merge_sectors


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
