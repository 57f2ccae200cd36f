"""`lidarjax simulate`: the seed UDF's workflow, settings.dat + CFD runs -> seed output files."""

from __future__ import annotations

import argparse

import numpy as np

from ._common import add_run_arguments, field_paths, make_probe, make_scan, selected_betas


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
    which.add_argument("--beta", type=float, help="platform rotation to run (default: the "
                                                 "settings file's beta)")
    which.add_argument("--all", action="store_true", help="run every beta row, one batch")
    add_run_arguments(sim, default_scan="windcube_v1")
    sim.add_argument("--out", default=".", help="output folder (default: .)")
    sim.set_defaults(func=run)



def run(args) -> int:
    from ..io import read_settings
    from ..io.fields import load_field
    from ..workflow import simulate_settings

    settings = read_settings(args.settings)
    betas = selected_betas(args, settings)
    for b in betas:
        settings.location(b)  # raises a ValueError naming the missing row
    paths = field_paths(args, betas)
    scan = make_scan(args.scan, args.cone_angle)
    probe = make_probe(args)
    sims = simulate_settings(settings, betas, lambda b: load_field(paths[b]), scan,
                             u_ref=args.u_ref, probe=probe)
    write_results(args, settings, sims, {b: str(p) for b, p in paths.items()})
    return 0


def write_results(args, settings, sims, sources) -> None:
    """Write the seed files and CSV (and NetCDF with xarray) tables of `sims` ({beta:
    Simulation}) to ``args.out``; `sources` names each beta's CFD data in the metadata.
    Shared with `lidarjax probes --sampled`."""
    from pathlib import Path

    from ..io import write_netcdf, write_seed_output, write_table_csv
    from ..io._common import have_module
    from ..io.seed_output import SEED_UNITS, format_number
    from ..workflow import seed_columns

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    print(f"{'beta':>7s} {'file':<40s} {'U_lidar(top)':>13s} {'cff_U range':>18s}")
    for b, sim in sims.items():
        cols = seed_columns(sim)
        path = write_seed_output(out, b, cols, verbose=settings.verbose)
        meta = {"settings": str(args.settings), "field": sources[b], "scan": args.scan,
                "beta_deg": b, "gamma_deg": settings.gamma, "psi_deg": settings.psi,
                "epsilon_deg": settings.epsilon, "u_ref_cfd_m_s": ",".join(map(str, args.u_ref)),
                "directions": "Th_lidar/th_point: seed azimuth = (-atan2(v,u)) mod 360; "
                              "meteorological = (seed + 270) mod 360"}
        write_table_csv(out / f"simulation_{format_number(b)}.csv", cols, SEED_UNITS, meta)
        if have_module("xarray"):
            write_netcdf(out / f"simulation_{format_number(b)}.nc", cols, meta)
        cff = cols["cff_U"][np.isfinite(cols["cff_U"])]
        span = f"{cff.min():8.4f}..{cff.max():8.4f}" if cff.size else f"{'nan':>18s}"
        print(f"{b:7.1f} {path.name:<40s} {cols['U_mag_lidar'][-1]:13.3f} {span}")
    extra = " and NetCDF" if have_module("xarray") else ""
    print(f"wrote {len(sims)} seed file(s), CSV{extra} table(s) to {out}")
