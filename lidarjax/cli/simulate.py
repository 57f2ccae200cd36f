"""`lidarjax simulate`: the seed UDF's workflow, settings.dat + CFD runs -> seed output files.

The runs are `lidarjax.simulate_settings`, the files `lidarjax.write_seed_results` and the
NaN warning `lidarjax.explain_nans` (`lidarjax.workflows.seed_results`).
"""

from __future__ import annotations

import argparse
import sys

import jax.numpy as jnp

from ..forward import probe_for_field
from ..io import read_settings, simulate_points
from ..io.fields import check_field_file, load_field
from ..probe import PulsedProbe
from ..workflows.seed_results import explain_nans, seed_result_files, write_seed_results
from ..workflows.seed_tables import settings_mount, simulate_settings, table_region
from ._common import (
    add_run_arguments,
    add_tilt_arguments,
    check_output_folder,
    field_paths,
    finite_float,
    make_probe,
    make_scan,
    selected_betas,
)


def register(sub) -> None:
    sim = sub.add_parser(
        "simulate", help="the seed workflow: settings.dat + CFD runs -> seed output files",
        description="Simulate the lidar of a seed settings.dat in CFD runs (one per platform "
                    "rotation beta) and write the seed's 'windcube simulation <beta> "
                    "degrees.dat' files plus self-describing CSV tables.",
        epilog="example: lidarjax simulate settings.dat --field 'runs/platform_{beta}.npz' "
               "--all --scan windcube_v1 --out results/",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    sim.add_argument("settings", help="the seed's settings.dat")
    which = sim.add_mutually_exclusive_group()
    which.add_argument("--beta", type=finite_float, help="platform rotation to run (default: the "
                                                 "settings file's beta)")
    which.add_argument("--all", action="store_true", help="run every beta row, one batch")
    add_run_arguments(sim, default_scan="windcube_v1")
    add_tilt_arguments(sim)
    sim.add_argument("--out", default=".", help="output folder (default: .)")
    sim.set_defaults(func=run)


def run(args) -> int:
    settings = read_settings(args.settings)
    betas = selected_betas(args, settings)
    for b in betas:
        settings.location(b)  # raises a ValueError naming the missing row
    paths = field_paths(args, betas)
    scan = make_scan(args.scan, args.cone_angle, tilt_compensation=args.tilt_compensation)
    probe = make_probe(args)
    inputs = [("settings", args.settings)] + [(f"--field (beta {b:g})", p)
                                               for b, p in paths.items()]
    check_output_folder(args.out, files=seed_result_files(betas), inputs=inputs)
    fields = {}
    nodes = {}

    for path in paths.values():  # every file's format checked before computing
        check_field_file(path)

    heights = jnp.asarray(settings.heights())

    def field_for(b):
        # each run read only where its beams look, as `lidarjax table` reads it (a GridField
        # crop is bit-exact; an OpenFOAM or VTK mesh is resampled over that region only and
        # made exact, the mesh's own cellPoint, at the very points simulate samples: the
        # probe's nodes, chosen for the grid's resolution, of this beta's mount)
        region = table_region(settings, [b], scan, probe=probe, pitch=args.pitch, roll=args.roll)
        mount = settings_mount(settings, [b], pitch=args.pitch, roll=args.roll)[0]

        def points(grid):
            used = probe_for_field(grid, scan, heights, probe, caller="simulate") if probe else None
            if used is not None:
                nodes[b] = used.n_nodes
            return simulate_points(scan, mount, heights, used)

        field = load_field(paths[b], region=region, exact_at=points)
        fields[b] = getattr(field, "grid", field)  # the grid explains NaNs by its extent
        return field

    sims = simulate_settings(settings, betas, field_for, scan, u_ref=args.u_ref, probe=probe,
                             pitch=args.pitch, roll=args.roll)
    write_seed_results(args.out, settings, sims, scan=args.scan, u_ref=args.u_ref,
                       sources={b: str(p) for b, p in paths.items()},
                       settings_file=args.settings, pitch=args.pitch, roll=args.roll, log=print)
    if nodes and isinstance(probe, PulsedProbe):  # the pulsed rule depends on the count only
        counts = " ".join(sorted({str(n) for n in nodes.values()}, key=int))
        print(f"probe nodes per beam: {counts} (chosen for the CFD field's resolution; "
              f"`lidarjax monitor-points --probe pulsed --probe-nodes N` writes the same nodes)")
    why = explain_nans(sims, fields, settings, paths)
    if why:
        print(f"lidarjax simulate: warning: {why}", file=sys.stderr)
    return 0
