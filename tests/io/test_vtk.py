"""VTK unstructured grids (real foamToVTK output: .vtm + .vtu, legacy .vtk) sampled inside
their own cells with OpenFOAM's cellPoint ingredients."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

import lidarjax as lj
from lidarjax.io.openfoam import read_openfoam_field, sample_openfoam
from lidarjax.io.vtk import read_vtk_field

from ..helpers import DATA as TEST_DATA

DATA = TEST_DATA / "vtk_hole"
_spec = importlib.util.spec_from_file_location("make_case", DATA / "make_case.py")
make_case = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(make_case)


@pytest.fixture(scope="module")
def foam(tmp_path_factory):
    return read_openfoam_field(make_case.write(tmp_path_factory.mktemp("hole") / "hole"))


@pytest.fixture(scope="module")
def vtm():
    return read_vtk_field(DATA / "hole_0.vtm")


def test_vtu_reader_rebuilds_the_openfoam_mesh_and_ingredients(foam, vtm):
    assert vtm.mesh.n_cells == foam.mesh.n_cells == 9 * 9 * 8 - 36
    assert vtm.mesh.n_internal == foam.mesh.n_internal
    np.testing.assert_allclose(vtm.mesh.points, foam.mesh.points, atol=1e-6)  # foamToVTK: float32
    np.testing.assert_allclose(vtm.cell_values, foam.cell_values, atol=2e-6)
    s_v, s_f = vtm.sampler(), foam.sampler()
    np.testing.assert_allclose(s_v.cell_centre, s_f.cell_centre, atol=1e-6)
    # foamToVTK's point data is OpenFOAM's volPointInterpolation: the same as lidarjax's
    np.testing.assert_allclose(s_v.point_value, s_f.point_value, atol=2e-6)


def test_legacy_vtk_reads_the_same(vtm):
    import meshio  # noqa: F401  (the test extra brings it)
    leg = read_vtk_field(DATA / "hole_legacy.vtk")
    np.testing.assert_array_equal(leg.mesh.points, vtm.mesh.points)
    np.testing.assert_array_equal(leg.cell_values, vtm.cell_values)
    np.testing.assert_array_equal(leg.point_values, vtm.point_values)


def test_sampling_never_bridges_the_solid_and_matches_at_nodes(foam, vtm):
    rng = np.random.default_rng(0)
    q = np.array([8.0, 8.0, 7.0]) * rng.random((3000, 3))
    a, b = sample_openfoam(foam, q), sample_openfoam(vtm, q)
    assert np.array_equal(np.isnan(a).any(1), np.isnan(b).any(1))
    inside = (q[:, :2] > 2.5).all(1) & (q[:, :2] < 4.0).all(1) & (q[:, 2] < 2.25)
    assert inside.sum() > 10 and np.isnan(b[inside]).all()
    # at cell centres and mesh points the interpolant is the cell / point value itself
    s = vtm.sampler()
    np.testing.assert_allclose(sample_openfoam(vtm, s.cell_centre), s.cell_value, atol=1e-9)
    ok = np.isfinite(a).all(1)
    # inside a cell, OpenFOAM's tet decomposition starts at its own first face point, which
    # a VTK hexahedron does not keep: the two piecewise-linear interpolants differ there
    assert np.sqrt(np.mean((a[ok] - b[ok]) ** 2)) < 0.1


def test_load_field_vtm_with_region(vtm):
    field, report = lj.io.load_field(DATA / "hole_0.vtm", region=([0.5, 0.5, 0.25], [7.5, 7.5, 6.5]),
                                     spacing=0.5, return_report=True)
    assert report.format == "vtk" and report.n_cells == vtm.mesh.n_cells
    v = np.asarray(field.sample(np.array([[3.2, 3.2, 1.0], [1.0, 1.0, 4.0]])))
    assert np.isnan(v[0]).all() and np.isfinite(v[1]).all()


def test_missing_velocity_lists_arrays(tmp_path):
    text = (DATA / "hole_0" / "internal.vtu").read_text(errors="replace")
    (tmp_path / "x.vtu").write_text(text.replace("Name='U'", "Name='p'"))
    with pytest.raises(ValueError, match="no velocity array.*found p"):
        read_vtk_field(tmp_path / "x.vtu")


def test_legacy_polyhedra_walked_at_once_as_the_hexahedra():
    """A legacy file's polyhedra (meshio's ``polyhedronN`` blocks: a list of faces per cell)
    give the same faces, cells and sizes as the same cells given as hexahedra, in one pass
    over all faces (no numpy call per cell or face)."""
    import meshio

    from lidarjax.io.vtk import _FACES, _cell_faces

    ax = np.linspace(0.0, 3.0, 4)
    pts = np.stack(np.meshgrid(ax, ax, ax, indexing="ij"), axis=-1).reshape(-1, 3)
    idx = np.arange(pts.shape[0]).reshape(4, 4, 4)
    hexes = np.array([[idx[i, j, k], idx[i + 1, j, k], idx[i + 1, j + 1, k], idx[i, j + 1, k],
                       idx[i, j, k + 1], idx[i + 1, j, k + 1], idx[i + 1, j + 1, k + 1],
                       idx[i, j + 1, k + 1]] for i in range(3) for j in range(3) for k in range(3)])
    poly = [[h[list(f)] for f in _FACES["hexahedron"]] for h in hexes]
    a = _cell_faces(meshio.Mesh(pts, [("polyhedron8", poly)]), Path("poly.vtk"))
    b = _cell_faces(meshio.Mesh(pts, [("hexahedron", hexes)]), Path("hex.vtk"))
    order_a = np.lexsort((np.arange(a[1].size), a[1]))  # faces cell by cell in both
    order_b = np.lexsort((np.arange(b[1].size), b[1]))
    np.testing.assert_array_equal(a[0][:, order_a], b[0][:, order_b])
    np.testing.assert_array_equal(a[1][order_a], b[1][order_b])
    np.testing.assert_array_equal(a[2][order_a], b[2][order_b])
    assert a[3] == b[3] == 27
