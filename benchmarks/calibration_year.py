"""Speed of `lidarjax.calibrate` on one year of 10-minute records at 12 heights with the
displacement term in (issue 29, target <= 10 s on the CPU, compilation included).

The table is the ridge of the `hill` scene (H = 40 m, L = 200 m) seen by a Windcube V2 beside
its crest, every 10 degrees, 12 heights from 40 to 200 m, built by `lidarjax.simulate` and
`ResponseTable.from_simulations(fields=...)`, so it carries `beam_gradient`. The records
(52,560 x 12 heights) are written by `simulate` with a truly turned and tilted `Mount`
(north offset 1 degree, pitch 0.3, roll -0.2) and 0.1 m/s of LOS noise. Times: the first
call in the process (compilation included) and the warm median, with and without a
reference, and with the table's runs (`calibrate(runs=...)`, iterating on the exact
geometry: the table built again at the estimate); the estimates against the truth as a
check.

Writes benchmarks/results/calibration_year.json. Run from a checkout:
``python3 benchmarks/calibration_year.py [--repeats 3]``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _common import machine, machine_line, median_time  # noqa: E402

import lidarjax as lj  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"
HEIGHTS = np.array([40.0, 50.0, 60.0, 70.0, 80.0, 90.0, 100.0, 120.0, 140.0, 160.0, 180.0,
                    200.0])
DIRECTIONS = np.arange(0.0, 360.0, 10.0)
YEAR = 52_560
SIGMA = 0.1
TRUTH = (1.0, 0.3, -0.2)
SCAN = lj.windcube_v2()
LOC = (60.0, 0.0, 40.0 / (1.0 + (60.0 / 200.0) ** 2))


def ridge(direction, speed):
    return lj.scenes.hill(height=40.0, half_width=200.0, speed=speed, direction=direction)


def table() -> lj.ResponseTable:
    mount = lj.Mount(LOC)
    fields = [ridge(d, 1.0) for d in DIRECTIONS]
    sims = [lj.simulate(f, SCAN, mount, HEIGHTS, u_ref=np.asarray(lj.heading(d)))
            for f, d in zip(fields, DIRECTIONS, strict=True)]
    return lj.ResponseTable.from_simulations(sims, mount=mount, fields=fields, scan=SCAN)


def runs() -> lj.TableRuns:
    """The same runs as `table`, for `calibrate(runs=...)` (the exact geometry)."""
    return lj.TableRuns([ridge(d, 1.0) for d in DIRECTIONS], lj.Mount(LOC),
                        np.stack([np.asarray(lj.heading(d)) for d in DIRECTIONS]), SCAN,
                        HEIGHTS)


def records(rng):
    d, u = rng.uniform(0.0, 360.0, YEAR), 9.0 * rng.weibull(2.0, YEAR) + 0.5
    mount = lj.Mount(LOC, gamma=-TRUTH[0], pitch=TRUTH[1], roll=TRUTH[2])
    run = jax.jit(jax.vmap(lambda dd, uu: lj.simulate(ridge(dd, uu), SCAN, mount, HEIGHTS).los))
    los = np.concatenate([np.asarray(run(jnp.asarray(d[i:i + 8760]), jnp.asarray(u[i:i + 8760])))
                          for i in range(0, YEAR, 8760)])
    los = los + SIGMA * rng.standard_normal(los.shape)
    shape = (YEAR, HEIGHTS.size)
    return los, (np.broadcast_to(u[:, None], shape), np.broadcast_to(d[:, None], shape))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    m = machine()
    print(machine_line(m), flush=True)
    t = table()
    assert t.beam_gradient is not None
    los, ref = records(np.random.default_rng(29))
    out = {"machine": m, "records": YEAR, "heights": int(HEIGHTS.size),
           "problems": YEAR * int(HEIGHTS.size), "truth_offsets_deg": list(TRUTH),
           "load_average_at_start": os.getloadavg()[0]}

    def timed(name, fn):
        t0, c0 = time.perf_counter(), time.process_time()
        res = fn()
        first, first_cpu = time.perf_counter() - t0, time.process_time() - c0
        c0 = time.process_time()
        warm = median_time(fn, args.repeats, warm=False)
        warm_cpu = (time.process_time() - c0) / args.repeats
        # CPU seconds of this process too: the machine is shared, and they do not grow with
        # the other jobs' load as the wall clock does
        out[name] = {"first_s": first, "warm_median_s": warm, "first_cpu_s": first_cpu,
                     "warm_mean_cpu_s": warm_cpu,
                     "offset_deg": [float(v) for v in np.asarray(res.offset)],
                     "std_deg": [float(v) for v in np.asarray(res.std)],
                     "passes": int(res.num_steps), "flags": int(res.flags),
                     "rebuilds": int(res.rebuilds)}
        print(f"  {name}: first call {first:.2f} s ({first_cpu:.2f} cpu-s), warm {warm:.2f} s "
              f"({warm_cpu:.2f} cpu-s); offsets "
              f"{out[name]['offset_deg']} +- {out[name]['std_deg']}", flush=True)

    timed("calibrate_reference", lambda: lj.calibrate(los, t, reference=ref))
    timed("calibrate_no_reference", lambda: lj.calibrate(los, t))
    # iterating on the exact geometry: the table built again at the estimate from its runs
    r = runs()
    timed("calibrate_reference_exact", lambda: lj.calibrate(los, t, reference=ref, runs=r))
    timed("calibrate_no_reference_exact", lambda: lj.calibrate(los, t, runs=r))
    out["load_average_at_end"] = os.getloadavg()[0]
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "calibration_year.json").write_text(json.dumps(out, indent=1) + "\n")
    print(f"load average {out['load_average_at_start']:.1f} at start, "
          f"{out['load_average_at_end']:.1f} at end (2 cores)")


if __name__ == "__main__":
    main()
