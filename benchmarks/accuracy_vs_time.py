"""Accuracy against run time: probe node count, float32 against float64, grid spacing.

What it measures: a Windcube V2 (28 degree cone) with the default pulsed probe
(`lidarjax.PulsedProbe`: 26.2 m pulse, 25 m gate) at 9 heights from 40 to 200 m, seen from
360 mounts (platform rotations every degree, the "sectors"; 36 with ``--quick``), in two
scenes gridded the way a CFD field is (cell ``dx`` horizontally, ``dx/2`` vertically):

- **shear**: `lidarjax.scenes.power_law` (10 m/s at 100 m, alpha 0.2, veer 0.05 deg/m), lidar
  on flat ground;
- **hill**: `lidarjax.scenes.hill` (60 m high, 200 m half-width ridge), lidar on the crest.

The error of a configuration is the largest absolute error over sectors and heights of the
reported horizontal speed (m/s) and direction (degrees) against the *truth*: the analytic
scene (no grid) in float64 with a 257-node probe. Configurations vary one thing at a time
around the default (dx = 5 m, 9 nodes, float64):

- nodes: 1 (the point probe), 3, 5, 9, 17, 33, 65; the error against the 257-node probe on
  the same grid isolates the quadrature error;
- float32 against float64;
- grid spacing dx = 20, 10, 5, 2.5 m;
- *auto*: the nodes `simulate` chooses for each grid (`lidarjax.probe_for_field`, from the
  grid's resolution: its vertical spacing dx/2);
- *cw*: the CW probe (`lidarjax.CWProbe`, whole Lorentzian cut at the lidar) with 17, 33, 65
  nodes and auto, against its own 257-node truth.

Time is the median wall time of one compiled call for all 360 x 9 x 5 beams (compile time
excluded). Run ``python benchmarks/accuracy_vs_time.py [--quick]``; writes
``benchmarks/results/accuracy_vs_time.json``, ``.png`` (Pareto plot) and ``.md`` (table).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _common import machine, median_time  # noqa: E402

import lidarjax as lj  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
HEIGHTS = np.linspace(40.0, 200.0, 9)
SCAN = lj.windcube_v2(28.0)
REF_NODES = 257

SCENES = {
    "shear": dict(
        scene=lj.scenes.power_law(10.0, 100.0, 0.2, 270.0, veer=0.05),
        lidar=(0.0, 0.0, 0.0),
        extent=(200.0, 280.0),
        cw_extent=(230.0, 470.0),  # the CW probe reaches twice the focus range
    ),
    "hill": dict(
        scene=lj.scenes.hill(height=60.0, half_width=200.0, speed=10.0, direction=250.0),
        lidar=(0.0, 0.0, 62.0),
        extent=(200.0, 340.0),
        cw_extent=(230.0, 530.0),
    ),
}



def probe_for(nodes, field, kind="pulsed"):
    """The probe of a configuration: ``nodes`` explicit, or ``"auto"``: what `simulate`
    chooses for the field's resolution (`lidarjax.probe_for_field`)."""
    make = lj.PulsedProbe if kind == "pulsed" else lj.CWProbe
    if nodes == "auto":
        return lj.probe_for_field(field, SCAN, HEIGHTS, make())
    return lj.PointProbe() if nodes == 1 else make(n_nodes=nodes)


def grid(scene, extent, dx, dtype):
    half, top = extent
    x = np.arange(-half, half + dx / 2, dx)
    z = np.arange(0.0, top + dx / 4, dx / 2)
    field = lj.GridField.from_function(scene.sample, x, x, z)
    return lj.GridField(x, x, z, field.velocity.astype(dtype))


