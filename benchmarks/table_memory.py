"""Peak memory of building a response table against the number of CFD runs.

Each run is a (n, n, n/2) float64 GridField saved as .npz (a hemisphere 'platform' flow);
the table is built (Windcube V2, pulsed probe) by

- `streamed`: `lidarjax.workflows.seed_tables.build_table` (one run at a time, cropped to where the beams
  look, then dropped);
- `all-at-once`: the previous way, `simulate_settings` (every run loaded, then stacked and
  simulated in one vmapped batch), the baseline.

Each case runs in a fresh process; the resident memory is polled every 2 ms while the table
is built and its peak above the resident memory just before is reported (it includes the
compilation, the same for both).

    python3 benchmarks/table_memory.py [--quick]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from _common import machine  # noqa: E402

CHILD = r"""
import os, sys, threading, time
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
import lidarjax as lj
from lidarjax.io import Settings, load_field
from lidarjax.workflows.seed_tables import build_table, simulate_settings
mode, n_runs, d = sys.argv[1], int(sys.argv[2]), sys.argv[3]
betas = [float(b) for b in np.arange(n_runs) * (360.0 / n_runs)]
st = Settings(zone=2, verbose=1, height=60.0, nh=4, gamma=0.0, beta=0.0, psi=180.0, epsilon=0.0,
              betas=np.array(betas), locations=np.tile([2.0, 1.0, 20.5], (n_runs, 1)))
scan, probe = lj.windcube_v2(), lj.PulsedProbe()
page = os.sysconf("SC_PAGE_SIZE") / 2**20
def rss():
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * page
peak = [0.0]
stop = threading.Event()
def poll():
    while not stop.is_set():
        peak[0] = max(peak[0], rss())
        time.sleep(0.002)
base = rss()
threading.Thread(target=poll, daemon=True).start()
t = time.perf_counter()
load = lambda b: load_field(f"{d}/run_{int(round(b))}.npz")
if mode == "streamed":
    build_table(st, betas, load, scan, probe=probe)
else:
    sims = simulate_settings(st, betas, load, scan, probe=probe)
    lj.ResponseTable.from_simulations(list(sims.values()))
secs = time.perf_counter() - t
stop.set()
time.sleep(0.01)
print(max(peak[0], rss()), base, secs)
"""


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    n = 60 if args.quick else 160
    runs = [4, 12] if args.quick else [4, 12, 24]
    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np

    import lidarjax as lj
    from lidarjax.io import save_field_npz

    rows = []
    with tempfile.TemporaryDirectory() as d:
        x = np.linspace(-200.0, 200.0, n)
        z = np.linspace(0.0, 200.0, n // 2)
        one = lj.GridField.from_function(lj.scenes.hemisphere(20.0, 10.0, 270.0).sample, x, x, z)
        for k in range(max(runs)):
            save_field_npz(Path(d) / f"run_{int(round(k * 360.0 / max(runs)))}.npz", one)
        for r in runs:  # run names must match the betas of r runs
            for k in range(r):
                src = Path(d) / f"run_{int(round(k * 360.0 / max(runs)))}.npz"
                dst = Path(d) / f"run_{int(round(k * 360.0 / r))}.npz"
                if not dst.exists():
                    dst.write_bytes(src.read_bytes())
        run_mb = n * n * (n // 2) * 3 * 8 / 1e6
        for r in runs:
            for mode in ("streamed", "all-at-once"):
                out = subprocess.run([sys.executable, "-c", CHILD, mode, str(r), d], capture_output=True,
                                     text=True, check=True).stdout.split()
                peak, base, _secs = (float(v) for v in out)
                rows.append({"mode": mode, "runs": r, "grid": [n, n, n // 2], "run_MB": run_mb,
                             "peak_MB": peak, "extra_MB": peak - base})
                print(f"{mode:12s} {r:3d} runs of {run_mb:6.1f} MB: peak RSS {peak:7.0f} MB "
                      f"(+{peak - base:6.0f} MB while building the table)")
    res = Path(__file__).parent / "results"
    res.mkdir(exist_ok=True)
    (res / "table_memory.json").write_text(json.dumps({"machine": machine(), "rows": rows}, indent=1))
    lines = ["| runs | run size (MB) | streamed: extra peak (MB) | all-at-once: extra peak (MB) |",
             "|---:|---:|---:|---:|"]
    for r in runs:
        s = next(x for x in rows if x["runs"] == r and x["mode"] == "streamed")
        a = next(x for x in rows if x["runs"] == r and x["mode"] == "all-at-once")
        lines.append(f"| {r} | {s['run_MB']:.0f} | {s['extra_MB']:.0f} | {a['extra_MB']:.0f} |")
    (res / "table_memory.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    plot(rows, res / "table_memory.png")


def plot(rows, path) -> None:
    """Extra peak memory against the number of runs, both ways."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3.5))
    for mode, style in (("streamed", "o-"), ("all-at-once", "s--")):
        sel = [r for r in rows if r["mode"] == mode]
        ax.plot([r["runs"] for r in sel], [r["extra_MB"] for r in sel], style, label=mode)
    ax.set_xlabel("CFD runs in the table")
    ax.set_ylabel("peak memory while building (MB)")
    ax.set_title(f"runs of {rows[0]['run_MB']:.0f} MB ({'x'.join(map(str, rows[0]['grid']))} float64)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)


if __name__ == "__main__":
    if sys.argv[1:] == ["--plot-only"]:
        res = Path(__file__).parent / "results"
        saved = json.loads((res / "table_memory.json").read_text())
        plot(saved["rows"] if isinstance(saved, dict) else saved, res / "table_memory.png")
    else:
        main()
