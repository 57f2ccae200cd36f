"""Writing small OpenFOAM cases: structured hex meshes (with solid blocks) and vector fields.

Private helper of the tests and `benchmarks/cfd_ingest.py` (synthetic graded meshes with a
known exact field). Writes `constant/polyMesh/{points,faces,owner,neighbour,boundary}` and
`<time>/U` in ASCII or binary (`arch "LSB;label=32;scalar=64"`), optionally gzipped.
"""

from __future__ import annotations

import gzip
from pathlib import Path
from typing import Any

import numpy as np

__all__: list[str] = []

_BANNER = "/*--------------------------------*- C++ -*----------------------------------*\\\n" \
          "  written by lidarjax (test/benchmark helper)\n" \
          "\\*---------------------------------------------------------------------------*/\n"


def _header(cls: str, obj: str, binary: bool, location: str, note: str = "") -> bytes:
    fmt = "binary" if binary else "ascii"
    extra = f'    note        "{note}";\n' if note else ""
    return (f'{_BANNER}FoamFile\n{{\n    version     2.0;\n    format      {fmt};\n'
            f'    arch        "LSB;label=32;scalar=64";\n    class       {cls};\n'
            f'    location    "{location}";\n{extra}    object      {obj};\n}}\n\n').encode()


def _list_bytes(arr: np.ndarray, binary: bool, label: bool) -> bytes:
    arr = np.asarray(arr)
    n = arr.shape[0]
    if binary:
        dt = "<i4" if label else "<f8"
        return f"{n}\n(".encode() + np.ascontiguousarray(arr, dtype=dt).tobytes() + b")\n"
    if arr.ndim == 1:
        body = "\n".join(str(int(v)) if label else repr(float(v)) for v in arr)
    else:
        fmt = "({})"
        body = "\n".join(fmt.format(" ".join(repr(float(x)) for x in row)) for row in arr)
    return f"{n}\n(\n{body}\n)\n".encode()


def _write(path: Path, data: bytes, compress: bool) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if compress:
        with gzip.open(path.with_name(path.name + ".gz"), "wb", compresslevel=1) as fh:
            fh.write(data)
    else:
        path.write_bytes(data)


def write_polymesh(
    case: Path, points: np.ndarray, face_offsets: np.ndarray, face_labels: np.ndarray,
    owner: np.ndarray, neighbour: np.ndarray, patches: list[tuple[str, str, int, int]],
    *, binary: bool = False, compress: bool = False, compact: bool | None = None,
) -> None:
    """Write `constant/polyMesh`. Faces as `faceCompactList` when `compact` (default: binary)."""
    d = Path(case) / "constant" / "polyMesh"
    loc = "constant/polyMesh"
    n_cells = int(max(owner.max(), neighbour.max() if neighbour.size else 0)) + 1
    note = (f"nPoints:{points.shape[0]}  nCells:{n_cells}  nFaces:{owner.size}  "
            f"nInternalFaces:{neighbour.size}")
    _write(d / "points", _header("vectorField", "points", binary, loc)
           + _list_bytes(points, binary, False), compress)
    compact = binary if compact is None else compact
    if compact:
        data = (_header("faceCompactList", "faces", binary, loc) + _list_bytes(face_offsets, binary, True)
                + b"\n" + _list_bytes(face_labels, binary, True))
    else:
        if binary:
            raise ValueError("binary faces must be a faceCompactList")
        sizes = np.diff(face_offsets)
        lines = []
        for f in range(sizes.size):
            lab = face_labels[face_offsets[f]: face_offsets[f + 1]]
            lines.append(f"{sizes[f]}(" + " ".join(str(int(v)) for v in lab) + ")")
        data = _header("faceList", "faces", False, loc) + (
            f"{sizes.size}\n(\n" + "\n".join(lines) + "\n)\n").encode()
    _write(d / "faces", data, compress)
    _write(d / "owner", _header("labelList", "owner", binary, loc, note) + _list_bytes(owner, binary, True),
           compress)
    _write(d / "neighbour", _header("labelList", "neighbour", binary, loc, note)
           + _list_bytes(neighbour, binary, True), compress)
    body = [f"{len(patches)}\n(\n"]
    for name, ptype, start, n in patches:
        body.append(f"    {name}\n    {{\n        type            {ptype};\n"
                    f"        nFaces          {n};\n        startFace       {start};\n    }}\n")
    body.append(")\n")
    _write(d / "boundary", _header("polyBoundaryMesh", "boundary", False, loc) + "".join(body).encode(),
           compress)


