"""Write the ground-graded transient OpenFOAM case (pimpleFoam, laminar) whose snapshots
and probes test that a snapshot sequence is exact by default. Run: python3 make_case.py
CASE_DIR, then Allrun in CASE_DIR.

The recipe of tests/data/openfoam_transient (written first, then changed here): a 160 x 80 x
80 m box, 10 m cells across (16 x 8) and 12 layers graded to the ground (first layer 0.99 m,
ratio 1.313 between layers: `simpleGrading (1 1 20)`), with a 20 x 20 x 20 m block at
x 30..50, y 30..50 (cut out by topoSet + subsetMesh, patch `obstacle`), inflow along +x whose
speed ramps 6 -> 10 m/s over 0..20 s (a table), laminar with nu = 0.05 m2/s, no-slip
ground: a boundary layer and the block's wake over a Windcube V2 at (100, 40, 0). OpenFOAM's
`probes` (cellPoint) record U at the lidar's LOS points (point probe, heights 5, 10, 20, 40,
60 m) every step; output every 2.5 s up to 15 s.
"""

import re
import runpy
import sys
from pathlib import Path

import lidarjax as lj

case = Path(sys.argv[1])
runpy.run_path(str(Path(__file__).resolve().parents[2] / "openfoam_transient" / "recipe"
                   / "make_case.py"), run_name="__main__")  # the transient case, in `case`


def edit(rel, *pairs):
    text = (case / rel).read_text()
    for old, new in pairs:
        assert old in text, (rel, old)
        text = text.replace(old, new)
    (case / rel).write_text(text)


edit("system/blockMeshDict",
     ("(240 0 0) (240 120 0) (0 120 0) (0 0 80) (240 0 80) (240 120 80) (0 120 80)",
      "(160 0 0) (160 80 0) (0 80 0) (0 0 80) (160 0 80) (160 80 80) (0 80 80)"),
     ("(24 12 8) simpleGrading (1 1 1)", "(16 8 12) simpleGrading (1 1 20)"))
edit("system/topoSetDict", ("box (60 50 0) (80 70 30);", "box (30 30 0) (50 50 20);"))
heights = [5.0, 10.0, 20.0, 40.0, 60.0]
mp = lj.monitor_points(lj.windcube_v2(), lj.Mount([100.0, 40.0, 0.0]), heights)
pts = mp.points.reshape(-1, 3)
(case / "lidar_points.txt").write_text("\n".join(" ".join(f"{c:.12g}" for c in p) for p in pts) + "\n")
locs = "\n".join(f"            ({p[0]:.12g} {p[1]:.12g} {p[2]:.12g})" for p in pts)
control = (case / "system" / "controlDict").read_text()
control = re.sub(r"(probeLocations\n        \(\n).*?(\n        \);)", lambda m: m[1] + locs + m[2],
                 control, flags=re.S)
(case / "system" / "controlDict").write_text(control)
edit("system/controlDict", ("endTime         40;", "endTime         15;"),
     ("writeInterval   2;", "writeInterval   2.5;"))
edit("0/U", ("table ((0 (6 0 0)) (20 (10 0 0)) (40 (6 0 0)))", "table ((0 (6 0 0)) (20 (10 0 0)))"))
