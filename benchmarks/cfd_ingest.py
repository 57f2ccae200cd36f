"""CFD ingest: load time, peak memory and accuracy of OpenFOAM cases, old vs new sampling.

Two workloads, each loaded in a fresh subprocess (so peak memory is that of one load):

1. a graded synthetic hex mesh (OpenFOAM binary format) around `lidarjax.scenes.hemisphere`
   (radius 20 m, 10 m/s from 250 deg; cells whose centre is inside the body are removed: a
   solid with a `walls` patch), at about 1e5, 1e6 and 5e6 cells, with the exact potential
   flow as cell values. A Windcube V2 on the body (as in the README) is simulated in
   - **new**: `lidarjax.io.load_field(case, region=scan_bounds(...))`: the mesh's own
     cellPoint interpolation, only in the cells the beams look through, on an automatic
     graded grid;
   - **old**: the scattered-data path (Delaunay of every cell centre, whole domain, the
     default 128^3 grid: `lidarjax.io.resample_to_grid`), skipped beyond 1e6 cells;
   and compared with the exact scene (horizontal speed error per height);
2. the v1912 `turbineSiting` tutorial run (terrain + two actuator discs, 120k cells, binary),
   if present at `--turbine-case` (see tests/data/openfoam/README.md), else the committed
   18k-cell cut: load time of a Windcube's region and LOS difference to OpenFOAM's own probes
   (`interpolationScheme cellPoint`).

3. `.vtu` against the OpenFOAM case it was exported from (`--vtk-case`, the v1912
   `windAroundBuildings` tutorial run, see tests/data/openfoam/README.md, and its
   `foamToVTK -latestTime` internal mesh): for the `roof` and `street` Windcube V2 of that
   case (region = `scan_bounds`), the read (`read_openfoam_field` / `read_vtk_field`) and the
   resampling (`resample_openfoam`, as `load_field` does) timed side by side, interleaved, in
   fresh processes, medians of `--repeats`; optionally (`--vtk-baseline REV`) the `.vtu`
   reader of an older git revision, whose grids must equal today's bitwise.

Writes benchmarks/results/cfd_ingest.{json,png,md}. `--quick` runs only the 1e5 mesh;
`--vtk-only` runs only workload 3 and writes benchmarks/results/cfd_ingest_vtk.{json,md}.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _common import machine, machine_line  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "benchmarks" / "results"
RADIUS, SPEED, DIRECTION = 20.0, 10.0, 250.0
LOCATION = [4.0, 3.0, 20.1]
HEIGHTS = [5.0, 10.0, 20.0, 40.0, 60.0, 100.0]


def graded_axis(lo: float, hi: float, fine_lo: float, fine_hi: float, h: float, ratio: float = 1.08):
    """Nodes: uniform `h` on [fine_lo, fine_hi], growing by `ratio` towards `lo` and `hi`."""
    mid = np.arange(fine_lo, fine_hi + 0.5 * h, h)
    right, s, step = [], mid[-1], h
    while s < hi - 1e-9:
        step *= ratio
        s = min(s + step, hi)
        right.append(s)
    left, s, step = [], mid[0], h
    while s > lo + 1e-9:
        step *= ratio
        s = max(s - step, lo)
        left.append(s)
    return np.concatenate([left[::-1], mid, right])


def axes_for(h: float):
    x = graded_axis(-300.0, 300.0, -80.0, 80.0, h)
    y = graded_axis(-300.0, 300.0, -80.0, 80.0, h)
    z = graded_axis(0.0, 400.0, 0.0, 140.0, h)
    return x, y, z


def spacing_for(n_cells: float) -> float:
    lo, hi = 0.2, 20.0
    for _ in range(40):
        mid = math.sqrt(lo * hi)
        n = np.prod([a.size - 1 for a in axes_for(mid)])
        lo, hi = (mid, hi) if n > n_cells else (lo, mid)
    return hi


def write_hemisphere_case(case: Path, n_cells: float) -> dict:
    import lidarjax as lj
    from lidarjax.io import _cells
    from tests._foamwrite import hex_mesh, write_polymesh, write_vector_field

    h = spacing_for(n_cells)
    x, y, z = axes_for(h)
    cx, cy, cz = (0.5 * (a[1:] + a[:-1]) for a in (x, y, z))
    r2 = cx[:, None, None] ** 2 + cy[None, :, None] ** 2 + cz[None, None, :] ** 2
    solid = r2 < RADIUS ** 2
    m = hex_mesh(x, y, z, solid)
    scene = lj.scenes.hemisphere(RADIUS, SPEED, DIRECTION, dtype=np.float64)
    vals = np.empty_like(m["cell_centres"])
    for s in range(0, vals.shape[0], 1_000_000):
        vals[s: s + 1_000_000] = np.asarray(scene.sample(m["cell_centres"][s: s + 1_000_000]))
    mesh = _cells.PolyMesh(m["points"], m["face_offsets"], m["face_labels"], m["owner"], m["neighbour"],
                           vals.shape[0], tuple(m["patches"]))
    write_polymesh(case, m["points"], m["face_offsets"], m["face_labels"], m["owner"], m["neighbour"],
                   m["patches"], binary=True)
    bnd = {}
    for name, _t, start, n in m["patches"]:
        if name == "walls":
            bnd[name] = ("zeroGradient", None)
        else:
            fc = _cells.face_geometry(mesh, np.arange(start, start + n))[0]
            bnd[name] = ("fixedValue", np.asarray(scene.sample(fc)))
    write_vector_field(case, "1", "U", vals, bnd, binary=True)
    (case / "system").mkdir(exist_ok=True)
    np.save(case / "cell_centres.npy", m["cell_centres"])
    return {"n_cells": int(vals.shape[0]), "h_fine": h, "shape": [x.size - 1, y.size - 1, z.size - 1]}


CHILD = r"""
import json, sys, time, resource
import numpy as np
sys.path.insert(0, {root!r})
import jax
jax.config.update("jax_enable_x64", True)
import lidarjax as lj
mode, case = {mode!r}, {case!r}
scan = lj.windcube_v2()
out = {{}}
if mode in ("new", "old"):
    mount = lj.Mount({location!r}, beta=0.0, gamma=0.0, psi=0.0, epsilon=0.0)
    heights = np.array({heights!r})
    t = time.perf_counter()
    if mode == "new":
        lo, hi = lj.scan_bounds(scan, mount, heights)
        field, rep = lj.io.load_field(case, region=(lo, hi), return_report=True)
        out.update(grid=list(rep.shape), spacing_min=rep.spacing_min, n_cells_used=rep.n_cells_used,
                   resample_error_rms=rep.resample_error_rms, resample_error_max=rep.resample_error_max)
    else:
        from lidarjax.io.openfoam import read_openfoam_field
        of = read_openfoam_field(case)
        cc = np.load(case + "/cell_centres.npy")
        arr = lj.io.resample_to_grid(cc, of.cell_values)
        field = lj.GridField(arr.x, arr.y, arr.z, arr.velocity)
        out.update(grid=list(arr.velocity.shape[:3]))
    out["load_s"] = time.perf_counter() - t
    scene = lj.scenes.hemisphere({radius!r}, {speed!r}, {direction!r}, dtype=np.float64)
    ref = lj.simulate(scene, scan, mount, heights)
    sim = lj.simulate(field, scan, mount, heights)
    out["speed_error"] = (np.asarray(sim.lidar_speed) - np.asarray(ref.lidar_speed)).tolist()
    out["los_error"] = np.abs(np.asarray(sim.los) - np.asarray(ref.los)).max(axis=1).tolist()
