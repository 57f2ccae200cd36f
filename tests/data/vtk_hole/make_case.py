"""The OpenFOAM case behind the foamToVTK files here (run from the repository root).

    python3 tests/data/vtk_hole/make_case.py /tmp/hole
    cd /tmp/hole && cp <any case>/system/{controlDict,fvSchemes,fvSolution} system/
    foamToVTK -latestTime -fields '(U)'                         # -> VTK/hole_0.vtm + hole_0/internal.vtu
    foamToVTK -latestTime -fields '(U)' -legacy -no-boundary    # -> VTK/hole_0.vtk (hole_legacy.vtk here)

OpenFOAM v1912 (Debian openfoam 1912.200626). A graded 9 x 9 x 8 hex mesh with a 3 x 3 x 4-cell
solid block (a building; `walls` patch, zero velocity) and a smooth nonlinear field.
"""

import sys
from pathlib import Path

import numpy as np

from lidarjax.io import _cells
from tests._foamwrite import hex_mesh, write_polymesh, write_vector_field

AX = np.array([0, 1, 2, 2.5, 3, 3.5, 4, 5, 6.5, 8.0])
AZ = np.array([0, 0.5, 1, 1.5, 2.25, 3, 4, 5.5, 7.0])


def field(p):
    p = np.asarray(p)
    return np.stack([3 + np.sin(p[..., 0]) * p[..., 2], np.cos(p[..., 1]) + 0.2 * p[..., 0] ** 2,
                     0.1 * p[..., 2] ** 2 - p[..., 0]], -1)


def write(root: Path) -> Path:
    solid = np.zeros((AX.size - 1, AX.size - 1, AZ.size - 1), bool)
    solid[3:6, 3:6, 0:4] = True
    m = hex_mesh(AX, AX, AZ, solid)
    mesh = _cells.PolyMesh(m["points"], m["face_offsets"], m["face_labels"], m["owner"], m["neighbour"],
                           int(m["owner"].max()) + 1, tuple(m["patches"]))
    fc = _cells.face_geometry(mesh, np.arange(mesh.n_faces))[0]
    write_polymesh(root, m["points"], m["face_offsets"], m["face_labels"], m["owner"], m["neighbour"],
                   m["patches"], binary=True)
    bnd = {name: ("fixedValue", np.zeros((n, 3)) if name == "walls" else field(fc[start:start + n]))
           for name, _t, start, n in m["patches"]}
    write_vector_field(root, "100", "U", field(m["cell_centres"]), bnd, binary=True)
    (root / "system").mkdir(exist_ok=True)
    return root


if __name__ == "__main__":
    write(Path(sys.argv[1]))
