"""Forward-model throughput: lidarjax against a scipy/numpy pipeline and a numba yardstick.

What it measures, on one (200, 200, 100, 3) gridded field (the hill scene, 10 m x 10 m x
5 m cells) and the same sample points for every implementation:

- **pipeline**: a Windcube V2 scan (5 beams) with the default pulsed probe (the nodes
  `simulate` chooses for this grid's 5 m resolution, `lidarjax.probe_for_field`) at 20
  heights, seen from ``s`` mounts (platform rotations, the "sectors"); N = s x 20 x 5 x q
  samples from about 1e3 to 1e6. Each implementation computes the beam points, samples
  and projects the field, applies the probe weights and the symmetric cut at the lidar,
  reconstructs the wind (DBS) and rotates it to north:
  - lidarjax: `jax.vmap` of `lidarjax.simulate` over the mounts, jit-compiled;
  - scipy: numpy geometry, `scipy.interpolate.RegularGridInterpolator` (linear), numpy
    projection, quadrature and reconstruction;
  - numba: the same numpy geometry and reconstruction around a ``parallel=True`` trilinear
    + projection kernel (the yardstick of a compiled loop on this machine).
- **kernel**: trilinear sampling projected on the beam only (``GridField.los_local`` against
  the numba kernel) on the same points.
- float64 and float32 (the field's dtype); compile time apart (``jax.jit(f).lower(...)
  .compile()``, and numba's first call); medians of several runs.
- reverse-mode gradient of the reported horizontal speeds with respect to the whole field
  (a scatter-add into the grid) relative to the forward pass, and the memory a
  `lidarjax.GridField.crop` to `lidarjax.scan_bounds` saves.
- agreement: the largest absolute LOS difference between the three implementations.

- **target**: the size the project's speed target names: a pulsed probe with 33 nodes,
  180 platform rotations x 50 heights (N = 1.485e6), lidarjax and numba run interleaved on
  the same points (a shared machine's load falls on both alike), medians and load average.

Run ``python benchmarks/forward.py [--quick]`` (needs the ``bench`` extra: numba and
matplotlib); ``--target`` runs only the target size into the existing JSON. Writes
``benchmarks/results/forward.json`` and ``forward.png``.
"""

# ruff: noqa: B023 -- the timing lambdas run inside the loop iteration that defines them
from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numba  # noqa: E402
import numpy as np  # noqa: E402
from _common import machine, median_time  # noqa: E402
from scipy.interpolate import RegularGridInterpolator  # noqa: E402

import lidarjax as lj  # noqa: E402

# numba's OpenMP layer idles badly next to XLA's thread pool on small machines (9 ms for a
# 900-sample call on 2 cores); its own work-queue layer does not.
numba.config.THREADING_LAYER = os.environ.get("NUMBA_THREADING_LAYER", "workqueue")

RESULTS = Path(__file__).resolve().parent / "results"
GRID = (200, 200, 100)
X = np.linspace(-1000.0, 1000.0, GRID[0])
Y = np.linspace(-1000.0, 1000.0, GRID[1])
Z = np.linspace(0.0, 500.0, GRID[2])
HILL = lj.scenes.hill(height=60.0, half_width=300.0, speed=10.0, direction=250.0)
LIDAR = np.array([0.0, 0.0, 62.0])  # on the crest, 2 m above ground
HEIGHTS = np.arange(20.0, 220.0, 10.0)  # 20 heights
SCAN = lj.windcube_v2(28.0)
# the nodes simulate chooses for this grid (its resolution: the 5.05 m vertical spacing)
PROBE = lj.probe_for_spacing(lj.PulsedProbe(), float(Z[1] - Z[0]),
                             HEIGHTS[:, None] / np.asarray(SCAN.directions())[None, :, 2])



def mounts_for(s: int) -> list[lj.Mount]:
    return [lj.Mount(LIDAR, beta=360.0 * k / s, psi=180.0) for k in range(s)]


# -- the numpy geometry shared by the scipy and numba pipelines ------------------------------
def rotation_z(deg):
    """(s, 3, 3) rotations about z by ``deg`` (s,) degrees, anticlockwise from above."""
    t = np.radians(deg)
    c, s_, o, i = np.cos(t), np.sin(t), np.zeros_like(t), np.ones_like(t)
    return np.stack([np.stack([c, -s_, o], -1), np.stack([s_, c, o], -1),
                     np.stack([o, o, i], -1)], -2)


