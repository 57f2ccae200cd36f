"""`lidarjax correct`: invert lidar records for the free-stream wind with a response table."""

from __future__ import annotations

import numpy as np


def register(sub) -> None:
    cor = sub.add_parser(
        "correct", help="invert lidar records for the free-stream wind with a response table",
        description="Read Windcube .sta/.rtd or ZephIR .csv records, invert every record and "
                    "height with the table, and write corrected speed, direction, "
                    "uncertainty and flags as CSV (written atomically).",
        epilog="example: lidarjax correct --table site_table.npz --records "
               "wls7_2020_10_07.sta --out corrected.csv")
    cor.add_argument("--table", required=True, help="response table from `lidarjax table`")
    cor.add_argument("--records", required=True, help=".sta, .stdsta, .rtd or ZephIR .csv")
    cor.add_argument("--out", default=None, help="output CSV (default: <records>_corrected.csv)")
    cor.add_argument("--noise", type=float, default=None,
                     help="noise standard deviation (m/s) for the uncertainties (default: "
                          "estimated from spare beams; needed for .sta/.csv)")
    cor.add_argument("--quiet", action="store_true", help="no progress bar")
    cor.set_defaults(func=run)


def run(args) -> int:
    from pathlib import Path

    from ..io import load_table
    from ..workflow import correct_records, write_corrected_csv

    table, meta = load_table(args.table, return_metadata=True)
    records = Path(args.records)
    if not records.is_file():
        raise FileNotFoundError(f"record file not found: {records}")
    out = Path(args.out) if args.out else records.with_name(records.stem + "_corrected.csv")
    if not out.parent.is_dir():
        raise FileNotFoundError(f"output folder not found: {out.parent}")
    result = correct_records(table, records, noise=args.noise, progress=not args.quiet)
    write_corrected_csv(out, result, {"records": str(records), "table": str(args.table),
                                      "scan": meta.get("scan", "?")})
    ok = np.asarray(result.converged)
    du = np.nanmedian(np.abs(result.speed - result.measured_speed))
    print(f"corrected {ok.sum()} of {ok.size} record-heights ({len(result.time)} records x "
          f"{len(result.heights)} heights); median |correction| {du:.3f} m/s -> {out}")
    return 0
