"""Write the ground-graded transient OpenFOAM case (pimpleFoam, laminar) whose snapshots
and probes test that a snapshot sequence is exact by default. Run: python3 make_case.py
CASE_DIR, then Allrun in CASE_DIR.

A 160 x 80 x 80 m box, 10 m cells across (16 x 8) and 12 layers graded to the ground (first
layer 0.99 m, ratio 1.313 between layers: `simpleGrading (1 1 20)`), with a 20 x 20 x 20 m
block at x 30..50, y 30..50 (cut out by topoSet + subsetMesh, patch `obstacle`), inflow
along +x whose speed ramps 6 -> 10 m/s over 0..20 s (a table), laminar with nu = 0.05 m2/s,
no-slip ground: a boundary layer and the block's wake over a Windcube V2 at (100, 40, 0).
OpenFOAM's `probes` (cellPoint) record U at the lidar's LOS points (point probe, heights
5, 10, 20, 40, 60 m) every step.
"""

import sys
from pathlib import Path

import lidarjax as lj

case = Path(sys.argv[1])
(case / "system").mkdir(parents=True, exist_ok=True)
(case / "constant").mkdir(exist_ok=True)
(case / "0").mkdir(exist_ok=True)

HEAD = """FoamFile
{{
    version     2.0;
    format      ascii;
    class       {cls};
    object      {obj};
}}
"""

def w(rel, cls, obj, body):
    (case / rel).write_text(HEAD.format(cls=cls, obj=obj) + body)

w("system/blockMeshDict", "dictionary", "blockMeshDict", """
convertToMeters 1;
vertices ((0 0 0) (160 0 0) (160 80 0) (0 80 0) (0 0 80) (160 0 80) (160 80 80) (0 80 80));
blocks (hex (0 1 2 3 4 5 6 7) (16 8 12) simpleGrading (1 1 20));
boundary
(
    inlet  { type patch; faces ((0 4 7 3)); }
    outlet { type patch; faces ((1 2 6 5)); }
    ground { type wall;  faces ((0 3 2 1)); }
    top    { type patch; faces ((4 5 6 7)); }
    sides  { type patch; faces ((0 1 5 4) (3 7 6 2)); }
    obstacle { type wall; faces (); }
);
""")
w("system/topoSetDict", "dictionary", "topoSetDict", """
actions
(
    { name fluid; type cellSet; action new; source boxToCell; box (30 30 0) (50 50 20); }
    { name fluid; type cellSet; action invert; }
);
""")

heights = [5.0, 10.0, 20.0, 40.0, 60.0]
mp = lj.monitor_points(lj.windcube_v2(), lj.Mount([100.0, 40.0, 0.0]), heights)
pts = mp.points.reshape(-1, 3)
(case / "lidar_points.txt").write_text("\n".join(" ".join(f"{c:.12g}" for c in p) for p in pts) + "\n")
locs = "\n".join(f"            ({p[0]:.12g} {p[1]:.12g} {p[2]:.12g})" for p in pts)

w("system/controlDict", "dictionary", "controlDict", f"""
application     pimpleFoam;
startFrom       startTime;
startTime       0;
stopAt          endTime;
endTime         15;
deltaT          0.5;
writeControl    runTime;
writeInterval   2.5;
purgeWrite      0;
writeFormat     binary;
writePrecision  12;
writeCompression off;
timeFormat      general;
timePrecision   6;
runTimeModifiable false;
functions
{{
    lidarProbes
    {{
        type            probes;
        libs            ("libsampling.so");
        writeControl    timeStep;
        writeInterval   1;
        interpolationScheme cellPoint;
        fields          (U);
        probeLocations
        (
{locs}
        );
    }}
}}
""")
w("system/fvSchemes", "dictionary", "fvSchemes", """
ddtSchemes { default Euler; }
gradSchemes { default Gauss linear; }
divSchemes { default none; div(phi,U) Gauss linearUpwind grad(U); div((nuEff*dev2(T(grad(U))))) Gauss linear; }
laplacianSchemes { default Gauss linear corrected; }
interpolationSchemes { default linear; }
snGradSchemes { default corrected; }
""")
w("system/fvSolution", "dictionary", "fvSolution", """
solvers
{
    p { solver GAMG; tolerance 1e-7; relTol 0.01; smoother DICGaussSeidel; }
    pFinal { $p; relTol 0; }
    U { solver smoothSolver; smoother symGaussSeidel; tolerance 1e-7; relTol 0.1; }
    UFinal { $U; relTol 0; }
}
PIMPLE { nNonOrthogonalCorrectors 0; nCorrectors 2; nOuterCorrectors 1; }
""")
w("constant/transportProperties", "dictionary", "transportProperties", """
transportModel  Newtonian;
nu              0.05;
""")
w("constant/turbulenceProperties", "dictionary", "turbulenceProperties", """
simulationType  laminar;
""")
w("0/U", "volVectorField", "U", """
dimensions      [0 1 -1 0 0 0 0];
internalField   uniform (6 0 0);
boundaryField
{
    inlet    { type uniformFixedValue; uniformValue table ((0 (6 0 0)) (20 (10 0 0))); }
    outlet   { type inletOutlet; inletValue uniform (0 0 0); value uniform (6 0 0); }
    ground   { type noSlip; }
    obstacle { type noSlip; }
    top      { type slip; }
    sides    { type slip; }
}
""")
w("0/p", "volScalarField", "p", """
dimensions      [0 2 -2 0 0 0 0];
internalField   uniform 0;
boundaryField
{
    inlet    { type zeroGradient; }
    outlet   { type fixedValue; value uniform 0; }
    ground   { type zeroGradient; }
    obstacle { type zeroGradient; }
    top      { type zeroGradient; }
    sides    { type zeroGradient; }
}
""")
(case / "Allrun").write_text("""#!/bin/bash
cd "${0%/*}" || exit 1
. /usr/share/openfoam/etc/bashrc
mv 0 0.orig
blockMesh > log.blockMesh 2>&1
topoSet > log.topoSet 2>&1
subsetMesh fluid -patch obstacle -overwrite > log.subsetMesh 2>&1
rm -rf constant/polyMesh/sets 0
cp -r 0.orig 0
pimpleFoam > log.pimpleFoam 2>&1
""")
(case / "Allrun").chmod(0o755)