def numpy_setup(mounts, heights=HEIGHTS, probe=PROBE):
    """What the numpy pipelines take as given: mount angles and the probe's nodes."""
    n_lidar = np.asarray(SCAN.directions(), np.float64)
    ranges = heights[:, None] / n_lidar[None, :, 2]
    offsets, weights = (np.asarray(a, np.float64) for a in probe.nodes(jnp.asarray(ranges)))
    angles = {k: np.array([float(getattr(m, k)) for m in mounts])
              for k in ("beta", "gamma", "psi", "epsilon")}
    return dict(n_lidar=n_lidar, ranges=ranges, offsets=offsets, weights=weights, **angles)


def geometry(setup, dtype):
    """Points (s, h, b, q, 3), directions (s, b, 3), kept weights (h, b, q) in numpy."""
    ranges = setup["ranges"]
    offsets = np.broadcast_to(setup["offsets"], ranges.shape + setup["offsets"].shape[-1:])
    keep = np.abs(offsets) < ranges[..., None]  # the symmetric cut at the lidar
    w = np.where(keep, setup["weights"], 0.0)
    w = w / w.sum(-1, keepdims=True)
    rot = rotation_z(setup["beta"] + setup["gamma"] - setup["psi"])  # lidar -> CFD
    dirs = np.einsum("sij,bj->sbi", rot, setup["n_lidar"])
    node_r = ranges[..., None] + offsets  # (h, b, q)
    pts = LIDAR + node_r[None, ..., None] * dirs[:, None, :, None, :]
    return pts.astype(dtype), dirs.astype(dtype), w.astype(dtype)


def reconstruct_v2(los, setup):
    """Windcube V2 DBS in numpy, then the north rotation: (s, h, b) -> (s, h, 3)."""
    c = np.radians(28.0)
    u = (los[..., 1] - los[..., 3]) / (2 * np.sin(c))
    v = (los[..., 0] - los[..., 2]) / (2 * np.sin(c))
    vec = np.stack([u, v, los[..., 4]], -1)
    return np.einsum("sij,shj->shi", rotation_z(-setup["epsilon"]), vec)


def scipy_pipeline(interp, setup, dtype):
    pts, dirs, w = geometry(setup, dtype)
    vel = interp(pts.reshape(-1, 3)).reshape(pts.shape)
    los_q = np.einsum("shbqc,sbc->shbq", vel, dirs)
    los = np.sum(np.where(w > 0, w * los_q, 0.0), -1)
    return los, reconstruct_v2(los, setup)


@numba.njit(parallel=True, fastmath=False, cache=False)
def numba_los(vel, lo, inv, pts, dirs, out):
    """Trilinear velocity at ``pts`` (N, 3) projected on ``dirs`` (N, 3); NaN outside."""
    nx, ny, nz, _ = vel.shape
    for n in numba.prange(pts.shape[0]):
        fx = (pts[n, 0] - lo[0]) * inv[0]
        fy = (pts[n, 1] - lo[1]) * inv[1]
        fz = (pts[n, 2] - lo[2]) * inv[2]
        if not (0 <= fx <= nx - 1 and 0 <= fy <= ny - 1 and 0 <= fz <= nz - 1):
            out[n] = np.nan
            continue
        i = min(int(fx), nx - 2)
        j = min(int(fy), ny - 2)
        k = min(int(fz), nz - 2)
        tx, ty, tz = fx - i, fy - j, fz - k
        dx, dy, dz = dirs[n, 0], dirs[n, 1], dirs[n, 2]

        def proj(a, b, e):
            return (vel[i + a, j + b, k + e, 0] * dx + vel[i + a, j + b, k + e, 1] * dy
                    + vel[i + a, j + b, k + e, 2] * dz)

        c00 = proj(0, 0, 0) + tz * (proj(0, 0, 1) - proj(0, 0, 0))
        c01 = proj(0, 1, 0) + tz * (proj(0, 1, 1) - proj(0, 1, 0))
        c10 = proj(1, 0, 0) + tz * (proj(1, 0, 1) - proj(1, 0, 0))
        c11 = proj(1, 1, 0) + tz * (proj(1, 1, 1) - proj(1, 1, 0))
        c0 = c00 + ty * (c01 - c00)
        c1 = c10 + ty * (c11 - c10)
        out[n] = c0 + tx * (c1 - c0)