else:  # turbine: a Windcube per lidar of the points file, LOS vs OpenFOAM's probes
    import re
    from lidarjax.frames import lidar_to_cfd_rotation, rotate
    pts_file, probe_file = {points!r}, {probes!r}
    rows = np.loadtxt(pts_file, delimiter=",", skiprows=1, usecols=(1, 2, 3, 4, 5))
    names = np.loadtxt(pts_file, delimiter=",", skiprows=1, usecols=(0,), dtype=str)
    last = open(probe_file).read().splitlines()[-1]
    ref = np.array([[float(v) for v in g.split()] for g in re.findall(r"\(([^)]*)\)", last)])[: rows.shape[0]]
    for lidar in dict.fromkeys(names):
        sel = (names == lidar) & (rows[:, 1] >= 40.0)
        r, rr = rows[sel], ref[sel]
        heights = np.unique(r[:, 1])
        v = r[r[:, 0] == 4][0]
        mount = lj.Mount(np.array([v[2], v[3], v[4] - v[1]]), beta=0.0, gamma=0.0, psi=0.0, epsilon=0.0)
        lo, hi = lj.scan_bounds(scan, mount, heights)
        t = time.perf_counter()
        field, rep = lj.io.load_field(case, region=(lo, hi), return_report=True)
        load_s = time.perf_counter() - t
        los = np.asarray(lj.simulate(field, scan, mount, heights).los)
        n = np.asarray(rotate(lidar_to_cfd_rotation(mount), scan.directions()))
        d = []
        for k, (b, hh) in enumerate(r[:, :2]):
            d.append(los[np.searchsorted(heights, hh), int(b)] - rr[k] @ n[int(b)])
        d = np.asarray(d)
        out[lidar] = dict(load_s=load_s, n_cells=rep.n_cells, n_cells_used=rep.n_cells_used,
                          grid=list(rep.shape), los_rms=float(np.sqrt(np.mean(d ** 2))),
                          los_max=float(np.abs(d).max()), n_points=int(d.size),
                          resample_error_rms=rep.resample_error_rms)
