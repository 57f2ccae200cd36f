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
from ..workflows.seed_tables import settings_mount, table_region
from ._common import (
    add_probe_arguments,
    field_paths,
    finite_float,
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
    pr = sub.add_parser(
        "monitor-points", aliases=["probes"],
        help="write the lidar's sample points as CFD monitor points (OpenFOAM probes, zCFD, "
             "CSV), "
                       "or simulate from the CFD code's samples (--sampled)",
        description="Write the beam focus points (or probe-volume quadrature nodes) and the "
                    "point-reference column of every selected mount of a seed settings.dat as "
                    "an OpenFOAM probes function object (<out>/<name>), a zCFD probe file "
                    "(<out>/<name>_zcfd.py, turb_probe layout) and CSV (<out>/<name>.csv). "
                    "Each probe is named <mount>_h<height>_beam<b>_q<node>. With --sampled, "
                    "read the values the CFD code sampled there instead and write the seed "
                    "output files, as 'lidarjax simulate' does.",
        epilog="example: lidarjax monitor-points settings.dat --all --scan windcube_v2 --probe pulsed "
               "--out probes/ ; cp probes/lidarProbes case/system/ ; (cd case && postProcess "
               "-func lidarProbes -latestTime) ; lidarjax monitor-points settings.dat --all --scan "
               "windcube_v2 --probe pulsed --sampled case/postProcessing/lidarProbes --out results/",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    pr.add_argument("settings", help="the seed's settings.dat")
    which = pr.add_mutually_exclusive_group()
    which.add_argument("--beta", type=finite_float, help="platform rotation (default: the settings "
                                                 "file's beta)")
    which.add_argument("--all", action="store_true", help="every beta row of the settings")
    pr.add_argument("--scan", choices=SCAN_CHOICES, default="windcube_v2")
    pr.add_argument("--cone-angle", type=positive_float, default=None,
                    help="cone angle in degrees (default: the scan's)")
    pr.add_argument("--heights", type=_heights, default=None,
                    help="heights above the lidar, metres, 'h1,h2,...' (default: the "
                         "settings' j * height / nh)")
    add_probe_arguments(pr)
    nodes = pr.add_mutually_exclusive_group()
    nodes.add_argument("--field", default=None, metavar="CFD",
                       help="the CFD run(s) `lidarjax simulate --field` would read ('{beta}' "
                            "for several betas): the probe's nodes are chosen for its "
                            "resolution as simulate chooses them, so both routes sample the "
                            "same nodes")
    nodes.add_argument("--resolution", type=positive_float, default=None, metavar="M",
                       help="the CFD grid's resolution in metres (what simulate reports as the "
                            "field's spacing): the nodes simulate would choose for it")
    pr.add_argument("--name", default="lidarProbes",
                    help="function-object name and file stem (default lidarProbes)")
    pr.add_argument("--frequency", type=positive_int, default=100,
                    help="zCFD report frequency, solver cycles (default 100)")
    pr.add_argument("--sampled", default=None,
                    help="read mode: OpenFOAM probes output (postProcessing/<name>, a time "
                         "folder or its U file) or a CSV with columns name,u,v,w")
    pr.add_argument("--time", type=finite_float, default=None,
                    help="read mode: the sampled time to use (default: the latest)")
    pr.add_argument("--u-ref", type=vector, default=(-15.0, 0.0, 0.0),
                    help="read mode: free stream u,v,w in the CFD frame, m/s (default -15,0,0)")
    pr.add_argument("--out", required=True, help="output folder")
    pr.set_defaults(func=run)


def _configuration(args):
    settings = read_settings(args.settings)
    betas = selected_betas(args, settings)
    for b in betas:
        settings.location(b)  # a ValueError naming the missing row
    heights = np.asarray(args.heights if args.heights is not None else settings.heights())
    scan = make_scan(args.scan, args.cone_angle)
    probe = _simulate_nodes(args, settings, betas, heights, scan, make_probe(args))
    mounts = settings_mount(settings, betas)
    locs = monitor_points(scan, mounts, heights, probe)
    return settings, betas, heights, scan, probe, mounts, locs


def _simulate_nodes(args, settings, betas, heights, scan, probe):
    """The probe with the nodes `lidarjax simulate` uses: chosen for --field's (or
    --resolution's) grid as simulate chooses them (`probe_for_field`, each beta's run read
    over the region simulate reads), or the probe as given (a note on stderr where simulate
    would choose others)."""
    if args.field is None and args.resolution is None:
        if probe is not None and getattr(probe, "auto_nodes", False):
            print(f"monitor-points: the {args.probe} probe's default {probe.n_nodes} nodes; "
                  "`lidarjax simulate` chooses nodes for the CFD field's resolution: add --field "
                  "CFD (or --resolution M) to write the same nodes", file=sys.stderr)
        return probe
    if probe is None:
        raise ValueError(f"--{'field' if args.field else 'resolution'} chooses the nodes of a "
                         "probe volume; add --probe pulsed or --probe cw")
    if args.probe_nodes is not None:
        raise ValueError("--probe-nodes fixes the node count; drop it or drop --field/--resolution")
    mounts = settings_mount(settings, betas)
    if args.resolution is not None:  # one spacing everywhere: one count (no mount needed)
        chosen = {b: probe_for_field(types.SimpleNamespace(resolution=args.resolution), scan,
                                     heights, probe, caller="monitor-points") for b in betas}
    else:
        paths = field_paths(args, betas)
        for path in paths.values():
            check_field_file(path)
        chosen = {}
        for k, b in enumerate(betas):  # each run over the region `lidarjax simulate` reads
            region = table_region(settings, [b], scan, probe=probe)
            grid = load_field(paths[b], region=region)
            chosen[b] = probe_for_field(grid, scan, heights, probe, mount=mounts[k],
                                        caller="monitor-points")
    counts = {b: tuple(getattr(p, "node_counts", (p.n_nodes,))) for b, p in chosen.items()}
    if len(set(counts.values())) > 1:
        listed = ", ".join(f"beta {b:g}: {'/'.join(map(str, n))}" for b, n in counts.items())
        raise ValueError(f"the runs' grids give different node counts ({listed}); write the "
                         "monitor points of one beta at a time (--beta)")
    used = chosen[betas[0]]
    shown = " ".join(str(n) for n in counts[betas[0]])
    print(f"probe nodes per beam: {shown} (chosen for the CFD field's resolution, as "
          "`lidarjax simulate` chooses them)", file=sys.stderr)
    return used


def run(args) -> int:
    if args.command == "probes":
        print("lidarjax probes: deprecated name; use 'lidarjax monitor-points' (same options)",
              file=sys.stderr)
    if args.sampled is not None:
        return _read(args)
    settings, betas, heights, scan, probe, mounts, locs = _configuration(args)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    meta = {"settings": str(args.settings), "scan": args.scan,
            "cone_angle_deg": float(scan.cone_angle), "probe": args.probe,
            "probe_nodes": args.probe_nodes, "probe_scale": args.probe_scale,
            "betas_deg": " ".join(f"{b:g}" for b in betas),
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
    settings, betas, heights, scan, probe, mounts, locs = _configuration(args)
    src = Path(args.sampled)
    if src.is_file() and src.suffix.lower() == ".csv":
        values = read_monitor_values_csv(src)
    else:
        probes = read_openfoam_probes(src, field="U")
        held = int(probes.indices.max()) + 1 if probes.indices.size else 0
        if held != len(locs):
            raise ValueError(_count_mismatch(src, held, locs, probe, len(betas), heights, scan))
        values = probes.values_for(locs, time=args.time)
    sims = simulate_from_monitor_points(locs, values, scan, mounts, heights, probe=probe,
                                u_ref=args.u_ref)
    write_seed_results(args.out, settings, dict(zip(betas, sims, strict=True)),
                       scan=args.scan, u_ref=args.u_ref, sources=str(src),
                       settings_file=args.settings, log=print)
    return 0


def _count_mismatch(src, held, locs, probe, n_mounts, heights, scan) -> str:
    """The one-line error for samples of another number of points than these options give,
    with the node count the file implies where it implies one."""
    per = n_mounts * len(heights)
    nodes = "focus points" if probe is None else f"{probe.n_nodes} nodes per beam"
    beams = int(scan.n_beams)
    spare = held - per  # the column above each lidar: one point per mount and height
    hint = "write and sample the nodes `lidarjax simulate` uses (--field CFD or --resolution M)"
    if spare > 0 and spare % (per * beams) == 0:
        hint = f"it was written with --probe-nodes {spare // (per * beams)}; give the same, or {hint}"
    return (f"--sampled {src}: holds {held} probes but these options give {len(locs)} "
            f"({nodes}); {hint}")
