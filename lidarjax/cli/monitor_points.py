"""`lidarjax monitor-points`: let the CFD code sample the lidar's points itself, then read them back.

Writing (default): the beam focus points or probe-volume nodes of every selected mount, and
the column above the lidar, as an OpenFOAM ``probes`` function object, a zCFD probe file
and CSV. Reading (``--sampled``): the CFD code's samples (OpenFOAM ``postProcessing`` or
CSV ``name,u,v,w``) through the forward model, written as `lidarjax simulate` writes.

The command was called ``probes`` before 0.2; that name still works, with a one-line
deprecation note on stderr.

The points are `lidarjax.monitor_points`, the simulation `lidarjax.simulate_from_monitor_points`
and the result files `lidarjax.write_seed_results`; this module parses and prints.
"""

from __future__ import annotations

import argparse
import sys
import types
from pathlib import Path

import numpy as np

from ..forward import probe_for_field
from ..io import read_settings
from ..io.fields import check_field_file, load_field
from ..io.monitor_points import (
    read_monitor_values_csv,
    read_openfoam_probes,
    write_monitor_points_csv,
    write_openfoam_probes,
    write_zcfd_probes,
)
from ..workflows.monitor_points import monitor_points, simulate_from_monitor_points
from ..workflows.seed_results import write_seed_results
from ..workflows.seed_tables import settings_mount, settings_probes, table_region
from ._common import (
    add_beta_arguments,
    add_command,
    add_probe_arguments,
    add_settings_argument,
    add_tilt_arguments,
    field_input,
    field_paths,
    finite_float,
    input_path,
    make_probe,
    make_scan,
    positive_float,
    positive_int,
    selected_betas,
    vector,
)

SCAN_CHOICES = ("windcube_v1", "windcube_v2", "zephir")


def _heights(text: str) -> list[float]:
    try:
        values = [float(v) for v in text.replace(" ", "").split(",") if v]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected heights in metres 'h1,h2,...', got {text!r}") from None
    if not values or any(not v > 0 for v in values):
        raise argparse.ArgumentTypeError(f"heights must be positive metres, got {text!r}")
    return values


def register(sub) -> None:
    pr = add_command(
        sub, "monitor-points", run,
        "write the lidar's sample points as CFD monitor points (OpenFOAM probes, zCFD, "
        "CSV), "
        "or simulate from the CFD code's samples (--sampled)",
        "Write the beam focus points (or probe-volume quadrature nodes) and the "
        "point-reference column of every selected mount of a seed settings.dat as "
        "an OpenFOAM probes function object (<out>/<name>), a zCFD probe file "
        "(<out>/<name>_zcfd.py, turb_probe layout) and CSV (<out>/<name>.csv). "
        "Each probe is named <mount>_h<height>_beam<b>_q<node>. With --field CFD "
        "the nodes are those 'lidarjax simulate --field CFD' samples, every beta "
        "its own (one points list: each mount's points in turn). With --sampled, "
        "read the values the CFD code sampled there instead (checked rotation "
        "by rotation against the points these options give) and write the seed "
        "output files, as 'lidarjax simulate' does.",
        epilog="example: lidarjax monitor-points settings.dat --all --scan windcube_v2 --probe pulsed "
        "--field 'runs/b{beta}' --out probes/ ; cp probes/lidarProbes case/system/ ; "
        "(cd case && postProcess -func lidarProbes -latestTime) ; lidarjax monitor-points "
        "settings.dat --all --scan windcube_v2 --probe pulsed --field 'runs/b{beta}' "
        "--sampled case/postProcessing/lidarProbes --out results/",
        aliases=["probes"],
        raw=True)
    add_settings_argument(pr)
    add_beta_arguments(pr, beta_help="platform rotation (default: the settings file's beta)",
                       all_help="every beta row of the settings")
    pr.add_argument("--scan", choices=SCAN_CHOICES, default="windcube_v2")
    add_tilt_arguments(pr)
    pr.add_argument("--cone-angle", type=positive_float, default=None,
                    help="cone angle in degrees (default: the scan's)")
    pr.add_argument("--heights", type=_heights, default=None,
                    help="heights above the lidar, metres, 'h1,h2,...' (default: the "
                         "settings' j * height / nh)")
    add_probe_arguments(pr)
    nodes = pr.add_mutually_exclusive_group()
    nodes.add_argument("--field", default=None, metavar="CFD", type=field_input,
                       help="the CFD run(s) `lidarjax simulate --field` would read ('{beta}' "
                            "for several betas): the probe's nodes are chosen for its "
                            "resolution as simulate chooses them, so both routes sample the "
                            "same nodes; each beta gets its own node counts per height (a "
                            "mesh's rotations whose beams see other cells get other counts). "
                            "Give it again with --sampled: the file must hold every beta's "
                            "nodes")
    nodes.add_argument("--resolution", type=positive_float, default=None, metavar="M",
                       help="the CFD grid's resolution in metres (what simulate reports as the "
                            "field's spacing): the nodes simulate would choose for it")
    pr.add_argument("--name", default="lidarProbes",
                    help="function-object name and file stem (default lidarProbes)")
    pr.add_argument("--frequency", type=positive_int, default=100,
                    help="zCFD report frequency, solver cycles (default 100)")
    pr.add_argument("--sampled", default=None, type=input_path,
                    help="read mode: OpenFOAM probes output (postProcessing/<name>, a time "
                         "folder or its U file) or a CSV with columns name,u,v,w")
    pr.add_argument("--time", type=finite_float, default=None,
                    help="read mode: the sampled time to use (default: the latest)")
    pr.add_argument("--u-ref", type=vector, default=(-15.0, 0.0, 0.0),
                    help="read mode: free stream u,v,w in the CFD frame, m/s (default -15,0,0)")
    pr.add_argument("--out", required=True, help="output folder")