def write_vector_field(
    case: Path, time: str, name: str, internal: np.ndarray, boundary: dict[str, Any],
    *, binary: bool = False, compress: bool = False, uniform: bool = False,
) -> None:
    """Write `<time>/<name>`: `boundary[patch]` is `("fixedValue", values (n, 3) or (3,))`,
    `("zeroGradient", None)`, `("slip", None)` or `("empty", None)`."""
    loc = time
    out = [_header("volVectorField", name, binary, loc), b"dimensions      [0 1 -1 0 0 0 0];\n\n"]
    if uniform:
        v = [float(c) for c in np.asarray(internal, np.float64).reshape(-1, 3)[0]]
        out.append(f"internalField   uniform ({v[0]!r} {v[1]!r} {v[2]!r});\n\n".encode())
    else:
        out.append(b"internalField   nonuniform List<vector> " + _list_bytes(internal, binary, False).rstrip()
                   + b";\n\n")
    out.append(b"boundaryField\n{\n")
    for patch, (btype, values) in boundary.items():
        out.append(f"    {patch}\n    {{\n        type            {btype};\n".encode())
        if values is not None:
            arr = np.asarray(values, np.float64)
            if arr.ndim == 1:
                arr = [float(c) for c in arr]
                out.append(f"        value           uniform ({arr[0]!r} {arr[1]!r} {arr[2]!r});\n".encode())
            else:
                out.append(b"        value           nonuniform List<vector> "
                           + _list_bytes(arr, binary, False).rstrip() + b";\n")
        out.append(b"    }\n")
    out.append(b"}\n")
    _write(Path(case) / time / name, b"".join(out), compress)


