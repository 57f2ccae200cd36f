"""`lidarjax simulate`: the seed UDF's workflow, settings.dat + CFD runs -> seed output files."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from .._util import have_module
from ..flags import Flag
from ..io import read_settings, write_netcdf, write_seed_output, write_table_csv
from ..io.fields import load_field
from ..io.seed_output import SEED_UNITS, format_number, seed_output_filename
from ..workflows.seed_tables import seed_columns, simulate_settings
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



def nan_reasons(sims, fields, settings, paths) -> str | None:
    """One line explaining why values are NaN (decoding `lidarjax.Flag`), or None."""

    lidar = np.concatenate([np.asarray(s.lidar_velocity)[..., 0].ravel() for s in sims.values()])
    n_nan = int(np.count_nonzero(~np.isfinite(lidar)))
    if lidar.size == 0 or n_nan == 0:
        return None
    head = ("most values are NaN" if n_nan > lidar.size / 2 else
            f"{n_nan} of {lidar.size} height-runs are NaN")
    reasons = []
    for b, sim in sims.items():
        f = fields[b]
        vel = np.asarray(f.velocity)
        if not np.isfinite(vel).any():
            reasons.append(f"the CFD field {paths[b]} is NaN everywhere")
            continue
        flags = np.asarray(sim.flags)
        if not (flags & int(Flag.BEAM_OUTSIDE)).any():
            continue
        loc = np.asarray(settings.location(b), np.float64)
        origin = np.asarray(f.origin, np.float64) + np.asarray(getattr(f, "origin_lo", 0.0))
        lo = origin + np.array([float(np.min(a)) for a in (f.x_local, f.y_local, f.z_local)])
        hi = origin + np.array([float(np.max(a)) for a in (f.x_local, f.y_local, f.z_local)])
        top = loc[2] + float(np.max(settings.heights()))
        if np.any(loc[:2] < lo[:2]) or np.any(loc[:2] > hi[:2]):
            reasons.append(f"beta {b:g}: the lidar at x={loc[0]:g}, y={loc[1]:g} m is off the "
                           f"CFD grid (x {lo[0]:g}..{hi[0]:g}, y {lo[1]:g}..{hi[1]:g} m)")
        elif top > hi[2]:
            reasons.append(f"beta {b:g}: the grid is too low (top z={hi[2]:g} m, highest "
                           f"measurement z={top:g} m)")
        else:
            n = int(np.count_nonzero(flags & int(Flag.BEAM_OUTSIDE)))
            reasons.append(f"beta {b:g}: {n} heights have beams outside the grid or in a solid "
                           "(NaN cells)")
    if not reasons:
        return f"{head}; see the flags column (lidarjax.Flag bits)"
    more = f" (+{len(reasons) - 2} more)" if len(reasons) > 2 else ""
    return f"{head}: " + "; ".join(reasons[:2]) + more


def run(args) -> int:
    settings = read_settings(args.settings)
    betas = selected_betas(args, settings)
    for b in betas:
        settings.location(b)  # raises a ValueError naming the missing row
    paths = field_paths(args, betas)
    scan = make_scan(args.scan, args.cone_angle, tilt_compensation=args.tilt_compensation)
    probe = make_probe(args)
    nc = have_module("xarray")
    names = []
    for b in betas:
        names += [seed_output_filename(b), f"simulation_{format_number(b)}.csv"]
        if nc:
            names.append(f"simulation_{format_number(b)}.nc")
    inputs = [("settings", args.settings)] + [(f"--field (beta {b:g})", p)
                                               for b, p in paths.items()]
    check_output_folder(args.out, files=names, inputs=inputs)
    fields = {}

    def field_for(b):
        fields[b] = load_field(paths[b])
        return fields[b]

    sims = simulate_settings(settings, betas, field_for, scan, u_ref=args.u_ref, probe=probe,
                             pitch=args.pitch, roll=args.roll)
    write_results(args, settings, sims, {b: str(p) for b, p in paths.items()})
    why = nan_reasons(sims, fields, settings, paths)
    if why:
        print(f"lidarjax simulate: warning: {why}", file=sys.stderr)
    return 0


def write_results(args, settings, sims, sources) -> None:
    """Write the seed files (with the `lidarjax.Flag` bits as a 22nd column), CSV and (with
    xarray) NetCDF tables of `sims` ({beta: Simulation}) to ``args.out``; `sources` names each
    beta's CFD data in the metadata. Shared with `lidarjax monitor-points --sampled`."""

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    nc = have_module("xarray")
    pitch, roll = getattr(args, "pitch", 0.0), getattr(args, "roll", 0.0)
    flag_doc = ", ".join(f"{int(f)} {f.name.lower()}" for f in Flag if f)
    print(f"{'beta':>7s} {'file':<40s} {'U_lidar(top)':>13s} {'cff_U range':>18s}")
    for b, sim in sims.items():
        cols = seed_columns(sim)
        flags = np.asarray(sim.flags).astype(np.int64)
        path = write_seed_output(out, b, cols, verbose=settings.verbose, flags=flags)
        meta = {"settings": str(args.settings), "field": sources[b], "scan": args.scan,
                "beta_deg": b, "gamma_deg": settings.gamma, "psi_deg": settings.psi,
                "epsilon_deg": settings.epsilon, "pitch_deg": pitch,
                "roll_deg": roll, "u_ref_cfd_m_s": ",".join(map(str, args.u_ref)),
                "directions": "Th_lidar/th_point: seed azimuth = (-atan2(v,u)) mod 360; "
                              "meteorological = (seed + 270) mod 360",
                "flags": f"lidarjax.Flag bits per height: {flag_doc}"}
        with_flags = {**cols, "flags": flags.astype(np.float64)}
        units = {**SEED_UNITS, "flags": "bits"}
        write_table_csv(out / f"simulation_{format_number(b)}.csv", with_flags, units, meta)
        if nc:
            write_netcdf(out / f"simulation_{format_number(b)}.nc", with_flags, meta, units=units)
        cff = cols["cff_U"]
        rng = (f"{np.nanmin(cff):8.4f}..{np.nanmax(cff):8.4f}" if np.isfinite(cff).any()
               else f"{'nan':>18s}")
        print(f"{b:7.1f} {path.name:<40s} {cols['U_mag_lidar'][-1]:13.3f} {rng}")
    extra = " and NetCDF" if nc else ""
    print(f"wrote {len(sims)} seed file(s), CSV{extra} table(s) to {out}")