def _configuration(args):
    settings = read_settings(args.settings)
    betas = selected_betas(args, settings)
    for b in betas:
        settings.location(b)  # a ValueError naming the missing row
    heights = np.asarray(args.heights if args.heights is not None else settings.heights())
    scan = make_scan(args.scan, args.cone_angle, tilt_compensation=args.tilt_compensation)
    probes = _simulate_nodes(args, settings, betas, heights, scan, make_probe(args))
    # the installation's tilt moves every beam's points, as `lidarjax simulate --pitch/--roll`
    mounts = settings_mount(settings, betas, pitch=args.pitch, roll=args.roll)
    locs = monitor_points(scan, mounts, heights, probes)
    return settings, betas, heights, scan, probes, mounts, locs


def _counts(probe) -> str:
    """A probe's node counts per height, 'n1/n2/...' (one number where all heights share it)."""
    if probe is None:
        return "1"
    counts = getattr(probe, "node_counts", (probe.n_nodes,))
    return "/".join(map(str, counts)) if len(set(counts)) > 1 else str(counts[0])


def _simulate_nodes(args, settings, betas, heights, scan, probe) -> list:
    """The probe of every beta (in order) with the nodes `lidarjax simulate` uses: chosen for
    --field's (or --resolution's) grid as simulate chooses them (`settings_probes`: each
    beta's run read over the region simulate reads, batched as simulate batches it; a mesh's
    rotations get each their own node counts per height), or the probe as given (a note on
    stderr where simulate would choose others)."""
    if args.field is None and args.resolution is None:
        if probe is not None and getattr(probe, "auto_nodes", False):
            print(f"monitor-points: the {args.probe} probe's default {probe.n_nodes} nodes; "
                  "`lidarjax simulate` chooses nodes for the CFD field's resolution: add --field "
                  "CFD (or --resolution M) to write the same nodes", file=sys.stderr)
        return [probe] * len(betas)
    if probe is None:
        raise ValueError(f"--{'field' if args.field else 'resolution'} chooses the nodes of a "
                         "probe volume; add --probe pulsed or --probe cw")
    if args.probe_nodes is not None:
        raise ValueError("--probe-nodes fixes the node count; drop it or drop --field/--resolution")
    if args.resolution is not None:  # one spacing everywhere: one count (no mount needed)
        used = probe_for_field(types.SimpleNamespace(resolution=args.resolution), scan, heights,
                               probe, caller="monitor-points")
        probes = [used] * len(betas)
    else:
        paths = field_paths(args, betas)
        for path in paths.values():
            check_field_file(path)

        def load(b, exact_at=None):  # as `lidarjax simulate --field` reads each run
            region = table_region(settings, [b], scan, probe=probe, pitch=args.pitch,
                                  roll=args.roll)
            return load_field(paths[b], region=region, exact_at=exact_at)

        chosen = settings_probes(settings, betas, load, scan, probe, heights=heights,
                                 pitch=args.pitch, roll=args.roll)
        probes = [chosen[float(b)] for b in betas]
    counts = [_counts(p) for p in probes]
    if len(set(counts)) == 1:
        shown = counts[0].replace("/", " ")
    else:
        shown = "; ".join(f"beta {b:g}: {c}" for b, c in zip(betas, counts, strict=True))
    print(f"probe nodes per beam: {shown} (chosen for the CFD field's resolution, as "
          "`lidarjax simulate` chooses them)", file=sys.stderr)
    return probes