def hex_mesh(
    x: np.ndarray, y: np.ndarray, z: np.ndarray, solid: np.ndarray | None = None,
) -> dict[str, Any]:
    """A structured hex mesh on the node axes `x, y, z` (metres); `solid (nx-1, ny-1, nz-1)`
    marks removed cells (a hole with a `walls` patch around it).

    Returns a dict with `points`, `face_offsets`, `face_labels`, `owner`, `neighbour`,
    `patches` (walls, xmin, xmax, ymin, ymax, zmin, zmax), `cell_centres` (geometric
    centres of the hexes) and `cell_index (nx-1, ny-1, nz-1)` (-1 in solids)."""
    x, y, z = (np.asarray(a, np.float64) for a in (x, y, z))
    nx, ny, nz = x.size - 1, y.size - 1, z.size - 1
    active = np.ones((nx, ny, nz), bool) if solid is None else ~np.asarray(solid, bool)
    cid = np.full((nx, ny, nz), -1, np.int64)
    # cell numbering: x fastest
    order = np.flatnonzero(active.transpose(2, 1, 0).reshape(-1))
    kk, jj, ii = np.unravel_index(order, (nz, ny, nx))
    cid[ii, jj, kk] = np.arange(order.size)
    px, py = nx + 1, ny + 1

    def pid(i, j, k):
        return i + px * (j + py * k)

    P = np.stack(np.meshgrid(x, y, z, indexing="ij"), axis=-1).transpose(2, 1, 0, 3).reshape(-1, 3)
    faces, own, nei, kind = [], [], [], []
    # axis 0 faces at i = 0..nx, cells (i-1) and (i)
    for axis in range(3):
        n = [nx, ny, nz]
        shp = [nx, ny, nz]
        shp[axis] += 1
        idx = np.indices(shp).reshape(3, -1)
        i, j, k = idx
        if axis == 0:
            quad = [pid(i, j, k), pid(i, j + 1, k), pid(i, j + 1, k + 1), pid(i, j, k + 1)]
        elif axis == 1:
            quad = [pid(i, j, k), pid(i, j, k + 1), pid(i + 1, j, k + 1), pid(i + 1, j, k)]
        else:
            quad = [pid(i, j, k), pid(i + 1, j, k), pid(i + 1, j + 1, k), pid(i, j + 1, k)]
        quad = np.stack(quad, axis=1)
        lo_idx = idx.copy()
        lo_idx[axis] -= 1
        c_lo = np.full(i.size, -1, np.int64)
        ok = lo_idx[axis] >= 0
        c_lo[ok] = cid[lo_idx[0][ok], lo_idx[1][ok], lo_idx[2][ok]]
        c_hi = np.full(i.size, -1, np.int64)
        ok = idx[axis] < n[axis]
        c_hi[ok] = cid[idx[0][ok], idx[1][ok], idx[2][ok]]
        both = (c_lo >= 0) & (c_hi >= 0)
        faces.append(quad[both])
        own.append(np.minimum(c_lo[both], c_hi[both]))
        nei.append(np.maximum(c_lo[both], c_hi[both]))
        kind.append(np.full(both.sum(), -1))
        # boundary: owner is the active side; normal out of it
        only_lo = (c_lo >= 0) & (c_hi < 0)
        only_hi = (c_hi >= 0) & (c_lo < 0)
        on_edge_hi = idx[axis] == n[axis]
        on_edge_lo = idx[axis] == 0
        faces.append(quad[only_lo])
        own.append(c_lo[only_lo])
        nei.append(np.full(only_lo.sum(), -1))
        kind.append(np.where(on_edge_hi[only_lo], 1 + 2 * axis + 1, 0))
        faces.append(quad[only_hi][:, ::-1])
        own.append(c_hi[only_hi])
        nei.append(np.full(only_hi.sum(), -1))
        kind.append(np.where(on_edge_lo[only_hi], 1 + 2 * axis, 0))
    F = np.concatenate(faces)
    own_all = np.concatenate(own)
    N = np.concatenate(nei)
    K = np.concatenate(kind)
    internal = K < 0
    oi = np.lexsort((N[internal], own_all[internal]))
    fi = F[internal][oi]
    b_order = np.lexsort((own_all[~internal], K[~internal]))
    fb = F[~internal][b_order]
    kb = K[~internal][b_order]
    names = ["walls", "xmin", "xmax", "ymin", "ymax", "zmin", "zmax"]
    n_int = fi.shape[0]
    patches = []
    for p, name in enumerate(names):
        cnt = int(np.count_nonzero(kb == p))
        start = n_int + int(np.count_nonzero(kb < p))
        patches.append((name, "wall" if p == 0 else "patch", start, cnt))
    faces_all = np.concatenate([fi, fb])
    owner = np.concatenate([own_all[internal][oi], own_all[~internal][b_order]])
    neighbour = N[internal][oi]
    # compact the points (drop points used by no face: inside solid blocks)
    used = np.zeros(P.shape[0], bool)
    used[faces_all.reshape(-1)] = True
    newp = np.cumsum(used) - 1
    cc = np.stack(np.meshgrid(0.5 * (x[1:] + x[:-1]), 0.5 * (y[1:] + y[:-1]), 0.5 * (z[1:] + z[:-1]),
                              indexing="ij"), axis=-1)
    centres = np.zeros((order.size, 3))
    centres[cid[active]] = cc[active]
    return {
        "points": P[used], "face_offsets": np.arange(0, 4 * faces_all.shape[0] + 1, 4),
        "face_labels": newp[faces_all.reshape(-1)], "owner": owner, "neighbour": neighbour,
        "patches": patches, "cell_centres": centres, "cell_index": cid,
    }


def write_probes_output(path, locations, times_values, unset=()):
    """OpenFOAM v1912 probes output, as `postProcess -func <name>` writes it (full
    precision here so the round trip can be checked to rounding)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = []
    for i, p in enumerate(locations.points):
        tail = "  # Not Found" if i in unset else ""
        lines.append(f"# Probe {i} ({p[0]:.17g} {p[1]:.17g} {p[2]:.17g}){tail}")
    lines.append("#       Probe" + "".join(f"{i:>14d}" for i in range(len(locations))))
    lines.append("#        Time")
    for t, vals in times_values:
        cells = []
        for i, v in enumerate(vals):
            v = (-1e300,) * 3 if i in unset else v
            cells.append("(" + " ".join(f"{x:.17g}" for x in v) + ")")
        lines.append(f"{t:>13g}             " + "             ".join(cells))
    path.write_text("\n".join(lines) + "\n")
