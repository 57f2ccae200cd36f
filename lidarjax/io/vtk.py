"""VTK unstructured grids (`.vtu`, legacy `.vtk`, `.vtm` multiblock), sampled inside their
own cells.

`foamToVTK` and ParaView write a CFD solution as an unstructured grid: cells (tetrahedra,
hexahedra, prisms, pyramids, polyhedra), cell data (the solver's cell values) and point
data (values interpolated to the mesh points; `foamToVTK`'s are OpenFOAM's own
`volPointInterpolation`). lidarjax turns the cells into a face-based mesh (faces shared by
two cells found by their vertices) and samples it with the same cellPoint interpolation as
OpenFOAM cases (`lidarjax.io.openfoam`, `lidarjax.io._cells`): each cell cut into
tetrahedra (cell centre, two points of a face and the face's base point), values mixed from
the cell value at the cell centre and the point values at the corners. So a `foamToVTK`
export of the internal mesh with both cell and point data samples as OpenFOAM's `probes`
(`interpolationScheme cellPoint`) would, and no value is ever interpolated across a solid:
points in no cell are NaN.

- cell and point data: used as they are;
- cell data only: point values by inverse-distance weighting of the surrounding cell
  centres (OpenFOAM's interior rule; boundary points take their cells' values, so a wall's
  no-slip value is not seen);
- point data only: the cell value is the mean of the cell's point values.

`.vtu` files are read by a small reader of VTK's XML format here (inline ascii or base64
binary, optionally zlib-compressed, and appended raw or base64 data; polyhedra included,
which meshio cannot mix with other cells); legacy `.vtk` files with meshio (`pip install
lidarjax[meshio]`; its parser walks polyhedra cell by cell, the faces are then matched here
at once as for `.vtu`: for a large polyhedral mesh write `.vtu` instead, `foamToVTK -legacy
off`). Only the velocity arrays are decoded, and the faces are matched and
oriented for all cells at once (no loop per cell or face): the 185,237-cell `foamToVTK`
export of the v1912 `windAroundBuildings` tutorial reads in 0.8-1.7 s of CPU time
(`benchmarks/results/cfd_ingest_vtk.md`). `.vtm` multiblock files are read directly (XML) and every volume block
(`.vtu`, `.vtk`) they list is merged; surface blocks (`.vtp`, boundary patches) are
skipped.

Two limits of the format, measured on real `foamToVTK` (v1912) output: its points are
float32, so at UTM coordinates the mesh moves by up to 0.25-0.5 m (on `turbineSiting`,
sampled velocities then differ from the case's own by up to 2.1 m/s next to the terrain,
0.04 m/s rms); and a VTK hexahedron does not keep the point order of OpenFOAM's faces, which
sets where OpenFOAM cuts a cell into tetrahedra, so inside cells the piecewise-linear
interpolant may differ from OpenFOAM's own (cell centres, cell and point values are the
same). Read the OpenFOAM case itself where it is at hand. Velocity is the point/cell array named
`U` (or `velocity`, `Velocity`, `V`, case-insensitive) with three components, in m/s in
the CFD frame; coordinates in metres.
"""

from __future__ import annotations

import base64
import dataclasses
import os
import re
import xml.etree.ElementTree as ET
import zlib
from pathlib import Path

import numpy as np

from .._util import PathLike, import_optional
from ._cells import (
    BoundaryValues,
    CellPointSampler,
    PolyMesh,
    _faces_of_cells,
    _gather_face_points,
    build_sampler,
)
from .openfoam import OpenFOAMField

__all__ = ["VTK_SUFFIXES", "VTKField", "read_vtk_field"]

VTK_SUFFIXES = (".vtu", ".vtk", ".vtm")
_NAMES = ("u", "velocity", "v", "vel")

# outward-or-inward faces of the linear VTK cells (orientation is fixed numerically)
_FACES = {
    "tetra": ((0, 1, 3), (1, 2, 3), (2, 0, 3), (0, 2, 1)),
    "hexahedron": ((0, 4, 7, 3), (1, 2, 6, 5), (0, 1, 5, 4), (3, 7, 6, 2), (0, 3, 2, 1), (4, 5, 6, 7)),
    "wedge": ((0, 1, 2), (3, 5, 4), (0, 3, 4, 1), (1, 4, 5, 2), (2, 5, 3, 0)),
    "pyramid": ((0, 3, 2, 1), (0, 1, 4), (1, 2, 4), (2, 3, 4), (3, 0, 4)),
}


