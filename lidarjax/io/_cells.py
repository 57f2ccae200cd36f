"""Sampling a finite-volume field inside its own polyhedral cells: OpenFOAM's `cellPoint`.

Private to `lidarjax.io` (plain numpy + scipy, no jit). The interpolation is rebuilt from the
same ingredients as OpenFOAM's `interpolationCellPoint` (what the `probes` function object
and `sample` use with `interpolationScheme cellPoint`):

1. geometry as `primitiveMesh` computes it: face centre = area-weighted centroid of the fan
   of triangles (edge, face-point average); face area vector = half the sum of their normals;
   cell centre = volume-weighted centroid of the face pyramids over the average of the face
   centres;
2. point values as `volPointInterpolation`: a point not on a boundary patch takes the
   inverse-distance weighted mean of the values at the centres of the cells around it
   (weights `1/|x_p - C_c|`); a point on a boundary patch (not `empty`, not coupled) takes
   the inverse-distance weighted mean of the boundary *face* values of the patch faces
   around it (weights `1/|x_p - C_f|`);
3. each cell cut into tetrahedra (cell centre, the face's tet base point, two consecutive
   face points: `polyMeshTetDecomposition`, base point = the first face point whose fan of
   tets has positive quality seen from both cells); a point is located in its tetrahedron
   and the value is the barycentric mix of the cell-centre value and the three point
   values.

The result is continuous and piecewise linear; a linear field is reproduced exactly in the
interior. Points in no cell (inside solids: buildings, below terrain; outside the domain)
are NaN: nothing is ever interpolated across a solid.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree

__all__: list[str] = []

_CHUNK = 2_000_000
_INSIDE_TOL = 1e-9
_MIN_TET_QUALITY = 1e-15


@dataclasses.dataclass(frozen=True, eq=False)
class PolyMesh:
    """An OpenFOAM `polyMesh` as flat arrays (global numbering).

    - `points` `(P, 3)` metres; faces as CSR `face_offsets (F+1,)`, `face_labels (M,)`;
    - `owner (F,)`, `neighbour (Fi,)` (internal faces first, as in OpenFOAM);
    - `patches`: `(name, type, startFace, nFaces)` for each boundary patch.
    """

    points: np.ndarray
    face_offsets: np.ndarray
    face_labels: np.ndarray
    owner: np.ndarray
    neighbour: np.ndarray
    n_cells: int
    patches: tuple[tuple[str, str, int, int], ...]

    @property
    def n_faces(self) -> int:
        return int(self.owner.size)

    @property
    def n_internal(self) -> int:
        return int(self.neighbour.size)


@dataclasses.dataclass(frozen=True, eq=False)
class BoundaryValues:
    """Boundary face values of a vector field, per patch: `values[name]` is `(nFaces, 3)`,
    or a string naming how to derive them from the owner cells (`"cell"` for zero-gradient
    types, `"slip"` for slip/symmetry: the cell value less its normal component)."""

    values: dict[str, np.ndarray | str]


_NOT_PROPER = ("empty", "processor", "processorCyclic", "cyclic", "cyclicAMI", "cyclicACMI",
               "cyclicSlip", "nonConformalCyclic", "nonConformalProcessorCyclic")


def _face_sizes(mesh: PolyMesh, faces: np.ndarray) -> np.ndarray:
    return mesh.face_offsets[faces + 1] - mesh.face_offsets[faces]


def _gather_face_points(mesh: PolyMesh, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flat point labels of `faces`, their local offsets, and each label's position in its face."""
    sizes = _face_sizes(mesh, faces)
    offs = np.zeros(faces.size + 1, np.int64)
    np.cumsum(sizes, out=offs[1:])
    pos_in_face = np.arange(offs[-1], dtype=np.int64) - np.repeat(offs[:-1], sizes)
    flat = mesh.face_labels[np.repeat(mesh.face_offsets[faces], sizes) + pos_in_face]
    return flat, offs, pos_in_face


def face_geometry(mesh: PolyMesh, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Face centres `(n, 3)` and area vectors `(n, 3)` of `faces`, as `primitiveMesh`."""
    centres = np.empty((faces.size, 3))
    areas = np.empty((faces.size, 3))
    for s in range(0, faces.size, _CHUNK // 4):
        f = faces[s: s + _CHUNK // 4]
        flat, offs, pos = _gather_face_points(mesh, f)
        sizes = np.diff(offs)
        p = mesh.points[flat]
        est = np.add.reduceat(p, offs[:-1], axis=0) / sizes[:, None]
        nxt_pos = np.where(pos + 1 == np.repeat(sizes, sizes), 0, pos + 1)
        pn = p[np.repeat(offs[:-1], sizes) + nxt_pos]
        fe = np.repeat(est, sizes, axis=0)
        c = p + pn + fe
        n = np.cross(pn - p, fe - p)
        a = np.linalg.norm(n, axis=1)
        sum_n = np.add.reduceat(n, offs[:-1], axis=0)
        sum_a = np.add.reduceat(a, offs[:-1])
        sum_ac = np.add.reduceat(a[:, None] * c, offs[:-1], axis=0)
        good = sum_a > 1e-150
        safe = np.where(good, sum_a, 1.0)
        centres[s: s + f.size] = np.where(good[:, None], sum_ac / (3.0 * safe[:, None]), est)
        areas[s: s + f.size] = np.where(good[:, None], 0.5 * sum_n, 0.0)
    return centres, areas


def cell_centres(
    face_ctr: np.ndarray, face_area: np.ndarray, own: np.ndarray, nei: np.ndarray, n_cells: int,
) -> np.ndarray:
    """Cell centres as `primitiveMesh::makeCellCentresAndVols`.

    `own[i]`, `nei[i]`: local cell numbers of face i's two sides (-1 where that side is not
    one of the `n_cells` cells); every face of every cell must be present."""
    est = np.zeros((n_cells, 3))
    count = np.zeros(n_cells)
    for side in (own, nei):
        ok = side >= 0
        for a in range(3):
            est[:, a] += np.bincount(side[ok], weights=face_ctr[ok, a], minlength=n_cells)
        count += np.bincount(side[ok], minlength=n_cells)
    est /= np.maximum(count, 1)[:, None]
    ctr = np.zeros((n_cells, 3))
    vol = np.zeros(n_cells)
    for side, sign in ((own, 1.0), (nei, -1.0)):
        ok = side >= 0
        c = side[ok]
        pyr3 = sign * np.einsum("ij,ij->i", face_area[ok], face_ctr[ok] - est[c])
        pc = 0.75 * face_ctr[ok] + 0.25 * est[c]
        for a in range(3):
            ctr[:, a] += np.bincount(c, weights=pyr3 * pc[:, a], minlength=n_cells)
        vol += np.bincount(c, weights=pyr3, minlength=n_cells)
    good = np.abs(vol) > 1e-300
    ctr = np.where(good[:, None], ctr / np.where(good, vol, 1.0)[:, None], est)
    return ctr


def cell_bounds(mesh: PolyMesh) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned bounding boxes `(lo, hi)`, each `(n_cells, 3)`, of every cell."""
    lo = np.full((mesh.n_cells, 3), np.inf)
    hi = np.full((mesh.n_cells, 3), -np.inf)
    fo = mesh.face_offsets
    nf = mesh.n_faces
    step = _CHUNK
    for s in range(0, nf, step):
        e = min(nf, s + step)
        starts = fo[s: e] - fo[s]
        labels = mesh.face_labels[fo[s]: fo[e]]
        own = mesh.owner[s:e]
        nei = mesh.neighbour[s: min(e, mesh.n_internal)]
        for a in range(3):
            pa = mesh.points[labels, a]
            mn = np.minimum.reduceat(pa, starts)
            mx = np.maximum.reduceat(pa, starts)
            np.minimum.at(lo[:, a], own, mn)
            np.maximum.at(hi[:, a], own, mx)
            if nei.size:
                np.minimum.at(lo[:, a], nei, mn[: nei.size])
                np.maximum.at(hi[:, a], nei, mx[: nei.size])
    return lo, hi


