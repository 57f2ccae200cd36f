"""Write ``docs/benchmarks.md`` from ``benchmarks/results/*.json`` (and the tables the benchmark
scripts write beside them, ``*.md``, and their pictures, ``*.png``).

Run ``python tools/docs/gen_benchmarks.py`` after a benchmark has been rerun;
``tests/test_docs.py`` regenerates the page and fails when the committed one differs, so the
page cannot drift from the results. Each section says how the figure was measured (the
script and what it times), on which machine (read from the JSON's own machine record) and
against which peer.
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

from _page import write_or_check

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "benchmarks" / "results"
PAGE = ROOT / "docs" / "benchmarks.md"

#: One entry per benchmark, in the order of the page: the results' stem, the title, what is
#: timed or measured, the peer it is compared with, and the guide that explains it.
BENCHMARKS = [
    ("forward", "Forward model",
     "`simulate` of a Windcube V2 with the pulsed probe in a (200, 200, 100, 3) field, "
     "compilation timed apart, medians of several runs; at the project's target size (33 nodes x "
     "180 rotations x 50 heights) lidarjax and numba run interleaved",
     "a scipy/numpy pipeline (`RegularGridInterpolator`, projection, DBS) and a fused two-thread "
     "numba loop on the same points", "probe-volumes.md"),
    ("accuracy_vs_time", "Accuracy against time",
     "largest horizontal-speed error of a Windcube V2 with the pulsed probe over 360 sectors x 9 "
     "heights, against the analytic scene with a 257-node probe, for node counts 1-65 and the "
     "automatic choice", "the analytic scene (a closed form) at 257 nodes", "probe-volumes.md"),
    ("probe_nodes", "Probe nodes",
     "distance of the chosen nodes' transfer function from the weighting's, focus ranges "
     "10-300 m, resolutions 2-8 m", "the probes' default node counts and OpenFAST's CW scheme",
     "probe-volumes.md"),
    ("inverse", "Inverse",
     "`lidarjax.invert` on one year of 10-minute records at 12 heights (630,720 problems), "
     "compilation timed apart, medians of repeats; speed and direction errors on synthetic "
     "records with LOS noise 0.1 m/s",
     "`scipy.optimize.least_squares` in a loop on the same model and starts; ZephyCube's scalar "
     "and vector corrections", "records.md"),
    ("correct_year", "Correcting a year of records",
     "`lidarjax correct` on one year of 10-minute records at 12 heights, in a fresh process "
     "(read, corrected, CSV and NetCDF written), cold and warm compilation cache",
     "the target of 10 s and 1 GB", "records.md"),
    ("read_records", "Reading records", "the record readers on generated files of a year",
     "the earlier readers", "records.md"),
    ("calibration", "Joint inversion and calibration",
     "coverage of the calibration's intervals over synthetic campaigns, joint against "
     "per-height errors, one-year timings", "per-height `invert`; the true offsets",
     "calibration.md"),
    ("calibration_coverage", "Calibration coverage",
     "95 % interval coverage of `calibrate` over campaigns written by `simulate` itself "
     "(tilted and turned mounts in shear, on a ridge, on a roof, in an OpenFOAM case)",
     "the true offsets of the simulated campaigns", "calibration.md"),
    ("calibration_coverage_seed31", "Calibration coverage, second draw",
     "as above, a second random draw of campaigns", "the true offsets", "calibration.md"),
    ("calibration_year", "Calibration of a year",
     "`calibrate` on one year of 10-minute records at 12 heights, with and without a "
     "reference, first order and iterating on the exact geometry, compilation included",
     "the true offsets", "calibration.md"),
    ("cfd_ingest", "CFD ingestion",
     "loading graded hemisphere meshes of 0.1-5M cells in a lidar's region: time, peak memory, "
     "speed error", "the targets (120 s, 8 GB) and the earlier whole-domain Delaunay path",
     "cfd.md"),
    ("cfd_ingest_vtk", "CFD ingestion, VTK", "the same through VTK files", "the OpenFOAM path",
     "cfd.md"),
    ("cfd_ingest_windAroundBuildings", "OpenFOAM windAroundBuildings",
     "LOS of lidars on a roof and in a street of the 185k-cell case", "OpenFOAM's own `probes`",
     "cfd.md"),
    ("exact_paths", "Exact paths on a mesh",
     "cost of each snapshot of a sequence exact at a Windcube V2's pulsed-probe nodes, and of "
     "`lidarjax table` exact at every node", "reading the snapshot's binary velocity file; the "
     "table through the graded grid", "cfd.md"),
    ("table_memory", "Table memory", "peak memory of `lidarjax table` over 4-24 runs of 49 MB",
     "the earlier loader that held every run", "cfd.md"),
    ("snapshots", "Snapshot sequences",
     "time per OpenFOAM snapshot once the grid is located in the mesh",
     "locating every snapshot afresh", "time-series.md"),
    ("sensitivity", "Sensitivity and uncertainty",
     "the gradient uncertainty budget of a platform and a hill lidar",
     "a mocalum-style Monte Carlo loop of the numpy/scipy pipeline (5000 samples, 1 % accuracy)",
     "sensitivity.md"),
    ("design", "Design by gradients",
     "`design_placement` and `design_dual_doppler`, timed from a cold start in the same run",
     "a grid search of the same objective", "design.md"),
    ("series", "Time series throughput",
     "`simulate_statistics` of a Windcube V2 with the pulsed probe at 12 heights through a Mann "
     "box, 10-minute records per second; one year measured whole",
     "numpy/scipy with the same sampling, and numpy with lidarjax's per-point lines",
     "time-series.md"),
    ("series_quick", "Time series throughput, quick run", "as above, the quick settings",
     "as above", "time-series.md"),
    ("turbulence_spectral", "Lidar turbulence against the spectral model",
     "lidar/point variance ratios in Mann turbulence and 10-minute statistics of 48 boxes",
     "lidarjax's spectral model (`lidar_variance_ratio`)", "time-series.md"),
    ("turbulence_spectral_quick", "Lidar turbulence, quick run", "as above, the quick settings",
     "as above", "time-series.md"),
    ("scanning", "Scanning lidars",
     "a 360-ray x 200-gate PPI in a 200 x 200 x 100 grid, and 10 minutes of 1 Hz rays through a "
     "Mann box, the whole `simulate_scan` / `simulate_scan_series` call",
     "numpy integrating the very same quadrature (`lidarjax.gate_nodes`)", "scanning.md"),
    ("scanning_h100", "Scanning lidars on a GPU", "as above, on a GPU", "as above",
     "scanning.md"),
    ("farm", "Wind farms",
     "100 turbines x 360 directions at a V2's pulsed beam points, forward and gradient",
     "FLORIS 4.7", "wind-farms.md"),
    ("lac", "Lidar-assisted control",
     "Task 52's lidar-rotor spectra and filter cut-offs reproduced at all 1024 frequencies; the "
     "analytic coherence at 500 frequencies for a 709-point rotor and an 88-node lidar after "
     "compilation; a scan design by gradients against a dense grid search, and Fu et al.'s "
     "spinner case", "IEA Wind Task 52's published analytic spectra and FFP inputs, a numpy "
     "implementation of the same sums, a 30 x 30 grid search", "lidar-assisted-control.md"),
    ("lac_fu", "Lidar-assisted control beside Fu et al. 2023",
     "the optimal scan radius of a single-beam spinner CW lidar on the IEA 15 MW with one "
     "assumption changed at a time (turbulence model, mean wind, intensity, objective, probe, "
     "scan points and timing, rotor weighting, focus distance)",
     "Fu et al. 2023 (WES 8, 1893): 0.6 R", "lidar-assisted-control.md"),
    ("lac_time_domain", "Lidar-assisted control in the time domain",
     "REWS and its lidar estimate simulated over 1 and 6 hours through a Kaimal/IEC-coherence "
     "field (Veers' method with frozen-turbulence leads), Welch coherence against the analytic "
     "model in every bin up to the coherence bandwidth",
     "`lidarjax.control.lac_spectra`, the analytic model the Task 52 comparison validates",
     "lidar-assisted-control.md"),
    ("mount", "Mount construction",
     "`Mount(locations, beta=betas)` for 10,000 platform rotations from numpy arrays, JAX "
     "arrays, lists and tuples, medians of 31 alternating calls",
     "the same constructor at commit 1d75568 (before the tracer-in-a-tuple fix) and at df8d71b, "
     "loaded with `git show` into the same process", "conventions.md"),
    ("stability", "Numerical stability",
     "random scenes (speeds 0-60 m/s, cones 5-60 degrees, UTM offsets, float32 and float64): "
     "finite-or-flagged outputs and finite gradients; conditioning; bad records",
     "closed forms and float64", "stability.md"),
]


def machine(doc) -> str:
    """One line naming the machine a result was measured on, from its own record."""
    found = None
    if isinstance(doc, dict):
        found = doc.get("machine")
        if found is None and isinstance(doc.get("meta"), dict):
            found = doc["meta"].get("machine", None)
        if found is None and isinstance(doc.get("runs"), (list, dict)):
            runs = doc["runs"]
            first = runs[0] if isinstance(runs, list) else next(iter(runs.values()), None)
            found = first.get("machine") if isinstance(first, dict) else None
    elif isinstance(doc, list) and doc and isinstance(doc[0], dict):
        found = doc[0].get("machine")
    if isinstance(found, dict):
        device = found.get("device") or found.get("jax_backend") or found.get("backend", "?")
        device = "CPU" if device == "cpu" else device
        parts = [f"{found['cpus']} CPU cores" if "cpus" in found else None, device,
                 f"jax {found['jax']}" if "jax" in found else None,
                 f"Python {found['python']}" if "python" in found else None]
        return ", ".join(p for p in parts if p)
    if isinstance(found, str) and found:
        return found
    return "not recorded in the JSON (the project's 2-core CPU machine, see the table below)"


def table_of(stem: str) -> str:
    """The benchmark's own Markdown (its title dropped, its headings demoted below ours)."""
    path = RESULTS / f"{stem}.md"
    if not path.exists():
        return ""
    lines = path.read_text().strip().splitlines()
    if lines and lines[0].startswith("# "):
        lines = lines[1:]
    out = []
    for line in lines:
        if re.match(r"#{1,3} ", line):
            line = "####" + line.lstrip("#")
        out.append(line)
    text = "\n".join(out).strip()
    # links between result files point at this page's sections
    return re.sub(r"\]\((?:\.\./)*(?:benchmarks/results/)?(\w+)\.md\)", r"](#\1)", text)


