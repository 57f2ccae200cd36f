"""Velocity-field files: npz and NetCDF round trips, Fluent ASCII resampling, errors."""

import os
import sys

import numpy as np
import pytest

import lidarjax
from lidarjax.io import (
    FieldArrays,
    load_field,
    read_field_arrays,
    read_fluent_points,
    resample_to_grid,
    save_field_netcdf,
    save_field_npz,
)

OFFSET = np.array([500_000.0, 6_000_000.0, 10.0])  # UTM-sized CFD coordinates
SEMI_AXES = np.array([1.0, 0.8, 0.6])  # octahedron |x|/1 + |y|/0.8 + |z|/0.6 <= 1


def linear_field(p):
    """An analytic linear velocity field (m/s) of absolute points (..., 3) in metres."""
    x, y, z = np.moveaxis(np.asarray(p) - OFFSET, -1, 0)
    return np.stack([1.0 + 2.0 * x - 3.0 * y + 0.5 * z,
                     -2.0 + 0.1 * x + y - z,
                     0.3 - x + 4.0 * z], axis=-1)


def octahedron_points(n_inside=300, seed=0):
    """The octahedron's 6 vertices plus points strictly inside: its hull is known exactly."""
    rng = np.random.default_rng(seed)
    verts = np.concatenate([np.diag(SEMI_AXES), -np.diag(SEMI_AXES)])
    cand = rng.uniform(-1.0, 1.0, size=(12 * n_inside, 3)) * SEMI_AXES
    inside = cand[np.sum(np.abs(cand) / SEMI_AXES, axis=1) < 0.98][:n_inside]
    return np.concatenate([verts, inside]) + OFFSET


FLUENT_ORDER = ["nodenumber", "z-coordinate", "x-velocity", "x-coordinate", "pressure",
                "y-coordinate", "z-velocity", "y-velocity"]


def fluent_text(points, values, *, sep=", ", fmt=repr, bad=None):
    cols = {"x-coordinate": points[:, 0], "y-coordinate": points[:, 1],
            "z-coordinate": points[:, 2], "x-velocity": values[:, 0], "y-velocity": values[:, 1],
            "z-velocity": values[:, 2], "pressure": np.full(len(points), 101325.0)}
    lines = [sep.join(f"{name:>16}" for name in FLUENT_ORDER)]
    for i in range(len(points)):
        cells = [str(i + 1)] + [fmt(float(cols[name][i])) for name in FLUENT_ORDER[1:]]
        if bad is not None and bad[0] == i:
            cells[FLUENT_ORDER.index(bad[1])] = bad[2]
        lines.append(sep.join(cells))
    return "\n".join(lines) + "\n"


@pytest.fixture
def fluent_file(tmp_path):
    pts = octahedron_points()
    path = tmp_path / "export.csv"
    path.write_text(fluent_text(pts, linear_field(pts)))
    return path


