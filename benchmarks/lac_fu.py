"""Beside Fu et al. 2023 (WES 8, 1893): which assumption moves the optimal scan radius of a
single-beam spinner CW lidar on the IEA 15 MW, and by how much.

Fu et al. optimised the focus distance and the cone angle of a spinner-mounted single-beam
lidar (CW and pulsed) for the coherence of its rotor-effective wind speed (REWS) estimate with
the rotor's, and found a scan radius of 0.6 R for both. ``benchmarks/lac.py`` finds 0.68-0.73 R
for 50 simultaneous scan points of a CW lidar (lidarjax's `CWProbe`, default optics), IEC
Kaimal turbulence with the IEC coherence, 10.59 m/s, class B, the widest coherence bandwidth.
Here each assumption is changed alone from that case, at a focus distance of 200 m (and over
the focus distance), and the scan radius with the widest bandwidth (or the smallest filtered
REWS error) is found again:

- the turbulence model: the Mann (1994) tensor (IEC 61400-1: L = 29.4 m, Gamma = 3.9, the same
  sigma_u) instead of Kaimal; isotropic Mann (Gamma = 0);
- the mean wind (15 m/s, above rated) and the turbulence intensity (class A);
- the objective: the REWS error variance left by the optimal filter instead of the bandwidth;
- the probe: a point measurement instead of the CW Lorentzian (at 200 m and at 400 m);
- the scan: 10, 20 or 100 points instead of 50; the points measured in turn over one rotor
  revolution (7.56 rpm: 7.9 s, the spinner turning with the IEA 15 MW rotor) instead of
  simultaneously; 20 points in turn with the error objective together;
- the REWS: weighted by ``r / R`` (more weight outboard, as the aerodynamic sensitivity of a
  blade) instead of the disc mean;
- the focus distance itself (100 to 400 m).

A quadrature check computes the Mann case's bandwidth at three radii with ``MANN_NODES`` and
twice as many nodes. ``python benchmarks/lac_fu.py NAME ...`` reruns only the cases whose
name contains one of the words (and ``quadrature`` the check), keeping the others' results.

Each optimum is the maximum over scan radius of the objective on a grid of radii (step
0.05 R, then 0.01 R about the best) refined by a parabola through the best three; the spectra
on ``FREQUENCY`` (Kaimal) or ``FREQUENCY_MANN`` (Mann, Gauss-Legendre quadrature of ``(k2,
k3)`` with ``MANN_NODES`` nodes per axis), the bandwidth by linear interpolation of
``gamma^2 = 0.5`` on that grid.

Run ``python benchmarks/lac_fu.py``; writes ``benchmarks/results/lac_fu.json`` and
``lac_fu.md``.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402
from _common import machine, machine_line  # noqa: E402

import lidarjax as lj  # noqa: E402
from lidarjax import control as lc  # noqa: E402
from lidarjax.design import control as dc  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "benchmarks" / "results"
TURBINE = dc.TURBINES["IEA15MW"]
R = TURBINE.radius
FREQUENCY = np.linspace(0.001, 0.15, 150)
FREQUENCY_MANN = np.linspace(0.0025, 0.15, 60)
MANN_NODES = 48
ROTOR_SPACING = 8.0  # m: Task 52's 709-point IEA 15 MW grid
REVOLUTION = 60 / 7.56  # s: one IEA 15 MW rotor revolution at rated speed


def case(name, *, speed=TURBINE.rated_speed, turbulence_class="B", model="kaimal", gamma=3.9, n_points=50,
         probe="cw", distance=200.0, scan_time=None, weighting=None, objective="bandwidth"):
    return dict(name=name, speed=speed, turbulence_class=turbulence_class, model=model, gamma=gamma,
                n_points=n_points, probe=probe, distance=distance, scan_time=scan_time, weighting=weighting,
                objective=objective)


CASES = [
    case("baseline: Kaimal/IEC, 10.59 m/s, class B, CW, 50 points, disc mean, bandwidth"),
    case("mean wind 15 m/s", speed=15.0),
    case("turbulence class A", turbulence_class="A"),
    case("objective: filtered REWS error", objective="error"),
    case("point probe (no range weighting)", probe="point"),
    case("10 scan points", n_points=10),
    case("20 scan points", n_points=20),
    case("100 scan points", n_points=100),
    case("points in turn over one revolution (7.9 s)", scan_time=REVOLUTION),
    case("REWS weighted by r / R", weighting="linear"),
    case("Mann, IEC (L 29.4 m, Gamma 3.9)", model="mann"),
    case("Mann, isotropic (Gamma 0)", model="mann", gamma=0.0),
    case("combined: 20 points in turn over one revolution, filtered REWS error", n_points=20,
         scan_time=REVOLUTION, objective="error"),
] + [case(f"focus distance {x:.0f} m", distance=x) for x in (100.0, 150.0, 250.0, 300.0, 400.0)] + [
    case("focus distance 400 m, point probe", distance=400.0, probe="point")]


def inflow_of(c):
    ti = float(lc.iec_turbulence_intensity(c["speed"], c["turbulence_class"]))
    if c["model"] == "mann":
        return lc.MannInflow(c["speed"], length_scale=0.7 * 42.0, gamma=c["gamma"], sigma_u=ti * c["speed"],
                             n_nodes=MANN_NODES)
    return lc.KaimalInflow(c["speed"], ti)


def objective_of(c, inflow, rotor, ratio):
    """The objective at scan radius ``ratio * R``: ``(value to maximise, bandwidth Hz)``."""
    half_cone = np.rad2deg(np.arctan(ratio * R / c["distance"]))
    focus = lc.cone_points(c["distance"], half_cone, c["n_points"])
    times = None if c["scan_time"] is None else np.arange(c["n_points"]) * c["scan_time"] / c["n_points"]
    probe = lj.CWProbe(n_nodes=9) if c["probe"] == "cw" else None
    samples = lc.lidar_samples(focus, probe=probe, times=times)
    f = FREQUENCY_MANN if c["model"] == "mann" else FREQUENCY
    sp = lc.lac_spectra(samples, rotor, inflow, f)
    bandwidth = float(lc.coherence_bandwidth(sp)[0])
    if c["objective"] == "bandwidth":
        return bandwidth, bandwidth
    error = float(np.sum(np.asarray(sp.S_RR) * (1 - np.asarray(sp.coherence)) * np.gradient(f)))
    return -error, bandwidth


def optimum(c):
    inflow = inflow_of(c)
    weighting = (lambda r: r) if c["weighting"] == "linear" else None
    rotor = lc.rotor_disc(R, spacing=ROTOR_SPACING, weighting=weighting)
    seen = {}

    def value(ratio):
        ratio = round(float(ratio), 6)
        if ratio not in seen:
            seen[ratio] = objective_of(c, inflow, rotor, ratio)
        return seen[ratio][0]

    coarse = np.arange(0.45, 0.9001, 0.05)
    best = coarse[int(np.nanargmax([value(r) for r in coarse]))]
    fine = np.arange(best - 0.03, best + 0.03001, 0.01)
    fine = fine[(fine > 0.05) & (fine < 1.2)]
    vals = np.array([value(r) for r in fine])
    i = int(np.clip(np.nanargmax(vals), 1, len(fine) - 2))
    a, b, cc = np.polyfit(fine[i - 1:i + 2], vals[i - 1:i + 2], 2)
    ratio = float(-b / (2 * a)) if a < 0 else float(fine[i])
    _, bandwidth = objective_of(c, inflow, rotor, ratio)
    return {**c, "radius_over_R": ratio, "radius_m": ratio * R,
            "half_cone_deg": float(np.rad2deg(np.arctan(ratio * R / c["distance"]))),
            "bandwidth_hz": bandwidth, "bandwidth_rad_m": 2 * np.pi * bandwidth / c["speed"],
            "n_evaluations": len(seen) + 1,
            "curve": sorted((r, v[0]) for r, v in seen.items())}


def quadrature_check(ratios=(0.65, 0.70, 0.75)):
    """The Mann (IEC) case's bandwidth at three scan radii about its optimum with ``MANN_NODES``
    and twice as many quadrature nodes, and the parabola's optimum of each."""
    c = next(c for c in CASES if c["model"] == "mann")
    rotor = lc.rotor_disc(R, spacing=ROTOR_SPACING)
    out = {}
    for nodes in (MANN_NODES, 2 * MANN_NODES):
        inflow = lc.MannInflow(c["speed"], length_scale=29.4, gamma=3.9, n_nodes=nodes,
                               sigma_u=float(lc.iec_turbulence_intensity(c["speed"], "B")) * c["speed"])
        bw = [objective_of(c, inflow, rotor, r)[1] for r in ratios]
        a, b, _ = np.polyfit(ratios, bw, 2)
        out[str(nodes)] = {"bandwidth_hz": bw, "radius_over_R": float(-b / (2 * a))}
        print(nodes, out[str(nodes)], flush=True)
    return {"ratios": list(ratios), "nodes": out}