def section(stem, title, what, peer, guide) -> str:
    doc = json.loads((RESULTS / f"{stem}.json").read_text())
    script = ROOT / "benchmarks" / f"{stem}.py"
    base = stem.replace("_quick", "").replace("_seed31", "").replace("_h100", "")
    base = {"cfd_ingest_vtk": "cfd_ingest", "cfd_ingest_windAroundBuildings": "cfd_ingest"}.get(
        base, base)
    runner = f"`python benchmarks/{base}.py`" if (ROOT / "benchmarks" / f"{base}.py").exists() \
        else "a benchmark script"
    if script.exists():
        runner = f"`python benchmarks/{stem}.py`"
    parts = [f"## {title} {{#{stem}}}", "",
             f"- **Measured:** {what}; by {runner}, results in "
             f"[`benchmarks/results/{stem}.json`](benchmarks/results/{stem}.json).",
             f"- **Machine:** {machine(doc)}.",
             f"- **Against:** {peer}.",
             f"- **Guide:** [{guide.removesuffix('.md')}]({guide}).", ""]
    table = table_of(stem)
    if table:
        parts += [table, ""]
    if (RESULTS / f"{stem}.png").exists():
        parts += [f"![{title}](benchmarks/results/{stem}.png)", ""]
    return "\n".join(parts)