@numba.njit(parallel=True, fastmath=False, cache=False)
def numba_beam_los(vel, lo, inv, lidar, dirs, node_r, w, out):
    """The fused yardstick: LOS ``out`` (s, h, b) of probe nodes at ranges ``node_r``
    (h, b, q) with weights ``w`` along ``dirs`` (s, b, 3) from ``lidar``; one loop, no
    intermediate arrays."""
    nx, ny, nz, _ = vel.shape
    ns, nh, nb = out.shape
    nq = node_r.shape[2]
    for sh in numba.prange(ns * nh):
        s = sh // nh
        h = sh % nh
        for b in range(nb):
            dx, dy, dz = dirs[s, b, 0], dirs[s, b, 1], dirs[s, b, 2]
            acc = 0.0
            for q in range(nq):
                if w[h, b, q] == 0:
                    continue
                r = node_r[h, b, q]
                fx = (lidar[0] + r * dx - lo[0]) * inv[0]
                fy = (lidar[1] + r * dy - lo[1]) * inv[1]
                fz = (lidar[2] + r * dz - lo[2]) * inv[2]
                if not (0 <= fx <= nx - 1 and 0 <= fy <= ny - 1 and 0 <= fz <= nz - 1):
                    acc = np.nan
                    continue
                i = min(int(fx), nx - 2)
                j = min(int(fy), ny - 2)
                k = min(int(fz), nz - 2)
                tx, ty, tz = fx - i, fy - j, fz - k
                c = np.zeros(8, vel.dtype)
                m = 0
                for a in range(2):
                    for bb in range(2):
                        for e in range(2):
                            c[m] = (vel[i + a, j + bb, k + e, 0] * dx
                                    + vel[i + a, j + bb, k + e, 1] * dy
                                    + vel[i + a, j + bb, k + e, 2] * dz)
                            m += 1
                c00 = c[0] + tz * (c[1] - c[0])
                c01 = c[2] + tz * (c[3] - c[2])
                c10 = c[4] + tz * (c[5] - c[4])
                c11 = c[6] + tz * (c[7] - c[6])
                c0 = c00 + ty * (c01 - c00)
                c1 = c10 + ty * (c11 - c10)
                acc += w[h, b, q] * (c0 + tx * (c1 - c0))
            out[s, h, b] = acc


def numba_pipeline(vel, lo, inv, setup, dtype):
    """numpy geometry (directions, node ranges, weights: small arrays) around the fused
    numba loop, then numpy DBS."""
    ranges = setup["ranges"]
    offsets = np.broadcast_to(setup["offsets"], ranges.shape + setup["offsets"].shape[-1:])
    keep = np.abs(offsets) < ranges[..., None]
    w = np.where(keep, setup["weights"], 0.0)
    w = (w / w.sum(-1, keepdims=True)).astype(dtype)
    rot = rotation_z(setup["beta"] + setup["gamma"] - setup["psi"])
    dirs = np.einsum("sij,bj->sbi", rot, setup["n_lidar"]).astype(dtype)
    node_r = (ranges[..., None] + offsets).astype(dtype)
    out = np.empty((dirs.shape[0],) + ranges.shape, dtype)
    numba_beam_los(vel, lo, inv, LIDAR.astype(dtype), dirs, node_r, w, out)
    return out, reconstruct_v2(out, setup)


def lidarjax_fn(probe=PROBE):
    def run(field, mounts, heights):
        sims = jax.vmap(
            lambda m: lj.simulate(field, SCAN, m, heights, probe=probe, point_reference=False)
        )(mounts)
        return sims.los, sims.lidar_velocity

    return run


def speed_loss(velocity, field, mounts, heights):
    field = lj.unstack_field(field, velocity)
    sims = jax.vmap(
        lambda m: lj.simulate(field, SCAN, m, heights, probe=PROBE, point_reference=False)
    )(mounts)
    return jnp.nansum(sims.lidar_speed)


# -- the target: 33 nodes, 180 rotations x 50 heights, interleaved with numba -------
TARGET_HEIGHTS = np.arange(20.0, 270.0, 5.0)  # 50 heights
TARGET_SECTORS = 180
TARGET_PROBE = lj.PulsedProbe(n_nodes=33)


