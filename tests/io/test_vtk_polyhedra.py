"""The vectorised `.vtu` reader (lidarjax.io.vtk) against a straightforward per-cell reference,
on a real foamToVTK export with polyhedra (tests/data/vtk_poly: 673 cells of the v1912
`windAroundBuildings` mesh, 80 of them split-hex polyhedra, see its README)."""

import base64
import re

import numpy as np
import pytest
from scipy.spatial import cKDTree

from lidarjax.io.openfoam import read_openfoam_field
from lidarjax.io.vtk import _sorted_rows, _unique_rows, read_vtk_field

from ..helpers import DATA

VTU = DATA / "vtk_poly" / "windAroundBuildings_box.vtu"
CUT = DATA / "openfoam" / "windAroundBuildings_cut"

# the reference's own face tables (any orientation: it is checked geometrically)
_HEX = ((0, 1, 2, 3), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7))
_TETRA = ((0, 1, 2), (0, 1, 3), (1, 2, 3), (0, 2, 3))
_DTYPES = {"Float32": "<f4", "Float64": "<f8", "Int32": "<i4", "Int64": "<i8", "UInt8": "u1"}


def _raw_arrays(path):
    """Every DataArray of a foamToVTK `.vtu` (inline base64, UInt64 header, uncompressed),
    decoded by a regex and `base64` alone: `{(section, name): array}`."""
    text = path.read_text()
    out, section = {}, None
    for m in re.finditer(r"<(PointData|CellData|Points|Cells)>|<DataArray ([^>]*)>\s*([^<]*)</DataArray>",
                         text):
        if m.group(1):
            section = m.group(1)
            continue
        attrs = dict(re.findall(r"(\w+)='([^']*)'", m.group(2)))
        raw = base64.b64decode("".join(m.group(3).split()))
        n = int(np.frombuffer(raw[:8], "<u8")[0])
        a = np.frombuffer(raw[8: 8 + n], _DTYPES[attrs["type"]])
        nc = int(attrs.get("NumberOfComponents", 1))
        out[section, attrs.get("Name", "")] = a.reshape(-1, nc) if nc > 1 else a
    return out


def _reference_mesh(path):
    """Per cell, its faces in a Python loop; faces matched through a dict keyed by their sorted
    vertex ids. Returns `{key: [(cell, vertex tuple), ...]}`, points, cell/point U."""
    a = _raw_arrays(path)
    points = a["Points", "Points"].astype(np.float64)
    conn, offs, types = a["Cells", "connectivity"], a["Cells", "offsets"], a["Cells", "types"]
    stream = a.get(("Cells", "faces"))
    foffs = a.get(("Cells", "faceoffsets"))
    faces: dict[tuple, list] = {}
    start, fstart = 0, 0
    for c in range(types.size):
        nodes = [int(v) for v in conn[start: offs[c]]]
        start = int(offs[c])
        if types[c] == 12:
            cell_faces = [tuple(nodes[i] for i in f) for f in _HEX]
        elif types[c] == 10:
            cell_faces = [tuple(nodes[i] for i in f) for f in _TETRA]
        elif types[c] == 42:
            pos, cell_faces = fstart, []
            for _ in range(int(stream[pos])):
                n = int(stream[pos + 1])
                cell_faces.append(tuple(int(v) for v in stream[pos + 2: pos + 2 + n]))
                pos += 1 + n
            fstart = int(foffs[c])
        else:
            raise AssertionError(f"cell type {types[c]} not in this file")
        for f in cell_faces:
            faces.setdefault(tuple(sorted(f)), []).append((c, f))
    return faces, points, a["CellData", "U"], a["PointData", "U"]


def _same_cycle(a, b):
    """Whether the vertex lists are the same cycle, in either direction."""
    if sorted(a) != sorted(b):
        return False
    k = b.index(a[0])
    rot = b[k:] + b[:k]
    return list(a) == list(rot) or list(a) == [rot[0]] + list(rot[1:])[::-1]


@pytest.fixture(scope="module")
def box():
    return read_vtk_field(VTU)


