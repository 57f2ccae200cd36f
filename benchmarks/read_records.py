"""Reading speed and peak memory of `read_sta` on large Windcube `.sta` files.

One year of 10-minute records at 12 heights (52,560 rows) and 200,000 rows; each read runs in
a fresh subprocess so that its peak resident memory (ru_maxrss) is its own. Baseline, side by
side: pandas' C CSV parser on the same file (values only, no header facts, no flags), when
pandas is installed. Writes benchmarks/results/read_records.json and .md.

    python3 benchmarks/read_records.py [--quick]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _common import machine  # noqa: E402

CHILD = r"""
import sys, time
kind, path = sys.argv[1], sys.argv[2]
if kind == "read_sta":
    from lidarjax.io import read_sta  # imported before the clock starts (jax import excluded)
else:
    import pandas as pd
BASE = int([ln for ln in open("/proc/self/status") if ln.startswith("VmRSS")][0].split()[1])
t0 = time.perf_counter()
if kind == "read_sta":
    r = read_sta(path)
    n = r.time.size
else:
    df = pd.read_csv(path, sep="\t", skiprows=11, encoding="cp1252")
    n = len(df)
dt = time.perf_counter() - t0
# VmHWM: this process's peak resident memory (ru_maxrss would include the parent's, kept
# across exec), minus the resident size before reading (interpreter + imports)
hwm = [ln for ln in open("/proc/self/status") if ln.startswith("VmHWM")][0].split()[1]
print(n, dt, int(hwm) / 1024, BASE / 1024)
"""


def make(path: Path, n: int, k: int = 12) -> None:
    from lidarjax.io import write_sta

    t = np.datetime64("2023-01-01T00:10") + np.arange(n) * np.timedelta64(10, "m")
    rng = np.random.default_rng(0)
    write_sta(path, t, 40 + 20 * np.arange(k), rng.uniform(2, 15, (n, k)),
              rng.uniform(0, 360, (n, k)), w=rng.normal(0, 0.1, (n, k)),
              speed_std=np.full((n, k), 0.5), availability=np.full((n, k), 100.0))


def run(kind: str, path: Path, repeat: int) -> dict:
    times, mem, base = [], [], []
    for _ in range(repeat):
        out = subprocess.run([sys.executable, "-c", CHILD, kind, str(path)], check=True,
                             capture_output=True, text=True).stdout.split()
        times.append(float(out[1]))
        mem.append(float(out[2]))
        base.append(float(out[3]))
    return {"rows": int(out[0]), "median_s": float(np.median(times)),
            "peak_rss_mb": float(np.median(mem)),
            "rss_before_read_mb": float(np.median(base))}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="smaller files, one repeat")
    args = ap.parse_args()
    sizes = {"month": 4320} if args.quick else {"year": 52_560, "200k": 200_000}
    repeat = 1 if args.quick else 2
    try:
        import pandas  # noqa: F401
        baselines = ["pandas_read_csv"]
    except ImportError:
        baselines = []
    results = {"machine": machine(), "runs": {}}
    with tempfile.TemporaryDirectory() as d:
        for label, n in sizes.items():
            path = Path(d) / f"{label}.sta"
            t0 = time.perf_counter()
            make(path, n)
            entry = {"write_sta_s": time.perf_counter() - t0,
                     "file_mb": path.stat().st_size / 2**20}
            for kind in ["read_sta", *baselines]:
                entry[kind] = run(kind, path, repeat)
            if baselines:
                entry["ratio_read_sta_over_pandas"] = (entry["read_sta"]["median_s"]
                                                       / entry["pandas_read_csv"]["median_s"])
            results["runs"][label] = entry
            print(label, json.dumps(entry))
    out = Path(__file__).parent / "results"
    out.mkdir(exist_ok=True)
    name = "read_records_quick" if args.quick else "read_records"
    (out / f"{name}.json").write_text(json.dumps(results, indent=2) + "\n")
    rows = ["| file | rows | read_sta (s) | peak RSS (MB) (of which before reading) | "
            "pandas read_csv (s) | write_sta (s) |", "|---|---|---|---|---|---|"]
    for label, e in results["runs"].items():
        pd_s = f"{e['pandas_read_csv']['median_s']:.2f}" if baselines else "n/a"
        rows.append(f"| {label} | {e['read_sta']['rows']} | {e['read_sta']['median_s']:.2f} | "
                    f"{e['read_sta']['peak_rss_mb']:.0f} "
                    f"({e['read_sta']['rss_before_read_mb']:.0f}) | {pd_s} | "
                    f"{e['write_sta_s']:.1f} |")
    (out / f"{name}.md").write_text("\n".join(rows) + "\n")


if __name__ == "__main__":
    main()
