"""Lidar-assisted control (`lidarjax.control`, `lidarjax.design.control`): Task 52's published
analytic spectra reproduced at every frequency, the speed of the analytic coherence against a
numpy implementation of the same sums, a scan optimisation against a dense grid search, and
Fu et al. (2023)'s spinner-lidar case.

- **Task 52**: ``LidarRotorSpectra_IEA15MW_{4BeamPulsed,CircularCW}.mat`` (tests/data/lac, MIT):
  the largest relative difference of ``S_RR``, ``S_LL`` and ``|S_RL|`` over all 1024
  frequencies; the -3 dB cut-offs against ``FFP_v1_*.IN`` (0.1232, 0.3268 rad/s); the coherence
  bandwidth; the analytic filter delay and buffer time (tau = 2 s, T_scan = 1 s).
- **speed**: the spectra and coherence at 500 frequencies for Task 52's 709-point IEA 15 MW
  rotor and an 88-node lidar (8 beams x 11 range-weighting nodes), median of 5 after
  compilation, beside numpy doing the same sums (one vectorised pass per frequency).
- **design**: `design_lac_scan` on the IEA 15 MW at 18 m/s, class B, a 4-beam pulsed lidar at
  160 m: half-cone angle and gate length by gradients (cold start, compilation included)
  against a 30 x 30 grid search of the same objective.
- **Fu et al. 2023** (WES 8, 1893): a single-beam spinner CW lidar (lidarjax's `CWProbe`,
  default optics) scanning a circle of 50 points on the IEA 15 MW at 10.59 m/s (rated),
  class B: the optimal scan radius at several focus distances, beside their 0.6 R.

Run ``python benchmarks/lac.py``; writes ``benchmarks/results/lac.json``, ``lac.md``, ``lac.png``.
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402
import scipy.io  # noqa: E402
from _common import machine, machine_line, median_time  # noqa: E402

from lidarjax import control as lc  # noqa: E402
from lidarjax.design import control as dc  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "tests" / "data" / "lac"
OUT = REPO / "benchmarks" / "results"
FFP = {"4BeamPulsed": (0.1232, 1.3889), "CircularCW": (0.3268, 6.1111)}


def load():
    return os.getloadavg() if hasattr(os, "getloadavg") else None


def task52(name):
    m = scipy.io.loadmat(DATA / f"LidarRotorSpectra_IEA15MW_{name}.mat", squeeze_me=True,
                         struct_as_record=False)
    p, t = m["Parameter"], m["Trajectory"]
    focus = np.stack([np.atleast_1d(getattr(t, f"{c}_L_AllDistances")) for c in "xyz"], 1).astype(float)
    samples = lc.lidar_samples(focus, offsets=p.Lidar.a, offset_weights=p.Lidar.f_L_d)
    rotor = lc.rotor_disc(120.0, spacing=8.0)
    inflow = lc.KaimalInflow(p.TurbSim.URef, p.TurbSim.IECturbc)
    sp = lc.lac_spectra(samples, rotor, inflow, m["f"])
    rel = {k: float(np.max(np.abs(np.asarray(getattr(sp, k)) / m[k] - 1))) for k in ("S_RR", "S_LL")}
    rel["abs_S_RL"] = float(np.max(np.abs(np.abs(np.asarray(sp.S_RL)) / np.abs(m["S_RL"]) - 1)))
    cutoff = float(lc.filter_cutoff(sp))
    t_filter = float(lc.filter_delay(sp, cutoff))
    f_b, k_b = (float(v) for v in lc.coherence_bandwidth(sp))
    buffer = float(lc.buffer_time(focus[0, 0], 18.0, scan_time=1.0, filter_delay=t_filter, prediction_time=2.0))
    out = {"max_relative_difference": rel, "cutoff_rad_s": cutoff, "ffp_cutoff_rad_s": FFP[name][0],
           "cutoff_relative_difference": cutoff / FFP[name][0] - 1, "bandwidth_hz": f_b,
           "bandwidth_rad_m": k_b, "filter_delay_s": t_filter, "buffer_time_s": buffer,
           "ffp_buffer_time_s": FFP[name][1]}
    curves = (m["f"], np.asarray(sp.coherence), np.asarray(sp.transfer),
              np.abs(m["S_RL"]) ** 2 / m["S_RR"] / m["S_LL"], np.abs(m["S_RL"]) / m["S_LL"])
    return out, curves


def numpy_spectra(samples, rotor, inflow, f):
    """The same sums as `lac_spectra`, in numpy, one vectorised pass per frequency."""
    pts, nd, w, rho = (np.asarray(a) for a in (samples.points, samples.directions, samples.weights,
                                                rotor.weights))
    yz, ryz = pts[:, 1:], np.asarray(rotor.points)
    r_ll = np.sqrt(((yz[:, None] - yz[None]) ** 2).sum(-1))
    r_rl = np.sqrt(((ryz[:, None] - yz[None]) ** 2).sum(-1))
    pd, pw = np.asarray(rotor.pair_distance), np.asarray(rotor.pair_weight)
    u = float(inflow.mean_speed)
    spec = np.asarray(inflow.spectra(f))
    rate = np.asarray(inflow.decay_rate(f))
    lead = pts[:, 0] / u
    vw = ((w**2 * (nd[:, 1] / nd[:, 0]) ** 2).sum(), (w**2 * (nd[:, 2] / nd[:, 0]) ** 2).sum())
    out = np.empty((3, f.size), complex)
    for i, (fi, s) in enumerate(zip(f, rate, strict=True)):
        wc, ws = w * np.cos(2 * np.pi * fi * lead), w * np.sin(2 * np.pi * fi * lead)
        e = np.exp(-s * r_ll)
        a = rho @ np.exp(-s * r_rl)
        out[0, i] = spec[0, i] * (pw @ np.exp(-s * pd))
        out[1, i] = spec[0, i] * (wc @ e @ wc + ws @ e @ ws) + spec[1, i] * vw[0] + spec[2, i] * vw[1]
        out[2, i] = spec[0, i] * (a @ wc - 1j * (a @ ws))
    return out[0].real, out[1].real, out[2]


def speed():
    rotor = lc.rotor_disc(120.0, spacing=8.0)
    focus = lc.cone_points(160.0, 19.0, 8)
    m = scipy.io.loadmat(DATA / "LidarRotorSpectra_IEA15MW_4BeamPulsed.mat", squeeze_me=True,
                         struct_as_record=False)
    samples = lc.lidar_samples(focus, offsets=m["Parameter"].Lidar.a, offset_weights=m["Parameter"].Lidar.f_L_d)
    inflow = lc.KaimalInflow(18.0, lc.iec_turbulence_intensity(18.0, "B"))
    f = np.linspace(0.001, 0.5, 500)
    fj = jax.numpy.asarray(f)
    t0 = time.perf_counter()
    jax.block_until_ready(lc.lac_spectra(samples, rotor, inflow, fj).coherence)
    t_first = time.perf_counter() - t0
    t_jax = median_time(lambda: jax.block_until_ready(lc.lac_spectra(samples, rotor, inflow, fj).coherence), 5)
    c0 = time.process_time()
    for _ in range(5):
        jax.block_until_ready(lc.lac_spectra(samples, rotor, inflow, fj).coherence)
    cpu_jax = (time.process_time() - c0) / 5
    t_np = median_time(lambda: numpy_spectra(samples, rotor, inflow, f), 3, warm=False)
    sp = lc.lac_spectra(samples, rotor, inflow, fj)
    rr, ll, rl = numpy_spectra(samples, rotor, inflow, f)
    agree = float(np.max(np.abs(np.abs(rl) ** 2 / rr / ll - np.asarray(sp.coherence))))
    return {"n_rotor": int(rotor.points.shape[0]), "n_lidar": int(samples.points.shape[0]),
            "n_frequencies": 500,
            "jax_first_call_s": t_first, "jax_s": t_jax, "jax_cpu_time_s": cpu_jax, "numpy_s": t_np,
            "max_coherence_difference": agree}


def design():
    inflow = lc.KaimalInflow(18.0, lc.iec_turbulence_intensity(18.0, "B"))
    kw = dict(distance=160.0, half_cone=(5.0, 40.0), gate_length=(10.0, 80.0))
    t0, c0 = time.perf_counter(), time.process_time()
    d = dc.design_lac_scan("IEA15MW", inflow, n_points=(4,), **kw)
    t_opt, cpu_opt = time.perf_counter() - t0, time.process_time() - c0
    g1, g2 = np.linspace(5.0, 40.0, 30), np.linspace(10.0, 80.0, 30)
    x = np.stack(np.meshgrid(g1, g2, indexing="ij"), -1).reshape(-1, 2)
    t0 = time.perf_counter()
    values, _ = dc.lac_objective("IEA15MW", inflow, x, n_points=4, **kw)
    t_grid = time.perf_counter() - t0
    i = int(np.nanargmin(values))
    return {"optimiser": {"half_cone_deg": float(d.x[0]), "gate_length_m": float(d.x[1]),
                          "bandwidth_hz": d.bandwidth, "n_evaluations": d.n_evaluations,
                          "time_s_with_compilation": t_opt, "cpu_time_s_with_compilation": cpu_opt,
                          "converged": d.converged},
            "grid_search": {"half_cone_deg": float(x[i, 0]), "gate_length_m": float(x[i, 1]),
                            "bandwidth_hz": float(-values[i]), "n_evaluations": int(x.shape[0]),
                            "time_s_with_compilation": t_grid},
            "bandwidth_ratio": d.bandwidth / float(-values[i])}


def fu2023(distances=(100.0, 150.0, 200.0, 250.0)):
    turbine = dc.TURBINES["IEA15MW"]
    inflow = lc.KaimalInflow(turbine.rated_speed, lc.iec_turbulence_intensity(turbine.rated_speed, "B"))
    rows = []
    for x in distances:
        d = dc.design_lac_scan(turbine, inflow, n_points=(50,), distance=x, half_cone=(2.0, 45.0), lidar="cw")
        rows.append({"distance_m": x, "half_cone_deg": float(d.x[0]), "scan_radius_m": d.scan_radius,
                     "scan_radius_over_R": d.scan_radius / turbine.radius, "bandwidth_hz": d.bandwidth,
                     "n_evaluations": d.n_evaluations})
        print(rows[-1], flush=True)
    return rows


def plot(curves, fu):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(15, 4))
    for name, (f, g2, g, g2_ref, g_ref) in curves.items():
        ax[0].semilogx(f, g2, label=f"lidarjax {name}")
        ax[0].semilogx(f, g2_ref, "k:", lw=1)
        ax[1].semilogx(f, g, label=f"lidarjax {name}")
        ax[1].semilogx(f, g_ref, "k:", lw=1)
    ax[0].axhline(0.5, color="grey", lw=0.5)
    ax[1].axhline(10 ** (-3 / 20), color="grey", lw=0.5)
    ax[0].set(xlabel="f (Hz)", ylabel="coherence gamma^2", title="Task 52 (dotted) and lidarjax")
    ax[1].set(xlabel="f (Hz)", ylabel="|G_RL|", title="transfer function")
    ax[0].legend()
    ax[2].plot([r["distance_m"] for r in fu], [r["scan_radius_over_R"] for r in fu], "o-",
               label="lidarjax optimum")
    ax[2].axhline(0.6, color="k", ls="--", label="Fu et al. 2023: 0.6 R")
    ax[2].set(xlabel="focus distance (m)", ylabel="scan radius / R", title="spinner CW lidar, IEA 15 MW")
    ax[2].legend()
    fig.tight_layout()
    fig.savefig(OUT / "lac.png", dpi=110)


def main() -> int:
    results = {"machine": machine(), "load_before": load()}
    curves = {}
    results["task52"] = {}
    for name in FFP:
        results["task52"][name], curves[name] = task52(name)
        print(name, results["task52"][name], flush=True)
    results["speed"] = speed()
    print(results["speed"], flush=True)
    results["design"] = design()
    print(results["design"], flush=True)
    results["fu2023"] = fu2023()
    results["load_after"] = load()
    (OUT / "lac.json").write_text(json.dumps(results, indent=1))
    plot(curves, results["fu2023"])
    write_md(results)
    return 0


def write_md(r):
    s, d = r["speed"], r["design"]
    lines = ["# Lidar-assisted control: Task 52's spectra, speed, scan design", "",
             f"{machine_line(r['machine'])}; load average before {r['load_before']}, after {r['load_after']} "
             "(shared machine).", "",
             "| Task 52 case | max rel. diff S_RR / S_LL / abs S_RL (1024 f) | cut-off (rad/s) | FFP_v1 | "
             "bandwidth (Hz) | T_filter (s) | T_buffer (s) | FFP_v1 T_buffer |",
             "|---|---|---:|---:|---:|---:|---:|---:|"]
    for name, t in r["task52"].items():
        m = t["max_relative_difference"]
        lines.append(f"| {name} | {m['S_RR']:.1e} / {m['S_LL']:.1e} / {m['abs_S_RL']:.1e} | "
                     f"{t['cutoff_rad_s']:.5f} | "
                     f"{t['ffp_cutoff_rad_s']} | {t['bandwidth_hz']:.4f} | {t['filter_delay_s']:.2f} | "
                     f"{t['buffer_time_s']:.3f} | {t['ffp_buffer_time_s']} |")
    lines += ["", f"Analytic coherence, {s['n_frequencies']} frequencies, {s['n_rotor']}-point rotor, "
              f"{s['n_lidar']}-node lidar: JAX {1e3 * s['jax_s']:.1f} ms wall after compilation "
              f"({1e3 * s['jax_cpu_time_s']:.1f} ms of CPU time; first call {s['jax_first_call_s']:.1f} s), "
              f"numpy {1e3 * s['numpy_s']:.1f} ms (every node's sums; JAX evaluates the disc's coherence once "
              f"per class of nodes the disc's symmetries map onto each other; max coherence difference "
              f"{s['max_coherence_difference']:.1e}).", "",
              f"Scan design (IEA 15 MW, 18 m/s, 4-beam pulsed at 160 m): gradients "
              f"{d['optimiser']['bandwidth_hz']:.5f} Hz at {d['optimiser']['half_cone_deg']:.2f} deg, gate "
              f"{d['optimiser']['gate_length_m']:.1f} m in {d['optimiser']['n_evaluations']} evaluations, "
              f"{d['optimiser']['time_s_with_compilation']:.1f} s with compilation "
              f"({d['optimiser']['cpu_time_s_with_compilation']:.1f} s of CPU time); 30 x 30 grid "
              f"{d['grid_search']['bandwidth_hz']:.5f} Hz at {d['grid_search']['half_cone_deg']:.2f} deg, gate "
              f"{d['grid_search']['gate_length_m']:.1f} m in {d['grid_search']['n_evaluations']} evaluations, "
              f"{d['grid_search']['time_s_with_compilation']:.1f} s (ratio {d['bandwidth_ratio']:.4f}).", "",
              "| Fu et al. case: focus distance (m) | optimal half-cone (deg) | scan radius (m) | radius / R "
              "(Fu: 0.6) | bandwidth (Hz) |", "|---:|---:|---:|---:|---:|"]
    for row in r["fu2023"]:
        lines.append(f"| {row['distance_m']:.0f} | {row['half_cone_deg']:.2f} | {row['scan_radius_m']:.1f} | "
                     f"{row['scan_radius_over_R']:.3f} | {row['bandwidth_hz']:.4f} |")
    (OUT / "lac.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    sys.exit(main())
