# ruff: noqa
# Recipe script as run for tests/data/openfoam (paths are those of the run; adapt them).
"""windAroundBuildings: load_field time, LOS vs OpenFOAM probes, NaN inside buildings."""
import json
import sys
import time

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)
import lidarjax as lj
from lidarjax.frames import lidar_to_cfd_rotation, rotate
from lidarjax.io.openfoam import read_openfoam_field, sample_openfoam
from lidarjax.io.monitor_points import read_openfoam_probes, read_monitor_points_csv

case = sys.argv[1]; pdir = sys.argv[2]
locs = read_monitor_points_csv('/work/f11_of/probes/lidarProbes.csv')
of = read_openfoam_probes(pdir).values_for(locs)
scan = lj.windcube_v2()
mounts = {"roof": np.array([96.0, 126.0, 39.0]), "street": np.array([72.0, 66.0, 1.0])}
out = {}
f = read_openfoam_field(case)
pts = sample_openfoam(f, locs.points)
fin = np.isfinite(of).all(1)
out["pointwise_max"] = float(np.nanmax(np.abs(pts[fin] - of[fin])))
out["nan_agree"] = bool(np.array_equal(~fin, ~np.isfinite(pts).all(1)))
out["n_notfound"] = int((~fin).sum())
out["n_cells"] = int(f.mesh.n_cells)
for lab, loc in mounts.items():
    rows = locs.rows(lab); rows = rows[locs.beam[rows] >= 0]
    heights = np.unique(locs.height[rows])
    mount = lj.Mount(loc, beta=0.0, gamma=0.0, psi=0.0, epsilon=0.0)
    lo, hi = lj.scan_bounds(scan, mount, heights)
    t = time.perf_counter()
    field, rep = lj.io.load_field(case, region=(lo, hi), return_report=True)
    tl = time.perf_counter() - t
    los = np.asarray(lj.simulate(field, scan, mount, heights).los)
    n = np.asarray(rotate(lidar_to_cfd_rotation(mount), scan.directions()))
    ref = np.full_like(los, np.nan)
    for r in rows:
        ref[np.searchsorted(heights, locs.height[r]), locs.beam[r]] = of[r] @ n[locs.beam[r]]
    d = los - ref
    ok = np.isfinite(d)
    order = np.argsort(-np.abs(np.nan_to_num(d)).ravel())[:6]
    print(lab, "worst:", [(float(heights[i // d.shape[1]]), int(i % d.shape[1]), round(float(d.ravel()[i]), 4)) for i in order])
    for hmin in (10.0, 20.0, 30.0):
        sel = ok & (heights[:, None] >= hmin)
        print(lab, f"h>={hmin}: rms", float(np.sqrt(np.mean(d[sel] ** 2))), "max", float(np.abs(d[sel]).max()))
    # NaN inside buildings: grid nodes inside the solid
    g = np.asarray(field.values) if hasattr(field, "values") else None
    out[lab] = dict(load_s=tl, grid=list(np.shape(field.velocity)[:3]),
                    cells_used=int(rep.n_cells_used) if getattr(rep, "n_cells_used", None) is not None else None,
                    nan_fraction=float(rep.nan_fraction), los_rms=float(np.sqrt(np.mean(d[ok] ** 2))),
                    los_max=float(np.abs(d[ok]).max()), n_los=int(ok.sum()),
                    los_nan_both=int((np.isnan(los) & np.isnan(ref)).sum()),
                    los_nan_lj_only=int((np.isnan(los) & ~np.isnan(ref)).sum()),
                    los_nan_of_only=int((~np.isnan(los) & np.isnan(ref)).sum()),
                    resample_rms=float(rep.resample_error_rms), resample_max=float(rep.resample_error_max))
    print(lab, out[lab], flush=True)
# points inside buildings
inside = np.array([[96.0, 126.0, 20.0], [96.0, 126.0, 37.0], [60.0, 35.0, 30.0]])
lo, hi = inside.min(0) - 2, inside.max(0) + 2
out["inside_samples"] = sample_openfoam(f, inside).tolist()
print(json.dumps(out, indent=1))
json.dump(out, open(sys.argv[3], "w"), indent=1)
