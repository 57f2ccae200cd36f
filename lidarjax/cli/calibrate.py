"""`lidarjax calibrate`: installation offsets (north offset, pitch, roll) from LOS records."""

from __future__ import annotations

import argparse
import csv
import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from .._util import atomic_path
from ..calibrate import CALIBRATION_PARAMETERS, calibrate
from ..io import load_table, read_settings
from ..io.fields import check_field_file, load_field
from ..response import ProfileTable
from ..workflows.records import (
    load_records,
    match_heights,
    subset_table,
)
from ..workflows.seed_tables import SEED_U_REF, table_runs
from ._common import (
    add_command,
    add_record_arguments,
    check_output_file,
    finite_float,
    input_file,
    make_probe,
    make_scan,
    status_line,
)


def _wrt(text: str) -> tuple[str, ...]:
    names = tuple(x.strip() for x in text.split(",") if x.strip())
    bad = [x for x in names if x not in CALIBRATION_PARAMETERS]
    if bad or not names:
        raise argparse.ArgumentTypeError(f"expected a comma list of {','.join(CALIBRATION_PARAMETERS)}"
                                         f", got {text!r}")
    return names


def register(sub) -> None:
    cal = add_command(
        sub, "calibrate", run,
        "estimate the installation's north offset and tilt from LOS records",
        "Fit constant offsets of the installation (epsilon: north offset, pitch, "
        "roll; degrees) to many raw LOS records (.rtd) through the table's forward "
        "model, with standard errors and correlations. Without --reference only "
        "pitch and roll are identifiable (from the vertical beam and how the "
        "apparent vertical wind follows the direction); epsilon needs a reference "
        "free stream (mast, other lidar, model). The estimate is compared with the "
        "tilt in the record header where it has one.",
        epilog="example: lidarjax calibrate --table site_table.npz --records wls.rtd "
        "--reference mast.csv --out calibration.json")
    add_record_arguments(cal, table="built with the nominal installation", records={
        "nargs": "+", "help": "raw LOS record files (.rtd); several files are pooled"})
    cal.add_argument("--reference", default=None, type=input_file,
                     help="CSV of the reference free stream, columns time,height_m,speed_m_s,"
                          "direction_deg (time as in the records, end of interval, UTC)")
    cal.add_argument("--wrt", type=_wrt, default=CALIBRATION_PARAMETERS,
                     help="offsets to estimate (default epsilon,pitch,roll)")
    cal.add_argument("--north-offset", choices=("instrument", "site"), default="instrument",
                     help="what a north offset is: 'instrument' (default) the instrument turned "
                          "on its site (its beams and measurement points turn, the flow stays), "
                          "'site' the flow turns with it (a platform that distorts the flow "
                          "shares its heading error); see lidarjax.calibrate")
    cal.add_argument("--period", default="10min",
                     help="averaging interval of the raw records (default 10min; shorter "
                          "intervals give more records from a short file)")
    cal.add_argument("--parameter", type=finite_float, default=None,
                     help="for a table over a profile parameter: the value to calibrate at "
                          "(default the middle of its range)")
    cal.add_argument("--exact", action="store_true",
                     help="iterate on the exact geometry: read the table's CFD runs again "
                          "(the settings and field files its metadata names, cropped to where "
                          "an instrument turned by up to 15 and tilted by up to 3 degrees "
                          "looks, all held in memory), build the table at each estimate and "
                          "fit what is left (lidarjax.calibrate(runs=...)); meshes are sampled "
                          "on their resampling grid, the table too")
    cal.add_argument("--out", default=None, help="write the result as JSON")