def _faces_touching(mesh: PolyMesh, point_mask: np.ndarray) -> np.ndarray:
    """Indices of faces with at least one point in `point_mask`."""
    out = []
    fo = mesh.face_offsets
    for s in range(0, mesh.n_faces, _CHUNK):
        e = min(mesh.n_faces, s + _CHUNK)
        hit = np.logical_or.reduceat(point_mask[mesh.face_labels[fo[s]: fo[e]]], fo[s:e] - fo[s])
        out.append(np.flatnonzero(hit) + s)
    return np.concatenate(out) if out else np.zeros(0, np.int64)


def _faces_of_cells(mesh: PolyMesh, cell_mask: np.ndarray) -> np.ndarray:
    hit = cell_mask[mesh.owner].copy()
    hit[: mesh.n_internal] |= cell_mask[mesh.neighbour]
    return np.flatnonzero(hit)


@dataclasses.dataclass(frozen=True, eq=False)
class CellPointSampler:
    """The cellPoint interpolant restricted to a set of cells.

    Tetrahedra `(n_tets,)`: `tet_cell` (local cell), `tet_pts (n_tets, 3)` (local point
    numbers of base, A, B), inverse edge matrices `tet_inv (n_tets, 3, 3)` for barycentric
    coordinates relative to the cell centre; `cell_centre (nc, 3)`, `cell_value (nc, 3)`;
    `point_xyz (np, 3)`, `point_value (np, 3)`; `cell_tets`: CSR of tets per local cell.
    """

    cell_centre: np.ndarray
    cell_value: np.ndarray
    cell_size: np.ndarray  # (nc, 3) bounding-box extent per axis
    cell_lo: np.ndarray
    cell_hi: np.ndarray
    point_xyz: np.ndarray
    point_value: np.ndarray
    tet_cell: np.ndarray
    tet_pts: np.ndarray
    tet_inv: np.ndarray
    tet_ok: np.ndarray
    cell_tet_offsets: np.ndarray
    n_cells_total: int
    n_boundary_points: int

    @property
    def n_cells(self) -> int:
        return int(self.cell_centre.shape[0])

    def with_values(self, cell_value: np.ndarray, point_value: np.ndarray) -> CellPointSampler:
        """The same interpolant of other values on the same cells and points (a
        `PointValues` recipe's output)."""
        return dataclasses.replace(self, cell_value=cell_value, point_value=point_value)

    # -- evaluation ------------------------------------------------------------------
    def _bary(self, tets: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Barycentric weights `(n, 4)` (cell centre, base, A, B) of points `q` in `tets`."""
        rel = q - self.cell_centre[self.tet_cell[tets]]
        lam = np.einsum("nij,nj->ni", self.tet_inv[tets], rel)
        return np.concatenate([1.0 - lam.sum(axis=1, keepdims=True), lam], axis=1)

    def _combine(self, tets: np.ndarray, w: np.ndarray) -> np.ndarray:
        vals = w[:, :1] * self.cell_value[self.tet_cell[tets]]
        for k in range(3):
            vals += w[:, k + 1: k + 2] * self.point_value[self.tet_pts[tets, k]]
        return vals

    def sample_points(self, q: np.ndarray, k_candidates: tuple[int, ...] = (8, 32, 128)) -> np.ndarray:
        """Values `(n, 3)` at arbitrary points `(n, 3)`; NaN in no cell of the set."""
        q = np.asarray(q, np.float64).reshape(-1, 3)
        out = np.full((q.shape[0], 3), np.nan)
        tets, w = self.locate(q, k_candidates)
        found = tets >= 0
        if found.any():
            out[found] = self._combine(tets[found], w[found])
        return out

    def locate(self, q: np.ndarray, k_candidates: tuple[int, ...] = (8, 32, 128)
               ) -> tuple[np.ndarray, np.ndarray]:
        """The tetrahedron holding each point `(n, 3)` (index into the tet arrays, -1 in no
        cell of the set) and its barycentric weights `(n, 4)` (cell centre, base, A, B; NaN
        where not found). Candidate cells are the `k` nearest cell centres, `k` growing
        through `k_candidates`; the first containing cell in that order wins (as OpenFOAM's
        `findCell` by nearest centre, then neighbours)."""
        q = np.asarray(q, np.float64).reshape(-1, 3)
        tet_of = np.full(q.shape[0], -1, np.int64)
        w_of = np.full((q.shape[0], 4), np.nan)
        if self.n_cells == 0 or q.shape[0] == 0:
            return tet_of, w_of
        todo = np.arange(q.shape[0])
        tree = cKDTree(self.cell_centre)
        # points outside every cell box cannot be in a cell: skip them at once
        inbox = (q >= self.cell_lo.min(axis=0)).all(axis=1) & (q <= self.cell_hi.max(axis=0)).all(axis=1)
        todo = todo[inbox]
        for k in k_candidates:
            if todo.size == 0:
                break
            kk = min(k, self.n_cells)
            found_all = np.zeros(todo.size, bool)
            for s in range(0, todo.size, max(1, 200_000 // kk)):
                ids = todo[s: s + max(1, 200_000 // kk)]
                _, cand = tree.query(q[ids], k=kk)
                cand = cand.reshape(ids.size, kk)
                found = self._locate(q, ids, cand, tet_of, w_of)
                found_all[s: s + ids.size] = found
                if kk == self.n_cells:
                    found_all[s: s + ids.size] = True
            todo = todo[~found_all]
        return tet_of, w_of

    def tet_vertices(self, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Vertex positions `(n, 4, 3)` (metres) and values `(n, 4, 3)` (m/s) of `tets`, in
        the order cell centre, base, A, B (the order of `locate`'s weights)."""
        tets = np.asarray(tets, np.int64)
        cells = self.tet_cell[tets]
        pos = np.stack([self.cell_centre[cells]] + [self.point_xyz[self.tet_pts[tets, k]]
                                                    for k in range(3)], axis=1)
        val = np.stack([self.cell_value[cells]] + [self.point_value[self.tet_pts[tets, k]]
                                                   for k in range(3)], axis=1)
        return pos, val

    def _locate(self, q: np.ndarray, ids: np.ndarray, cand: np.ndarray, tet_of: np.ndarray,
                w_of: np.ndarray) -> np.ndarray:
        """Test the tets of candidate cells; write tets and weights; return which `ids` were
        found."""
        pid = np.repeat(np.arange(ids.size), cand.shape[1])
        cells = cand.reshape(-1)
        inb = (q[ids[pid]] >= self.cell_lo[cells] - 1e-9 * self.cell_size[cells]).all(axis=1) & (
            q[ids[pid]] <= self.cell_hi[cells] + 1e-9 * self.cell_size[cells]).all(axis=1)
        pid, cells = pid[inb], cells[inb]
        counts = self.cell_tet_offsets[cells + 1] - self.cell_tet_offsets[cells]
        tpid = np.repeat(pid, counts)
        tets = np.repeat(self.cell_tet_offsets[cells], counts) + (
            np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts))
        w = self._bary(tets, q[ids[tpid]])
        inside = (w >= -_INSIDE_TOL).all(axis=1) & self.tet_ok[tets]
        tpid, tets, w = tpid[inside], tets[inside], w[inside]
        found = np.zeros(ids.size, bool)
        if tpid.size:
            # first hit per point (the cell order follows the candidate order: nearest first)
            first = np.unique(tpid, return_index=True)[1]
            tet_of[ids[tpid[first]]] = tets[first]
            w_of[ids[tpid[first]]] = w[first]
            found[tpid[first]] = True
        return found

    def sample_grid(self, axes: list[np.ndarray], use_numba: bool = True) -> tuple[np.ndarray, int]:
        """Values `(nx, ny, nz, 3)` at the nodes of a tensor grid (NaN in no cell), scattering
        each tetrahedron onto the nodes inside its bounding box. Returns also the number of
        point-in-tet tests made. Uses a numba kernel when numba is installed (the `openfoam`
        extra), else the same computation vectorised in numpy (several times slower)."""
        return self._scatter(axes, use_numba, locations=False)

    def grid_locations(self, axes: list[np.ndarray], use_numba: bool = True
                       ) -> tuple[np.ndarray, np.ndarray]:
        """The tetrahedron holding each node of a tensor grid, `(nx, ny, nz)` (-1 in no cell),
        and its barycentric weights `(nx, ny, nz, 4)` (cell centre, base, A, B), as
        `sample_grid` finds them: `values_at` of them is `sample_grid` for any values on the
        same mesh (a snapshot sequence locates its grid once)."""
        return self._scatter(axes, use_numba, locations=True)

    def values_at(self, tets: np.ndarray, weights: np.ndarray, use_numba: bool = True) -> np.ndarray:
        """Values `(..., 3)` at located points (`grid_locations` or `locate`), NaN where the
        tetrahedron is -1 (a numba loop when numba is installed, else numpy)."""
        tets = np.asarray(tets)
        out = np.full(tets.shape + (3,), np.nan)
        kernel = _mix_kernel() if use_numba else None
        if kernel is not None:
            kernel(tets.reshape(-1), np.ascontiguousarray(weights).reshape(-1, 4), self.tet_cell,
                   self.tet_pts, self.cell_value, self.point_value, out.reshape(-1, 3))
            return out
        found = tets >= 0
        t, w = tets[found], weights[found]
        cells = self.tet_cell[t]
        out[found] = (w[:, 0:1] * self.cell_value[cells] + w[:, 1:2] * self.point_value[self.tet_pts[t, 0]]
                      + w[:, 2:3] * self.point_value[self.tet_pts[t, 1]]
                      + w[:, 3:4] * self.point_value[self.tet_pts[t, 2]])
        return out

    def _scatter(self, axes, use_numba, *, locations: bool):
        shape = tuple(a.size for a in axes)
        if locations:
            tet_out = np.full(shape, -1, np.int64)
            w_out = np.full((*shape, 4), np.nan)
            done = (tet_out, w_out)
        else:
            out = np.full((*shape, 3), np.nan)
            done = (out, 0)
        tets_all = np.flatnonzero(self.tet_ok)
        if tets_all.size == 0:
            return done
        # bounding boxes of the tets
        verts = [self.cell_centre[self.tet_cell[tets_all]]] + [
            self.point_xyz[self.tet_pts[tets_all, k]] for k in range(3)]
        tlo = np.minimum.reduce(verts)
        thi = np.maximum.reduce(verts)
        del verts
        i0 = np.stack([np.searchsorted(axes[a], tlo[:, a] - 1e-9 * (thi[:, a] - tlo[:, a] + 1), "left")
                       for a in range(3)], axis=1)
        i1 = np.stack([np.searchsorted(axes[a], thi[:, a] + 1e-9 * (thi[:, a] - tlo[:, a] + 1), "right")
                       for a in range(3)], axis=1)
        span = np.maximum(i1 - i0, 0)
        n_cand = span.prod(axis=1)
        keep = n_cand > 0
        tets_all, i0, span, n_cand = tets_all[keep], i0[keep], span[keep], n_cand[keep]
        tests = int(n_cand.sum())
        kernel = _grid_kernel() if use_numba else None
        if kernel is not None:
            centre = self.cell_centre[self.tet_cell[tets_all]]
            inv = np.ascontiguousarray(self.tet_inv[tets_all])
            if locations:  # the value arrays are not read
                vc, vp, out = np.zeros((1, 3)), np.zeros((1, 3, 3)), np.zeros((1, 1, 1, 3))
            else:
                vc = self.cell_value[self.tet_cell[tets_all]]
                vp = np.stack([self.point_value[self.tet_pts[tets_all, k]] for k in range(3)], axis=1)
                tet_out, w_out = np.zeros((1, 1, 1), np.int64), np.zeros((1, 1, 1, 4))
            kernel(centre, inv, tets_all, vc, vp, i0, i0 + span, axes[0], axes[1], axes[2], out,
                   tet_out, w_out, locations)
            return done if locations else (out, tests)
        flat = (tet_out.reshape(-1), w_out.reshape(-1, 4)) if locations else out.reshape(-1, 3)
        csum = np.cumsum(n_cand)
        budget = _CHUNK * 2
        start = 0
        while start < tets_all.size:
            base = csum[start - 1] if start else 0
            stop = int(np.searchsorted(csum, base + budget, "right"))
            stop = max(stop, start + 1)
            sl = slice(start, stop)
            cnt = n_cand[sl]
            rep = np.repeat(np.arange(stop - start), cnt)
            local = np.arange(int(cnt.sum())) - np.repeat(np.cumsum(cnt) - cnt, cnt)
            sp = span[sl][rep]
            ii = i0[sl][rep, 0] + local // (sp[:, 1] * sp[:, 2])
            jj = i0[sl][rep, 1] + (local // sp[:, 2]) % sp[:, 1]
            kk = i0[sl][rep, 2] + local % sp[:, 2]
            q = np.stack([axes[0][ii], axes[1][jj], axes[2][kk]], axis=1)
            tets = tets_all[sl][rep]
            w = self._bary(tets, q)
            inside = (w >= -_INSIDE_TOL).all(axis=1)
            node = (ii * shape[1] + jj) * shape[2] + kk
            if locations:
                flat[0][node[inside]] = tets[inside]
                flat[1][node[inside]] = w[inside]
            else:
                flat[node[inside]] = self._combine(tets[inside], w[inside])
            start = stop
        return done if locations else (out, tests)


@dataclasses.dataclass(frozen=True, eq=False)
class FaceValues:
    """Values `(n, 3)` of fixed boundary `faces` from any field on the mesh: the faces are
    grouped by patch once (`FaceValues.build`), so that each field costs one pass per patch
    the faces touch. `proper[i]`: face `i` is on a proper patch (not empty, not coupled):
    those carry the boundary point values in `volPointInterpolation`."""

    faces: np.ndarray
    area: np.ndarray  # (n, 3) the faces' area vectors, m^2
    owner: np.ndarray  # the faces' owner cells (global numbers)
    proper: np.ndarray
    # per proper patch the faces touch: (name, positions in `faces`, face numbers within
    # the patch, unit face normals)
    groups: tuple[tuple[str, np.ndarray, np.ndarray, np.ndarray], ...]

    @classmethod
    def build(cls, mesh: PolyMesh, faces: np.ndarray, face_area: np.ndarray) -> FaceValues:
        faces = np.asarray(faces, np.int64)
        face_area = np.asarray(face_area, np.float64).reshape(-1, 3)
        proper = np.zeros(faces.size, bool)
        groups = []
        for name, ptype, start, n in mesh.patches:
            sel = np.flatnonzero((faces >= start) & (faces < start + n))
            if not sel.size or ptype in _NOT_PROPER:
                continue
            proper[sel] = True
            nrm = face_area[sel] / np.maximum(np.linalg.norm(face_area[sel], axis=1), 1e-300)[:, None]
            groups.append((name, sel, faces[sel] - start, nrm))
        return cls(faces=faces, area=face_area, owner=mesh.owner[faces], proper=proper,
                   groups=tuple(groups))

    def __call__(self, cell_value: np.ndarray, boundary: BoundaryValues) -> np.ndarray:
        """The faces' values (m/s) from `cell_value (n_cells, 3)` and the patch values."""
        vals = np.zeros((self.faces.size, 3))
        for name, sel, local, nrm in self.groups:
            spec = boundary.values.get(name, "cell")
            if isinstance(spec, str):
                v = cell_value[self.owner[sel]]
                if spec == "slip":
                    v = v - np.einsum("ij,ij->i", v, nrm)[:, None] * nrm
                vals[sel] = v
            else:
                arr = np.asarray(spec, np.float64)
                vals[sel] = arr if arr.ndim == 1 else arr[local]
        return vals


@dataclasses.dataclass(frozen=True, eq=False)
class PointValues:
    """How `build_sampler` forms the values its sampler holds from a field on the same mesh:
    the region cells' values and `volPointInterpolation`'s point values (inverse-distance
    weights to the cell centres around interior points, to the proper patch faces' centres
    around patch points), everything geometric kept. `sampler.with_values(*recipe(values,
    boundary))` is `build_sampler` of those values, without the geometry (a snapshot
    sequence builds it once)."""

    mesh: PolyMesh
    ring_cells: np.ndarray
    sub_cells: np.ndarray
    pair_point: np.ndarray
    pair_cell: np.ndarray
    pair_weight: np.ndarray
    faces: FaceValues  # the boundary faces around the region's points
    patch_point: np.ndarray
    patch_face: np.ndarray
    patch_weight: np.ndarray
    wsum: np.ndarray

    def __call__(self, cell_value: np.ndarray, boundary: BoundaryValues) -> tuple[np.ndarray, np.ndarray]:
        """``(cell values (nc, 3), point values (np, 3))`` of the sampler's cells and points."""
        cell_value = np.asarray(cell_value, np.float64)
        cv = cell_value[self.ring_cells]
        n = self.wsum.size
        vsum = np.zeros((n, 3))
        for a in range(3):
            vsum[:, a] += np.bincount(self.pair_point, weights=self.pair_weight * cv[self.pair_cell, a],
                                      minlength=n)
        bvals = self.faces(cell_value, boundary)
        for a in range(3):
            vsum[:, a] += np.bincount(self.patch_point, weights=self.patch_weight * bvals[self.patch_face, a],
                                      minlength=n)
        pval = vsum / np.where(self.wsum > 0, self.wsum, 1.0)[:, None]
        pval[self.wsum <= 0] = np.nan
        return cv[self.sub_cells], pval

    def vertex_values(self, sampler: CellPointSampler, tets: np.ndarray) -> VertexValues:
        """The recipe that gives the vertex values `(n, 4, 3)` of the tetrahedra `tets` (of
        `sampler`, built with this recipe; -1: in no cell) from any field on the mesh: each
        distinct vertex (a cell centre, a mesh point) once, as two sparse matrices, one over
        the cell values those vertices use, one over the boundary face values they use, then
        gathered into the `(n, 4)` rows. Built once per mesh and point set; a snapshot then
        costs a sparse matrix product over a few hundred vertices (`VertexValues.__call__`)."""
        tets = np.asarray(tets, np.int64).reshape(-1)
        n = tets.size
        nc = self.mesh.n_cells
        npts = self.wsum.size
        inv = np.where(self.wsum > 0, 1.0 / np.where(self.wsum > 0, self.wsum, 1.0), 0.0)
        # point rows: volPointInterpolation's weights, normalised
        p_cell = sparse.csr_matrix(
            (self.pair_weight * inv[self.pair_point],
             (self.pair_point, self.ring_cells[self.pair_cell])), shape=(npts, nc))
        p_face = sparse.csr_matrix(
            (self.patch_weight * inv[self.patch_point], (self.patch_point, self.patch_face)),
            shape=(npts, self.faces.faces.size))
        found = tets >= 0
        t = np.where(found, tets, 0)
        cells = self.ring_cells[self.sub_cells[sampler.tet_cell[t]]]  # global cell numbers
        pts = sampler.tet_pts[t]  # (n, 3) sampler point numbers
        found &= (self.wsum[pts] > 0).all(axis=1)
        # the distinct vertices: the cell centres, then the mesh points
        ucell, icell = np.unique(cells[found], return_inverse=True)
        upt, ipt = np.unique(pts[found].reshape(-1), return_inverse=True)
        rows = np.zeros((n, 4), np.int64)
        rows[found, 0] = icell.reshape(-1)
        rows[found, 1:] = ucell.size + ipt.reshape(-1, 3)
        centre = sparse.csr_matrix((np.ones(ucell.size), (np.arange(ucell.size), ucell)),
                                   shape=(ucell.size, nc))
        cell_m = sparse.vstack([centre, p_cell[upt]]).tocsc()
        face_m = sparse.vstack([sparse.csr_matrix((ucell.size, p_face.shape[1])),
                                p_face[upt]]).tocsc()
        cols = np.flatnonzero(np.diff(cell_m.indptr) > 0)
        used = np.flatnonzero(np.diff(face_m.indptr) > 0)
        return VertexValues(cells=cols, cell=cell_m[:, cols].tocsr(), face=face_m[:, used].tocsr(),
                            faces=FaceValues.build(self.mesh, self.faces.faces[used],
                                                   self.faces.area[used]),
                            rows=rows.reshape(-1), found=found)


@dataclasses.dataclass(frozen=True, eq=False)
class VertexValues:
    """Vertex values `(n, 4, 3)` (cell centre, base, A, B) of located tetrahedra from a
    field on the mesh (`PointValues.vertex_values`): the distinct vertices' values ``cell @
    cell_value[cells] + face @ faces(...)`` (the boundary face values by `FaceValues`),
    gathered by `rows (4 n,)`; NaN rows where `found` is False."""

    cells: np.ndarray
    cell: sparse.csr_matrix
    face: sparse.csr_matrix
    faces: FaceValues
    rows: np.ndarray
    found: np.ndarray

    def __call__(self, cell_value: np.ndarray, boundary: BoundaryValues) -> np.ndarray:
        cell_value = np.asarray(cell_value, np.float64)
        n = self.found.size
        if self.cell.shape[0] == 0:  # no point in a cell
            return np.full((n, 4, 3), np.nan)
        vertex = self.cell @ cell_value.take(self.cells, axis=0)
        if self.faces.faces.size:
            vertex += self.face @ self.faces(cell_value, boundary)
        out = vertex.take(self.rows, axis=0).reshape(n, 4, 3)
        out[~self.found] = np.nan
        return out


def build_sampler(
    mesh: PolyMesh, cell_value: np.ndarray, boundary: BoundaryValues, region_cells: np.ndarray,
    bounds: tuple[np.ndarray, np.ndarray] | None = None,
) -> CellPointSampler:
    """The cellPoint interpolant over the cells `region_cells` (global numbers, sorted).

    Reads only what those cells need: their points, the cells around those points (for the
    point values), and those cells' faces (for their centres)."""
    return build_sampler_and_values(mesh, cell_value, boundary, region_cells, bounds)[0]


def build_sampler_and_values(
    mesh: PolyMesh, cell_value: np.ndarray, boundary: BoundaryValues, region_cells: np.ndarray,
    bounds: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[CellPointSampler, PointValues]:
    """`build_sampler` and the `PointValues` recipe that refills it with another field's
    values on the same mesh."""
    ring = _ring_around(mesh, region_cells)
    sub_cells = ring.cell_local[region_cells]
    values, n_boundary_points = _point_values(mesh, ring, sub_cells)
    tet_cell, tet_pts, cto = _region_tets(mesh, ring, region_cells, sub_cells)
    rcc = ring.cc[sub_cells]
    inv, tet_ok = _tet_inverses(ring.pxyz, rcc, tet_cell, tet_pts)
    if bounds is not None:
        clo, chi = bounds[0][region_cells], bounds[1][region_cells]
    else:
        clo, chi = _tet_boxes(ring.pxyz, tet_cell, tet_pts, region_cells.size)
    cell_v, point_v = values(cell_value, boundary)
    sampler = CellPointSampler(
        cell_centre=rcc, cell_value=cell_v, cell_size=chi - clo, cell_lo=clo, cell_hi=chi,
        point_xyz=ring.pxyz, point_value=point_v, tet_cell=tet_cell, tet_pts=tet_pts,
        tet_inv=inv, tet_ok=tet_ok, cell_tet_offsets=cto, n_cells_total=mesh.n_cells,
        n_boundary_points=n_boundary_points,
    )
    return sampler, values


@dataclasses.dataclass(frozen=True, eq=False)
class _Ring:
    """A region's points and every cell touching them (the ring), with the ring's geometry.

    `rfaces`: the region cells' faces; `points`: the region's points (global numbers),
    `plocal`: their local numbers (-1 elsewhere), `pxyz`: their coordinates (m); `tfaces`:
    the faces touching those points; `cells`: the ring cells (global numbers), `cell_local`:
    their local numbers (-1 elsewhere); `fctr`, `farea`: centres and area vectors of the ring
    cells' faces, found at `face_pos[face]`; `cc`: the ring cells' centres."""

    rfaces: np.ndarray
    points: np.ndarray
    plocal: np.ndarray
    pxyz: np.ndarray
    tfaces: np.ndarray
    cells: np.ndarray
    cell_local: np.ndarray
    fctr: np.ndarray
    farea: np.ndarray
    face_pos: np.ndarray
    cc: np.ndarray


def _local_neighbour(mesh: PolyMesh, faces: np.ndarray, local: np.ndarray) -> np.ndarray:
    """`local[neighbour]` of each of `faces`; -1 for a boundary face."""
    out = np.full(faces.size, -1, np.int64)
    internal = faces < mesh.n_internal
    out[internal] = local[mesh.neighbour[faces[internal]]]
    return out


def _ring_around(mesh: PolyMesh, region_cells: np.ndarray) -> _Ring:
    """The points of `region_cells`, the cells around them and those cells' geometry."""
    in_region = np.zeros(mesh.n_cells, bool)
    in_region[region_cells] = True
    rfaces = _faces_of_cells(mesh, in_region)
    pmask = np.zeros(mesh.points.shape[0], bool)
    flat_r, _, _ = _gather_face_points(mesh, rfaces)
    pmask[flat_r] = True
    tfaces = _faces_touching(mesh, pmask)
    ring = np.zeros(mesh.n_cells, bool)
    ring[mesh.owner[tfaces]] = True
    ring[mesh.neighbour[tfaces[tfaces < mesh.n_internal]]] = True
    ring_cells = np.flatnonzero(ring)
    cell_local = np.full(mesh.n_cells, -1, np.int64)
    cell_local[ring_cells] = np.arange(ring_cells.size)
    # all faces of the ring cells, their geometry, the ring's cell centres
    gfaces = _faces_of_cells(mesh, ring)
    fctr, farea = face_geometry(mesh, gfaces)
    cc = cell_centres(fctr, farea, cell_local[mesh.owner[gfaces]],
                      _local_neighbour(mesh, gfaces, cell_local), ring_cells.size)
    face_pos = np.full(mesh.n_faces, -1, np.int64)
    face_pos[gfaces] = np.arange(gfaces.size)
    pts = np.flatnonzero(pmask)
    plocal = np.full(mesh.points.shape[0], -1, np.int64)
    plocal[pts] = np.arange(pts.size)
    return _Ring(rfaces=rfaces, points=pts, plocal=plocal, pxyz=mesh.points[pts], tfaces=tfaces,
                 cells=ring_cells, cell_local=cell_local, fctr=fctr, farea=farea,
                 face_pos=face_pos, cc=cc)


def _point_cell_pairs(mesh: PolyMesh, ring: _Ring) -> tuple[np.ndarray, np.ndarray]:
    """Each distinct (region point, ring cell) pair that share a face, as local numbers."""
    flat, offs, _ = _gather_face_points(mesh, ring.tfaces)
    sizes = np.diff(offs)
    lab_p = ring.plocal[flat]
    own_rep = np.repeat(ring.cell_local[mesh.owner[ring.tfaces]], sizes)
    nei_rep = np.repeat(_local_neighbour(mesh, ring.tfaces, ring.cell_local), sizes)
    pairs_p = np.concatenate([lab_p, lab_p])
    pairs_c = np.concatenate([own_rep, nei_rep])
    ok = (pairs_p >= 0) & (pairs_c >= 0)
    n_ring = ring.cells.size
    key = np.sort(pairs_p[ok] * np.int64(n_ring) + pairs_c[ok])
    key = key[np.concatenate([[True], key[1:] != key[:-1]])] if key.size else key
    return key // n_ring, key % n_ring


def _point_values(mesh: PolyMesh, ring: _Ring, sub_cells: np.ndarray) -> tuple[PointValues, int]:
    """volPointInterpolation's weights for the region's points (a `PointValues`) and how many
    of those points lie on a proper boundary patch."""
    pp, pc = _point_cell_pairs(mesh, ring)
    # boundary faces among those touching the region points
    bfaces = ring.tfaces[~(ring.tfaces < mesh.n_internal)]
    bvalues = FaceValues.build(mesh, bfaces, ring.farea[ring.face_pos[bfaces]])
    b_ctr = ring.fctr[ring.face_pos[bfaces]]
    bflat, boffs, _ = _gather_face_points(mesh, bfaces)
    bp = ring.plocal[bflat]
    bface_rep = np.repeat(np.arange(bfaces.size), np.diff(boffs))
    bproper_rep = bvalues.proper[bface_rep] & (bp >= 0)
    n = ring.points.size
    is_patch = np.zeros(n, bool)
    is_patch[bp[bproper_rep]] = True
    # interior points: inverse distance to the cell centres
    wsum = np.zeros(n)
    sel = ~is_patch[pp]
    w_int = 1.0 / np.linalg.norm(ring.pxyz[pp[sel]] - ring.cc[pc[sel]], axis=1)
    wsum += np.bincount(pp[sel], weights=w_int, minlength=n)
    # patch points: inverse distance to the proper patch faces' centres, face values
    bpp = bp[bproper_rep]
    bff = bface_rep[bproper_rep]
    w_b = 1.0 / np.linalg.norm(ring.pxyz[bpp] - b_ctr[bff], axis=1)
    wsum += np.bincount(bpp, weights=w_b, minlength=n)
    values = PointValues(mesh=mesh, ring_cells=ring.cells, sub_cells=sub_cells,
                         pair_point=pp[sel], pair_cell=pc[sel], pair_weight=w_int,
                         faces=bvalues, patch_point=bpp, patch_face=bff, patch_weight=w_b,
                         wsum=wsum)
    return values, int(is_patch.sum())


def _region_tets(
    mesh: PolyMesh, ring: _Ring, region_cells: np.ndarray, sub_cells: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The region cells' tetrahedra, `polyMeshTetDecomposition`: `(tet_cell (n,) region
    cell, tet_pts (n, 3) local points base, A, B, cell_tet_offsets (nc + 1,))`, by cell."""
    rfaces = ring.rfaces
    sub_local = np.full(ring.cells.size, -1, np.int64)
    sub_local[sub_cells] = np.arange(region_cells.size)
    fl, fo, _ = _gather_face_points(mesh, rfaces)
    fsz = np.diff(fo)
    base = _base_points(mesh, rfaces, fl, fo, ring.cc, ring.cell_local)
    rown = sub_local[ring.cell_local[mesh.owner[rfaces]]]
    rnei = np.full(rfaces.size, -1, np.int64)
    rint = rfaces < mesh.n_internal
    rnei[rint] = sub_local[ring.cell_local[mesh.neighbour[rfaces[rint]]]]
    ntri = fsz - 2
    fidx = np.repeat(np.arange(rfaces.size), ntri)
    tpt = np.arange(ntri.sum()) - np.repeat(np.cumsum(ntri) - ntri, ntri) + 1  # 1 .. n-2
    b = base[fidx]
    s = fsz[fidx]
    start = fo[:-1][fidx]
    p_base = ring.plocal[fl[start + b]]
    p_a = ring.plocal[fl[start + (b + tpt) % s]]
    p_b = ring.plocal[fl[start + (b + tpt + 1) % s]]
    tets_cell, tets_pts = [], []
    for side, swap in ((rown, False), (rnei, True)):
        cs = side[fidx]
        m = cs >= 0
        tets_cell.append(cs[m])
        if swap:
            tets_pts.append(np.stack([p_base[m], p_b[m], p_a[m]], axis=1))
        else:
            tets_pts.append(np.stack([p_base[m], p_a[m], p_b[m]], axis=1))
    tet_cell = np.concatenate(tets_cell)
    tet_pts = np.concatenate(tets_pts)
    order = np.argsort(tet_cell, kind="stable")
    tet_cell, tet_pts = tet_cell[order], tet_pts[order]
    cto = np.zeros(region_cells.size + 1, np.int64)
    np.cumsum(np.bincount(tet_cell, minlength=region_cells.size), out=cto[1:])
    return tet_cell, tet_pts, cto


def _tet_inverses(
    pxyz: np.ndarray, rcc: np.ndarray, tet_cell: np.ndarray, tet_pts: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Inverse edge matrices `(n, 3, 3)` (from the cell centre) and which tets are not
    degenerate; a degenerate tet's inverse is zero."""
    e = np.stack([pxyz[tet_pts[:, k]] - rcc[tet_cell] for k in range(3)], axis=2)  # (n, 3, 3) columns
    inv, det = _inverse3(e)
    scale = np.max(np.abs(e), axis=(1, 2)) ** 3
    tet_ok = np.abs(det) > 1e-12 * np.maximum(scale, 1e-300)
    inv[~tet_ok] = 0.0
    return inv, tet_ok


def _tet_boxes(
    pxyz: np.ndarray, tet_cell: np.ndarray, tet_pts: np.ndarray, n_cells: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Bounding boxes `(lo, hi)`, `(n_cells, 3)` each, of each cell's tetrahedra."""
    clo = np.full((n_cells, 3), np.inf)
    chi = np.full((n_cells, 3), -np.inf)
    for k in range(3):
        np.minimum.at(clo, tet_cell, pxyz[tet_pts[:, k]])
        np.maximum.at(chi, tet_cell, pxyz[tet_pts[:, k]])
    return clo, chi


def _inverse3(m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverses and determinants of `(n, 3, 3)` matrices (adjugate formula; singular rows
    give inf/nan and are masked by the caller)."""
    a, b, c = m[:, 0, 0], m[:, 0, 1], m[:, 0, 2]
    d, e, f = m[:, 1, 0], m[:, 1, 1], m[:, 1, 2]
    g, h, i = m[:, 2, 0], m[:, 2, 1], m[:, 2, 2]
    A, B, C = e * i - f * h, f * g - d * i, d * h - e * g
    det = a * A + b * B + c * C
    with np.errstate(divide="ignore", invalid="ignore"):
        r = 1.0 / det
        inv = np.empty_like(m)
        inv[:, 0, 0], inv[:, 1, 0], inv[:, 2, 0] = A * r, B * r, C * r
        inv[:, 0, 1] = (c * h - b * i) * r
        inv[:, 1, 1] = (a * i - c * g) * r
        inv[:, 2, 1] = (b * g - a * h) * r
        inv[:, 0, 2] = (b * f - c * e) * r
        inv[:, 1, 2] = (c * d - a * f) * r
        inv[:, 2, 2] = (a * e - b * d) * r
    return inv, det


def _base_points(
    mesh: PolyMesh, faces: np.ndarray, flat: np.ndarray, offs: np.ndarray, cc: np.ndarray,
    cell_local: np.ndarray,
) -> np.ndarray:
    """Tet base point (index within the face) of each face, as `findFaceBasePts`: the first
    face point whose fan of tets is positive (quality > 1e-15) from the owner's centre and,
    for internal faces, from the neighbour's centre."""
    sizes = np.diff(offs)
    base = np.zeros(faces.size, np.int64)
    own_c = cc[cell_local[mesh.owner[faces]]]
    internal = faces < mesh.n_internal
    nei_c = np.full((faces.size, 3), np.nan)
    nl = cell_local[mesh.neighbour[faces[internal]]]
    nei_c[internal] = np.where((nl >= 0)[:, None], cc[np.maximum(nl, 0)], np.nan)
    bad = np.flatnonzero(~_fan_ok(mesh, flat, offs, sizes, base, own_c, nei_c))
    trial = 1
    while bad.size:
        bad = bad[sizes[bad] > trial]
        if not bad.size:
            break
        sub_sizes = sizes[bad]
        sub_offs = np.zeros(bad.size + 1, np.int64)
        np.cumsum(sub_sizes, out=sub_offs[1:])
        sub_flat = flat[np.repeat(offs[bad], sub_sizes) + np.arange(sub_offs[-1])
                        - np.repeat(sub_offs[:-1], sub_sizes)]
        ok = _fan_ok(mesh, sub_flat, sub_offs, sub_sizes, np.full(bad.size, trial), own_c[bad], nei_c[bad])
        base[bad[ok]] = trial
        bad = bad[~ok]
        trial += 1
    return base


def _quality(a, b, c, d):
    """OpenFOAM's tetrahedron::quality: signed volume over that of the regular tet with the
    same circumradius."""
    ba, ca, da = b - a, c - a, d - a
    vol = np.einsum("...i,...i->...", ba, np.cross(ca, da)) / 6.0
    # circumradius
    num = (np.einsum("...i,...i->...", ba, ba)[..., None] * np.cross(ca, da)
           + np.einsum("...i,...i->...", ca, ca)[..., None] * np.cross(da, ba)
           + np.einsum("...i,...i->...", da, da)[..., None] * np.cross(ba, ca))
    denom = 2.0 * np.einsum("...i,...i->...", ba, np.cross(ca, da))
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.linalg.norm(num, axis=-1) / np.abs(denom)
    r = np.where(np.isfinite(r), np.minimum(r, 1e300), 1e300)
    return vol / (8.0 / (9.0 * np.sqrt(3.0)) * np.minimum(r, 1e100) ** 3 + 1e-300)


def _fan_ok(mesh, flat, offs, sizes, base, own_c, nei_c) -> np.ndarray:
    n = sizes.size
    ntri = sizes - 2
    fidx = np.repeat(np.arange(n), ntri)
    tpt = np.arange(ntri.sum()) - np.repeat(np.cumsum(ntri) - ntri, ntri) + 1
    s = sizes[fidx]
    start = offs[:-1][fidx]
    b = base[fidx]
    p0 = mesh.points[flat[start + b]]
    pa = mesh.points[flat[start + (b + tpt) % s]]
    pb = mesh.points[flat[start + (b + tpt + 1) % s]]
    q_own = _quality(own_c[fidx], p0, pa, pb)
    q_nei = _quality(nei_c[fidx], p0, pb, pa)
    q_nei = np.where(np.isnan(nei_c[fidx, 0]), np.inf, q_nei)
    q = np.minimum(q_own, q_nei)
    ok = np.ones(n, bool)
    np.logical_and.at(ok, fidx, q > _MIN_TET_QUALITY)
    return ok


@functools.cache
def _mix_kernel():
    """The numba-compiled barycentric mix of located points' tetrahedra (`values_at`), or
    None without numba."""
    try:
        import numba
    except ImportError:
        return None

    @numba.njit(cache=True, nogil=True)
    def mix(tets, w, tet_cell, tet_pts, cv, pv, out):  # pragma: no cover - compiled
        for n in range(tets.shape[0]):
            t = tets[n]
            if t < 0:
                continue
            c = tet_cell[t]
            p0, p1, p2 = tet_pts[t, 0], tet_pts[t, 1], tet_pts[t, 2]
            for a in range(3):
                out[n, a] = (w[n, 0] * cv[c, a] + w[n, 1] * pv[p0, a] + w[n, 2] * pv[p1, a]
                             + w[n, 3] * pv[p2, a])

    return mix


@functools.cache
def _grid_kernel():
    """The numba-compiled tet-to-grid scatter, or None without numba: for every node inside
    a tetrahedron, its values (`out`), or with `locations` the tetrahedron's number and the
    barycentric weights (`tet_out`, `w_out`); the arrays not written may be dummies."""
    try:
        import numba
    except ImportError:
        return None

    @numba.njit(cache=True, nogil=True)
    def kernel(centre, inv, tet_id, vc, vp, i0, i1, ax, ay, az, out, tet_out, w_out,
               locations):  # pragma: no cover - compiled
        tol = _INSIDE_TOL
        for t in range(centre.shape[0]):
            for i in range(i0[t, 0], i1[t, 0]):
                rx = ax[i] - centre[t, 0]
                for j in range(i0[t, 1], i1[t, 1]):
                    ry = ay[j] - centre[t, 1]
                    for k in range(i0[t, 2], i1[t, 2]):
                        rz = az[k] - centre[t, 2]
                        l1 = inv[t, 0, 0] * rx + inv[t, 0, 1] * ry + inv[t, 0, 2] * rz
                        if l1 < -tol:
                            continue
                        l2 = inv[t, 1, 0] * rx + inv[t, 1, 1] * ry + inv[t, 1, 2] * rz
                        if l2 < -tol:
                            continue
                        l3 = inv[t, 2, 0] * rx + inv[t, 2, 1] * ry + inv[t, 2, 2] * rz
                        if l3 < -tol:
                            continue
                        l0 = 1.0 - l1 - l2 - l3
                        if l0 < -tol:
                            continue
                        if locations:
                            tet_out[i, j, k] = tet_id[t]
                            w_out[i, j, k, 0] = l0
                            w_out[i, j, k, 1] = l1
                            w_out[i, j, k, 2] = l2
                            w_out[i, j, k, 3] = l3
                        else:
                            for c in range(3):
                                out[i, j, k, c] = (l0 * vc[t, c] + l1 * vp[t, 0, c]
                                                   + l2 * vp[t, 1, c] + l3 * vp[t, 2, c])

    return kernel