def test_reader_equals_a_per_cell_reference(box):
    faces, points, cell_u, point_u = _reference_mesh(VTU)
    mesh = box.mesh
    assert mesh.n_cells == 673
    np.testing.assert_array_equal(mesh.points, points)
    np.testing.assert_array_equal(box.cell_values, cell_u.astype(np.float64))
    np.testing.assert_array_equal(box.point_values, point_u.astype(np.float64))
    assert mesh.n_faces == len(faces)
    assert mesh.n_internal == sum(len(v) == 2 for v in faces.values())
    by_cell = _faces_by_cell(faces, mesh.n_cells)
    per_cell = np.bincount(mesh.owner, minlength=mesh.n_cells) + np.bincount(mesh.neighbour,
                                                                             minlength=mesh.n_cells)
    np.testing.assert_array_equal(per_cell, [len(ff) for ff in by_cell])
    assert (per_cell > 6).sum() == 72  # of the 80 polyhedra, 72 have more than 6 faces
    vertex_mean = np.array([points[sorted({v for _, f in ff for v in f})].mean(0) for ff in by_cell]).tolist()
    xyz = points.tolist()
    fo, fl = mesh.face_offsets, mesh.face_labels
    for i in range(mesh.n_faces):
        f = [int(v) for v in fl[fo[i]: fo[i + 1]]]
        occ = faces[tuple(sorted(f))]
        cells = sorted(c for c, _ in occ)
        assert mesh.owner[i] == cells[0]
        if i < mesh.n_internal:
            assert len(cells) == 2 and mesh.neighbour[i] == cells[1]
        else:
            assert len(cells) == 1
        assert _same_cycle(f, list(next(g for c, g in occ if c == cells[0])))
        # oriented out of the owner (Newell normal against the owner's vertex mean)
        p = [xyz[v] for v in f]
        edges = list(zip(p, p[1:] + p[:1], strict=True))
        normal = [sum(a[1] * b[2] - a[2] * b[1] for a, b in edges),
                  sum(a[2] * b[0] - a[0] * b[2] for a, b in edges),
                  sum(a[0] * b[1] - a[1] * b[0] for a, b in edges)]
        out = [sum(q[k] for q in p) / len(p) - vertex_mean[cells[0]][k] for k in range(3)]
        assert sum(normal[k] * out[k] for k in range(3)) > 0
    # internal faces first, ordered by owner
    assert np.all(np.diff(mesh.owner[: mesh.n_internal]) >= 0)


def _faces_by_cell(faces, n_cells):
    out = [[] for _ in range(n_cells)]
    for occ in faces.values():
        for c, f in occ:
            out[c].append((c, f))
    return out


def test_polyhedra_match_the_openfoam_cells(box):
    """The same cells read from the OpenFOAM case the box was exported from: cell centres
    (primitiveMesh's, from the VTK faces) within the float32 rounding of foamToVTK's points,
    cell values exactly the float32 ones."""
    of = read_openfoam_field(CUT)
    s_v = box.sampler()
    near = of.cells_in_box(s_v.cell_lo.min(0) - 1.0, s_v.cell_hi.max(0) + 1.0)
    s_of = of.sampler(near)
    d, idx = cKDTree(s_of.cell_centre).query(s_v.cell_centre)
    assert d.max() < 2e-5  # metres; points near 100 m in float32
    assert np.unique(idx).size == box.mesh.n_cells
    np.testing.assert_array_equal(box.cell_values, of.cell_values[near[idx]].astype(np.float32))


@pytest.mark.parametrize("n_points", [40, 200_000, 3_000_000, 2**40])  # 11, 3, 2, 1 ids per int64
@pytest.mark.parametrize("rows", ["pairs", "repeats", "ties"])
def test_unique_rows_is_numpys_lexicographic_unique(n_points, rows):
    """Rows repeated in pairs (a valid mesh's faces), up to many times, or sharing their three
    smallest ids while differing beyond: always `np.unique(axis=0)`'s order and groups."""
    rng = np.random.default_rng(3)
    pad = rng.integers(0, min(n_points, 60 if rows == "ties" else 10**6), (4000, 6))
    pad[rng.random(4000) < 0.5, 4:] = -1
    if rows == "pairs":
        pad = rng.permutation(np.concatenate([pad[:2000], pad[:2000]]))
    else:
        pad[:2000] = pad[rng.integers(0, 2000, 2000)]
    sizes = (pad >= 0).sum(1)
    key = _sorted_rows(pad.T.copy(), sizes, n_points)  # column-major in and out
    table = np.sort(np.where(pad < 0, n_points, pad), axis=1)
    np.testing.assert_array_equal(key.T, table)
    order, group = _unique_rows(key, n_points)
    _, first, inverse = np.unique(table, axis=0, return_index=True, return_inverse=True)
    np.testing.assert_array_equal(group[np.argsort(order)], inverse.reshape(-1))
    np.testing.assert_array_equal(order[np.r_[True, group[1:] != group[:-1]]], first)
    np.testing.assert_array_equal(order, np.lexsort(table.T[::-1]))  # stable: row order in ties


