"""Benchmark: scanning lidars (`lidarjax.scanning`), against numpy implementations of the same
sampling.

1. **PPI in a grid.** A 360-ray x 200-gate PPI (Windcube 200S-like: 25 m gates, 100 ns pulse,
   `lidarjax.PulsedProbe` with the nodes `simulate_scan` chooses for the grid, shared
   between neighbouring gates: `lidarjax.gate_nodes`) in a 200 x 200 x 100 `GridField` of
   50 m spacing (10 x 10 x 5 km), float64 and float32: median wall time of
   `lidarjax.simulate_scan` after compilation (the whole call: validation, probe choice, the
   jit-compiled model), also with the nodes chosen once (an explicit count) and with
   per-gate nodes (``shared_nodes=False``), and the CPU time per call (summed over threads:
   the work, whatever else shares the machine). Target: at most 20 ms on the project's 2-core
   CPU, 1 ms on an H100.
2. **A 10-minute series of 1 Hz rays at 200 gates through a turbulence box**
   (`lidarjax.scenes.FrozenTurbulence`: the 512 x 32 x 64 Mann box of 4 x 8 x 4 m of
   `benchmarks/series.py`, over a 10 m/s uniform wind; Halo-like 30 m gates, 0.2 us pulse):
   (a) a stare at 60 degrees elevation (600 rays of 1 s), (b) a 60-ray step-and-stare PPI
   at 5 degrees repeated 10 times. `lidarjax.simulate_scan_series` against numpy sampling
   every ray at its own time (periodic box), one vectorised call per ray: trilinear written
   out in numpy, and scipy's RegularGridInterpolator on the periodically padded box as
   `benchmarks/series.py` does. Target: at least 50x.

The numpy side integrates the very quadrature `lidarjax.gate_nodes` reports, in two layouts:
every node of every gate (``per_gate``, shared nodes sampled again), and every distinct node
once (``shared``, as lidarjax does); the ratio is against the faster. The two sides agree to
rounding (checked; the largest difference is reported). Timings are medians over repeats;
the machine is shared (its load average is recorded).

Run: ``PYTHONPATH=$PWD python3 benchmarks/scanning.py [--quick] [--out DIR --name STEM]``.
Writes ``benchmarks/results/scanning.{json,png}``.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import jax
import numpy as np
from _common import machine, machine_line, median_time  # noqa: E402

import lidarjax as lj
from lidarjax.beam import pattern_probe as _refine

jax.config.update("jax_enable_x64", True)
OUT = Path(__file__).resolve().parent / "results"


# -- numpy implementations ------------------------------------------------------------------------
def np_grid_los(vel, origin, spacing, pts, n):
    """Trilinear velocity of a uniform grid at points (..., 3), projected on n (..., 3)."""
    f = (pts - origin) / spacing
    shape = np.array(vel.shape[:3])
    inside = np.all((f >= 0) & (f <= shape - 1), axis=-1)
    i0 = np.clip(np.floor(np.where(inside[..., None], f, 0)), 0, shape - 2).astype(np.int64)
    t = f - i0
    out = 0.0
    for dx in (0, 1):
        wx = t[..., 0] if dx else 1 - t[..., 0]
        for dy in (0, 1):
            wy = t[..., 1] if dy else 1 - t[..., 1]
            for dz in (0, 1):
                wz = t[..., 2] if dz else 1 - t[..., 2]
                v = vel[i0[..., 0] + dx, i0[..., 1] + dy, i0[..., 2] + dz]
                out = out + (wx * wy * wz) * np.sum(v * n, axis=-1)
    return np.where(inside, out, np.nan)


def np_windows(los_fine, window, weights):
    """Gate values ``(..., g)`` from samples ``(..., L)``: ``sum_j w_gj los[window_gj]``, NaN
    where a node of nonzero weight is NaN."""
    los_q = los_fine[..., window]  # (..., g, q)
    kept = weights > 0
    bad = np.any(np.isnan(los_q) & kept, axis=-1)
    return np.where(bad, np.nan, np.sum(np.where(kept, weights * np.nan_to_num(los_q), 0.0), axis=-1))


def layouts(ranges, offsets, weights):
    """Two ways to lay out the same quadrature (`lidarjax.gate_nodes`) along a beam:
    ``per_gate`` samples every node of every gate (shared nodes twice), ``shared`` every
    distinct node range once. Each: (sample ranges (L,), window (g, q))."""
    node_r = ranges[:, None] + offsets
    per_gate = (node_r.ravel(), np.arange(node_r.size).reshape(node_r.shape))
    distinct, inverse = np.unique(np.round(node_r, 9), return_inverse=True)
    return {"per_gate": per_gate, "shared": (distinct, inverse.reshape(node_r.shape))}


def np_ppi(vel, origin, spacing, loc, az, el, fine, window, weights):
    a, e = np.deg2rad(az), np.deg2rad(el)
    n = np.stack([np.cos(e) * np.sin(a), np.cos(e) * np.cos(a), np.full_like(a, np.sin(e))], -1)
    pts = loc + fine[None, :, None] * n[:, None, :]  # (b, L, 3)
    return np_windows(np_grid_los(vel, origin, spacing, pts, n[:, None, :]), window, weights)


def np_box_fluct(box_vel, spacing, axes, anchor, shift, speed, pts, t):
    """FrozenTurbulence's fluctuation (CFD frame) at points (..., 3) and times (...)."""
    nx, ny, nz, _ = box_vel.shape
    loc = (pts - anchor) @ axes.T
    xi = loc[..., 0] - shift - speed * t
    s = np.stack([xi / spacing[0], loc[..., 1] / spacing[1] + (ny - 1) / 2, loc[..., 2] / spacing[2]], -1)
    fl = np.floor(s)
    frac = s - fl
    i0 = fl.astype(np.int64)
    sizes = np.array([nx, ny, nz])
    uvw = 0.0
    for dx in (0, 1):
        wx = frac[..., 0] if dx else 1 - frac[..., 0]
        for dy in (0, 1):
            wy = frac[..., 1] if dy else 1 - frac[..., 1]
            for dz in (0, 1):
                wz = frac[..., 2] if dz else 1 - frac[..., 2]
                idx = np.mod(i0 + np.array([dx, dy, dz]), sizes)
                uvw = uvw + (wx * wy * wz)[..., None] * box_vel[idx[..., 0], idx[..., 1], idx[..., 2]]
    return uvw @ axes


