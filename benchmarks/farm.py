"""Benchmark: a lidar in a 100-turbine farm, lidarjax's WindFarm against FLORIS.

Farm: 100 NREL-5MW-sized turbines (D = 126 m, hub 90 m) on a 10 x 10 grid at 7 D, constant
Ct = 0.8 (speed independent, so both codes solve the same thrust), free stream 8 m/s, no
shear, turbine yaws spread over -20..20 degrees. A Windcube V2 in the middle of the farm,
10 heights from 40 to 200 m, the pulsed probe (9 nodes per beam): 450 points per direction.

1. **Throughput, same model, same points.** Jensen top-hat wakes + Jimenez deflection, sum
   of squares, for 360 directions (1 degree): FLORIS ``sample_flow_at_points`` (all 360
   directions in one call, its vectorised path) against lidarjax (`WindFarm.solve` +
   `streamwise_local`, vmapped over directions, jit-compiled; compile time apart). The
   streamwise speeds are compared point by point. Also timed: lidarjax's full forward
   model (LOS with the pulsed probe, reconstruction) and its gradient (reverse mode) of the
   sum of reconstructed speeds w.r.t. every turbine's yaw, x and y, for all 360 directions.
2. **Inverting on a waked site.** Gaussian wakes (smooth in direction), the same lidar
   3.5 D downstream of a 3 x 3 block of turbines. Response tables every 30, 10, 5 and 2
   degrees; "records" at 0.25-degree steps (1440 directions, all off the table nodes for
   the finer tables, no noise), each inverted with `lidarjax.invert`; the error of the
   recovered free-stream speed and direction against the uncorrected lidar, over all
   directions and outside the IEC 61400-12-1 Annex A disturbed sectors.

Writes benchmarks/results/farm.{json,md,png}. Run from a checkout:
``python benchmarks/farm.py [--quick]``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # benchmark this checkout, not an installed copy

import equinox as eqx  # noqa: E402
import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _common import machine, machine_line  # noqa: E402

import lidarjax as lj  # noqa: E402
from lidarjax.disturbed_sectors import disturbed_sectors, in_sectors, merge_sectors  # noqa: E402
from lidarjax.scenes import farm as fm  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"
D, HUB, SPEED = 126.0, 90.0, 8.0


def grid_farm(n_side, model, directions=270.0, yaw=True):
    g = np.arange(n_side) * 7 * D
    e, n = (a.ravel() for a in np.meshgrid(g, g))
    yaws = np.linspace(-20, 20, e.size) if yaw else 0.0
    return lj.scenes.wind_farm(e + 500_000.0, n + 6_000_000.0, HUB, D, ct=0.8, yaw=yaws,
                               speed=SPEED, direction=directions, model=model)


def timed(fn, repeats):
    out = []
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(fn())
        out.append(time.perf_counter() - t)
    return float(np.median(out)), out


def throughput(quick):
    n_side = 5 if quick else 10
    n_dir = 60 if quick else 360
    farm = grid_farm(n_side, "top_hat")
    dirs = np.arange(n_dir) * (360.0 / n_dir)
    scan, probe = lj.windcube_v2(), lj.PulsedProbe()
    heights = jnp.linspace(40.0, 200.0, 10)
    centre = np.array([np.mean(farm.x) + 3.5 * D, np.mean(farm.y) + 0.5 * D, 0.0])
    mount = lj.Mount(centre + np.asarray(farm.origin) + np.asarray(farm.origin_lo))
    # the sample points of the pulsed probe (beam nodes), local coordinates
    sim0 = lj.simulate(farm, scan, mount, heights, probe=probe)
    dirs_cfd = np.asarray(sim0.directions)
    ranges = np.asarray(heights)[:, None] / np.asarray(scan.directions())[None, :, 2]
    offs = np.asarray(probe.nodes(jnp.asarray(ranges))[0])  # (q,) range offsets of the nodes
    r = ranges[..., None] + offs
    pts = centre + r[..., None] * dirs_cfd[None, :, None, :]  # (h, b, q, 3)
    pts = pts.reshape(-1, 3)
    pts = pts[pts[:, 2] > 0]
    n_pts = pts.shape[0]

    @jax.jit
    def lj_points(f, d):
        def one(di):
            g = eqx.tree_at(lambda x: x.direction, f, di)
            return g.streamwise_local(jnp.asarray(pts))
        return jax.vmap(one)(d)

    d_j = jnp.asarray(dirs)
    t0 = time.perf_counter()
    lj_points.lower(farm, d_j).compile()
    compile_s = time.perf_counter() - t0
    lj_med, lj_all = timed(lambda: lj_points(farm, d_j), 5)
    u_lj = np.asarray(lj_points(farm, d_j))

    @jax.jit
    def forward(f, d):
        def one(di):
            g = eqx.tree_at(lambda x: x.direction, f, di)
            return lj.simulate(g, scan, mount, heights, probe=probe, point_reference=False).lidar_speed
        return jax.vmap(one)(d)

    def loss(params, f, d):
        g = eqx.tree_at(lambda x: (x.yaw, x.x, x.y), f, params)
        return jnp.sum(forward(g, d))

    grad = jax.jit(jax.grad(loss))
    params = (farm.yaw, farm.x, farm.y)
    forward(farm, d_j).block_until_ready()
    grad(params, farm, d_j)[0].block_until_ready()
    fwd_med, _ = timed(lambda: forward(farm, d_j), 3)
    grad_med, _ = timed(lambda: grad(params, farm, d_j), 1 if not quick else 3)
    g = grad(params, farm, d_j)
    grads_finite = bool(all(np.all(np.isfinite(np.asarray(a))) for a in g))

    result = dict(n_turbines=int(farm.n_turbines), n_directions=n_dir, n_points=int(n_pts),
                  lidarjax_points_s=lj_med, lidarjax_points_all_s=lj_all,
                  lidarjax_compile_s=compile_s, lidarjax_forward_s=fwd_med,
                  lidarjax_gradient_s=grad_med, gradient_over_forward=grad_med / fwd_med,
                  gradients_finite=grads_finite)
    try:
        model = fm.to_floris(farm)
    except ImportError:
        result["floris"] = "not installed (pip install lidarjax[farm])"
        return result
    # FLORIS's cost is linear in the number of directions (its `findex` axis is vectorised);
    # `stride` > 1 times it on every stride-th direction only (throughput per direction)
    stride = 1
    fd = dirs[::stride]
    model.set(wind_directions=fd, wind_speeds=np.full(fd.size, SPEED),
              turbulence_intensities=np.full(fd.size, 0.06),
              yaw_angles=np.tile(np.asarray(farm.yaw), (fd.size, 1)))
    t0 = time.perf_counter()
    u_fl = np.asarray(model.sample_flow_at_points(*pts.T))
    fl_med = time.perf_counter() - t0
    fl_all = [fl_med]
    err = np.abs(u_lj[::stride] - u_fl)
    per_dir_fl = fl_med / fd.size
    per_dir_lj = lj_med / n_dir
    result.update(floris_directions=int(fd.size), floris_points_s=fl_med,
                  floris_points_all_s=fl_all, floris_per_direction_s=per_dir_fl,
                  lidarjax_per_direction_s=per_dir_lj,
                  floris_points_360_estimate_s=per_dir_fl * n_dir,
                  speedup_points=per_dir_fl / per_dir_lj,
                  speedup_with_gradient=per_dir_fl / (grad_med / n_dir),
                  max_abs_difference_m_s=float(err.max()),
                  frac_points_within_1e4=float(np.mean(err <= 1e-4)),
                  frac_points_waked=float(np.mean(u_fl < SPEED - 1e-9)))
    return result


def inverse_error(quick):
    e0, n0 = np.meshgrid(np.arange(3) * 5 * D, np.arange(3) * 5 * D)
    e0, n0 = e0.ravel(), n0.ravel()
    farm = lj.scenes.wind_farm(e0, n0, HUB, D, ct=0.8, speed=SPEED, model="gaussian")
    lidar = np.array([e0.max() + 3.5 * D, 5 * D + 0.3 * D, 0.0])
    scan, probe = lj.windcube_v2(), lj.PulsedProbe()
    heights = jnp.array([60.0, 90.0, 120.0])
    mount = lj.Mount(lidar)

    @jax.jit
    def sims(d):
        def one(di):
            g = eqx.tree_at(lambda x: x.direction, farm, di)
            return lj.simulate(g, scan, mount, heights, u_ref=SPEED * lj.heading(di),
                               probe=probe, point_reference=False)
        return jax.vmap(one)(d)

    step = 1.0 if quick else 0.25
    truth = np.arange(0.0, 360.0, step) + 0.5 * step
    rec = sims(jnp.asarray(truth))
    los = np.asarray(rec.los)
    sec = merge_sectors(disturbed_sectors(lidar, e0, n0, D))
    clean = ~in_sectors(truth, sec)
    unc_speed = np.abs(np.asarray(rec.lidar_speed) / SPEED - 1.0)
    unc_dir = np.abs(np.asarray(lj.wrap180(np.asarray(rec.lidar_direction) - truth[:, None])))

    def stats(a, mask):
        a = a[mask].ravel()  # NaN: not converged (counted in `converged`)
        return dict(median=float(np.nanmedian(a)), p95=float(np.nanpercentile(a, 95)),
                    max=float(np.nanmax(a)))

    out = dict(lidar=lidar.tolist(), n_records=int(truth.size), heights_m=[60.0, 90.0, 120.0],
               disturbed_sectors=sec, uncorrected=dict(
                   speed_all=stats(unc_speed, slice(None)), speed_clean=stats(unc_speed, clean),
                   direction_all=stats(unc_dir, slice(None)), direction_clean=stats(unc_dir, clean)),
               tables={})
    for res in (30.0, 10.0, 5.0, 2.0):
        dt = np.arange(0.0, 360.0, res)
        table = lj.ResponseTable.from_simulations(sims(jnp.asarray(dt)))
        t = time.perf_counter()
        inv = lj.invert(table, jnp.asarray(los))
        jax.block_until_ready(inv.speed)
        t_inv = time.perf_counter() - t
        sp = np.abs(np.asarray(inv.speed) / SPEED - 1.0)
        di = np.abs(np.asarray(lj.wrap180(np.asarray(inv.direction) - truth[:, None])))
        out["tables"][f"{res:g}"] = dict(
            speed_all=stats(sp, slice(None)), speed_clean=stats(sp, clean),
            direction_all=stats(di, slice(None)), direction_clean=stats(di, clean),
            converged=float(np.mean(np.asarray(inv.converged))), invert_s=t_inv)
    return out


def write(results):
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "farm.json").write_text(json.dumps(results, indent=1))
    if "throughput" not in results or "inverse" not in results:
        return
    t, inv = results["throughput"], results["inverse"]
    lines = ["# Farm benchmark", "",
             f"{t['n_turbines']} turbines, {t['n_directions']} directions, {t['n_points']} pulsed-probe "
             f"points per direction ({machine_line(results['machine'])}).", "",
             "| | seconds (median) | ratio |", "|---|---|---|"]
    if "floris_points_s" in t:
        lines.append(f"| FLORIS sample_flow_at_points ({t.get('floris_directions', t['n_directions'])} "
                     f"directions timed, per {t['n_directions']}) | "
                     f"{t.get('floris_points_360_estimate_s', t['floris_points_s']):.3g} | 1 |")
        lines.append(f"| lidarjax streamwise at the same points | {t['lidarjax_points_s']:.3g} | "
                     f"{t['speedup_points']:.1f}x faster |")
        lines.append(f"| lidarjax gradient (yaw, x, y; all directions) | {t['lidarjax_gradient_s']:.3g} | "
                     f"{t['speedup_with_gradient']:.1f}x faster than FLORIS forward |")
    lines += [f"| lidarjax full forward (LOS, probe, reconstruction) | {t['lidarjax_forward_s']:.3g} | |",
              f"| lidarjax compile (points) | {t['lidarjax_compile_s']:.3g} | |", ""]
    if "max_abs_difference_m_s" in t:
        lines += [f"Largest |lidarjax - FLORIS| over all points and directions: "
                  f"{t['max_abs_difference_m_s']:.2e} m/s ({100 * t['frac_points_within_1e4']:.3f}% within "
                  f"1e-4 m/s; {100 * t['frac_points_waked']:.1f}% of the points are waked).", ""]
    lines += ["## Inverse on a waked site (Gaussian wakes)", "",
              "Absolute errors of the free-stream speed (fraction) and direction (degrees): median / "
              "95th percentile / max, all directions and outside the disturbed sectors.", "",
              "| | speed all | speed undisturbed | direction all | direction undisturbed |",
              "|---|---|---|---|---|"]

    def f(s, pct):
        k = 100.0 if pct else 1.0
        return f"{k * s['median']:.3g} / {k * s['p95']:.3g} / {k * s['max']:.3g}"
    u = inv["uncorrected"]
    lines.append(f"| uncorrected lidar | {f(u['speed_all'], 1)} % | {f(u['speed_clean'], 1)} % | "
                 f"{f(u['direction_all'], 0)} | {f(u['direction_clean'], 0)} |")
    for res, s in inv["tables"].items():
        lines.append(f"| invert, table every {res} deg | {f(s['speed_all'], 1)} % | "
                     f"{f(s['speed_clean'], 1)} % | {f(s['direction_all'], 0)} | "
                     f"{f(s['direction_clean'], 0)} |")
    (RESULTS / "farm.md").write_text("\n".join(lines) + "\n")
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    if "floris_points_s" in t:
        names = ["FLORIS\npoints", "lidarjax\npoints", "lidarjax\nforward", "lidarjax\ngradient"]
        vals = [t.get("floris_points_360_estimate_s", t["floris_points_s"]), t["lidarjax_points_s"],
                t["lidarjax_forward_s"],
                t["lidarjax_gradient_s"]]
        ax[0].bar(names, vals, color=["C3", "C0", "C0", "C1"])
        ax[0].set_yscale("log")
        ax[0].set_ylabel("seconds (median)")
        ax[0].set_title(f"{t['n_turbines']} turbines x {t['n_directions']} directions")
    res = list(inv["tables"])
    for key, lab in (("speed_clean", "speed, undisturbed"), ("speed_all", "speed, all")):
        ax[1].plot([float(r) for r in res], [100 * inv["tables"][r][key]["p95"] for r in res], "o-",
                   label=f"invert: {lab}")
        ax[1].axhline(100 * inv["uncorrected"][key]["p95"], ls="--", color="0.5" if "clean" in key else "k",
                      label=f"uncorrected: {lab}")
    ax[1].set_xscale("log")
    ax[1].set_xticks([float(r) for r in res], [str(r) for r in res])
    ax[1].minorticks_off()
    ax[1].set_xlabel("table step (degrees)")
    ax[1].set_ylabel("95th percentile |speed error| (%)")
    ax[1].set_yscale("log")
    ax[1].legend(fontsize=7)
    ax[1].set_title("waked site, Gaussian wakes")
    fig.tight_layout()
    fig.savefig(RESULTS / "farm.png", dpi=110)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="25 turbines, 60 directions")
    p.add_argument("--only", choices=("throughput", "inverse"), default=None,
                   help="run one part, keeping the other from the existing farm.json")
    args = p.parse_args(argv)
    old = RESULTS / "farm.json"
    results = json.loads(old.read_text()) if args.only and old.is_file() else {}
    results.update(quick=args.quick, machine=machine())
    if args.only != "inverse":
        results["throughput"] = throughput(args.quick)
        print(json.dumps(results["throughput"], indent=1))
        RESULTS.mkdir(parents=True, exist_ok=True)
        old.write_text(json.dumps(results, indent=1))
    if args.only != "throughput":
        results["inverse"] = inverse_error(args.quick)
    write(results)
    print((RESULTS / "farm.md").read_text())


if __name__ == "__main__":
    main()
