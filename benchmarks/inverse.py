"""Benchmark: free-stream recovery for a campaign, lidarjax.invert against scipy and baselines.

Site: a 20 m hemisphere "platform" with a Gaussian wake behind it (so the response is not a
pure first harmonic of direction, unlike plain potential flow), a Windcube V2 on its flank
(12.6 m off the top), 12 heights from 5 to 150 m. CFD runs every 10 degrees build the
`ResponseTable`; the synthetic campaign (one year of 10-minute records: 52 560 records x 12
heights = 630 720 problems) has Weibull speeds (k = 2, A = 9 m/s), a two-lobed wind rose,
and Gaussian LOS noise of 0.1 m/s.

Timed side by side in one run:

- `lidarjax.invert` on 1e3 .. 6.3e5 problems (compile time apart from run time: the solver
  is lowered and compiled ahead of time, then run; medians of repeats);
- `scipy.optimize.least_squares` (MINPACK Levenberg--Marquardt, analytic Jacobian) in a Python
  loop over a subsample, on the same model (the same spline coefficients evaluated in numpy)
  from the same starts, reported per problem;
- the closed-form homogeneous reconstruction (what the instrument reports) as the floor;
- ZephyCube's scalar and vector corrections and 1-degree / 12-sector correction roses.

Accuracy of every method on the same records, against the free stream (and, for ZephyCube's
native target, against the wind on the vertical above the lidar). Results go to
benchmarks/results/inverse.{json,md,png}.

Run from a checkout: ``python benchmarks/inverse.py [--quick]``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # benchmark this checkout, not an installed copy

import equinox as eqx  # noqa: E402
import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import scipy  # noqa: E402
from _common import machine, machine_line  # noqa: E402
from jaxtyping import Array, Float  # noqa: E402
from scipy.optimize import least_squares  # noqa: E402

import lidarjax as lj  # noqa: E402
from lidarjax import zephycube as zc  # noqa: E402
from lidarjax.angles import heading  # noqa: E402
from lidarjax.field import AbstractField  # noqa: E402
from lidarjax.scenes import Hemisphere, hemisphere  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"
RADIUS = 20.0
HEIGHTS = (5.0, 10.0, 15.0, 20.0, 30.0, 40.0, 50.0, 60.0, 80.0, 100.0, 125.0, 150.0)
MOUNT = lj.Mount([12.0, -4.0, float(np.sqrt(RADIUS**2 - 160.0))])
SCAN = lj.windcube_v2()
NOISE = 0.1  # LOS noise, m/s
RECORDS_PER_YEAR = 365 * 24 * 6


class WakeHemisphere(AbstractField):
    """Potential flow over a hemisphere plus a Gaussian velocity deficit downstream.

    The deficit ``deficit * U * exp(-c**2 / (2 sigma**2))`` acts along the free stream, with
    ``c`` the distance from the wake axis (the downstream ray through the centre at ground
    level) and ``sigma = R + 0.1 s`` growing with the downstream distance ``s`` (a smooth
    ``max(s, 0)``); it is switched on smoothly over one radius behind the centre. Not a flow
    solution: a smooth synthetic site whose response has sharp features in direction.
    """

    origin: Float[Array, 3]
    origin_lo: Float[Array, 3]
    body: Hemisphere
    deficit: Float[Array, ""]

    def sample_local(self, points):
        b = self.body
        v = b.sample_local(points)
        e = heading(b.direction, b.dtype)
        s = jnp.sum(points * e, axis=-1)
        c2 = jnp.sum(points * points, axis=-1) - s * s
        downstream = 0.5 * (s + jnp.sqrt(s * s + b.radius**2))  # smooth max(s, 0)
        sigma = b.radius + 0.1 * downstream
        on = 0.5 * (1.0 + jnp.tanh(s / b.radius))
        d = b.speed * self.deficit * on * jnp.exp(-c2 / (2.0 * sigma**2))
        return v - d[..., None] * e


def scene(direction, speed):
    body = hemisphere(radius=RADIUS, speed=speed, direction=direction)
    return WakeHemisphere(body.origin, body.origin_lo, body, jnp.asarray(0.4))


@jax.jit
def _simulate(directions, speeds):
    def one(d, u):
        return lj.simulate(scene(d, u), SCAN, MOUNT, jnp.asarray(HEIGHTS), u_ref=u * heading(d))

    return jax.vmap(one)(directions, speeds)


def simulate(directions, speeds, chunk=4096):
    """Simulations for many runs, in fixed-size chunks (one compile)."""
    n = len(directions)
    out = []
    for i in range(0, n, chunk):
        d = np.asarray(directions[i : i + chunk], np.float64)
        u = np.asarray(speeds[i : i + chunk], np.float64)
        m = d.size
        d = np.concatenate([d, np.zeros(chunk - m)])
        u = np.concatenate([u, np.ones(chunk - m)])
        sims = _simulate(jnp.asarray(d), jnp.asarray(u))
        out.append(jax.tree_util.tree_map(lambda a, m=m: np.asarray(a[:m]), sims))
    return jax.tree_util.tree_map(lambda *a: np.concatenate(a), *out)


def build_table(sector):
    cfd = np.arange(0.0, 360.0, sector)
    sims = simulate(cfd, np.full(cfd.shape, 10.0), chunk=128)
    sims = jax.tree_util.tree_map(jnp.asarray, sims)
    fields = [scene(float(d), 10.0) for d in cfd]
    return lj.ResponseTable.from_simulations(sims, mount=MOUNT, fields=fields)


def campaign(n_records, seed=0):
    """Synthetic truth: Weibull speeds, a two-lobed rose (SW prevailing, some NE)."""
    rng = np.random.default_rng(seed)
    lobe = rng.random(n_records) < 0.7
    direction = np.where(
        lobe, rng.normal(225.0, 40.0, n_records), rng.normal(45.0, 30.0, n_records)
    )
    direction = np.mod(direction, 360.0)
    speed = 9.0 * rng.weibull(2.0, n_records)
    sims = simulate(direction, speed)
    los = sims.los + NOISE * rng.standard_normal(sims.los.shape)
    return sims, los


# -------------------------------------------------------------------------------------------
# scipy reference: the same model and starts, one problem at a time


def numpy_model(table):
    sp = table.response_spline
    return dict(
        start=float(sp.start), offsets=np.asarray(sp.offsets), widths=np.asarray(sp.widths),
        coefficients=np.asarray(sp.coefficients), knots=np.asarray(table.directions),
        values=np.asarray(table.response),
    )


def _eval(model, h, d):
    x = np.mod(d - model["start"], 360.0)
    k = np.searchsorted(model["offsets"], x, side="right") - 1
    k = int(np.clip(k, 0, model["offsets"].size - 1))
    t = (x - model["offsets"][k]) / model["widths"][k]
    c = model["coefficients"][:, k, h]
    r = c[0] + t * (c[1] + t * (c[2] + t * c[3]))
    dr = (c[1] + t * (2 * c[2] + 3 * t * c[3])) / model["widths"][k]
    return r, dr


def scipy_solve(model, los, h):
    """One problem: LOS (b,) at height index h. Same start as lidarjax (best knot, closed-form
    speed), same residual, analytic Jacobian, MINPACK LM."""
    rk = model["values"][:, h, :]
    a, c = rk @ los, (rk * rk).sum(1)
    uk = np.where((a > 0) & (c > 0), a / np.where(c > 0, c, 1), 0.0)
    k = int(np.argmax(a * uk))
    d0 = np.deg2rad(model["knots"][k])
    y0 = np.array([-uk[k] * np.sin(d0), -uk[k] * np.cos(d0)])

    def polar(y):
        u, v = y
        return np.hypot(u, v), np.rad2deg(np.arctan2(-u, -v))

    def fun(y):
        speed, d = polar(y)
        r, _ = _eval(model, h, d)
        return los - speed * r

    def jac(y):
        u, v = y
        speed, d = polar(y)
        r, dr = _eval(model, h, d)
        du = np.array([u, v]) / speed
        dd = np.rad2deg(np.array([v, -u])) / speed**2
        return -(r[:, None] * du[None, :] + speed * dr[:, None] * dd[None, :])

    sol = least_squares(fun, y0, jac=jac, method="lm", xtol=1e-10, ftol=1e-10, gtol=1e-10)
    speed, d = polar(sol.x)
    return speed, np.mod(d, 360.0), sol.nfev


# -------------------------------------------------------------------------------------------


def median_time(fn, repeats):
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - t)
    return float(np.median(times)), [float(x) for x in times]


def errors(speed, direction, true_speed, true_direction, mask):
    es = np.asarray(speed) / true_speed - 1.0
    ed = np.asarray(lj.wrap180(jnp.asarray(direction) - true_direction))
    es, ed = es[mask], ed[mask]
    ok = np.isfinite(es) & np.isfinite(ed)
    return dict(
        speed_median=float(np.median(np.abs(es[ok]))),
        speed_bias=float(np.mean(es[ok])),
        speed_rms=float(np.sqrt(np.mean(es[ok] ** 2))),
        speed_p95=float(np.percentile(np.abs(es[ok]), 95)),
        direction_bias=float(np.mean(ed[ok])),
        direction_rms=float(np.sqrt(np.mean(ed[ok] ** 2))),
        direction_p95=float(np.percentile(np.abs(ed[ok]), 95)),
        direction_median=float(np.median(np.abs(ed[ok]))),
        nan_fraction=float(1.0 - ok.mean()),
        n=int(ok.size),
    )


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes, under a minute")
    parser.add_argument("--batch-size", type=int, default=None, help="problems per batch")
    args = parser.parse_args(argv)
    quick = args.quick
    batch_size = args.batch_size or lj.inverse.DEFAULT_BATCH_SIZE
    h = len(HEIGHTS)
    sizes = [1_000, 10_000] if quick else [1_000, 10_000, 100_000, RECORDS_PER_YEAR * h]
    n_scipy = 240 if quick else 3_000
    repeats = 3 if quick else 5
    sector = 10.0
    out = dict(
        quick=quick, sector_deg=sector, heights_m=list(HEIGHTS), noise_ms=NOISE,
        batch_size=batch_size, machine=machine(),
        versions=dict(scipy=scipy.__version__, equinox=eqx.__version__, lidarjax=lj.__version__),
    )

    t0 = time.perf_counter()
    table = build_table(sector)
    out["table_build_s"] = time.perf_counter() - t0
    n_max = max(sizes)
    n_rec = -(-n_max // h)
    t0 = time.perf_counter()
    sims, los = campaign(n_rec)
    out["campaign_build_s"] = time.perf_counter() - t0
    print(f"table ({table.n_directions} runs) {out['table_build_s']:.1f} s, campaign of "
          f"{n_rec} records {out['campaign_build_s']:.1f} s", flush=True)

    # --- throughput of lidarjax.invert ---------------------------------------------------
    def solver(n_records):
        def f(x):
            return lj.invert(table, x, batch_size=batch_size)

        x = jnp.asarray(los[:n_records])
        t = time.perf_counter()
        lowered = jax.jit(f).lower(x)
        t_lower = time.perf_counter() - t
        t = time.perf_counter()
        compiled = lowered.compile()
        t_compile = time.perf_counter() - t
        return compiled, x, t_lower, t_compile

    rows = []
    inv_full = None
    for n in sizes:
        nr = -(-n // h)
        compiled, x, t_lower, t_compile = solver(nr)
        run, all_runs = median_time(lambda c=compiled, x=x: c(x).speed, repeats)
        inv = compiled(x)
        steps = np.asarray(inv.num_steps).ravel()
        p = nr * h
        rows.append(dict(problems=p, records=nr, trace_s=t_lower, compile_s=t_compile,
                         run_s=run, runs_s=all_runs, problems_per_s=p / run,
                         mean_steps=float(steps.mean()), max_steps=int(steps.max())))
        print(f"invert {p:>7d} problems: trace {t_lower:.2f} s, compile {t_compile:.2f} s, run "
              f"{run:.3f} s = {p / run:,.0f} problems/s, steps mean {steps.mean():.2f} max "
              f"{steps.max()}", flush=True)
        inv_full, full_compiled = inv, compiled
    out["invert"] = rows

    # step distribution and the cost of the slowest member per vmapped batch
    steps = np.asarray(inv_full.num_steps).ravel()
    hist = np.bincount(steps)
    per_batch = (batch_size // h) * h  # invert batches whole records
    pad = (-steps.size) % per_batch
    per_batch_max = np.concatenate([steps, np.zeros(pad, int)]).reshape(-1, per_batch).max(1)
    out["steps"] = dict(
        histogram={int(k): int(v) for k, v in enumerate(hist) if v},
        mean=float(steps.mean()), p50=float(np.median(steps)), p99=float(np.percentile(steps, 99)),
        max=int(steps.max()), mean_of_batch_max=float(per_batch_max.mean()),
        vmap_efficiency=float(steps.mean() / per_batch_max.mean()),
    )
    print(f"steps: {out['steps']['histogram']}; mean {steps.mean():.2f}, mean of per-batch max "
          f"{per_batch_max.mean():.2f}", flush=True)

    # --- scipy on a subsample ----------------------------------------------------------------
    model = numpy_model(table)
    rng = np.random.default_rng(7)
    n_all = los.shape[0] * h
    pick = rng.choice(min(n_all, n_rec * h), size=n_scipy, replace=False)
    rec_i, h_i = pick // h, pick % h
    t = time.perf_counter()
    sc = [scipy_solve(model, los[r, k], k) for r, k in zip(rec_i, h_i, strict=True)]
    t_scipy = time.perf_counter() - t
    sc = np.asarray(sc)
    js, jd = np.asarray(inv_full.speed)[rec_i, h_i], np.asarray(inv_full.direction)[rec_i, h_i]
    fast = js > 1.0
    out["scipy"] = dict(
        problems=n_scipy, total_s=t_scipy, per_problem_s=t_scipy / n_scipy,
        problems_per_s=n_scipy / t_scipy, mean_nfev=float(sc[:, 2].mean()),
        max_abs_speed_diff_vs_lidarjax=float(np.nanmax(np.abs(sc[:, 0] - js))),
        max_abs_direction_diff_vs_lidarjax=float(np.nanmax(np.abs(lj.wrap180(sc[:, 1] - jd)))),
        max_abs_direction_diff_vs_lidarjax_above_1ms=float(
            np.nanmax(np.abs(lj.wrap180(sc[fast, 1] - jd[fast])))),
    )
    print(f"scipy: {t_scipy / n_scipy * 1e3:.3f} ms/problem = {n_scipy / t_scipy:,.0f} "
          f"problems/s; max |dU| vs lidarjax {out['scipy']['max_abs_speed_diff_vs_lidarjax']:.2e}",
          flush=True)

    # --- floor and baselines on all problems ------------------------------------------------
    x = jnp.asarray(los)
    homog = zc.homogeneous_wind(table, x)
    run, _ = median_time(lambda: zc.homogeneous_wind(table, x).speed, repeats)
    out["homogeneous"] = dict(problems=n_all, run_s=run, problems_per_s=n_all / run)
    print(f"homogeneous: {n_all / run:,.0f} problems/s", flush=True)
    rose = lj.correction_rose(table)
    rose12 = lj.sector_rose(rose, 12)
    w_m = jnp.asarray(los[..., 4])  # the V2's vertical beam
    for name, fn in (("zephycube_vector", lambda: zc.vector_correction(table, x).speed),
                     ("zephycube_scalar", lambda: zc.scalar_correction(
                         table, homog.speed, homog.direction, w_m).speed),
                     ("rose_1deg", lambda: rose.apply(homog.speed, homog.direction)[0]),
                     ("invert_reconstructed", lambda: lj.invert_reconstructed(
                         table, homog.speed, homog.direction).speed)):
        run, _ = median_time(fn, repeats)
        out.setdefault("baseline_throughput", {})[name] = n_all / run

    # --- accuracy on the same records, with and without LOS noise ---------------------------
    free_u = np.asarray(sims.free_speed)[:, None]
    free_d = np.asarray(sims.free_direction)[:, None]
    cen_u, cen_d = np.asarray(sims.point_speed), np.asarray(sims.point_direction)
    masks = dict(strong=np.broadcast_to(free_u > 3.0, cen_u.shape),  # exclude near-calm
                 all=np.ones(cen_u.shape, bool))

    def centre_to_free(w):
        """ZephyCube's centre-line wind to the free stream with the table's point factors,
        taken at its corrected direction (its own assumption)."""
        p = table.point_spline.per_row(jnp.asarray(w.direction))  # per unit free speed
        rad = jnp.deg2rad(jnp.asarray(w.direction))
        free = jnp.stack([-jnp.sin(rad), -jnp.cos(rad), 0 * rad], -1)
        addend = lj.direction_difference(free, p)
        return w.speed / lj.horizontal_speed(p), jnp.mod(w.direction + addend, 360.0)

    def accuracy(x, inv):
        homog = zc.homogeneous_wind(table, x)
        vec = zc.vector_correction(table, x)
        sca = zc.scalar_correction(table, homog.speed, homog.direction, x[..., 4])
        rec = lj.invert_reconstructed(table, homog.speed, homog.direction)
        inv_c = table.point_spline.per_row(jnp.nan_to_num(inv.direction)) * inv.speed[..., None]
        free = {
            "uncorrected (homogeneous)": (homog.speed, homog.direction),
            "correction rose, 12 sectors": rose12.apply(homog.speed, homog.direction),
            "correction rose, 1 degree": rose.apply(homog.speed, homog.direction),
            "ZephyCube scalar -> free": centre_to_free(sca),
            "ZephyCube vector -> free": centre_to_free(vec),
            "lidarjax.invert_reconstructed (.sta)": (rec.speed, rec.direction),
            "lidarjax.invert (raw LOS)": (inv.speed, inv.direction),
        }
        centre = {
            "uncorrected (homogeneous)": (homog.speed, homog.direction),
            "ZephyCube scalar": (sca.speed, sca.direction),
            "ZephyCube vector": (vec.speed, vec.direction),
            "lidarjax.invert -> centre": (lj.horizontal_speed(inv_c), lj.wind_direction(inv_c)),
        }
        return (
            {n: {k: errors(u, d, free_u, free_d, m) for k, m in masks.items()}
             for n, (u, d) in free.items()},
            {n: {k: errors(u, d, cen_u, cen_d, m) for k, m in masks.items()}
             for n, (u, d) in centre.items()},
        )

    acc_free, acc_centre = accuracy(x, inv_full)
    # scipy on its subsample against the same truth
    sub = np.zeros(cen_u.shape, bool)
    sub[rec_i, h_i] = True
    su, sd = np.full(cen_u.shape, np.nan), np.full(cen_u.shape, np.nan)
    su[rec_i, h_i], sd[rec_i, h_i] = sc[:, 0], sc[:, 1]
    acc_free["scipy least_squares (subsample)"] = {
        k: errors(su, sd, free_u, free_d, m & sub) for k, m in masks.items()}
    acc_free["lidarjax.invert (same subsample)"] = {
        k: errors(inv_full.speed, inv_full.direction, free_u, free_d, m & sub)
        for k, m in masks.items()}
    out["accuracy_vs_free_stream"] = acc_free
    out["accuracy_vs_centre_line"] = acc_centre
    out["invert_converged_fraction"] = float(np.mean(inv_full.converged))
    x0 = jnp.asarray(sims.los)  # the same records without noise
    inv0 = full_compiled(x0)
    out["noise_free_accuracy_vs_free_stream"], out["noise_free_accuracy_vs_centre_line"] = \
        accuracy(x0, inv0)
    print("accuracy done", flush=True)

    # noise-free accuracy against sector spacing (order of convergence)
    n_conv = 200 if quick else 1000
    truth_sims, _ = campaign(n_conv, seed=3)
    t_u = np.asarray(truth_sims.free_speed)[:, None]
    t_d = np.asarray(truth_sims.free_direction)[:, None]
    t_all = np.ones(truth_sims.los.shape[:2], bool)
    order = []
    for sec in ((30.0, 15.0) if quick else (30.0, 15.0, 10.0, 5.0)):
        t_sec = table if sec == sector else build_table(sec)
        i = lj.invert(t_sec, jnp.asarray(truth_sims.los))
        e = errors(i.speed, i.direction, t_u, t_d, t_all)
        order.append(dict(sector_deg=sec, speed_rms=e["speed_rms"],
                          direction_rms=e["direction_rms"],
                          speed_max=float(np.nanmax(np.abs(np.asarray(i.speed) / t_u - 1))),
                          converged=float(np.mean(i.converged))))
    unc = errors(truth_sims.lidar_speed, truth_sims.lidar_direction, t_u, t_d, t_all)
    sp = np.log([o["sector_deg"] for o in order])
    out["noise_free"] = dict(
        records=n_conv, by_sector=order, uncorrected=unc,
        order_speed=float(np.polyfit(sp, np.log([o["speed_rms"] for o in order]), 1)[0]),
        order_direction=float(np.polyfit(sp, np.log([o["direction_rms"] for o in order]), 1)[0]),
    )

    # headline: the largest (campaign-sized) run against scipy's per-problem rate
    out["speedup_vs_scipy"] = rows[-1]["problems_per_s"] / out["scipy"]["problems_per_s"]
    RESULTS.mkdir(parents=True, exist_ok=True)
    suffix = "_quick" if quick else ""
    (RESULTS / f"inverse{suffix}.json").write_text(json.dumps(out, indent=2))
    (RESULTS / f"inverse{suffix}.md").write_text(markdown(out))
    plot(out, steps, RESULTS / f"inverse{suffix}.png")
    print(markdown(out))
    return out


def markdown(out):
    lines = [f"# lidarjax.invert benchmark{' (quick)' if out['quick'] else ''}", ""]
    m = out["machine"]
    lines += [f"{machine_line(m)}, SciPy {out['versions']['scipy']}; "
              f"table every {out['sector_deg']:g} degrees, "
              f"{len(out['heights_m'])} heights, LOS noise {out['noise_ms']} m/s, "
              f"batch size {out['batch_size']}. Times are medians of repeats.", ""]
    lines += ["| method | problems | compile (s) | run (s) | problems/s |",
              "|---|---:|---:|---:|---:|"]
    for r in out["invert"]:
        lines.append(f"| lidarjax.invert | {r['problems']:,} | {r['compile_s']:.2f} | "
                     f"{r['run_s']:.3f} | {r['problems_per_s']:,.0f} |")
    s = out["scipy"]
    lines.append(f"| scipy least_squares loop | {s['problems']:,} (subsample) | - | "
                 f"{s['total_s']:.2f} | {s['problems_per_s']:,.0f} |")
    hm = out["homogeneous"]
    lines.append(f"| homogeneous reconstruction (floor) | {hm['problems']:,} | - | "
                 f"{hm['run_s']:.4f} | {hm['problems_per_s']:,.0f} |")
    lines += ["", f"Speed-up of lidarjax.invert ({out['invert'][-1]['problems']:,} problems) over "
              f"scipy: **{out['speedup_vs_scipy']:,.0f}x**; "
              f"scipy and lidarjax agree to {s['max_abs_speed_diff_vs_lidarjax']:.1e} m/s and "
              f"{s['max_abs_direction_diff_vs_lidarjax_above_1ms']:.1e} degrees above 1 m/s "
              f"({s['max_abs_direction_diff_vs_lidarjax']:.1e} degrees over all records: both "
              f"stop on a step tolerance, and below 1 m/s the noise leaves the direction flat).",
              ""]
    st = out["steps"]
    lines += [f"Solver steps (full run): {st['histogram']}; mean {st['mean']:.2f}, p99 "
              f"{st['p99']:.0f}, max {st['max']}; mean of the per-batch maximum "
              f"{st['mean_of_batch_max']:.2f} (vmap efficiency {st['vmap_efficiency']:.0%}).", ""]
    for title, key in (
        ("free stream, LOS noise 0.1 m/s", "accuracy_vs_free_stream"),
        ("free stream, noise-free LOS", "noise_free_accuracy_vs_free_stream"),
        ("wind above the lidar (ZephyCube's target), LOS noise 0.1 m/s", "accuracy_vs_centre_line"),
        ("wind above the lidar, noise-free LOS", "noise_free_accuracy_vs_centre_line"),
    ):
        lines += [f"Accuracy against the {title}; relative speed errors and direction errors "
                  f"(degrees) over records with U > 3 m/s; NaN share over all records:", "",
                  "| method | speed median | speed bias | speed rms | speed p95 | direction "
                  "median | direction rms | direction p95 | NaN |",
                  "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for name, e in out[key].items():
            a = e["strong"]
            lines.append(f"| {name} | {a['speed_median']:.2e} | {a['speed_bias']:+.2e} | "
                         f"{a['speed_rms']:.2e} | {a['speed_p95']:.2e} | "
                         f"{a['direction_median']:.2e} | {a['direction_rms']:.2e} | "
                         f"{a['direction_p95']:.2e} | {e['all']['nan_fraction']:.2%} |")
        lines.append("")
    nf = out["noise_free"]
    lines += ["Noise-free records, error against sector spacing (rms, all records):", "",
              "| sector (deg) | speed rms | direction rms (deg) |", "|---:|---:|---:|"]
    for o in nf["by_sector"]:
        lines.append(f"| {o['sector_deg']:g} | {o['speed_rms']:.2e} | {o['direction_rms']:.2e} |")
    u = nf["uncorrected"]
    lines += [f"| uncorrected | {u['speed_rms']:.2e} | {u['direction_rms']:.2e} |", "",
              f"Measured order: speed {nf['order_speed']:.2f}, "
              f"direction {nf['order_direction']:.2f}.",
              ""]
    return "\n".join(lines)


def plot(out, steps, path):
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:  # matplotlib is the optional `plot` extra
        print("matplotlib not installed: no plot (pip install lidarjax[plot])")
        return
    fig, ax = plt.subplots(1, 3, figsize=(18, 5), gridspec_kw=dict(width_ratios=[1, 1, 1.2]))
    p = [r["problems"] for r in out["invert"]]
    ax[0].loglog(p, [r["problems_per_s"] for r in out["invert"]], "o-", label="lidarjax.invert")
    ax[0].axhline(out["scipy"]["problems_per_s"], color="C1", label="scipy least_squares loop")
    ax[0].axhline(out["homogeneous"]["problems_per_s"], color="C2", ls="--",
                  label="homogeneous reconstruction")
    ax[0].set(xlabel="problems (record x height)", ylabel="problems / s", title="Throughput")
    ax[0].legend(loc="lower right", bbox_to_anchor=(1.0, 0.1))
    hist = np.bincount(steps)
    ax[1].bar(np.arange(hist.size), hist)
    ax[1].set(xlabel="solver steps", ylabel="problems", yscale="log", title="Step distribution")
    names = list(out["noise_free_accuracy_vs_free_stream"])[::-1]
    y = np.arange(len(names))
    for i, (key, label) in enumerate((("accuracy_vs_free_stream", "LOS noise 0.1 m/s"),
                                      ("noise_free_accuracy_vs_free_stream", "noise-free"))):
        med = [out[key][n]["strong"]["speed_median"] * 100 for n in names]
        ax[2].barh(y + 0.4 * i - 0.2, med, height=0.4, label=label)
    ax[2].set_yticks(y, names)
    ax[2].set(xscale="log", xlabel="median |speed error| vs free stream (%), U > 3 m/s")
    ax[2].set_title("Accuracy", pad=24)
    ax[2].legend(loc="lower left", bbox_to_anchor=(0.0, 1.0), ncol=2, frameon=False)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


if __name__ == "__main__":
    main()
