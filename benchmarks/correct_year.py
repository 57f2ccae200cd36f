"""Time `lidarjax correct` on a year of 10-minute records, as a user runs it (whole command).

Writes a synthetic table (36 directions x 12 heights, Windcube V2) and a year of ``.sta``
records (52,560 rows x 12 heights, Windcube V2 layout), then runs the command line in fresh
processes:

- cold: an empty persistent compilation cache (first run on a machine);
- warm: the same command again (compiled code from the cache);
- no cache: ``--no-cache`` (every run compiles);

and a 200,000-row file for peak memory (maximum resident set size of the process, from
``/usr/bin/time -v`` when present, else ``resource.getrusage``). The baseline is the
previous command (lidarjax before this change) where available: not run here, its figures
from issue 10 are quoted in the README (200,000 rows in 50-65 s, 1.7 GB).

    python3 benchmarks/correct_year.py [--quick]

Results: benchmarks/results/correct_year.json and .md. `--quick` uses 5,000 rows.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _common import machine, machine_line  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
HEIGHTS = np.array([40, 54, 74, 94, 114, 134, 154, 174, 194, 214, 234, 254], float)


def make_table(path):
    import jax

    jax.config.update("jax_enable_x64", True)
    import lidarjax as lj
    from lidarjax.io import save_table

    d = np.arange(0.0, 360.0, 10.0)
    r = np.deg2rad(d)
    free = np.stack([-np.sin(r), -np.cos(r), 0 * r], -1)
    gain = 1.0 - 0.04 * np.cos(r)[:, None] * (1 + HEIGHTS / 500.0)[None, :]
    turn = np.deg2rad(1.5 * np.sin(r))[:, None] * np.ones(HEIGHTS.size)
    c, s = np.cos(turn), np.sin(turn)
    rec = np.stack([gain * (c * free[:, None, 0] - s * free[:, None, 1]),
                    gain * (s * free[:, None, 0] + c * free[:, None, 1]),
                    np.zeros_like(gain)], -1)
    vec = np.asarray(lj.windcube_v2().directions())
    table = lj.ResponseTable(d, np.einsum("shk,bk->shb", rec, vec), reconstructed=rec,
                             beam_vectors=vec, heights=HEIGHTS)
    save_table(path, table, {"scan": "windcube_v2", "cone_angle_deg": 28.0, "n_beams": 5,
                             "epsilon_deg": 0.0, "pitch_deg": 0.0, "roll_deg": 0.0,
                             "heights_m": HEIGHTS.tolist()})


def make_records(path, n, seed=0):
    from lidarjax.io import write_sta

    rng = np.random.default_rng(seed)
    time0 = np.datetime64("2023-01-01T00:10")
    t = time0 + np.arange(n) * np.timedelta64(10, "m")
    base = rng.weibull(2.0, n) * 9.0 + 0.5
    speed = base[:, None] * (HEIGHTS / 100.0) ** 0.14 + 0.05 * rng.standard_normal((n, 12))
    direction = (rng.uniform(0, 360, n)[:, None] + 2 * rng.standard_normal((n, 12))) % 360
    std = 0.1 * speed + 0.2
    avail = rng.uniform(60, 100, (n, 12))
    write_sta(path, t, HEIGHTS, speed, direction, speed_std=std, availability=avail,
              scan_angle=28.0)


def run(argv, env):
    """Wall time (s) and peak RSS (MB) of one command-line run in a fresh process."""
    cmd = [sys.executable, "-m", "lidarjax.cli", *argv]
    timer = Path("/usr/bin/time")
    if timer.exists():
        cmd = [str(timer), "-v", *cmd]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(proc.stderr[-2000:])
    m = re.search(r"Maximum resident set size \(kbytes\): (\d+)", proc.stderr)
    rss = int(m.group(1)) / 1024 if m else float("nan")
    u = re.search(r"User time \(seconds\): ([\d.]+)", proc.stderr)
    s = re.search(r"System time \(seconds\): ([\d.]+)", proc.stderr)
    cpu = float(u.group(1)) + float(s.group(1)) if u and s else float("nan")
    return wall, rss, cpu


def plot(out: dict, path: Path) -> None:
    """Bars of wall and CPU time per run (matplotlib, optional)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    runs = ["cold", "warm", "warm_2", "no_cache", "big_warm"]
    labels = ["cold", "warm", "warm again", "--no-cache", f"warm, {out['rows_big']:,} rows"]
    x = np.arange(len(runs))
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.bar(x - 0.2, [out[r]["wall_s"] for r in runs], 0.4, label="wall (loaded machine)")
    ax.bar(x + 0.2, [out[r]["cpu_s"] for r in runs], 0.4, label="CPU (user + system)")
    ax.axhline(10.0, color="k", lw=0.8, ls="--", label="10 s target (one year)")
    ax.set_xticks(x, labels, fontsize=8)
    ax.set_ylabel("seconds")
    ax.set_title(f"lidarjax correct, {out['rows_year']:,} x 12 records (load "
                 f"{out['load_average_at_start']:.0f} on 2 cores)", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--plot-only", action="store_true", help="redraw the PNG from the JSON")
    ap.add_argument("--reuse", default=None, help="folder of a previous run's inputs")
    args = ap.parse_args()
    if args.plot_only:
        res = ROOT / "benchmarks" / "results"
        plot(json.loads((res / "correct_year.json").read_text()), res / "correct_year.png")
        return
    n_year = 5000 if args.quick else 52_560
    n_big = 10_000 if args.quick else 200_000
    work = Path(args.reuse) if args.reuse else Path(tempfile.mkdtemp(prefix="lidarjax-bench-"))
    env = dict(os.environ, PYTHONPATH=str(ROOT), XDG_CACHE_HOME=str(work / "cache"))
    env.pop("LIDARJAX_NO_CACHE", None)
    if args.reuse:
        import shutil

        shutil.rmtree(work / "cache", ignore_errors=True)
    else:
        make_table(work / "table.npz")
        t0 = time.perf_counter()
        make_records(work / "year.sta", n_year)
        make_records(work / "big.sta", n_big, seed=1)
        print(f"inputs written in {time.perf_counter() - t0:.1f} s to {work}")
    base = ["correct", "--table", str(work / "table.npz"), "--quiet"]
    year = base + ["--records", str(work / "year.sta"), "--out", str(work / "year.csv")]
    results = {}
    results["cold"] = run(year, env)
    results["warm"] = run(year, env)
    results["warm_2"] = run(year, env)
    results["no_cache"] = run(["--no-cache", *year], env)
    results["big_warm"] = run(base + ["--records", str(work / "big.sta"), "--out",
                                      str(work / "big.csv")], env)
    lines = sum(1 for _ in open(work / "year.csv")) if (work / "year.csv").exists() else 0
    out = {
        "machine": machine(),
        "load_average_at_start": os.getloadavg()[0],
        "rows_year": n_year, "rows_big": n_big, "heights": int(HEIGHTS.size),
        "csv_lines_year": lines,
        **{k: {"wall_s": round(v[0], 2), "peak_rss_mb": round(v[1], 1),
               "cpu_s": round(v[2], 2)} for k, v in results.items()},
    }
    print(json.dumps(out, indent=2))
    res = ROOT / "benchmarks" / "results"
    res.mkdir(exist_ok=True)
    name = "correct_year_quick" if args.quick else "correct_year"
    (res / f"{name}.json").write_text(json.dumps(out, indent=2) + "\n")
    md = ["# lidarjax correct: a year of 10-minute records, whole command", "",
          f"{machine_line(out['machine'])}; load average at start {out['load_average_at_start']:.1f}. "
          f"Each run is a fresh `python -m lidarjax.cli correct` process (import, read, "
          f"invert, write CSV + NetCDF); wall time, CPU time (user + system, all threads) "
          f"and peak resident memory. On a loaded machine the wall time grows with the load; "
          f"the CPU time does not.", "",
          "| run | rows x heights | wall (s) | CPU (s) | peak RSS (MB) |",
          "|---|---:|---:|---:|---:|"]
    for k, label, rows in (("cold", "cold (empty compilation cache)", n_year),
                           ("warm", "warm (cache filled)", n_year),
                           ("warm_2", "warm, again", n_year),
                           ("no_cache", "--no-cache", n_year),
                           ("big_warm", "warm", n_big)):
        md.append(f"| {label} | {rows:,} x 12 | {out[k]['wall_s']:.2f} | {out[k]['cpu_s']:.2f} | "
                  f"{out[k]['peak_rss_mb']:.0f} |")
    (res / f"{name}.md").write_text("\n".join(md) + "\n")
    plot(out, res / f"{name}.png")


if __name__ == "__main__":
    main()
