"""Scattered data must not bridge solids; NetCDF names in any case; Fluent repeated columns."""

import numpy as np
import pytest

from lidarjax.io import read_field_arrays, resample_to_grid


def lattice(dx, dz, solid, top=16.0):
    x = np.arange(1.0, 31.0, dx)
    z = np.arange(0.5, top, dz)
    p = np.stack(np.meshgrid(x, x, z, indexing="ij"), -1).reshape(-1, 3)
    if solid:  # a 12 m x 12 m x 9 m building: no data inside
        p = p[~((p[:, 0] > 9) & (p[:, 0] < 21) & (p[:, 1] > 9) & (p[:, 1] < 21) & (p[:, 2] < 9))]
    return p


def linear(p):
    return np.stack([1 + 0.1 * p[:, 0] + 0.2 * p[:, 2], 0.3 * p[:, 1], 0.05 * p[:, 2]], -1)


def grid_points(a):
    return np.stack(np.meshgrid(a.x, a.y, a.z, indexing="ij"), -1).reshape(-1, 3)


def test_simplices_bridging_a_solid_are_masked_and_reported():
    p = lattice(2.0, 2.0, solid=True)
    a = resample_to_grid(p, linear(p), spacing=1.5)
    g = grid_points(a)
    v = a.velocity.reshape(-1, 3)
    ok = np.isfinite(v).all(axis=1)
    core = (g[:, 0] > 12) & (g[:, 0] < 18) & (g[:, 1] > 12) & (g[:, 1] < 18) & (g[:, 2] < 6)
    assert core.sum() > 20 and not ok[core].any()          # nothing inside the building
    np.testing.assert_allclose(v[ok], linear(g[ok]), atol=1e-12)   # exact elsewhere
    assert 0 < a.report.masked_fraction < 0.1 and "masked" in a.report.notes[0]
    bridged = resample_to_grid(p, linear(p), spacing=1.5, max_edge_factor=np.inf)
    assert np.isfinite(bridged.velocity.reshape(-1, 3)[core]).all()   # the old behaviour
    assert bridged.report.masked_fraction == 0


def test_stretched_cells_without_solids_are_kept():
    p = lattice(3.0, 0.3, solid=False, top=5.0)  # aspect ratio 10, as in ABL meshes
    a = resample_to_grid(p, linear(p), spacing=1.5)
    assert a.report.masked_fraction == 0 and a.report.outside_fraction < 0.2


def test_fluent_repeated_columns_are_tolerated(tmp_path):
    p = lattice(5.0, 5.0, solid=False)
    v = linear(p)
    lines = ["nodenumber, x-coordinate, y-coordinate, z-coordinate, x-velocity, y-velocity, "
             "z-velocity, x-coordinate"]
    lines += [f"{i}, {a[0]}, {a[1]}, {a[2]}, {b[0]}, {b[1]}, {b[2]}, {a[0]}"
              for i, (a, b) in enumerate(zip(p, v, strict=True))]
    (tmp_path / "f.csv").write_text("\n".join(lines) + "\n")
    a = read_field_arrays(tmp_path / "f.csv", spacing=5.0)
    ok = np.isfinite(a.velocity.reshape(-1, 3)).all(axis=1)
    np.testing.assert_allclose(a.velocity.reshape(-1, 3)[ok], linear(grid_points(a)[ok]), atol=1e-12)


def test_netcdf_names_in_any_case_and_missing_names_listed(tmp_path):
    import xarray as xr
    x, y, z = np.arange(4.0), np.arange(5.0), np.arange(3.0)
    vel = np.random.default_rng(1).random((3, 4, 5))  # stored (Z, X, Y)
    ds = xr.Dataset({n: (("Z", "X", "Y"), vel * (k + 1)) for k, n in enumerate("UVW")},
                    coords={"X": x, "Y": y, "Z": z})
    ds.to_netcdf(tmp_path / "f.nc")
    a = read_field_arrays(tmp_path / "f.nc")
    np.testing.assert_array_equal(a.velocity[..., 1], 2 * vel.transpose(1, 2, 0))
    ds.drop_vars("W").to_netcdf(tmp_path / "g.nc")
    with pytest.raises(ValueError, match=r"missing variables w.*found U, V, X, Y, Z"):
        read_field_arrays(tmp_path / "g.nc")


def test_two_to_one_refinement_is_kept():
    coarse = lattice(2.0, 2.0, solid=False, top=12.0)
    fine_axis = np.arange(10.5, 20.0, 1.0)
    fine = np.stack(np.meshgrid(fine_axis, fine_axis, np.arange(0.5, 6.0, 1.0), indexing="ij"), -1)
    fine = fine.reshape(-1, 3)
    box = (coarse[:, 0] > 10) & (coarse[:, 0] < 20) & (coarse[:, 1] > 10) & (coarse[:, 1] < 20) & (
        coarse[:, 2] < 6)
    p = np.concatenate([coarse[~box], fine])  # snappyHexMesh-like refinement level
    a = resample_to_grid(p, linear(p), spacing=1.5)
    assert a.report.masked_fraction == 0
