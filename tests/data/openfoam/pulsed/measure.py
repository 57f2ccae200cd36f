# ruff: noqa
"""Native path (graded grid alone, and exact at simulate's points) against OpenFOAM's own
probes of the same pulsed-probe nodes; prints lidar speeds and load times.

python3 tests/data/openfoam/pulsed/measure.py [CASE SETTINGS PROBES_DIR NODES]  (default: the
three committed cuts; PROBES_DIR is postProcessing/<name> with <time>/U or <time>/U.gz)."""
import gzip, shutil, sys, tempfile, time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np

import lidarjax as lj
from lidarjax.io import load_field, read_openfoam_probes, read_settings
from lidarjax.workflows.seed_tables import settings_mount, table_region

HERE = Path(__file__).resolve().parent
FOAM = HERE.parent
RUNS = [(FOAM / "windAroundBuildings_cut", HERE / "roof.dat", "pulsed_roof", 77),
        (FOAM / "turbineSiting_cut", HERE / "disc.dat", "pulsed_disc", 433),
        (FOAM / "turbineSiting_cut", HERE / "hill.dat", "pulsed_hill", 43)]
if len(sys.argv) == 5:
    RUNS = [(Path(sys.argv[1]), Path(sys.argv[2]), Path(sys.argv[3]), int(sys.argv[4]))]


def probes(case, name):
    d = Path(name) if Path(name).is_absolute() else case / "postProcessing" / name
    out = Path(tempfile.mkdtemp()) / "p"
    for f in d.glob("*/U*"):
        (out / f.parent.name).mkdir(parents=True)
        if f.suffix == ".gz":
            with gzip.open(f, "rb") as a, open(out / f.parent.name / "U", "wb") as b:
                shutil.copyfileobj(a, b)
        else:
            shutil.copy(f, out / f.parent.name / "U")
    return read_openfoam_probes(out)


for case, sfile, name, nodes in RUNS:
    s = read_settings(sfile)
    scan, probe = lj.windcube_v2(), lj.PulsedProbe()
    h = np.asarray(s.heights())
    region = table_region(s, [s.beta], scan, probe=probe)  # as `lidarjax simulate`
    mount = settings_mount(s, [s.beta])[0]
    t = time.perf_counter()
    grid = load_field(case, region=region)
    t_grid = time.perf_counter() - t
    chosen = {}

    def points(g):
        chosen["p"] = lj.probe_for_field(g, scan, h, probe)
        return lj.monitor_points(scan, mount, h, chosen["p"]).points

    t = time.perf_counter()
    exact = load_field(case, region=region, exact_at=points)
    t_exact = time.perf_counter() - t
    assert chosen["p"].n_nodes == nodes, chosen["p"].n_nodes
    fixed = lj.PulsedProbe(n_nodes=nodes)
    locs = lj.monitor_points(scan, mount, h, fixed)
    foam = lj.simulate_from_monitor_points(locs, probes(case, name).values_for(locs), scan, [mount], h,
                                           probe=fixed)[0].lidar_speed
    a = np.asarray(lj.simulate(exact, scan, mount, h, probe=probe).lidar_speed)
    g = np.asarray(lj.simulate(grid, scan, mount, h, probe=probe).lidar_speed)
    foam = np.asarray(foam)
    print(f"{case.name} {sfile.stem}: {nodes} nodes, load {t_grid:.1f} s grid / {t_exact:.1f} s exact")
    print("  h [m]   OpenFOAM   exact-OpenFOAM   grid-OpenFOAM")
    for k in range(h.size):
        print(f"  {h[k]:5.0f}  {foam[k]:9.4f}  {a[k] - foam[k]:+.2e}  {g[k] - foam[k]:+.4f}")
