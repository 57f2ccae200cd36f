"""Design by gradients against grid search: where to put the lidar (`lidarjax.design_placement`)
and two dual-Doppler lidars (`lidarjax.design_dual_doppler`).

Cases (every optimiser run is timed from a cold start, compilation included, beside a grid
search of the same objective timed the same way, in the same process):

- **hemisphere (scene)**: the analytic hemisphere of radius 20 m (potential flow, 10 m/s), a
  Windcube V1 1 m above its surface anywhere over the square |x|, |y| <= 12 m (a polygon region
  with the dome as surface), 36 inflow directions weighted by a wind rose (mostly from the
  west), 8 heights 10-80 m, objective the smooth worst case (p-norm, p = 8) of
  ``sqrt((C_U - 1)^2 + (0.01 C_th)^2)``; grid search: 50 x 50 = 2,500 candidates x 36
  directions.
- **hemisphere (200 x 200 x 100 grid)**: the same hemisphere gridded on 200 x 200 x 100 nodes
  (1 m horizontally, 1 m vertically), one run seen by the platform turned through 36 rotations
  (the seed's rotated platform), the lidar 1 m above the dome: the issue's speed case (goal
  <= 60 s with compilation on this 2-core CPU). (The surface read from the grid's solid nodes
  is a staircase of the node spacing, whose kinks give the objective local minima; a known
  surface is given as a function.) Trilinear interpolation's kinks keep BFGS from meeting its
  tolerance: the local searches stop at ``max_steps=35``.
- **OpenFOAM roof**: the committed windAroundBuildings cut (inflow 10 m/s along +x), a Windcube
  V2 1 m above the 38 m roof, heights 10-30 m, one inflow; grid search 50 x 50.
- **dual-Doppler**: nine target points over 400 m x 400 m at 100 m, two lidars in 1 km boxes;
  grid search 12^4 = 20,736 pairs.

The machine is shared with other jobs: the load average (`uptime`) before and after is
recorded. Run ``python benchmarks/design.py``; writes ``benchmarks/results/design.json``,
``design.md``, ``design.png`` and ``design_openfoam.png``.
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _common import machine, machine_line  # noqa: E402

import lidarjax as lj  # noqa: E402
from lidarjax import plots  # noqa: E402

ROOT = Path(__file__).resolve().parent
OUT = ROOT / "results"
DATA = ROOT.parent / "tests" / "data"
R = 20.0


def load():
    return [round(v, 2) for v in os.getloadavg()]


def grid2(lo, hi, n):
    a, b = np.linspace(lo[0], hi[0], n), np.linspace(lo[1], hi[1], n)
    return np.stack(np.meshgrid(a, b, indexing="ij"), -1).reshape(-1, 2)


def timed(fn):
    t = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t


def placement_case(name, field, scan, mount, heights, region, kw, grid, n_dirs, design_kw=None):
    res, t_opt = timed(lambda: lj.design_placement(field, scan, mount, heights, region,
                                                   **kw, **(design_kw or {})))
    problem = lj.placement_problem(field, scan, mount, heights, region, **kw)[0]
    (values, ok), t_grid = timed(lambda: lj.evaluate_placements(problem, grid))
    k = int(np.nanargmin(values))
    out = {
        "case": name, "directions": n_dirs, "heights": len(heights),
        "optimiser": {"x": res.x.tolist(), "location": res.location.tolist(),
                      "value": res.value, "worst": res.worst, "rms": res.rms,
                      "gradient": res.gradient.tolist(), "converged": res.converged,
                      "n_evaluations": res.n_evaluations, "n_forward": res.n_forward,
                      "time_s_with_compilation": t_opt, "start_value": res.start_value},
        "grid_search": {"candidates": int(grid.shape[0]), "feasible": int(ok.sum()),
                        "x": grid[k].tolist(), "value": float(values[k]),
                        "n_forward": int(grid.shape[0]) * n_dirs,
                        "time_s_with_compilation": t_grid},
    }
    out["value_ratio"] = res.value / float(values[k])
    out["forward_ratio"] = out["grid_search"]["n_forward"] / res.n_forward
    print(f"{name}: optimiser {res.value:.6g} at {np.round(res.x, 3)} in {t_opt:.1f} s "
          f"({res.n_forward} forward), grid {values[k]:.6g} at {grid[k]} in {t_grid:.1f} s "
          f"({out['grid_search']['n_forward']} forward); ratio {out['value_ratio']:.5f}",
          flush=True)
    return out, res, (grid, values)


def main() -> int:
    OUT.mkdir(exist_ok=True)
    results = {"machine": machine(), "load_before": load(), "cases": []}
    print(machine_line(results["machine"]), "load", results["load_before"], flush=True)
    heights = np.arange(10.0, 81.0, 10.0)  # 8 heights
    dirs = np.arange(0.0, 360.0, 10.0)  # 36 directions
    rose = 1.0 + 0.8 * np.cos(np.deg2rad(dirs - 270.0))
    square = [(-12.0, -12.0), (12.0, -12.0), (12.0, 12.0), (-12.0, 12.0)]

    def dome(x, y):
        return jnp.sqrt(jnp.maximum(R**2 - x**2 - y**2, 0.0))

    scene = lj.scenes.hemisphere(radius=R, speed=10.0)
    grid = grid2((-12.0, -12.0), (12.0, 12.0), 50)
    case, res, (g, v) = placement_case(
        "hemisphere (scene)", scene, lj.windcube_v1(), lj.Mount([0.0, 0.0, R + 1.0]), heights,
        lj.RegionPolygon(square, height=1.0, surface=dome),
        dict(directions=dirs, weights=rose), grid, dirs.size)
    results["cases"].append(case)
    plots.plot_design(res, OUT / "design.png", grid_xy=g, grid_values=v, outline=square,
                      title="hemisphere platform: worst-case |C_U - 1|, 36 directions x 8 heights")

    # the 200 x 200 x 100 grid: one run, the platform turned through 36 rotations
    x = np.linspace(-100.0, 100.0, 200)
    z = np.linspace(0.0, 100.0, 100)
    field = lj.GridField.from_function(scene.sample, x, x, z)
    case, res_g, _ = placement_case(
        "hemisphere (200x200x100 grid, 36 rotations)", field, lj.windcube_v1(),
        lj.Mount([0.0, 0.0, R + 1.0]), heights, lj.RegionPolygon(square, height=1.0, surface=dome),
        dict(rotations=dirs, pivot=(0.0, 0.0), u_ref=[10.0, 0.0, 0.0], weights=rose), grid,
        dirs.size, dict(max_steps=35))
    results["cases"].append(case)
    del field

    # the committed OpenFOAM roof
    of = lj.io.load_field(DATA / "openfoam" / "windAroundBuildings_cut",
                          region=([76.0, 106.0, 20.0], [116.0, 146.0, 80.0]), spacing=2.0)
    roof = [(90.0, 120.0), (96.0, 120.0), (96.0, 132.0), (90.0, 132.0)]
    case, res_o, (g, v) = placement_case(
        "OpenFOAM roof (windAroundBuildings)", of, lj.windcube_v2(), lj.Mount([93.0, 126.0, 39.0]),
        [10.0, 20.0, 30.0], lj.RegionPolygon(roof, height=1.0), dict(u_ref=[10.0, 0.0, 0.0]),
        grid2((90.0, 120.0), (96.0, 132.0), 50), 1, dict(n_coarse=36, n_starts=3, max_steps=30))
    results["cases"].append(case)
    plots.plot_design(res_o, OUT / "design_openfoam.png", grid_xy=g, grid_values=v,
                      outline=roof, title="windAroundBuildings roof: worst-case error, inflow +x")

    # dual-Doppler over a region
    xs = np.linspace(-200.0, 200.0, 3)
    pts = np.array([(a, b, 100.0) for a in xs for b in xs])
    ra = lj.RegionBox((-1500.0, -1000.0, 0.0), (-500.0, 1000.0, 0.0))
    rb = lj.RegionBox((-1000.0, 500.0, 0.0), (1000.0, 1500.0, 0.0))
    dd, t_dd = timed(lambda: lj.design_dual_doppler(pts, ra, rb, n_coarse=81))
    a = grid2((-1500.0, -1000.0), (-500.0, 1000.0), 12)
    b = grid2((-1000.0, 500.0), (1000.0, 1500.0), 12)

    @jax.jit
    def all_pairs(a, b):
        def mean_var(pa, pb):
            return jnp.mean(lj.dual_doppler_variance(jnp.append(pa, 0.0), jnp.append(pb, 0.0),
                                                     pts))
        return jax.vmap(lambda pa: jax.vmap(lambda pb: mean_var(pa, pb))(b))(a)

    gv, t_gs = timed(lambda: np.asarray(all_pairs(jnp.asarray(a), jnp.asarray(b))))
    i, j = np.unravel_index(np.nanargmin(gv), gv.shape)
    results["dual_doppler"] = {
        "optimiser": {"location_a": dd.location_a.tolist(), "location_b": dd.location_b.tolist(),
                      "mean_variance": dd.value, "n_evaluations": dd.n_evaluations,
                      "time_s_with_compilation": t_dd},
        "grid_search": {"pairs": int(gv.size), "location_a": a[i].tolist(),
                        "location_b": b[j].tolist(), "mean_variance": float(gv[i, j]),
                        "time_s_with_compilation": t_gs}}
    print(f"dual-Doppler: optimiser {dd.value:.6g} ({dd.n_evaluations} evaluations, {t_dd:.1f} s)"
          f", grid {gv[i, j]:.6g} ({gv.size} pairs, {t_gs:.1f} s)", flush=True)
    results["load_after"] = load()
    (OUT / "design.json").write_text(json.dumps(results, indent=1))
    lines = ["# Design by gradients against grid search", "",
             f"{machine_line(results['machine'])}; load average before "
             f"{results['load_before']}, after {results['load_after']} (shared machine).", "",
             "| case | directions x heights | optimiser objective | grid objective | ratio | "
             "forward sims (opt / grid) | time with compilation (opt / grid) | optimum | "
             "grid optimum |", "|---|---|---:|---:|---:|---:|---:|---|---|"]
    for c in results["cases"]:
        o, gs = c["optimiser"], c["grid_search"]
        lines.append(f"| {c['case']} | {c['directions']} x {c['heights']} | {o['value']:.5g} | "
                     f"{gs['value']:.5g} | {c['value_ratio']:.4f} | {o['n_forward']} / "
                     f"{gs['n_forward']} ({c['forward_ratio']:.0f}x fewer) | "
                     f"{o['time_s_with_compilation']:.1f} s / "
                     f"{gs['time_s_with_compilation']:.1f} s | "
                     f"({', '.join(f'{v:.2f}' for v in o['location'])}) | "
                     f"({', '.join(f'{v:.2f}' for v in gs['x'])}) |")
    d = results["dual_doppler"]
    lines += ["", f"Dual-Doppler, 9 points: optimiser mean var(u)+var(v) "
              f"{d['optimiser']['mean_variance']:.5g} sigma^2 in "
              f"{d['optimiser']['n_evaluations']} evaluations "
              f"({d['optimiser']['time_s_with_compilation']:.1f} s), grid search of "
              f"{d['grid_search']['pairs']} pairs {d['grid_search']['mean_variance']:.5g} "
              f"({d['grid_search']['time_s_with_compilation']:.1f} s)."]
    (OUT / "design.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
