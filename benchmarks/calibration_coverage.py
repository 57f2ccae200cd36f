"""Validation of `lidarjax.calibrate` against campaigns written by `lidarjax.simulate` (issue 29).

The records come from `lidarjax.simulate` with truly tilted and turned `lidarjax.Mount`s
(pitch and roll uniform in +-2 degrees, a north offset uniform in +-10 degrees made by
turning the lidar with `gamma`, drawn per campaign) in flows that vary in space: power-law
shear over flat ground, a ridge (lidar on and beside the crest), the hemisphere platform
(lidar on its roof) and the committed OpenFOAM turbineSiting case; plus a uniform flow as
the control, where the tilt moves no measurement point into another velocity. Each record has
its own free stream (speed uniform in 4-14 m/s, direction in [0, 360)), LOS noise 0.1 m/s.
The table is `simulate` at the nominal installation every 10 degrees
(`ResponseTable.from_simulations`). The generator is tests/_campaign_spatial.py; nothing in
it shares `calibrate`'s model (its first-order tilt term, the direction shift, gradients).

Per setting and offset: coverage of the 95 % intervals ``offset +- 1.96 std`` (target
93-97 %), mean and sd of ``z = (estimate - truth) / std`` (target |mean z| < 0.2), and the
mean of ``z * sign(truth)``: a bias proportional to the offset (what neglecting the
displacement gives) cancels in the plain mean when the offsets are drawn symmetric about
zero, and shows in this one. With a reference (epsilon, pitch, roll) and without (pitch,
roll; epsilon is not identifiable).

``--label`` names the model the run measured (``before``: main's `calibrate`, which
neglects the displacement of the measurement points; ``after``: with it); results of other
labels already in the JSON are kept, so the markdown table shows both. The same seed gives
the same campaigns. The tables carry the flow's gradient along the beams (issue 29's
`beam_gradient`) when this checkout's `ResponseTable.from_simulations` takes it from the
fields; the JSON says whether they did.

Writes benchmarks/results/calibration_coverage.{json,md,png}. Run from a checkout:
``python3 benchmarks/calibration_coverage.py --label before [--campaigns 200] [--records 400]
[--settings power_law,hill_crest]``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # benchmark this checkout, and reach tests/_campaign_spatial.py

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
from _common import machine, machine_line  # noqa: E402

from tests import _campaign_spatial as cs  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"
SETTINGS = ("uniform",) + cs.SETTINGS


def _commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                              capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def run_setting(name: str, n_campaigns: int, n_records: int, seed: int,
                chunk: int = 50, exact: bool = False) -> dict:
    t0 = time.perf_counter()
    s = cs.setting(name)
    table = cs.table(s)
    runs = cs.runs(s) if exact else None
    gradient = getattr(table, "beam_gradient", None) is not None
    t_table = time.perf_counter() - t0
    rng = np.random.default_rng([seed, SETTINGS.index(name)])
    out = {"heights_m": s.heights.tolist(), "location_m": s.location.tolist(),
           "gradient": gradient}
    parts = {True: [], False: []}
    t_sim = t_cal = 0.0
    for start in range(0, n_campaigns, chunk):
        c = min(chunk, n_campaigns - start)
        t = time.perf_counter()
        camp = cs.campaigns(s, rng, c, n_records)
        t_sim += time.perf_counter() - t
        t = time.perf_counter()
        for ref in (True, False):
            parts[ref].append(cs.estimate(table, camp, reference=ref, runs=runs))
        t_cal += time.perf_counter() - t
    for ref, key in ((True, "reference"), (False, "no_reference")):
        res = {k: np.concatenate([p[k] for p in parts[ref]]) for k in
               ("estimate", "std", "truth", "z", "converged", "rebuilds")}
        summ = cs.summary(res["z"], res["truth"])
        summ["names"] = parts[ref][0]["names"]
        summ["converged"] = float(np.mean(res["converged"]))
        summ["rebuilds_mean"] = float(np.mean(res["rebuilds"]))
        summ["max_abs_error_deg"] = np.max(np.abs(res["estimate"] - res["truth"]), 0).tolist()
        summ["median_std_deg"] = np.median(res["std"], 0).tolist()
        out[key] = summ
    out["seconds"] = {"table": t_table, "simulate": t_sim, "calibrate": t_cal}
    return out


def markdown(data: dict) -> str:
    order = ("before", "after", "exact")
    labels = [x for x in order if x in data["runs"]] + sorted(
        x for x in data["runs"] if x not in order)
    first = data["runs"][labels[0]]
    lines = ["# Calibration against campaigns written by `simulate` "
             "(benchmarks/calibration_coverage.py)", ""]
    for lab in labels:
        r = data["runs"][lab]
        lines.append(f"- **{lab}**: {r['model']} (commit {r['commit']}, tables with gradient: "
                     f"{r['gradient']}); {r['campaigns']} campaigns x {r['records']} records "
                     f"x 3 heights per setting; {machine_line(r['machine'])}")
    lines += ["", "Truth: pitch and roll uniform in +-2 deg, north offset (gamma) in +-10 deg "
              "per campaign; per record speed 4-14 m/s, direction 0-360; LOS noise 0.1 m/s. "
              "Targets: coverage of 95 % intervals 93-97 %, |mean z| < 0.2. `z.sgn` is the "
              "mean of z * sign(truth), a bias proportional to the offset.", ""]
    head = "| setting | offset | " + " | ".join(
        f"{lab} coverage | {lab} mean z | {lab} sd z | {lab} z.sgn" for lab in labels) + " |"
    lines += [head, "|" + "---|" * (2 + 4 * len(labels))]
    for name in first["settings"]:
        for key, tag in (("reference", "ref"), ("no_reference", "no ref")):
            for j, off in enumerate(first["settings"][name][key]["names"]):
                cells = []
                for lab in labels:
                    st = data["runs"][lab]["settings"].get(name)
                    if st is None:
                        cells += ["", "", "", ""]
                        continue
                    sm = st[key]
                    cov = sm["coverage"][j]
                    mark = "" if 0.93 <= cov <= 0.97 else "**"
                    mz = sm["mean_z"][j]
                    mmark = "" if abs(mz) < 0.2 else "**"
                    cells += [f"{mark}{cov:.3f}{mark}", f"{mmark}{mz:+.2f}{mmark}",
                              f"{sm['sd_z'][j]:.2f}", f"{sm['mean_z_signed'][j]:+.2f}"]
                lines.append(f"| {name} | {off} ({tag}) | " + " | ".join(cells) + " |")
    lines += ["", "Campaigns whose calibration reports `converged` (with / without a "
              "reference):", ""]
    for lab in labels:
        st = data["runs"][lab]["settings"]
        lines.append(f"- {lab}: " + ", ".join(
            f"{n} {st[n]['reference']['converged']:.3f} / {st[n]['no_reference']['converged']:.3f}"
            for n in st))
        reb = [(n, st[n]["reference"].get("rebuilds_mean"), st[n]["no_reference"].get(
            "rebuilds_mean")) for n in st]
        if any(a for _, a, _ in reb):
            lines.append(f"  - {lab}, mean rebuilds of the table at the estimate (with / "
                         "without): " + ", ".join(f"{n} {a:.2f} / {b:.2f}" for n, a, b in reb))
    lines += ["", "Bold: outside the target. Largest |estimate - truth| and the median "
              "standard error (deg), last run:", ""]
    last = data["runs"][labels[-1]]
    for name, st in last["settings"].items():
        for key in ("reference", "no_reference"):
            sm = st[key]
            errs = ", ".join(f"{n} {e:.3f}/{s:.3f}" for n, e, s in zip(
                sm["names"], sm["max_abs_error_deg"], sm["median_std_deg"], strict=True))
            lines.append(f"- {name}, {key.replace('_', ' ')}: {errs}")
    return "\n".join(lines) + "\n"


def plot(data: dict, path: Path) -> None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    labels = [x for x in ("before", "after", "exact") if x in data["runs"]]
    if not labels:
        return
    first = data["runs"][labels[0]]["settings"]
    rows = [(n, k, j, off) for n in first for k in ("reference", "no_reference")
            for j, off in enumerate(first[n][k]["names"])]
    fig, ax = plt.subplots(figsize=(10, 4.5))
    x = np.arange(len(rows))
    for i, lab in enumerate(labels):
        st = data["runs"][lab]["settings"]
        cov = [st[n][k]["coverage"][j] if n in st else np.nan for n, k, j, _ in rows]
        width = 0.8 / len(labels)
        ax.bar(x + (i - 0.5 * (len(labels) - 1)) * width, cov, width, label=lab)
    ax.axhspan(0.93, 0.97, color="g", alpha=0.2, label="target 93-97 %")
    ax.set_xticks(x, [f"{n}\n{off}{'' if k == 'reference' else ' (no ref)'}"
                      for n, k, _, off in rows], rotation=90, fontsize=7)
    ax.set_ylabel("coverage of 95 % intervals")
    ax.set_ylim(0, 1)
    ax.legend(loc="lower left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--campaigns", type=int, default=200)
    p.add_argument("--records", type=int, default=400)
    p.add_argument("--settings", default=",".join(SETTINGS))
    p.add_argument("--label", default="before")
    p.add_argument("--model", default=None, help="words naming the calibrate model measured")
    p.add_argument("--seed", type=int, default=29)
    p.add_argument("--exact", action="store_true",
                   help="calibrate with the table's runs (lidarjax.TableRuns): iterate on the "
                        "exact geometry")
    p.add_argument("--out", default=str(RESULTS / "calibration_coverage.json"))
    p.add_argument("--report", action="store_true",
                   help="only rewrite the markdown and png from the JSON")
    a = p.parse_args(argv)
    if a.report:
        data = json.loads(Path(a.out).read_text())
        Path(a.out).with_suffix(".md").write_text(markdown(data))
        plot(data, Path(a.out).with_suffix(".png"))
        print(markdown(data))
        return
    names = [x for x in a.settings.split(",") if x]
    bad = [x for x in names if x not in SETTINGS]
    if bad:
        raise SystemExit(f"unknown settings {bad}; choose among {SETTINGS}")
    out = Path(a.out)
    data = json.loads(out.read_text()) if out.exists() else {"runs": {}}
    run = {"model": a.model or ("main's calibrate: neglects the displacement of the "
                                "measurement points" if a.label == "before" else a.label),
           "commit": _commit(), "campaigns": a.campaigns,
           "records": a.records, "seed": a.seed, "machine": machine(), "settings": {}}
    old = data["runs"].get(a.label, {}).get("settings", {})
    for name in SETTINGS:  # keep this label's other settings from an earlier partial run
        if name in old and name not in names:
            run["settings"][name] = old[name]
    for name in names:
        t = time.perf_counter()
        res = run_setting(name, a.campaigns, a.records, a.seed, exact=a.exact)
        run["settings"][name] = res
        run["gradient"] = bool(res["gradient"])
        cov = {k: dict(zip(res[k]["names"], np.round(res[k]["coverage"], 3).tolist(),
                           strict=True)) for k in ("reference", "no_reference")}
        print(f"{name}: {time.perf_counter() - t:.1f} s, coverage {cov}", flush=True)
    run["settings"] = {n: run["settings"][n] for n in SETTINGS if n in run["settings"]}
    data["runs"][a.label] = run
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(data, indent=1) + "\n")
    out.with_suffix(".md").write_text(markdown(data))
    plot(data, out.with_suffix(".png"))
    print(markdown(data))


if __name__ == "__main__":
    main()