def main(names=None) -> int:
    path = OUT / "lac_fu.json"
    results = json.loads(path.read_text()) if path.exists() and names else {"cases": {}}
    results["machine"] = machine()
    if not names or "quadrature" in names:
        results["mann_quadrature_check"] = quadrature_check()
        path.write_text(json.dumps(results, indent=1))
    for c in CASES:
        if names and not any(n in c["name"] for n in names):
            continue
        t0 = time.perf_counter()
        row = optimum(c)
        row["time_s"] = time.perf_counter() - t0
        results["cases"][c["name"]] = row
        print(f"{c['name']}: {row['radius_over_R']:.3f} R, {row['bandwidth_hz']:.4f} Hz, "
              f"{row['time_s']:.0f} s", flush=True)
        path.write_text(json.dumps(results, indent=1))
    write_md(results)
    return 0


def write_md(r):
    lines = ["# Beside Fu et al. 2023: the optimal scan radius of a spinner CW lidar, assumption by assumption",
             "", f"{machine_line(r['machine'])}.", "",
             "IEA 15 MW (R = 120 m); each row changes one assumption from the baseline (focus distance 200 m "
             "unless stated). Fu et al. 2023: 0.6 R.", "",
             "| case | optimal scan radius / R | half-cone (deg) | bandwidth (Hz) | bandwidth (rad/m) |",
             "|---|---:|---:|---:|---:|"]
    order = [c["name"] for c in CASES if c["name"] in r["cases"]]
    for name in order + [n for n in r["cases"] if n not in order]:
        row = r["cases"][name]
        lines.append(f"| {name} | {row['radius_over_R']:.3f} | {row['half_cone_deg']:.2f} | "
                     f"{row['bandwidth_hz']:.4f} | {row['bandwidth_rad_m']:.4f} |")
    q = r.get("mann_quadrature_check")
    if q:
        coarse, fine = sorted(q["nodes"], key=int)
        bw = {k: ", ".join(f"{v:.5f}" for v in q["nodes"][k]["bandwidth_hz"]) for k in (coarse, fine)}
        opt = {k: q["nodes"][k]["radius_over_R"] for k in (coarse, fine)}
        lines += ["", f"Mann quadrature check (IEC case, radii {q['ratios']} R): bandwidths {bw[coarse]} Hz "
                  f"with {coarse} nodes per axis, {bw[fine]} Hz with {fine}; parabola optimum "
                  f"{opt[coarse]:.3f} R and {opt[fine]:.3f} R."]
    (OUT / "lac_fu.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:] or None))