# VmHWM: this process's own peak (ru_maxrss would include the forking parent's)
hwm = [ln for ln in open("/proc/self/status") if ln.startswith("VmHWM")]
out["peak_rss_gb"] = (int(hwm[0].split()[1]) / 1e6 if hwm
                      else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6)
print("RESULT" + json.dumps(out))
"""


VTK_CHILD = r"""
import json, sys, time, importlib.util
import numpy as np
sys.path.insert(0, {root!r})
import jax
jax.config.update("jax_enable_x64", True)
import lidarjax as lj
from lidarjax.io.openfoam import read_openfoam_field, resample_openfoam
from lidarjax.io.vtk import read_vtk_field
mode, path, out_npz = {mode!r}, {path!r}, {out_npz!r}
lo, hi = np.array({lo!r}), np.array({hi!r})
if mode == "openfoam":
    reader = read_openfoam_field
elif mode == "vtk":
    reader = read_vtk_field
else:  # the reader of an older revision, saved as a module file
    spec = importlib.util.spec_from_file_location("lidarjax.io._vtk_baseline", mode)
    old = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = old
    spec.loader.exec_module(old)
    reader = old.read_vtk_field
c0, t0 = time.process_time(), time.perf_counter()
of = reader(path)
c1, t1 = time.process_time(), time.perf_counter()
axes, vel, info = resample_openfoam(of, (lo, hi), None)
c2, t2 = time.process_time(), time.perf_counter()
if out_npz:
    np.savez(out_npz, x=axes[0], y=axes[1], z=axes[2], velocity=vel)
hwm = [ln for ln in open("/proc/self/status") if ln.startswith("VmHWM")]
print("RESULT" + json.dumps(dict(read_s=t1 - t0, resample_s=t2 - t1, load_s=t2 - t0, read_cpu_s=c1 - c0,
      resample_cpu_s=c2 - c1, load_cpu_s=c2 - c0,
      n_cells=int(of.mesh.n_cells), n_faces=int(of.mesh.n_faces), n_cells_used=int(info["n_cells_used"]),
      grid=list(vel.shape[:3]), peak_rss_gb=int(hwm[0].split()[1]) / 1e6 if hwm else float("nan"))))
