"""The exact (cellPoint) paths on a real mesh: a snapshot sequence and a 36-rotation table.

Issue 31's speed targets, on OpenFOAM's `windAroundBuildings` (185k cells; not committed:
build it with the recipe in tests/data/openfoam/README.md and pass its folder):

1. **Sequence** (`load_field_sequence(case, exact_at=...)`, a Windcube V2 with the pulsed
   probe on the roof at (228.5, 120.5, 51), heights 10-40 m): each snapshot after the first
   costs at most 1.5x reading its velocity file (``grid_fallback=False``: a fixed lidar
   samples only its prepared points, so no snapshot is resampled onto the graded grid;
   with the grid each later snapshot also pays its resampling). The snapshots are copies of the case's
   latest `U` (same file, same read cost) in `N` time directories of a scratch case that
   links the mesh. Reported: the read time of one `U` (median), each later snapshot's
   time (read + grid + the sparse product at the prepared points), `simulate_series` over
   all snapshots (snapshots per second) and its peak memory for two sequence lengths
   (each in a fresh process).
2. **Table** (`build_table` as `lidarjax table` calls it, one run per rotation, the same
   case for every rotation): 36 rotations exact at every node against the graded grid
   alone (a loader without `exact_at`), measured in the same run: grid, exact, grid, exact,
   the first pair compiling `simulate` for each field type, the second pair compared.

Run: ``PYTHONPATH=$PWD python3 benchmarks/exact_paths.py CASE [--snapshots 8]
[--rotations 36] [--part sequence|table]``. Writes ``benchmarks/results/exact_paths.{json,md}``
(one part rerun: the other's results are kept from the previous file, each part with the
load average it ran at).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _common import machine, machine_line  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
OUT = ROOT / "benchmarks" / "results"
LIDAR = tuple(float(v) for v in os.environ.get("EXACT_PATHS_LIDAR", "228.5,120.5,51").split(","))
HEIGHTS = tuple(float(v) for v in os.environ.get("EXACT_PATHS_HEIGHTS", "10,20,30,40").split(","))


def _latest(case: Path) -> str:
    from lidarjax.io.openfoam import openfoam_times

    return openfoam_times(case)[-1]


def scratch_sequence(case: Path, n: int, where: Path) -> Path:
    """A case linking `case`'s mesh with `n` time directories holding its latest U."""
    seq = where / "seq"
    seq.mkdir()
    for d in ("constant", "system"):
        (seq / d).symlink_to(case / d, target_is_directory=True)
    src = case / _latest(case)
    u = next(p for p in src.iterdir() if p.name in ("U", "U.gz"))
    for k in range(n):
        t = seq / str(10 + 10 * k)
        t.mkdir()
        shutil.copy(u, t / u.name)
    return seq


def _setup():
    import jax

    jax.config.update("jax_enable_x64", True)
    import lidarjax as lj

    scan, probe = lj.windcube_v2(), lj.PulsedProbe()
    mount = lj.Mount(np.array(LIDAR))
    return lj, scan, probe, mount, np.array(HEIGHTS)


