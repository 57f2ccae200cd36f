"""Building a batched `lidarjax.Mount` of 10,000 platform rotations, against its baseline.

``Mount(locations, beta=betas, psi=180.0)`` with 10,000 mounts given as numpy arrays, JAX
arrays, one shared location, nested lists and tuples (issue 37: 140 ms where commit 1d75568
took 55-72 ms; the goal is at most 100 ms). The baseline is the `Mount` of commit 1d75568
itself, read with ``git show`` and loaded beside the current one (and, for the record, that
of df8d71b, the last commit before the fix), so all run in one process on one machine; the
calls alternate, and each figure is the median of the repeats after one untimed call.
Writes benchmarks/results/mount.json and .md.

    python3 benchmarks/mount.py [--repeats N]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from _common import machine, machine_line  # noqa: E402

import lidarjax as lj

BASELINE_COMMIT = "1d75568"
#: The last commit before the fix of issue 37 (the regression, for the record).
REGRESSED_COMMIT = "df8d71b"
N = 10_000
GOAL_S = 0.100
REPO = Path(__file__).resolve().parent.parent


def mount_at(commit: str):
    """The `Mount` class of `commit` (its lidarjax/mount.py, loaded as a module of the current
    package so that its relative imports resolve)."""
    source = subprocess.run(["git", "-C", str(REPO), "show", f"{commit}:lidarjax/mount.py"],
                            check=True, capture_output=True, text=True).stdout
    name = f"lidarjax._mount_{commit}"
    spec = importlib.util.spec_from_loader(name, loader=None)
    module = importlib.util.module_from_spec(spec)
    module.__package__ = "lidarjax"
    sys.modules[name] = module
    exec(compile(source, f"{commit}:lidarjax/mount.py", "exec"), module.__dict__)
    return module.Mount


def cases(n: int = N) -> dict:
    """Each case's ``(locations, betas)``: 10,000 rotations of a lidar moved along a line."""
    betas = np.linspace(0.0, 360.0, n, endpoint=False)
    locs = np.tile([12.0, -7.0, 31.0], (n, 1)) + np.linspace(0.0, 1.0, n)[:, None]
    return {
        "numpy arrays": (locs, betas),
        "JAX arrays": (jnp.asarray(locs), jnp.asarray(betas)),
        "one location, numpy betas": (locs[0], betas),
        "lists": (locs.tolist(), betas.tolist()),
        "tuples": (tuple(map(tuple, locs.tolist())), tuple(betas.tolist())),
    }


def medians(builders: dict, locs, betas, repeats: int) -> dict:
    """Median seconds of each builder on one case, the builders' calls alternating."""
    times = {k: [] for k in builders}
    for build in builders.values():
        jax.block_until_ready(build(locs, beta=betas, psi=180.0))
    for _ in range(repeats):
        for k, build in builders.items():
            t = time.perf_counter()
            jax.block_until_ready(build(locs, beta=betas, psi=180.0))
            times[k].append(time.perf_counter() - t)
    return {k: float(np.median(v)) for k, v in times.items()}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=21)
    args = ap.parse_args()
    builders = {"current": lj.Mount, BASELINE_COMMIT: mount_at(BASELINE_COMMIT),
                REGRESSED_COMMIT: mount_at(REGRESSED_COMMIT)}
    results = {"machine": machine(), "n_mounts": N, "repeats": args.repeats,
               "baseline": BASELINE_COMMIT, "goal_s": GOAL_S, "cases": {}}
    for label, (locs, betas) in cases().items():
        m = medians(builders, locs, betas, args.repeats)
        entry = {"current_s": m["current"], "baseline_s": m[BASELINE_COMMIT],
                 "before_fix_s": m[REGRESSED_COMMIT],
                 "ratio_current_over_baseline": m["current"] / m[BASELINE_COMMIT]}
        results["cases"][label] = entry
        print(label, json.dumps(entry))
    results["load_average"] = list(os.getloadavg())  # other work sharing the CPUs
    out = Path(__file__).parent / "results"
    out.mkdir(exist_ok=True)
    (out / "mount.json").write_text(json.dumps(results, indent=2) + "\n")
    rows = [f"`Mount(locations, beta=betas, psi=180.0)`, {N:,} mounts, median of "
            f"{args.repeats} (ms); {machine_line(results['machine'])}; load average "
            f"{results['load_average'][0]:.1f} (figures of a few ms are at the noise level of "
            "a loaded machine)", "",
            f"| input | current | {BASELINE_COMMIT} (baseline) | {REGRESSED_COMMIT} (before the "
            "fix) | current / baseline |", "|---|---:|---:|---:|---:|"]
    for label, e in results["cases"].items():
        rows.append(f"| {label} | {1e3 * e['current_s']:.1f} | {1e3 * e['baseline_s']:.1f} | "
                    f"{1e3 * e['before_fix_s']:.1f} | {e['ratio_current_over_baseline']:.2f} |")
    (out / "mount.md").write_text("\n".join(rows) + "\n")


if __name__ == "__main__":
    main()