@dataclasses.dataclass(frozen=True, eq=False)
class VTKField(OpenFOAMField):
    """A VTK unstructured grid ready for cellPoint sampling (an `OpenFOAMField` whose point
    values, when the file has them, are the file's own). `point_values`: ``(P, 3)`` or None."""

    point_values: np.ndarray | None = None

    def sampler(self, cells: np.ndarray | None = None) -> CellPointSampler:
        if cells is None:
            cells = np.arange(self.mesh.n_cells)
        cells = np.asarray(cells, np.int64)
        s = build_sampler(self.mesh, self.cell_values, self.boundary, cells, self.bounds)
        if self.point_values is None:
            return s
        # the points build_sampler used, in its order: those of the region cells' faces
        in_region = np.zeros(self.mesh.n_cells, bool)
        in_region[cells] = True
        flat, _, _ = _gather_face_points(self.mesh, _faces_of_cells(self.mesh, in_region))
        pmask = np.zeros(self.mesh.points.shape[0], bool)
        pmask[flat] = True
        return dataclasses.replace(s, point_value=self.point_values[np.flatnonzero(pmask)])


def _pick(data: dict, what: str, path: Path) -> np.ndarray | None:
    for key, arr in data.items():
        if arr is not None and str(key).lower() in _NAMES:
            a = np.asarray(arr, np.float64)
            if a.ndim == 2 and a.shape[1] >= 3:
                return a[:, :3]
    return None


def _blocks(path: Path) -> list[Path]:
    if path.suffix.lower() != ".vtm":
        return [path]
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as err:
        raise ValueError(f"{os.fspath(path)}: not a readable .vtm multiblock file ({err})") from None
    files = [Path(path.parent, d.get("file")) for d in root.iter("DataSet") if d.get("file")]
    vol = [f for f in files if f.suffix.lower() in (".vtu", ".vtk")]
    if not vol:
        raise ValueError(f"{os.fspath(path)}: the multiblock lists no volume (.vtu/.vtk) block; "
                         f"found {', '.join(f.name for f in files) or 'none'}")
    missing = [os.fspath(f) for f in vol if not f.is_file()]
    if missing:
        raise FileNotFoundError(f"{os.fspath(path)}: block file(s) not found: {', '.join(missing)}")
    return vol


def _cell_faces(mesh, path: Path):
    """Per face occurrence: owning cell, padded vertex ids (column-major ``(k, n)``), sizes;
    plus the per-cell data blocks and cell count."""
    cells_faces, cell_ids, sizes = [], [], []
    n_cells = 0
    kept_blocks = []
    for b, block in enumerate(mesh.cells):
        ctype = block.type
        if ctype in _FACES:
            conn = np.asarray(block.data, np.int64)
            for face in _FACES[ctype]:
                f = conn[:, face]
                cells_faces.append(f)
                cell_ids.append(n_cells + np.arange(conn.shape[0]))
                sizes.append(np.full(conn.shape[0], len(face)))
            kept_blocks.append(b)
            n_cells += conn.shape[0]
        elif ctype.startswith("polyhedron"):
            # every face of every cell at once, padded as the .vtu reader pads its faces
            per_cell = np.fromiter((len(faces) for faces in block.data), np.int64,
                                   count=len(block.data))
            flat = [face for faces in block.data for face in faces]
            size = np.fromiter((len(face) for face in flat), np.int64, count=len(flat))
            if size.size:
                stream = np.concatenate([np.asarray(face, np.int64).reshape(-1) for face in flat])
                col = np.arange(int(size.max()))
                inside = col[None, :] < size[:, None]
                start = np.concatenate([[0], np.cumsum(size)[:-1]])
                cells_faces.append(np.where(inside, stream[np.where(inside, start[:, None] + col, 0)],
                                            -1))
                cell_ids.append(n_cells + np.repeat(np.arange(per_cell.size), per_cell))
                sizes.append(size)
            kept_blocks.append(b)
            n_cells += len(block.data)
        # vertices, lines, surface cells: not part of the volume mesh
    if n_cells == 0:
        raise ValueError(f"{os.fspath(path)}: no volume cells (tetra, hexahedron, wedge, pyramid, "
                         "polyhedron) in the file")
    width = max(f.shape[1] for f in cells_faces)
    pad = np.concatenate([np.pad(f, ((0, 0), (0, width - f.shape[1])), constant_values=-1)
                          for f in cells_faces])
    return _label_type(pad.T, mesh.points.shape[0]), np.concatenate(cell_ids), np.concatenate(sizes), \
        n_cells, kept_blocks


