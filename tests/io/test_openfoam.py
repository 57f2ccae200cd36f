"""OpenFOAM case reading and cellPoint sampling.

Tiny hand-made cases (ASCII, binary, gzip; hexes, a polyhedral cell, a solid block) check the
reader and the interpolation; the committed cut of the v1912 `turbineSiting` tutorial checks
agreement with OpenFOAM's own `probes` function object (`interpolationScheme cellPoint`).
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pytest

import lidarjax as lj
from lidarjax.frames import lidar_to_cfd_rotation, rotate
from lidarjax.io import _cells
from lidarjax.io.openfoam import (
    openfoam_times,
    read_openfoam_field,
    resample_openfoam,
    sample_openfoam,
)

from .._foamwrite import hex_mesh, write_polymesh, write_vector_field
from ..helpers import DATA as TEST_DATA

DATA = TEST_DATA / "openfoam"
CUT = DATA / "turbineSiting_cut"
CUT_ASCII = DATA / "turbineSiting_cut_ascii"

A = np.array([[0.3, -0.2, 0.1], [0.05, 0.4, -0.3], [0.2, 0.1, 0.25]])
B = np.array([10.0, -2.0, 0.5])


def linear(p):
    return np.asarray(p) @ A.T + B


def _face_centres(m):
    mesh = _cells.PolyMesh(m["points"], m["face_offsets"], m["face_labels"], m["owner"], m["neighbour"],
                           int(m["owner"].max()) + 1, tuple(m["patches"]))
    return _cells.face_geometry(mesh, np.arange(mesh.n_faces))[0]


def write_case(root: Path, m: dict, values, *, binary=False, compress=False, time="100", uniform=False):
    write_polymesh(root, m["points"], m["face_offsets"], m["face_labels"], m["owner"], m["neighbour"],
                   m["patches"], binary=binary, compress=compress)
    fc = _face_centres(m)
    bnd = {}
    for name, _t, start, n in m["patches"]:
        bnd[name] = ("fixedValue", linear(fc[start:start + n]) if not uniform else values[0])
    write_vector_field(root, time, "U", values, bnd, binary=binary, compress=compress, uniform=uniform)
    (root / "system").mkdir(exist_ok=True)
    return root


@pytest.fixture(scope="module")
def cube(tmp_path_factory):
    """A 4x4x4 uniform hex case with a linear field, in ASCII, binary and gzipped ASCII."""
    ax = np.linspace(0.0, 8.0, 5)
    m = hex_mesh(ax, ax + 100.0, ax * 0.5 + 50.0)
    vals = linear(m["cell_centres"])
    root = tmp_path_factory.mktemp("cube")
    return {
        "mesh": m,
        "ascii": write_case(root / "ascii", m, vals),
        "binary": write_case(root / "binary", m, vals, binary=True),
        "gz": write_case(root / "gz", m, vals, compress=True),
    }


def test_reader_ascii_binary_gzip_agree(cube):
    m = cube["mesh"]
    fields = [read_openfoam_field(cube[k]) for k in ("ascii", "binary", "gz")]
    for f in fields:
        assert f.time == "100" and f.mesh.n_cells == 64
        np.testing.assert_array_equal(f.mesh.owner, m["owner"])
        np.testing.assert_array_equal(f.mesh.neighbour, m["neighbour"])
        np.testing.assert_array_equal(f.mesh.face_labels, m["face_labels"])
        np.testing.assert_allclose(f.mesh.points, m["points"], rtol=0, atol=0)
        np.testing.assert_allclose(f.cell_values, linear(m["cell_centres"]), rtol=1e-15)
        assert [p[0] for p in f.mesh.patches] == ["walls", "xmin", "xmax", "ymin", "ymax", "zmin", "zmax"]


def test_cell_centres_match_geometry(cube):
    f = read_openfoam_field(cube["binary"])
    s = f.sampler()
    np.testing.assert_allclose(np.sort(s.cell_centre, axis=0), np.sort(cube["mesh"]["cell_centres"], axis=0),
                               atol=1e-12)


def test_cellpoint_exact_for_linear_field_inside(cube):
    """Interior points (one cell from the boundary) of a uniform mesh: point values are exact
    (symmetric inverse-distance stencils), hence cellPoint reproduces a linear field."""
    rng = np.random.default_rng(1)
    lo = np.array([2.0, 102.0, 51.0])
    hi = np.array([6.0, 106.0, 53.0])
    q = lo + (hi - lo) * rng.random((300, 3))
    for key in ("ascii", "binary"):
        got = sample_openfoam(cube[key], q)
        np.testing.assert_allclose(got, linear(q), rtol=0, atol=1e-11)


def test_grid_resampling_of_linear_field(cube):
    f = read_openfoam_field(cube["binary"])
    axes, vel, info = resample_openfoam(f, ([2.0, 102.0, 51.0], [6.0, 106.0, 53.0]))
    assert info["grid"] == "graded" and info["spacing_max"][0] <= 1.0 + 1e-9  # 2 nodes per 2 m cell
    g = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    inner = (g[..., 0] >= 2) & (g[..., 0] <= 6) & (g[..., 1] >= 102) & (g[..., 1] <= 106) \
        & (g[..., 2] >= 51) & (g[..., 2] <= 53)
    np.testing.assert_allclose(vel[inner], linear(g[inner]), atol=1e-11)
    assert info["resample_error_max"] < 1e-10


def test_uniform_internal_field(tmp_path):
    ax = np.linspace(0.0, 2.0, 3)
    m = hex_mesh(ax, ax, ax)
    v = np.tile([4.0, 1.0, -0.5], (8, 1))
    root = write_case(tmp_path / "u", m, v, uniform=True)
    f = read_openfoam_field(root)
    np.testing.assert_array_equal(f.cell_values, v)
    got = sample_openfoam(f, [[0.3, 0.7, 1.2], [1.9, 0.1, 0.5]])
    np.testing.assert_allclose(got, v[:2], atol=1e-13)  # uniform walls too: exact everywhere
    assert "uniform (4.0 1.0 -0.5)" in (root / "100" / "U").read_text()


def test_polyhedral_cell(tmp_path):
    """Merge the two left cells of a 2x2x1 mesh into one 10-face polyhedron whose bottom and
    top faces are hexagons; the reader (ASCII faceList with mixed sizes, and binary) and the
    cellPoint interpolant handle it; the cell centre is the volume centroid."""
    m = hex_mesh(np.array([0.0, 1.0, 2.0]), np.array([0.0, 0.5, 1.0]), np.array([0.0, 1.0]))
    own, nei = m["owner"].copy(), m["neighbour"].copy()
    # cells: 0 (i0 j0), 1 (i1 j0), 2 (i0 j1), 3 (i1 j1): merge 2 into 0, renumber 3 -> 2
    ren = np.array([0, 1, 0, 2])
    own, nei = ren[own], ren[nei]
    offs, labs = m["face_offsets"], m["face_labels"]
    faces = [list(labs[offs[f]:offs[f + 1]]) for f in range(own.size)]
    keep_int = [f for f in range(nei.size) if own[f] != nei[f]]
    bfaces = list(range(nei.size, own.size))
    pts = m["points"]
    # bottom (zmin) and top (zmax) faces of the merged cell: join the two quads into hexagons
    new_faces, new_own, new_kind = [], [], []
    patch_of = {}
    for name, _t, start, n in m["patches"]:
        for f in range(start, start + n):
            patch_of[f] = name
    merged = {}
    for f in bfaces:
        if own[f] == 0 and patch_of[f] in ("zmin", "zmax"):
            merged.setdefault(patch_of[f], []).append(f)
            continue
        new_faces.append(faces[f])
        new_own.append(own[f])
        new_kind.append(patch_of[f])
    for name, fl in merged.items():
        ring = [p for f in fl for p in faces[f]]
        uniq = list(dict.fromkeys(ring))
        c = pts[uniq].mean(axis=0)
        ang = np.arctan2(pts[uniq, 1] - c[1], pts[uniq, 0] - c[0])
        order = [uniq[i] for i in np.argsort(ang)]  # anticlockwise seen from +z
        if name == "zmin":
            order = order[::-1]  # normal -z (out of the cell)
        new_faces.append(order)
        new_own.append(0)
        new_kind.append(name)
    names = [p[0] for p in m["patches"]]
    order_b = sorted(range(len(new_faces)), key=lambda i: (names.index(new_kind[i]), new_own[i]))
    all_faces = [faces[f] for f in keep_int] + [new_faces[i] for i in order_b]
    owner = np.array([own[f] for f in keep_int] + [new_own[i] for i in order_b])
    neighbour = np.array([nei[f] for f in keep_int])
    patches, start = [], len(keep_int)
    for name, t, _s, _n in m["patches"]:
        cnt = sum(1 for i in order_b if new_kind[i] == name)
        patches.append((name, t, start, cnt))
        start += cnt
    offsets = np.concatenate([[0], np.cumsum([len(f) for f in all_faces])])
    labels = np.concatenate(all_faces)
    centres = np.array([[0.5, 0.5, 0.5], [1.5, 0.25, 0.5], [1.5, 0.75, 0.5]])
    mm = {"points": pts, "face_offsets": offsets, "face_labels": labels, "owner": owner,
          "neighbour": neighbour, "patches": patches}
    for binary in (False, True):
        root = write_case(tmp_path / f"poly{binary}", mm, linear(centres), binary=binary)
        f = read_openfoam_field(root)
        sizes = np.diff(f.mesh.face_offsets)
        assert sorted(set(sizes.tolist())) == [4, 6]
        s = f.sampler()
        np.testing.assert_allclose(s.cell_centre, centres, atol=1e-14)
        # inside the polyhedron, on its centre: the cell value
        np.testing.assert_allclose(s.sample_points(np.array([[0.5, 0.5, 0.5]])), linear([[0.5, 0.5, 0.5]]),
                                   atol=1e-12)
        # everywhere inside the domain: finite, continuous, bounded by the data
        q = np.random.default_rng(0).random((200, 3)) * [2, 1, 1]
        v = s.sample_points(q)
        assert np.isfinite(v).all()
        ref = linear(q)
        assert np.abs(v - ref).max() < 0.5  # boundary inverse-distance weights are not exact


def test_solid_block_is_nan_and_not_bridged(tmp_path):
    ax = np.linspace(0.0, 6.0, 7)
    solid = np.zeros((6, 6, 6), bool)
    solid[2:4, 2:4, 0:3] = True  # a building 2 x 2 x 3 cells on the ground
    m = hex_mesh(ax, ax, ax, solid)
    cc = m["cell_centres"]
    vals = linear(cc)
    root = write_case(tmp_path / "hole", m, vals, binary=True)
    f = read_openfoam_field(root)
    assert f.mesh.n_cells == 216 - 12
    axes, vel, info = resample_openfoam(f, ([0.0, 0.0, 0.0], [6.0, 6.0, 6.0]), spacing=0.25)
    g = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    strictly_inside = ((g[..., 0] > 2 + 1e-9) & (g[..., 0] < 4 - 1e-9) & (g[..., 1] > 2 + 1e-9)
                       & (g[..., 1] < 4 - 1e-9) & (g[..., 2] < 3 - 1e-9))
    assert np.isnan(vel[strictly_inside]).all()
    assert np.isfinite(vel[~strictly_inside]).all()
    # on the wall faces, the value is the wall's (the boundary face values), not a bridge
    q = np.array([[3.0, 3.0, 3.0], [2.0, 3.0, 1.5]])
    np.testing.assert_allclose(sample_openfoam(f, q), linear(q), atol=0.35)
    assert np.isnan(sample_openfoam(f, [[3.0, 3.0, 1.0]])).all()
    # and as a GridField: beams through the block are NaN
    field = lj.io.load_field(root, region=([0.5, 0.5, 0.5], [5.5, 5.5, 5.5]), spacing=0.25)
    v = np.asarray(field.sample(np.array([[3.0, 3.0, 1.5], [1.0, 1.0, 4.0]])))
    assert np.isnan(v[0]).all() and np.isfinite(v[1]).all()


def test_numpy_and_numba_grid_paths_agree(cube):
    import numba  # noqa: F401  (the test extra brings it)
    f = read_openfoam_field(cube["ascii"])
    s = f.sampler()
    axes = [np.linspace(0.1, 7.9, 9), np.linspace(100.1, 107.9, 8), np.linspace(50.1, 53.9, 7)]
    a, _ = s.sample_grid(axes, use_numba=True)
    b, _ = s.sample_grid(axes, use_numba=False)
    np.testing.assert_allclose(a, b, atol=1e-13)


# ---------------------------------------------------------------- errors


def test_errors(tmp_path, cube):
    with pytest.raises(FileNotFoundError, match="not found"):
        read_openfoam_field(tmp_path / "nope")
    bad = tmp_path / "notacase"
    bad.mkdir()
    with pytest.raises(ValueError, match="constant/polyMesh"):
        read_openfoam_field(bad)
    # no time directory
    c = tmp_path / "notime"
    shutil.copytree(cube["ascii"], c)
    shutil.rmtree(c / "100")
    with pytest.raises(ValueError, match="no time directories"):
        read_openfoam_field(c)
    # a time directory without U
    (c / "5").mkdir()
    (c / "5" / "p").write_text("x")
    with pytest.raises(ValueError, match="no time directory holds the field 'U'.*5"):
        read_openfoam_field(c)
    with pytest.raises(ValueError, match="no time 7"):
        read_openfoam_field(cube["ascii"], time=7)
    assert openfoam_times(cube["ascii"]) == ["100"]
    # a corrupt ASCII list names the file and line
    c2 = tmp_path / "corrupt"
    shutil.copytree(cube["ascii"], c2)
    pts = c2 / "constant" / "polyMesh" / "points"
    lines = pts.read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if line.startswith("(") and " " in line)
    lines[k + 3] = "(1.0 abc 2.0)"
    pts.write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match=rf"points, line {k + 4}: point list: expected a number, found 'abc'"):
        read_openfoam_field(c2)
    # a truncated binary list
    c3 = tmp_path / "trunc"
    shutil.copytree(cube["binary"], c3)
    own = c3 / "constant" / "polyMesh" / "owner"
    own.write_bytes(own.read_bytes()[:-60])
    with pytest.raises(ValueError, match=r"owner, line \d+: binary list .* truncated"):
        read_openfoam_field(c3)
    # decomposed case
    c4 = tmp_path / "decomposed"
    (c4 / "processor0" / "constant" / "polyMesh").mkdir(parents=True)
    with pytest.raises(ValueError, match="reconstructPar"):
        read_openfoam_field(c4)
    # region outside the mesh
    with pytest.raises(ValueError, match="outside the mesh"):
        lj.io.load_field(cube["ascii"], region=([1e6, 0, 0], [1e6 + 1, 1, 1]))


# ---------------------------------------------------------------- OpenFOAM's own probes


def _probes():
    rows = np.loadtxt(DATA / "turbineSiting_points.csv", delimiter=",", skiprows=1, usecols=(1, 2, 3, 4, 5))
    names = np.loadtxt(DATA / "turbineSiting_points.csv", delimiter=",", skiprows=1, usecols=(0,), dtype=str)
    last = (CUT / "postProcessing" / "probes" / "168" / "U").read_text().splitlines()[-1]
    ref = np.array([[float(v) for v in g.split()] for g in re.findall(r"\(([^)]*)\)", last)])
    return rows, names, ref


@pytest.fixture(scope="module")
def cut_case():
    return read_openfoam_field(CUT)


def test_matches_openfoam_probes_pointwise(cut_case):
    """OpenFOAM v1912 `probes` (cellPoint) at 480 Windcube V2 beam points near a turbine disc
    and on a hill: lidarjax's cellPoint gives the same values to OpenFOAM's 12 written digits."""
    rows, _names, ref = _probes()
    got = sample_openfoam(cut_case, rows[:, 2:])
    assert np.isfinite(got).all()
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-8)


def test_ascii_gz_case_matches_binary():
    """The same case converted by foamFormatConvert to ASCII (12 digits) and gzip."""
    rows, _names, ref = _probes()
    f = read_openfoam_field(CUT_ASCII)
    assert f.time == "168"
    got = sample_openfoam(f, rows[:, 2:])
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-5)  # 12-digit UTM coordinates


def test_windcube_los_against_openfoam_probes(cut_case):
    """Target: LOS within 0.02 m/s rms and 0.1 m/s max of OpenFOAM's probes (10 m/s inflow)
    for a lidar 20 m behind a turbine disc (beams through it) and one on a hill, through
    load_field(region=scan_bounds) -> GridField -> simulate."""
    rows, names, ref = _probes()
    scan = lj.windcube_v2()
    for lidar in ("disc", "hill"):
        sel = names == lidar
        r, rr = rows[sel], ref[sel]
        # the disc's region holds the finest cells (0.47 m): fewer heights keep the grid small
        keep = (r[:, 1] >= 40.0) & (r[:, 1] <= 120.0) if lidar == "disc" else r[:, 1] >= 12.0
        r, rr = r[keep], rr[keep]
        heights = np.unique(r[:, 1])
        v = r[r[:, 0] == 4][0]
        mount = lj.Mount(np.array([v[2], v[3], v[4] - v[1]]), beta=0.0, gamma=0.0, psi=0.0, epsilon=0.0)
        lo, hi = lj.scan_bounds(scan, mount, heights)
        field, report = lj.io.load_field(CUT, region=(lo, hi), return_report=True)
        assert report.format == "openfoam" and report.time == "168" and report.n_cells == 18034
        assert report.nan_fraction < 0.5 and np.isfinite(report.resample_error_rms)
        los = np.asarray(lj.simulate(field, scan, mount, heights).los)
        n = np.asarray(rotate(lidar_to_cfd_rotation(mount), scan.directions()))
        los_ref = np.full_like(los, np.nan)
        for k, (b, h) in enumerate(r[:, :2]):
            los_ref[np.searchsorted(heights, h), int(b)] = rr[k] @ n[int(b)]
        d = los - los_ref
        assert np.isfinite(d).all()
        assert np.sqrt(np.mean(d ** 2)) < 0.02, lidar
        assert np.abs(d).max() < 0.1, lidar


def test_reader_agrees_with_foamlib():
    """An independent parser (foamlib) reads the same binary mesh and field."""
    import foamlib
    f = read_openfoam_field(CUT)
    d = CUT / "constant" / "polyMesh"
    np.testing.assert_array_equal(foamlib.FoamFile(d / "points")[None], f.mesh.points)
    np.testing.assert_array_equal(foamlib.FoamFile(d / "owner")[None], f.mesh.owner)
    np.testing.assert_array_equal(foamlib.FoamFile(d / "neighbour")[None], f.mesh.neighbour)
    offsets, labels = foamlib.FoamFile(d / "faces")[None]
    np.testing.assert_array_equal(offsets, f.mesh.face_offsets)
    np.testing.assert_array_equal(labels, f.mesh.face_labels)
    u = foamlib.FoamFieldFile(CUT / "168" / "U")
    np.testing.assert_array_equal(u.internal_field, f.cell_values)
    terrain = [p for p in f.mesh.patches if p[0] == "terrain"][0]
    np.testing.assert_array_equal(np.broadcast_to(u.boundary_field["terrain"]["value"], (terrain[3], 3)),
                                  f.boundary.values["terrain"])


# ---------------------------------------------------------------- windAroundBuildings (v1912 tutorial)

WAB = DATA / "windAroundBuildings_cut"


def test_windaroundbuildings_cut_against_openfoam_probes():
    """snappyHexMesh polyhedra around buildings: lidarjax's cellPoint at Windcube V2 beam points
    of a lidar on a roof and one in a street equals OpenFOAM's `probes` (cellPoint, 12 digits);
    points inside buildings or outside the cut are NaN exactly where OpenFOAM reports them not
    found; a grid from load_field is NaN inside the roof lidar's building. The building walls are
    `noSlip` (no `value` entry in the file: zero velocity, which sets the wall points' values)."""
    from lidarjax.io.monitor_points import read_monitor_points_csv, read_openfoam_probes

    locs = read_monitor_points_csv(DATA / "windAroundBuildings_points.csv")
    ref = read_openfoam_probes(WAB / "postProcessing" / "lidarProbes").values_for(locs)
    f = read_openfoam_field(WAB)
    assert f.time == "400" and f.mesh.n_cells == 13730
    faces_per_cell = np.bincount(np.concatenate([f.mesh.owner, f.mesh.neighbour]), minlength=f.mesh.n_cells)
    assert (faces_per_cell > 6).sum() > 500  # split-hex polyhedra from snappyHexMesh
    got = sample_openfoam(f, locs.points)
    found = np.isfinite(ref).all(axis=1)
    assert found.sum() >= 70 and (~found).sum() >= 100
    np.testing.assert_array_equal(np.isfinite(got).all(axis=1), found)
    np.testing.assert_allclose(got[found], ref[found], rtol=0, atol=1e-8)
    # inside the building under the roof lidar (roof at 38 m): NaN on the grid, finite above the roof
    field = lj.io.load_field(WAB, region=([90.0, 120.0, 30.0], [102.0, 132.0, 45.0]), spacing=1.0)
    v = np.asarray(field.sample(np.array([[96.0, 126.0, 34.0], [96.0, 126.0, 41.0]])))
    assert np.isnan(v[0]).all() and np.isfinite(v[1]).all()


# ---------------------------------------------------------------- decomposed case (decomposePar)


def test_decomposed_case_merges_to_the_original(tmp_path):
    """`decomposePar` (v1912, simple 2x2x1) of the 6^3 mesh with a building: the four processor
    meshes merged through *ProcAddressing give the original mesh (same point, face and cell
    numbering) and field, so points on processor boundaries are sampled as in the whole case."""
    ax = np.linspace(0.0, 6.0, 7)
    solid = np.zeros((6, 6, 6), bool)
    solid[2:4, 2:4, 0:3] = True
    m = hex_mesh(ax, ax, ax, solid)
    f = read_openfoam_field(DATA / "block_decomposed")
    assert f.time == "100" and f.mesh.n_cells == 204
    np.testing.assert_array_equal(f.mesh.points, m["points"])
    np.testing.assert_array_equal(f.mesh.face_offsets, m["face_offsets"])
    np.testing.assert_array_equal(f.mesh.face_labels, m["face_labels"])
    np.testing.assert_array_equal(f.mesh.owner, m["owner"])
    np.testing.assert_array_equal(f.mesh.neighbour, m["neighbour"])
    assert [p[:2] + p[2:] for p in f.mesh.patches] == [tuple(p) for p in m["patches"]]
    np.testing.assert_allclose(f.cell_values, linear(m["cell_centres"]), rtol=0, atol=1e-12)
    # processor boundaries at x = 3 and y = 3: sampled as in the undecomposed case
    whole = read_openfoam_field(write_case(tmp_path / "whole", m, linear(m["cell_centres"]), binary=True))
    rng = np.random.default_rng(3)
    q = rng.uniform(0.2, 5.8, (200, 3))
    q[:50, 0] = 3.0
    q[50:100, 1] = 3.0
    q = q[~((q[:, 0] > 2) & (q[:, 0] < 4) & (q[:, 1] > 2) & (q[:, 1] < 4) & (q[:, 2] < 3))]
    got = sample_openfoam(f, q)
    assert np.isfinite(got).all()
    np.testing.assert_allclose(got, sample_openfoam(whole, q), rtol=0, atol=1e-12)
    assert lj.io.openfoam_times(DATA / "block_decomposed") == ["100"]