def _ascii_vtu(path, faces_stream):
    """A unit hexahedron (x 0..1) beside a unit cube written as a VTK polyhedron (x 1..2)."""
    x = np.array([[i, j, k] for k in (0, 1) for j in (0, 1) for i in (0, 1, 2)], float)
    idx = {tuple(p): n for n, p in enumerate(x)}
    hexa = [idx[p] for p in [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1),
                              (0, 1, 1)]]
    cube = [idx[p] for p in [(1, 0, 0), (2, 0, 0), (2, 1, 0), (1, 1, 0), (1, 0, 1), (2, 0, 1), (2, 1, 1),
                              (1, 1, 1)]]
    u = np.column_stack([x[:, 0], 2 * x[:, 1], 3 * x[:, 2]])

    def arr(name, values, typ, nc=1):
        return (f"<DataArray type='{typ}' Name='{name}' NumberOfComponents='{nc}' format='ascii'>"
                f"{' '.join(str(v) for v in np.ravel(values))}</DataArray>")

    stream = faces_stream(cube)
    path.write_text(
        "<?xml version='1.0'?><VTKFile type='UnstructuredGrid' version='0.1' byte_order='LittleEndian'>"
        f"<UnstructuredGrid><Piece NumberOfPoints='{x.shape[0]}' NumberOfCells='2'>"
        f"<PointData>{arr('U', u, 'Float64', 3)}</PointData>"
        f"<Points>{arr('Points', x, 'Float64', 3)}</Points><Cells>"
        f"{arr('connectivity', hexa + cube, 'Int64')}{arr('offsets', [8, 16], 'Int64')}"
        f"{arr('types', [12, 42], 'UInt8')}{arr('faces', stream, 'Int64')}"
        f"{arr('faceoffsets', [-1, len(stream)], 'Int64')}</Cells></Piece></UnstructuredGrid></VTKFile>")
    return path


def _cube_faces(c):
    quads = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
    return [6] + [v for q in quads for v in [4] + [c[i] for i in q]]


def test_hexahedron_beside_polyhedron(tmp_path):
    f = read_vtk_field(_ascii_vtu(tmp_path / "two.vtu", _cube_faces))
    assert f.mesh.n_cells == 2 and f.mesh.n_faces == 11 and f.mesh.n_internal == 1
    assert f.mesh.owner[0] == 0 and f.mesh.neighbour[0] == 1
    shared = f.mesh.points[f.mesh.face_labels[: f.mesh.face_offsets[1]]]
    np.testing.assert_array_equal(shared[:, 0], 1.0)
    # cell values: the mean of each cell's point values (no cell data in the file)
    np.testing.assert_allclose(f.cell_values, [[0.5, 1.0, 1.5], [1.5, 1.0, 1.5]], atol=1e-15)


@pytest.mark.parametrize("cut", [1, 5, 20])
def test_truncated_polyhedron_stream_is_refused(tmp_path, cut):
    path = _ascii_vtu(tmp_path / "bad.vtu", lambda c: _cube_faces(c)[:-cut])
    with pytest.raises(ValueError, match="bad.vtu: the polyhedron face stream"):
        read_vtk_field(path)


@pytest.mark.parametrize("binary, compression", [(True, "zlib"), (True, None), (False, None)])
def test_other_encodings_read_the_same(tmp_path, binary, compression):
    """The foamToVTK hexahedra of tests/data/vtk_hole rewritten by meshio: zlib-compressed
    base64, plain base64 (UInt32 headers) and ascii give the same mesh and values."""
    import meshio
    src = DATA / "vtk_hole" / "hole_0" / "internal.vtu"
    ref = read_vtk_field(src)
    a = _raw_arrays(src)
    m = meshio.Mesh(a["Points", "Points"], [("hexahedron", a["Cells", "connectivity"].reshape(-1, 8))],
                    point_data={"U": a["PointData", "U"]}, cell_data={"U": [a["CellData", "U"]]})
    m.write(tmp_path / "h.vtu", binary=binary, compression=compression)
    got = read_vtk_field(tmp_path / "h.vtu")
    for name in ("points", "face_offsets", "face_labels", "owner", "neighbour"):
        np.testing.assert_array_equal(getattr(got.mesh, name), getattr(ref.mesh, name))
    np.testing.assert_array_equal(got.cell_values, ref.cell_values)
    np.testing.assert_array_equal(got.point_values, ref.point_values)
