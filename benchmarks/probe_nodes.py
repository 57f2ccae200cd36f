"""Probe node rules against the closed forms of their weightings, and OpenFAST's CW scheme.

What it measures, for the default `lidarjax.PulsedProbe` (Windcube) and `lidarjax.CWProbe`
(ZephIR) at focus ranges 10-300 m and field resolutions dx = 2, 4, 8 m:

- the node count `lidarjax.probe_for_spacing` chooses (what `simulate` uses for a field of
  that resolution) and the time it takes to choose (host, cached afterwards);
- the largest error of the rule's transfer function ``sum_q w_q cos(k o_q)`` for ``k`` up to
  ``pi / dx``, against (a) the weighting as simulated, cut at the lidar and renormalised
  (pulsed: quadrature; CW: closed form with exponential integrals), and (b) the ideal closed
  forms ``exp(-(k rp)^2/4) sinc(k Dp/2)`` and ``exp(-G |k|)``; the difference between (a) and
  (b) is the cut at the lidar itself, not the rule;
- OpenFAST's InflowWind CW lidar (``Lidar.f90``, re-implemented here in numpy from its
  source: the Gaussian-beam weighting ``1 / (r^2 + (1 - r/f')^2 z_R^2)``, ``z_R = pi a^2 /
  lambda``, sampled every ``SpatialRes = URef dt / 2`` on the far side and mirrored, stopped
  below 2 % of the peak or at the lidar), with its common ``URef = 12 m/s``, ``dt = 0.25 s``.

Run ``python benchmarks/probe_nodes.py``; writes ``benchmarks/results/probe_nodes.json``,
``.md`` and ``.png``.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
from _common import machine  # noqa: E402

import lidarjax as lj  # noqa: E402
from lidarjax.probe import _choose_nodes  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
RANGES = (10.0, 40.0, 100.0, 150.0, 200.0, 250.0, 300.0)
SPACINGS = (2.0, 4.0, 8.0)
PROBES = {"pulsed": lj.PulsedProbe(), "cw": lj.CWProbe()}


def rule_transfer(probe, k, r):
    o, w = (np.asarray(a, np.float64) for a in probe.nodes(np.asarray(r)))
    return np.cos(np.multiply.outer(k, o)) @ (w / w.sum())


def openfast_cw(k, r, lam=1.565e-6, a=28e-3, uref=12.0, dt=0.25, trunc=0.02):
    """Transfer function of OpenFAST's CW lidar weighting and sampling (numpy)."""
    zr2 = (np.pi * a**2 / lam) ** 2
    fmod = (zr2 - np.sqrt(zr2**2 - 4 * zr2 * r**2)) / (2 * r)  # peak at the focus
    weight = lambda rr: 1.0 / (rr**2 + (1 - rr / fmod) ** 2 * zr2)  # noqa: E731
    step = 0.5 * uref * dt
    w_max = weight(r)
    offsets, weights = [0.0], [w_max]
    lid = 0.0
    while True:
        lid += step
        w = weight(r + lid)
        if w / w_max < trunc or lid > r:
            break
        offsets += [lid, -lid]
        weights += [w, w]
    o, w = np.array(offsets), np.array(weights)
    return np.cos(np.multiply.outer(k, o)) @ (w / w.sum()), o.size


def main():
    rows = []
    for name, probe in PROBES.items():
        for dx in SPACINGS:
            k = np.linspace(0.0, np.pi / dx, 1025)
            for r in RANGES:
                _choose_nodes.cache_clear()
                t0 = time.perf_counter()
                chosen = lj.probe_for_spacing(probe, dx, [r])
                t_choose = time.perf_counter() - t0
                t = rule_transfer(chosen, k, r)
                modelled = lj.probe_transfer(chosen, k, r, model="truncated")
                ideal = lj.probe_transfer(chosen, k, r, model="weight")
                row = dict(probe=name, dx=dx, range=r, nodes=chosen.n_nodes,
                           choose_ms=1e3 * t_choose,
                           error_vs_modelled=float(np.max(np.abs(t - modelled))),
                           error_vs_ideal=float(np.max(np.abs(t - ideal))),
                           cut_vs_ideal=float(np.max(np.abs(modelled - ideal))),
                           default_nodes_error_vs_modelled=float(np.max(np.abs(
                               rule_transfer(probe, k, r) - modelled))))
                if name == "cw":
                    of, n_of = openfast_cw(k, r)
                    row.update(openfast_nodes=n_of,
                               openfast_error_vs_ideal=float(np.max(np.abs(of - ideal))))
                rows.append(row)
                print(json.dumps({k_: (round(v, 4) if isinstance(v, float) else v)
                                  for k_, v in row.items()}), flush=True)
    RESULTS.mkdir(exist_ok=True)
    out = dict(meta=dict(ranges=RANGES, spacings=SPACINGS, tolerance=lj.probe.TRANSFER_TOL,
                         machine=machine()), rows=rows)
    (RESULTS / "probe_nodes.json").write_text(json.dumps(out, indent=1))
    write_table(rows, RESULTS / "probe_nodes.md")
    plot(rows, RESULTS / "probe_nodes.png")
    print(f"wrote {RESULTS / 'probe_nodes.json'}, .md and .png")


def write_table(rows, path):
    lines = ["<!-- written by benchmarks/probe_nodes.py -->",
             "Largest |transfer-function error| for k up to pi/dx. *modelled*: the weighting as "
             "simulated (cut at the lidar, renormalised); *ideal*: exp(-(k rp)^2/4) sinc(k Dp/2) "
             "or exp(-G|k|); *cut*: modelled against ideal (the cut itself); *default nodes*: the "
             "probe's default count (9 pulsed, 17 CW) against modelled; OpenFAST: its CW scheme "
             "(URef 12 m/s, dt 0.25 s) against ideal.", "",
             "| probe | dx (m) | range (m) | nodes | vs modelled | vs ideal | cut | default nodes "
             "| OpenFAST nodes | OpenFAST vs ideal |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(
            f"| {r['probe']} | {r['dx']:g} | {r['range']:g} | {r['nodes']} | "
            f"{r['error_vs_modelled']:.4f} | {r['error_vs_ideal']:.4f} | {r['cut_vs_ideal']:.4f} | "
            f"{r['default_nodes_error_vs_modelled']:.3f} | {r.get('openfast_nodes', '')} | "
            + (f"{r['openfast_error_vs_ideal']:.3f} |" if "openfast_nodes" in r else " |"))
    path.write_text("\n".join(lines) + "\n")


def plot(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for ax, name in zip(axes, PROBES, strict=True):
        for dx in SPACINGS:
            sel = [r for r in rows if r["probe"] == name and r["dx"] == dx]
            ax.plot([r["range"] for r in sel], [r["nodes"] for r in sel], "o-",
                    label=f"dx = {dx:g} m")
        ax.set(xlabel="focus range (m)", ylabel="nodes chosen (transfer within 0.01)",
               title=f"{name}: nodes for the field's resolution", yscale="log")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    main()