def _reference(path: Path, times: np.ndarray, heights: np.ndarray):
    """``(speed, direction)`` ``(r, h)`` from a long-format CSV, NaN where absent."""
    speed = np.full((times.size, heights.size), np.nan)
    direction = np.full((times.size, heights.size), np.nan)
    index = {np.datetime64(t, "s"): i for i, t in enumerate(times)}
    with open(path, newline="") as fh:
        rows = csv.DictReader(line for line in fh if not line.startswith("#"))
        need = {"time", "height_m", "speed_m_s", "direction_deg"}
        if rows.fieldnames is None or not need <= set(rows.fieldnames):
            raise ValueError(f"--reference {path}: expected columns {','.join(sorted(need))}")
        for k, row in enumerate(rows, 2):
            try:
                t = np.datetime64(row["time"].strip().replace(" ", "T"), "s")
                z = float(row["height_m"])
                s, d = float(row["speed_m_s"]), float(row["direction_deg"])
            except ValueError:
                raise ValueError(f"--reference {path}, line {k}: unreadable row") from None
            i = index.get(t)
            j = int(np.argmin(np.abs(heights - z)))
            if i is not None and abs(heights[j] - z) <= 0.5:
                speed[i, j], direction[i, j] = s, d
    return speed, direction


def _table_runs(meta: dict, heights: np.ndarray):
    """The `lidarjax.TableRuns` of a table file written by `lidarjax table`, from its
    metadata (settings file, one CFD file per platform rotation, scan, probe, installation,
    free stream) at the calibration's `heights` (m)."""
    settings_path = Path(meta.get("settings", ""))
    if not settings_path.is_file():
        raise FileNotFoundError(f"--exact: the table's settings file is gone: {settings_path}")
    settings = read_settings(settings_path).with_heights(heights)
    files = {float(k): Path(v) for k, v in meta["cfd_files"].items()}
    missing = [str(p) for p in files.values() if not (p.is_file() or p.is_dir())]
    if missing:
        raise FileNotFoundError(f"--exact: the table's CFD files are gone: {', '.join(missing)}")
    for p in set(files.values()):
        check_field_file(p)
    betas = [float(b) for b in settings.betas]
    paths = {b: files[min(files, key=lambda k: abs(k - b))] for b in betas}
    scan = make_scan(meta["scan"], meta.get("cone_angle_deg"),
                     tilt_compensation=bool(meta.get("tilt_compensation", False)))
    kind = meta.get("probe", "point")
    volume = kind != "point"
    probe = make_probe(SimpleNamespace(probe=kind,
                                       probe_nodes=meta.get("probe_nodes") if volume else None,
                                       probe_scale=meta.get("probe_scale") if volume else None))
    loaded = {}

    def field_for_beta(beta):  # one read per file, however many rotations share it
        p = paths[beta]
        if p not in loaded:
            loaded[p] = load_field(p)
        return loaded[p]

    return table_runs(settings, betas, field_for_beta, scan,
                      u_ref=tuple(meta.get("u_ref_cfd_m_s", SEED_U_REF)), probe=probe,
                      pitch=float(meta.get("pitch_deg", 0.0)),
                      roll=float(meta.get("roll_deg", 0.0)))


def _say(text) -> None:
    status_line("calibrate", text)


def _load_table(args):
    """The table to calibrate with and its metadata: a table over a profile parameter is
    taken at ``--parameter`` (default the middle of its range)."""
    table, meta = load_table(args.table, return_metadata=True)
    if isinstance(table, ProfileTable):
        if args.exact:
            raise ValueError(f"--exact: {args.table} is a table over {table.name}: its runs are "
                             "not one set of CFD runs; calibrate without --exact")
        value = args.parameter if args.parameter is not None else float(
            0.5 * (table.parameters[0] + table.parameters[-1]))
        _say(f"table over {table.name}: calibrating at {table.name} = {value:g}")
        table = table.at(value)
    return table, meta


