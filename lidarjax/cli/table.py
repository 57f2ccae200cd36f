"""`lidarjax table`: a response table of CFD runs over directions, for `correct`."""

from __future__ import annotations

import argparse
import copy
import math
import os
import sys
from pathlib import Path

import numpy as np

from .. import __version__
from .._util import format_number
from ..io import read_settings, save_table
from ..io.fields import check_field_file, load_field
from ..response import PowerLawProfile, UniformProfile
from ..workflows.records import check_instrument, load_records
from ..workflows.seed_tables import build_table, table_region
from ._common import (
    add_command,
    add_run_arguments,
    add_settings_argument,
    add_tilt_arguments,
    check_output_file,
    field_paths,
    height_list,
    input_file,
    make_probe,
    make_scan,
)
from ._dask import add_dask_arguments, dask_client, region_loader


def register(sub) -> None:
    tab = add_command(
        sub, "table", run,
        "build a response table (for `correct`) from CFD runs over directions",
        "Simulate the lidar of a seed settings.dat in every CFD run (one per "
        "platform rotation beta, i.e. per inflow direction) and save the LOS "
        "per unit free-stream speed as a response table (.npz). The table records "
        "the instrument (scan, cone angle, beams), probe, mount, heights and CFD "
        "source, which `correct` checks against each record file's header.",
        epilog="example: lidarjax table settings.dat --field 'runs/platform_{beta}.npz' "
        "--scan windcube_v2 --heights-from wls7_2020_10_07.sta --out site_table.npz")
    add_settings_argument(tab, "all beta rows are used")
    add_run_arguments(tab, default_scan="windcube_v2")
    add_tilt_arguments(tab)
    heights = tab.add_mutually_exclusive_group()
    heights.add_argument("--heights", type=height_list, default=None,
                         help="measurement heights in m above the lidar, e.g. 40,54,74 "
                              "(default: the settings file's)")
    heights.add_argument("--heights-from", default=None, metavar="RECORDS", type=input_file,
                         help="take the heights from a record file (.sta, .rtd or ZephIR .csv)")
    tab.add_argument("--tilt-from-records", action="store_true",
                     help="with --heights-from: take --pitch and --roll from the record "
                          "header's PitchAngle and RollAngle (taken in lidarjax's convention: "
                          "positive pitch raises the S0 side, positive roll lowers S1)")
    tab.add_argument("--param", type=parameter_values, default=None, metavar="NAME=V1,V2,...",
                     help="runs over directions x one inflow-profile parameter, e.g. "
                          "alpha=0.0,0.1,0.2 with --field 'runs/d{beta}_a{alpha}.npz': a "
                          "ProfileTable for `correct --joint` (each run's --u-ref is its free "
                          "stream at --reference-height)")
    tab.add_argument("--profile", choices=("power", "uniform"), default=None,
                     help="with --param: the free-stream profile the parameter sets: power "
                          "((z/zref)^NAME, a shear exponent; the default for alpha/shear) or "
                          "uniform (the parameter changes only the distortion)")
    tab.add_argument("--reference-height", type=float, default=None, metavar="M",
                     help="with --profile power: height (m above the lidar) where the runs' "
                          "--u-ref is the free stream")
    tab.add_argument("--out", required=True, help="table file to write (.npz); an existing "
                     "file is replaced atomically, an input never")
    add_dask_arguments(tab)


def parameter_values(text: str) -> tuple[str, list[float]]:
    """``NAME=V1,V2,...`` -> ``(name, values)``: an identifier and two or more finite
    increasing numbers."""
    name, sep, rest = text.partition("=")
    name = name.strip()
    try:
        values = [float(v) for v in rest.split(",") if v.strip()]
    except ValueError:
        values = []
    if not sep or not name.isidentifier() or name == "beta" or len(values) < 2 or not all(
            math.isfinite(v) for v in values) or bool(np.any(np.diff(values) <= 0)):
        raise argparse.ArgumentTypeError(
            f"expected NAME=V1,V2,... with a name other than beta and at least two increasing "
            f"numbers (e.g. alpha=0.0,0.1,0.2), got {text!r}")
    return name, values


def _profile(args):
    """The `AbstractProfile` of --profile / --reference-height (--param given)."""
    name = args.param[0]
    kind = args.profile or ("power" if name.lower() in ("alpha", "shear", "shear_exponent")
                            else "uniform")
    if kind == "uniform":
        return UniformProfile()
    z = args.reference_height
    if z is None or not (math.isfinite(z) and z > 0):
        raise ValueError(f"--param {name} with a power-law profile needs --reference-height M "
                         "(positive, m above the lidar: where the runs' --u-ref is the free "
                         "stream), or --profile uniform")
    return PowerLawProfile(z)


def _profile_paths(args, betas):
    """``{(beta, value): path}`` for --param runs: '{NAME}' and '{beta}' in --field."""
    name, values = args.param
    token = "{" + name + "}"
    if token not in args.field:
        raise ValueError(f"--field {args.field!r} must contain '{token}' to name the run of "
                         f"each {name} value (e.g. 'runs/d{{beta}}_{name[0]}{token}.npz')")
    out = {}
    for v in values:
        sub = copy.copy(args)
        sub.field = args.field.replace(token, format_number(v))
        out.update({(b, v): p for b, p in field_paths(sub, betas).items()})
    return out


