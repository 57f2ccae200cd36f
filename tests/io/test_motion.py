"""Platform motion logs (`lidarjax.io.read_motion_csv`)."""

import numpy as np
import pytest


def test_read_motion_csv(tmp_path):
    from lidarjax.io import read_motion_csv

    p = tmp_path / "buoy.csv"
    p.write_text("# buoy motion\ntime [s],heave [m],roll [deg],surge\n0,0.1,1.0,0.0\n1,0.2,-1.0,0.5\n"
                 "2,0.0,0.5,0.2\n")
    m = read_motion_csv(p)
    np.testing.assert_allclose(m.times, [0, 1, 2])
    np.testing.assert_allclose(m.offset[:, 2], [0.1, 0.2, 0.0])  # heave -> z
    np.testing.assert_allclose(m.offset[:, 1], [0.0, 0.5, 0.2])  # surge -> y
    np.testing.assert_allclose(m.attitude[:, 1], [1.0, -1.0, 0.5])  # roll
    np.testing.assert_allclose(m.attitude[:, 0], 0.0)
    bad = tmp_path / "bad.csv"
    bad.write_text("time,bob\n0,1\n1,2\n")
    with pytest.raises(ValueError, match="bad.csv, line 1"):
        read_motion_csv(bad)
    bad.write_text("time,heave\n0,1\n0,2\n")
    with pytest.raises(ValueError, match="line 3.*increase"):
        read_motion_csv(bad)