def run_config(field, mounts, nodes, repeats, kind="pulsed"):
    probe = probe_for(nodes, field, kind)
    heights = jnp.asarray(HEIGHTS, field.dtype)

    def fn(f, m, h, p):
        sims = jax.vmap(
            lambda mm: lj.simulate(f, SCAN, mm, h, probe=p, point_reference=False))(m)
        return sims.lidar_speed, sims.lidar_direction

    compiled = jax.jit(fn).lower(field, mounts, heights, probe).compile()
    t = median_time(lambda: jax.block_until_ready(compiled(field, mounts, heights, probe)),
                    repeats)
    speed, direction = compiled(field, mounts, heights, probe)
    return t, np.asarray(speed, np.float64), np.asarray(direction, np.float64), getattr(
        probe, "n_nodes", 1)


def errors(speed, direction, ref):
    ds = np.abs(speed - ref[0])
    dd = np.abs((direction - ref[1] + 180.0) % 360.0 - 180.0)
    return float(np.max(ds)), float(np.max(dd))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer configurations (< 1 min)")
    args = parser.parse_args()
    repeats = 3 if args.quick else 7
    sectors = 36 if args.quick else 360
    node_counts = (1, 3, 9, 33) if args.quick else (1, 3, 5, 9, 17, 33, 65)
    spacings = (20.0, 10.0, 5.0) if args.quick else (20.0, 10.0, 5.0, 2.5)
    rows = []
    for name, cfg in SCENES.items():
        scene = cfg["scene"]
        betas = np.arange(sectors) * 360.0 / sectors
        mounts = lj.stack_mounts([lj.Mount(cfg["lidar"], beta=b, psi=180.0) for b in betas])
        truths = {kind: run_config(scene, mounts, REF_NODES, 1, kind)[1:3]
                  for kind in ("pulsed", "cw")}
        truth = truths["pulsed"]
        effect = run_config(scene, mounts, 1, 1)[1:3]  # the point probe: no volume at all
        volume_effect = errors(*effect, truth)[0]
        print(f"{name}: probe-volume effect on the speed (point vs 257 nodes, analytic) "
              f"{volume_effect:.3f} m/s")
        fields = {}

        def field_for(dx, dtype, kind="pulsed", _fields=fields, _scene=scene, _cfg=cfg):
            key = (dx, dtype, kind)
            if key not in _fields:
                extent = _cfg["extent"] if kind == "pulsed" else _cfg["cw_extent"]
                _fields[key] = grid(_scene, extent, dx, dtype)
            return _fields[key]

        ref_same_grid = {}
        configs = [(5.0, np.float64, q, "nodes", "pulsed") for q in node_counts]
        configs += [(5.0, np.float32, q, "float32", "pulsed") for q in (1, 9)]
        configs += [(dx, np.float64, 9, "spacing", "pulsed") for dx in spacings if dx != 5.0]
        # what simulate chooses by default: nodes for the grid's resolution (dx / 2 vertically)
        configs += [(dx, np.float64, "auto", "auto", "pulsed") for dx in spacings]
        configs += [(5.0, np.float64, q, "cw", "cw") for q in (17, 33, 65, "auto")]
        for dx, dtype, nodes, sweep, kind in configs:
            field = field_for(dx, dtype, kind)
            if (dx, dtype, kind) not in ref_same_grid:
                ref_same_grid[(dx, dtype, kind)] = run_config(field, mounts, REF_NODES, 1, kind)[1:3]
            t, speed, direction, nodes = run_config(field, mounts, nodes, repeats, kind)
            e_speed, e_dir = errors(speed, direction, truths[kind])
            q_speed, q_dir = errors(speed, direction, ref_same_grid[(dx, dtype, kind)])
            row = dict(scene=name, sweep=sweep, probe=kind, dx=dx, dtype=np.dtype(dtype).name,
                       nodes=nodes,
                       time_ms=1e3 * t, speed_error=e_speed, direction_error=e_dir,
                       speed_error_vs_257_same_grid=q_speed,
                       direction_error_vs_257_same_grid=q_dir,
                       sectors=sectors, samples=sectors * HEIGHTS.size * SCAN.n_beams * nodes,
                       probe_volume_effect=volume_effect,
                       field_mbytes=field.nbytes / 1e6)
            rows.append(row)
            print(f"  {sweep:8s} dx={dx:5.1f} {row['dtype']:7s} q={nodes:3d}  "
                  f"{row['time_ms']:7.2f} ms  speed err {e_speed:.2e} m/s "
                  f"(quadrature {q_speed:.2e})  dir err {e_dir:.2e} deg")
    RESULTS.mkdir(exist_ok=True)
    meta = dict(heights=HEIGHTS.tolist(), sectors=sectors, reference_nodes=REF_NODES,
                scan="windcube_v2(28)", probe="PulsedProbe() defaults", quick=args.quick,
                repeats=repeats, machine=machine())
    with open(RESULTS / "accuracy_vs_time.json", "w") as fh:
        json.dump({"meta": meta, "rows": rows}, fh, indent=1)
    write_table(rows, RESULTS / "accuracy_vs_time.md")
    plot(rows, RESULTS / "accuracy_vs_time.png")
    print(f"wrote {RESULTS / 'accuracy_vs_time.json'}, .md and .png")