class _ProfileLoader:
    """``(beta, value) -> GridField`` through one region loader per value (picklable)."""

    def __init__(self, loaders):
        self.loaders = loaders

    def __call__(self, beta, value, exact_at=None):
        return self.loaders[value](beta, exact_at=exact_at)


def _tilt_from(args, rec) -> None:
    """Set ``args.pitch`` / ``args.roll`` from a record header (`--tilt-from-records`)."""
    got = {k: float(getattr(rec, k, math.nan)) for k in ("pitch", "roll")}
    missing = [k for k, v in got.items() if not math.isfinite(v)]
    if missing:
        raise ValueError(f"--tilt-from-records: {args.heights_from} states no "
                         f"{' or '.join(missing)} angle in its header; give --pitch/--roll")
    args.pitch, args.roll = got["pitch"], got["roll"]
    print(f"tilt from {args.heights_from}: pitch {args.pitch:g} deg, roll {args.roll:g} deg",
          file=sys.stderr)


def _record_heights(path):
    p = Path(path)  # an existing file (checked when parsed)
    rec = load_records(p)
    if rec.heights.size == 0:
        raise ValueError(f"--heights-from {p}: the file lists no heights")
    return rec


def table_metadata(args, settings, scan, paths, heights) -> dict:
    """The instrument facts `correct` checks, plus the CFD source."""

    return {
        "scan": args.scan, "scan_method": scan.method,
        "cone_angle_deg": float(np.asarray(scan.cone_angle)),
        "n_beams": int(scan.n_beams),
        "beam_azimuths_deg": [float(a) for a in np.asarray(scan.azimuths)],
        "vertical_beam": bool(scan.vertical),
        "probe": args.probe, "probe_nodes": args.probe_nodes,
        "probe_scale": 1.0 if args.probe_scale is None else args.probe_scale,
        "gamma_deg": settings.gamma, "psi_deg": settings.psi, "epsilon_deg": settings.epsilon,
        "pitch_deg": float(args.pitch), "roll_deg": float(args.roll),
        "tilt_compensation": bool(args.tilt_compensation),
        "heights_m": [float(h) for h in heights],
        "settings": os.path.abspath(args.settings), "field": args.field,
        "cfd_files": {(f"{k:g}" if not isinstance(k, tuple) else f"{k[0]:g}_{k[1]:g}"):
                      os.path.abspath(p) for k, p in paths.items()},
        "u_ref_cfd_m_s": list(args.u_ref),
        "lidarjax_version": __version__,
    }


def run(args) -> int:
    settings = read_settings(args.settings)
    betas = [float(b) for b in settings.betas]
    if args.param is None:
        if args.profile is not None or args.reference_height is not None:
            raise ValueError("--profile and --reference-height need --param NAME=V1,V2,...")
        paths = field_paths(args, betas)
        profile = None
    else:
        paths = _profile_paths(args, betas)
        profile = _profile(args)
    scan = make_scan(args.scan, args.cone_angle, tilt_compensation=args.tilt_compensation)
    probe = make_probe(args)
    inputs = [("settings", args.settings)] + [(f"--field ({k})", p) for k, p in paths.items()]
    rec = None
    if args.heights_from is not None:
        inputs.append(("--heights-from", args.heights_from))
    if args.tilt_from_records and args.heights_from is None:
        raise ValueError("--tilt-from-records needs --heights-from RECORDS (the file whose "
                         "header gives the tilt)")
    out = check_output_file(args.out, inputs=inputs)
    if args.heights_from is not None:
        rec = _record_heights(args.heights_from)
        settings = settings.with_heights(rec.heights)
        if args.tilt_from_records:
            _tilt_from(args, rec)
    elif args.heights is not None:
        settings = settings.with_heights(args.heights)
    meta = table_metadata(args, settings, scan, paths, settings.heights())
    if rec is not None:
        bad = check_instrument(meta, None, rec)
        if bad:
            raise ValueError(f"--heights-from {args.heights_from}: the record does not match "
                             f"the table being built: {'; '.join(bad)}")
    for path in paths.values():  # every file's format checked before computing
        check_field_file(path)
    # one run at a time, each read only where the beams look (peak memory about one run)
    region = table_region(settings, betas, scan, probe=probe, pitch=args.pitch, roll=args.roll)
    print(f"simulating {len(betas)} CFD runs x {settings.nh} heights ({args.scan}, "
          f"{args.probe} probe) ...", file=sys.stderr)
    with dask_client(args) as client:
        if args.param is None:
            table, _ = build_table(settings, betas, region_loader(load_field, paths, region),
                                   scan, u_ref=args.u_ref, probe=probe, pitch=args.pitch,
                                   roll=args.roll, client=client, progress=True)
        else:
            name, values = args.param
            loaders = {v: region_loader(load_field, {b: paths[(b, v)] for b in betas}, region)
                       for v in values}
            table, _ = build_table(settings, betas, _ProfileLoader(loaders), scan,
                                   u_ref=args.u_ref, probe=probe, pitch=args.pitch,
                                   roll=args.roll, client=client, progress=True,
                                   parameter=(name, values), profile=profile)
    save_table(out, table, meta)
    bad = ~np.asarray(table.valid)
    note = ""
    if bad.any():
        note = (f"; {int(bad.sum())} height-beams are outside the CFD grid or in a solid "
                "for every run (missing beams)")
    axis = "" if args.param is None else f" x {table.n_parameters} {table.name} values"
    print(f"response table: {table.n_directions} directions{axis} x {table.n_heights} heights "
          f"x {table.n_beams} beams -> {out}{note}")
    return 0