class RgiBox:
    """The box as `benchmarks/series.py` samples it: scipy's RegularGridInterpolator on the box
    padded by one periodic plane per axis."""

    def __init__(self, box_vel, spacing):
        from scipy.interpolate import RegularGridInterpolator

        self.n = np.array(box_vel.shape[:3])
        self.spacing = np.asarray(spacing, float)
        padded = np.pad(box_vel, [(0, 1), (0, 1), (0, 1), (0, 0)], mode="wrap")
        grids = [np.arange(k + 1) * d for k, d in zip(self.n, self.spacing, strict=True)]
        self.rgi = RegularGridInterpolator(grids, padded)

    def __call__(self, box_vel, spacing, axes, anchor, shift, speed, pts, t):
        loc = (pts - anchor) @ axes.T
        period = self.n * self.spacing
        xi = np.mod(loc[..., 0] - shift - speed * t, period[0])
        eta = np.mod(loc[..., 1] + (self.n[1] - 1) / 2 * self.spacing[1], period[1])
        zeta = np.mod(loc[..., 2], period[2])
        q = np.stack([xi, eta, zeta], -1)
        return self.rgi(q.reshape(-1, 3)).reshape(q.shape) @ axes


def np_series(mean, box_vel, spacing, axes, anchor, shift, speed, loc, az, el, t_ray, fine, window,
              weights, fluct=np_box_fluct):
    """One vectorised call per ray: its samples at its time, then the gates' windows."""
    out = np.empty((az.size, window.shape[0]))
    for i in range(az.size):
        a, e = np.deg2rad(az[i]), np.deg2rad(el[i])
        n = np.array([np.cos(e) * np.sin(a), np.cos(e) * np.cos(a), np.sin(e)])
        pts = loc + fine[:, None] * n
        v = mean + fluct(box_vel, spacing, axes, anchor, shift, speed, pts, t_ray[i])
        out[i] = np_windows(v @ n, window, weights)
    return out


