"""Benchmark: 10-minute records per second of a Windcube V2 (pulsed probe, 12 heights) in
frozen Mann turbulence, lidarjax against a numpy/scipy implementation of the same sampling;
the time for one year of records; the error of the simulated TI ratio against the spectral
model (`lidarjax.spectral`).

Both sides compute the same thing per record: every LOS at its own time (120 cycles of 5
beams, 1 s per LOS), each the pulsed-probe average along its beam (25 nodes: the count
`simulate_statistics` refines the default 9 to for the 4 m box; cut at the lidar
as `lidarjax.simulate` does) of the box advected at ``U`` (Taylor, periodic box, trilinear
interpolation: scipy's `RegularGridInterpolator` on the box padded by one periodic plane per
axis), the sliding Windcube reconstruction after every LOS from the latest 5, then the
``.sta`` statistics plus a cup at 1 Hz at each height. The two agree to rounding (checked and
reported). lidarjax streams chunks of records through `simulate_statistics` (jit, vmap);
numpy loops over records (each record vectorised over all its LOS and nodes).

Accuracy: an ensemble of Mann boxes gives per-height ``(TI_lidar / TI_point)^2`` (pooled
speed variance over the cup's), compared with `lidarjax.spectral.lidar_variance` for the
same box wavenumbers, probe nodes, the five sliding-window beam-time patterns and 600 s
records, interpolating every probe node between the box's nodes as the simulator does
(``interpolation="nodes"``); the older uniform-cell approximation is reported beside it.
The spectral model predicts the variance of the reconstructed ``u``; the speed dispersion
equals it to first order in the turbulence intensity (the boxes are drawn at TI of about 5 %).

Run: ``PYTHONPATH=$PWD python3 benchmarks/series.py [--quick]``. Writes
``benchmarks/results/series.{json,png,md}``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from _common import machine, machine_line  # noqa: E402
from scipy.interpolate import RegularGridInterpolator

import lidarjax
from lidarjax.scenes import FrozenTurbulence
from lidarjax.series import probe_for_field, simulate_statistics
from lidarjax.spectral import lidar_variance
from lidarjax.turbulence import TurbulenceBox, fft_mann_box

HERE = Path(__file__).parent
U, DIRECTION = 10.0, 270.0
L_SCALE, GAMMA = 30.0, 3.9
RECORDS_PER_YEAR = 52_560
#: Spectral level of the accuracy boxes: sigma_u about 0.5 m/s (TI 5 %). The model predicts
#: the variance of the reconstructed u; the .sta speed dispersion equals it to first order in
#: TI only: the speed sqrt((U + u)^2 + v^2) adds v^2 / 2U, whose variance (the lidar's v is
#: inflated by the w difference across the cone, growing with height) biases the ratio up by
#: about 10-20 % at TI 25 %.
ALPHA_EPS = 0.05


def make_field(vel, spacing, dtype, anchor=(0.0, 0.0, 0.0), speed=U):
    box = TurbulenceBox(jnp.asarray(vel, dtype), jnp.asarray(spacing, dtype), periodic=(True, True))
    mean = lidarjax.scenes.uniform(speed, DIRECTION, dtype=dtype)
    return FrozenTurbulence(mean, box, speed, DIRECTION, anchor=anchor)


class NumpySeries:
    """The same sampling in numpy/scipy: V2 sliding reconstruction, pulsed probe, Taylor."""

    def __init__(self, vel, spacing, heights, probe, scan):
        self.spacing = np.asarray(spacing, float)
        nx, ny, nz = vel.shape[:3]
        self.n = np.array([nx, ny, nz])
        padded = np.pad(vel, ((0, 1), (0, 1), (0, 1), (0, 0)), mode="wrap")
        grids = [np.arange(k + 1) * d for k, d in zip(self.n, self.spacing, strict=True)]
        self.rgi = RegularGridInterpolator(grids, padded, method="linear", bounds_error=True)
        d = np.deg2rad(DIRECTION)
        ex = np.array([-np.sin(d), -np.cos(d), 0.0])
        ey = np.array([-ex[1], ex[0], 0.0])
        self.axes = np.stack([ex, ey, [0.0, 0.0, 1.0]])
        self.heights = np.asarray(heights, float)
        self.dirs = np.asarray(scan.directions(), float)  # (b, 3), level lidar = CFD frame
        ranges = self.heights[:, None] / self.dirs[None, :, 2]  # (h, b)
        off, w = probe.nodes(jnp.asarray(ranges))
        off = np.broadcast_to(np.asarray(off, float), ranges.shape + (np.shape(off)[-1],))
        w = np.broadcast_to(np.asarray(w, float), off.shape)
        ahead = np.abs(off) < ranges[..., None]
        w = np.where(ahead, w, 0.0)
        self.weights = w / w.sum(-1, keepdims=True)  # (h, b, q)
        self.points = (ranges[..., None] + off)[..., None] * self.dirs[None, :, None, :]  # (h,b,q,3)
        self.length = self.n[0] * self.spacing[0]
        self.cone = float(scan.cone_angle)

    def velocity(self, points, t):
        """Mean + advected box fluctuation (CFD frame) at points (..., 3), times (...)."""
        local = points @ self.axes.T
        xi = np.mod(local[..., 0] - U * t, self.length)
        eta = np.mod(local[..., 1] + (self.n[1] - 1) / 2 * self.spacing[1], self.n[1] * self.spacing[1])
        zeta = np.mod(local[..., 2], self.n[2] * self.spacing[2])
        q = np.stack([xi, eta, zeta], -1)
        fl = self.rgi(q.reshape(-1, 3)).reshape(q.shape)
        return U * self.axes[0] + fl @ self.axes

    def node_los(self, t_los):
        """LOS of every probe node (m, h, b, q) at the LOS times (m, b)."""
        pts = np.broadcast_to(self.points[None], (t_los.shape[0],) + self.points.shape)
        tt = np.broadcast_to(t_los[:, None, :, None], pts.shape[:-1])
        v = self.velocity(pts, tt)  # (m, h, b, q, 3)
        return np.einsum("mhbqi,bi->mhbq", v, self.dirs)

    def point_velocity(self, tp):
        """Velocity (p, h, 3) above the lidar at times (p,)."""
        pp = np.broadcast_to((self.heights[:, None] * np.array([0.0, 0.0, 1.0]))[None],
                             (tp.size, self.heights.size, 3))
        return self.velocity(pp, np.broadcast_to(tp[:, None], pp.shape[:-1]))

    def record(self, start):
        m, b = 120, 5
        t_los = start + np.arange(m)[:, None] * 5.0 + np.arange(b)[None, :]  # (m, b)
        los = np.sum(self.weights * self.node_los(t_los), -1)  # (m, h, b)
        seq = los.transpose(0, 2, 1).reshape(m * b, -1)  # LOS in time order, (m b, h)
        k = np.arange(b - 1, m * b)
        latest = np.stack([k - np.mod(k - j, b) for j in range(b)], -1)  # (n, b) LOS index
        win = seq[latest]  # (n, b, h)
        s = np.sin(np.deg2rad(self.cone))
        u = (win[:, 1] - win[:, 3]) / (2 * s)
        vv = (win[:, 0] - win[:, 2]) / (2 * s)
        w = win[:, 4]
        spd = np.hypot(u, vv)
        vp = self.point_velocity(start + np.arange(600.0))
        cup = np.hypot(vp[..., 0], vp[..., 1])
        return {"speed": spd.mean(0), "speed_std": spd.std(0), "w": w.mean(0), "w_std": w.std(0),
                "cup_speed": cup.mean(0), "cup_std": cup.std(0)}


class NumpyLines(NumpySeries):
    """The same sampling with lidarjax's fixed-point preparation done in numpy too (the
    stronger baseline): every probe node and point sensor stays put, so the box is
    interpolated once per point along its whole x period (scipy, nx + 1 values per point,
    projected on the beam for the nodes) and each sample is a linear interpolation in that
    line (numpy fancy indexing)."""

    def __init__(self, vel, spacing, heights, probe, scan):
        super().__init__(vel, spacing, heights, probe, scan)
        nx = self.n[0]
        xs = np.arange(nx + 1) * self.spacing[0]

        def lines(points):  # (P, 3) -> xi0 (P,), lines (P, nx + 1, 3) in the CFD frame
            local = points @ self.axes.T
            eta = np.mod(local[:, 1] + (self.n[1] - 1) / 2 * self.spacing[1],
                         self.n[1] * self.spacing[1])
            zeta = np.mod(local[:, 2], self.n[2] * self.spacing[2])
            q = np.stack(np.broadcast_arrays(xs[None, :], eta[:, None], zeta[:, None]), -1)
            return local[:, 0], self.rgi(q.reshape(-1, 3)).reshape(q.shape) @ self.axes

        shape = self.points.shape[:-1]  # (h, b, q)
        xi0, ln = lines(self.points.reshape(-1, 3))
        dirs = np.broadcast_to(self.dirs[None, :, None, :], shape + (3,)).reshape(-1, 3)
        self.node_xi0 = xi0.reshape(shape)
        self.node_lines = np.einsum("pxi,pi->px", ln, dirs)  # (P, nx + 1)
        pts = self.heights[:, None] * np.array([0.0, 0.0, 1.0])
        self.pt_xi0, self.pt_lines = lines(pts)  # (h,), (h, nx + 1, 3)

    def _lerp(self, lines, xi0, t):
        s = np.mod(xi0 - U * t, self.length) / self.spacing[0]
        i0 = np.minimum(np.floor(s).astype(np.int64), self.n[0] - 1)
        f = s - i0
        p = np.broadcast_to(np.arange(lines.shape[0]).reshape(xi0.shape), s.shape)
        if lines.ndim == 3:
            f = f[..., None]
        return lines[p, i0] * (1 - f) + lines[p, i0 + 1] * f

    def node_los(self, t_los):
        mean = U * (self.dirs @ self.axes[0])[None, None, :, None]
        return mean + self._lerp(self.node_lines, self.node_xi0[None], t_los[:, None, :, None])

    def point_velocity(self, tp):
        return U * self.axes[0] + self._lerp(self.pt_lines, self.pt_xi0[None], tp[:, None])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    quick = args.quick
    jax.config.update("jax_enable_x64", True)
    heights = np.linspace(40.0, 200.0, 12)
    scan = lidarjax.windcube_v2()
    mount = lidarjax.Mount([0.0, 0.0, 0.0])
    shape, spacing = ((512, 32, 64), (4.0, 8.0, 4.0)) if not quick else ((256, 32, 64), (4.0, 8.0, 4.0))
    vel = fft_mann_box(shape, spacing, length_scale=L_SCALE, gamma=GAMMA, sigma_u=1.0, seed=1)
    # the nodes simulate_statistics integrates the pulsed weighting with in a 4 m box (it
    # refines the default 9 itself, for the accuracy ensemble's heights up to 216 m too);
    # numpy and the spectral model use the same
    probe = probe_for_field(make_field(vel, spacing, jnp.float64), scan, np.append(heights, 216.0),
                            lidarjax.PulsedProbe())
    results = {"machine": machine(),
               "setup": {"scan": "windcube_v2", "probe": f"PulsedProbe({probe.n_nodes} nodes)",
                         "heights": heights.tolist(), "box_shape": shape, "box_spacing": spacing,
                         "U": U, "los_per_record": 600,
                         "field_samples_per_record": 600 * 12 * probe.n_nodes + 600 * 12}}

    # --- speed: lidarjax (float32 and float64) against numpy, same records
    n_np = 3 if quick else 6
    ref = NumpySeries(vel, spacing, heights, probe, scan)
    t0 = time.perf_counter()
    np_stats = [ref.record(600.0 * r) for r in range(n_np)]
    t_np = (time.perf_counter() - t0) / n_np
    results["numpy_seconds_per_record"] = t_np
    # the stronger baseline: lines per point in numpy too (preparation timed separately)
    t0 = time.perf_counter()
    ref_lines = NumpyLines(vel, spacing, heights, probe, scan)
    t_prep = time.perf_counter() - t0
    n_lines = 4 * n_np
    t0 = time.perf_counter()
    lines_stats = [ref_lines.record(600.0 * r) for r in range(n_lines)]
    t_lines = (time.perf_counter() - t0) / n_lines
    results["numpy_lines_seconds_per_record"] = t_lines
    results["numpy_lines_preparation_s"] = t_prep
    results["numpy_lines_max_abs_diff_speed_std_vs_numpy"] = max(
        float(np.max(np.abs(lines_stats[r]["speed_std"] - np_stats[r]["speed_std"])))
        for r in range(n_np))
    print(f"numpy/scipy: {1 / t_np:.2f} records/s; numpy with lines: {1 / t_lines:.1f} records/s "
          f"(+{t_prep:.2f} s preparation per box)")
    speed = {}
    for name, dtype in (("float32", jnp.float32), ("float64", jnp.float64)):
        field = make_field(vel, spacing, dtype)
        chunk = 32 if quick else 64
        starts = np.arange(chunk) * 600.0
        t0 = time.perf_counter()
        simulate_statistics(field, scan, mount, heights, starts, probe=probe, chunk=chunk)
        t_first = time.perf_counter() - t0
        reps = []
        n_runs = 2 if quick else 3
        for _ in range(n_runs):
            t0 = time.perf_counter()
            st = simulate_statistics(field, scan, mount, heights, starts, probe=probe, chunk=chunk)
            reps.append(time.perf_counter() - t0)
        per = float(np.median(reps)) / chunk
        diff = max(float(np.max(np.abs(np.asarray(st.speed_std[r]) - np_stats[r]["speed_std"])))
                   for r in range(n_np))
        diff_cup = max(float(np.max(np.abs(np.asarray(st.cup_std[r]) - np_stats[r]["cup_std"])))
                       for r in range(n_np))
        speed[name] = {"seconds_per_record": per, "records_per_second": 1 / per,
                       "compile_and_first_chunk_s": t_first - per * chunk, "chunk": chunk,
                       "speedup_vs_numpy": t_np / per, "speedup_vs_numpy_lines": t_lines / per,
                       "max_abs_diff_speed_std_vs_numpy": diff,
                       "max_abs_diff_cup_std_vs_numpy": diff_cup,
                       "year_seconds_extrapolated": per * RECORDS_PER_YEAR}
        print(f"{name}: {1 / per:.1f} records/s (numpy {1 / t_np:.2f}/s, x{t_np / per:.1f}); "
              f"year {per * RECORDS_PER_YEAR / 60:.1f} min (extrapolated from {n_runs} x {chunk} "
              f"records); |dstd| vs numpy {diff:.2e} m/s")
    results["lidarjax"] = speed

    # --- one year of records at 12 heights, measured whole (float32, streamed in chunks)
    if not quick:
        field = make_field(vel, spacing, jnp.float32)
        starts = np.arange(RECORDS_PER_YEAR) * 600.0
        t0 = time.perf_counter()
        st = simulate_statistics(field, scan, mount, heights, starts, probe=probe, chunk=64)
        t_year = time.perf_counter() - t0
        results["year_float32_seconds_measured"] = t_year
        results["year_float32_finite_share"] = float(np.mean(np.isfinite(st.speed_std)))
        print(f"one year (52,560 records x 12 heights, float32): {t_year:.1f} s measured")

    # --- accuracy: ensemble of exact-spectrum boxes against the spectral model
    # Low TI (ALPHA_EPS). The lidar stands on a column of box nodes (lateral anchor offset
    # dy/2 for the even ny, heights on multiples of dz): the E and W beams (those of u) then
    # stay on the lateral node plane, the N and S beams cut it. The model interpolates every
    # probe node as the simulator does (`interpolation="nodes"`): exact fixed lateral and
    # vertical fractions, the advected x position as aliases of the linear interpolation,
    # which needs LOS times that do not keep landing on the same spots in the 4 m cells: at
    # 10 m/s a beam comes back every 5 s, 12.5 cells later, so it would see only two
    # positions; at U_ACC = 9.73 m/s it sweeps the cells. The point sensors sample every
    # 0.25 s. One record per box pair keeps the records independent (a 600 s record sweeps
    # the 1 km box almost 6 times), and the uncertainty is the spread over boxes.
    u_acc = 9.73
    n_boxes = 8 if quick else 48
    n_rec = 2
    group = 8
    acc_shape, acc_spacing = ((256, 32, 64), (4.0, 8.0, 4.0))
    heights = np.arange(40.0, 220.0, 16.0)  # 12 heights on box nodes
    anchor = (0.0, -acc_spacing[1] / 2, 0.0)
    ratios = []
    t0 = time.perf_counter()
    var_l, var_p = [], []
    for g0 in range(0, n_boxes, group):
        fields = [make_field(fft_mann_box(acc_shape, acc_spacing, length_scale=L_SCALE, gamma=GAMMA,
                                          alphaepsilon=ALPHA_EPS, seed=100 + s),
                             acc_spacing, jnp.float64, anchor=anchor, speed=u_acc)
                  for s in range(g0, min(g0 + group, n_boxes))]
        st = simulate_statistics(lidarjax.stack_fields(fields), scan, mount, heights,
                                 np.arange(n_rec) * 600.0, probe=probe, ensemble=True,
                                 chunk=n_rec, point_dt=0.25)
        var_l.append(np.asarray(st.speed_std) ** 2)  # (e, r, h)
        var_p.append(np.asarray(st.cup_std) ** 2)
    var_l, var_p = np.concatenate(var_l), np.concatenate(var_p)
    t_ens = time.perf_counter() - t0
    # The V2 rebuilds the vector after every LOS from the latest LOS of each beam: five window
    # types, each with its own beam times (S1 to S3 is +2 s in three of them, -3 s in two).
    # The model averages the lidar variance over them, with the simulator's probe nodes.
    windows = np.asarray([[[j - last if j <= last else j - last - 5 for j in range(5)]]
                          for last in range(5)], float)  # (w, 1, b)
    t0 = time.perf_counter()
    model, model_cells = [], []
    for h in heights:
        common = dict(box_shape=acc_shape, box_spacing=acc_spacing, direction=DIRECTION,
                      speed=u_acc, record_length=600.0, probe_model="nodes")
        model.append(lidar_variance(scan, probe, h, L_SCALE, GAMMA, beam_times=windows,
                                    interpolation="nodes", **common).ratio)
        lvs = [lidar_variance(scan, probe, h, L_SCALE, GAMMA, beam_times=w[0],
                              interpolation="trilinear", **common) for w in windows]
        model_cells.append(np.mean([lv.lidar for lv in lvs]) / lvs[0].point)
    model, model_cells = np.asarray(model), np.asarray(model_cells)
    t_model = time.perf_counter() - t0
    # the model is a ratio of expected variances: pool the variances, then divide
    mean_ratio = var_l.mean(axis=(0, 1)) / var_p.mean(axis=(0, 1))
    per_box = var_l.mean(axis=1) / var_p.mean(axis=1)
    sem = per_box.std(axis=0, ddof=1) / np.sqrt(n_boxes)
    for k, h in enumerate(heights):
        ratios.append({"height": float(h), "simulated": float(mean_ratio[k]), "sem": float(sem[k]),
                       "model": float(model[k]),
                       "error_in_sem": float((mean_ratio[k] - model[k]) / sem[k]),
                       "model_uniform_cells": float(model_cells[k])})
    err = (mean_ratio - model) / sem
    results["accuracy"] = {"quantity": "mean speed_std^2 / mean cup_std^2 over boxes and records "
                                       "(the model's var_lidar / var_point of u)",
                           "boxes": n_boxes, "records_per_box": n_rec, "box_shape": acc_shape,
                           "box_spacing": acc_spacing, "speed": u_acc, "seconds": t_ens,
                           "model_seconds": t_model, "heights": ratios,
                           "max_abs_error_in_sem": float(np.max(np.abs(err))),
                           "mean_error_in_sem": float(np.mean(err)),
                           "mean_relative_error": float(np.mean(np.abs(mean_ratio - model) / model)),
                           "mean_relative_error_uniform_cells_model": float(
                               np.mean(np.abs(mean_ratio - model_cells) / model_cells))}
    print("accuracy: max |sim - model| / sem =", results["accuracy"]["max_abs_error_in_sem"],
          "mean", results["accuracy"]["mean_error_in_sem"])

    out = HERE / "results"
    out.mkdir(exist_ok=True)
    name = "series_quick" if quick else "series"
    (out / f"{name}.json").write_text(json.dumps(results, indent=2))
    write_md(out / f"{name}.md", results)
    try:
        plot(out / f"{name}.png", results)
    except ImportError:
        pass


def write_md(path, r):
    s32, s64 = r["lidarjax"]["float32"], r["lidarjax"]["float64"]
    a = r["accuracy"]
    lines = [f"Windcube V2, {r['setup']['probe']}, 12 heights, 600 LOS per 10-minute record "
             f"({r['setup']['field_samples_per_record']} field samples), {machine_line(r['machine'])}", "",
             "| implementation | records/s | speed-up | one year (52,560 records) |",
             "|---|---|---|---|",
             f"| numpy/scipy (RegularGridInterpolator) | {1 / r['numpy_seconds_per_record']:.2f} | 1 | "
             f"{r['numpy_seconds_per_record'] * RECORDS_PER_YEAR / 3600:.1f} h |",
             f"| numpy with per-point lines (stronger baseline) | "
             f"{1 / r['numpy_lines_seconds_per_record']:.1f} | "
             f"{r['numpy_seconds_per_record'] / r['numpy_lines_seconds_per_record']:.1f}x | "
             f"{r['numpy_lines_seconds_per_record'] * RECORDS_PER_YEAR / 60:.1f} min |"]
    for name, s in (("float32", s32), ("float64", s64)):
        lines.append(f"| lidarjax {name} (chunk {s['chunk']}) | {s['records_per_second']:.1f} | "
                     f"{s['speedup_vs_numpy']:.1f}x ({s['speedup_vs_numpy_lines']:.1f}x the lines "
                     f"baseline) | {s['year_seconds_extrapolated'] / 60:.1f} min |")
    if "year_float32_seconds_measured" in r:
        lines += ["", f"One year measured whole (52,560 records x 12 heights, float32, chunks of 64, "
                      f"compilation included): {r['year_float32_seconds_measured']:.1f} s."]
    lines += ["", "The year column is extrapolated from the measured chunks (median of repeated runs); "
              "the numpy lines baseline's preparation "
              f"({r['numpy_lines_preparation_s']:.2f} s per box) is not counted.",
              f"Max |speed_std difference| lidarjax float64 vs numpy: "
              f"{s64['max_abs_diff_speed_std_vs_numpy']:.1e} m/s.", "",
              f"Statistics against the spectral model: {a['boxes']} exact-spectrum Mann boxes "
              f"{tuple(a['box_shape'])} x {tuple(a['box_spacing'])} m, {a['records_per_box']} "
              f"records each, U = {a['speed']} m/s; simulation {a['seconds']:.0f} s, model "
              f"{a['model_seconds']:.0f} s. Mean |relative error| {100 * a['mean_relative_error']:.1f} %"
              f" (mean error {a['mean_error_in_sem']:+.2f} sem, max {a['max_abs_error_in_sem']:.2f} sem); "
              f"the model with uniform positions in the cells "
              f"(`interpolation=\"trilinear\"`) is off by "
              f"{100 * a['mean_relative_error_uniform_cells_model']:.1f} %.", "",
              "| height (m) | simulated (TI_lidar/TI_cup)^2 | +- sem | spectral model (nodes) | "
              "error / sem | model, uniform cells |",
              "|---|---|---|---|---|---|"]
    for h in a["heights"]:
        lines.append(f"| {h['height']:.0f} | {h['simulated']:.4f} | {h['sem']:.4f} | {h['model']:.4f} | "
                     f"{h['error_in_sem']:+.2f} | {h['model_uniform_cells']:.4f} |")
    Path(path).write_text("\n".join(lines) + "\n")


def plot(path, r):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 4))
    names = ["numpy/scipy", "numpy lines", "lidarjax f32", "lidarjax f64"]
    vals = [1 / r["numpy_seconds_per_record"], 1 / r["numpy_lines_seconds_per_record"],
            r["lidarjax"]["float32"]["records_per_second"],
            r["lidarjax"]["float64"]["records_per_second"]]
    ax.bar(names, vals, color=["grey", "darkgrey", "C0", "C1"])
    ax.set_ylabel("10-minute records per second")
    ax.set_yscale("log")
    ax.set_title("Windcube V2, pulsed, 12 heights")
    acc = r["accuracy"]["heights"]
    h = [a["height"] for a in acc]
    bx.errorbar([a["simulated"] for a in acc], h, xerr=[2 * a["sem"] for a in acc], fmt="o",
                label="simulated (2 sem)")
    bx.plot([a["model"] for a in acc], h, "k-", label="spectral model (nodes)")
    bx.plot([a["model_uniform_cells"] for a in acc], h, "k:", label="model, uniform cells")
    bx.set_xlabel("(TI_lidar / TI_cup)^2")
    bx.set_ylabel("height (m)")
    bx.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    main()