def _label_type(pad: np.ndarray | None, n_points: int):
    """Point labels as int32 where they fit (half the memory traffic), else int64: the
    dtype, or `pad` converted to it."""
    dtype = np.dtype(np.int32 if n_points < 2**31 - 1 else np.int64)
    return dtype if pad is None else pad.astype(dtype)


def _sorted_rows(pad: np.ndarray, sizes: np.ndarray, fill: int) -> np.ndarray:
    """The vertex ids of each face (column `i` of `pad` `(k, n)`, `-1` beyond `sizes[i]`)
    sorted, the padding as `fill` (above every id): row `j` of the result holds the `j`-th
    smallest ids. Triangles and quads are sorted by a sorting network, the others by
    `np.sort`."""
    key = np.where(pad < 0, pad.dtype.type(fill), pad)
    small = sizes <= 4
    cols = min(4, key.shape[0])
    rows = None if small.all() else np.flatnonzero(small)
    k = key[:cols] if rows is None else key[:cols, rows]
    if cols == 4:
        for i, j in ((0, 1), (2, 3), (0, 2), (1, 3), (1, 2)):
            lo = np.minimum(k[i], k[j])
            np.maximum(k[i], k[j], out=k[j])
            k[i] = lo
    else:
        k = np.sort(k, axis=0)
    if rows is not None:
        key[:cols, rows] = k
        big = np.flatnonzero(~small)
        key[:, big] = np.sort(key[:, big], axis=0)
    return key


