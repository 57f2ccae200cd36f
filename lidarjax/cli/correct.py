"""`lidarjax correct`: invert lidar records for the free-stream wind with a response table."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .._util import atomic_path
from ..io import load_table
from ..response import ProfileTable
from ..workflows.joint_records import correct_records_joint
from ..workflows.records import (
    check_instrument,
    correct_records,
    load_records,
    quality_summary,
    table_warnings,
    tilt_difference,
    write_corrected_csv,
    write_corrected_netcdf,
)
from ._common import (
    add_command,
    add_record_arguments,
    check_output_file,
    finite_float,
    positive_float,
    status_line,
    warning_line,
)


def register(sub) -> None:
    cor = add_command(
        sub, "correct", run,
        "invert lidar records for the free-stream wind with a response table",
        "Read Windcube .sta/.rtd or ZephIR .csv records, check the instrument "
        "against the table, invert every record and height the table has, and "
        "write corrected speed, direction, uncertainty and flags as CSV and CF "
        "NetCDF, written atomically. Bad records "
        "come back NaN with a reason in the flags column.",
        epilog="example: lidarjax correct --table site_table.npz --records "
        "wls7_2020_10_07.sta --out corrected.csv")
    add_record_arguments(cor, records={"help": ".sta, .stdsta, .rtd or ZephIR .csv"},
                         used="flagged and not used")
    cor.add_argument("--out", default=None, help="output CSV (default: <records>_corrected.csv); "
                     "an existing file is replaced atomically, an input never")
    cor.add_argument("--netcdf", default=None, help="CF NetCDF output (default: the CSV's name "
                     "with .nc)")
    cor.add_argument("--no-netcdf", action="store_true", help="write the CSV only")
    cor.add_argument("--noise", type=positive_float, default=None,
                     help="noise standard deviation (m/s) for the uncertainties (default: "
                          ".rtd from the spare beams; .sta/.csv from each record's dispersion "
                          "and availability)")
    cor.add_argument("--scan-period", type=positive_float, default=None,
                     help="seconds per full scan, for the standard error of reported records "
                          "(default: 5 Windcube V2, 6 V1, 3 ZephIR)")
    cor.add_argument("--cnr-threshold", type=finite_float, default=None,
                     help="CNR threshold in dB for .rtd samples (default: the file header's "
                          "CNRThreshold)")
    cor.add_argument("--allow-mismatch", action="store_true",
                     help="correct although the record header disagrees with the table (scan, "
                          "cone angle, direction offset); the mismatch is printed")
    cor.add_argument("--joint", action="store_true",
                     help="with a table over directions x a profile parameter (lidarjax table "
                          "--param): solve each record over all heights at once for the "
                          "reference-height speed, the direction and the profile parameter "
                          "(lidarjax.invert_joint); the per-record solution is written beside "
                          "the CSV as <out>_profile.csv. A table without a profile axis is "
                          "corrected per height (said in one line)")
    cor.add_argument("--quiet", action="store_true", help="no progress lines")


def write_profile_csv(path, time, joint, name, profile) -> None:
    """One row per record: reference-height speed, direction, profile parameter, their
    standard deviations, converged and flags (`lidarjax.InverseFlag` bits)."""
    meta = profile.metadata()
    zref = meta.get("reference_height_m")
    head = (f"# lidarjax correct --joint: per-record solution; profile {meta['kind']}"
            + (f", reference height {zref:g} m" if zref is not None else "") + "\n"
            f"time,speed_ref_m_s,direction_deg,{name},speed_std_m_s,direction_std_deg,"
            f"{name}_std,converged,flags\n")
    cols = [np.asarray(getattr(joint, k), np.float64) for k in
            ("speed", "direction", "parameter", "speed_std", "direction_std", "parameter_std")]
    conv, flags = np.asarray(joint.converged), np.asarray(joint.flags)
    lines = [",".join([str(t)] + [f"{c[i]:.6g}" for c in cols] + [str(bool(conv[i])),
                                                                 str(int(flags[i]))])
             for i, t in enumerate(np.asarray(time))]
    with atomic_path(Path(path)) as tmp:
        Path(tmp).write_text(head + "\n".join(lines) + "\n")


def run(args) -> int:
    def say(text):
        status_line("correct", text)

    records = Path(args.records)  # it and --table exist (checked when parsed)
    min_avail = args.min_availability  # a percentage (checked when parsed)
    inputs = [("--table", args.table), ("--records", records)]
    out = Path(args.out) if args.out else records.with_name(records.stem + "_corrected.csv")
    check_output_file(out, inputs=inputs)
    nc = None
    if not args.no_netcdf:
        nc = Path(args.netcdf) if args.netcdf else out.with_suffix(".nc")
        if nc.resolve() == out.resolve():
            raise ValueError(f"--netcdf {nc} is the same file as the CSV output; name it .nc")
        check_output_file(nc, inputs=inputs, option="--netcdf")
    table, meta = load_table(args.table, return_metadata=True)
    progress = not args.quiet
    t0 = time.perf_counter()
    rec = load_records(records, cnr_threshold=args.cnr_threshold, min_availability=min_avail,
                       progress=progress)
    if progress:
        say(f"read {rec.time.size} records x {rec.heights.size} heights from {records} in "
            f"{time.perf_counter() - t0:.1f} s")
    mismatch = check_instrument(meta, table, rec)
    if mismatch and not args.allow_mismatch:
        raise ValueError(f"{records} does not match the table {args.table}: "
                         f"{'; '.join(mismatch)} (rebuild the table for this instrument, or "
                         "pass --allow-mismatch)")
    for w in rec.warnings:  # after the refusals: a refused file gets one line
        warning_line("correct", w)
    for w in table_warnings(meta):
        warning_line("correct", w)
    for m in mismatch:
        warning_line("correct", f"mismatch allowed: {m}")
    tilt = tilt_difference(meta, rec)
    if tilt:
        say(tilt)
    joint = None
    if args.joint:
        done = correct_records_joint(table, records, records=rec, noise=args.noise,
                                     progress=progress)
        if done.note:
            say(done.note)
        result, joint = done.corrected, done.joint
    elif isinstance(table, ProfileTable):
        raise ValueError(f"--table {args.table} is a table over directions x {table.name}; "
                         "correct it with --joint")
    else:
        result = correct_records(table, records, records=rec, noise=args.noise,
                                 progress=progress, scan_period_s=args.scan_period)
    if result.record_only_heights:
        say("the table has no heights " + ", ".join(f"{h:g}" for h in result.record_only_heights)
            + " m of the record; those are not corrected (lidarjax table --heights-from "
            f"{records} covers them)")
    if result.table_only_heights:
        say("the record has no heights " + ", ".join(f"{h:g}" for h in result.table_only_heights)
            + " m of the table; skipped")
    info = {"records": str(records), "table": str(args.table), "scan": meta.get("scan", "?"),
            "instrument": rec.instrument or "?", "time": "UTC, end of interval",
            "noise": "given" if args.noise else ("record dispersion and availability"
                                                 if rec.kind != "rtd" else "spare beams")}
    write_corrected_csv(out, result, info, progress=progress)
    written = [str(out)]
    if joint is not None:
        prof = out.with_name(out.stem + "_profile.csv")
        write_profile_csv(prof, result.time, joint, table.name, table.profile)
        written.append(str(prof))
    if nc is not None:
        write_corrected_netcdf(nc, result, info)
        written.append(str(nc))
    for line in quality_summary(result):
        print(line)
    print(f"wrote {' and '.join(written)}")
    return 0