def test_fluent_resampling_reproduces_linear_field(fluent_file):
    shape = (12, 10, 8)
    # a uniformly random cloud is far more irregular than CFD nodes: keep every simplex here
    # (masking simplices that bridge solids is tested in test_io_scattered_netcdf.py)
    arrays = read_field_arrays(fluent_file, shape=shape, max_edge_factor=np.inf)
    x, y, z, vel = arrays  # unpacks as the GridField arguments
    assert vel.shape == (*shape, 3)
    np.testing.assert_allclose(x, np.linspace(-1.0, 1.0, 12) + OFFSET[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(z, np.linspace(-0.6, 0.6, 8) + OFFSET[2], rtol=0, atol=1e-12)
    nodes = np.stack(np.meshgrid(x, y, z, indexing="ij"), axis=-1)
    g = np.sum(np.abs(nodes - OFFSET) / SEMI_AXES, axis=-1)
    assert np.min(np.abs(g - 1.0)) > 1e-3  # no node near the hull surface: the test is sharp
    inside = g < 1.0
    assert 0 < inside.sum() < inside.size
    np.testing.assert_allclose(vel[inside], linear_field(nodes[inside]), rtol=0, atol=1e-10)
    assert np.all(np.isnan(vel[~inside]))
    report = arrays.report
    assert report.format == "fluent" and report.path == str(fluent_file)
    assert report.shape == shape and report.n_points == 306
    assert report.outside_fraction == pytest.approx(1.0 - inside.mean(), abs=0)
    assert report.nan_fraction == report.outside_fraction


def test_fluent_whitespace_exponent_format_and_chunks(tmp_path, fluent_file):
    pts = octahedron_points(seed=3)
    vals = linear_field(pts)
    path = tmp_path / "export.txt"
    path.write_text(fluent_text(pts, vals, sep="   ", fmt=lambda v: f"{v:.17E}"))
    p1, v1 = read_fluent_points(path)
    p7, v7 = read_fluent_points(path, chunk_rows=7)
    np.testing.assert_array_equal(p1, pts)
    np.testing.assert_array_equal(v1, vals)
    np.testing.assert_array_equal(p7, p1)
    np.testing.assert_array_equal(v7, v1)
    a = read_field_arrays(path, shape=(5, 5, 5), progress=True)
    b = read_field_arrays(path, shape=(5, 5, 5), format="fluent", chunk_rows=13)
    np.testing.assert_array_equal(a.velocity, b.velocity)


def test_default_grid_and_spacing(fluent_file):
    a = read_field_arrays(fluent_file)
    assert a.report.shape == (7, 7, 7)  # round(cbrt(306))
    b = read_field_arrays(fluent_file, spacing=0.25)
    np.testing.assert_allclose(b.x - OFFSET[0], -1.0 + 0.25 * np.arange(9), atol=1e-9)
    np.testing.assert_allclose(b.y - OFFSET[1], -0.8 + 0.25 * np.arange(7), atol=1e-9)
    np.testing.assert_allclose(b.z - OFFSET[2], -0.6 + 0.25 * np.arange(5), atol=1e-12)
    c = read_field_arrays(fluent_file, spacing=(0.5, 0.4, 0.3))
    assert c.report.shape == (5, 5, 5)
    with pytest.raises(ValueError, match="give either spacing or shape, not both"):
        read_field_arrays(fluent_file, spacing=0.5, shape=(3, 3, 3))
    with pytest.raises(ValueError, match="spacing 2 m exceeds the data extent 1.6 m along y"):
        read_field_arrays(fluent_file, spacing=2.0)
    with pytest.raises(ValueError, match=r"shape must be 3 integers >= 2"):
        read_field_arrays(fluent_file, shape=(3, 1, 3))
    with pytest.raises(ValueError, match="spacing must be positive metres"):
        read_field_arrays(fluent_file, spacing=-1.0)


def test_load_field_gives_grid_field(fluent_file):
    field, report = load_field(fluent_file, shape=(12, 10, 8), return_report=True)
    assert isinstance(field, lidarjax.GridField)
    assert field.shape == (12, 10, 8) and report.outside_fraction > 0
    np.testing.assert_array_equal(np.asarray(field.velocity),
                                  read_field_arrays(fluent_file, shape=(12, 10, 8)).velocity)
    # one call, two points: inside the hull (trilinear of a linear field is exact) and outside
    pts = OFFSET + np.array([[0.01, -0.02, 0.03], [0.95, 0.7, 0.5]])
    got = np.asarray(field.sample(pts))
    np.testing.assert_allclose(got[0], linear_field(pts[0]), rtol=0, atol=1e-9)
    assert np.all(np.isnan(got[1]))


def test_fluent_errors(tmp_path):
    pts = octahedron_points(n_inside=30)
    path = tmp_path / "bad.csv"
    path.write_text(fluent_text(pts, linear_field(pts), bad=(18, "y-velocity", "abc")))
    with pytest.raises(ValueError, match=rf"^{path}, line 20: column 'y-velocity': expected a "
                                         "number, found 'abc'"):
        read_fluent_points(path, chunk_rows=7)
    text = fluent_text(pts, linear_field(pts)).splitlines()
    text[5] = ", ".join(text[5].split(", ")[:4])
    path.write_text("\n".join(text) + "\n")
    with pytest.raises(ValueError, match=r"line 6: expected at least 8 fields, found 4"):
        read_fluent_points(path)
    path.write_text("nodenumber, x-coordinate, y-coordinate, x-velocity, y-velocity\n"
                    "1, 2, 3, 4, 5\n")
    with pytest.raises(ValueError, match=r"line 1: header lacks z-coordinate, z-velocity; expected "
                                         r"a Fluent ASCII export"):
        read_fluent_points(path)
    path.write_text("x-coordinate y-coordinate z-coordinate x-velocity y-velocity z-velocity\n")
    with pytest.raises(ValueError, match=rf"^{path}: no data rows after the header"):
        read_fluent_points(path)
    path.write_text("\n\n")
    with pytest.raises(ValueError, match="empty file"):
        read_fluent_points(path)
    with pytest.raises(FileNotFoundError, match="field file not found: .*absent.csv"):
        read_field_arrays(tmp_path / "absent.csv")


def test_degenerate_point_sets():
    rng = np.random.default_rng(2)
    flat = rng.uniform(size=(20, 3))
    flat[:, 2] = 5.0
    with pytest.raises(ValueError, match="no extent along z"):
        resample_to_grid(flat, flat)
    plane = rng.uniform(size=(20, 3))
    plane[:, 2] = plane[:, 0] + plane[:, 1]  # spans a box, but all in one plane
    with pytest.raises(ValueError, match="cannot triangulate the points"):
        resample_to_grid(plane, plane, shape=(3, 3, 3))
    with pytest.raises(ValueError, match="need at least 4 scattered points"):
        resample_to_grid(plane[:3], plane[:3])
    with pytest.raises(ValueError, match=r"shape \(n, 3\)"):
        resample_to_grid(plane, plane[:, :2])


def gridded(nx=4, ny=3, nz=5):
    x = np.linspace(0.0, 30.0, nx) + 1000.0
    y = np.array([-5.0, 0.0, 7.5])[:ny]
    z = np.geomspace(1.0, 100.0, nz)
    vel = linear_field(np.stack(np.meshgrid(x, y, z, indexing="ij"), axis=-1) + OFFSET)
    vel[1, 1, 0] = np.nan  # a solid node
    return x, y, z, vel


def test_npz_round_trip(tmp_path):
    x, y, z, vel = gridded()
    path = save_field_npz(tmp_path / "f.npz", (x, y, z, vel))
    with np.load(path) as data:
        assert sorted(data.files) == ["u", "v", "w", "x", "y", "z"]
        assert data["u"].shape == (4, 3, 5)
    a = read_field_arrays(path)
    assert isinstance(a, FieldArrays)
    for got, want in zip(a, (x, y, z, vel), strict=True):
        np.testing.assert_array_equal(got, want)
    assert a.report.format == "npz" and a.report.shape == (4, 3, 5)
    assert a.report.outside_fraction == 0.0 and a.report.nan_fraction == 1 / 60
    assert os.listdir(tmp_path) == ["f.npz"]
    field = load_field(path)
    assert isinstance(field, lidarjax.GridField)
    # GridField -> npz -> arrays is exact
    again = read_field_arrays(save_field_npz(tmp_path / "g.npz", field))
    np.testing.assert_array_equal(again.x, x)
    np.testing.assert_array_equal(again.z, z)
    np.testing.assert_array_equal(again.velocity, vel)


def test_npz_velocity_array_and_format_override(tmp_path):
    x, y, z, vel = gridded()
    path = tmp_path / "field.bin"
    with open(path, "wb") as fh:
        np.savez(fh, x=x, y=y, z=z, velocity=vel)
    a = read_field_arrays(path, format="npz")
    np.testing.assert_array_equal(a.velocity, vel)
    with pytest.raises(ValueError, match="format must be 'npz', 'netcdf' or 'fluent'"):
        read_field_arrays(path, format="stl")
    with pytest.raises(ValueError, match="spacing and shape apply to scattered Fluent exports"):
        read_field_arrays(path, format="npz", spacing=1.0)


def test_npz_errors(tmp_path):
    x, y, z, vel = gridded()
    path = tmp_path / "bad.npz"
    np.savez(path, x=x, y=y, u=vel[..., 0], v=vel[..., 1])
    with pytest.raises(ValueError, match=rf"^{path}: missing arrays z, w; expected x, y, z and "
                                         r"u, v, w \(or velocity\), found u, v, x, y"):
        read_field_arrays(path)
    np.savez(path, x=x[::-1], y=y, z=z, u=vel[..., 0], v=vel[..., 1], w=vel[..., 2])
    with pytest.raises(ValueError, match=r"x must be strictly increasing; x\[0\] = 1030.0 >= "
                                         r"x\[1\] = 1020.0"):
        read_field_arrays(path)
    np.savez(path, x=x, y=y, z=z, u=vel[..., 0], v=vel[..., 1], w=vel[:, :, :2, 2])
    with pytest.raises(ValueError, match=r"u, v, w must have the same shape"):
        read_field_arrays(path)
    np.savez(path, x=x, y=y, z=z[:2], u=vel[..., 0], v=vel[..., 1], w=vel[..., 2])
    with pytest.raises(ValueError, match=r"velocity must have shape \(nx, ny, nz, 3\) = "
                                         r"\(4, 3, 2, 3\), got \(4, 3, 5, 3\)"):
        read_field_arrays(path)
    path.write_text("not a zip")
    with pytest.raises(ValueError, match="not a readable .npz archive"):
        read_field_arrays(path)
    with pytest.raises(ValueError, match="y must be 1-D with at least 2 nodes"):
        save_field_npz(tmp_path / "x.npz", (x, y[:1], z, vel[:, :1]))
    assert not (tmp_path / "x.npz").exists()


def test_netcdf_needs_xarray(tmp_path, monkeypatch):
    x, y, z, vel = gridded()
    monkeypatch.setitem(sys.modules, "xarray", None)
    with pytest.raises(ImportError, match=r"pip install lidarjax\[netcdf\]"):
        save_field_netcdf(tmp_path / "f.nc", (x, y, z, vel))
    path = tmp_path / "f.nc"
    path.write_bytes(b"CDF\x01")
    with pytest.raises(ImportError, match=r"Reading NetCDF fields needs the optional package "
                                          r"'xarray'.*pip install lidarjax\[netcdf\]"):
        read_field_arrays(path)


def test_netcdf_round_trip_and_dimension_order(tmp_path):
    import xarray as xr
    x, y, z, vel = gridded()
    path = save_field_netcdf(tmp_path / "f.nc", (x, y, z, vel), {"source": "test"})
    a = read_field_arrays(path)
    assert a.report.format == "netcdf"
    for got, want in zip(a, (x, y, z, vel), strict=True):
        np.testing.assert_array_equal(got, want)
    # a file written with (z, y, x) dimension order reads the same
    ds = xr.Dataset({n: (("z", "y", "x"), vel[..., i].transpose(2, 1, 0))
                     for i, n in enumerate("uvw")}, coords={"x": x, "y": y, "z": z})
    other = tmp_path / "zyx.nc"
    ds.to_netcdf(other, engine="scipy")
    np.testing.assert_array_equal(read_field_arrays(other).velocity, vel)
    ds.drop_vars("w").to_netcdf(tmp_path / "now.nc", engine="scipy")
    with pytest.raises(ValueError, match="missing variables w; expected u, v, w on coordinates"):
        read_field_arrays(tmp_path / "now.nc")