def run(args) -> int:
    if args.command == "probes":
        print("lidarjax probes: deprecated name; use 'lidarjax monitor-points' (same options)",
              file=sys.stderr)
    if args.sampled is not None:
        return _read(args)
    settings, betas, heights, scan, probes, mounts, locs = _configuration(args)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    meta = {"settings": str(args.settings), "scan": args.scan,
            "cone_angle_deg": float(scan.cone_angle), "probe": args.probe,
            "probe_nodes": " ".join(f"{b:g}:{_counts(p)}" for b, p in zip(betas, probes, strict=True)),
            "probe_scale": args.probe_scale,
            "betas_deg": " ".join(f"{b:g}" for b in betas),
            "pitch_deg": float(args.pitch), "roll_deg": float(args.roll),
            "heights_m": " ".join(f"{h:g}" for h in heights),
            "frame": "absolute CFD coordinates, m; sample U (m/s, CFD frame)"}
    foam = write_openfoam_probes(out / args.name, locs, metadata=meta)
    zcfd = write_zcfd_probes(out / f"{args.name}_zcfd.py", locs, frequency=args.frequency,
                             metadata=meta)
    csv = write_monitor_points_csv(out / f"{args.name}.csv", locs, metadata=meta)
    print(f"{len(locs)} probes ({len(betas)} mount(s) x {len(heights)} heights x beams x nodes, "
          f"plus the column above each lidar):\n  OpenFOAM: {foam}\n  zCFD:     {zcfd}\n"
          f"  CSV:      {csv}")
    return 0


def _read(args) -> int:
    settings, betas, heights, scan, probes, mounts, locs = _configuration(args)
    src = Path(args.sampled)
    if src.is_file() and src.suffix.lower() == ".csv":
        values = read_monitor_values_csv(src)
        held = np.array([n in values for n in locs.names])
        if not held.all():
            raise ValueError(_count_mismatch(src, len(values), held, locs, betas, probes, scan))
    else:
        foam = read_openfoam_probes(src, field="U")
        n_held = int(foam.indices.max()) + 1 if foam.indices.size else 0
        held, wrong = _held_at(foam, locs)
        if n_held != len(locs) or wrong:
            raise ValueError(_count_mismatch(src, n_held, held, locs, betas, probes, scan))
        values = foam.values_for(locs, time=args.time)
    sims = simulate_from_monitor_points(locs, values, scan, mounts, heights, probe=probes,
                                        u_ref=args.u_ref)
    write_seed_results(args.out, settings, dict(zip(betas, sims, strict=True)),
                       scan=args.scan, u_ref=args.u_ref, sources=str(src),
                       settings_file=args.settings, pitch=args.pitch, roll=args.roll, log=print)
    return 0


def _held_at(foam, locs) -> tuple[np.ndarray, bool]:
    """``(n,)`` whether OpenFOAM's probe ``i`` is printed at point ``i`` of `locs` (to the
    printed digits; probes the file leaves out, ``includeOutOfBounds false``, are not held),
    and whether any probe of the file is elsewhere."""
    held = np.zeros(len(locs), bool)
    inside = foam.indices < len(locs)
    idx = foam.indices[inside]
    expected = locs.points[idx]
    gap = np.abs(foam.header_points[inside] - expected)
    ok = np.all(gap <= 1.01 * foam.header_resolution[inside] + 1e-12 * np.abs(expected), axis=1)
    held[idx[ok]] = True
    return held, bool(not ok.all() or not inside.all())


def _count_mismatch(src, n_held, held, locs, betas, probes, scan) -> str:
    """The one-line error for samples that are not every point these options give, rotation
    by rotation (its node counts per height and how many of its points the file holds), with
    the node count the file implies where it implies one."""
    parts = []
    for b, label, probe in zip(betas, locs.labels, probes, strict=True):
        rows = locs.rows(label)
        got = int(held[rows].sum())
        state = "all held" if got == rows.size else f"{got} held there"
        parts.append(f"beta {b:g}: {rows.size} points ({_counts(probe)} nodes per beam), {state}")
    per = len(betas) * len(set(locs.height.tolist()))
    beams = int(scan.n_beams)
    spare = n_held - per  # the column above each lidar: one point per mount and height
    hint = ("write and sample the nodes `lidarjax simulate` uses (--field CFD or --resolution M, "
            "the same options when reading)")
    if spare > 0 and spare % (per * beams) == 0:
        hint = f"it was written with --probe-nodes {spare // (per * beams)}; give the same, or {hint}"
    return (f"--sampled {src}: holds {n_held} probes but these options sample {len(locs)} "
            f"({'; '.join(parts)}); {hint}")
