"""Monitor-point files (`lidarjax.io.MonitorPoints` and its readers and writers), on points built
by hand: no forward model is needed to check the file layouts."""

import numpy as np
import pytest

from lidarjax.io import (
    MonitorPoints,
    read_monitor_points_csv,
    read_monitor_values_csv,
    read_openfoam_probes,
    write_monitor_points_csv,
    write_openfoam_probes,
)

from .._foamwrite import write_probes_output


def points(n=3):
    return MonitorPoints(
        names=tuple(f"b0_h10_beam{b}_q0" for b in range(n)), mount=("b0",) * n,
        points=np.array([[1.5, -2.25, 10.0 + b] for b in range(n)]), beta=np.zeros(n),
        height=np.full(n, 10.0), beam=np.arange(n), node=np.zeros(n, int), weight=np.ones(n))


def test_validation_names_the_field():
    p = points()
    with pytest.raises(ValueError, match="points must have shape"):
        MonitorPoints(p.names, p.mount, p.points[:2], p.beta, p.height, p.beam, p.node, p.weight)
    with pytest.raises(ValueError, match="unique"):
        MonitorPoints(("a", "a", "b"), p.mount, p.points, p.beta, p.height, p.beam, p.node,
                      p.weight)
    with pytest.raises(ValueError, match="finite"):
        MonitorPoints(p.names, p.mount, p.points * np.nan, p.beta, p.height, p.beam, p.node,
                      p.weight)
    assert len(p) == 3 and p.labels == ("b0",)
    np.testing.assert_array_equal(p.rows("b0"), [0, 1, 2])


def test_csv_round_trip_is_exact(tmp_path):
    p = points()
    path = write_monitor_points_csv(tmp_path / "points.csv", p, metadata={"scan": "v2"})
    back = read_monitor_points_csv(path)
    assert back.names == p.names and back.mount == p.mount
    for field in ("points", "beta", "height", "beam", "node", "weight"):
        np.testing.assert_array_equal(getattr(back, field), getattr(p, field))


def test_openfoam_output_read_back_in_row_order_with_not_found_as_nan(tmp_path):
    p = points()
    vals = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]])
    write_probes_output(tmp_path / "U", p, [(100, vals), (200, vals + 1)], unset=(1,))
    out = read_openfoam_probes(tmp_path / "U")
    got = out.values_for(p)  # the latest time
    np.testing.assert_array_equal(got[[0, 2]], vals[[0, 2]] + 1)
    assert np.all(np.isnan(got[1]))
    np.testing.assert_array_equal(out.values_for(p, time=100)[0], vals[0])
    assert "probeLocations" in write_openfoam_probes(tmp_path / "lidarProbes", p).read_text()


def test_values_csv_reads_names_and_nan(tmp_path):
    path = tmp_path / "v.csv"
    path.write_text("Name,u [m/s],v,w,extra\nb0_h10_beam0_q0,1,2,3,x\nb0_h10_beam1_q0,nan,,0,y\n")
    vals = read_monitor_values_csv(path)
    np.testing.assert_array_equal(vals["b0_h10_beam0_q0"], [1.0, 2.0, 3.0])
    assert np.isnan(vals["b0_h10_beam1_q0"][:2]).all() and vals["b0_h10_beam1_q0"][2] == 0
    path.write_text("name,u,v\n")
    with pytest.raises(ValueError, match="v.csv, line 1: header lacks w"):
        read_monitor_values_csv(path)


def _float32_points(p, points):
    return MonitorPoints(p.names, p.mount, points, p.beta, p.height, p.beam, p.node, p.weight)


@pytest.mark.parametrize("written", ["float32", "float64"])
def test_values_for_float32_points_on_either_side(tmp_path, written):
    """Probes written (at full precision) from float32 points match the float64 points they
    were rounded from, and float32 points match a float64 file: the check allows float32's
    rounding (up to 4e-7 m here), where the printed precision alone (1e-17 m) refused them."""
    p64 = _float32_points(points(), np.array([[0.1, -1 / 3, 10.7], [1.5, 2.2, 11.3], [-3.9, 0.0, 12.1]]))
    p32 = _float32_points(p64, p64.points.astype(np.float32))
    vals = np.arange(9.0).reshape(3, 3)
    write_probes_output(tmp_path / "U", p32 if written == "float32" else p64, [(1, vals)])
    out = read_openfoam_probes(tmp_path / "U")
    other = p64 if written == "float32" else p32
    gap = np.abs(out.header_points - np.asarray(other.points, np.float64))
    assert np.any(gap > 1.01 * out.header_resolution) and 1e-9 < np.max(gap) < 1e-6
    np.testing.assert_array_equal(out.values_for(other), vals)
    np.testing.assert_array_equal(out.values_for(p32 if written == "float32" else p64), vals)
    # a real misplacement is still refused, float32 or not
    off = _float32_points(other, np.asarray(other.points) + np.array([0.0, 1e-3, 0.0], other.points.dtype))
    with pytest.raises(ValueError, match="written for other probes"):
        out.values_for(off)


def test_values_for_float64_keeps_the_printed_precision(tmp_path):
    """A float64 file and float64 points: a float32-sized gap (1e-8 m) is still refused."""
    p = _float32_points(points(), np.array([[0.1, -1 / 3, 10.7], [1.5, 2.2, 11.3], [-3.9, 0.0, 12.1]]))
    write_probes_output(tmp_path / "U", p, [(1, np.zeros((3, 3)))])
    shifted = _float32_points(p, p.points + 1e-8)
    with pytest.raises(ValueError, match="written for other probes"):
        read_openfoam_probes(tmp_path / "U").values_for(shifted)