def write_table(rows, path):
    lines = [
        "<!-- written by benchmarks/accuracy_vs_time.py -->",
        f"Windcube V2 + `PulsedProbe()`, {rows[0]['sectors']} sectors x {HEIGHTS.size} heights; "
        "errors are "
        "the largest over sectors and heights against the analytic scene with a "
        f"{REF_NODES}-node probe (float64); *quadrature* is against {REF_NODES} nodes on the "
        "same grid. Time: one compiled call, median.",
        "",
        "| scene | sweep | probe | dx (m) | dtype | nodes | time (ms) | speed error (m/s) | "
        "quadrature (m/s) | direction error (deg) |",
        "|---|---|---|---:|---|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['scene']} | {r['sweep']} | {r['probe']} | {r['dx']:g} | {r['dtype']} | "
            f"{r['nodes']} | "
            f"{r['time_ms']:.2f} | {r['speed_error']:.2e} | "
            f"{r['speed_error_vs_257_same_grid']:.2e} | {r['direction_error']:.2e} |")
    effects = {r["scene"]: r["probe_volume_effect"] for r in rows}
    lines += ["", "Probe-volume effect (point probe against the 257-node probe, analytic): "
              + ", ".join(f"{k} {v:.3f} m/s" for k, v in effects.items()) + "."]
    path.write_text("\n".join(lines) + "\n")


def plot(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = sorted({r["scene"] for r in rows}, reverse=True)
    fig, axes = plt.subplots(1, len(scenes), figsize=(5.5 * len(scenes), 4.3))
    markers = {"nodes": "o", "float32": "s", "spacing": "^", "auto": "*", "cw": "D"}
    for ax, scene in zip(np.atleast_1d(axes), scenes, strict=True):
        sel = [r for r in rows if r["scene"] == scene]
        for sweep, marker in markers.items():
            pts = [r for r in sel if r["sweep"] == sweep]
            ax.loglog([r["time_ms"] for r in pts], [max(r["speed_error"], 1e-9) for r in pts],
                      marker, label=sweep, ms=7)
            for r in pts:
                label = (f"q={r['nodes']}" if sweep in ("nodes", "cw") else
                         f"f32 q={r['nodes']}" if sweep == "float32" else
                         f"dx={r['dx']:g} q={r['nodes']}" if sweep == "auto" else f"dx={r['dx']:g}")
                ax.annotate(label, (r["time_ms"], max(r["speed_error"], 1e-9)), fontsize=7,
                            xytext=(3, 3), textcoords="offset points")
        front = pareto([(r["time_ms"], r["speed_error"]) for r in sel if r["probe"] == "pulsed"])
        ax.loglog(*zip(*front, strict=True), "k-", lw=0.8, alpha=0.5, label="Pareto front")
        ax.set(xlabel="time per call (ms)", ylabel="max horizontal speed error (m/s)",
               title=f"{scene}: {sel[0]['sectors']} sectors x {HEIGHTS.size} heights, V2")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def pareto(points):
    front, best = [], np.inf
    for t, e in sorted(points):
        if e < best:
            front.append((t, max(e, 1e-9)))
            best = e
    return front


if __name__ == "__main__":
    main()