def target(field64, repeats):
    """The forward pipeline at the size the project's target names (a pulsed probe with 33
    nodes, 180 platform rotations x 50 heights, N = 1.485e6 samples) against the numba
    yardstick on the same points. The two run interleaved (lidarjax, numba, lidarjax, ...),
    so a shared machine's load falls on both alike; medians, and the load average (1 min)
    before and after."""
    rows = []
    load0 = os.getloadavg()[0]
    mounts = mounts_for(TARGET_SECTORS)
    stacked = lj.stack_mounts(mounts)
    setup = numpy_setup(mounts, TARGET_HEIGHTS, TARGET_PROBE)
    lo = np.array([X[0], Y[0], Z[0]])
    inv = (np.array(GRID) - 1) / np.array([X[-1] - X[0], Y[-1] - Y[0], Z[-1] - Z[0]])
    n = TARGET_SECTORS * TARGET_HEIGHTS.size * SCAN.n_beams * TARGET_PROBE.n_nodes
    for dtype in (np.float64, np.float32):
        vel = np.asarray(field64.velocity).astype(dtype)
        field = lj.GridField(X, Y, Z, jnp.asarray(vel))
        h = jnp.asarray(TARGET_HEIGHTS, dtype)
        lo_d, inv_d = lo.astype(dtype), inv.astype(dtype)
        t = time.perf_counter()
        compiled = jax.jit(lidarjax_fn(TARGET_PROBE)).lower(field, stacked, h).compile()
        compile_s = time.perf_counter() - t
        fj = lambda: jax.block_until_ready(compiled(field, stacked, h))  # noqa: E731
        fn = lambda: numba_pipeline(vel, lo_d, inv_d, setup, dtype)  # noqa: E731
        fj(), fn()
        tj, tn = [], []
        for _ in range(repeats):
            t = time.perf_counter()
            fj()
            tj.append(time.perf_counter() - t)
            t = time.perf_counter()
            fn()
            tn.append(time.perf_counter() - t)
        los_j, los_n = np.asarray(fj()[0]), fn()[0]
        t_j, t_n = float(np.median(tj)), float(np.median(tn))
        rows.append(dict(dtype=np.dtype(dtype).name, sectors=TARGET_SECTORS,
                         heights=int(TARGET_HEIGHTS.size), nodes=TARGET_PROBE.n_nodes, samples=n,
                         compile_s=compile_s, lidarjax_s=t_j, numba_s=t_n,
                         lidarjax_msps=n / t_j / 1e6, numba_msps=n / t_n / 1e6,
                         ratio_vs_numba=t_n / t_j,
                         ratio_runs=[b / a for a, b in zip(tj, tn, strict=True)],
                         max_abs_los_diff_numba=float(np.nanmax(np.abs(los_j - los_n)))))
        r = rows[-1]
        print(f"target {r['dtype']} N={n}: lidarjax {t_j * 1e3:.1f} ms ({r['lidarjax_msps']:.1f} "
              f"M/s), numba {t_n * 1e3:.1f} ms: {r['ratio_vs_numba']:.2f}x numba "
              f"(diff {r['max_abs_los_diff_numba']:.1e})")
    return {"rows": rows, "load_before": load0, "load_after": os.getloadavg()[0],
            "uptime": os.popen("uptime").read().strip()}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="N up to 1e5, 3 repeats (< 1 min)")
    parser.add_argument("--target", action="store_true",
                        help="only the target size (33 nodes, 180 rotations x 50 heights), "
                             "written into the existing forward.json")
    parser.add_argument("--repeats", type=int, default=None, help="timed runs per figure")
    args = parser.parse_args()
    if args.target:
        field64 = lj.GridField.from_function(HILL.sample, X, Y, Z)
        out = target(field64, args.repeats or 11)
        path = RESULTS / "forward.json"
        data = json.loads(path.read_text()) if path.exists() else {}
        data["target"] = out
        data.setdefault("meta", {})["target_machine"] = machine()
        path.write_text(json.dumps(data, indent=1))
        print(f"load {out['load_before']:.1f} -> {out['load_after']:.1f}; wrote {path}")
        return
    sectors = [1, 11, 111] if args.quick else [1, 11, 111, 1111]
    repeats = args.repeats or (3 if args.quick else 7)
    per_sector = HEIGHTS.size * SCAN.n_beams * PROBE.n_nodes

    t0 = time.perf_counter()
    field64 = lj.GridField.from_function(HILL.sample, X, Y, Z)
    vel64 = np.asarray(field64.velocity)
    lo = np.array([X[0], Y[0], Z[0]])
    inv = (np.array(GRID) - 1) / np.array([X[-1] - X[0], Y[-1] - Y[0], Z[-1] - Z[0]])
    print(f"field {GRID} built in {time.perf_counter() - t0:.1f} s")

    rows = []
    for dtype in (np.float64, np.float32):
        name = np.dtype(dtype).name
        vel = vel64.astype(dtype)
        field = lj.GridField(X, Y, Z, jnp.asarray(vel))
        interp = RegularGridInterpolator((X, Y, Z), vel, bounds_error=False, fill_value=np.nan)
        lo_d, inv_d = lo.astype(dtype), inv.astype(dtype)
        t = time.perf_counter()
        numba_los(vel, lo_d, inv_d, np.zeros((2, 3), dtype), np.ones((2, 3), dtype),
                  np.empty(2, dtype))
        numba_pipeline(vel, lo_d, inv_d, numpy_setup(mounts_for(1)), dtype)
        numba_compile = time.perf_counter() - t
        run = jax.jit(lidarjax_fn())
        kernel = jax.jit(lambda f, p, d: f.los_local(p - f.origin, d))
        grad = jax.jit(jax.grad(speed_loss))
        for s in sectors:
            n = s * per_sector
            mounts = mounts_for(s)
            stacked = lj.stack_mounts(mounts)
            setup = numpy_setup(mounts)
            h = jnp.asarray(HEIGHTS, dtype)
            t = time.perf_counter()
            compiled = run.lower(field, stacked, h).compile()
            compile_s = time.perf_counter() - t
            t_jax = median_time(lambda: jax.block_until_ready(compiled(field, stacked, h)),
                                repeats)
            los_j, vec_j = (np.asarray(a) for a in compiled(field, stacked, h))
            sci_repeats = max(1, repeats if n <= 1e5 else 2)
            t_sci = median_time(lambda: scipy_pipeline(interp, setup, dtype), sci_repeats)
            los_s, _ = scipy_pipeline(interp, setup, dtype)
            t_nb = median_time(lambda: numba_pipeline(vel, lo_d, inv_d, setup, dtype), repeats)
            los_n, _ = numba_pipeline(vel, lo_d, inv_d, setup, dtype)
            # kernel only, same points
            pts, dirs, _ = geometry(setup, dtype)
            d = np.ascontiguousarray(
                np.broadcast_to(dirs[:, None, :, None, :], pts.shape).reshape(-1, 3))
            p = np.ascontiguousarray(pts.reshape(-1, 3))
            pj, dj = jnp.asarray(p), jnp.asarray(d)
            out = np.empty(p.shape[0], dtype)
            t_kj = median_time(lambda: kernel(field, pj, dj).block_until_ready(), repeats)
            t_kn = median_time(lambda: numba_los(vel, lo_d, inv_d, p, d, out), repeats)
            k_diff = float(np.nanmax(np.abs(np.asarray(kernel(field, pj, dj)) - out)))
            row = dict(
                dtype=name, sectors=s, samples=n, compile_s=compile_s,
                lidarjax_s=t_jax, scipy_s=t_sci, numba_s=t_nb,
                lidarjax_msps=n / t_jax / 1e6, scipy_msps=n / t_sci / 1e6,
                numba_msps=n / t_nb / 1e6,
                kernel_lidarjax_msps=n / t_kj / 1e6, kernel_numba_msps=n / t_kn / 1e6,
                speedup_vs_scipy=t_sci / t_jax, ratio_vs_numba=t_nb / t_jax,
                kernel_ratio_vs_numba=t_kn / t_kj,
                max_abs_los_diff_scipy=float(np.nanmax(np.abs(los_j - los_s))),
                max_abs_los_diff_numba=float(np.nanmax(np.abs(los_j - los_n))),
                max_abs_kernel_diff_numba=k_diff,
                nan_los=int(np.isnan(los_j).sum()),
                numba_compile_s=numba_compile,
            )
            if dtype == np.float64:
                t = time.perf_counter()
                gcomp = grad.lower(field.velocity, field, stacked, h).compile()
                row["grad_compile_s"] = time.perf_counter() - t
                t_g = median_time(
                    lambda: gcomp(field.velocity, field, stacked, h).block_until_ready(),
                    max(1, repeats // 2))
                row["grad_s"] = t_g
                row["grad_over_forward"] = t_g / t_jax
                # the same gradient on the field cropped to the scan: the dense cotangent of
                # the whole grid (zeroing 96 MB, then a scatter-add) is what costs
                small = field.crop(*lj.scan_bounds(SCAN, stacked, HEIGHTS, PROBE,
                                                   point_reference=False))
                gsmall = grad.lower(small.velocity, small, stacked, h).compile()
                t_gs = median_time(
                    lambda: gsmall(small.velocity, small, stacked, h).block_until_ready(),
                    max(1, repeats // 2))
                row["grad_cropped_s"] = t_gs
                row["grad_cropped_over_forward"] = t_gs / t_jax
            rows.append(row)
            print(
                f"{name} N={n:>8d}  lidarjax {row['lidarjax_msps']:6.1f}  scipy "
                f"{row['scipy_msps']:5.2f}  numba {row['numba_msps']:6.1f} Msamples/s  "
                f"(x{row['speedup_vs_scipy']:.0f} scipy, {row['ratio_vs_numba']:.2f} numba; "
                f"kernel {row['kernel_lidarjax_msps']:.1f} vs {row['kernel_numba_msps']:.1f}) "
                f"compile {compile_s:.2f} s  diff {row['max_abs_los_diff_scipy']:.1e}/"
                f"{row['max_abs_los_diff_numba']:.1e}"
                + (f"  grad x{row['grad_over_forward']:.1f} (cropped "
                   f"x{row['grad_cropped_over_forward']:.1f})" if "grad_s" in row else "")
            )

    # memory a crop saves
    one = lj.scan_bounds(SCAN, mounts_for(1)[0], HEIGHTS, PROBE, point_reference=True)
    every = lj.scan_bounds(SCAN, mounts_for(max(sectors)), HEIGHTS, PROBE)
    crop = {
        "full_bytes": field64.nbytes,
        "one_mount_bytes": field64.crop(*one).nbytes,
        "one_mount_shape": list(field64.crop(*one).shape),
        "all_sectors_bytes": field64.crop(*every).nbytes,
        "all_sectors_shape": list(field64.crop(*every).shape),
    }
    crop["saving_one_mount"] = 1 - crop["one_mount_bytes"] / crop["full_bytes"]
    crop["saving_all_sectors"] = 1 - crop["all_sectors_bytes"] / crop["full_bytes"]
    print(f"crop: {crop['full_bytes'] / 1e6:.1f} MB -> {crop['one_mount_bytes'] / 1e6:.2f} MB "
          f"(one mount), {crop['all_sectors_bytes'] / 1e6:.2f} MB (all sectors)")

    RESULTS.mkdir(exist_ok=True)
    meta = dict(
        grid=list(GRID), heights=HEIGHTS.size, beams=SCAN.n_beams, nodes=PROBE.n_nodes,
        repeats=repeats, quick=args.quick, machine=machine(), numba=numba.__version__,
        numba_threads=numba.get_num_threads(),
    )
    out = target(field64, max(repeats, 5))
    with open(RESULTS / "forward.json", "w") as fh:
        json.dump({"meta": meta, "rows": rows, "crop": crop, "target": out}, fh, indent=1)
    plot(rows, RESULTS / "forward.png")
    print(f"wrote {RESULTS / 'forward.json'} and forward.png")


def plot(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.2))
    colours = {"lidarjax": "C0", "scipy": "C1", "numba": "C2"}
    for dtype, style in (("float64", "-"), ("float32", "--")):
        sel = [r for r in rows if r["dtype"] == dtype]
        n = [r["samples"] for r in sel]
        for impl in ("lidarjax", "scipy", "numba"):
            ax.loglog(n, [r[f"{impl}_msps"] for r in sel], style, marker="o",
                      color=colours[impl], label=f"{impl} {dtype}")
        for impl in ("lidarjax", "numba"):
            bx.loglog(n, [r[f"kernel_{impl}_msps"] for r in sel], style, marker="o",
                      color=colours[impl], label=f"{impl} {dtype}")
    ax.set(xlabel="samples N (heights x beams x nodes x sectors)", ylabel="M samples / s",
           title="forward pipeline (V2, pulsed probe, DBS)")
    bx.set(xlabel="samples N", ylabel="M samples / s", title="kernel: trilinear + projection")
    for a in (ax, bx):
        a.grid(True, which="both", alpha=0.3)
        a.legend(fontsize=7)
    fig.suptitle(f"(200, 200, 100, 3) field, {os.cpu_count()} CPU cores, medians")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    main()
