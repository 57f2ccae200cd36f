"""Benchmark: numerical stability of lidarjax in float32 and float64, near its limits.

What it measures (every number is written to benchmarks/results/stability.{json,md,png};
``--quick`` writes stability_quick.* with fewer samples):

- **Condition (cone angle).** For DBS (Windcube V1), the Windcube V2 and the 50-beam sine fit
  (ZephIR), at cone angles from 0.01 to 80 degrees: the beam-matrix condition number (SVD
  against the closed forms of `lidarjax.scan`); the rms error of the reconstructed horizontal
  wind under LOS noise of 0.1 m/s (Monte Carlo) against the prediction
  ``cond sigma / (sqrt(K) cos c)``; and the rounding error of `lidarjax.simulate` in a
  uniform wind (exact answer known) in float32 and float64.
- **Speed.** A platform (potential flow over a 20 m hemisphere, a Windcube V2 on its flank)
  at free-stream speeds from 0 to 60 m/s and 36 directions: float32 against float64 for the
  LOS, the reconstructed speed and direction, and the speed and direction from
  `lidarjax.invert` (each precision with its own response table).
- **Coordinate offset.** A constant-gradient flow gridded at 2 m (trilinear interpolation
  reproduces it exactly, so the exact LOS is known) at easting/northing offsets from 0 to
  6e6 m: the LOS, speed and direction errors of lidarjax in float64 and float32 (coordinates
  kept relative to the grid origin, lidar location as a hi/lo pair) against a naive float32
  trilinear interpolation on absolute coordinates, written here as the baseline.
- **Gradient finiteness.** Random valid configurations (speeds 0 to 60 m/s with exact 0,
  every direction with exact 0/90/180/270/360, cone angles 5 to 60 degrees, arbitrary
  angles, heights from 3 cm) of three scenes at UTM coordinates (power-law shear; a 0.35 m
  model-scale hemisphere with the lidar 1-5 cm above its deck or flank; the same platform
  gridded, with solid nodes) with point, pulsed and CW probes: how many configurations give
  outputs that are finite or NaN with an explaining flag, and finite gradients of a loss
  that masks NaN results out, with respect to every input.
- **Inverse failure rates per case.** `lidarjax.invert` on records with LOS noise 0.1 m/s:
  clean, zero speed, one or two missing beams, one wild beam (+-50 m/s), all beams equal,
  all beams missing; mixed in one batch. Converged share, reasons for NaN, errors and
  uncertainties, step counts, and whether any clean record differs from an all-clean batch.

Run from a checkout: ``python benchmarks/stability.py [--quick]`` (quick: under a minute on
two cores; full: a few minutes).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # benchmark this checkout, not an installed copy

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _common import machine, machine_line  # noqa: E402
from scipy import stats  # noqa: E402

import lidarjax as lj  # noqa: E402
from lidarjax.angles import heading  # noqa: E402
from lidarjax.flags import InverseFlag  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"
F32, F64 = np.float32, np.float64
NOISE = 0.1  # LOS noise, m/s


def wrap(a):
    return np.asarray(lj.wrap180(np.asarray(a, np.float64)))


def nanmax(a):
    a = np.asarray(a, np.float64)
    return float(np.nanmax(a)) if np.any(np.isfinite(a)) else float("nan")


# -------------------------------------------------------------------------------------------
# A. error against the condition number (cone angle)

SCANS = {
    "DBS (V1)": (lambda c: lj.windcube_v1(c), 4),
    "Windcube V2": (lambda c: lj.windcube_v2(c), 4),
    "sine fit (50 beams)": (lambda c: lj.zephir(c, 50), 50),
}
WIND = np.array([-9.4, -3.4, 0.5])  # about 10 m/s from 250 degrees, 0.5 m/s updraught


def cond_formula(name, c):
    c = np.radians(c)
    if name == "Windcube V2":
        r = (4 * np.cos(c) ** 2 + 1) / (2 * np.sin(c) ** 2)
        return np.sqrt(np.maximum(r, 1 / r))
    t = np.tan(c)
    return np.maximum(np.sqrt(2) / t, t / np.sqrt(2))


def noise_prediction(name, c, k):
    """rms of one reconstructed horizontal component under LOS noise NOISE."""
    s = np.sin(np.radians(c))
    return NOISE * np.sqrt(2.0 / k) / s


def conditioning(quick):
    cones = (np.array([0.01, 0.1, 1.0, 5.0, 30.0, 60.0]) if quick else
             np.array([0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 15.0, 20.0, 28.0,
                       30.0, 45.0, 54.74, 60.0, 70.0, 80.0]))
    n_draws = 2000 if quick else 20000
    rng = np.random.default_rng(0)
    rows = []
    for name, (make, k) in SCANS.items():
        sims = {}
        for dtype in (F64, F32):
            scene = lj.scenes.Uniform(jnp.zeros(3, dtype), jnp.zeros(3, dtype),
                                      jnp.asarray(np.hypot(*WIND[:2]), dtype),
                                      jnp.asarray(float(lj.wind_direction(WIND)), dtype),
                                      jnp.asarray(WIND[2], dtype))

            def one(c, scene=scene, make=make, dtype=dtype):
                return lj.simulate(scene, make(c), lj.Mount([0.0, 0.0, 0.0]),
                                   jnp.array([40.0], dtype), point_reference=False)

            sims[dtype] = jax.jit(jax.vmap(one))(jnp.asarray(cones, dtype))
        for i, c in enumerate(cones):
            scan = make(float(c))
            los = np.asarray(scan.directions()) @ WIND
            noisy = los + NOISE * rng.standard_normal((n_draws, los.size))
            err = np.asarray(lj.reconstruct(scan, jnp.asarray(noisy)))[:, :2] - WIND[:2]
            row = dict(scan=name, cone_deg=float(c), beams=scan.n_beams,
                       cond_svd=float(scan.condition_number()),
                       cond_formula=float(cond_formula(name, c)),
                       noise_rms_ms=float(np.sqrt(np.mean(err**2))),
                       noise_rms_predicted_ms=float(noise_prediction(name, c, k)))
            for dtype in (F64, F32):
                sim = sims[dtype]
                v = np.asarray(sim.lidar_velocity[i, 0], np.float64)
                flags = int(sim.flags[i, 0])
                row[f"rounding_{np.dtype(dtype).name}_ms"] = float(np.max(np.abs(v[:2] - WIND[:2])))
                row[f"ill_conditioned_{np.dtype(dtype).name}"] = bool(
                    flags & lj.Flag.ILL_CONDITIONED)
            rows.append(row)
    refused = {}
    for name, (make, _) in SCANS.items():
        try:
            make(0.005)
        except ValueError as e:
            refused[name] = str(e)
    return dict(noise_ms=NOISE, draws=n_draws, rows=rows, refused_at_0_005_deg=refused,
                thresholds=dict(ILL_CONDITIONED=lj.scan.ILL_CONDITIONED,
                                MAX_CONDITION=lj.scan.MAX_CONDITION))


# -------------------------------------------------------------------------------------------
# B. float32 against float64 over speed, forward and inverse

RADIUS = 20.0
HEIGHTS = (5.0, 10.0, 20.0, 40.0, 80.0)
SITE_MOUNT = lj.Mount([12.0, -4.0, float(np.sqrt(RADIUS**2 - 160.0))], epsilon=10.0)


def site_simulations(directions, speeds, dtype):
    @jax.jit
    def run(d, u):
        def one(d, u):
            scene = lj.scenes.Hemisphere(jnp.zeros(3, dtype), jnp.zeros(3, dtype),
                                         jnp.asarray(RADIUS, dtype), u.astype(dtype),
                                         d.astype(dtype))
            return lj.simulate(scene, lj.windcube_v2(), SITE_MOUNT,
                               jnp.asarray(HEIGHTS, dtype), u_ref=u * heading(d))
        return jax.vmap(one)(d, u)

    return run(jnp.asarray(directions, F64), jnp.asarray(speeds, F64))


def speed_sweep(quick):
    speeds = (np.array([0.0, 1e-3, 0.1, 1.0, 10.0, 60.0]) if quick else
              np.array([0.0, 1e-4, 1e-3, 0.01, 0.1, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 40.0, 60.0]))
    n_dir = 12 if quick else 36
    rng = np.random.default_rng(1)
    dirs = rng.uniform(0.0, 360.0, n_dir)
    d_all = np.tile(dirs, speeds.size)
    u_all = np.repeat(speeds, n_dir)
    knots = np.arange(0.0, 360.0, 10.0)
    out = {}
    for dtype in (F64, F32):
        sims = site_simulations(d_all, u_all, dtype)
        tab = lj.ResponseTable.from_simulations(
            site_simulations(knots, np.full(knots.shape, 10.0), dtype))
        inv = lj.invert(tab, sims.los)
        out[dtype] = (sims, inv)
    (s64, i64), (s32, i32) = out[F64], out[F32]
    truth_dir = np.mod(d_all + 10.0, 360.0)  # north frame: CFD + epsilon
    rows = []
    for j, u in enumerate(speeds):
        m = slice(j * n_dir, (j + 1) * n_dir)
        los_err = np.abs(np.asarray(s32.los[m], F64) - np.asarray(s64.los[m]))
        row = dict(speed_ms=float(u), los_abs_ms=nanmax(los_err))
        if u > 0:
            sp64, sp32 = np.asarray(s64.lidar_speed[m]), np.asarray(s32.lidar_speed[m], F64)
            row["lidar_speed_rel"] = nanmax(np.abs(sp32 / sp64 - 1))
            row["lidar_direction_deg"] = nanmax(np.abs(wrap(np.asarray(
                s32.lidar_direction[m], F64) - np.asarray(s64.lidar_direction[m]))))
            row["invert_speed_rel_f32_vs_f64"] = nanmax(np.abs(
                np.asarray(i32.speed[m], F64) / np.asarray(i64.speed[m]) - 1))
            row["invert_direction_deg_f32_vs_f64"] = nanmax(np.abs(wrap(
                np.asarray(i32.direction[m], F64) - np.asarray(i64.direction[m]))))
            for name, inv in (("f64", i64), ("f32", i32)):
                row[f"invert_speed_rel_vs_truth_{name}"] = nanmax(
                    np.abs(np.asarray(inv.speed[m], F64) / u - 1))
                row[f"invert_direction_deg_vs_truth_{name}"] = nanmax(np.abs(wrap(
                    np.asarray(inv.direction[m], F64) - truth_dir[m][:, None])))
        row["converged_f64"] = float(np.mean(i64.converged[m]))
        row["converged_f32"] = float(np.mean(i32.converged[m]))
        row["calm_flag_f32"] = float(np.mean((np.asarray(s32.flags[m]) & lj.Flag.CALM) != 0))
        rows.append(row)
    return dict(directions=int(n_dir), heights_m=list(HEIGHTS), table_sector_deg=10.0,
                rows=rows)


# -------------------------------------------------------------------------------------------
# C. coordinate offset: lidarjax float32/float64 against a naive float32 trilinear

GRAD = np.array([[0.02, -0.03, 0.01], [0.04, 0.01, -0.02], [0.0, 0.0, 0.005]])  # 1/s
V0 = np.array([-8.0, -4.0, 0.3])
LOCAL_AXES = (np.linspace(-60.0, 60.0, 61), np.linspace(-60.0, 60.0, 61),
              np.linspace(0.0, 80.0, 41))
LIDAR_LOCAL = np.array([1.234567, -2.345678, 2.5])
OFFSET_HEIGHTS = np.array([10.0, 20.0, 40.0, 60.0, 70.0])


def linear_velocity(local):
    return V0 + local @ GRAD.T


def naive_trilinear_los(vel, x0, inv_dx, n, pts, dirs):
    """The baseline: float32 trilinear interpolation on absolute float32 coordinates."""
    f = (pts - x0) * inv_dx  # float32 throughout: the absolute coordinates lose the digits
    i = np.clip(np.floor(f).astype(np.int64), 0, np.array(n) - 2)
    t = (f - i.astype(f.dtype))[..., None]
    out = 0.0
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                w = ((t[..., 0, :] if dx else 1 - t[..., 0, :])
                     * (t[..., 1, :] if dy else 1 - t[..., 1, :])
                     * (t[..., 2, :] if dz else 1 - t[..., 2, :]))
                out = out + w * vel[i[..., 0] + dx, i[..., 1] + dy, i[..., 2] + dz]
    return np.sum(out * dirs, axis=-1)


def offset_sweep(quick):
    offsets = ([0.0, 1e4, 1e6, 6e6] if quick else
               [0.0, 1e2, 1e3, 1e4, 1e5, 5e5, 1e6, 3e6, 6e6, 1e7])
    scan = lj.windcube_v2()
    mesh = np.stack(np.meshgrid(*LOCAL_AXES, indexing="ij"), -1)
    vel64 = linear_velocity(mesh)
    n_lidar = np.asarray(scan.directions(), F64)
    ranges = OFFSET_HEIGHTS[:, None] / n_lidar[None, :, 2]
    exact_pts = LIDAR_LOCAL + ranges[..., None] * n_lidar  # lidar frame = CFD frame here
    exact_los = np.sum(linear_velocity(exact_pts) * n_lidar, -1)
    exact_vec = np.asarray(lj.reconstruct(scan, jnp.asarray(exact_los)))
    exact_speed = np.hypot(exact_vec[:, 0], exact_vec[:, 1])
    exact_dir = np.asarray(lj.wind_direction(exact_vec))
    run = jax.jit(lambda f, m, h: lj.simulate(f, scan, m, h, point_reference=False))
    scan32 = lj.Scan(np.asarray(scan.azimuths, F32), np.float32(scan.cone_angle),
                     vertical=True, method="windcube_v2")
    rows = []

    def errors(los, vec):
        vec = np.asarray(vec, F64)
        sp = np.hypot(vec[:, 0], vec[:, 1])
        return dict(los_abs_ms=float(np.max(np.abs(np.asarray(los, F64) - exact_los))),
                    speed_rel=float(np.max(np.abs(sp / exact_speed - 1))),
                    direction_deg=float(np.max(np.abs(wrap(
                        np.asarray(lj.wind_direction(vec)) - exact_dir)))))

    for off in offsets:
        shift = np.array([off, off, 0.0])
        axes = [a + s for a, s in zip(LOCAL_AXES, shift, strict=True)]
        loc = LIDAR_LOCAL + shift
        row = dict(offset_m=off)
        for dtype in (F64, F32):
            field = lj.GridField(*axes, jnp.asarray(vel64, dtype))
            sim = run(field, lj.Mount(loc), jnp.asarray(OFFSET_HEIGHTS, dtype))
            row[f"lidarjax_{np.dtype(dtype).name}"] = errors(sim.los, sim.lidar_velocity)
        # the naive float32 pipeline: absolute float32 coordinates everywhere
        x0 = np.array([a[0] for a in axes], F32)
        inv_dx = np.array([(a.size - 1) / (a[-1] - a[0]) for a in axes], F32)
        n32 = n_lidar.astype(F32)
        pts = loc.astype(F32) + ranges.astype(F32)[..., None] * n32
        los = naive_trilinear_los(vel64.astype(F32), x0, inv_dx, vel64.shape[:3], pts,
                                  np.broadcast_to(n32, pts.shape))
        vec = np.asarray(lj.reconstruct(scan32, jnp.asarray(los.astype(F32))))
        row["naive_float32"] = errors(los, vec)
        rows.append(row)
    return dict(grid_spacing_m=2.0, gradient_per_s=GRAD.tolist(), heights_m=OFFSET_HEIGHTS.tolist(),
                rows=rows)


# -------------------------------------------------------------------------------------------
# D. gradient finiteness over random configurations

UTM = np.array([512_345.678, 6_123_456.789, 3.0])
MODEL_R = 0.35
EXPLAINS_NAN = (lj.Flag.CALM | lj.Flag.RATIO_UNDEFINED | lj.Flag.BEAM_OUTSIDE
                | lj.Flag.POINT_OUTSIDE)
PROBES = {"point": lj.PointProbe(), "pulsed": lj.PulsedProbe(n_nodes=4),
          "cw": lj.CWProbe()}
GRID_AXES = tuple(UTM[a] + np.linspace(lo, hi, 25)
                  for a, (lo, hi) in enumerate(((-1.2, 1.2), (-1.2, 1.2), (0.0, 2.4))))


def masked_total(sim):
    total = 0.0
    for name in ("los", "lidar_velocity", "point_velocity", "free_velocity", "cff_u", "cff_v",
                 "cff_w", "cff_U", "cff_th", "cfp_u", "cfp_v", "cfp_w", "cfp_U", "cfp_th"):
        leaf = getattr(sim, name)
        total = total + jnp.sum(jnp.where(jnp.isfinite(leaf), leaf, 0.0))
    total = total + jnp.sum(jnp.nan_to_num(lj.wind_direction(sim.lidar_velocity)))
    return total + jnp.sum(lj.horizontal_speed(jnp.nan_to_num(sim.lidar_velocity)))


def make_config(scene_name, probe_name, dtype):
    probe = PROBES[probe_name]
    model = scene_name != "power law"
    if model and probe_name != "point":
        probe = probe.scaled(100.0)
    unit = None
    if scene_name == "gridded platform":
        unit = np.asarray(lj.GridField.from_function(
            lj.scenes.hemisphere(MODEL_R, 1.0, 0.0, centre=UTM).sample, *GRID_AXES).velocity)
    solid = None if unit is None else np.isnan(unit)

    def run(p):
        speed, direction, cone, beta, gamma, psi, eps = (p[i] for i in range(7))
        heights, loc = p[7:10].astype(dtype), p[10:13]
        if scene_name == "power law":
            field = lj.scenes.PowerLaw(jnp.asarray(UTM, dtype), jnp.zeros(3, dtype),
                                       speed.astype(dtype), jnp.asarray(100.0, dtype),
                                       jnp.asarray(0.14, dtype), direction.astype(dtype),
                                       jnp.asarray(0.02, dtype))
            u_ref = speed * heading(direction)
        elif scene_name == "model platform":
            field = lj.scenes.Hemisphere(jnp.asarray(UTM, dtype), jnp.zeros(3, dtype),
                                         jnp.asarray(MODEL_R, dtype), speed.astype(dtype),
                                         direction.astype(dtype))
            u_ref = speed * heading(direction)
        else:
            vel = jnp.where(solid, jnp.nan, speed * jnp.where(solid, 0.0, unit))
            field = lj.GridField(*GRID_AXES, vel.astype(dtype))
            u_ref = speed * heading(0.0)
        scan = lj.Scan(jnp.array([0.0, 90.0, 180.0, 270.0]), cone, vertical=True,
                       method="windcube_v2")
        mount = lj.Mount(jnp.asarray(UTM) + loc, beta, gamma, psi, eps)
        return lj.simulate(field, scan, mount, heights, u_ref=u_ref, probe=probe)

    def f(p):
        sim = run(p)
        return masked_total(sim), sim

    return jax.jit(jax.value_and_grad(f, has_aux=True))


def sample_config(rng, scene_name):
    speed = 0.0 if rng.random() < 0.15 else rng.uniform(0.0, 60.0)
    direction = (rng.choice([0.0, 90.0, 180.0, 270.0, 360.0]) if rng.random() < 0.3
                 else rng.uniform(0.0, 360.0))
    cone = rng.uniform(5.0, 60.0)
    angles = rng.uniform(-360.0, 360.0, 4)
    if scene_name == "power law":
        heights = rng.uniform(0.03, 300.0, 3)
        loc = np.array([rng.uniform(-100, 100), rng.uniform(-100, 100), rng.uniform(0, 50)])
    else:
        heights = rng.uniform(0.03, 3.0 if scene_name == "model platform" else 1.5, 3)
        rho, theta = rng.uniform(0.0, 0.33), rng.uniform(0.0, 2 * np.pi)
        loc = np.array([rho * np.cos(theta), rho * np.sin(theta),
                        np.sqrt(MODEL_R**2 - rho**2) + rng.uniform(0.01, 0.05)])
    return np.concatenate([[speed, direction, cone], angles, heights, loc])


def finite_or_explained(sim):
    flags = np.asarray(sim.flags)
    explained = (flags & EXPLAINS_NAN) != 0
    ok = True
    for name in ("los", "lidar_velocity", "point_velocity", "cff_u", "cff_v", "cff_U",
                 "cff_th", "cfp_u", "cfp_v", "cfp_w", "cfp_U", "cfp_th"):
        v = np.asarray(getattr(sim, name)).reshape(flags.shape[0], -1)
        ok &= not np.any(np.isinf(v)) and bool(np.all(np.isfinite(v[~explained])))
    return ok, bool(np.any(explained))


def gradients(quick):
    n = 15 if quick else 120
    scenes = ("power law", "model platform", "gridded platform")
    configs = ([(s, "pulsed", F32) for s in scenes] if quick else
               [(s, p, d) for s in scenes for p in PROBES for d in (F64, F32)])
    rng = np.random.default_rng(2)
    rows = []
    for scene_name, probe_name, dtype in configs:
        fn = make_config(scene_name, probe_name, dtype)
        counts = dict(samples=0, outputs_ok=0, gradients_finite=0, with_flagged_nan=0)
        for _ in range(n):
            p = jnp.asarray(sample_config(rng, scene_name))
            (_, sim), g = fn(p)
            ok, flagged = finite_or_explained(sim)
            counts["samples"] += 1
            counts["outputs_ok"] += int(ok)
            counts["gradients_finite"] += int(bool(np.all(np.isfinite(np.asarray(g)))))
            counts["with_flagged_nan"] += int(flagged)
        rows.append(dict(scene=scene_name, probe=probe_name, dtype=np.dtype(dtype).name,
                         **counts))
    return dict(inputs=15, rows=rows)


# -------------------------------------------------------------------------------------------
# E. inverse failure rates per case

CASES = ("clean", "zero speed", "1 beam missing", "2 beams missing", "wild beam (+-50 m/s)",
         "all beams equal", "all beams missing")


def inverse_cases(quick):
    per_case = 128 if quick else 1024
    knots = np.arange(0.0, 360.0, 10.0)
    rng = np.random.default_rng(3)
    n = per_case * len(CASES)
    dirs = rng.uniform(0.0, 360.0, n)
    speeds = rng.uniform(0.5, 25.0, n)
    kind = np.repeat(np.arange(len(CASES)), per_case)
    rng.shuffle(kind)  # the cases mixed in one batch
    out = dict(records_per_case=per_case, noise_ms=NOISE, rows=[])
    for dtype in (F64, F32):
        tab = lj.ResponseTable.from_simulations(
            site_simulations(knots, np.full(knots.shape, 10.0), dtype))
        sims = site_simulations(dirs, np.where(kind == 1, 0.0, speeds), dtype)
        clean = np.asarray(sims.los, F64) + NOISE * rng.standard_normal(sims.los.shape)
        los = clean.copy()
        nb = los.shape[-1]
        for i in range(n):
            k = CASES[kind[i]]
            beams = rng.choice(nb, 2, replace=False)
            if k == "1 beam missing":
                los[i][:, beams[0]] = np.nan
            elif k == "2 beams missing":
                los[i][:, beams] = np.nan
            elif k.startswith("wild"):
                los[i][:, beams[0]] += rng.choice([-50.0, 50.0])
            elif k == "all beams equal":
                los[i] = rng.uniform(-20.0, 20.0)
            elif k == "all beams missing":
                los[i] = np.nan
        inv = lj.invert(tab, jnp.asarray(los, dtype))
        ref = lj.invert(tab, jnp.asarray(clean, dtype))  # the same batch, every record clean
        conv = np.asarray(inv.converged)
        flags = np.asarray(inv.flags)
        truth_dir = np.mod(dirs + 10.0, 360.0)
        for c, name in enumerate(CASES):
            m = kind == c
            cv, fl = conv[m], flags[m]
            row = dict(case=name, dtype=np.dtype(dtype).name, problems=int(cv.size),
                       converged=float(cv.mean()),
                       calm=float(np.mean(cv & ((fl & InverseFlag.CALM) != 0))),
                       nan_too_few_beams=float(np.mean(~cv & ((fl & InverseFlag.TOO_FEW_BEAMS) != 0))),
                       nan_ill_conditioned=float(np.mean(~cv & ((fl & InverseFlag.ILL_CONDITIONED) != 0))),
                       nan_not_converged=float(np.mean(~cv & ((fl & InverseFlag.NOT_CONVERGED) != 0))),
                       infinite_outputs=int(np.sum(np.isinf(np.asarray(inv.speed)[m]))),
                       max_steps=int(np.asarray(inv.num_steps)[m].max()),
                       mean_steps=float(np.asarray(inv.num_steps)[m].mean()))
            s = np.asarray(inv.speed, F64)[m]
            if name not in ("zero speed", "all beams equal", "all beams missing"):
                u = speeds[m][:, None]
                e = np.abs(s / u - 1)
                std = np.asarray(inv.speed_std, F64)[m] / u
                ed = np.abs(wrap(np.asarray(inv.direction, F64)[m] - truth_dir[m][:, None]))
                # the noise is estimated from n_beams - 2 spare beams: the error over the
                # standard deviation follows Student's t with that many degrees of freedom
                dof = np.asarray(inv.n_beams)[m] - 2
                expected = 2 * stats.t.cdf(3.0, np.maximum(dof, 1)) - 1
                row.update(speed_err_median=float(np.nanmedian(e)),
                           speed_std_median=float(np.nanmedian(std)),
                           direction_err_median_deg=float(np.nanmedian(ed)),
                           within_3_std=float(np.mean(e[cv] < 3 * std[cv])),
                           within_3_std_student_t=float(np.mean(expected[cv])))
            else:
                row.update(speed_median_ms=float(np.nanmedian(s)) if np.any(np.isfinite(s))
                           else float("nan"),
                           speed_std_median_ms=float(np.nanmedian(np.asarray(inv.speed_std,
                                                                             F64)[m]))
                           if np.any(cv) else float("nan"))
            out["rows"].append(row)
        c0 = kind == 0
        out[f"clean_records_changed_by_neighbours_{np.dtype(dtype).name}"] = int(np.sum(
            np.asarray(inv.speed)[c0] != np.asarray(ref.speed)[c0]))
    return out


# -------------------------------------------------------------------------------------------


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer samples (under a minute)")
    quick = parser.parse_args().quick
    t0 = time.perf_counter()
    out = dict(quick=quick, machine=machine(), lidarjax=lj.__version__)
    for key, fn in (("conditioning", conditioning), ("speed", speed_sweep),
                    ("offset", offset_sweep), ("gradients", gradients),
                    ("inverse", inverse_cases)):
        t = time.perf_counter()
        out[key] = fn(quick)
        out[key]["seconds"] = time.perf_counter() - t
        print(f"{key}: {out[key]['seconds']:.1f} s", flush=True)
    out["seconds"] = time.perf_counter() - t0
    RESULTS.mkdir(parents=True, exist_ok=True)
    suffix = "_quick" if quick else ""
    (RESULTS / f"stability{suffix}.json").write_text(json.dumps(out, indent=2))
    (RESULTS / f"stability{suffix}.md").write_text(markdown(out))
    plot(out, RESULTS / f"stability{suffix}.png")
    print(markdown(out))
    return out


def g(x, fmt=".1e"):
    return "-" if x is None or (isinstance(x, float) and np.isnan(x)) else format(x, fmt)


def markdown(out):
    lines = [f"# lidarjax numerical stability{' (quick)' if out['quick'] else ''}", ""]
    m = out["machine"]
    lines += [f"{machine_line(m)}; "
              f"{out['seconds']:.0f} s in all.", ""]
    c = out["conditioning"]
    lines += ["## Condition number against cone angle", "",
              f"Horizontal error under LOS noise {c['noise_ms']} m/s ({c['draws']} draws; "
              f"prediction ``sigma sqrt(2/K) / sin c``), and rounding error of `simulate` in a "
              f"uniform 10 m/s wind (exact answer known). Flags: ILL_CONDITIONED above "
              f"{c['thresholds']['ILL_CONDITIONED']:g}; Scan refuses above "
              f"{c['thresholds']['MAX_CONDITION']:g}.", "",
              "| scan | cone (deg) | cond (SVD) | cond (formula) | noise rms (m/s) | predicted | "
              "rounding f64 (m/s) | rounding f32 (m/s) | flagged |",
              "|---|---:|---:|---:|---:|---:|---:|---:|:-:|"]
    for r in c["rows"]:
        lines.append(f"| {r['scan']} | {r['cone_deg']:g} | {r['cond_svd']:.4g} | "
                     f"{r['cond_formula']:.4g} | {r['noise_rms_ms']:.3g} | "
                     f"{r['noise_rms_predicted_ms']:.3g} | {g(r['rounding_float64_ms'])} | "
                     f"{g(r['rounding_float32_ms'])} | "
                     f"{'yes' if r['ill_conditioned_float64'] else ''} |")
    lines += ["", "Refused at a cone angle of 0.005 degrees (Windcube V1): "
              f"\"{c['refused_at_0_005_deg'].get('DBS (V1)', '')}\"", ""]
    s = out["speed"]
    lines += ["## float32 against float64 over speed", "",
              f"Hemisphere platform, Windcube V2 on its flank, {s['directions']} directions, "
              f"heights {s['heights_m']} m; tables every {s['table_sector_deg']:g} degrees in "
              f"each precision. Maximum errors; direction in degrees.", "",
              "| speed (m/s) | LOS f32-f64 (m/s) | speed f32/f64-1 | direction f32-f64 | "
              "inverted speed f32/f64-1 | inverted direction f32-f64 | inverted speed vs "
              "truth f64 | f32 | converged f64 | f32 |",
              "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in s["rows"]:
        lines.append(
            f"| {r['speed_ms']:g} | {g(r['los_abs_ms'])} | {g(r.get('lidar_speed_rel'))} | "
            f"{g(r.get('lidar_direction_deg'))} | {g(r.get('invert_speed_rel_f32_vs_f64'))} | "
            f"{g(r.get('invert_direction_deg_f32_vs_f64'))} | "
            f"{g(r.get('invert_speed_rel_vs_truth_f64'))} | "
            f"{g(r.get('invert_speed_rel_vs_truth_f32'))} | {r['converged_f64']:.0%} | "
            f"{r['converged_f32']:.0%} |")
    o = out["offset"]
    lines += ["", "## Coordinate offset", "",
              f"Constant-gradient flow on a {o['grid_spacing_m']:g} m grid offset by the given "
              f"easting and northing; errors against the exact LOS (maximum over heights "
              f"{o['heights_m']} m and beams).", "",
              "| offset (m) | LOS f64 (m/s) | LOS f32 (m/s) | LOS naive f32 (m/s) | speed f32 | "
              "speed naive f32 | direction f32 (deg) | direction naive f32 (deg) |",
              "|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in o["rows"]:
        a, b, n = r["lidarjax_float64"], r["lidarjax_float32"], r["naive_float32"]
        lines.append(f"| {r['offset_m']:.0e} | {g(a['los_abs_ms'])} | {g(b['los_abs_ms'])} | "
                     f"{g(n['los_abs_ms'])} | {g(b['speed_rel'])} | {g(n['speed_rel'])} | "
                     f"{g(b['direction_deg'])} | {g(n['direction_deg'])} |")
    gr = out["gradients"]
    lines += ["", "## Finite outputs and gradients over random configurations", "",
              f"Each configuration: {gr['inputs']} numeric inputs drawn at random (see the "
              f"module docs); outputs finite or NaN with an explaining flag; gradient of a "
              f"loss masking NaN results out finite with respect to every input.", "",
              "| scene | probe | dtype | samples | outputs ok | gradients finite | with "
              "flagged NaN |", "|---|---|---|---:|---:|---:|---:|"]
    for r in gr["rows"]:
        lines.append(f"| {r['scene']} | {r['probe']} | {r['dtype']} | {r['samples']} | "
                     f"{r['outputs_ok']} | {r['gradients_finite']} | {r['with_flagged_nan']} |")
    iv = out["inverse"]
    lines += ["", "## Inverse: outcome per case", "",
              f"{iv['records_per_case']} records per case, mixed in one batch, LOS noise "
              f"{iv['noise_ms']} m/s; shares of problems (record x height). Clean records "
              f"changed by their neighbours: float64 "
              f"{iv['clean_records_changed_by_neighbours_float64']}, float32 "
              f"{iv['clean_records_changed_by_neighbours_float32']}.", "",
              "| case | dtype | converged | NaN: too few beams | NaN: ill-conditioned | NaN: "
              "not converged | inf | steps max | speed error median (relative) | speed std "
              "median (relative) | within 3 std | Student t expects | speed median (m/s) | "
              "speed std median (m/s) |",
              "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in iv["rows"]:
        lines.append(f"| {r['case']} | {r['dtype']} | {r['converged']:.1%} | "
                     f"{r['nan_too_few_beams']:.1%} | {r['nan_ill_conditioned']:.1%} | "
                     f"{r['nan_not_converged']:.1%} | {r['infinite_outputs']} | "
                     f"{r['max_steps']} | {g(r.get('speed_err_median'))} | "
                     f"{g(r.get('speed_std_median'))} | {g(r.get('within_3_std'), '.1%')} | "
                     f"{g(r.get('within_3_std_student_t'), '.1%')} | "
                     f"{g(r.get('speed_median_ms'), '.2f')} | "
                     f"{g(r.get('speed_std_median_ms'), '.2f')} |")
    lines.append("")
    return "\n".join(lines)


def plot(out, path):
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:  # matplotlib is the optional `plot` extra
        print("matplotlib not installed: no plot (pip install lidarjax[plot])")
        return
    fig, ax = plt.subplots(2, 3, figsize=(18, 10))
    rows = out["conditioning"]["rows"]
    for i, name in enumerate(SCANS):
        # cone angles up to 54.7 degrees, where the horizontal wind is the ill-determined part
        # (beyond, the condition number grows again through the vertical component)
        rr = sorted((r for r in rows if r["scan"] == name and r["cone_deg"] <= 54.75),
                    key=lambda r: r["cond_svd"])
        cond = [r["cond_svd"] for r in rr]
        ax[0, 0].loglog(cond, [r["noise_rms_ms"] for r in rr], "o", color=f"C{i}", label=name)
        ax[0, 0].loglog(cond, [r["noise_rms_predicted_ms"] for r in rr], "-", color=f"C{i}",
                        alpha=0.5)
        for dt, mk in (("float64", "s"), ("float32", "^")):
            ax[0, 1].loglog(cond, [max(r[f"rounding_{dt}_ms"], 1e-17) for r in rr], mk + "-",
                            color=f"C{i}", label=f"{name}, {dt}")
    th = out["conditioning"]["thresholds"]
    for a in (ax[0, 0], ax[0, 1]):
        a.axvline(th["ILL_CONDITIONED"], color="k", ls=":", label="ILL_CONDITIONED flag")
        a.set_xlabel("beam-matrix condition number")
    ax[0, 0].set(ylabel="rms horizontal error (m/s)",
                 title=f"LOS noise {NOISE} m/s, cones 0.01-55 deg (lines: prediction)")
    ax[0, 0].legend(fontsize=8)
    ax[0, 1].set(ylabel="max |error| of u, v (m/s)",
                 title="Rounding of simulate in a uniform 10 m/s wind")
    ax[0, 1].legend(fontsize=7, ncol=2)
    sp = [r for r in out["speed"]["rows"] if r["speed_ms"] > 0]
    u = [r["speed_ms"] for r in sp]
    for key, label in (("lidar_speed_rel", "reported speed"),
                       ("invert_speed_rel_f32_vs_f64", "inverted speed"),
                       ("lidar_direction_deg", "reported direction (deg)"),
                       ("invert_direction_deg_f32_vs_f64", "inverted direction (deg)")):
        ax[0, 2].loglog(u, [max(r[key], 1e-12) for r in sp], "o-", label=label)
    ax[0, 2].set(xlabel="free-stream speed (m/s)", ylabel="max |float32 - float64| (relative)",
                 title="float32 against float64 over speed")
    ax[0, 2].legend(fontsize=8)
    off = out["offset"]["rows"]
    x = [max(r["offset_m"], 1.0) for r in off]
    for key, label, mk in (("lidarjax_float64", "lidarjax float64", "s-"),
                           ("lidarjax_float32", "lidarjax float32", "o-"),
                           ("naive_float32", "naive float32 (absolute coordinates)", "x--")):
        ax[1, 0].loglog(x, [max(r[key]["los_abs_ms"], 1e-16) for r in off], mk, label=label)
    ax[1, 0].set(xlabel="coordinate offset (m; 0 plotted at 1)", ylabel="max |LOS error| (m/s)",
                 title="Large coordinates (UTM)")
    ax[1, 0].legend(fontsize=8)
    gr = out["gradients"]["rows"]
    labels = [f"{r['scene']}\n{r['probe']} {r['dtype'][-2:]}" for r in gr]
    y = np.arange(len(gr))
    ax[1, 1].barh(y, [r["samples"] for r in gr], color="0.85", label="samples")
    ax[1, 1].barh(y, [r["gradients_finite"] for r in gr], height=0.5, label="finite gradients")
    ax[1, 1].plot([r["with_flagged_nan"] for r in gr], y, "k|", ms=12,
                  label="with flagged NaN outputs")
    ax[1, 1].set_yticks(y, labels, fontsize=6)
    ax[1, 1].set(title="Configurations with finite gradients (loss masking NaN)")
    ax[1, 1].legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.05), ncol=3)
    iv = out["inverse"]["rows"]
    names = list(CASES)
    for j, dt in enumerate(("float64", "float32")):
        rr = {r["case"]: r for r in iv if r["dtype"] == dt}
        conv = np.array([rr[n]["converged"] for n in names])
        few = np.array([rr[n]["nan_too_few_beams"] for n in names])
        ill = np.array([rr[n]["nan_ill_conditioned"] for n in names])
        pos = np.arange(len(names)) + 0.4 * j - 0.2
        ax[1, 2].bar(pos, conv, 0.4, color=f"C{j}", label=f"converged, {dt}")
        ax[1, 2].bar(pos, few, 0.4, bottom=conv, color=f"C{j}", alpha=0.4,
                     label=f"NaN: too few beams, {dt}")
        ax[1, 2].bar(pos, ill, 0.4, bottom=conv + few, color=f"C{j}", alpha=0.15,
                     hatch="//", label=f"NaN: ill-conditioned, {dt}")
    ax[1, 2].set_xticks(np.arange(len(names)), [n.replace(" (", "\n(") for n in names],
                        fontsize=7, rotation=20)
    ax[1, 2].set(ylabel="share of problems", title="Inverse outcome per case", ylim=(0, 1.4))
    ax[1, 2].legend(fontsize=7, loc="upper center", ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    main()