def _unique_rows(key: np.ndarray, n_points: int) -> tuple[np.ndarray, np.ndarray]:
    """Group equal rows of a table given column-major (`key` `(k, n)`: row `i` of the table
    is `key[:, i]`, sorted, every id in `0..n_points`, `n_points` being the padding):
    `(order, group)`, `order` sorting the rows lexicographically (stable, so
    `np.unique(table, axis=0)`'s order) and `group[i]` the unique-row number of row
    `order[i]`.

    Rows are packed a few ids per int64 (order kept) and sorted on the packs covering their
    three smallest ids, which mostly tell two faces of a mesh apart; runs of equal such
    packs are then ordered by their other ids and row number, a pair by a swap, longer runs
    (or pairs differing beyond) by a small lexsort."""
    width, n = key.shape
    if n == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    base = np.int64(n_points) + 1
    per = max(1, int(np.floor(62 * np.log(2) / np.log(float(base)))))

    def pack(j: int, rows=slice(None)) -> np.ndarray:
        k = key[j, rows].astype(np.int64)
        for c in range(j + 1, min(j + per, width)):
            k *= base
            k += key[c, rows]
        return k

    packs = list(range(0, width, per))
    n_primary = min(len(packs), -(-3 // per))
    primary, rest = packs[:n_primary], packs[n_primary:]
    if n_primary == 1:
        k0 = pack(0)
        order = k0.argsort()  # not stable: equal keys are put in row order below
        ks = k0[order]
        tie = ks[1:] == ks[:-1]
    else:
        order = np.lexsort([pack(j) for j in primary][::-1])
        tie = np.ones(n - 1, bool)
        for j in primary:
            ks = pack(j, order)
            tie &= ks[1:] == ks[:-1]
    at = np.flatnonzero(tie)
    if at.size:
        # pairs (runs of two) alike beyond the primary ids: row order by a swap; other runs:
        # ordered by (other ids, row)
        padded = np.r_[False, tie, False]
        hard = padded[at] | padded[at + 2]  # the pair's run is longer than two
        if rest:
            c0 = packs[n_primary]
            hard |= np.any(key[c0:, order[at]] != key[c0:, order[at + 1]], axis=0)
        easy = at[~hard]
        swap = easy[order[easy] > order[easy + 1]]
        order[swap], order[swap + 1] = order[swap + 1], order[swap].copy()
        if hard.any():
            run = np.zeros(n, np.int64)
            np.cumsum(~tie, out=run[1:])
            flagged = np.zeros(int(run[-1]) + 1, bool)
            flagged[run[at[hard]]] = True
            pos = np.flatnonzero(flagged[run])
            sub = order[pos]
            perm = np.lexsort([sub] + [pack(j, sub) for j in rest][::-1] + [run[pos]])
            sub = sub[perm]
            order[pos] = sub
            same = np.ones(pos.size - 1, bool)
            for j in rest:
                ks = pack(j, sub)
                same &= ks[1:] == ks[:-1]
            inner = run[pos[1:]] == run[pos[:-1]]  # both in the same primary run
            tie[pos[:-1][inner]] = same[inner]
    group = np.zeros(n, np.int64)
    np.cumsum(~tie, out=group[1:])
    return order, group


def _face_centre_normal(points: np.ndarray, pad: np.ndarray, faces: np.ndarray, nv: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Vertex mean `fc` `(n, 3)` of each face (columns `faces` of the padded vertex ids `pad`
    `(k, m)`, the first `nv[i]` valid) and twice its area vector: the sum over its edges of
    ``(p_j - fc) x (p_next - fc)``; both summed vertex by vertex, in the face's order.

    A vertex column most faces have is computed for all faces and added where valid (so
    each valid sum is the plain one); a column few faces have, for those faces only."""
    n = faces.size
    xyz = np.ascontiguousarray(points.T)
    cols = []  # per vertex column j: (valid mask, or None if all; sparse row ids or None; points)
    acc = np.zeros((3, n))
    for j in range(pad.shape[0]):
        valid = nv > j
        count = int(np.count_nonzero(valid))
        if count == 0:
            break
        if 4 * count > n:  # dense: every face, padding read as point -1
            mask, rows = (None if count == n else valid), None
            ids = pad[j, faces]
        else:
            mask, rows = valid, np.flatnonzero(valid)
            ids = pad[j, faces[rows]]
        pj = np.stack([xyz[a][ids] for a in range(3)])
        cols.append((mask, rows, pj))
        _add_column(acc, j, mask, rows, pj)
    fc = acc / nv
    d = [pj - (fc if rows is None else fc[:, rows]) for _, rows, pj in cols]
    normal = np.zeros((3, n))
    for j, (mask, rows, _) in enumerate(cols):
        # the next vertex: column j + 1 where the face has one, else the first vertex
        if j + 1 == len(cols):
            nxt = d[0] if rows is None else d[0][:, rows]
        else:
            mask1, rows1, _ = cols[j + 1]
            if rows is None and rows1 is None:
                nxt = d[j + 1] if mask1 is None else np.where(mask1, d[j + 1], d[0])
            elif rows is None:  # the next column is sparse
                nxt = d[0].copy()
                nxt[:, rows1] = d[j + 1]
            else:  # both sparse: the next column's rows are a subset of these, in order
                nxt = d[0][:, rows]
                nxt[:, nv[rows] > j + 1] = d[j + 1]
        a, b = d[j], nxt
        term = np.stack([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])
        _add_column(normal, j, mask, rows, term)
    return fc.T, normal.T


def _add_column(acc: np.ndarray, j: int, mask: np.ndarray | None, rows: np.ndarray | None,
                value: np.ndarray) -> None:
    """`acc (3, n) += value` over the faces vertex column `j` covers (`rows` when sparse,
    else every face or those of `mask`); column 0 sets `acc`."""
    if j == 0:
        acc[:] = value
    elif rows is not None:
        acc[:, rows] += value
    elif mask is None:
        acc += value
    else:
        np.add(acc, value, out=acc, where=mask)


def _poly_mesh(points: np.ndarray, pad, cell_of, sizes, n_cells, path: Path) -> PolyMesh:
    """The face-based mesh of the cells' faces (`pad` `(k, n)`: one column of vertex ids per
    face of each cell, padded with -1, `cell_of` its cell): each face once, owned by the
    lower cell number and oriented out of it, internal faces first (by owner), then the
    boundary faces."""
    key = _sorted_rows(pad, sizes, points.shape[0])
    order, group = _unique_rows(key, points.shape[0])
    n_faces = int(group[-1]) + 1 if group.size else 0
    counts = np.bincount(group, minlength=n_faces)
    if np.any(counts > 2):
        raise ValueError(f"{os.fspath(path)}: {int((counts > 2).sum())} faces are shared by more "
                         "than two cells; the grid is not a valid volume mesh")
    starts = np.flatnonzero(np.r_[True, group[1:] != group[:-1]])
    cell_sorted = cell_of[order]
    owner = np.minimum.reduceat(cell_sorted, starts)
    neighbour = np.maximum.reduceat(cell_sorted, starts)
    neighbour[counts == 1] = -1
    # the owner's (first) occurrence gives the vertex order; orient it out of the owner
    own_pos = np.flatnonzero(cell_sorted == owner[group])
    first = np.r_[True, group[own_pos[1:]] != group[own_pos[:-1]]]
    occ = order[own_pos[first]]
    nv = sizes[occ]
    fc, normal = _face_centre_normal(points, pad, occ, nv)
    # an interior point of each cell: the mean of its face centres
    centroid = np.zeros((n_cells, 3))
    count = np.bincount(owner, minlength=n_cells) + np.bincount(neighbour[neighbour >= 0],
                                                                minlength=n_cells)
    for a in range(3):
        centroid[:, a] = (np.bincount(owner, weights=fc[:, a], minlength=n_cells)
                          + np.bincount(neighbour[neighbour >= 0], weights=fc[neighbour >= 0, a],
                                        minlength=n_cells))
    centroid /= np.maximum(count, 1)[:, None]
    flip = np.einsum("ij,ij->i", normal, fc - centroid[owner]) < 0
    internal = neighbour >= 0
    order = np.concatenate([np.flatnonzero(internal)[np.argsort(owner[internal], kind="stable")],
                            np.flatnonzero(~internal)])
    occ, nv, flip = occ[order], nv[order], flip[order]
    offsets = np.zeros(order.size + 1, np.int64)
    np.cumsum(nv, out=offsets[1:])
    # the labels face by face, flipped faces read backwards
    face = np.repeat(np.arange(order.size), nv)
    j = np.arange(offsets[-1]) - offsets[:-1][face]
    j = np.where(flip[face], nv[face] - 1 - j, j)
    labels = pad[j, occ[face]].astype(np.int64)
    n_int = int(internal.sum())
    return PolyMesh(points=points, face_offsets=offsets, face_labels=labels, owner=owner[order],
                    neighbour=neighbour[order][:n_int], n_cells=n_cells,
                    patches=(("boundary", "patch", n_int, int(order.size - n_int)),))


_VTK_TYPES = {"Float32": "<f4", "Float64": "<f8", "Int8": "<i1", "UInt8": "<u1", "Int16": "<i2",
              "UInt16": "<u2", "Int32": "<i4", "UInt32": "<u4", "Int64": "<i8", "UInt64": "<u8"}
_VTK_CELL_FACES = {10: "tetra", 12: "hexahedron", 13: "wedge", 14: "pyramid"}
_VTK_CELL_NODES = {"tetra": 4, "hexahedron": 8, "wedge": 6, "pyramid": 5}


class _VtuReader:
    """Just enough of VTK's XML UnstructuredGrid format: inline ascii / binary (base64,
    optionally zlib-compressed) and appended (raw or base64) data arrays."""

    def __init__(self, path: Path):
        self.path, self._b64, self._zlib = path, base64, zlib
        data = path.read_bytes()
        self.appended = b""
        self.appended_b64 = False
        k = data.find(b"<AppendedData")
        if k >= 0:
            head_end = data.index(b">", k)
            self.appended_b64 = b"base64" in data[k:head_end]
            start = data.index(b"_", head_end) + 1
            stop = data.rfind(b"</AppendedData>")
            self.appended = data[start: stop if stop > 0 else len(data)]
            if self.appended_b64:
                self.appended = self.appended.strip()
            data = data[:k] + b"</VTKFile>"
        # the XML tree is parsed without the arrays' text (most of the file): each inline
        # DataArray keeps the span of its text in `data`, read when the array is decoded
        self.data, self.spans, parts, pos = data, [], [], 0
        for m in re.finditer(rb"<DataArray\b[^>]*>", data):
            if m.group().endswith(b"/>") or m.start() < pos:
                continue
            end = data.find(b"</DataArray>", m.end())
            if end < 0:
                break
            parts += [data[pos: m.end() - 1], b" lidarjax_text='%d'>" % len(self.spans)]
            self.spans.append((m.end(), end))
            pos = end
        parts.append(data[pos:])
        try:
            self.root = ET.fromstring(b"".join(parts))
        except ET.ParseError as err:
            raise ValueError(f"{os.fspath(path)}: not a readable VTK XML file ({err})") from None
        if self.root.get("type") != "UnstructuredGrid":
            raise ValueError(f"{os.fspath(path)}: a VTK {self.root.get('type')} file; expected an "
                             "UnstructuredGrid (.vtu)")
        self.header = np.dtype("<u8" if self.root.get("header_type") == "UInt64" else "<u4")
        if self.root.get("byte_order", "LittleEndian") != "LittleEndian":
            self.header = self.header.newbyteorder(">")
        self.compressed = self.root.get("compressor") is not None
        self.big = self.root.get("byte_order") == "BigEndian"

    def _decode(self, raw: bytes, dtype: np.dtype) -> np.ndarray:
        h = self.header
        if not self.compressed:
            n = int(np.frombuffer(raw[: h.itemsize], h)[0])
            return np.frombuffer(raw[h.itemsize: h.itemsize + n], dtype)
        nb = int(np.frombuffer(raw[: h.itemsize], h)[0])
        head = np.frombuffer(raw[: h.itemsize * (3 + nb)], h)
        sizes = head[3:]
        pos = h.itemsize * (3 + nb)
        out = []
        for c in sizes:
            out.append(self._zlib.decompress(raw[pos: pos + int(c)]))
            pos += int(c)
        return np.frombuffer(b"".join(out), dtype)

    def _b64_blocks(self, text: bytes, dtype: np.dtype) -> np.ndarray:
        b64 = self._b64
        h = self.header
        if not self.compressed:
            return self._decode(b64.b64decode(text), dtype)
        # header and data are encoded separately; the header's length follows its first word
        first = b64.b64decode(text[: 4 * ((h.itemsize + 2) // 3 + 1)])
        nb = int(np.frombuffer(first[: h.itemsize], h)[0])
        hlen = 4 * ((h.itemsize * (3 + nb) + 2) // 3)
        head = b64.b64decode(text[:hlen])
        return self._decode(head + b64.b64decode(text[hlen:]), dtype)

    def array(self, el) -> np.ndarray:
        dtype = np.dtype(_VTK_TYPES[el.get("type")])
        if self.big:
            dtype = dtype.newbyteorder(">")
        fmt = el.get("format", "ascii")
        span = el.get("lidarjax_text")
        text = (el.text or "").encode() if span is None else self.data[slice(*self.spans[int(span)])]
        if fmt == "ascii":
            a = np.array(text.decode().split(), dtype=np.float64).astype(dtype)
        elif fmt == "binary":
            # base64 decoding skips whitespace; the compressed layout needs it removed first
            a = self._b64_blocks(text.translate(None, b" \t\r\n") if self.compressed else text, dtype)
        elif fmt == "appended":
            off = int(el.get("offset"))
            if self.appended_b64:
                a = self._b64_blocks(self.appended[off:], dtype)
            else:
                a = self._decode(self.appended[off:], dtype)
        else:
            raise ValueError(f"{os.fspath(self.path)}: unknown DataArray format {fmt!r}")
        nc = int(el.get("NumberOfComponents", "1"))
        return a.reshape(-1, nc) if nc > 1 else a

    def arrays(self, section: str) -> dict[str, np.ndarray]:
        piece = self.root.find("UnstructuredGrid/Piece")
        node = piece.find(section) if piece is not None else None
        if node is None:
            return {}
        return {el.get("Name", ""): el for el in node.findall("DataArray")}


def _is_velocity(name: str, el) -> bool:
    """Whether a DataArray element may be the velocity (as `_pick` would take it)."""
    return str(name).lower() in _NAMES and int(el.get("NumberOfComponents", "1")) >= 3


def _polyhedron_faces(stream: np.ndarray, starts: np.ndarray, cells: np.ndarray, path: Path
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The faces of VTK polyhedra from the `faces` stream (per cell: face count, then per
    face its vertex count and vertex ids), walked for all cells at once, one face per step.

    **Returns:** `(start, size, cell)` per face: position of its first vertex id in
    `stream`, its vertex count and its cell (from `cells`), cell by cell, faces in stream
    order."""
    bad = ValueError(f"{os.fspath(path)}: the polyhedron face stream ('faces', 'faceoffsets') "
                     "is inconsistent")
    n_stream = stream.size
    if starts.size and (starts.max() >= n_stream or starts.min() < 0):
        raise bad
    n_faces = stream[starts]
    if n_faces.size and n_faces.min() < 1:
        raise bad
    pos = starts + 1
    f_start, f_size, f_cell, f_k = [], [], [], []
    live = np.arange(cells.size)
    for k in range(int(n_faces.max()) if n_faces.size else 0):
        live = live[n_faces[live] > k]
        at = pos[live]
        if at.max() >= n_stream:
            raise bad
        n = stream[at]
        if n.min() < 3 or (at + n).max() >= n_stream:
            raise bad
        f_start.append(at + 1)
        f_size.append(n)
        f_cell.append(live)
        f_k.append(np.full(live.size, k))
        pos[live] = at + 1 + n
    f_cell_i = np.concatenate(f_cell)
    order = np.lexsort((np.concatenate(f_k), f_cell_i))
    return np.concatenate(f_start)[order], np.concatenate(f_size)[order], cells[f_cell_i[order]]


def _read_vtu(path: Path):
    r = _VtuReader(path)
    pts_el = r.arrays("Points")
    if not pts_el:
        raise ValueError(f"{os.fspath(path)}: no Points in the UnstructuredGrid")
    points = np.asarray(r.array(next(iter(pts_el.values()))), np.float64).reshape(-1, 3)
    cells = r.arrays("Cells")
    try:
        conn = r.array(cells["connectivity"]).astype(np.int64)
        offs = r.array(cells["offsets"]).astype(np.int64)
        types = r.array(cells["types"]).astype(np.int64)
    except KeyError as err:
        raise ValueError(f"{os.fspath(path)}: Cells lack the {err} array") from None
    starts = np.concatenate([[0], offs[:-1]])
    face_parts, cell_parts, size_parts = [], [], []
    keep = np.zeros(types.size, bool)
    for code, name in _VTK_CELL_FACES.items():
        sel = np.flatnonzero(types == code)
        if sel.size == 0:
            continue
        keep[sel] = True
        nodes = conn[starts[sel][:, None] + np.arange(_VTK_CELL_NODES[name])]
        for face in _FACES[name]:
            face_parts.append(nodes[:, face])
            cell_parts.append(sel)
            size_parts.append(np.full(sel.size, len(face)))
    poly = np.flatnonzero(types == 42)
    poly_part = None
    if poly.size:
        if "faces" not in cells or "faceoffsets" not in cells:
            raise ValueError(f"{os.fspath(path)}: polyhedral cells without faces/faceoffsets")
        stream = r.array(cells["faces"]).astype(np.int64)
        foffs = r.array(cells["faceoffsets"]).astype(np.int64)
        fstarts = np.concatenate([[0], np.maximum.accumulate(np.maximum(foffs, 0))[:-1]])
        f_start, f_size, f_cell = _polyhedron_faces(stream, fstarts[poly], poly, path)
        width_p = int(f_size.max())
        col = np.arange(width_p)
        inside = col[None, :] < f_size[:, None]
        poly_part = np.where(inside, stream[np.where(inside, f_start[:, None] + col, 0)], -1)
        face_parts.append(poly_part)
        cell_parts.append(f_cell)
        size_parts.append(f_size)
        keep[poly] = True
    if not keep.any():
        raise ValueError(f"{os.fspath(path)}: no volume cells (tetra, hexahedron, wedge, pyramid, "
                         "polyhedron)")
    # number the kept (volume) cells 0..n-1
    new = np.cumsum(keep) - 1
    width = max(f.shape[1] for f in face_parts)
    for f in face_parts:
        ids = f[f >= 0] if f is poly_part else f
        if ids.size and (ids.max() >= points.shape[0] or ids.min() < 0):
            raise ValueError(f"{os.fspath(path)}: cell connectivity refers to points outside the "
                             f"{points.shape[0]} points of the file")
    pad = np.full((width, sum(f.shape[0] for f in face_parts)), -1, _label_type(None, points.shape[0]))
    row = 0
    for f in face_parts:
        pad[: f.shape[1], row: row + f.shape[0]] = f.T
        row += f.shape[0]
    cell_of = new[np.concatenate(cell_parts)]
    sizes = np.concatenate(size_parts)
    # decode only the velocity candidates (the other arrays are listed by name)
    pdata = {k: r.array(v) if _is_velocity(k, v) else None for k, v in r.arrays("PointData").items()}
    cdata = {k: r.array(v)[keep] if _is_velocity(k, v) else None
             for k, v in r.arrays("CellData").items()}
    return points, pad, cell_of, sizes, int(keep.sum()), pdata, cdata


def _read_legacy(path: Path):
    meshio = import_optional("meshio", "meshio", "Reading legacy .vtk files")
    try:
        m = meshio.read(path, file_format="vtk")
    except Exception as err:  # meshio raises many types for unreadable files
        raise ValueError(f"{os.fspath(path)}: not a readable legacy VTK file ({err}); write "
                         f".vtu instead (foamToVTK -legacy off)") from None
    pad, cell_of, sizes, nc, kept = _cell_faces(m, path)
    cdata = {}
    for key, blocks in m.cell_data.items():
        parts = [np.asarray(blocks[b]) for b in kept]
        cdata[str(key)] = np.concatenate(parts)
    return (np.asarray(m.points, np.float64)[:, :3], pad, cell_of, sizes, nc,
            {str(k): np.asarray(v) for k, v in m.point_data.items()}, cdata)



def _cat(parts: list[np.ndarray]) -> np.ndarray:
    return parts[0] if len(parts) == 1 else np.concatenate(parts)


def read_vtk_field(path: PathLike) -> VTKField:
    """Read a `.vtu`, legacy `.vtk` or `.vtm` file's volume cells and velocity (see the
    module docstring). Raises `ValueError` naming the file for a file without volume cells
    or without a three-component velocity array (listing the arrays found)."""
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"VTK file not found: {os.fspath(p)}")
    pts_all, pad_all, cell_all, size_all, cval_all, pval_all = [], [], [], [], [], []
    n_pts = n_cells = 0
    for f in _blocks(p):
        reader = _read_vtu if f.suffix.lower() == ".vtu" else _read_legacy
        points_f, pad, cell_of, sizes, nc, pdata, cdata = reader(f)
        pv, cv = _pick(pdata, "point", f), _pick(cdata, "cell", f)
        if pv is None and cv is None:
            found = sorted(set(pdata) | set(cdata))
            raise ValueError(f"{os.fspath(f)}: no velocity array (U, velocity, V with 3 "
                             f"components) in the point or cell data; found {', '.join(found) or 'none'}")
        pts_all.append(points_f)
        pad_all.append(pad if n_pts == 0 else np.where(pad >= 0, pad.astype(np.int64) + n_pts, -1))
        cell_all.append(cell_of + n_cells)
        size_all.append(sizes)
        cval_all.append(cv)
        pval_all.append(pv)
        n_pts += points_f.shape[0]
        n_cells += nc
    points = _cat(pts_all)
    if len(pad_all) == 1:
        pad = pad_all[0]
    else:
        width = max(b.shape[0] for b in pad_all)
        pad = _label_type(np.concatenate([np.pad(a.astype(np.int64), ((0, width - a.shape[0]), (0, 0)),
                                                 constant_values=-1) for a in pad_all], axis=1),
                          points.shape[0])
    cell_of, sizes = _cat(cell_all), _cat(size_all)
    mesh = _poly_mesh(points, pad, cell_of, sizes, n_cells, p)
    have_points = all(v is not None for v in pval_all)
    point_values = _cat(pval_all) if have_points else None
    if all(v is not None for v in cval_all):
        cell_values = _cat(cval_all)
    elif point_values is not None:  # mean of the cell's points (each point counted once)
        valid = pad >= 0
        flat_cell = np.broadcast_to(cell_of, pad.shape)[valid]
        flat_pt = pad[valid].astype(np.int64)
        pairs = np.unique(flat_cell * np.int64(points.shape[0]) + flat_pt)
        c, q = pairs // points.shape[0], pairs % points.shape[0]
        cell_values = np.zeros((n_cells, 3))
        np.add.at(cell_values, c, point_values[q])
        cell_values /= np.bincount(c, minlength=n_cells)[:, None]
    else:
        raise ValueError(f"{os.fspath(p)}: blocks mix cell-data-only and point-data-only velocity")
    return VTKField(case=p, time="", field="U", mesh=mesh, cell_values=cell_values,
                    boundary=BoundaryValues({"boundary": "cell"}), point_values=point_values)