def sequence_run(seq: Path, n_used: int) -> dict:
    """In this process: per-snapshot times, simulate_series over `n_used` snapshots."""
    lj, scan, probe, mount, h = _setup()
    from lidarjax.io import load_field_sequence
    from lidarjax.io.openfoam import _read_vector_field, openfoam_times, read_openfoam_mesh
    names = openfoam_times(seq)[:n_used]

    from lidarjax.beam import ExactPoints

    exact_points = ExactPoints(scan, mount, h, probe)  # the series' own node choice (mount)

    mesh = read_openfoam_mesh(seq)
    region = lj.scan_bounds(scan, mount, h, probe=probe)
    s = load_field_sequence(seq, region=region, exact_at=exact_points,
                            time_range=(float(names[0]), float(names[-1])), max_snapshots=4,
                            grid_fallback=False)
    first = time.perf_counter()
    s.snapshot(0)
    first = time.perf_counter() - first
    # each later snapshot, three times, interleaved with a read of its velocity file alone
    # (the same page-cache state and machine load for both)
    reads, later = [], []
    for _ in range(3):
        for k in range(1, len(names)):
            t1 = time.perf_counter()
            _read_vector_field(seq / names[k] / "U", mesh)
            reads.append(time.perf_counter() - t1)
            t1 = time.perf_counter()
            s.snapshot(k)
            later.append(time.perf_counter() - t1)
    s = load_field_sequence(seq, region=region, exact_at=exact_points,
                            time_range=(float(names[0]), float(names[-1])), max_snapshots=4,
                            grid_fallback=False)
    span = float(names[-1]) - float(names[0])
    t2 = time.perf_counter()
    series = lj.simulate_series(s, scan, mount, h, (float(names[0]), span), probe=probe)
    np.asarray(series.los)
    total = time.perf_counter() - t2
    return {"snapshots": len(names), "read_s": float(np.median(reads)), "first_s": first,
            "later_s": later, "later_median_s": float(np.median(later)),
            "ratio_to_read": float(np.median(later) / np.median(reads)),
            "series_s": total, "snapshots_per_s": len(names) / total,
            "finite_los": float(np.isfinite(np.asarray(series.los)).mean()),
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def table_run(case: Path, n_rot: int, where: Path) -> dict:
    """build_table over `n_rot` rotations, exact and graded grid alone, same process."""
    lj, scan, probe, _, h = _setup()
    from lidarjax.cli._dask import region_loader
    from lidarjax.io import read_settings
    from lidarjax.io.fields import load_field
    from lidarjax.workflows.seed_tables import build_table, table_region

    betas = [360.0 * k / n_rot for k in range(n_rot)]
    rows = ["zone\tverbose\theight\tnh\tgamma\tbeta\tpsi\tepsilon",
            f"2\t1\t{HEIGHTS[-1]:g}\t{len(HEIGHTS)}\t0\t0\t0\t0"]
    rows += [f"{b:g}\t{LIDAR[0]}\t{LIDAR[1]}\t{LIDAR[2]}" for b in betas]
    (where / "settings.dat").write_text("\n".join(rows) + "\n")
    s = read_settings(where / "settings.dat")
    paths = {b: case for b in s.betas}
    region = table_region(s, s.betas, scan, probe=probe)
    loader = region_loader(load_field, paths, region)

    def grid_only(b):  # no `exact_at`: the graded grid answers every node, as before
        return loader(b)

    out = {}
    # grid, exact, grid, exact: the first pair compiles simulate for each field type (about
    # 20 s each) and warms the page cache; the second pair is the comparison
    for label, load in (("grid0", grid_only), ("exact0", loader), ("grid", grid_only),
                        ("exact", loader)):
        t = time.perf_counter()
        try:
            table, _ = build_table(s, s.betas, load, scan, probe=probe)
            resp = np.asarray(table.response)
        except ValueError as err:  # a NaN pattern a table cannot hold: timing still valid
            resp, _ = None, str(err)
        out[f"{label}_s"] = time.perf_counter() - t
        out[f"{label}_response"] = resp
    diff = (None if out["grid_response"] is None or out["exact_response"] is None else
            float(np.nanmax(np.abs(out["grid_response"] - out["exact_response"])) * 15.0))
    return {"rotations": n_rot, "grid_s": out["grid_s"], "exact_s": out["exact_s"],
            "first_pair_s": [out["grid0_s"], out["exact0_s"]],
            "ratio": out["exact_s"] / out["grid_s"], "max_los_change_m_s": diff}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("case", nargs="?", help="the 185k-cell windAroundBuildings case folder")
    ap.add_argument("--snapshots", type=int, default=8)
    ap.add_argument("--rotations", type=int, default=36)
    ap.add_argument("--part", choices=("all", "sequence", "table"), default="all")
    ap.add_argument("--lidar", default=None, help="x,y,z of the lidar (default the roof's)")
    ap.add_argument("--heights", default=None, help="h1,h2,... m (default 10,20,30,40)")
    ap.add_argument("--child", nargs=2, metavar=("SEQ", "N"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    global LIDAR, HEIGHTS
    if args.lidar:
        LIDAR = tuple(float(v) for v in args.lidar.split(","))
        os.environ["EXACT_PATHS_LIDAR"] = args.lidar
    if args.heights:
        HEIGHTS = tuple(float(v) for v in args.heights.split(","))
        os.environ["EXACT_PATHS_HEIGHTS"] = args.heights
    if args.child:
        print(json.dumps(sequence_run(Path(args.child[0]), int(args.child[1]))))
        return 0
    case = Path(args.case).resolve()
    res = {"machine": machine(), "case": os.fspath(case), "lidar": LIDAR, "heights": HEIGHTS,
           "load_before": os.getloadavg()}
    # one part rerun: the other part's results are kept from the previous file, with the
    # load average they were measured at
    prev_file = OUT / "exact_paths.json"
    prev = json.loads(prev_file.read_text()) if args.part != "all" and prev_file.is_file() else {}
    for part in ("sequence", "table"):
        if part != args.part and part in prev:
            keys = [part] + (["series_marginal_snapshots_per_s"] if part == "sequence" else [])
            res.update({k: prev[k] for k in keys if k in prev})
            res[f"{part}_load"] = prev.get(f"{part}_load",
                                           [prev.get("load_before"), prev.get("load_after")])
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if args.part in ("all", "sequence"):
            before = os.getloadavg()
            seq = scratch_sequence(case, args.snapshots, tmp)
            runs = []
            for n in (max(2, args.snapshots // 4), args.snapshots):  # memory vs length
                p = subprocess.run([sys.executable, __file__, "--child", os.fspath(seq), str(n)],
                                   capture_output=True, text=True, check=True,
                                   env={**os.environ, "PYTHONPATH": os.fspath(ROOT)})
                runs.append(json.loads(p.stdout.strip().splitlines()[-1]))
            res["sequence"] = runs
            a, b = runs
            # the marginal cost of a snapshot inside simulate_series (compilation cancels)
            extra = b["series_s"] - a["series_s"]
            res["series_marginal_snapshots_per_s"] = ((b["snapshots"] - a["snapshots"]) / extra
                                                      if extra > 0 else None)
            res["sequence_load"] = [before, os.getloadavg()]
        if args.part in ("all", "table"):
            before = os.getloadavg()
            res["table"] = table_run(case, args.rotations, tmp)
            res["table_load"] = [before, os.getloadavg()]
    res["load_after"] = os.getloadavg()
    OUT.mkdir(exist_ok=True)
    (OUT / "exact_paths.json").write_text(json.dumps(res, indent=1))
    lines = [f"# Exact paths on {case.name}", "", machine_line(res["machine"]),
             f"load average before/after this run ({args.part}): {res['load_before']} / "
             f"{res['load_after']}", ""]
    if "sequence_load" in res:
        lines.append(f"Sequence: load average before/after {res['sequence_load'][0]} / "
                     f"{res['sequence_load'][1]}")
    for r in res.get("sequence", []):
        lines.append(f"- sequence, {r['snapshots']} snapshots: read U {r['read_s']:.3f} s; first "
                     f"snapshot {r['first_s']:.2f} s; each later {r['later_median_s']:.3f} s "
                     f"(x{r['ratio_to_read']:.2f} the read; target <= 1.5); simulate_series "
                     f"{r['series_s']:.1f} s = {r['snapshots_per_s']:.2f} snapshots/s; peak RSS "
                     f"{r['peak_rss_mb']:.0f} MB")
    if "series_marginal_snapshots_per_s" in res:
        m = res["series_marginal_snapshots_per_s"]
        lines.append("- simulate_series, marginal: " + (
            f"{m:.1f} snapshots/s (the difference of the two runs; compilation cancels)"
            if m is not None else "the longer run took no longer (the snapshots' cost is below "
            "the noise of compilation)"))
    if "table" in res:
        t = res["table"]
        lines.append(f"Table: load average before/after {res['table_load'][0]} / "
                     f"{res['table_load'][1]}")
        lines.append(f"- table, {t['rotations']} rotations (second pair; the first, compiling: "
                     f"{t['first_pair_s'][0]:.1f} / {t['first_pair_s'][1]:.1f} s): graded grid "
                     f"{t['grid_s']:.1f} s, exact "
                     f"{t['exact_s']:.1f} s (x{t['ratio']:.2f}; target <= 1.5); LOS change "
                     f"{t['max_los_change_m_s']} m/s")
    (OUT / "exact_paths.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