# -- cases ----------------------------------------------------------------------------------------
def ppi_case(dtype, repeats):
    dx = 50.0
    x = np.arange(200) * dx - 5000.0
    z = np.arange(100) * dx
    rng = np.random.default_rng(0)
    vel = (rng.normal(size=(200, 200, 100, 3)) * 0.5 + np.array([8.0, 2.0, 0.0])).astype(dtype)
    field = lj.GridField(x, x, z, vel)
    pattern = lj.ppi(3.0, lj.gate_ranges(200, 25.0, first=100.0), n_rays=360, accumulation=0.1)
    probe = lj.instrument_probe("windcube_200s", gate_length=25.0, pulse_duration=100e-9)
    mount = lj.Mount([0.0, 0.0, 10.0])
    t0 = time.perf_counter()
    res = lj.simulate_scan(field, pattern, mount, probe=probe)
    res.los.block_until_ready()
    compile_s = time.perf_counter() - t0
    t_jax = median_time(lambda: lj.simulate_scan(field, pattern, mount, probe=probe).los.block_until_ready(),
                        repeats)
    cpu = time.process_time()
    for _ in range(repeats):
        lj.simulate_scan(field, pattern, mount, probe=probe).los.block_until_ready()
    cpu_ms = 1e3 * (time.process_time() - cpu) / repeats  # summed over threads: the work
    chosen, rule = _refine(field, pattern, probe, "benchmark")
    # the nodes chosen once (`lidarjax.probe_for_field`, or an explicit count): no host-side
    # choice per call, the call is validation and the compiled model
    fixed = chosen.with_nodes(chosen.n_nodes)
    t_fixed = median_time(
        lambda: lj.simulate_scan(field, pattern, mount, probe=fixed).los.block_until_ready(), repeats)
    t_own = median_time(lambda: lj.simulate_scan(field, pattern, mount, probe=probe,
                                                 shared_nodes=False).los.block_until_ready(), repeats)
    ranges = np.asarray(pattern.ranges, np.float64)
    offsets, weights = lj.gate_nodes(field, pattern, probe)
    base = (vel.astype(np.float64), np.array([-5000.0, -5000.0, 0.0]), dx, np.array([0.0, 0.0, 10.0]),
            np.asarray(pattern.azimuth, np.float64), 3.0)
    np_ms, diff = {}, 0.0
    for name, (fine, window) in layouts(ranges, offsets, weights).items():
        ref = np_ppi(*base, fine, window, weights)
        np_ms[name] = 1e3 * median_time(lambda f=fine, w=window: np_ppi(*base, f, w, weights),
                                        max(3, repeats // 5))
        diff = max(diff, float(np.nanmax(np.abs(np.asarray(res.los, np.float64) - ref))))
    samples = layouts(ranges, offsets, weights)["shared"][0].size
    return {"dtype": np.dtype(dtype).name, "rays": 360, "gates": 200, "grid": [200, 200, 100],
            "probe_nodes": chosen.n_nodes, "nodes_per_gate": offsets.shape[1], "shared_rule": rule,
            "samples": 360 * samples, "samples_per_gate_layout": 360 * offsets.size,
            "compile_s": compile_s, "lidarjax_ms": 1e3 * t_jax, "lidarjax_cpu_ms": cpu_ms,
            "lidarjax_nodes_fixed_ms": 1e3 * t_fixed, "lidarjax_own_nodes_ms": 1e3 * t_own,
            "numpy_ms": np_ms["per_gate"], "numpy_shared_ms": np_ms["shared"],
            "ratio": min(np_ms.values()) / (1e3 * t_jax), "max_abs_diff": diff, "target_ms": 20.0}


def series_case(kind, repeats, shape=(512, 32, 64), spacing=(4.0, 8.0, 4.0)):
    box = lj.synthesize_box(shape, spacing, 0.1, 30.0, 3.9, seed=1)
    field = lj.scenes.FrozenTurbulence(lj.scenes.uniform(10.0, 270.0), box, 10.0, 270.0,
                                       anchor=(-100.0, 0.0, 0.0))
    ranges = lj.gate_ranges(200, 30.0)
    if kind == "stare":
        pattern, n_scans = lj.stare(0.0, 60.0, ranges, n_rays=1, accumulation=1.0), 600
    else:
        pattern, n_scans = lj.ppi(5.0, ranges, n_rays=60, mode="step", head_speed=1e9,
                                  accumulation=1.0), 10
    probe = lj.instrument_probe("halo_streamline")
    mount = lj.Mount([0.0, 0.0, 20.0])
    t0 = time.perf_counter()
    res = lj.simulate_scan_series(field, pattern, mount, n_scans=n_scans, probe=probe)
    res.los.block_until_ready()
    compile_s = time.perf_counter() - t0
    t_jax = median_time(lambda: lj.simulate_scan_series(field, pattern, mount, n_scans=n_scans,
                                                        probe=probe).los.block_until_ready(), repeats)
    chosen, rule = _refine(field, pattern, probe, "benchmark")
    t_own = median_time(lambda: lj.simulate_scan_series(field, pattern, mount, n_scans=n_scans, probe=probe,
                                                        shared_nodes=False).los.block_until_ready(), repeats)
    ranges = np.asarray(pattern.ranges, np.float64)
    offsets, weights = lj.gate_nodes(field, pattern, probe)
    rays = pattern.repeated(n_scans)
    args = (np.asarray(field.mean.sample(np.zeros(3))), np.asarray(box.velocity), np.asarray(box.spacing),
            np.asarray(field.axes()), np.asarray(field.anchor), float(field.shift), 10.0,
            np.array([0.0, 0.0, 20.0]), np.asarray(rays.azimuth), np.asarray(rays.elevation),
            np.asarray(rays.ray_times()))
    got = np.asarray(res.los).reshape(-1, 200)
    out, diff = {}, 0.0
    rgi = RgiBox(np.asarray(box.velocity), np.asarray(box.spacing))
    for name, (fine, window) in layouts(ranges, offsets, weights).items():
        for base, fluct in (("numpy", np_box_fluct), ("scipy_rgi", rgi)):
            ref = np_series(*args, fine, window, weights, fluct=fluct)
            diff = max(diff, float(np.nanmax(np.abs(got - ref))))
            key = f"{base}_s" if name == "per_gate" else f"{base}_shared_s"
            out[key] = median_time(
                lambda f=fine, w=window, fl=fluct: np_series(*args, f, w, weights, fluct=fl), 1, warm=False)
    best_np = min(out["numpy_s"], out["numpy_shared_s"])
    best_rgi = min(out["scipy_rgi_s"], out["scipy_rgi_shared_s"])
    return {"case": kind, "rays": rays.n_rays, "gates": 200, "box": list(shape), "box_spacing": list(spacing),
            "probe_nodes": chosen.n_nodes, "nodes_per_gate": offsets.shape[1], "shared_rule": rule,
            "compile_s": compile_s, "lidarjax_s": t_jax, "lidarjax_own_nodes_s": t_own, **out,
            "ratio": best_np / t_jax, "ratio_rgi": best_rgi / t_jax,
            "max_abs_diff": diff, "target_ratio": 50.0}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", type=Path, default=OUT, help="folder for scanning.{json,png}")
    ap.add_argument("--name", default="scanning", help="file stem (e.g. scanning_h100)")
    args = ap.parse_args()
    repeats = 5 if args.quick else 31
    out = {"machine": machine(), "load_average": list(os.getloadavg())}
    out["ppi"] = [ppi_case(np.float64, repeats), ppi_case(np.float32, repeats)]
    out["series"] = [series_case("stare", max(3, repeats // 4)), series_case("ppi", max(3, repeats // 4))]
    out["load_average_after"] = list(os.getloadavg())
    args.out.mkdir(exist_ok=True, parents=True)
    (args.out / f"{args.name}.json").write_text(json.dumps(out, indent=1))
    print(machine_line(out["machine"]), "load", out["load_average"])
    for c in out["ppi"]:
        print(f"PPI {c['dtype']}: {c['lidarjax_ms']:.2f} ms wall ({c['lidarjax_nodes_fixed_ms']:.2f} ms with "
              f"the nodes chosen once, {c['lidarjax_own_nodes_ms']:.2f} ms with per-gate nodes), "
              f"{c['lidarjax_cpu_ms']:.1f} ms CPU (numpy {c['numpy_ms']:.0f} ms, shared "
              f"{c['numpy_shared_ms']:.0f} ms: "
              f"{c['ratio']:.0f}x; {c['nodes_per_gate']} nodes per gate, rule {c['shared_rule']}; "
              f"diff {c['max_abs_diff']:.1e})")
    for c in out["series"]:
        print(f"series {c['case']}: {c['lidarjax_s'] * 1e3:.0f} ms (per-gate nodes "
              f"{c['lidarjax_own_nodes_s'] * 1e3:.0f} ms) vs numpy {c['numpy_s']:.2f} s / shared "
              f"{c['numpy_shared_s']:.2f} s ({c['ratio']:.0f}x), scipy RGI {c['scipy_rgi_s']:.2f} s / shared "
              f"{c['scipy_rgi_shared_s']:.2f} s ({c['ratio_rgi']:.0f}x); diff {c['max_abs_diff']:.1e}")
    plot(out, args.out / f"{args.name}.png")


def plot(out, path=OUT / "scanning.png"):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    ax = axes[0]
    labels = [f"PPI {c['dtype']}" for c in out["ppi"]]
    xpos = np.arange(len(labels))
    ax.bar(xpos - 0.2, [c["lidarjax_ms"] for c in out["ppi"]], 0.4, color="C0", label="wall (median)")
    ax.bar(xpos + 0.2, [c.get("lidarjax_cpu_ms", np.nan) for c in out["ppi"]], 0.4, color="C9",
           label="CPU time (all threads)")
    ax.set_xticks(xpos, labels)
    ax.axhline(20.0, color="k", ls="--", lw=1, label="target 20 ms")
    ax.set_ylabel("ms per 360 x 200 PPI (median)")
    ax.set_title("PPI, pulsed probe, 200x200x100 grid")
    ax.legend()
    ax = axes[1]
    labels = [f"{c['case']} ({c['rays']} rays)" for c in out["series"]]
    xpos = np.arange(len(labels))
    ax.bar(xpos - 0.2, [c["ratio"] for c in out["series"]], 0.4, color="C1", label="vs numpy trilinear")
    ax.bar(xpos + 0.2, [c["ratio_rgi"] for c in out["series"]], 0.4, color="C2", label="vs scipy RGI")
    ax.set_xticks(xpos, labels)
    ax.axhline(50.0, color="k", ls="--", lw=1, label="target 50x")
    ax.set_ylabel("speed-up over numpy (same sampling)")
    ax.set_title("10-min series of 1 Hz rays, 200 gates, Mann box")
    ax.legend()
    load = out.get("load_average", [np.nan])[0]
    fig.suptitle(f"{machine_line(out['machine'])}; shared machine, load average {load:.1f}", fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    import sys

    if sys.argv[1:] == ["--plot-only"]:  # redraw from the last results
        plot(json.loads((OUT / "scanning.json").read_text()))
    else:
        main()