"""

# the two Windcube V2 of the windAroundBuildings case (tests/data/openfoam/README.md)
VTK_LIDARS = {"roof": ([96.0, 126.0, 39.0], (10.0, 95.0)), "street": ([72.0, 66.0, 1.0], (10.0, 130.0))}


def vtk_child(mode: str, path: str, region, out_npz: str = "", timeout: float = 600.0) -> dict:
    code = VTK_CHILD.format(root=str(ROOT), mode=mode, path=path, out_npz=out_npz,
                            lo=[float(v) for v in region[0]], hi=[float(v) for v in region[1]])
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    try:
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                              timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"error": f"not finished after {timeout:g} s (stopped)"}
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT")]
    if proc.returncode != 0 or not line:
        return {"error": (proc.stderr or proc.stdout)[-800:]}
    return json.loads(line[-1][6:])


def baseline_module(rev: str, tmp: Path) -> str:
    """`lidarjax/io/vtk.py` of git revision `rev`, its relative imports made absolute."""
    src = subprocess.run(["git", "-C", str(ROOT), "show", f"{rev}:lidarjax/io/vtk.py"], capture_output=True,
                         text=True, check=True).stdout
    src = (src.replace("from .._util import", "from lidarjax._util import")
           .replace("from ._cells import", "from lidarjax.io._cells import")
           .replace("from .openfoam import", "from lidarjax.io.openfoam import"))
    path = tmp / f"vtk_{rev}.py"
    path.write_text(src)
    return str(path)


def run_vtk(case: Path, vtu: Path, repeats: int, baseline: str | None, baseline_repeats: int) -> dict:
    """Workload 3: `.vtu` against the OpenFOAM case, per lidar region, medians."""
    import lidarjax as lj

    scan = lj.windcube_v2()
    out: dict = {"case": str(case), "vtu": str(vtu), "repeats": repeats, "baseline": baseline, "lidars": {}}
    with tempfile.TemporaryDirectory(prefix="cfd_ingest_vtk_") as tmp:
        tmp_p = Path(tmp)
        paths = {"openfoam": str(case), "vtk": str(vtu)}
        if baseline:
            paths[f"vtk@{baseline}"] = str(vtu)
        modes = {"openfoam": "openfoam", "vtk": "vtk"}
        if baseline:
            modes[f"vtk@{baseline}"] = baseline_module(baseline, tmp_p)
        # warm-up: numba's on-disk cache of the grid kernel, the page cache of both files
        for key in ("openfoam", "vtk"):
            vtk_child(modes[key], paths[key], ([10.0, 10.0, 10.0], [20.0, 20.0, 20.0]))
        for lidar, (loc, (h0, h1)) in VTK_LIDARS.items():
            mount = lj.Mount(np.array(loc), beta=0.0, gamma=0.0, psi=0.0, epsilon=0.0)
            bounds = lj.scan_bounds(scan, mount, np.arange(h0, h1 + 1, 5.0))
            lo, hi = (np.asarray(v, np.float64).tolist() for v in bounds)
            runs: dict = {k: [] for k in modes}
            for r in range(max(repeats, baseline_repeats if baseline else 0)):
                for key in modes:  # interleaved, so that the machine's load falls on all alike
                    if r >= (baseline_repeats if key.startswith("vtk@") else repeats):
                        continue
                    npz = str(tmp_p / f"{lidar}_{key.replace('@', '_')}.npz") if r == 0 else ""
                    res = vtk_child(modes[key], paths[key], (lo, hi), npz)
                    print(lidar, key, json.dumps(res), flush=True)
                    runs[key].append(res)
            entry: dict = {"region": [lo, hi]}
            for key, rs in runs.items():
                ok = [x for x in rs if "load_s" in x]
                if not ok:
                    entry[key] = {"error": rs[0].get("error", "") if rs else "not run"}
                    continue
                entry[key] = {f: float(np.median([x[f] for x in ok]))
                              for f in ("read_s", "resample_s", "load_s", "read_cpu_s", "resample_cpu_s",
                                        "load_cpu_s")}
                entry[key].update({f"{f}_all": [x[f] for x in ok] for f in ("read_s", "load_s")})
                entry[key].update({f: ok[0][f] for f in ("n_cells", "n_faces", "n_cells_used", "grid")})
                entry[key]["peak_rss_gb"] = float(max(x["peak_rss_gb"] for x in ok))
            grids = {k: np.load(tmp_p / f"{lidar}_{k.replace('@', '_')}.npz") for k in modes
                     if (tmp_p / f"{lidar}_{k.replace('@', '_')}.npz").is_file()}
            if "vtk" in grids and "openfoam" in grids:
                a, b = grids["vtk"]["velocity"], grids["openfoam"]["velocity"]
                if a.shape == b.shape:
                    both = np.isfinite(a).all(-1) & np.isfinite(b).all(-1)
                    entry["vtk_vs_openfoam"] = {
                        "same_nan": bool(np.array_equal(np.isnan(a).any(-1), np.isnan(b).any(-1))),
                        "max_abs": float(np.abs(a[both] - b[both]).max()),
                        "rms": float(np.sqrt(np.mean((a[both] - b[both]) ** 2)))}
                else:
                    entry["vtk_vs_openfoam"] = {"grids": [list(a.shape), list(b.shape)]}
            if baseline and f"vtk@{baseline}" in grids and "vtk" in grids:
                g0, g1 = grids[f"vtk@{baseline}"], grids["vtk"]
                entry["vtk_equals_baseline_bitwise"] = bool(all(
                    np.array_equal(g0[k], g1[k], equal_nan=True) for k in ("x", "y", "z", "velocity")))
            out["lidars"][lidar] = entry
    return out


def write_vtk_md(res: dict, path: Path | None = None) -> list[str]:
    v = res["vtk"]
    keys = [k for k in ("openfoam", "vtk", f"vtk@{v['baseline']}") if k in next(iter(v["lidars"].values()), {})]
    lines = ["## `.vtu` against the OpenFOAM case (windAroundBuildings, v1912 `foamToVTK -latestTime`)", "",
             f"Machine: {machine_line(res['machine'])} (shared). Each load in a fresh process (JAX and "
             f"lidarjax imported, not timed), paths interleaved, medians of {v['repeats']} "
             "(the baseline: of its own repeats). read = `read_openfoam_field` / `read_vtk_field`; "
             "resample = `resample_openfoam` on the region of the lidar's `scan_bounds` "
             "(what `load_field(path, region=...)` does, less building the `GridField`). Wall seconds, "
             "and in brackets the process's CPU seconds (less sensitive to the other work on a shared "
             "machine).", "",
             "| lidar | path | cells | faces | cells used | grid | read s | resample s | load s | peak GB |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for lidar, e in v["lidars"].items():
        for k in keys:
            r = e.get(k, {})
            if "load_s" not in r:
                lines.append(f"| {lidar} | {k} | - | - | - | - | - | - | - | {r.get('error', '')[:60]} |")
                continue
            t = " | ".join(f"{r[f + '_s']:.2f} ({r.get(f + '_cpu_s', float('nan')):.2f})"
                           for f in ("read", "resample", "load"))
            lines.append(f"| {lidar} | {k} | {r['n_cells']:,} | {r['n_faces']:,} | {r['n_cells_used']:,} | "
                         f"{'x'.join(map(str, r['grid']))} | {t} | {r['peak_rss_gb']:.2f} |")
    lines.append("")
    for lidar, e in v["lidars"].items():
        c = e.get("vtk_vs_openfoam", {})
        if "grids" in c:
            lines.append(f"- {lidar}: the `.vtu` grid ({'x'.join(map(str, c['grids'][0][:3]))}) is not the "
                         f"case's ({'x'.join(map(str, c['grids'][1][:3]))}): the automatic axes are built "
                         "from the mesh's own points, float32 in the .vtu")
        if "max_abs" in c:
            lines.append(f"- {lidar}: `.vtu` grid against the case's: NaN nodes the same: {c['same_nan']}; "
                         f"max |diff| {c['max_abs']:.3g} m/s, rms {c['rms']:.3g} m/s (foamToVTK's float32 "
                         "points and values; VTK hexahedra cut into other tetrahedra)")
        if "vtk_equals_baseline_bitwise" in e:
            lines.append(f"- {lidar}: grid of today's `.vtu` reader equals {v['baseline']}'s bitwise: "
                         f"{e['vtk_equals_baseline_bitwise']}")
    if path is not None:
        head = "# CFD ingest: `.vtu` (benchmarks/cfd_ingest.py --vtk-only)\n\n"
        path.write_text(head + "\n".join(lines) + "\n")
    return lines


def run_child(mode: str, case: str, points: str = "", probes: str = "", timeout: float | None = None) -> dict:
    code = CHILD.format(root=str(ROOT), mode=mode, case=case, location=LOCATION, heights=HEIGHTS,
                        radius=RADIUS, speed=SPEED, direction=DIRECTION, points=points, probes=probes)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    try:
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                              timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"error": f"not finished after {timeout:g} s (stopped)"}
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT")]
    if proc.returncode != 0 or not line:
        return {"error": (proc.stderr or proc.stdout)[-800:]}
    return json.loads(line[-1][6:])


def main() -> None:
    import jax

    jax.config.update("jax_enable_x64", True)  # the exact cell values in float64
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="only the 1e5-cell mesh")
    ap.add_argument("--sizes", type=float, nargs="*", default=None)
    ap.add_argument("--old-max", type=float, default=1.5e6, help="largest mesh for the old path")
    ap.add_argument("--old-timeout", type=float, default=240.0, help="seconds allowed to the old path")
    ap.add_argument("--turbine-case", default="/work/i11a_of/ts")
    ap.add_argument("--turbine-probes", default="/work/i11a_of/ts/postProcessing/probes/168/U")
    ap.add_argument("--vtk-case", default="/work/cases/windAroundBuildings",
                    help="windAroundBuildings case run to its latest time, with foamToVTK's output")
    ap.add_argument("--vtu", default=None, help="default: VTK/<case>_<index>/internal.vtu of --vtk-case")
    ap.add_argument("--vtk-only", action="store_true", help="only the .vtu vs OpenFOAM workload")
    ap.add_argument("--repeats", type=int, default=5, help="loads per path and lidar (.vtu workload)")
    ap.add_argument("--vtk-baseline", default=None, help="git revision whose .vtu reader is timed too")
    ap.add_argument("--baseline-repeats", type=int, default=3)
    args = ap.parse_args()
    vcase = Path(args.vtk_case)
    vtu = Path(args.vtu) if args.vtu else next(iter(sorted(vcase.glob("VTK/*/internal.vtu"))), None)
    if args.vtk_only:
        if vtu is None or not vtu.is_file():
            raise SystemExit(f"no .vtu: run foamToVTK -latestTime in {vcase} or give --vtu")
        res = {"machine": machine(), "vtk": run_vtk(vcase, vtu, args.repeats, args.vtk_baseline,
                                                     args.baseline_repeats)}
        RESULTS.mkdir(parents=True, exist_ok=True)
        (RESULTS / "cfd_ingest_vtk.json").write_text(json.dumps(res, indent=1))
        write_vtk_md(res, RESULTS / "cfd_ingest_vtk.md")
        return
    sizes = args.sizes or ([1e5] if args.quick else [1e5, 1e6, 5e6])
    results: dict = {"hemisphere": [], "turbineSiting": None, "machine": machine()}
    data = ROOT / "tests" / "data" / "openfoam"
    with tempfile.TemporaryDirectory(prefix="cfd_ingest_") as tmp:
        for n in sizes:
            case = Path(tmp) / f"hemi_{int(n)}"
            t = time.perf_counter()
            meta = write_hemisphere_case(case, n)
            meta["write_s"] = time.perf_counter() - t
            meta["bytes"] = sum(f.stat().st_size for f in case.rglob("*") if f.is_file())
            entry = {"target_cells": n, **meta, "new": run_child("new", str(case))}
            entry["old"] = (run_child("old", str(case), timeout=args.old_timeout) if n <= args.old_max
                            else {"skipped": "Delaunay of every cell centre"})
            print(json.dumps(entry), flush=True)
            results["hemisphere"].append(entry)
            for f in case.rglob("*"):
                if f.is_file():
                    f.unlink()
    tcase, tprobes = Path(args.turbine_case), Path(args.turbine_probes)
    if tcase.is_dir() and tprobes.is_file():
        pts = "/tmp/cfd_ingest_points.csv"
        # the full run's probes cover three lidars; the points file lists them in order
        full_pts = Path(args.turbine_case) / "lidar_points.csv"
        src = full_pts if full_pts.is_file() else data / "turbineSiting_points.csv"
        Path(pts).write_text(src.read_text())
        results["turbineSiting"] = {"case": str(tcase), **run_child("turbine", str(tcase), pts, str(tprobes))}
    else:
        results["turbineSiting"] = {"case": "committed cut", **run_child(
            "turbine", str(data / "turbineSiting_cut"), str(data / "turbineSiting_points.csv"),
            str(data / "turbineSiting_cut" / "postProcessing" / "probes" / "168" / "U"))}
    print(json.dumps(results["turbineSiting"]), flush=True)
    if vtu is not None and vtu.is_file():
        results["vtk"] = run_vtk(vcase, vtu, args.repeats, args.vtk_baseline, args.baseline_repeats)
    RESULTS.mkdir(parents=True, exist_ok=True)
    name = "cfd_ingest_quick" if args.quick else "cfd_ingest"
    (RESULTS / f"{name}.json").write_text(json.dumps(results, indent=1))
    write_md(results, RESULTS / f"{name}.md")
    plot(results, RESULTS / f"{name}.png")


def write_md(res: dict, path: Path) -> None:
    lines = ["# CFD ingest (benchmarks/cfd_ingest.py)", "",
             f"Machine: {machine_line(res['machine'])} (shared). Each load in a fresh process; "
             "peak = max RSS of that process (includes JAX).", "",
             "## Graded hemisphere mesh (exact potential flow), Windcube V2 on the body", "",
             "| cells | path | load s | peak GB | grid | max speed error m/s (heights " +
             ", ".join(f"{h:g}" for h in HEIGHTS) + " m) |", "|---|---|---|---|---|---|"]
    for e in res["hemisphere"]:
        for key in ("new", "old"):
            r = e[key]
            if "load_s" not in r:
                why = r.get("skipped", r.get("error", ""))[:80]
                lines.append(f"| {e['n_cells']:,} | {key} | - | - | - | {why} |")
                continue
            err = ", ".join(f"{abs(v):.4f}" for v in r["speed_error"])
            lines.append(f"| {e['n_cells']:,} | {key} | {r['load_s']:.1f} | {r['peak_rss_gb']:.2f} | "
                         f"{'x'.join(map(str, r['grid']))} | {err} |")
    t = res.get("turbineSiting") or {}
    lines += ["", f"## OpenFOAM turbineSiting ({t.get('case')}), LOS vs OpenFOAM probes (cellPoint), "
              "heights >= 40 m", "",
              "| lidar | cells | cells used | grid | load s | LOS rms m/s | LOS max m/s |",
              "|---|---|---|---|---|---|---|"]
    for k, v in t.items():
        if isinstance(v, dict):
            grid = "x".join(map(str, v["grid"]))
            lines.append(f"| {k} | {v['n_cells']:,} | {v['n_cells_used']:,} | {grid} | "
                         f"{v['load_s']:.1f} | {v['los_rms']:.4f} | {v['los_max']:.4f} |")
    if res.get("vtk"):
        lines += [""] + write_vtk_md(res)
    path.write_text("\n".join(lines) + "\n")


def plot(res: dict, path: Path) -> None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    for key, mk in (("new", "o-"), ("old", "s--")):
        ok = [e for e in res["hemisphere"] if "load_s" in e[key]]
        if ok:
            ax[0].loglog([e["n_cells"] for e in ok], [e[key]["load_s"] for e in ok], mk, label=f"{key} load s")
            ax[0].loglog([e["n_cells"] for e in ok], [e[key]["peak_rss_gb"] for e in ok], mk, alpha=0.5,
                         label=f"{key} peak GB")
        for e in ok:
            ax[1].semilogy(HEIGHTS, np.maximum(np.abs(e[key]["speed_error"]), 1e-6), mk,
                           label=f"{key} {e['n_cells']:.1e} cells")
    ax[0].set_xlabel("cells")
    ax[0].legend(fontsize=7)
    ax[1].axhline(0.01, color="k", lw=0.8)
    ax[1].set_xlabel("height above lidar (m)")
    ax[1].set_ylabel("|horizontal speed error| (m/s)")
    ax[1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    main()