def _read_records(args, files, table):
    """The raw LOS of every record file at the heights it shares with `table`: ``(los (r, h,
    b), times (r,), (table index, record index) of the heights, header tilt {name: deg})``;
    every file must be a ``.rtd`` with the same heights."""
    min_avail = args.min_availability
    los, times, heights, header = [], [], None, {}
    for f in files:
        rec = load_records(f, period=args.period, min_availability=min_avail)
        if rec.kind != "rtd" or rec.los is None:
            raise ValueError(f"--records {f}: calibration needs raw LOS records (.rtd); a "
                             f"{rec.kind} file reports reconstructed winds only")
        ti, ri, _, _ = match_heights(table.heights, rec.heights)
        if ti.size == 0:
            raise ValueError(f"--records {f}: none of the table's heights is in the file")
        if heights is not None and not np.array_equal(ti, heights[0]):
            raise ValueError(f"--records {f}: other heights than {files[0]}")
        heights = (ti, ri)
        los.append(np.asarray(rec.los)[:, ri, : table.n_beams])
        times.append(np.asarray(rec.time))
        for k in ("pitch", "roll"):
            v = float(getattr(rec, k))
            if math.isfinite(v):
                header.setdefault(k, v)
    return np.concatenate(los), np.concatenate(times), heights, header


def _print_result(result, sub, header) -> None:
    print(f"calibration from {int(result.n_records)} records x {sub.n_heights} heights "
          f"({int(result.n_problems)} record-heights used); LOS residual "
          f"{float(result.noise):.3f} m/s")
    for line in result.summary():
        print(line)
    if header:
        print("header tilt: " + ", ".join(f"{k} {v:g} deg" for k, v in header.items())
              + " (PitchAngle/RollAngle read in lidarjax's convention; the files do not "
                "state theirs)")


def _write_json(args, files, z, result) -> None:
    """The calibration as JSON at ``--out`` (atomically)."""
    doc = {
        "table": str(args.table), "records": [str(f) for f in files],
        "reference": args.reference, "heights_m": [float(v) for v in z],
        "names": list(result.names),
        "offset_deg": [float(v) for v in np.asarray(result.offset)],
        "value_deg": [float(v) for v in np.asarray(result.value)],
        "nominal_deg": [float(v) for v in np.asarray(result.nominal)],
        "std_deg": [float(v) for v in np.asarray(result.std)],
        "correlation": np.asarray(result.correlation).tolist(),
        "identifiable": [bool(v) for v in np.asarray(result.identifiable)],
        "header_deg": [float(v) for v in np.asarray(result.header)],
        "n_records": int(result.n_records), "n_problems": int(result.n_problems),
        "noise_m_s": float(result.noise), "converged": result.converged,
        "flags": int(result.flags), "passes": int(result.num_steps),
        "north_offset": args.north_offset, "rebuilds": int(result.rebuilds),
        "notes": list(result.notes),
    }
    with atomic_path(Path(args.out)) as tmp:
        Path(tmp).write_text(json.dumps(doc, indent=1, allow_nan=True) + "\n")
    print(f"wrote {args.out}")


def run(args) -> int:
    files = [Path(r) for r in args.records]  # they and --table exist (checked when parsed)
    if args.out is not None:
        check_output_file(Path(args.out), inputs=[("--table", args.table)] + [
            ("--records", f) for f in files])
    table, meta = _load_table(args)
    los, times, (ti, _), header = _read_records(args, files, table)
    sub = subset_table(table, ti)
    z = np.asarray(sub.heights, np.float64)
    reference = None
    if args.reference is not None:
        reference = _reference(Path(args.reference), times, z)
        matched = int(np.isfinite(reference[1]).sum())
        _say(f"reference: {matched} of {reference[1].size} record-heights matched")

    # what calibrate reads: the LOS and the header's tilt
    recs = SimpleNamespace(los=los, pitch=header.get("pitch", math.nan),
                           roll=header.get("roll", math.nan))
    runs = None
    if args.exact:
        if "cfd_files" not in meta or "settings" not in meta:
            raise ValueError(f"--exact: {args.table} does not name its CFD runs (not written "
                             "by `lidarjax table`); calibrate without --exact")
        _say("--exact: reading the table's CFD runs again ...")
        runs = _table_runs(meta, z)
        sub = runs.table()
    result = calibrate(recs, sub, wrt=args.wrt, reference=reference,
                       north_offset=args.north_offset, runs=runs)
    _print_result(result, sub, header)
    if args.out is not None:
        _write_json(args, files, z, result)
    return 0