def render() -> str:
    listed = {b[0] for b in BENCHMARKS}
    stems = {p.stem for p in RESULTS.glob("*.json")}
    missing = sorted(stems - listed)
    if missing:
        raise SystemExit(f"gen_benchmarks: results without an entry in BENCHMARKS: {missing}; "
                         "add them (title, what is measured, peer, guide)")
    head = [
        "# Benchmarks", "",
        "<!-- generated by tools/docs/gen_benchmarks.py from benchmarks/results/*.json; "
        "do not edit by hand -->", "",
        "Every figure below was measured by a script in `benchmarks/`, which writes its JSON "
        "(with a record of the machine), a Markdown table and a picture to "
        "`benchmarks/results/`. Unless a section says otherwise the machine is a shared 2-core "
        "x86-64 CPU virtual machine; timings on it swing with the load of other jobs, so the "
        "tables give medians of repeats and compare implementations run in the same process. "
        "Compilation is timed apart unless stated.", "",
        "| benchmark | against |", "|---|---|",
    ]
    head += [f"| [{t}](#{s}) | {p} |" for s, t, _, p, _ in BENCHMARKS if (RESULTS / f"{s}.json").exists()]
    body = [section(*b) for b in BENCHMARKS if (RESULTS / f"{b[0]}.json").exists()]
    return "\n".join(head) + "\n\n" + "\n".join(body).rstrip() + "\n"


def main(argv: list[str] | None = None) -> int:
    return write_or_check(PAGE, render, argv)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
