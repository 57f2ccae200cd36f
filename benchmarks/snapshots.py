"""OpenFOAM snapshot sequences (`lidarjax.io.load_field_sequence`): the time to bring each
later snapshot onto the sequence's grid, against building the cellPoint interpolant again.

Every snapshot of a sequence is sampled by the mesh's own cellPoint interpolation at the
first snapshot's grid nodes. The mesh is the same in every snapshot, so the sequence finds
the cells' tetrahedra, `volPointInterpolation`'s weights and each node's tetrahedron once and
then only mixes each snapshot's values (**reuse**). The baseline (**rebuild**, what the
sequence did before) builds the interpolant from the snapshot and scatters it onto the grid
(`OpenFOAMField.sampler(cells).sample_grid(axes)`, numba). Both read the same files (the read
is timed apart) and give the same values (the largest difference is reported).

Cases:
1. the committed pimpleFoam transient (`tests/data/openfoam_transient`, 2,292 cells) on a 1 m
   grid of the whole box (2.4M nodes);
2. graded hex meshes around a hemisphere (`benchmarks/cfd_ingest.py`'s, binary), about 1e5
   and 1e6 cells, with six snapshots (the potential flow scaled by 1.0 .. 1.5, inflow patches
   alike), on the automatic graded grid of a Windcube V2's region and on a 2 m grid of it.

Run: ``PYTHONPATH=$PWD python3 benchmarks/snapshots.py [--quick]`` (``--quick``: the
transient and the 1e5 mesh). Writes ``benchmarks/results/snapshots.{json,png}``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _common import machine, machine_line  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
OUT = ROOT / "benchmarks" / "results"
TRANSIENT = ROOT / "tests" / "data" / "openfoam_transient" / "case"


def _median(fn, repeats=3):
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return float(np.median(times)), out


def measure(case: Path, times: list[str], *, region=None, spacing=None, label: str) -> dict:
    """Per-snapshot seconds of both ways for every snapshot after the first two."""
    import jax

    jax.config.update("jax_enable_x64", True)
    from lidarjax.io import load_field_sequence
    from lidarjax.io.openfoam import read_openfoam_field
    from lidarjax.io.snapshots import cells_covering

    t0 = time.perf_counter()
    seq = load_field_sequence(case, region=region, spacing=spacing, max_snapshots=len(times))
    win = seq.window(0, len(times) - 1)  # loads every snapshot: the first, the one that prepares
    total_new = time.perf_counter() - t0
    axes = [np.asarray(a, np.float64) for a in (win.grid.x, win.grid.y, win.grid.z)]
    of0 = read_openfoam_field(case, time=times[0])
    cells = cells_covering(of0.bounds, axes)  # the cells the sequence samples
    # the sequence's own prepared interpolant (built at its second snapshot)
    from lidarjax.io._cells import build_sampler_and_values

    of1 = read_openfoam_field(case, time=times[1])
    t = time.perf_counter()
    sampler, refill = build_sampler_and_values(of1.mesh, of1.cell_values, of1.boundary, cells, of0.bounds)
    located = sampler.grid_locations(axes)
    prepare_s = time.perf_counter() - t
    rows = []
    for k in range(2, len(times)):
        read_s, of = _median(lambda k=k: read_openfoam_field(case, time=times[k]), 1)
        object.__setattr__(of, "_bounds", of0.bounds)  # as the sequence keeps them
        old_s, (old, _) = _median(lambda of=of: of.sampler(cells).sample_grid(axes))
        new_s, new = _median(lambda of=of: sampler.with_values(*refill(of.cell_values, of.boundary))
                             .values_at(*located))
        got = np.asarray(win.snapshot(k).velocity, np.float64)
        rows.append({"time": times[k], "read_s": read_s, "rebuild_s": old_s, "reuse_s": new_s,
                     "max_diff_rebuild_reuse": float(np.nanmax(np.abs(old - new))),
                     "max_diff_sequence": float(np.nanmax(np.abs(got - old)))})
    rebuild = float(np.median([r["rebuild_s"] for r in rows]))
    reuse = float(np.median([r["reuse_s"] for r in rows]))
    return {"case": label, "n_cells": int(of0.mesh.n_cells), "cells_used": int(cells.size),
            "grid": [a.size for a in axes], "snapshots": len(times), "prepare_s": prepare_s,
            "sequence_total_s": total_new, "rebuild_s": rebuild, "reuse_s": reuse,
            "speedup": rebuild / reuse, "read_s": float(np.median([r["read_s"] for r in rows])),
            "rows": rows}


def hemisphere_sequence(folder: Path, n_cells: float, n_times: int = 6) -> tuple[Path, list[str]]:
    """`cfd_ingest.write_hemisphere_case` with `n_times` snapshots: the flow and its fixed
    boundary values scaled by 1.0, 1.1, ..."""
    from cfd_ingest import write_hemisphere_case

    from lidarjax.io.openfoam import read_openfoam_field
    from tests._foamwrite import write_vector_field

    case = folder / f"hemisphere_{int(n_cells)}"
    case.mkdir(parents=True)
    write_hemisphere_case(case, n_cells)
    of = read_openfoam_field(case, time="1")
    names = ["1"]
    for k in range(1, n_times):
        s = 1.0 + 0.1 * k
        bnd = {name: (("zeroGradient", None) if isinstance(v, str) else ("fixedValue", np.asarray(v) * s))
               for name, v in of.boundary.values.items()}
        write_vector_field(case, str(1 + k), "U", of.cell_values * s, bnd, binary=True)
        names.append(str(1 + k))
    return case, names


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    out = {"machine": machine(), "load_average": list(os.getloadavg()), "cases": []}
    times = sorted((p.name for p in TRANSIENT.iterdir() if p.name.replace(".", "").isdigit()), key=float)
    out["cases"].append(measure(TRANSIENT, times[:6], spacing=1.0, label="transient, 1 m grid"))
    import lidarjax as lj

    region = lj.scan_bounds(lj.windcube_v2(), lj.Mount([4.0, 3.0, 20.1]), np.array([5.0, 20.0, 60.0, 100.0]),
                            probe=lj.PulsedProbe())
    with tempfile.TemporaryDirectory() as tmp:
        for n in (1e5,) if args.quick else (1e5, 1e6):
            case, names = hemisphere_sequence(Path(tmp), n)
            out["cases"].append(measure(case, names, region=region, label=f"hemisphere {n:.0e}, graded grid"))
            out["cases"].append(measure(case, names, region=region, spacing=2.0,
                                        label=f"hemisphere {n:.0e}, 2 m grid"))
    out["load_average_after"] = list(os.getloadavg())
    OUT.mkdir(exist_ok=True)
    (OUT / "snapshots.json").write_text(json.dumps(out, indent=1))
    print(machine_line(out["machine"]), "load", out["load_average"])
    for c in out["cases"]:
        print(f"{c['case']}: {c['n_cells']} cells ({c['cells_used']} used), grid {c['grid']}: per snapshot "
              f"rebuild {c['rebuild_s']:.3f} s, reuse {c['reuse_s']:.3f} s ({c['speedup']:.1f}x; read "
              f"{c['read_s']:.3f} s; prepared once in {c['prepare_s']:.2f} s); max diff "
              f"{max(r['max_diff_rebuild_reuse'] for r in c['rows']):.1e}")
    plot(out)


def plot(out):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = out["cases"]
    x = np.arange(len(cases))
    fig, ax = plt.subplots(figsize=(8, 3.6))
    ax.bar(x - 0.27, [c["read_s"] for c in cases], 0.27, label="read the snapshot", color="0.6")
    ax.bar(x, [c["rebuild_s"] for c in cases], 0.27, label="rebuild the interpolant (before)", color="C3")
    ax.bar(x + 0.27, [c["reuse_s"] for c in cases], 0.27, label="reuse it (now)", color="C0")
    ax.set_xticks(x, [f"{c['case']}\n{c['n_cells']} cells" for c in cases], fontsize=7)
    ax.set_yscale("log")
    ax.set_ylabel("s per snapshot (median)")
    ax.legend(fontsize=8)
    ax.set_title(f"OpenFOAM snapshots onto the sequence's grid; {machine_line(out['machine'])}", fontsize=8)
    fig.tight_layout()
    fig.savefig(OUT / "snapshots.png", dpi=110)


if __name__ == "__main__":
    main()
