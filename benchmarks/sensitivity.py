"""Installation uncertainty budgets: exact gradients (GUM) against a mocalum-style Monte Carlo.

What it measures, for two sites gridded on `lidarjax.GridField`s (the same grid for every
implementation):

- **platform**: the hemisphere of radius 20 m in potential flow (the demo's platform
  stand-in), a Windcube V2 on its deck 0.5 m above the surface, heights 5-80 m;
- **hill**: the 60 m ridge of `benchmarks/forward.py`, a Windcube V2 on the crest 2 m above
  ground, heights 20-200 m.

The lidar has the tilt logged in the real ``.rtd`` of the shared data (pitch 0.379, roll
0.262 degrees) and these standard uncertainties (realistic for a careful installation; the
issue's bounds): pitch and roll 1 degree, heading (``gamma``) 2 degrees, software north
offset ``epsilon`` 1 degree, location 0.1 m in x, y and z.

- **gradient budget**: `lidarjax.uncertainty` (forward-mode Jacobian of the whole forward
  model, GUM law of propagation, per height), compiled once, timed apart from compilation;
- **Monte Carlo loop** (mocalum's way): for each sample of the inputs, the numpy/scipy
  forward pipeline is re-run: numpy beam geometry with the tilt written from the issue's
  convention (``T = R_x(pitch) R_y(roll)``), `scipy.interpolate.RegularGridInterpolator`
  (linear), projection, the Windcube V2 DBS reconstruction, rotation to north, speed and
  direction; standard deviation over the samples. The relative standard error of a Monte
  Carlo standard deviation is ``1 / sqrt(2 (n - 1))``, so 1 % needs n = 5000: the loop
  runs 5000 samples (``--quick``: 500, timed and scaled to 5000);
- **lidarjax Monte Carlo**: the same inputs vmapped through `lidarjax.uncertainty(...,
  n_monte_carlo=20000)` (0.5 % standard error): the reference for agreement.

Reported: medians of the times, the speed-up of the gradient budget over the loop at equal
accuracy (goal >= 100x), the agreement of the linear and Monte Carlo standard uncertainties
(goal within 5 %), the nominal outputs of the two pipelines against each other, and the size
of each term (contribution ``|c_i| u_i``) for both sites.

Run ``python benchmarks/sensitivity.py [--quick]``. Writes
``benchmarks/results/sensitivity.json``, ``.png`` and ``.md``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
from _common import machine, median_time  # noqa: E402
from scipy.interpolate import RegularGridInterpolator  # noqa: E402

import lidarjax as lj  # noqa: E402
from lidarjax.sensitivity import OUTPUTS as UNITS  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
PITCH, ROLL = 0.379, 0.262  # the real .rtd header's tilt, degrees
STD = {"pitch": 1.0, "roll": 1.0, "gamma": 2.0, "epsilon": 1.0, "location": 0.1}
OUTPUTS = ("lidar_speed", "lidar_direction", "cff_U", "cff_th")
N_MC = 5000
SCAN = lj.windcube_v2(28.0)


def sites():
    hemi = lj.scenes.hemisphere(20.0, 10.0, 250.0)
    xh = np.arange(-60.0, 61.0, 1.0)
    zh = np.arange(0.0, 111.0, 1.0)
    deck = np.array([4.0, 3.0, np.sqrt(20.0**2 - 25.0) + 0.5])
    hill = lj.scenes.hill(height=60.0, half_width=300.0, speed=10.0, direction=250.0)
    xs = np.arange(-500.0, 501.0, 10.0)
    zs = np.arange(0.0, 301.0, 5.0)
    return {
        "platform": dict(scene=hemi, axes=(xh, xh, zh), location=deck,
                         heights=np.array([5.0, 10.0, 20.0, 40.0, 60.0, 80.0]), height_ref=20.0),
        "hill": dict(scene=hill, axes=(xs, xs, zs), location=np.array([0.0, 0.0, 62.0]),
                     heights=np.array([20.0, 40.0, 80.0, 120.0, 160.0, 200.0]), height_ref=60.0),
    }


# -- the numpy/scipy pipeline (mocalum style: everything re-run per sample) -----------------


def rot_z(t):
    t = np.radians(t)
    return np.array([[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1.0]])


def rot_x(a):
    a = np.radians(a)
    return np.array([[1.0, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])


def rot_y(b):
    b = np.radians(b)
    return np.array([[np.cos(b), 0, np.sin(b)], [0, 1.0, 0], [-np.sin(b), 0, np.cos(b)]])


BODY = np.array([[0.0, np.sin(np.radians(28.0)), np.cos(np.radians(28.0))],
                 [np.sin(np.radians(28.0)), 0.0, np.cos(np.radians(28.0))],
                 [0.0, -np.sin(np.radians(28.0)), np.cos(np.radians(28.0))],
                 [-np.sin(np.radians(28.0)), 0.0, np.cos(np.radians(28.0))],
                 [0.0, 0.0, 1.0]])  # Windcube V2 beams S0..S3 + vertical, body frame


def numpy_outputs(interp, loc, gamma, epsilon, pitch, roll, heights, u_ref):
    """One run of the forward pipeline: lidar speed, direction, cff_U, cff_th per height."""
    to_cfd = rot_z(gamma) @ rot_x(pitch) @ rot_y(roll)  # beta = psi = 0
    n = BODY @ to_cfd.T
    ranges = heights[:, None] / BODY[None, :, 2]
    pts = loc + ranges[..., None] * n
    vel = interp(pts.reshape(-1, 3)).reshape(pts.shape)
    los = np.sum(vel * n, -1)
    c = np.radians(28.0)
    u = (los[:, 1] - los[:, 3]) / (2 * np.sin(c))
    v = (los[:, 0] - los[:, 2]) / (2 * np.sin(c))
    to_north = rot_z(-epsilon)
    rec = np.stack([u, v, los[:, 4]], -1) @ to_north.T
    free = rot_z(-epsilon - gamma) @ u_ref
    speed = np.hypot(rec[:, 0], rec[:, 1])
    direction = np.degrees(np.arctan2(-rec[:, 0], -rec[:, 1])) % 360
    free_speed = np.hypot(free[0], free[1])
    free_dir = np.degrees(np.arctan2(-free[0], -free[1])) % 360
    return {"lidar_speed": speed, "lidar_direction": direction, "cff_U": free_speed / speed,
            "cff_th": (free_dir - direction + 180) % 360 - 180}


def mc_loop(interp, site, u_ref, n, seed=0):
    """mocalum-style: sample, re-run the whole pipeline, collect; std over samples."""
    rng = np.random.default_rng(seed)
    draws = {o: np.empty((n, len(site["heights"]))) for o in OUTPUTS}
    for k in range(n):
        dx = rng.normal(0.0, STD["location"], 3)
        out = numpy_outputs(interp, site["location"] + dx, rng.normal(0.0, STD["gamma"]),
                            rng.normal(0.0, STD["epsilon"]), PITCH + rng.normal(0.0, STD["pitch"]),
                            ROLL + rng.normal(0.0, STD["roll"]), site["heights"], u_ref)
        for o in OUTPUTS:
            draws[o][k] = out[o]
    nominal = numpy_outputs(interp, site["location"], 0.0, 0.0, PITCH, ROLL, site["heights"],
                            u_ref)
    std = {}
    for o in OUTPUTS:
        d = draws[o] - nominal[o]
        if o in ("lidar_direction", "cff_th"):
            d = (d + 180) % 360 - 180
        std[o] = np.std(d, axis=0, ddof=1)
    return std, nominal



def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--replot", action="store_true", help="redraw the figure and table "
                        "from the saved JSON")
    args = parser.parse_args()
    if args.replot:
        rows = json.loads((RESULTS / "sensitivity.json").read_text())["sites"]
        write_md(rows, RESULTS / "sensitivity.md")
        plot(rows, RESULTS / "sensitivity.png")
        return
    n_loop = 500 if args.quick else N_MC
    n_ref = 4000 if args.quick else 20000
    rows = {}
    for name, site in sites().items():
        scene = site["scene"]
        field = lj.GridField.from_function(scene.sample, *site["axes"])
        interp = RegularGridInterpolator(site["axes"], np.asarray(field.velocity), method="linear",
                                         bounds_error=False, fill_value=np.nan)
        u_ref = 10.0 * np.asarray(lj.heading(250.0))
        mount = lj.Mount(site["location"], pitch=PITCH, roll=ROLL)
        h = site["heights"]

        def budget(n_mc=0, second_order=True, field=field, mount=mount, h=h, u_ref=u_ref):
            b = lj.uncertainty(field, SCAN, mount, h, std=STD, u_ref=u_ref, outputs=OUTPUTS,
                               n_monte_carlo=n_mc, key=7, second_order=second_order)
            return jax.block_until_ready(b)

        t = time.perf_counter()
        lin = budget()
        compile_s = time.perf_counter() - t
        t_grad = median_time(budget, 7, warm=False)
        budget(second_order=False)
        t_grad1 = median_time(lambda: budget(second_order=False), 7, warm=False)
        t = time.perf_counter()
        ref = budget(n_ref)
        compile_mc_s = time.perf_counter() - t
        t_jax_mc = median_time(lambda: budget(n_ref), 3, warm=False) * N_MC / n_ref
        t = time.perf_counter()
        mc_std, nominal = mc_loop(interp, site, u_ref, n_loop)
        t_loop = (time.perf_counter() - t) * N_MC / n_loop

        sim = lj.simulate(field, SCAN, mount, h, u_ref=u_ref)
        agree = {o: float(np.nanmax(np.abs(np.asarray(getattr(sim, o)) - nominal[o])))
                 for o in OUTPUTS}
        res = {"heights_m": h.tolist(), "z_over_H": ((site["location"][2] + h)
                                                    / site["height_ref"]).tolist(),
               "inputs": list(lin.inputs), "std_in": np.asarray(lin.std_in).tolist(),
               "time_gradient_s": t_grad, "compile_gradient_s": compile_s,
               "time_gradient_first_order_s": t_grad1,
               "time_loop_5000_s": t_loop, "loop_samples_run": n_loop,
               "time_lidarjax_mc_5000_s": t_jax_mc, "compile_lidarjax_mc_s": compile_mc_s,
               "speedup_vs_loop": t_loop / t_grad, "nominal_max_abs_diff_numpy": agree,
               "outputs": {}}
        for o in OUTPUTS:
            u = np.asarray(lin.std[o])
            u1 = np.asarray(lin.std_linear[o])
            res["outputs"][o] = {
                "unit": UNITS[o],
                "value": np.asarray(lin.value[o]).tolist(),
                "u_budget": u.tolist(),
                "u_first_order": u1.tolist(),
                "u_second_order_term": np.asarray(lin.second_order[o]).tolist(),
                "rel_diff_mc_first_order": (np.asarray(ref.mc_std[o]) / u1 - 1).tolist(),
                "u_mc_lidarjax": np.asarray(ref.mc_std[o]).tolist(),
                "u_mc_loop": mc_std[o].tolist(),
                "rel_diff_mc_lidarjax": (np.asarray(ref.mc_std[o]) / u - 1).tolist(),
                "rel_diff_mc_loop": (mc_std[o] / u - 1).tolist(),
                "contribution": np.asarray(lin.contribution[o]).tolist(),
            }
        rows[name] = res
        worst = max(np.max(np.abs(res["outputs"][o]["rel_diff_mc_lidarjax"])) for o in OUTPUTS)
        worst1 = max(np.max(np.abs(res["outputs"][o]["rel_diff_mc_first_order"]))
                     for o in OUTPUTS)
        res["max_abs_rel_diff_mc"] = worst
        res["max_abs_rel_diff_mc_first_order"] = worst1
        print(f"{name}: first order alone: max |MC/u - 1| {worst1:.1%}; first order "
              f"{t_grad1 * 1e3:.2f} ms")
        print(f"{name}: gradient {t_grad * 1e3:.2f} ms (compile {compile_s:.1f} s), loop of "
              f"5000 {t_loop:.1f} s ({n_loop} run) -> {t_loop / t_grad:,.0f}x; lidarjax MC of "
              f"5000 {t_jax_mc * 1e3:.0f} ms; max |MC/u - 1| {worst:.2%}; nominal "
              f"agreement with numpy {max(agree.values()):.1e}", flush=True)
    meta = {"machine": machine(), "quick": args.quick,
            "std": STD, "nominal_tilt_deg": [PITCH, ROLL], "scan": "windcube_v2 28 deg",
            "probe": "point", "n_mc_equal_accuracy": N_MC}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "sensitivity.json").write_text(json.dumps({"meta": meta, "sites": rows}, indent=1))
    write_md(rows, RESULTS / "sensitivity.md")
    plot(rows, RESULTS / "sensitivity.png")


def write_md(rows, path):
    lines = ["# Installation uncertainty budgets: gradients vs Monte Carlo", "",
             "Windcube V2 (point probe), nominal tilt pitch 0.379 / roll 0.262 deg; standard "
             "uncertainties pitch, roll 1 deg, gamma (heading) 2 deg, epsilon 1 deg, location "
             "0.1 m (x, y, z). The gradient budget is second order (first-order Jacobian plus "
             "the tr((HC)^2)/2 term of the Hessian, forward over forward). Times: median, this "
             "machine.", "",
             "| site | gradient budget (2nd order) | 1st order only | compile | MC loop, 5000 "
             "samples (numpy/scipy) | speed-up | lidarjax MC, 5000 | max abs(MC/u - 1), 2nd "
             "order | 1st order |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, r in rows.items():
        lines.append(f"| {name} | {r['time_gradient_s'] * 1e3:.2f} ms | "
                     f"{r['time_gradient_first_order_s'] * 1e3:.2f} ms | "
                     f"{r['compile_gradient_s']:.1f} s | {r['time_loop_5000_s']:.1f} s | "
                     f"{r['speedup_vs_loop']:,.0f}x | {r['time_lidarjax_mc_5000_s'] * 1e3:.0f} ms"
                     f" | {r['max_abs_rel_diff_mc']:.1%} | "
                     f"{r['max_abs_rel_diff_mc_first_order']:.0%} |")
    for name, r in rows.items():
        lines += ["", f"## {name}: standard uncertainty per height and each term |c_i| u_i", ""]
        for o in OUTPUTS:
            d = r["outputs"][o]
            lines += [f"**{o}** [{d['unit']}]", "",
                      "| z/H | value | u | u (1st order) | 2nd-order term | u (MC, lidarjax) | "
                      "u (MC loop) | " + " | ".join(r["inputs"]) + " |",
                      "|---|---:|---:|---:|---:|---:|---:|" + "---:|" * len(r["inputs"])]
            for k, zh in enumerate(r["z_over_H"]):
                lines.append(
                    f"| {zh:.2f} | {d['value'][k]:.4f} | {d['u_budget'][k]:.3g} | "
                    f"{d['u_first_order'][k]:.3g} | {d['u_second_order_term'][k]:.3g} | "
                    f"{d['u_mc_lidarjax'][k]:.3g} ({d['rel_diff_mc_lidarjax'][k]:+.1%}) | "
                    f"{d['u_mc_loop'][k]:.3g} ({d['rel_diff_mc_loop'][k]:+.1%}) | "
                    + " | ".join(f"{c:.2g}" for c in d["contribution"][k]) + " |")
            lines.append("")
    path.write_text("\n".join(lines) + "\n")


def plot(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(16, 5))
    ax = axes[0]
    names = list(rows)
    x = np.arange(len(names))
    for k, (key, lab) in enumerate((("time_gradient_s", "gradient budget (lidarjax)"),
                                    ("time_lidarjax_mc_5000_s", "Monte Carlo 5000 (lidarjax, vmap)"),
                                    ("time_loop_5000_s", "Monte Carlo 5000 (numpy/scipy loop)"))):
        ax.bar(x + (k - 1) * 0.27, [rows[n][key] for n in names], width=0.27, label=lab)
    # (the gradient bar is the second-order budget)
    for i, n in enumerate(names):
        ax.text(i, rows[n]["time_loop_5000_s"] * 1.3, f"{rows[n]['speedup_vs_loop']:,.0f}x",
                ha="center", fontsize=9)
    ax.set_yscale("log")
    ax.set_ylim(top=max(rows[n]["time_loop_5000_s"] for n in names) * 10)
    ax.set_xticks(x)
    ax.set_xticklabels(names)
    ax.set_ylabel("time (s)")
    ax.set_title("standard uncertainty at 1 % accuracy")
    ax.legend(fontsize=8)
    for ax, name in zip(axes[1:], names, strict=True):
        r = rows[name]
        c = np.asarray(r["outputs"]["lidar_speed"]["contribution"])
        zh = np.asarray(r["z_over_H"])
        for i, inp in enumerate(r["inputs"]):
            ax.plot(c[:, i], zh, "-o", ms=3, label=inp)
        ax.plot(r["outputs"]["lidar_speed"]["u_second_order_term"], zh, "-s", ms=3, color="0.4",
                label="2nd order (tilt cosine)")
        ax.plot(r["outputs"]["lidar_speed"]["u_budget"], zh, "k-", lw=2, label="combined (gradients)")
        ax.plot(r["outputs"]["lidar_speed"]["u_mc_lidarjax"], zh, "k--", lw=1, label="Monte Carlo")
        ax.set_xscale("log")
        ax.set_xlim(left=float(np.max(r["outputs"]["lidar_speed"]["u_budget"])) * 1e-4)
        ax.set_xlabel("contribution to u(lidar speed) (m/s)")
        ax.set_ylabel("z / H")
        ax.set_title(f"{name}: terms of the speed budget")
        ax.grid(alpha=0.3)
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    main()
