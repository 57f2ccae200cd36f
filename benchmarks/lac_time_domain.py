"""Lidar-assisted control in the time domain: the REWS and its lidar estimate simulated in
Kaimal/IEC-coherence turbulence (`lidarjax.control.kaimal_rews_series`: frozen turbulence,
Veers' method, each sample processed as Task 52's lidar data processing does), Welch's
coherence against the analytic ``gamma^2`` of `lac_spectra` (issue 40, point 3).

Cases: the NREL 5 MW (113-point disc) with a 4-beam pulsed lidar at 100 m, 20 degrees (the
test's configuration), and Task 52's IEA 15 MW 4-beam pulsed trajectory (its file's beams and
range weighting, a 16 m disc grid), each over 1 h and 6 h at 1 Hz. Welch: Hann windows of
128 s, no overlap; the estimate delayed by its preview time. Counted in every bin up to the
analytic bandwidth (``gamma^2 = 0.5``): inside the pointwise 95 % band (Fisher z), and whether
every bin is inside the simultaneous 95 % band (Bonferroni).

Run ``python benchmarks/lac_time_domain.py``; writes ``benchmarks/results/lac_time_domain.json``,
``.md`` and ``.png``.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402
import scipy.io  # noqa: E402
from _common import machine, machine_line  # noqa: E402

from lidarjax import control as lc  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "benchmarks" / "results"
DT, NPERSEG = 1.0, 128


def nrel5mw():
    focus = lc.cone_points(100.0, 20.0, 4, azimuth_offset=45.0)
    samples = lc.lidar_samples(focus, offsets=np.linspace(-30, 30, 5), offset_weights=[1, 2, 3, 2, 1],
                               times=[0.25, 0.5, 0.75, 1.0])
    return samples, lc.rotor_disc(63.0, spacing=10.5), lc.KaimalInflow(12.0, 0.16)


def iea15mw():
    m = scipy.io.loadmat(REPO / "tests" / "data" / "lac" / "LidarRotorSpectra_IEA15MW_4BeamPulsed.mat",
                         squeeze_me=True, struct_as_record=False)
    p, t = m["Parameter"], m["Trajectory"]
    focus = np.stack([np.atleast_1d(getattr(t, f"{c}_L_AllDistances")) for c in "xyz"], 1).astype(float)
    samples = lc.lidar_samples(focus, offsets=p.Lidar.a, offset_weights=p.Lidar.f_L_d)
    return samples, lc.rotor_disc(120.0, spacing=16.0), lc.KaimalInflow(p.TurbSim.URef, p.TurbSim.IECturbc)


def run(case, duration, seed):
    samples, rotor, inflow = case()
    t0 = time.perf_counter()
    _, rews, est = lc.kaimal_rews_series(samples, rotor, inflow, duration=duration, dt=DT, seed=seed)
    t_sim = time.perf_counter() - t0
    u = float(inflow.mean_speed)
    lead = float(np.sum(samples.weights * (samples.points[:, 0] / u - samples.delays)))
    f, c, n = lc.welch_coherence(rews, est, DT, nperseg=NPERSEG, lead=lead)
    fine = lc.lac_spectra(samples, rotor, inflow, np.linspace(0.001, 0.5, 1000))
    f_b = float(lc.coherence_bandwidth(fine)[0])
    sel = f <= f_b
    g2 = np.asarray(lc.lac_spectra(samples, rotor, inflow, f[:64]).coherence)[: sel.sum()]
    lo, hi = lc.coherence_band(g2, n)
    slo, shi = lc.coherence_band(g2, n, n_bins=int(sel.sum()))
    inside = (lo <= c[sel]) & (c[sel] <= hi)
    return {"duration_s": duration, "seed": seed, "rotor_points": int(rotor.points.shape[0]),
            "lidar_nodes": int(samples.points.shape[0]), "segments": n, "bandwidth_hz": f_b,
            "bins_to_bandwidth": int(sel.sum()), "bins_in_pointwise_95": int(inside.sum()),
            "all_in_simultaneous_95": bool(np.all((slo <= c[sel]) & (c[sel] <= shi))),
            "max_abs_difference": float(np.max(np.abs(c[sel] - g2))), "simulation_s": t_sim,
            "frequency_hz": f[sel].tolist(), "welch": c[sel].tolist(), "analytic": g2.tolist(),
            "band_low": lo.tolist(), "band_high": hi.tolist()}


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    results = {"machine": machine(), "dt_s": DT, "nperseg": NPERSEG, "cases": {}}
    for name, case in (("NREL5MW_4beam_100m", nrel5mw), ("IEA15MW_Task52_4BeamPulsed", iea15mw)):
        results["cases"][name] = [run(case, d, seed) for d, seed in ((3600.0, 1), (21600.0, 2))]
    (OUT / "lac_time_domain.json").write_text(json.dumps(results, indent=1))
    lines = ["# Lidar-assisted control: time-domain coherence against the analytic model", "",
             f"Machine: {machine_line(results['machine'])}. Welch: Hann {NPERSEG} s, no overlap, 1 Hz.", "",
             "| case | run | segments | bandwidth (Hz) | bins in 95 % band | all in simultaneous 95 % "
             "| max abs diff | simulation (s) |", "|---|---|---|---|---|---|---|---|"]
    for name, rs in results["cases"].items():
        for r in rs:
            lines.append(f"| {name} | {r['duration_s'] / 3600:.0f} h | {r['segments']} "
                         f"| {r['bandwidth_hz']:.4f} | {r['bins_in_pointwise_95']}/{r['bins_to_bandwidth']} "
                         f"| {r['all_in_simultaneous_95']} | {r['max_abs_difference']:.3f} "
                         f"| {r['simulation_s']:.1f} |")
    (OUT / "lac_time_domain.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    plot(results)


def plot(results):
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:  # pragma: no cover
        return
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for ax, (name, rs) in zip(axes, results["cases"].items(), strict=True):
        for r, colour in zip(rs, ("C0", "C1"), strict=True):
            f = np.asarray(r["frequency_hz"])
            ax.fill_between(f, r["band_low"], r["band_high"], color=colour, alpha=0.2)
            ax.plot(f, r["welch"], "o", color=colour, label=f"Welch, {r['duration_s'] / 3600:.0f} h")
        ax.plot(f, rs[-1]["analytic"], "k-", label="analytic")
        ax.set(title=name, xlabel="f (Hz)", ylabel="gamma^2")
        ax.legend()
    fig.tight_layout()
    fig.savefig(OUT / "lac_time_domain.png", dpi=110)


if __name__ == "__main__":
    sys.exit(main())
