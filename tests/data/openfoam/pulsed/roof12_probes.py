# ruff: noqa
"""Write the OpenFOAM `probes` dictionaries of the nodes `lidarjax table` samples for each of
the 12 platform rotations of `roof12.dat` on `windAroundBuildings_cut` (the table's region,
each rotation's own per-height node counts: `probe_for_field(..., mount=)`), one function
object `pulsed_roof12_b<beta>` per rotation, into OUT (recipe in ../README.md).

python3 tests/data/openfoam/pulsed/roof12_probes.py OUT"""
import sys
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np

import lidarjax as lj
from lidarjax.io import load_field, read_settings
from lidarjax.io.monitor_points import write_openfoam_probes
from lidarjax.workflows.seed_tables import settings_mounts, table_region

HERE = Path(__file__).resolve().parent
CASE = HERE.parent / "windAroundBuildings_cut"


def table_probes():
    """``(settings, mounts, heights, {beta: probe})``: the probes `lidarjax table` uses."""
    s = read_settings(HERE / "roof12.dat")
    scan, probe = lj.windcube_v2(), lj.PulsedProbe()
    grid = load_field(CASE, region=table_region(s, s.betas, scan, probe=probe))
    mounts = settings_mounts(s, s.betas)
    h = np.asarray(s.heights())
    return s, mounts, h, {b: lj.probe_for_field(grid, scan, h, probe, mount=m)
                          for b, m in zip(s.betas, mounts)}


if __name__ == "__main__":
    out = Path(sys.argv[1])
    out.mkdir(parents=True, exist_ok=True)
    s, mounts, h, probes = table_probes()
    for (b, p), m in zip(probes.items(), mounts):
        locs = lj.monitor_points(lj.windcube_v2(), m, h, p)
        name = f"pulsed_roof12_b{b:g}"
        write_openfoam_probes(out / name, locs)
        print(name, getattr(p, "node_counts", p.n_nodes), len(locs))
